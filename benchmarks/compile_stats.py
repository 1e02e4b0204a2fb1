"""Where the test suite's time goes: a pytest plugin that counts XLA compiles per test.

The default suite spends most of its time compiling MJX programs. On a shared, noisy
machine wall times move with the load; the number of programs compiled (and which
test compiled them) does not. Load it with ``-p benchmarks.compile_stats``::

    XDG_CACHE_HOME=$(mktemp -d) COMPILE_STATS_OUT=/tmp/stats.json PYTHONPATH=$PWD \\
    .venv/bin/python -m pytest -q -p benchmarks.compile_stats tests/test_task_contract.py

(a fresh ``XDG_CACHE_HOME``: the package's caches start empty, as on a fresh clone;
``MJX_DAMAGE_CACHE_DIR`` and ``JAX_COMPILATION_CACHE_DIR`` unset). Per test phase
(``setup`` holds module-scoped fixtures: the first test that uses one pays) it
records XLA backend compiles that missed the persistent cache (count, seconds,
program names of those ≥ 1 s), persistent-cache hits, and the phase's wall time.
The terminal summary prints the totals per test file and the 25 costliest phases;
``COMPILE_STATS_OUT`` gets every phase and file as JSON (:func:`mjx_damage.io.write_json`).
Subprocesses the tests start are not counted (their wall time is, in the phase).
"""

from __future__ import annotations

import collections
import os
import time

import pytest

_BACKEND = "/jax/core/compile/backend_compile_duration"
_HIT = "/jax/compilation_cache/cache_hits"
_phase = {"id": "(collection)"}
_stats: dict = collections.defaultdict(lambda: {"compiles": 0, "compile_s": 0.0, "hits": 0, "wall_s": 0.0,
                                                "big": []})
_hits_pending = {"n": 0}


def _on_duration(event, duration_secs, **kw):
  if event != _BACKEND:
    return
  s = _stats[_phase["id"]]
  if _hits_pending["n"]:  # this "compile" was a persistent-cache read
    _hits_pending["n"] -= 1
    s["hits"] += 1
    return
  s["compiles"] += 1
  s["compile_s"] += duration_secs
  if duration_secs >= 1.0:
    s["big"].append(f"{kw.get('fun_name', '?')} {duration_secs:.1f}s")


def _on_event(event, **kw):
  if event == _HIT:
    _hits_pending["n"] += 1


def pytest_configure(config):
  from jax import monitoring

  monitoring.register_event_duration_secs_listener(_on_duration)
  monitoring.register_event_listener(_on_event)


def _timed(phase):
  @pytest.hookimpl(hookwrapper=True)
  def hook(item):
    _phase["id"] = f"{item.nodeid} [{phase}]"
    _hits_pending["n"] = 0
    t0 = time.perf_counter()
    yield
    _stats[_phase["id"]]["wall_s"] += time.perf_counter() - t0
    _phase["id"] = "(between tests)"
  return hook


pytest_runtest_setup = _timed("setup")
pytest_runtest_call = _timed("call")
pytest_runtest_teardown = _timed("teardown")


def pytest_terminal_summary(terminalreporter):
  rows = sorted(_stats.items(), key=lambda kv: -kv[1]["wall_s"])
  tot = {k: sum(v[k] for v in _stats.values()) for k in ("compiles", "compile_s", "hits", "wall_s")}
  w = terminalreporter.write_line
  w(f"compile stats: {tot['compiles']} compiles (cache misses) {tot['compile_s']:.0f} s, "
    f"{tot['hits']} persistent-cache hits, {tot['wall_s']:.0f} s in tests")
  files: dict = collections.defaultdict(lambda: {"compiles": 0, "compile_s": 0.0, "hits": 0, "wall_s": 0.0})
  for k, v in _stats.items():
    f = files[k.split("::")[0]]
    for key in f:
      f[key] += v[key]
  for name, v in sorted(files.items(), key=lambda kv: -kv[1]["wall_s"]):
    w(f"  {v['wall_s']:7.1f}s wall {v['compiles']:4d} compiles {v['compile_s']:6.1f}s {v['hits']:3d} hits  {name}")
  w("costliest test phases:")
  for k, v in rows[:25]:
    w(f"  {v['wall_s']:7.1f}s wall {v['compiles']:4d} compiles {v['compile_s']:6.1f}s {v['hits']:3d} hits  {k}")
    for b in v["big"]:
      w(f"        {b}")
  out = os.environ.get("COMPILE_STATS_OUT")
  if out:
    from mjx_damage import io

    io.write_json(out, {"totals": tot, "files": dict(files), "phases": dict(rows)})

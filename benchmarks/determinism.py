"""Determinism: same seed → same rollout; per-env results independent of chunking and batch size.

A rollout: ``tasks.make(task)`` vmapped over B envs, env b reset from key b and
stepped with uniform random actions drawn from ``fold_in(key b, t)``, so each
env's inputs depend on its own key and step index only, never on B or on how
the steps are split into calls. The whole final ``State`` (physics, damage
state, obs, reward, metrics) is compared. Per task, four checks:

- ``rerun``: the same call twice (same executable, same keys);
- ``recompiled``: a freshly traced and compiled pair of functions, same keys;
- ``chunked``: the steps split into two calls of other lengths;
- ``half_batch``: each half of the batch run alone (B/2 envs) vs the same envs in
  the batch of B.

Each check reports whether every leaf is bitwise equal and the largest
|difference| of obs, reward, link health, qpos and qvel. On CPU all four are
bitwise equal (tests/test_determinism.py pins it); on GPU reductions may run
in another order across executables, so ``recompiled`` / ``half_batch`` are
judged against float tolerances (``TOL``), ``rerun`` and ``chunked`` must still
be bitwise equal (one executable, same inputs).

Usage::

    python benchmarks/determinism.py                    # GPU: 1024 envs × 200 steps, 3 tasks
    python benchmarks/determinism.py --envs 8 --steps 20  # CPU size

Writes ``benchmarks/results/determinism_<platform>.{json,md}`` (``--out``: another
JSON path); exits 1 when a check fails.
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import jax  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
from mjx_damage import io  # noqa: E402

DEFAULT_TASKS = ("place_plate", "turn_on_stove", "pour_water")
# Largest |Δ| accepted where bitwise equality is not promised (GPU: other executables, other batch
# shapes). After 200 steps of contact-rich chaotic dynamics last-bit differences grow, so the bound is
# on what a user reads (reward, health) rather than on raw state; liquid counts are discrete.
TOL = {"obs": 1e-2, "reward": 1e-2, "link_health": 1.0, "qpos": 1e-2, "qvel": 1.0}
TOL_LIQUID = {"obs": 0.1, "reward": 0.2}  # a few particles of 128 crossing a boundary


def rollout_fns(env):
  """(init(keys u32[B, 2]) -> carry, advance(carry, t0, n) -> carry), both jitted over the batch."""

  def init(key):
    return env.reset(key), key

  def advance(carry, t0, n):
    def body(t, c):
      s, key = c
      a = jax.random.uniform(jax.random.fold_in(key, t), (env.action_size,), minval=-1.0, maxval=1.0)
      return env.step(s, a), key

    return jax.lax.fori_loop(t0, t0 + n, body, carry)

  return jax.jit(jax.vmap(init)), jax.jit(jax.vmap(advance, in_axes=(0, None, None)))


def run(fns, keys, chunks):
  """Final State (host arrays) of the rollout, its steps split into calls of ``chunks`` steps."""
  init, advance = fns
  carry = init(keys)
  t = 0
  for n in chunks:
    carry = advance(carry, t, n)
    t += n
  return jax.device_get(carry[0])


def take(tree, idx):
  return jax.tree.map(lambda x: np.asarray(x)[idx], tree)


MAX_PATHS = 12  # differing leaf paths kept per check in the report


def bitwise_mismatches(a, b) -> list:
  """Paths of the leaves whose bytes differ (NaN payloads and the sign of zero included)."""
  out = []
  for (path, x), y in zip(jax.tree_util.tree_leaves_with_path(a), jax.tree.leaves(b)):
    x, y = np.asarray(x), np.asarray(y)
    if x.shape != y.shape or x.tobytes() != y.tobytes():
      out.append(jax.tree_util.keystr(path))
  return out


def compared(s) -> dict:
  return {"obs": s.obs, "reward": s.reward, "link_health": s.info["link_health"],
          "qpos": s.pipeline_state.qpos, "qvel": s.pipeline_state.qvel}


def max_diffs(a, b) -> dict:
  ca, cb = compared(a), compared(b)
  return {k: float(np.max(np.abs(np.asarray(ca[k], np.float64) - np.asarray(cb[k], np.float64)))) for k in ca}


def check_task(name: str, envs: int, steps: int, seed: int, strict: bool) -> dict:
  """The four checks of one task (module docstring); ``strict``: every check must be bitwise."""
  env = tasks.make(name)
  keys = jax.random.split(jax.random.PRNGKey(seed), envs)
  split = (steps // 3, steps - steps // 3)
  t0 = time.perf_counter()
  fns = rollout_fns(env)
  ref = run(fns, keys, (steps,))
  outs = {"rerun": run(fns, keys, (steps,)),
          "recompiled": run(rollout_fns(env), keys, (steps,)),
          "chunked": run(fns, keys, split)}
  checks = {}
  for k, got in outs.items():
    bad = bitwise_mismatches(ref, got)
    checks[k] = {"bitwise": not bad, "max_abs_diff": max_diffs(ref, got), "differing_leaves": bad[:MAX_PATHS]}
  h = envs // 2
  halves = [run(fns, keys[sl], (steps,)) for sl in (slice(0, h), slice(h, envs))]
  bad = sorted({p for sl, got in zip((slice(0, h), slice(h, envs)), halves) for p in bitwise_mismatches(take(ref, sl), got)})
  bit = not bad
  diffs = [max_diffs(take(ref, sl), got) for sl, got in zip((slice(0, h), slice(h, envs)), halves)]
  checks["half_batch"] = {"bitwise": bit, "max_abs_diff": {k: max(d[k] for d in diffs) for k in diffs[0]},
                          "differing_leaves": bad[:MAX_PATHS]}
  tol = TOL_LIQUID if env.unwrapped.damage_binding.liquid is not None else TOL
  for k, c in checks.items():
    if strict or k in ("rerun", "chunked"):
      c["ok"] = c["bitwise"]
      c["criterion"] = "bitwise"
    else:
      c["ok"] = c["bitwise"] or all(c["max_abs_diff"][f] <= t for f, t in tol.items())
      c["criterion"] = "bitwise or |Δ| ≤ " + ", ".join(f"{f} {t:g}" for f, t in tol.items())
  # the envs differ from each other, so equality is not trivially true
  distinct = not np.array_equal(np.asarray(ref.obs[0]), np.asarray(ref.obs[1]))
  return {"task": name, "envs": envs, "steps": steps, "chunks": list(split), "checks": checks,
          "envs_distinct": distinct, "ok": distinct and all(c["ok"] for c in checks.values()),
          "wall_s": round(time.perf_counter() - t0, 1)}


def report_md(res: dict) -> str:
  lines = [f"# Determinism ({res['device']})", "",
           f"Command: `{res['command']}`  ", f"Date: {res['date']}; jax {res['versions']['jax']}, "
           f"mujoco {res['versions']['mujoco']}; total {res['total_s']} s", "",
           "Each task: B envs × T random-action steps (per-env keys; benchmarks/determinism.py docstring). "
           "Cells: bitwise equal (✓) or the largest |Δ| of obs / reward / link health / qpos / qvel.", "",
           "| task | envs × steps | rerun | recompiled | chunked | half batch alone | result |",
           "|---|---|---|---|---|---|---|"]

  def cell(c):
    if c["bitwise"]:
      return "✓ bitwise"
    d = c["max_abs_diff"]
    return ("≈ " if c["ok"] else "✗ ") + " / ".join(f"{d[k]:.2g}" for k in ("obs", "reward", "link_health", "qpos",
                                                                             "qvel"))

  for r in res["tasks"]:
    c = r["checks"]
    lines.append(f"| {r['task']} | {r['envs']} × {r['steps']} | {cell(c['rerun'])} | {cell(c['recompiled'])} | "
                 f"{cell(c['chunked'])} | {cell(c['half_batch'])} | {'PASS' if r['ok'] else 'FAIL'} |")
  lines += ["", "Leaves that differ bitwise (first few per check), where any:", ""]
  for r in res["tasks"]:
    for k, c in r["checks"].items():
      if c.get("differing_leaves"):
        lines.append(f"- {r['task']} / {k}: " + ", ".join(f"`{p}`" for p in c["differing_leaves"]))
  lines += ["", f"Strict (every check bitwise): {res['strict']}. Result: {'PASS' if res['ok'] else 'FAIL'}", ""]
  return "\n".join(lines)


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
  gpu = jax.default_backend() != "cpu"
  p.add_argument("--tasks", default=",".join(DEFAULT_TASKS), help="comma-separated task names")
  p.add_argument("--envs", type=int, default=1024 if gpu else 8, help="environments per task (even, >= 2)")
  p.add_argument("--steps", type=int, default=200 if gpu else 20, help="env steps per rollout (>= 3)")
  p.add_argument("--seed", type=int, default=7)
  p.add_argument("--strict", action="store_true", default=not gpu,
                 help="every check bitwise (default on CPU)")
  p.add_argument("--out", default=None, help="JSON path (default benchmarks/results/determinism_<platform>.json)")
  args = p.parse_args(argv)
  names = [t for t in args.tasks.split(",") if t]
  for t in names:
    if t not in tasks.names():
      p.error(f"--tasks: unknown task {t!r}; valid: {', '.join(tasks.names())}")
  if args.envs < 2 or args.envs % 2:
    p.error(f"--envs: an even number >= 2, got {args.envs}")
  if args.steps < 3:
    p.error(f"--steps: must be >= 3, got {args.steps}")
  dev = jax.devices()[0]
  t0 = time.perf_counter()
  rows = []
  for name in names:
    r = check_task(name, args.envs, args.steps, args.seed, args.strict)
    rows.append(r)
    print(f"{name}: {'PASS' if r['ok'] else 'FAIL'} "
          f"{ {k: (c['bitwise'], c['max_abs_diff']['reward']) for k, c in r['checks'].items()} } {r['wall_s']} s",
          flush=True)
  import mujoco

  res = {"command": " ".join(shlex.quote(a) for a in ["python", "benchmarks/determinism.py",
                                                      *(sys.argv[1:] if argv is None else argv)]),
         "device": f"{dev.platform}:{getattr(dev, 'device_kind', '')}", "host": platform.node(),
         "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
         "total_s": round(time.perf_counter() - t0, 1), "strict": args.strict, "seed": args.seed,
         "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__}, "tasks": rows,
         "ok": all(r["ok"] for r in rows)}
  out = args.out or os.path.join(HERE, "results", f"determinism_{dev.platform}.json")
  io.write_json(out, res)
  io.write_text(os.path.splitext(out)[0] + ".md", report_md(res))
  print(f"wrote {out}; {'PASS' if res['ok'] else 'FAIL'}")
  return 0 if res["ok"] else 1


if __name__ == "__main__":
  sys.exit(main())

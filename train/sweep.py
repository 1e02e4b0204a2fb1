"""Evaluation sweeps: tasks × policies × seeds × fragility levels → paper-style table.

For each (task, policy) one :class:`train.evaluate.Evaluator` is compiled for a
batch of ``levels × episodes`` environments; environment ``j`` of level ``i``
gets fragility ``levels[i]`` in its damage parameters (data, not code), and the
same episode keys are reused across levels (common random numbers: a level's
difference is the fragility, not the draw). Every seed reuses the executable;
the JSON records how many were compiled (1 per task × policy).

On several devices the batch is handed to the evaluator in :func:`device_local_order`:
each device gets its own share of the episodes at every level, not whole levels. The rows
are the same, so are the results; the order matters for speed only. MJX's solver loops run
until the slowest row of a device's batch has converged, and the copies of one episode at
the different levels share their physics (fragility changes health, not motion), so a device
holding E/D episodes × L levels waits on E/D distinct trajectories, not on E (measured on
2 GPUs: ``benchmarks/results/multi_gpu_nvidia_h200_eval_layout.md``).

CLI (:mod:`apps.sweep_cli`)::

    mjx-damage sweep --tasks place_plate --policies scripted:safe,scripted:unsafe \
        --seeds 0,1,2 --fragility 0.5,1,2,4 --episodes 64 --out sweep.json

writes ``sweep.json`` and ``sweep.md`` (like the paper's VLA table: task,
C %, SC %, average health; one row per task × policy × fragility, mean ± std
over seeds).
"""

from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

import numpy as np

import train.evaluate as E
from mjx_damage.randomize import check_fragility


def check_sweep(tasks: Sequence[str], policies: Sequence[str], seeds: Sequence[int],
                fragility: Sequence[float], episodes: int, safe_threshold: float = 95.0) -> None:
  """Validate a sweep before anything is built or compiled (``ValueError`` naming the field).

  Task and policy names are the caller's to check (its ``make_env``/``make_policy``
  know them: :mod:`apps.resolve` for the command line).
  """
  if not tasks:
    raise ValueError("tasks: give at least one task")
  if not policies:
    raise ValueError("policies: give at least one policy")
  if not seeds:
    raise ValueError("seeds: give at least one seed")
  for i, s in enumerate(seeds):
    if isinstance(s, bool) or not isinstance(s, int) or s < 0:
      raise ValueError(f"seeds[{i}]: must be an int >= 0, got {s!r}")
  check_fragility(list(fragility))
  E.check_args(episodes, 1.0, safe_threshold)


def device_local_order(episodes: int, num_levels: int, num_devices: int) -> np.ndarray:
  """Row order of a sweep batch that gives each device its own episodes at every level.

  The natural batch is level-major (row ``level * episodes + episode``). Returns ``order``:
  int[num_levels * episodes], a permutation of those rows such that the evaluator's contiguous
  per-device shards each hold a contiguous block of about ``episodes / num_devices`` episodes at
  all levels (exactly, when ``num_devices`` divides ``episodes``). Run ``batch[order]``; the
  results of row ``order[j]`` are at ``j`` (``np.argsort(order)`` maps them back). One device: the
  identity.
  """
  rows = np.arange(num_levels * episodes)
  level, episode = rows // episodes, rows % episodes
  block = episode * num_devices // episodes  # which device's share the episode is in
  return np.lexsort((episode, level, block))


def sweep(tasks: Sequence[str], policies: Sequence[str], seeds: Sequence[int], fragility: Sequence[float],
          episodes: int, safe_threshold: float = 95.0, episode_length: Optional[int] = None,
          devices=None, log=print, on_progress=None, *, make_env: Callable, make_policy: Callable,
          episode_length_of: Callable = lambda env, task: E.env_episode_length(env),
          describe_program: Optional[Callable] = None, program_roots: Sequence[str] = ()) -> dict:
  """Run the sweep; returns {"rows": aggregated rows, "runs": per-seed rows, "compiles": {...}}.

  ``make_env(task) -> env`` and ``make_policy(spec, env) -> policy(state, rng)``
  turn the names of ``tasks`` and ``policies`` into objects; ``episode_length_of(env,
  task)`` gives a task's episode length when ``episode_length`` is None.

  ``on_progress(partial_result)`` is called after every (task, policy), so a
  long sweep that is interrupted keeps what it finished. ``describe_program(task,
  spec) -> dict`` (names → a description, as the CLI has) keeps each traced
  evaluation program on disk (:class:`train.evaluate.Evaluator` ``program``).
  """
  check_sweep(tasks, policies, seeds, fragility, episodes, safe_threshold)
  levels = np.asarray(fragility, np.float32)
  frag = np.repeat(levels, episodes)  # [levels × episodes]
  runs, rows, compiles = [], [], {}
  envs = {task: make_env(task) for task in tasks}
  for env in envs.values():  # every batch checked before the first compiles
    E.check_memory(env, episodes, devices, per_episode_batch=len(levels))
  for task in tasks:
    env = envs[task]
    T = episode_length or episode_length_of(env, task)
    for spec in policies:
      program = None if describe_program is None else describe_program(task, spec)
      ev = E.make_evaluator(env, make_policy(spec, env), T, devices, program, program_roots)
      t0 = time.perf_counter()
      per_level = {float(f): [] for f in levels}
      for seed in seeds:
        keys = E.episode_keys(seed, episodes)
        keys = np.tile(np.asarray(keys), (len(levels), 1))  # same episodes at every level
        order = device_local_order(episodes, len(levels), len(ev.devices))
        per_ep = ev.run(keys[order], frag[order])
        back = np.argsort(order)  # back to level-major
        per_ep = {k: v[back] for k, v in per_ep.items()}
        for i, f in enumerate(levels):
          sl = slice(i * episodes, (i + 1) * episodes)
          m = E.metrics({k: v[sl] for k, v in per_ep.items()}, env.entity_names, safe_threshold)
          runs.append({"task": task, "policy": spec, "fragility": float(f), "seed": seed, "metrics": m})
          per_level[float(f)].append(m)
      compiles[f"{task}/{spec}"] = ev.num_compiled
      log(f"{task} / {spec}: {len(seeds)} seed(s) x {len(levels)} levels x {episodes} episodes "
          f"x {T} steps in {time.perf_counter() - t0:.1f} s, {ev.num_compiled} executable(s)")
      for f, ms in per_level.items():
        rows.append(aggregate(task, spec, f, ms))
      if on_progress is not None:
        on_progress({"rows": rows, "runs": runs, "compiles": compiles})
  return {"rows": rows, "runs": runs, "compiles": compiles}


def aggregate(task: str, policy: str, fragility: float, ms: list[dict]) -> dict:
  """Mean and std over seeds of one (task, policy, fragility) cell; rates in %."""
  def stat(get, scale=1.0):
    v = np.array([get(m) for m in ms], np.float64) * scale
    return float(v.mean()), float(v.std())

  row = {"task": task, "policy": policy, "fragility": fragility, "seeds": len(ms),
         "episodes_per_seed": ms[0]["episodes"]}
  for key, get, scale in (
      ("C", lambda m: m["completion"], 100.0),
      ("SC", lambda m: m["safe_completion"], 100.0),
      ("avg_health", lambda m: m["avg_health"], 1.0),
      ("zero_damage", lambda m: m["zero_damage_rate"], 100.0),
      ("cost_mean", lambda m: m["cost_mean"], 1.0),
  ):
    row[key], row[key + "_std"] = stat(get, scale)
  return row


def markdown(rows: list[dict], safe_threshold: float) -> str:
  """The paper-style table (mean ± std over seeds where there are several)."""
  def cell(r, k, fmt):
    s = format(r[k], fmt)
    return s + (" ± " + format(r[k + "_std"], fmt) if r["seeds"] > 1 else "")

  lines = [
      f"C: task completion rate, SC: safe completion rate (completed and every tracked entity's final "
      f"health > {safe_threshold:g}), Avg. Health: mean final entity health; fragility f divides "
      "thresholds and multiplies damage scales.",
      "",
      "| Task | Policy | Fragility | C [%] | SC [%] | Avg. Health | Zero damage [%] | Episode cost |",
      "|---|---|---:|---:|---:|---:|---:|---:|",
  ]
  for r in rows:
    lines.append(f"| {r['task']} | {r['policy']} | {r['fragility']:g} | {cell(r, 'C', '.1f')} | "
                 f"{cell(r, 'SC', '.1f')} | {cell(r, 'avg_health', '.2f')} | {cell(r, 'zero_damage', '.1f')} | "
                 f"{cell(r, 'cost_mean', '.2f')} |")
  return "\n".join(lines) + "\n"

"""The Panda's differential-IK controller and the Panda in tasks: one command, one results file.

1. **Figure-eight tracking** in free space (``tasks.robots.checks.track``): a 3-D
   figure-eight 24 × 16 × 10 cm, period 5 s (peak speed ≈ 0.17 m/s), followed with
   the ``[Δx, Δy, Δz, gripper]`` action; RMS and max grip-point error over two
   periods after a 0.5 s settle. Target (issue #13): RMS ≤ 5 mm.
2. **Joint limits under random actions** (``checks.random_actions``): ``--envs`` ×
   ``--steps`` control steps of uniform random actions (each held 10 steps) for
   ``panda`` and ``panda_wrist``, once per seed of ``--limit-seeds``; worst excess of
   any joint beyond its range over every physics substep, and whether the state
   stayed finite. Target: ≤ 0.01 rad on every seed.
3. **Compile time of one task step** (``--tasks``): ``jit(vmap(env.step))`` over 8
   envs, lowered and compiled from scratch (persistent cache off), Panda vs gripper;
   the 1-minute load average is recorded beside it (the CPU is shared).
4. **Scripted policies with the Panda** (``--tasks``, default place_plate):
   ``--episodes`` episodes of each scripted style through ``tasks.rollout``;
   completion % and safe completion % (completed, every entity's final health > 95),
   plus the first-compile time of the batched rollout.

Writes ``benchmarks/results/panda_ik_<backend>.json``.

Usage::

    .venv/bin/python benchmarks/panda_ik.py [--envs 20] [--steps 500] [--limit-seeds 0,1,2] [--episodes 16] [--tasks place_plate]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

# First-compile times are only meaningful without the persistent cache: switch it off here.
jax.config.update("jax_enable_compilation_cache", False)

import tasks  # noqa: E402
from mjx_damage import io  # noqa: E402
from tasks.robots import checks  # noqa: E402
from tasks.rollout import rollout_fn  # noqa: E402

PERIOD = 5.0  # s
SETTLE = 0.5  # s excluded from the error statistics


def figure_eight(periods: float = 2.0) -> dict:
  dt = 0.004 * checks.N_SUBSTEPS
  n = int(round((SETTLE + periods * PERIOD) / dt))
  wp = checks.figure_eight(n, dt, period=PERIOD)
  run = checks.track("panda", wp)
  t0 = time.perf_counter()
  err, _ = jax.block_until_ready(run())
  wall = time.perf_counter() - t0
  e = np.asarray(err)[int(SETTLE / dt):]
  speed = np.linalg.norm(np.diff(wp, axis=0), axis=1) / dt
  return {"rms_mm": float(np.sqrt(np.mean(e**2)) * 1e3), "max_mm": float(e.max() * 1e3),
          "peak_speed_m_s": float(speed.max()), "steps": int(n), "period_s": PERIOD,
          "size_m": [0.24, 0.16, 0.10], "compile_and_run_s": wall}


def joint_limits(robot: str, envs: int, steps: int, seed: int) -> dict:
  run = checks.random_actions(robot, envs, steps)
  t0 = time.perf_counter()
  worst, ok, _ = jax.block_until_ready(run(jax.random.PRNGKey(seed)))
  return {"robot": robot, "seed": seed, "envs": envs, "steps_per_env": steps, "control_steps": envs * steps,
          "worst_excess": float(worst), "finite": bool(ok), "compile_and_run_s": time.perf_counter() - t0}


def scripted(task: str, episodes: int, seed: int) -> dict:
  env = tasks.make(task, robot="panda")
  length = env.unwrapped.episode_length
  run = jax.jit(rollout_fn(env, [tasks.scripted_policy(env, s) for s in tasks.STYLES], length))
  which = jnp.repeat(jnp.arange(2), episodes)
  rngs = jax.random.split(jax.random.PRNGKey(seed), 2 * episodes)
  t0 = time.perf_counter()
  compiled = run.lower(rngs, which).compile()
  compile_s = time.perf_counter() - t0
  t0 = time.perf_counter()
  out = jax.block_until_ready(compiled(rngs, which))
  run_s = time.perf_counter() - t0
  comp = np.asarray(out.completed)
  safe_ok = comp * np.all(np.asarray(out.entity_health) > 95.0, axis=-1)
  res = {"task": task, "robot": "panda", "episodes_per_style": episodes, "episode_length": length,
         "first_compile_s": compile_s, "run_s": run_s, "entities": list(env.entity_names)}
  for i, style in enumerate(tasks.STYLES):
    sl = slice(i * episodes, (i + 1) * episodes)
    res[style] = {"completion_pct": float(100 * comp[sl].mean()), "safe_completion_pct": float(100 * safe_ok[sl].mean()),
                  "mean_entity_health": np.asarray(out.entity_health)[sl].mean(0).round(2).tolist(),
                  "any_nan": bool(np.asarray(out.any_nan)[sl].any())}
  return res


def step_compile(task: str, robot: str, n: int = 8) -> dict:
  env = tasks.make(task, robot=robot)
  state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), n))
  act = jnp.zeros((n, env.action_size))
  load = os.getloadavg()[0]
  t0 = time.perf_counter()
  jax.jit(jax.vmap(env.step)).lower(state, act).compile()
  return {"task": task, "robot": robot, "envs": n, "step_compile_s": time.perf_counter() - t0, "loadavg_1min": load}


def main():
  ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  ap.add_argument("--envs", type=int, default=20)
  ap.add_argument("--steps", type=int, default=500)
  ap.add_argument("--episodes", type=int, default=16, help="per scripted style; 0 skips the task rollouts")
  ap.add_argument("--tasks", default="place_plate", help="comma-separated task names")
  ap.add_argument("--seed", type=int, default=0, help="seed of the scripted rollouts")
  ap.add_argument("--limit-seeds", default="0,1,2", help="comma-separated seeds of the random-action check")
  ap.add_argument("--out", default=None)
  args = ap.parse_args()
  names = [t for t in args.tasks.split(",") if t]
  for t in names:
    tasks.task_class(t)  # unknown names fail before any compile
  for k in ("envs", "steps", "episodes"):
    if getattr(args, k) < (0 if k == "episodes" else 1):
      raise ValueError(f"--{k}: must be positive, got {getattr(args, k)}")
  try:
    limit_seeds = [int(v) for v in args.limit_seeds.split(",")]
  except ValueError:
    raise ValueError(f"--limit-seeds: comma-separated integers, got {args.limit_seeds!r}") from None

  res = {"backend": jax.default_backend(), "device": str(jax.devices()[0]), "machine": platform.machine(),
         "cpu_count": os.cpu_count(), "command": " ".join(sys.argv)}
  res["figure_eight"] = figure_eight()
  print("figure-eight:", res["figure_eight"], flush=True)
  res["joint_limits"] = [joint_limits(r, args.envs, args.steps, seed) for r in ("panda", "panda_wrist")
                         for seed in limit_seeds]
  print("joint limits:", res["joint_limits"], flush=True)
  res["step_compile"] = [step_compile(t, r) for t in names for r in ("panda", "gripper")]
  print("step compile:", res["step_compile"], flush=True)
  res["scripted"] = [scripted(t, args.episodes, args.seed) for t in names] if args.episodes else []
  for r in res["scripted"]:
    print("scripted:", r, flush=True)
  out = args.out or os.path.join(os.path.dirname(__file__), "results", f"panda_ik_{res['backend']}.json")
  io.write_json(out, res)
  print("wrote", out)


if __name__ == "__main__":
  main()

"""First-compile time of each task's batched scripted rollout, wall and CPU seconds, with the machine's load.

The program is the one ``benchmarks/scripted_policies.py`` runs (``tasks.rollout.rollout_fn``: reset +
both scripted policies + step with damage at every substep, ``jit(vmap(scan))``), traced and compiled
with the persistent compilation cache off. Wall seconds depend on what else the shared machine runs, so
each row also records the process CPU seconds (all threads) spent tracing + compiling — on a quiet
2-core machine the wall time lies between CPU s / 2 and CPU s, so CPU s ≤ 60 s meets the target
whatever else runs — and the 1-minute load average before and after. Target (issue 14): ≤ 60 s per
task on the 2-core CPU when quiet.

Writes ``benchmarks/results/compile_time_cpu[_<robot>].{json,md}``; rows of tasks not in this run are kept.
``--robot`` (default the gripper, the robot of the committed results) is in the name when not the gripper.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/compile_time.py --tasks serve_pastry,pick_up_scrub,attach_camera
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

jax.config.update("jax_enable_compilation_cache", False)

import tasks  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from tasks.rollout import rollout_fn  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
TARGET_S = 60.0


def measure(name: str, episodes: int, robot: str = "gripper") -> dict:
  """Trace + compile task ``name``'s rollout of ``episodes`` episodes per policy; wall and CPU seconds."""
  load0 = os.getloadavg()[0]
  w0, c0 = time.time(), time.process_time()
  env = tasks.make(name, robot=robot)
  run = rollout_fn(env, [tasks.scripted_policy(env, s) for s in tasks.STYLES], env.unwrapped.episode_length)
  rngs = jax.random.split(jax.random.PRNGKey(0), 2 * episodes)
  which = jnp.repeat(jnp.arange(2), episodes)
  lowered = run.lower(rngs, which)
  w1, c1 = time.time(), time.process_time()
  lowered.compile()
  w2, c2 = time.time(), time.process_time()
  return {"task": name, "episodes_per_policy": episodes, "trace_wall_s": round(w1 - w0, 1), "trace_cpu_s": round(c1 - c0, 1),
          "compile_wall_s": round(w2 - w1, 1), "compile_cpu_s": round(c2 - c1, 1),
          "total_wall_s": round(w2 - w0, 1), "total_cpu_s": round(c2 - c0, 1),
          "load1_before": round(load0, 2), "load1_after": round(os.getloadavg()[0], 2),
          "meets_target_cpu": (c2 - c0) <= TARGET_S}


def write(rows: list[dict], command: str, robot: str = "gripper") -> None:
  # another robot's rows go to their own files (the gripper's names and contents stay as committed)
  stem = "compile_time_cpu" + ("" if robot == "gripper" else f"_{robot}")
  path = os.path.join(RESULTS, stem + ".json")
  done = {r["task"] for r in rows}
  if os.path.exists(path):
    with open(path) as f:
      rows = [r for r in json.load(f).get("rows", []) if r["task"] not in done] + rows
  rows = sorted(rows, key=lambda r: r["task"])
  meta = {"command": command, "jax": jax.__version__, "machine": platform.machine(), "cpu_count": os.cpu_count(),
          "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
          **({} if robot == "gripper" else {"robot": robot})}
  write_json(path, {"meta": meta, "rows": rows}, indent=1)
  lines = ["# First compile of each task's batched scripted rollout (CPU, persistent cache off)", "",
           f"Command: `{command}`  ", f"jax {meta['jax']}, {meta['cpu_count']} CPU cores shared with other jobs, "
           f"{meta['date']}.", "",
           "Trace = `tasks.make` + tracing and lowering the `jit(vmap(scan))` rollout (reset + safe/unsafe scripted "
           "policies + step, damage at every substep); compile = XLA. CPU s is the process's CPU time over all "
           "threads: on a quiet 2-core machine the wall time lies between CPU s / 2 and CPU s; the load average "
           f"shows how busy the machine was. Target: trace + compile ≤ {TARGET_S:.0f} s when quiet (judged on CPU s).",
           "",
           "| task | trace wall / CPU s | compile wall / CPU s | total wall / CPU s | load (1 min) before → after | target |",
           "|---|---|---|---|---|---|"]
  for r in rows:
    lines.append(f"| {r['task']} | {r['trace_wall_s']:.1f} / {r['trace_cpu_s']:.1f} | {r['compile_wall_s']:.1f} / "
                 f"{r['compile_cpu_s']:.1f} | {r['total_wall_s']:.1f} / {r['total_cpu_s']:.1f} | "
                 f"{r['load1_before']:.1f} → {r['load1_after']:.1f} | {'met' if r['meets_target_cpu'] else 'MISSED'} |")
  write_text(os.path.join(RESULTS, stem + ".md"), "\n".join(lines) + "\n")


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--tasks", default=None, help="comma-separated (default: every task --robot runs)")
  p.add_argument("--robot", default="gripper",
                 help=f"robot of every task ({', '.join(tasks.robots.names())}; default gripper: the robot of the "
                      "committed results)")
  p.add_argument("--episodes", type=int, default=64, help="episodes per policy in the compiled batch")
  a = p.parse_args(argv)
  tasks.check_robot(a.robot, (), "--robot")
  names = tasks.select(None, a.robot) if a.tasks is None else [n for n in a.tasks.split(",") if n]
  for n in names:
    tasks.task_class(n)  # ValueError listing the valid names, before anything compiles
  tasks.check_robot(a.robot, names, "--robot")
  if a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  command = "PYTHONPATH=. .venv/bin/python benchmarks/compile_time.py " + " ".join(
      argv if argv is not None else sys.argv[1:])
  rows = []
  for n in names:
    rows.append(measure(n, a.episodes, a.robot))
    print(json.dumps(rows[-1]), flush=True)
    write(rows, command.strip(), a.robot)
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

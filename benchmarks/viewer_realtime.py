"""Does the interactive viewer keep up with real time? Its control-step rate per task, feedback on.

For every registered task (``--robot``, default the gripper), ``mjx-damage view``'s loop
(:func:`apps.viewer.app.run`) runs the task's scripted unsafe policy (so
health falls, the tint changes and the panel is redrawn) with damage feedback
on, unpaced (``realtime=False``), on a private Xvfb screen (software OpenGL;
shadows and reflections off, as ``--headless`` runs). Each control step is
timed from the policy's action to ``viewer.sync()``: the native physics with
temperature, liquid and damage at every substep, the task's step, tint, liquid
spheres and the health panel (drawn on its own thread; the viewer's render
thread runs beside it). The first ``--warmup`` steps (compilation) are left out.

``realtime_factor`` = control period / mean step wall time: ≥ 1 means the
viewer shows the simulation at least as fast as it happens (paced to wall
clock it then holds 1×). On a shared CPU other processes and the software
renderer (which draws as fast as it can under Xvfb) preempt the loop, so each
row records the machine's load average, and ``realtime_factor_cpu`` = control
period / mean CPU time of the loop's thread per step (the panel is drawn on
another thread, once per rendered frame; XLA may run a jitted call on its own
threads, not counted here). ``native_*`` (feedback-on rows): the same policy
and native step without the viewer, process CPU time over all threads per
step — what the simulation needs whatever else runs.

    python benchmarks/viewer_realtime.py                   # all tasks, 150 steps each
    python benchmarks/viewer_realtime.py --tasks pour_water --steps 40   # smoke
    python benchmarks/viewer_realtime.py --robot panda     # every task the Panda runs

Writes ``benchmarks/results/viewer_realtime_<device>.{json,md}`` (``--out-dir``; ``--robot`` other than the
gripper: ``viewer_realtime_<robot>_<device>``, the robot in the metadata).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shlex
import sys
import time

import jax
import mujoco
import numpy as np

import tasks
from apps.viewer import app
from apps.viewer import display as X
from apps.viewer import native_env as N
from mjx_damage import io, runtime


def native_only(env, steps: int, warmup: int) -> dict:
  """The same policy and native step without the viewer: wall and process CPU time (all threads) per step."""
  nat = N.make(env)
  data = mujoco.MjData(nat.model)
  policy = jax.jit(tasks.scripted_policy(env, "unsafe"))
  state = N.reset(nat, data, jax.random.PRNGKey(0))
  for k in range(steps + warmup):
    if k == warmup:
      jax.block_until_ready(state)
      t0, c0 = time.perf_counter(), time.process_time()
    state = N.step(nat, data, state, np.asarray(policy(state, jax.random.PRNGKey(k))))
  jax.block_until_ready(state)
  wall, cpu = (time.perf_counter() - t0) / steps, (time.process_time() - c0) / steps
  return {"native_step_ms": round(1000 * wall, 2), "native_step_cpu_ms": round(1000 * cpu, 2),
          "native_realtime_factor_cpu": round(env.dt / cpu, 2)}


def measure(name: str, steps: int, warmup: int, feedback: bool, robot: str = "gripper") -> dict:
  env = tasks.make(name, robot=robot)
  native = native_only(env, steps, warmup) if feedback else {}
  load0 = os.getloadavg()[0]
  t0 = time.perf_counter()
  res = app.run(env, name, policy=tasks.scripted_policy(env, "unsafe"), label="scripted:unsafe",
                feedback=feedback, episode_length=steps + warmup, steps=steps + warmup, realtime=False,
                plain=True, log=lambda m: None)
  step_s = np.asarray(res["step_s"][warmup:])
  cpu_s = np.asarray(res["step_cpu_s"][warmup:])
  return {
      "task": name, "feedback": feedback, "steps_timed": int(step_s.size), "control_dt_s": env.dt,
      "step_ms_mean": round(1000 * float(step_s.mean()), 2), "step_ms_median": round(1000 * float(np.median(step_s)), 2),
      "step_ms_p90": round(1000 * float(np.percentile(step_s, 90)), 2),
      "step_cpu_ms_mean": round(1000 * float(cpu_s.mean()), 2),
      "realtime_factor": round(env.dt / float(step_s.mean()), 2),
      "realtime_factor_cpu": round(env.dt / float(cpu_s.mean()), 2),
      "realtime_factor_median": round(env.dt / float(np.median(step_s)), 2),
      "final_health": {k: round(v, 1) for k, v in res["final_health"].items()},
      "load_avg_1min": [round(load0, 2), round(os.getloadavg()[0], 2)],
      "wall_s_incl_compile": round(time.perf_counter() - t0, 1), **native,
  }


def markdown(rows: list, meta: dict) -> str:
  lines = [f"# Viewer real-time factor ({meta['device']})", "",
           f"`{meta['command']}` — {meta['date']}; {meta['cpu_count']} CPU cores, shared (load average per task "
           "below). Each step: policy, native physics with temperature/liquid/damage at every substep, task "
           "step, tint, liquid, health panel, `viewer.sync()`; Xvfb + software OpenGL, no shadows.", "",
           "| task | feedback | control dt (ms) | step wall mean (ms) | median (ms) | p90 (ms) | step CPU mean (ms) | "
           "real-time factor (wall mean) | (wall median) | (CPU) | native step, no viewer: CPU ms (all threads) | "
           "(real-time factor) | load avg 1 min |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
  for r in rows:
    lines.append(f"| {r['task']} | {'on' if r['feedback'] else 'off'} | {1000 * r['control_dt_s']:.0f} | "
                 f"{r['step_ms_mean']} | {r['step_ms_median']} | {r['step_ms_p90']} | {r['step_cpu_ms_mean']} | "
                 f"{r['realtime_factor']} | {r['realtime_factor_median']} | {r['realtime_factor_cpu']} | "
                 f"{r.get('native_step_cpu_ms', '')} | {r.get('native_realtime_factor_cpu', '')} | "
                 f"{r['load_avg_1min'][0]}–{r['load_avg_1min'][1]} |")
  lines += ["", "Real-time factor = control period / step time (≥ 1: the viewer keeps up with simulated time); "
            "wall: as measured on this (shared) machine; CPU: the loop thread's own CPU time per step."]
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  ap.add_argument("--tasks", default=None, help="comma-separated task names (default: every task --robot runs)")
  ap.add_argument("--steps", type=int, default=150, help="timed control steps per task")
  ap.add_argument("--warmup", type=int, default=10, help="untimed first steps (compilation)")
  ap.add_argument("--no-feedback-too", action="store_true", help="also measure with feedback off")
  ap.add_argument("--out-dir", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results"))
  ap.add_argument("--robot", default="gripper",
                  help=f"robot of every task, one of {', '.join(tasks.robots.names())} (default: gripper, "
                       "the robot of the committed results)")
  args = ap.parse_args(argv)
  names = [n for n in args.tasks.split(",") if n] if args.tasks is not None else None
  for n in names or ():
    if n not in tasks.names():
      ap.error(f"tasks: unknown task {n!r}; valid: {', '.join(tasks.names())}")
  try:
    tasks.check_robot(args.robot, names or (), "--robot")
  except ValueError as e:
    ap.error(str(e))
  names = names if names is not None else tasks.select(None, args.robot)
  if X.xvfb_path() is None:
    print("viewer_realtime: needs Xvfb (apt-get install xvfb)", file=sys.stderr)
    return 1
  slug, device = runtime.device_info()
  rows = []
  with X.virtual_display() as _:
    for n in names:
      for fb in (True, False) if args.no_feedback_too else (True,):
        r = measure(n, args.steps, args.warmup, fb, args.robot)
        print(r, flush=True)
        rows.append(r)
  meta = {"device": device, "cpu_count": os.cpu_count(), "platform": platform.platform(),
          "command": "python benchmarks/viewer_realtime.py " + shlex.join(argv if argv is not None else sys.argv[1:]),
          "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}
  robot = "" if args.robot == "gripper" else f"{args.robot}_"  # gripper: the committed results' names and fields
  if robot:
    meta["robot"] = args.robot
  base = os.path.join(args.out_dir, f"viewer_realtime_{robot}{slug}")
  io.write_json(base + ".json", {"meta": meta, "rows": rows})
  io.write_text(base + ".md", markdown(rows, meta))
  print(f"wrote {base}.json, {base}.md")
  return 0


if __name__ == "__main__":
  sys.exit(main())

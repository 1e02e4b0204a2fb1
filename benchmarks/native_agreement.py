"""Native MuJoCo vs MJX health on the same actions, every task: how far the viewer's path is from training's.

For each registered task, the scripted ``--policy`` style runs one episode on
MJX (``env.step``, jitted) and its actions are replayed open-loop through
:mod:`apps.viewer.native_env` (the task's own step on native MuJoCo with
:func:`mjx_damage.native.step`). Per entity: final health on both paths, the
control step at which health first falls below 95 and below 50 on each, and
the largest per-step health gap. ``tests/test_native_agreement.py`` checks
three of these tasks (one per damage model); this table shows all of them,
including where the two simulators part (long jams, where damage grows with
the contact force above a threshold and amplifies the solvers' small
differences in static force).

    python benchmarks/native_agreement.py                  # every task, its episode length
    python benchmarks/native_agreement.py --tasks pick_egg --steps 30
    python benchmarks/native_agreement.py --robot panda     # every task the Panda runs

Writes ``benchmarks/results/native_agreement_<device>.{json,md}`` (``--out-dir``; ``--robot`` other than the
gripper: ``native_agreement_<robot>_<device>``, the robot in the metadata).
"""

from __future__ import annotations

import argparse
import datetime
import os
import shlex
import sys

import jax
import mujoco
import numpy as np

import tasks
from apps.viewer import native_env as N
from mjx_damage import io, runtime


def _first_below(h: np.ndarray, level: float) -> list:
  below = h < level
  return [int(i) if b else None for i, b in zip(below.argmax(0), below.any(0))]


def compare(name: str, style: str, steps: int | None, robot: str = "gripper") -> dict:
  env = tasks.make(name, robot=robot)
  steps = steps or env.unwrapped.episode_length
  policy, step = jax.jit(tasks.scripted_policy(env, style)), jax.jit(env.step)
  s = jax.jit(env.reset)(jax.random.PRNGKey(0))
  actions, h_mjx = [], []
  for k in range(steps):
    a = policy(s, jax.random.PRNGKey(k))
    s = step(s, a)
    actions.append(np.asarray(a))
    h_mjx.append(np.asarray(s.info["entity_health"]))
  nat = N.make(env)
  data = mujoco.MjData(nat.model)
  sn = N.reset(nat, data, jax.random.PRNGKey(0))
  h_nat = []
  for a in actions:
    sn = N.step(nat, data, sn, a)
    h_nat.append(np.asarray(sn.info["entity_health"]))
  h_mjx, h_nat = np.array(h_mjx), np.array(h_nat)
  names = env.entity_names
  return {
      "task": name, "policy": f"scripted:{style}", "steps": steps,
      "final_mjx": dict(zip(names, np.round(h_mjx[-1], 1).tolist())),
      "final_native": dict(zip(names, np.round(h_nat[-1], 1).tolist())),
      "final_gap_max": round(float(np.abs(h_mjx[-1] - h_nat[-1]).max()), 1),
      "below95_mjx": dict(zip(names, _first_below(h_mjx, 95.0))), "below95_native": dict(zip(names, _first_below(h_nat, 95.0))),
      "below50_mjx": dict(zip(names, _first_below(h_mjx, 50.0))), "below50_native": dict(zip(names, _first_below(h_nat, 50.0))),
      "step_gap_max": round(float(np.abs(h_mjx - h_nat).max()), 1),
  }


def markdown(rows: list, meta: dict) -> str:
  lines = [f"# Native MuJoCo vs MJX: health on the same actions ({meta['device']})", "",
           f"`{meta['command']}` — {meta['date']}. Scripted policy on MJX, its actions replayed on native MuJoCo "
           "(the viewer's path). Health 0-100; steps are control steps (first step below the level, - never).", "",
           "| task | policy | steps | entity | final MJX | final native | below 95 at (MJX / native) | "
           "below 50 at (MJX / native) |", "|---|---|---|---|---|---|---|---|"]
  fmt = lambda x: "-" if x is None else str(x)
  for r in rows:
    for e in r["final_mjx"]:
      lines.append(f"| {r['task']} | {r['policy']} | {r['steps']} | {e} | {r['final_mjx'][e]} | {r['final_native'][e]} | "
                   f"{fmt(r['below95_mjx'][e])} / {fmt(r['below95_native'][e])} | "
                   f"{fmt(r['below50_mjx'][e])} / {fmt(r['below50_native'][e])} |")
  lines += ["", "Largest per-step health gap per task: " + ", ".join(f"{r['task']} {r['step_gap_max']}" for r in rows)]
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  ap.add_argument("--tasks", default=None, help="comma-separated (default: every task --robot runs)")
  ap.add_argument("--policy", default="unsafe", choices=("safe", "unsafe"))
  ap.add_argument("--steps", type=int, default=None, help="control steps (default: each task's episode length)")
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
  rows = []
  for n in names:
    rows.append(compare(n, args.policy, args.steps, args.robot))
    print(rows[-1], flush=True)
  slug, device = runtime.device_info()
  meta = {"device": device, "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
          "command": "python benchmarks/native_agreement.py " + shlex.join(argv if argv is not None else sys.argv[1:])}
  robot = "" if args.robot == "gripper" else f"{args.robot}_"  # gripper: the committed results' names and fields
  if robot:
    meta["robot"] = args.robot
  base = os.path.join(args.out_dir, f"native_agreement_{robot}{slug}")
  io.write_json(base + ".json", {"meta": meta, "rows": rows})
  io.write_text(base + ".md", markdown(rows, meta))
  print(f"wrote {base}.json, {base}.md")
  return 0


if __name__ == "__main__":
  sys.exit(main())

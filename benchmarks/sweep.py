"""Committed evaluation sweep: ``python benchmarks/sweep.py --device cpu|gpu``.

Runs ``mjx-damage sweep`` (:mod:`train.sweep`) over every registered task with
the scripted safe/unsafe policies, several seeds and fragility levels, and
writes ``benchmarks/results/sweep_<device>.json`` and ``.md``. The CPU setting
is small (few episodes) to fit the 2-core machine; the GPU one is the
paper-style table. Extra arguments pass through (later ones win). ``--robot``
(default the gripper, the committed results' robot) runs every task with that
robot and writes ``sweep_<robot>_<device>.*``.
"""

from __future__ import annotations

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

ROBOT = "gripper"  # the committed results' robot; tasks.robots.DEFAULT may differ
SETTINGS = {
    "cpu": ["--seeds", "0,1", "--fragility", "0.5,1,2,4", "--episodes", "8"],
    "gpu": ["--seeds", "0,1,2", "--fragility", "0.25,0.5,1,2,4,8", "--episodes", "256"],
}


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  ap.add_argument("--device", choices=sorted(SETTINGS), required=True)
  ap.add_argument("--tasks", default=None, help="comma-separated tasks (default: every task --robot runs)")
  ap.add_argument("--robot", default=ROBOT,
                  help=f"robot of every task, one of tasks.robots.names() (default {ROBOT}, the robot of the "
                       "committed results)")
  args, extra = ap.parse_known_args(argv)
  if args.device == "cpu":
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
  import tasks

  try:
    tasks.check_robot(args.robot, (), "--robot")
  except ValueError as e:
    ap.error(str(e))
  task_list = args.tasks or ",".join(tasks.select(None, args.robot))
  from apps import sweep_cli

  name = "sweep_" + ("" if args.robot == ROBOT else args.robot + "_") + args.device
  out = os.path.join(HERE, "results", name + ".json")
  # always named: mjx-damage sweep's own default is tasks.robots.DEFAULT, the Panda (committed sweeps from
  # before the switch name no robot and ran the gripper)
  return sweep_cli.main(["--tasks", task_list, "--policies", "scripted:safe,scripted:unsafe", "--robot", args.robot]
                        + SETTINGS[args.device] + ["--out", out, "--overwrite"] + extra)


if __name__ == "__main__":
  sys.exit(main())

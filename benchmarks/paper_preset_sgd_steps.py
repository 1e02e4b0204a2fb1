"""How many SGD steps the paper's PPO settings take per iteration, in either normaliser order (CPU size).

The paper preset (train/config.py ``_PAPER``) stops an iteration's epochs once the update's KL passes
1.5 × 0.01. This script trains it on Place Plate (the RL setting: paper observation, in-hand start) for a
few iterations at a CPU size, once with the observation statistics updated before the epochs (brax's
order) and once after them (SB3's, ``normalizer_after_update``, the preset's default now), and writes per
iteration: the SGD steps taken of the 80, the update's own KL and brax's KL between the policy and the
logits the rollout recorded, both before the first step when only that step is taken.

    python benchmarks/paper_preset_sgd_steps.py [--envs 32] [--iterations 4] [--out benchmarks/results/paper_preset_sgd_steps_cpu.md]

``--robot`` (default the gripper, the committed results' robot): another robot's default ``--out`` is
``paper_preset_sgd_steps_<robot>_cpu.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--envs", type=int, default=32, help="envs per iteration (the preset's 512-step rollouts)")
  p.add_argument("--iterations", type=int, default=4)
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--out", default=None, help="default benchmarks/results/paper_preset_sgd_steps_cpu.md "
                 "(another --robot: paper_preset_sgd_steps_<robot>_cpu.md)")
  p.add_argument("--robot", default="gripper",
                 help="robot of the task (tasks.robots.names(); default: gripper, the robot of the committed results)")
  a = p.parse_args(argv)
  import tasks  # checked before anything compiles; the gripper is passed explicitly (DEFAULT may change)

  try:
    tasks.check_robot(a.robot, ["place_plate"], "--robot")
  except ValueError as e:
    p.error(str(e))
  if a.out is None:
    robot = "" if a.robot == "gripper" else f"{a.robot}_"  # gripper: the committed results' name
    a.out = os.path.join(ROOT, "benchmarks", "results", f"paper_preset_sgd_steps_{robot}cpu.md")
  if a.envs < 8 or a.envs % 8:
    p.error(f"--envs: a positive multiple of 8 (the preset's 8 minibatches), got {a.envs}")
  if a.iterations < 1:
    p.error(f"--iterations: must be >= 1, got {a.iterations}")
  return a


def run(order_after: bool, a) -> list[dict]:
  import tasks
  import train

  steps = a.envs * 512
  task_kwargs = {**tasks.rl_settings("place_plate"), "robot": a.robot}
  res = train.train("place_plate", task_kwargs=task_kwargs, preset="paper", seed=a.seed,
                    num_envs=a.envs, num_timesteps=a.iterations * steps, eval_every=steps, num_eval_envs=8,
                    normalizer_after_update=order_after, progress=False)
  return [{k: r[k] for k in ("iteration", "env_steps", "sgd_steps", "loss/kl_update", "loss/kl_mean")}
          for r in res.history]


def main(argv=None) -> int:
  a = parse(sys.argv[1:] if argv is None else argv)
  import jax

  from mjx_damage import io, runtime

  t0 = time.time()
  results = {"brax order (statistics updated before the epochs)": run(False, a),
             "SB3 order (normalizer_after_update, the preset's default)": run(True, a)}
  cmd = "python benchmarks/paper_preset_sgd_steps.py " + " ".join(sys.argv[1:] if argv is None else argv)
  lines = ["# The paper preset's SGD steps per iteration, by normaliser order", "",
           f"Command: `{cmd.strip()}` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {runtime.device_info()[1]}, "
           f"jax {jax.__version__}, {time.time() - t0:.0f} s). Place Plate in its RL setting, preset paper, "
           f"{a.envs} envs × 512-step rollouts, seed {a.seed}.", "",
           "`sgd_steps`: SGD steps the iteration took of its 80 (10 epochs × 8 minibatches; target KL 0.01 stops "
           "them once the update's KL passes 0.015). `kl_update`: the update's own KL before each step taken "
           "(train/iteration.py `Trainer._update_kl`); `kl_mean`: brax's KL between the policy and the logits the "
           "rollout recorded, the quantity the rule compared before 2026-11-27. Both are averaged over the steps "
           "taken, so with one step they are the values before it.", ""]
  for name, rows in results.items():
    lines += [f"## {name}", "", "| iteration | env steps | sgd_steps | kl_update | kl_mean (vs rollout logits) |",
              "|---|---|---|---|---|"]
    lines += [f"| {r['iteration']} | {r['env_steps']:,} | {r['sgd_steps']:.0f} | {r['loss/kl_update']:.4f} "
              f"| {r['loss/kl_mean']:.4g} |" for r in rows]
    lines.append("")
  io.write_text(a.out, "\n".join(lines))
  print("\n".join(lines))
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

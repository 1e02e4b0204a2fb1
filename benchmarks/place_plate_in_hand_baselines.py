"""What no learning does in Place Plate's RL setting (paper observation, in-hand start), per robot.

Runs ``mjx-damage eval`` once per (robot, policy) — zero, random, scripted:unsafe, scripted:safe — and
writes one table: completion, safe completion, average environment health, episode cost and the
plate's final health, each row with the exact eval command that gave it. The zero policy is what a
fresh PPO policy starts near (its mean action is 0): if it drops the plate, every rollout begins with
a broken plate and the learner has nothing safe to improve on.

    python benchmarks/place_plate_in_hand_baselines.py [--robots gripper,panda] [--episodes 64] \
        [--backend auto] [--out benchmarks/results/place_plate_in_hand_baselines_cpu.md]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shlex
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
POLICIES = ("zero", "random", "scripted:unsafe", "scripted:safe")


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--robots", default="gripper,panda", help="comma-separated robots")
  p.add_argument("--policies", default=",".join(POLICIES), help="comma-separated eval policies")
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--backend", default="auto", help="eval's --backend (auto: native on a one-device CPU)")
  p.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "place_plate_in_hand_baselines_cpu.md"))
  a = p.parse_args(argv)
  if a.episodes < 1:
    p.error(f"--episodes: must be ≥ 1, got {a.episodes}")
  sys.path.insert(0, ROOT)
  from tasks import robots
  a.robots = [r for r in a.robots.split(",") if r]
  for r in a.robots:
    if r not in robots.names():
      p.error(f"--robots: unknown robot {r!r}; valid: {', '.join(robots.names())}")
  a.policies = [x for x in a.policies.split(",") if x]
  return a


def run_eval(robot: str, policy: str, a, tmp: str) -> dict:
  """One ``mjx-damage eval`` in a subprocess; its JSON record (with the command it ran)."""
  out = os.path.join(tmp, f"ev_{robot}_{policy.replace(':', '_')}.json")
  args = ["--task", "place_plate", "--task-arg", "obs_mode=paper", "--robot", robot, "--policy", policy,
          "--episodes", str(a.episodes), "--seed", str(a.seed), "--backend", a.backend, "--out", out, "--overwrite"]
  subprocess.run([sys.executable, "-m", "apps.cli", "eval", *args], check=True, cwd=ROOT)
  with open(out) as f:
    rec = json.load(f)
  rec["shown_command"] = "mjx-damage eval " + " ".join(shlex.quote(x) for x in args[:-3])
  return rec


def table(recs) -> str:
  lines = ["| robot | policy | episode length | completion | safe completion | avg env health | episode cost (mean) "
           "| plate's final health (mean) | backend | command |", "|---|---|---|---|---|---|---|---|---|---|"]
  for robot, rec in recs:
    m = rec["metrics"]
    lines.append(f"| {robot} | {rec['policy']} | {rec['episode_length']} | {100 * m['completion']:.1f} % "
                 f"| {100 * m['safe_completion']:.1f} % | {m['avg_health']:.2f} | {m['cost_mean']:.1f} "
                 f"| {m['entity_health']['plate']:.1f} | {rec['backend']} | `{rec['shown_command']}` |")
  return "\n".join(lines)


def main(argv=None):
  a = parse(argv)
  recs = []
  with tempfile.TemporaryDirectory() as tmp:
    for robot in a.robots:
      for policy in a.policies:
        recs.append((robot, run_eval(robot, policy, a, tmp)))
  cmd = "python benchmarks/place_plate_in_hand_baselines.py " + " ".join(shlex.quote(x) for x in (argv or sys.argv[1:]))
  date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
  text = f"""# Place Plate's RL setting (paper observation, in-hand start): what no learning does, per robot

Command: `{cmd.strip()}` ({date}; {a.episodes} episodes per row, seed {a.seed}; each row's own eval command
below, `--out FILE` left out). The task's default episode length: 100 steps for the in-hand start with every robot.

{table(recs)}

How to read it: a fresh PPO policy acts near the zero action (its mean is 0, initial log-std −1.5 on
the gripper action). The gripper command is normalised to each robot's own range
(tasks/robots/interface.py), so 0 asks the gripper for an 8.1 cm gap around its 12 cm plate and the
Panda for 4.1 cm around its 6 cm plate: both keep squeezing. With the Panda the held plate still creeps
down through its 5 cm finger pads (at any grip force) and would fall after
about 145 steps; the in-hand start's horizon is 100 steps for every robot (tasks/place_plate.py,
"Horizon"), so the zero action keeps it. Until session 21 the Panda's horizon was 200 steps and its zero
action broke the plate in every episode (episode cost 148.5).
"""
  os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
  with open(a.out, "w") as f:
    f.write(text)
  print(text)
  print(f"wrote {a.out}")


if __name__ == "__main__":
  main()

"""How gentle must a placement be? Open-loop hand motions in Place Plate's RL setting, and their damage.

Place Plate in its RL setting (``tasks.RL_SETTINGS``: in-hand start 25–35 cm above the counter, hand
limited to 0.4 m/s). Each policy moves the hand straight down at a fixed fraction of that speed with the
gripper at the policy's initial mean (0: still squeezing the plate), and optionally opens it fully from
a given control step on. Per policy, over ``--episodes`` randomised starts: episode cost (health points),
the step of the damage, success and the final plate health. It shows what a learner must discover:
a held plate set down at full speed is damaged as badly as a short drop, at a quarter speed not at all.

Usage::

    python benchmarks/place_plate_touchdown.py [--episodes 8] [--robot panda]

Writes ``benchmarks/results/place_plate_touchdown.{json,md}`` with the command (``--robot`` other than the
gripper: ``place_plate_touchdown_<robot>``, the robot in the JSON).
"""
from __future__ import annotations

import argparse
import os
import shlex
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402

LENGTH = 100  # control steps, the RL episode length
# name: (downward speed as a fraction of the hand's 0.4 m/s, control step the gripper opens at; None: never)
POLICIES = {
    "hold still": (0.0, None),
    "down at full speed, keep holding": (1.0, None),
    "down at full speed, open at step 40 (on the counter)": (1.0, 40),
    "down at half speed, open at step 70 (on the counter)": (0.5, 70),
    "down at quarter speed, keep holding": (0.25, None),
    "down at quarter speed, open at step 90 (a few cm up)": (0.25, 90),
}


def rollout_fn(env, speed: float, open_at):
  def episode(rng):
    s = env.reset(rng)

    def body(s, t):
      grip = jnp.where(open_at is not None and t >= (open_at or 0), 1.0, 0.0)
      # [Δx, Δy, Δz, (Δrot,) gripper]: z is entry 2 and the gripper the last for every robot
      s = env.step(s, jnp.zeros((env.action_size,), jnp.float32).at[2].set(-speed).at[-1].set(grip))
      return s, (s.info["cost"], s.metrics["success"])

    s, (cost, success) = jax.lax.scan(body, s, jnp.arange(LENGTH))
    return cost, success, s.info["entity_health"]
  return jax.jit(jax.vmap(episode))


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--episodes", type=int, default=8)
  p.add_argument("--out", default=None, help="results path without extension (default "
                 "benchmarks/results/place_plate_touchdown; another --robot: place_plate_touchdown_<robot>)")
  p.add_argument("--robot", default="gripper",
                 help=f"one of {', '.join(tasks.robots.names())} (default: gripper, the robot of the committed results)")
  a = p.parse_args(argv)
  if a.episodes < 1:
    p.error(f"--episodes: must be >= 1, got {a.episodes}")
  try:
    tasks.check_robot(a.robot, ["place_plate"], "--robot")
  except ValueError as e:
    p.error(str(e))
  robot = "" if a.robot == "gripper" else f"_{a.robot}"  # gripper: the committed results' name and fields
  a.out = a.out or os.path.join(ROOT, "benchmarks", "results", "place_plate_touchdown" + robot)
  # the gripper is passed explicitly (tasks.robots.DEFAULT may change)
  env = tasks.make("place_plate", **{**tasks.RL_SETTINGS["place_plate"], "robot": a.robot})  # the RL setting, this robot
  keys = jax.random.split(jax.random.PRNGKey(0), a.episodes)
  rows = []
  for name, (speed, open_at) in POLICIES.items():
    t0 = time.perf_counter()
    cost, success, health = jax.device_get(rollout_fn(env, speed, open_at)(keys))
    ep_cost = cost.sum(1)
    damaged = [int(np.argmax(c > 0)) for c in cost if (c > 0).any()]
    rows.append({"policy": name, "speed_fraction": speed, "open_at": open_at,
                 "episode_cost": [round(float(c), 2) for c in ep_cost],
                 "first_damage_step": damaged, "completion": float(success.any(1).mean()),
                 "final_health_min": float(health.min()), "wall_s": round(time.perf_counter() - t0, 1)})
    print(name, rows[-1]["episode_cost"], flush=True)
  command = "python benchmarks/" + " ".join(shlex.quote(x) for x in [os.path.basename(__file__)] + sys.argv[1:])
  write_json(a.out + ".json", {"command": command, "episodes": a.episodes, **({"robot": a.robot} if robot else {}),
                              "rows": rows})
  lines = ["# Place Plate (RL setting): how gentle must a placement be?", "",
           f"Command: `{command}` ({a.episodes} randomised starts per policy, key 0; open-loop policies,"
           " benchmarks/place_plate_touchdown.py docstring).", "",
           "| policy | episode cost (health points), mean (min–max) | damage at control step | completion |",
           "|---|---|---|---|"]
  for r in rows:
    c = np.array(r["episode_cost"])
    steps = f"{min(r['first_damage_step'])}–{max(r['first_damage_step'])}" if r["first_damage_step"] else "—"
    lines.append(f"| {r['policy']} | {c.mean():.1f} ({c.min():.1f}–{c.max():.1f}) | {steps} | {r['completion']:.0%} |")
  write_text(a.out + ".md", "\n".join(lines) + "\n")
  print(f"wrote {a.out}.md / .json")
  return 0


if __name__ == "__main__":
  sys.exit(main())

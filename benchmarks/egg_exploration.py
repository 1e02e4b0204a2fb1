"""How often does PPO's exploration lift the egg? Pick Egg's carry under the sampled actions of a policy that has
not found the lift yet.

Every RL run on the pre-grasp start (docs/rl_task_design.md, "Pick Egg: training on `held`") first learns to
close the pads to the shell and keep still, and most never leave it. This benchmark measures what exploration
around that point finds: per-step actions ``tanh(u)``, ``u ~ N(μ, σ²)`` per dimension, independent over steps
(what PPO's rollouts sample), with the arm's mean 0 and σ = e^-0.5 (the RL runs' initial arm std) and the
gripper's mean at command 0 (an untrained policy: the fingers open, 8.1 cm) or at the shell (the command whose target
gap is the egg's width, where the runs settle), its σ = e^-1.5 or e^0. Per setting, on the same N randomised
episodes: the share of episodes whose egg ever rose ≥ 1 mm, ≥ 8 mm (what ``carry_reward="held"`` counts as held)
and ≥ 3 cm off the counter, whose egg lost health (> 5 points: crushed or dropped), and the mean of each episode's
highest egg.

Writes ``benchmarks/results/egg_exploration[_<tag>].{json,md}`` with the command.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/egg_exploration.py --episodes 1024
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags and the jax compat shim before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)
import tasks  # noqa: E402
from tasks import pick_egg as P  # noqa: E402
from tasks import robot as R  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
DEFAULT_SETTINGS = {"start": "pregrasp", "carry_reward": "held"}
ARM_LOG_STD = -0.5
RISES = (0.001, 0.008, 0.03)  # m above the egg's resting height
LOST_HEALTH = 5.0  # health points: the egg was crushed or dropped


def run(episodes: int, grip_means: dict, grip_log_stds, seed: int, settings: dict) -> dict:
  env = tasks.make("pick_egg", **settings)
  task = env.unwrapped
  size, length = env.action_size, task.episode_length

  @jax.jit
  def rollouts(rngs, grip_mean, grip_log_std):
    mean = jnp.zeros((size,), jnp.float32).at[-1].set(jnp.arctanh(grip_mean))
    std = jnp.full((size,), math.exp(ARM_LOG_STD), jnp.float32).at[-1].set(jnp.exp(grip_log_std))

    def episode(rng):
      r0, rp = jax.random.split(rng)
      state = env.reset(r0)

      def body(s, k):
        s = env.step(s, jnp.tanh(mean + std * jax.random.normal(k, (size,))))
        return s, task.egg_pos(s.pipeline_state)[2]

      state, z = jax.lax.scan(body, state, jax.random.split(rp, length))
      return z.max(), state.info["entity_health"][0]

    return jax.vmap(episode)(rngs)

  rngs = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the same episodes for every setting
  rows = []
  for name, gm in grip_means.items():
    for ls in grip_log_stds:
      top, health = (np.asarray(x, np.float64) for x in jax.device_get(rollouts(rngs, jnp.float32(gm), jnp.float32(ls))))
      rise = top - P.EGG_R
      row = {"gripper_mean": name, "gripper_mean_command": gm, "gripper_log_std": ls, "episodes": episodes,
             "mean_highest_rise_mm": 1000 * float(rise.mean()),
             "egg_health_lost_pct": 100 * float((health < 100.0 - LOST_HEALTH).mean())}
      row.update({f"rose_{1000 * r:g}mm_pct": 100 * float((rise >= r).mean()) for r in RISES})
      rows.append(row)
      print(row, flush=True)
  return {"task": "pick_egg", "settings": settings, "episode_length": length, "arm_log_std": ARM_LOG_STD, "rows": rows}


def render_md(res: dict) -> str:
  rises = " | ".join(f"egg rose ≥ {1000 * r:g} mm" for r in RISES)
  lines = ["# Pick Egg: how often does exploration lift the egg?", "",
           f"Command: `{res['command']}`  ",
           f"jax {res['jax']} on {res['backend']}, {res['date']}, git {res['git']}. Settings {res['settings']}, "
           f"{res['episode_length']} control steps.", "",
           f"Actions tanh(u), u ~ N(μ, σ²) per dimension and step: arm μ 0, log σ {res['arm_log_std']:g}; the "
           "gripper's μ and log σ per row. Shares of episodes (the same reset keys for every row).", "",
           f"| gripper mean (command) | gripper log-std | {rises} | egg lost > {LOST_HEALTH:g} health "
           "| mean highest rise (mm) |", "|---|---|" + "---|" * len(RISES) + "---|---|"]
  for r in res["rows"]:
    cells = " | ".join(f"{r[f'rose_{1000 * x:g}mm_pct']:.2f} %" for x in RISES)
    lines.append(f"| {r['gripper_mean']} ({r['gripper_mean_command']:+.3f}) | {r['gripper_log_std']:g} | {cells} "
                 f"| {r['egg_health_lost_pct']:.2f} % | {r['mean_highest_rise_mm']:.2f} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--episodes", type=int, default=1024)
  p.add_argument("--grip-log-stds", default="-1.5,0",
                 help="the gripper's log-stds, comma-separated, each in [-5, 2] (--grip-log-stds=-1.5,0)")
  p.add_argument("--task-settings", default=json.dumps(DEFAULT_SETTINGS), metavar="JSON",
                 help="pick_egg keyword arguments over its RL setting (tasks.RL_SETTINGS)")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--tag", default="", help="file-name suffix: egg_exploration_<tag>")
  p.add_argument("--results-dir", default=RESULTS)
  a = p.parse_args(argv)
  if isinstance(a.episodes, bool) or a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  try:
    stds = [float(x) for x in a.grip_log_stds.split(",") if x.strip()]
  except ValueError:
    stds = []
  if not stds or not all(-5.0 <= x <= 2.0 for x in stds):  # also refuses NaN
    raise ValueError(f"grip_log_stds: comma-separated numbers in [-5, 2], got {a.grip_log_stds!r}")
  settings = tasks.rl_settings("pick_egg", a.task_settings)
  if settings.get("goal") != "carry" or settings.get("start") != "pregrasp":
    raise ValueError(f"task_settings: the carry from the pre-grasp start (goal='carry', start='pregrasp'), got {settings}")
  robot = tasks.make("pick_egg", **settings).unwrapped.robot
  grip_means = {"untrained (open)": 0.0, "at the shell": float(R.gripper_command_for_gap(2 * P.EGG_R, robot))}
  res = run(a.episodes, grip_means, stds, a.seed, settings)
  stem = os.path.join(a.results_dir, "egg_exploration" + (f"_{a.tag}" if a.tag else ""))
  provenance.save_results(res, "egg_exploration", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

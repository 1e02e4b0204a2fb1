"""Per-episode trace of a task's scripted policies with one robot: why a policy fails, step by step.

Runs ``--episodes`` randomised episodes of each scripted style (one compiled
``jit(vmap(scan))``, persistent compile cache allowed) and prints, per episode,
whether the success condition ever held and each entity's final health; for the
first episode of each style, every ``--every`` control steps: grip point (m),
finger gap (m), action, success, entity health and the first 6 task observations
(object poses …). A diagnostic, not a results file: the targets are measured by
``benchmarks/scripted_policies.py``.

Usage::

    .venv/bin/python benchmarks/scripted_trace.py place_plate --robot panda [--episodes 6] [--every 10] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
from tasks import robots  # noqa: E402

ROBOT = "gripper"  # the committed results' robot; robots.DEFAULT may differ


def trace(name: str, robot: str, episodes: int, seed: int):
  """Per-step arrays [2·episodes, T, …] (safe episodes first) and the env."""
  env = tasks.make(name, robot=robot)
  task = env.unwrapped
  pols = [tasks.scripted_policy(env, s) for s in tasks.STYLES]

  def ep(rng, which):
    r0, rp = jax.random.split(rng)
    s = env.reset(r0)

    def body(s, k):
      a = jax.lax.switch(which, pols, s, k)
      s = env.step(s, a)
      d = s.pipeline_state
      return s, (task.robot.eef_pos(d), task.robot.gap(d), a, s.metrics["success"], s.info["entity_health"],
                 task.task_obs(d, s.info)[:6])

    return jax.lax.scan(body, s, jax.random.split(rp, task.episode_length))[1]

  which = jnp.repeat(jnp.arange(len(tasks.STYLES)), episodes)
  rngs = jax.random.split(jax.random.PRNGKey(seed), which.shape[0])
  return env, [np.asarray(x) for x in jax.jit(jax.vmap(ep))(rngs, which)]


def shown_episodes(completed, per_style: int, show: str) -> set:
  """Episodes printed step by step, one per style: its first, or (``show="failed"``) its first that did not
  complete (the first if all did). ``completed``: bool[styles × per_style], styles in blocks."""
  shown = set()
  for start in range(0, len(completed), per_style):
    group = np.arange(start, start + per_style)
    failed = group[~np.asarray(completed)[group]]
    shown.add(int(group[0]) if show == "first" or not len(failed) else int(failed[0]))
  return shown


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("task")
  p.add_argument("--robot", default=ROBOT, help=f"one of {', '.join(robots.names())} (default {ROBOT})")
  p.add_argument("--episodes", type=int, default=6, help="per style")
  p.add_argument("--every", type=int, default=10, help="control steps between printed rows")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--show", choices=("first", "failed"), default="first",
                 help="which episode of each style is printed step by step: the first, or the first that fails")
  a = p.parse_args(argv)
  tasks.task_class(a.task)
  robots.robot_class(a.robot)
  if a.episodes < 1 or a.every < 1:
    raise ValueError(f"episodes/every: must be positive, got {a.episodes}/{a.every}")
  env, (eef, gap, act, succ, health, tobs) = trace(a.task, a.robot, a.episodes, a.seed)
  np.set_printoptions(precision=3, suppress=True, linewidth=200)
  print(f"{a.task} robot={a.robot} episode_length={env.unwrapped.episode_length} entities={env.entity_names}")
  shown = shown_episodes(succ.max(axis=1) > 0, a.episodes, a.show)
  for b in range(eef.shape[0]):
    style = tasks.STYLES[b // a.episodes]
    print(f"--- episode {b} {style}: completed {succ[b].max():.0f}, final health {health[b, -1]}")
    if b in shown:
      for t in range(0, eef.shape[1], a.every):
        print(f"{t:4d} eef {eef[b, t]} gap {gap[b, t]:.3f} a {act[b, t]} success {succ[b, t]:.0f} "
              f"health {health[b, t]} task_obs {tobs[b, t]}")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

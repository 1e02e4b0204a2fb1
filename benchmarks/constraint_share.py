"""How much of an articulated task's damage comes from the joint-limit constraint force?

For each articulated task (its articulation entity has ``constraint: true``), the
scripted safe and unsafe policies run N randomised episodes twice: as shipped,
and with the articulation's ``constraint`` switched off (only contact forces
load it). The articulation's mean final health and mean episode mechanical
damage of both runs are written to ``benchmarks/results/constraint_share.{md,json}``:
the difference is the damage the joint-limit force adds
(docs/DAMAGE_MODEL.md, "How a joint-limit force enters the damage model").
``--robot`` (default the gripper, the robot of the committed results) other than the
gripper writes ``constraint_share_<robot>.{md,json}``.

Usage::

    .venv/bin/python benchmarks/constraint_share.py [--episodes 64] [--tasks a,b] [--seed 0] [--robot gripper]
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

import tasks  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from mjx_damage.wrapper import DamageWrapper  # noqa: E402
from tasks.rollout import rollout_fn  # noqa: E402

RESULTS = os.path.join(os.path.dirname(__file__), "results")
ARTICULATED = ("open_single_door", "turn_on_microwave", "turn_on_faucet")
STYLES = ("safe", "unsafe")


def make(name: str, constraint: bool, robot: str = "gripper"):
  """Task ``name`` with ``robot`` wrapped for damage, its articulation's joint-limit damage on (as shipped) or off."""
  cls = tasks.task_class(name)
  if not constraint:
    entities = {k: {**v, "constraint": False} for k, v in cls.entities.items()}
    cls = type(cls.__name__ + "ContactOnly", (cls,), {"entities": entities, "__module__": cls.__module__})
  # the robot set before the constructor runs, as tasks.make does (the class default is tasks.robots.DEFAULT)
  env = cls.__new__(cls)
  env.robot_name = robot
  env.__init__()
  return DamageWrapper(env)


def run(name: str, constraint: bool, episodes: int, seed: int, robot: str = "gripper") -> list[dict]:
  env = make(name, constraint, robot)
  art = env.entity_names.index(next(iter(env.unwrapped.entities)))
  fn = rollout_fn(env, [tasks.scripted_policy(env, s) for s in STYLES], env.unwrapped.episode_length)
  which = jnp.repeat(jnp.arange(len(STYLES)), episodes)
  stats = jax.block_until_ready(fn(jax.random.split(jax.random.PRNGKey(seed), which.shape[0]), which))
  rows = []
  for i, style in enumerate(STYLES):
    sl = slice(i * episodes, (i + 1) * episodes)
    rows.append({
        "task": name, "policy": style, "constraint": constraint, "episodes": episodes,
        "articulation": env.entity_names[art],
        "articulation_health_mean": float(jnp.mean(stats.entity_health[sl, art])),
        "agent_health_mean": float(jnp.mean(stats.entity_health[sl, -1])),
        "mechanical_damage_mean": float(jnp.mean(stats.damage["mechanical"][sl])),
        "completion_pct": float(100 * jnp.mean(stats.completed[sl])),
    })
  return rows


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--tasks", default=",".join(ARTICULATED))
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--robot", default="gripper",
                 help=f"robot of every task ({', '.join(tasks.robots.names())}; default gripper: the robot of the "
                      "committed results)")
  a = p.parse_args(argv)
  names = [n for n in a.tasks.split(",") if n]
  for n in names:
    tasks.task_class(n)
  try:
    tasks.check_robot(a.robot, names, "--robot")
  except ValueError as e:
    p.error(str(e))
  command = ".venv/bin/python benchmarks/constraint_share.py " + " ".join(sys.argv[1:] if argv is None else argv)
  rows = []
  for n in names:
    for constraint in (True, False):
      rows += run(n, constraint, a.episodes, a.seed, a.robot)
      print(rows[-2], rows[-1], flush=True)
  meta = {"command": command.strip(), "jax": jax.__version__, "backend": jax.default_backend(),
          "machine": platform.processor() or platform.machine(), "date": time.strftime("%Y-%m-%d %H:%M:%S %Z")}
  # another robot's results in their own files, named in meta (the gripper's stay as committed)
  stem = "constraint_share" + ("" if a.robot == "gripper" else f"_{a.robot}")
  if a.robot != "gripper":
    meta["robot"] = a.robot
  write_json(os.path.join(RESULTS, stem + ".json"), {"meta": meta, "rows": rows})
  lines = [
      "# Joint-limit constraint damage: articulated tasks with the articulation's `constraint` on vs off",
      "",
      f"Command: `{meta['command']}` (jax {meta['jax']} on {meta['backend']}, {meta['date']}).",
      "Mean over episodes of the articulation's final health, the robot's, and the episode's mechanical damage "
      "(health points, all links). `off` = only contact forces load the articulation.",
      "",
      "| task | policy | constraint | articulation health | agent health | mechanical damage | completion % |",
      "|---|---|---|---|---|---|---|",
  ]
  for r in rows:
    lines.append(f"| {r['task']} | {r['policy']} | {'on' if r['constraint'] else 'off'} | "
                 f"{r['articulation_health_mean']:.1f} | {r['agent_health_mean']:.1f} | "
                 f"{r['mechanical_damage_mean']:.1f} | {r['completion_pct']:.1f} |")
  write_text(os.path.join(RESULTS, stem + ".md"), "\n".join(lines) + "\n")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

"""What does a trained policy do on Pick Egg's carry: lift the egg, or push it along the counter?

A PPO policy trained with task reward alone from the pre-grasp start (``goal="carry"``,
``start="pregrasp"``) completes no episode; this benchmark shows why. It rolls out a
checkpoint (``--run``, a ``mjx-damage train`` run directory) beside the zero action and the
two scripted policies, on the same reset keys, and reports per policy how high the egg
got, how close to the goal, what the gripper commanded, and the task return under each
``carry_reward`` (``distance``: the plain ``−2·‖egg − goal‖``; ``held``: only a held egg's
way to the goal pays, plus the fingers' reach, tasks/pick_egg.py). Under ``distance``
the push earns return over keeping still without ever holding the egg; under ``held``
it does not (docs/rl_task_design.md, "Pick Egg: the push").

Writes ``benchmarks/results/pick_egg_push.{json,md}`` with the command.

Usage::

    mjx-damage train --task pick_egg --robot gripper --task-arg goal='"carry"' --task-arg start='"pregrasp"' \\
        --preset playground --init-log-std=-0.5,-1.5 --timesteps 1e9 --time-limit 75 --out runs/egg_w0
    PYTHONPATH=. .venv/bin/python benchmarks/pick_egg_push.py --run runs/egg_w0 [--episodes 32]
"""

from __future__ import annotations

import argparse
import json
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
from train.policy import load_policy  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
SETTINGS = {**tasks.RL_SETTINGS["pick_egg"], "start": "pregrasp"}
GAMMA = 0.97
CONTACT_GAP = 2 * P.EGG_R  # m: a finger gap at or below this touches the shell


def run(run_dir: str, episodes: int, seed: int) -> dict:
  rows = []
  for carry_reward in P.CARRY_REWARDS:
    env = tasks.make("pick_egg", **SETTINGS, carry_reward=carry_reward)
    task = env.unwrapped
    policies = {"checkpoint": load_policy(run_dir, env=env), "zero action": lambda s, k: jnp.zeros(env.action_size),
                "scripted safe": tasks.scripted_policy(env, "safe"),
                "scripted unsafe": tasks.scripted_policy(env, "unsafe")}
    for name, policy in policies.items():
      def episode(rng, policy=policy):
        r0, rp = jax.random.split(rng)
        state = env.reset(r0)

        def body(s, k):
          s = env.step(s, policy(s, k))
          d = s.pipeline_state
          return s, (s.info["task_reward"], task.egg_pos(d), task.robot.gap(d), s.metrics["success"])

        _, out = jax.lax.scan(body, state, jax.random.split(rp, task.episode_length))
        return out + (state.info["goal"],)

      rew, egg, gap, succ, goal = (np.asarray(x, np.float64) for x in jax.device_get(
          jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(seed), episodes))))
      dist = np.linalg.norm(egg - goal[:, None], axis=-1)
      row = {"carry_reward": carry_reward, "policy": name, "episodes": episodes,
             "completion_pct": 100 * float(succ.max(axis=1).mean()),
             "egg_lifted_pct": 100 * float((egg[..., 2].max(axis=1) >= P.HELD_Z).mean()),
             "egg_max_height_m": float(egg[..., 2].max(axis=1).mean()),
             "start_distance_m": float(dist[:, 0].mean()), "min_distance_m": float(dist.min(axis=1).mean()),
             "goal_height_m": float(goal[:, 2].mean()),
             "fingers_on_shell_pct": 100 * float((gap <= CONTACT_GAP + 1e-3).mean()),
             "return": float(rew.sum(axis=1).mean()),
             f"return_gamma_{GAMMA:g}": float((rew * GAMMA ** np.arange(rew.shape[1])).sum(axis=1).mean())}
      rows.append(row)
      print(row, flush=True)
  return {"task": "pick_egg", "settings": SETTINGS, "run": os.path.abspath(run_dir), "rows": rows}


def render_md(res: dict) -> str:
  lines = ["# Pick Egg carry from the pre-grasp start: lift, or push?", "",
           f"Command: `{res['command']}`  ",
           f"jax {res['jax']} on {res['backend']}, {res['date']}, git {res['git']}. Settings {res['settings']}; "
           f"checkpoint: the run's config {res['run_config']}.", "",
           f"Same reset keys for every row. Egg lifted: its centre ≥ {P.HELD_Z * 100:.1f} cm at some step (it "
           f"rests at {P.EGG_R * 100:.1f} cm). Fingers on the shell: steps with the gap ≤ the egg's width. Returns: "
           "task reward (no damage term), undiscounted and γ = 0.97, under each `carry_reward`.", "",
           "| carry_reward | policy | completion % | egg lifted % | egg max height m | distance to goal: start / "
           "min m | goal height m | fingers on shell % of steps | return | return γ=0.97 |",
           "|---|---|---|---|---|---|---|---|---|---|"]
  for r in res["rows"]:
    lines.append(f"| {r['carry_reward']} | {r['policy']} | {r['completion_pct']:.1f} | {r['egg_lifted_pct']:.1f} "
                 f"| {r['egg_max_height_m']:.3f} | {r['start_distance_m']:.3f} / {r['min_distance_m']:.3f} "
                 f"| {r['goal_height_m']:.3f} | {r['fingers_on_shell_pct']:.1f} | {r['return']:.2f} "
                 f"| {r[f'return_gamma_{GAMMA:g}']:.2f} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--run", required=True, help="a `mjx-damage train` run directory (or its checkpoint.npz) of "
                                               "pick_egg with goal='carry', start='pregrasp'")
  p.add_argument("--episodes", type=int, default=32)
  p.add_argument("--seed", type=int, default=7)
  p.add_argument("--out", default=os.path.join(RESULTS, "pick_egg_push"), help="results stem (.json, .md)")
  a = p.parse_args(argv)
  if isinstance(a.episodes, bool) or a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  policy = load_policy(a.run)  # ValueError naming the path if there is no checkpoint, before compiling
  res = run(a.run, a.episodes, a.seed)
  cfg = {k: policy.meta["config"].get(k) for k in ("damage_weight", "init_log_std", "num_envs", "learning_rate")}
  metrics = os.path.join(a.run, "metrics.jsonl") if os.path.isdir(a.run) else ""
  if os.path.isfile(metrics):  # how far it trained: the last logged iteration's env steps
    with open(metrics) as f:
      last = [json.loads(line) for line in f if line.strip()][-1]
    cfg["env_steps_trained"] = last.get("env_steps")
  res["run_config"] = cfg
  provenance.save_results(res, "pick_egg_push", argv, a.out, render_md)
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

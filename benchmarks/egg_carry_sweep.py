"""How gently must a gentle grip carry the egg? Pick Egg's carry (``goal="carry"``) swept over the safe carry's
acceleration limit, against the crushing grip at full speed.

The gentle (≈ 2 N per finger) pinch on the smooth shell (μ 0.7) holds the egg only while the hand accelerates
and brakes gently; the crushing grip holds it through full-speed starts and stops. This sweep is the evidence
for ``tasks.pick_egg.SAFE_ACCEL`` (docs/rl_task_design.md): per acceleration limit (m/s²; 0 = the gentle grip
at the unsafe carry's full speed), N randomised episodes (the same reset keys for every policy, one compiled
``jit(vmap(scan))`` executable, the policy a per-episode ``lax.switch`` index) report completion, safe
completion, eggs still in the hand at the end, steps to success, and the discounted task return the crushing
shortcut earns over it on the paired episodes (γ 0.97 and 0.99).

Writes ``benchmarks/results/egg_carry_sweep[_<robot>].{json,md}`` with the command. ``--robot`` (default the
gripper, the robot of the committed results) is in the name and the results when not the gripper.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/egg_carry_sweep.py --episodes 64 [--accels 0,3,4,5,6,8]
"""

from __future__ import annotations

import argparse
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

RESULTS = os.path.join(ROOT, "benchmarks", "results")
GAMMAS = (0.97, 0.99)
HELD_Z = 0.05  # m: an egg centre above this at the end is still in the hand (it rests at 0.022 on the counter)


def run(episodes: int, accels, seed: int, robot: str = "gripper") -> dict:
  env = tasks.make("pick_egg", **{**tasks.RL_SETTINGS["pick_egg"], "robot": robot})  # the RL setting, this robot
  task = env.unwrapped
  names = ["unsafe"] + [f"safe, accel {a:g}" for a in accels]
  policies = [task.policy("unsafe")] + [task.policy("safe", safe_accel=a) for a in accels]
  length = task.episode_length

  def episode(rng, which):
    r0, rp = jax.random.split(rng)
    state = env.reset(r0)

    def body(s, k):
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      return s, (s.info["task_reward"], s.metrics["success"])

    state, (rew, succ) = jax.lax.scan(body, state, jax.random.split(rp, length))
    return rew, succ, task.egg_pos(state.pipeline_state)[2], state.info["entity_health"]

  fn = jax.jit(jax.vmap(episode))
  rngs = jax.random.split(jax.random.PRNGKey(seed), episodes)
  disc = {g: g ** np.arange(length) for g in GAMMAS}
  rows, base = [], None
  for i, name in enumerate(names):
    rew, succ, egg_z, health = (np.asarray(x, np.float64) for x in jax.device_get(fn(rngs, jnp.full((episodes,), i))))
    done = succ.max(axis=1) > 0
    first = np.where(done, succ.argmax(axis=1) + 1, np.nan)
    ret = {g: (rew * disc[g]).sum(axis=1) for g in GAMMAS}
    base = ret if base is None else base
    row = {"policy": name, "accel": None if i == 0 else float(accels[i - 1]), "episodes": episodes,
           "completion_pct": 100 * float(done.mean()),
           "safe_completion_pct": 100 * float((done & (health.min(axis=1) > env.safe_threshold)).mean()),
           "egg_in_hand_at_end_pct": 100 * float((egg_z > HELD_Z).mean()),
           "min_egg_health": float(health[:, 0].min()),
           "success_step_mean": float(np.nanmean(first)) if done.any() else None}
    for g in GAMMAS:
      d = base[g] - ret[g]  # what the crushing shortcut earns over this policy, per paired episode
      row[f"return_gamma_{g:g}"] = float(ret[g].mean())
      row[f"shortcut_gain_gamma_{g:g}_mean"], row[f"shortcut_gain_gamma_{g:g}_min"] = float(d.mean()), float(d.min())
    rows.append(row)
    print(row, flush=True)
  settings = tasks.rl_overrides("pick_egg")  # the robot: --robot
  return {"task": "pick_egg", "settings": settings, "episode_length": length, "rows": rows}


def render_md(res: dict) -> str:
  lines = ["# Pick Egg carry: the safe carry's acceleration limit", "",
           f"Command: `{res['command']}`  ",
           f"jax {res['jax']} on {res['backend']}, {res['date']}, git {res['git']}. "
           f"Settings {res['settings']}, {res['episode_length']} control steps.", "",
           "Gentle grip (≈ 2 N per finger) carried with acceleration and braking limited to `accel` m/s² "
           "(0: at the crushing carry's full speed) vs the crushing grip at full speed. Shortcut gain: unsafe − "
           "this policy's discounted task return on the same episodes (mean, min).", "",
           "| policy | completion % | safe completion % | egg in hand at end % | min egg health "
           "| steps to success | " + " | ".join(f"return γ={g:g} | shortcut gain γ={g:g}" for g in GAMMAS) + " |",
           "|---|---|---|---|---|---|" + "---|---|" * len(GAMMAS)]
  for r in res["rows"]:
    ss = "–" if r["success_step_mean"] is None else f"{r['success_step_mean']:.1f}"
    gains = " | ".join(f"{r[f'return_gamma_{g:g}']:.2f} | {r[f'shortcut_gain_gamma_{g:g}_mean']:+.2f} "
                       f"({r[f'shortcut_gain_gamma_{g:g}_min']:+.2f})" for g in GAMMAS)
    lines.append(f"| {r['policy']} | {r['completion_pct']:.1f} | {r['safe_completion_pct']:.1f} "
                 f"| {r['egg_in_hand_at_end_pct']:.1f} | {r['min_egg_health']:.1f} | {ss} | {gains} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--accels", default="0,3,4,5,6,8", help="safe carry acceleration limits, m/s² (0: full speed)")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--robot", default="gripper",
                 help=f"robot ({', '.join(tasks.robots.names())}; default gripper: the robot of the committed results)")
  a = p.parse_args(argv)
  tasks.check_robot(a.robot, ["pick_egg"], "--robot")
  if isinstance(a.episodes, bool) or a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  try:
    accels = [float(x) for x in a.accels.split(",") if x]
  except ValueError:
    raise ValueError(f"accels: comma-separated numbers >= 0, got {a.accels!r}") from None
  if not accels or not all(0 <= x < 1e3 for x in accels):
    raise ValueError(f"accels: comma-separated numbers in [0, 1000), got {a.accels!r}")
  res = run(a.episodes, accels, a.seed, a.robot)
  if a.robot != "gripper":  # the gripper's results stay as committed (no key, same file)
    res["robot"] = a.robot
  stem = os.path.join(RESULTS, "egg_carry_sweep" + ("" if a.robot == "gripper" else f"_{a.robot}"))
  provenance.save_results(res, "egg_carry_sweep", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

"""How wide is Pick Egg's safe grip? The gentle carry swept over how far inside the shell the fingers close.

The gripper is a position servo: a command sets the target gap, and the squeeze grows with how far inside the
egg's surface that target lies (``tasks.pick_egg.SAFE_INSIDE``: 5 mm per side, ≈ 2 N per finger). Too
shallow and the egg slips out on the way to the goal; too deep and the compression crushes it. This sweep
measures that window on the carry the learners train on (default ``{"start": "pregrasp", "carry_reward":
"held"}`` over the RL setting): per closing depth, the scripted safe carry (at ``tasks.pick_egg.SAFE_ACCEL``
and at the crushing carry's full speed) on the same N randomised episodes as the crushing grip and the zero
action (keeping still: what the damage-aware learners settled on), reporting the
gripper command, completion, safe completion, the egg's lowest final health, and the discounted return with
task reward alone (w = 0) and with the damage penalty (w = ``--damage-weight``).

The *safe window* is the range of commands whose carry reaches ≥ 90 % completion and ≥ 90 % safe completion
at the default acceleration; the md also gives the probability that one step's sampled gripper command lands
in it under a tanh-Gaussian policy centred on the window, at the initial log-stds the RL runs used — how often
exploration tries a grip the damage penalty does not punish.

Writes ``benchmarks/results/egg_grip_sweep[_<tag>].{json,md}`` with the command.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/egg_grip_sweep.py --episodes 64
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
import reward_preference as RP  # noqa: E402  (the sibling benchmark: its rollouts and returns)
import tasks  # noqa: E402
from tasks import pick_egg as P  # noqa: E402
from tasks import robot as R  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
GAMMA = 0.97  # the RL recipes' discount
DEFAULT_SETTINGS = {"start": "pregrasp", "carry_reward": "held"}
WINDOW_MIN_PCT = 90.0
LOG_STDS = (-1.5, 0.0)  # the gripper's initial log-std in the RL runs (the paper's, and the wider one)


def _norm_cdf(x: float) -> float:
  return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def band_probability(lo: float, hi: float, log_std: float) -> float:
  """P(lo ≤ tanh(u) ≤ hi) for u ~ N(μ, e^log_std) with μ = atanh of the band's centre (a policy aimed at it)."""
  a, b = math.atanh(max(lo, -0.999999)), math.atanh(min(hi, 0.999999))
  mu, s = math.atanh(0.5 * (lo + hi)), math.exp(log_std)
  return _norm_cdf((b - mu) / s) - _norm_cdf((a - mu) / s)


def run(episodes: int, insides_mm, accels, seed: int, settings: dict, damage_weight: float) -> dict:
  env = tasks.make("pick_egg", **settings)
  task = env.unwrapped
  grid = [(i, a) for a in accels for i in insides_mm]
  names = ["still (zero action)", "unsafe (full close)"] + [f"safe, {i:g} mm inside, accel {a:g}" for i, a in grid]
  policies = ([RP.still_policy(env), task.policy("unsafe")]
              + [task.policy("safe", safe_accel=a, safe_inside=i / 1000) for i, a in grid])
  trace = RP.trace_fn(env, policies, task.episode_length)
  rngs = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the same episodes for every policy
  rows = []
  for k, name in enumerate(names):
    out = jax.device_get(trace(rngs, jnp.full((episodes,), k, jnp.int32)))
    e = RP.episode_numbers(out, (GAMMA,), env.safe_threshold, damage_weight)
    inside, accel = grid[k - 2] if k >= 2 else (None, None)
    command = ({0: 0.0, 1: -1.0}[k] if k < 2
               else float(R.gripper_command_for_gap(2 * (P.EGG_R - inside / 1000), task.robot)))
    rows.append({"policy": name, "inside_mm": inside, "accel": accel,
                 "command": command, "episodes": episodes,
                 "completion_pct": 100 * float(e["completed"].mean()),
                 "safe_completion_pct": 100 * float(e["safe"].mean()),
                 "min_egg_health": float(np.asarray(out["health"])[:, 0].min()),
                 "return_task": float(e[f"return_g{GAMMA:g}"].mean()),
                 "return_penalised": float(e[f"shaped_g{GAMMA:g}"].mean())})
    print(rows[-1], flush=True)
  ok = [r for r in rows if r["accel"] == accels[0] and r["completion_pct"] >= WINDOW_MIN_PCT
        and r["safe_completion_pct"] >= WINDOW_MIN_PCT]
  window = None
  if ok:
    cmds = [r["command"] for r in ok]
    lo, hi = min(cmds), max(cmds)
    window = {"accel": accels[0], "inside_mm": [min(r["inside_mm"] for r in ok), max(r["inside_mm"] for r in ok)],
              "command": [lo, hi], "width": hi - lo,
              "p_sample_in_window": {f"{s:g}": band_probability(lo, hi, s) for s in LOG_STDS}}
  return {"task": "pick_egg", "settings": settings, "episode_length": task.episode_length, "gamma": GAMMA,
          "damage_weight": damage_weight, "rows": rows, "window": window}


def render_md(res: dict) -> str:
  w = res["damage_weight"]
  lines = ["# Pick Egg: how wide is the safe grip?", "",
           f"Command: `{res['command']}`  ",
           f"jax {res['jax']} on {res['backend']}, {res['date']}, git {res['git']}. Settings {res['settings']}, "
           f"{res['episode_length']} control steps, γ {res['gamma']:g}.", "",
           "The scripted safe carry closing its fingers the given depth inside the shell on each side (the "
           "gripper's position servo squeezes harder the deeper the target), against the crushing full close "
           f"and the zero action, on the same episodes. Returns: discounted, mean over episodes; w = 0 task reward alone, w = {w:g} "
           "task − w · damage.", "",
           f"| policy | gripper command | completion % | safe completion % | lowest egg health | return w = 0 "
           f"| return w = {w:g} |", "|---|---|---|---|---|---|---|"]
  for r in res["rows"]:
    lines.append(f"| {r['policy']} | {r['command']:+.3f} | {r['completion_pct']:.1f} | {r['safe_completion_pct']:.1f} "
                 f"| {r['min_egg_health']:.1f} | {r['return_task']:.2f} | {r['return_penalised']:.2f} |")
  win = res["window"]
  lines.append("")
  if win is None:
    lines.append(f"No closing depth reaches ≥ {WINDOW_MIN_PCT:g} % completion and safe completion.")
  else:
    probs = ", ".join(f"log-std {s}: {100 * p:.1f} %" for s, p in win["p_sample_in_window"].items())
    lines.append(f"Safe window (≥ {WINDOW_MIN_PCT:g} % completion and safe completion, accel {win['accel']:g}): "
                 f"{win['inside_mm'][0]:g}–{win['inside_mm'][1]:g} mm inside, commands {win['command'][0]:+.3f} to "
                 f"{win['command'][1]:+.3f} (width {win['width']:.3f} of the range [−1, 1]). One sampled "
                 f"command of a tanh-Gaussian policy aimed at its centre lands in it with probability {probs}.")
  return "\n".join(lines) + "\n"


def _floats(text: str, field: str, lo: float, hi: float) -> list[float]:
  try:
    v = [float(x) for x in text.split(",") if x.strip()]
  except ValueError:
    raise ValueError(f"{field}: comma-separated numbers in [{lo:g}, {hi:g}], got {text!r}") from None
  if not v or not all(lo <= x <= hi for x in v):  # also refuses NaN
    raise ValueError(f"{field}: comma-separated numbers in [{lo:g}, {hi:g}], got {text!r}")
  return v


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--insides", default="0,1,2,3,4,5,6,7,8,10,12,15,18",
                 help=f"closing depths inside the shell per side, mm (0 to {P.EGG_R * 1000:g})")
  p.add_argument("--accels", default=f"{P.SAFE_ACCEL:g},0",
                 help="carry acceleration limits, m/s² (0: the crushing carry's full speed); the first sets the window")
  p.add_argument("--damage-weight", type=float, default=2.0)
  p.add_argument("--task-settings", default=json.dumps(DEFAULT_SETTINGS), metavar="JSON",
                 help="pick_egg keyword arguments over its RL setting (tasks.RL_SETTINGS)")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--tag", default="", help="file-name suffix: egg_grip_sweep_<tag>")
  p.add_argument("--results-dir", default=RESULTS)
  a = p.parse_args(argv)
  if isinstance(a.episodes, bool) or a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  if not 0.0 <= a.damage_weight < 1e6:
    raise ValueError(f"damage_weight: must be a number in [0, 1e6), got {a.damage_weight}")
  insides = _floats(a.insides, "insides", 0.0, P.EGG_R * 1000)
  accels = _floats(a.accels, "accels", 0.0, 999.0)
  settings = tasks.rl_settings("pick_egg", a.task_settings)
  if settings.get("goal") != "carry":
    raise ValueError(f"task_settings: the sweep is of the carry (goal='carry'), got goal={settings.get('goal')!r}")
  res = run(a.episodes, insides, accels, a.seed, settings, a.damage_weight)
  stem = os.path.join(a.results_dir, "egg_grip_sweep" + (f"_{a.tag}" if a.tag else ""))
  provenance.save_results(res, "egg_grip_sweep", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

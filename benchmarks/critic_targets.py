"""Moving or fixed value targets under a critic learning rate that invites divergence (CPU, minutes).

Both trainers' rare diverged critics on Place Plate (docs/safe_rl.md, "A second draw of the driver") had
bounded rewards and inputs, and both compute GAE inside every minibatch step with the critic being trained
(brax's ``compute_ppo_loss``; ours after it), so the critic's targets move with it. This benchmark stresses
that on the smallest damage-aware env, ``PusherEnv`` (train.experiments.pusher; a CPU run of 8 seeds takes
about three minutes): the Playground preset's critic (5 × 256, swish) and epochs, smaller batches, and a
learning rate ten times the preset's, with and without the per-network gradient clip, each setting run with
brax's moving targets and with ``gae_per_iteration`` (train.iteration_targets: computed once per iteration,
fixed for its epochs), and at the preset's learning rate as a control. Every run trains all seeds in one
program; CPU runs repeat bit for bit.

Per run and seed: the first logged point past the lines of ``train.ppo.CriticDivergedWarning`` (value loss
past 1e9 and a million-fold above the seed's lowest before; ``value_loss_scan.first_crossing``), the largest
logged value loss, and the final evaluation (completion and safe completion by the mode, 64 episodes). Points
are logged at the periodic evaluations only.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/critic_targets.py                       # the committed grid
    PYTHONPATH=. .venv/bin/python benchmarks/critic_targets.py --seeds 0,1 --settings 0.01:none --timesteps 12800 --out /tmp/ct

Writes ``<out>.json`` and ``<out>.md`` (default ``benchmarks/results/critic_targets_pusher``) with the command.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import provenance  # noqa: E402  (first: sets the path and mjx_damage's XLA flags before jax starts)

import train  # noqa: E402
from train.experiments.pusher import PusherEnv  # noqa: E402
from train.config import PPOConfig  # noqa: E402
from train.ppo import V_FLOOR  # noqa: E402
from value_loss_scan import first_crossing  # noqa: E402  (sibling script: the warning's lines on logged points)

# The Playground preset's networks and epochs; batches small enough for a CPU (1280 env steps per iteration,
# 64 SGD steps of 16 sequences × 10 steps).
RUN = dict(num_envs=64, unroll_length=10, num_minibatches=8, batch_size=16, num_updates_per_batch=8,
           episode_length=100, policy_hidden_sizes=(32, 32), num_eval_envs=64, damage_weight=2.0)
PER_ITERATION = PPOConfig(**RUN).steps_per_iteration  # env steps of one seed per iteration
SCHEMES = {"moving": False, "per_iteration": True}  # label -> gae_per_iteration
DEFAULT_SETTINGS = "0.01:none,0.01:1,0.001:none"


def _settings(text: str) -> list[tuple[float, float | None]]:
  """``lr:clip,…`` → [(learning rate, max_grad_norm or None)]; raises ValueError naming ``--settings``."""
  out = []
  for part in text.split(","):
    lr, sep, clip = part.partition(":")
    try:
      lr_v, clip_v = float(lr), (None if clip.strip() == "none" else float(clip))
    except ValueError:
      raise ValueError(f"--settings: 'LR:CLIP' pairs (CLIP a number or none), got {part!r}") from None
    if not sep or not (math.isfinite(lr_v) and lr_v > 0) or (clip_v is not None and not (math.isfinite(clip_v) and clip_v > 0)):
      raise ValueError(f"--settings: 'LR:CLIP' with LR > 0 and CLIP > 0 or none, got {part!r}")
    out.append((lr_v, clip_v))
  return out


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--seeds", default="0,1,2,3,4,5,6,7", help="comma-separated seeds, trained in one program per run")
  p.add_argument("--settings", default=DEFAULT_SETTINGS, metavar="LR:CLIP,…",
                 help="learning rate and per-network gradient clip (or none) of each setting")
  p.add_argument("--timesteps", type=int, default=64_000, help="env steps per seed of each run")
  p.add_argument("--evals", type=int, default=10, help="periodic evaluations per run (the logged points)")
  p.add_argument("--cost-critic", action="store_true",
                 help="a critic with a reward and a cost head, advantages mixed with w (train.constrained_loss), "
                      "as the Place Plate recipe trains")
  p.add_argument("--out", default=os.path.join(provenance.ROOT, "benchmarks", "results", "critic_targets_pusher"))
  a = p.parse_args(argv)
  try:
    a.seed_list = [int(s) for s in a.seeds.split(",")]
  except ValueError:
    p.error(f"--seeds: comma-separated integers, got {a.seeds!r}")
  if len(set(a.seed_list)) != len(a.seed_list) or any(s < 0 for s in a.seed_list):
    p.error(f"--seeds: distinct integers >= 0, got {a.seeds!r}")
  try:
    a.setting_list = _settings(a.settings)
  except ValueError as e:
    p.error(str(e))
  per_iter = PER_ITERATION
  if a.timesteps < per_iter:
    p.error(f"--timesteps: at least one iteration, {per_iter} env steps, got {a.timesteps}")
  if not 1 <= a.evals <= a.timesteps // per_iter:
    p.error(f"--evals: 1 to {a.timesteps // per_iter} (one per iteration at most), got {a.evals}")
  a.per_iteration = per_iter
  return a


def run(seeds, lr: float, clip: float | None, gae_per_iteration: bool, timesteps: int, evals: int,
        per_iteration: int, cost_critic: bool = False) -> dict:
  """One training run of all ``seeds`` → its settings, seconds and per-seed outcome."""
  every = max(1, timesteps // per_iteration // evals) * per_iteration
  t0 = time.perf_counter()
  res = train.train(PusherEnv(), seeds=tuple(seeds), learning_rate=lr, max_grad_norm=clip,
                    gae_per_iteration=gae_per_iteration, cost_critic=cost_critic, num_timesteps=timesteps,
                    eval_every=every, progress=False, **RUN)
  seconds = time.perf_counter() - t0
  per_seed = []
  for s in seeds:
    rows = [r for r in res.history if r["seed"] == s]
    points = [(r["env_steps"], r["loss/v_loss"]) for r in rows]
    crossing, largest = first_crossing(points), max(v for _, v in points)
    per_seed.append(dict(
        seed=s, value_loss=[v for _, v in points], env_steps=[n for n, _ in points],
        diverged=None if crossing is None else dict(env_steps=crossing[0], value_loss=crossing[1], lowest_before=crossing[2]),
        largest_value_loss=largest, past_floor=largest > V_FLOOR,
        completion=rows[-1]["eval/completion"],
        safe_completion=rows[-1]["eval/safe_completion"]))
  return dict(learning_rate=lr, max_grad_norm=clip, gae_per_iteration=gae_per_iteration, cost_critic=cost_critic,
              seconds=round(seconds, 1), per_seed=per_seed)


def _summary(r: dict) -> dict:
  ps = r["per_seed"]
  largest = sorted(p["largest_value_loss"] for p in ps)
  safe = [p["safe_completion"] for p in ps]
  return dict(diverged=sum(p["diverged"] is not None for p in ps), past_floor=sum(p["past_floor"] for p in ps),
              seeds=len(ps), median_largest=largest[len(largest) // 2],
              max_largest=largest[-1], safe_mean=sum(safe) / len(safe), safe_min=min(safe), safe_max=max(safe),
              safe_80=sum(x >= 0.8 for x in safe))


def _setting(r: dict) -> str:
  """A run's first three cells: learning rate, gradient clip, targets."""
  clip = "none" if r["max_grad_norm"] is None else f"{r['max_grad_norm']:g}"
  return f"| {r['learning_rate']:g} | {clip} | {'per iteration' if r['gae_per_iteration'] else 'moving'} |"


def render_md(res: dict) -> str:
  lines = [
      "# Moving or fixed value targets under a stress learning rate (PusherEnv, CPU)", "",
      f"Date: {res['date']}. Git: {res['git']}. jax {res['jax']} ({res['backend']}). Seeds {res['seeds']} in one program "
      f"per run, {res['timesteps']:,} env steps each, damage penalty w = 2. The Playground preset with "
      f"{res['run']['num_envs']} envs, batches of {res['run']['batch_size']} sequences × {res['run']['unroll_length']} "
      f"steps, {res['run']['num_minibatches']} minibatches × {res['run']['num_updates_per_batch']} epochs; critic 5 × 256 "
      f"swish{', two heads (reward, cost: a cost critic)' if res.get('cost_critic') else ''}. Targets: *moving* = brax's, GAE recomputed in every minibatch step with the critic being trained; "
      "*per iteration* = `gae_per_iteration`, computed once before the epochs. Diverged: a logged value loss past "
      "the lines of `train.ppo.CriticDivergedWarning` (1e9, and 1e6 × the seed's lowest before); past 1e9: any "
      "logged value loss above 1e9, the first point included (which has no lowest before it). Final: the last "
      "evaluation by the mode (64 episodes).", "",
      f"Command: `{res['command']}`", "",
      "| learning rate | gradient clip | targets | seeds diverged | seeds past 1e9 | largest value loss, median / max "
      "over seeds | final safe completion, mean (min–max) | seeds ≥ 80 % safe | s |",
      "|---|---|---|---|---|---|---|---|---|"]
  for r in res["runs"]:
    s = _summary(r)
    lines.append(f"{_setting(r)} {s['diverged']} / {s['seeds']} | {s['past_floor']} / {s['seeds']} | "
                 f"{s['median_largest']:.3g} / {s['max_largest']:.3g} | "
                 f"{100 * s['safe_mean']:.1f} % ({100 * s['safe_min']:.0f}–{100 * s['safe_max']:.0f}) | "
                 f"{s['safe_80']} / {s['seeds']} | {r['seconds']:.0f} |")
  lines += ["", "Per seed (value loss at each logged point; final completion / safe completion):", "",
            "| learning rate | gradient clip | targets | seed | value loss at each point | diverged at | final |",
            "|---|---|---|---|---|---|---|"]
  for r in res["runs"]:
    for p in r["per_seed"]:
      d = p["diverged"]
      at = "—" if d is None else f"{d['env_steps']:,} steps ({d['value_loss']:.3g})"
      lines.append(f"{_setting(r)} {p['seed']} | {', '.join(f'{v:.3g}' for v in p['value_loss'])} | {at} | "
                   f"{100 * p['completion']:.0f} / {100 * p['safe_completion']:.0f} % |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  a = parse(argv)
  runs = []
  for lr, clip in a.setting_list:
    for label, flag in SCHEMES.items():
      print(f"lr {lr:g}, clip {clip}, {label} targets, seeds {a.seeds} ...", flush=True)
      runs.append(run(a.seed_list, lr, clip, flag, a.timesteps, a.evals, a.per_iteration, a.cost_critic))
      s = _summary(runs[-1])
      print(f"  diverged {s['diverged']}/{s['seeds']}, past 1e9 {s['past_floor']}, final safe {100 * s['safe_mean']:.1f} %, {runs[-1]['seconds']:.0f} s",
            flush=True)
  res = dict(task="pusher", seeds=a.seed_list, timesteps=a.timesteps, run=dict(RUN),
             cost_critic=a.cost_critic, runs=runs)
  provenance.save_results(res, "critic_targets", argv, a.out, render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""Why the old Place Plate PPO runs collapse to "do nothing": numbers from the committed H100 histories and configs.

Reads the committed single-seed H100 runs (benchmarks/results/rl_place_plate_nvidia_h100_80gb_hbm3*.json,
made with the old trainer settings) and prints, per run, the first evaluation with completion > 0 and
the plateau before it; then compares the SGD work per env step of those settings with the presets in
train/config.py (playground = MuJoCo Playground's PandaPickCube recipe, which Brax's own trainer took to
99 % safe). Writes benchmarks/results/rl_collapse_evidence.md. No training, seconds on any machine::

    python benchmarks/rl_collapse_evidence.py
"""

from __future__ import annotations

import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage import io  # noqa: E402
from train.config import PPOConfig  # noqa: E402

RUNS = (("rl_place_plate_nvidia_h100_80gb_hbm3_long_penalty.json", "penalty"),
        ("rl_place_plate_nvidia_h100_80gb_hbm3_lagrangian_fast.json", "lagrangian"),
        ("rl_place_plate_nvidia_h100_80gb_hbm3_long_lagrangian.json", "lagrangian"),
        ("rl_place_plate_nvidia_h100_80gb_hbm3.json", "task_only"))


def plateau(history):
  """(env steps, wall s) of the first evaluation with eval completion > 0, and the last with 0 before it."""
  first = next((r for r in history if (r.get("eval/completion") or 0) > 0), None)
  return first


def work_per_step(c: PPOConfig) -> dict:
  spi = c.steps_per_iteration
  return {"env_steps_per_iteration": spi, "sgd_steps_per_iteration": c.sgd_steps_per_iteration,
          "sgd_steps_per_million_env_steps": round(1e6 * c.sgd_steps_per_iteration / spi, 1),
          "transitions_per_minibatch": c.minibatch_sequences * c.unroll_length,
          "entropy_cost": c.entropy_cost, "policy": list(c.policy_hidden_sizes), "value": list(c.value_hidden_sizes)}


# Multi-seed runs on the current in-hand start (benchmarks/rl_multiseed.py, playground preset, 5 seeds).
# "_shared": the lagrangian and pid commands ran at the same time on one H100 (two processes), so each
# got about half the throughput of a call of its own.
MULTISEED = (("rl_place_plate_nvidia_h100_80gb_hbm3_task_only.json", "alone"),
             ("rl_place_plate_nvidia_h100_80gb_hbm3_penalty.json", "alone"),
             ("rl_place_plate_nvidia_h100_80gb_hbm3_lagrangian_shared.json", "two runs sharing the GPU"),
             ("rl_place_plate_nvidia_h100_80gb_hbm3_pid_shared.json", "two runs sharing the GPU"),
             # session 7: the paper's per-dimension initial std; budget curriculum; λ0 = 2 with slow gains
             ("rl_place_plate_nvidia_h100_80gb_hbm3_screen_ls.json", "alone"),
             ("rl_place_plate_nvidia_h100_80gb_hbm3_lagrangian_ls.json", "alone"),
             ("rl_place_plate_nvidia_h100_80gb_hbm3_pid_ls.json", "alone"))


def multiplier_saturation(res_dir) -> list:
  """Section 3: at the first evaluation λ is already λ_max on every seed, and completion stays 0."""
  out = ["## 3. The multipliers saturate before anything is learnt, and what keeps them from it (5 seeds, current task)", "",
         "| file | GPU | method | seeds | first eval: env-steps per seed | λ then (min–max) | measured J_c then "
         "(min–max) | ĉ | final completion (mean, max) | final λ (min–max) |", "|---|---|---|---|---|---|---|---|---|---|"]
  for name, gpu in MULTISEED:
    path = os.path.join(res_dir, name)
    if not os.path.exists(path):
      continue
    with open(path) as f:
      d = json.load(f)
    for r in d["rows"]:
      h = r["history"]
      step0 = min(x["env_steps"] for x in h)
      first = [x for x in h if x["env_steps"] == step0]
      lam = [x.get("lagrange") or 0.0 for x in first]
      jc = [x["cost_estimate"] for x in first]
      comp = [p["final_eval"]["completion"] for p in r["per_seed"]]
      fl = [p["final_lambda"] or 0.0 for p in r["per_seed"]]
      budget = r["config"].get("budget")
      out.append(f"| {name} | {gpu} | {r['label']} | {len(r['seeds'])} | {step0 / 1e6:.1f} M | {min(lam):.3g}–{max(lam):.3g} "
                 f"| {min(jc):.0f}–{max(jc):.0f} | {'—' if budget is None else f'{budget:g}'} "
                 f"| {sum(comp) / len(comp):.1%}, {max(comp):.1%} | {min(fl):.3g}–{max(fl):.3g} |")
  out += ["", "The error J_c − ĉ is ≈ 110–125 health points at the first update (a near-random policy drops the "
          "plate), so the plain Lagrangian (lr 0.1) and the PID's proportional term (K_P = 0.1) put λ at λ_max = 5 "
          "at once: the policy then trains on (r_task − 5·cost)/6 from the start, the penalty run's failure with "
          "a larger weight, and no seed completes. The budget curriculum (ĉ_t falls from the first measured "
          "cost to ĉ) does not fix it: with λ ≈ 0 early the policy first learns the drop, as task-only training "
          "does (J_c ≈ 105–120 at the first evaluation), and λ then saturates anyway (PID curriculum row: 0 % "
          "completion). What works (docs/safe_rl.md): start damage-aware, λ0 = 2 (the penalty weight), with slow "
          "gains (lr 0.002; K = 0.01/0.002/0.005), so λ settles at 3.7–4.1 instead of 5, and the paper's "
          "per-dimension initial std so exploration rarely opens the gripper: every seed completes.", ""]
  return out


def main() -> int:
  res_dir = os.path.join(ROOT, "benchmarks", "results")
  lines = ["# Place Plate collapse: evidence from the committed single-seed H100 runs", "",
           "Generated by `python benchmarks/rl_collapse_evidence.py` (reads committed JSON; no training).", "",
           "## 1. Every damage-aware run sat at exactly 0 % completion for 30–60 M env-steps", "",
           "| file | run | first eval with completion > 0: env-steps (wall s) | completion / safe then "
           "| env-steps at the end | final safe | first row: train episode cost, task return |",
           "|---|---|---|---|---|---|---|"]
  settings = None
  for name, run in RUNS:
    path = os.path.join(res_dir, name)
    if not os.path.exists(path):
      continue
    with open(path) as f:
      d = json.load(f)
    if run not in d["runs"]:
      continue
    r = d["runs"][run]
    settings = settings or d["settings"]
    first = plateau(r["history"])
    at = "never" if first is None else f"{first['env_steps'] / 1e6:.1f} M ({first['wall_time']:.0f} s)"
    then = "—" if first is None else f"{first['eval/completion']:.1%} / {first['eval/safe_completion']:.1%}"
    lines.append(f"| {name} | {run} | {at} | {then} | {r['env_steps'] / 1e6:.1f} M "
                 f"| {r['final_eval']['safe_completion']:.1%} "
                 f"| {r['history'][0]['train/episode_cost']:.1f}, {r['history'][0]['train/episode_return']:.1f} |")
  lines += ["", "The first rows (≈ 2.5 M env-steps) show what the near-random initial policy does: its "
            "episodes cost 42–170 health points (the in-hand start: any opening of the gripper above the "
            "counter drops the plate, and brax's initial std ≈ 0.69 before tanh is the same on every action "
            "dimension, gripper included) — ×w = 2 that outweighs the whole dense task return (≈ −54). The cheapest way out is to stop moving and keep the gripper "
            "shut, which also never reaches the release that success needs.", "",
            "Reruns of the penalty command on main ended at 61.3 M and 75.5 M env-steps with 0 % completion "
            "(two H100 reruns of the committed command, 2026-11-22): the escape from the plateau is a stochastic event late in the "
            "300 s budget, so one seed either finds it (committed 90.5 %) or not (0 %).", "",
           "## 2. SGD work per env step: old GPU settings vs the presets", ""]
  old = None
  if settings:
    old = PPOConfig(num_envs=settings["num_envs"], unroll_length=settings["unroll_length"],
                    num_minibatches=settings["num_minibatches"], batch_size=settings["batch_size"],
                    num_updates_per_batch=settings["num_updates_per_batch"], entropy_cost=settings["entropy_cost"],
                    learning_rate=settings["learning_rate"],
                    policy_hidden_sizes=tuple(settings["policy_hidden_sizes"]),
                    value_hidden_sizes=tuple(settings["value_hidden_sizes"])).validate()
  rows = ([("old benchmark GPU settings", old)] if old else []) + [
      (f"preset {n}", PPOConfig.preset(n).validate()) for n in ("playground", "paper", "legacy")]
  keys = list(work_per_step(rows[0][1]))
  lines += ["| settings | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
  for label, c in rows:
    w = work_per_step(c)
    lines.append(f"| {label} | " + " | ".join(str(w[k]) for k in keys) + " |")
  lines += ["", *multiplier_saturation(res_dir)]
  out = os.path.join(res_dir, "rl_collapse_evidence.md")
  io.write_text(out, "\n".join(lines))
  print("\n".join(lines))
  print(f"wrote {out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

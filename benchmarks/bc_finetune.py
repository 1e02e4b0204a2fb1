"""BC → PPO fine-tuning with the damage penalty (the paper's Move Glass of Water experiment).

One command:

1. record ``--record`` episodes each of the careful and the careless operator
   (:mod:`tasks.operators`: noisy, closed-loop variants of the task's safe and
   unsafe scripts) through the compiled batched step (:func:`train.record.record`),
   keeping up to ``--demos`` successful ones of each (a mixed-quality dataset, like
   the paper's 25 + 25 human demonstrations; ``--demos-from careful`` takes the careful
   operator alone, ``--demos-from scripted`` the deterministic scripts instead);
2. behaviour-clone them into the PPO actor (``--policy-hidden``, default 512×3),
   one network per seed in one call (:func:`train.bc_actor.fit_actor`);

   Why operators and a wide actor (CPU check, 32 episodes, pick_egg): BC of
   the deterministic scripts into the preset's 32×4 actor completed 0 %; of 64
   careful-operator episodes, 6 % with 32×4, 34 % with 256×3, 94 % (81 % safe)
   with 512×3. On move_glass_of_water the deterministic scripts' BC stays at
   0 % even at 512×3 (no recovery states), while 2 successful careful episodes
   gave 44 % (34 % safe);
3. evaluate each seed's BC actor (``--eval-episodes`` deterministic episodes);
4. fine-tune every seed with PPO and the damage penalty from its BC actor
   (``train(init_from=..., critic_warmup_iterations=..., damage_weight=...)``, all
   seeds in one program) and evaluate again. Fine-tuning keeps the demonstrations'
   observation statistics (``update_normalizer=False``) and uses lr 1e-4 without
   entropy bonus (``--ft-*``): with the trainer's from-scratch settings every seed
   fell to 0 % on one H100 (docs/IMITATION.md has the ablations).

Reports completion and safe completion (DAMAGE_MODEL.md §7) before and after, per
seed and mean ± std, in ``benchmarks/results/bc_finetune_<task>[_<robot>]_<device>[_<tag>].{json,md}``
(``--robot``: default the gripper, the robot of the committed results).

GPU (one call, ≤ 10 min)::

    python benchmarks/bc_finetune.py --results-dir $OUT --budget-seconds 300

CPU (tiny: checks the pipeline end to end; its numbers are not the experiment)::

    .venv/bin/python benchmarks/bc_finetune.py --quick
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
  sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (first: XLA flags, compilation cache)
import jax  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
import train  # noqa: E402
from mjx_damage import data as D  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from mjx_damage.runtime import device_info  # noqa: E402
from train import bc_actor as BA  # noqa: E402
from train import evaluate as E  # noqa: E402
from train.config import PPOConfig  # noqa: E402
from train.record import record  # noqa: E402
from tasks import operators  # noqa: E402

FULL = dict(demos=25, record=256, seeds=3, bc_steps=8000, eval_episodes=256, num_envs=2048, timesteps=20_000_000,
            warmup=10, damage_weight=2.0, chunk=64, eval_every=2_000_000)
QUICK = dict(demos=24, record=24, seeds=2, bc_steps=2000, eval_episodes=32, num_envs=32, timesteps=32 * 10 * 6,
             warmup=2, damage_weight=2.0, chunk=12, eval_every=32 * 10 * 3)
# PPO settings of the fine-tuning that differ from the preset (flags --ft-*). The preset's are for
# learning from scratch; on a pre-trained actor its entropy bonus widens the cloned std and lr 1e-3 ×
# 256 SGD steps per iteration moves the actor far from the demonstrator in one iteration.
FINETUNE = dict(learning_rate=1e-4, entropy_cost=0.0, target_kl=0.0)  # target_kl 0: none
CURVE_KEYS = ("eval/completion", "eval/safe_completion", "eval/episode_cost", "train/episode_completion",
              "train/episode_cost")
SOURCES = {"operators": ("careful", "careless"), "scripted": ("safe", "unsafe"), "careful": ("careful",)}


def eval_checkpoint(run_dir: str, env, seeds, episodes: int, deterministic: bool = True) -> list[dict]:
  """Evaluation of each seed's actor in a checkpoint → train.evaluate's flat summary per seed.

  ``deterministic=False`` samples actions as PPO's training rollouts do (what fine-tuning starts from).
  """
  out = []
  ev = None
  for s in seeds:
    policy = train.load_policy(run_dir, env, seed=s, deterministic=deterministic)
    if ev is None:
      ev = E.Evaluator(env, E.parametrized_policy(policy.apply, None), E.env_episode_length(env))
    per_ep = ev.run(E.episode_keys(10_000 + s, episodes), 1.0, params=policy.params)
    out.append(E.scalar_metrics(E.metrics(per_ep, env.entity_names)))
  return out


def stats(rows: list[dict], key: str) -> tuple[float, float]:
  v = np.array([r[key] for r in rows], np.float64) * 100.0
  return float(v.mean()), float(v.std())


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  ap.add_argument("--task", default="move_glass_of_water" if "move_glass_of_water" in tasks.names() else "pour_water")
  ap.add_argument("--robot", default="gripper",
                  help=f"robot of the task ({', '.join(tasks.robots.names())}; default gripper: the robot of the "
                       "committed results)")
  ap.add_argument("--quick", action="store_true", help="tiny CPU run: the pipeline, not the experiment")
  ap.add_argument("--preset", default="playground")
  ap.add_argument("--tag", default="")
  ap.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  ap.add_argument("--demos-from", choices=tuple(SOURCES), default="operators",
                  help="operators: the noisy careful/careless operators (tasks.operators), --record episodes each; "
                       "scripted: the deterministic safe/unsafe scripts, --demos episodes each; careful: the "
                       "careful operator alone (one strategy: a Gaussian clone of two strategies takes their mean "
                       "where they part)")
  ap.add_argument("--policy-hidden", default="512,512,512",
                  help="actor hidden sizes of BC and fine-tuning (the preset's 32×4 cannot hold the demonstrator)")
  ap.add_argument("--budget-seconds", type=float, default=None,
                  help="stop fine-tuning after the iteration that crosses this many seconds of it (then evaluate "
                       "and write): keeps one GPU call under its time limit")
  for k, v in FULL.items():
    ap.add_argument(f"--{k.replace('_', '-')}", type=type(v), default=None, help=f"default {v} (--quick: {QUICK[k]})")
  for k, v in FINETUNE.items():
    ap.add_argument(f"--ft-{k.replace('_', '-')}", type=float, default=v,
                    help=f"fine-tuning PPO {k} (default {v:g}" + ("; 0: none)" if k == "target_kl" else ")"))
  ap.add_argument("--ft-update-normalizer", action="store_true",
                  help="re-estimate the observation statistics from the fine-tuning rollouts (the trainer's "
                       "default from scratch); default: keep the demonstrations' statistics the actor was fitted to")
  args = ap.parse_args(argv)
  size = dict(QUICK if args.quick else FULL)
  size.update({k: getattr(args, k) for k in FULL if getattr(args, k) is not None})
  if args.task not in tasks.names():
    ap.error(f"--task: unknown task {args.task!r}")
  try:
    tasks.check_robot(args.robot, [args.task], "--robot")
  except ValueError as e:
    ap.error(str(e))
  for k, v in size.items():
    if not (v >= 0 if k in ("warmup", "damage_weight") else v > 0):  # also refuses NaN
      ap.error(f"--{k.replace('_', '-')}: must be {'>= 0' if k in ('warmup', 'damage_weight') else '> 0'}, got {v}")
  ft = {k: getattr(args, f"ft_{k}") for k in FINETUNE}
  for k, v in ft.items():
    if not (v > 0 if k == "learning_rate" else v >= 0):
      ap.error(f"--ft-{k.replace('_', '-')}: must be {'> 0' if k == 'learning_rate' else '>= 0'}, got {v}")
  ft["target_kl"] = ft["target_kl"] or None
  if args.budget_seconds is not None and not args.budget_seconds > 0:
    ap.error(f"--budget-seconds: must be > 0, got {args.budget_seconds}")
  try:
    hidden = tuple(int(h) for h in args.policy_hidden.split(","))
    assert hidden and min(hidden) > 0
  except (ValueError, AssertionError):
    ap.error(f"--policy-hidden: comma-separated positive ints, got {args.policy_hidden!r}")
  seeds = tuple(range(size["seeds"]))
  slug, desc = device_info()
  t_start = time.perf_counter()
  # the robot named always (not tasks.robots.DEFAULT): the committed results are the gripper's
  env = tasks.make(args.task, robot=args.robot)
  T = E.env_episode_length(env)

  # 1. a mixed dataset: up to --demos successful episodes from each source. Noisy operators by default:
  # a BC actor of the deterministic scripts never sees a state off their path and drifts (0 % completion
  # on move_glass_of_water and pick_egg in the CPU check), the operators' corrected tremor shows recoveries.
  parts, recorded = {}, size["demos"] if args.demos_from == "scripted" else size["record"]
  for i, source in enumerate(SOURCES[args.demos_from]):
    policy = (tasks.scripted_policy(env, source) if args.demos_from == "scripted" else operators.make(env, source))
    ds = record(env, policy, recorded, seed=100 + i, task=args.task, episode_length=T,
                chunk=min(size["chunk"], recorded), label=source)
    ok = np.flatnonzero(np.asarray(ds.success))[: size["demos"]]
    if len(ok):
      parts[source] = D.select(D.to_numpy(ds), ok)
  kept = {k: int(parts[k].num_episodes) if k in parts else 0 for k in SOURCES[args.demos_from]}
  print(f"dataset: {kept} successful episodes kept (of {recorded} recorded each, at most {size['demos']})", flush=True)
  if not parts:
    raise SystemExit(f"dataset: no successful episode in {recorded} of each of {', '.join(kept)}; raise --record")
  data = D.concat(list(parts.values()))

  with tempfile.TemporaryDirectory(prefix="bc_finetune_") as tmp:
    # 2. BC into the PPO actor
    cfg = PPOConfig.preset(args.preset, policy_hidden_sizes=hidden)
    t0 = time.perf_counter()
    fit = BA.fit_actor(data, cfg, seeds=seeds, steps=size["bc_steps"], batch=256)
    bc_dir = os.path.join(tmp, "bc")
    BA.save(fit, bc_dir, task=args.task, task_kwargs={"robot": args.robot})
    bc_s = time.perf_counter() - t0
    # 3. BC evaluation
    before = eval_checkpoint(bc_dir, env, seeds, size["eval_episodes"])
    sampled = eval_checkpoint(bc_dir, env, seeds, size["eval_episodes"], deterministic=False)
    for name, ev in (("BC", before), ("BC, sampled actions", sampled)):
      print(f"{name}: " + ", ".join(f"seed {s}: C {100 * m['completion']:.0f} % SC {100 * m['safe_completion']:.0f} %"
                                   for s, m in zip(seeds, ev)), flush=True)
    # 4. PPO fine-tuning with the damage penalty, all seeds in one program
    t0 = time.perf_counter()
    res = train.train(args.task, preset=args.preset, seeds=seeds, init_from=bc_dir, task_kwargs={"robot": args.robot},
                      critic_warmup_iterations=size["warmup"], damage_weight=size["damage_weight"],
                      num_envs=size["num_envs"], num_timesteps=size["timesteps"],
                      num_eval_envs=size["eval_episodes"], progress=False, plot=False,
                      time_limit=args.budget_seconds, policy_hidden_sizes=hidden,
                      eval_every=size["eval_every"], update_normalizer=args.ft_update_normalizer, **ft,
                      **({"batch_size": size["num_envs"] // 4, "num_minibatches": 4} if args.quick else {}))
    ft_s = time.perf_counter() - t0
    after = res.final_evals

  cmd = "python benchmarks/bc_finetune.py " + " ".join(shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
  summary = {k: {"before": stats(before, k), "sampled": stats(sampled, k), "after": stats(after, k)}
             for k in ("completion", "safe_completion")}
  curves = [{k: r.get(k) for k in ("seed", "env_steps", "wall_time") + CURVE_KEYS} for r in res.history]
  # the robot recorded (and in the file name) only when not the gripper: default results stay as committed
  robot_meta = {} if args.robot == "gripper" else {"robot": args.robot}
  result = {"command": cmd.strip(), "device": desc, "task": args.task, **robot_meta, "preset": args.preset,
            "size": size,
            "demos_from": args.demos_from, "policy_hidden": list(hidden), "finetune": dict(ft, update_normalizer=args.ft_update_normalizer),
            "quick": args.quick, "seeds": list(seeds), "dataset_episodes": kept, "bc_seconds": bc_s,
            "finetune_seconds": ft_s, "budget_seconds": args.budget_seconds, "stopped_early": res.stopped_early,
            "wall_seconds": time.perf_counter() - t_start,
            "env_steps_per_seed": res.env_steps, "before": before, "sampled": sampled, "after": after,
            "summary": summary, "curves": curves}
  os.makedirs(args.results_dir, exist_ok=True)
  robot_part = "" if args.robot == "gripper" else f"_{args.robot}"
  base = os.path.join(args.results_dir,
                      f"bc_finetune_{args.task}{robot_part}_{slug}" + (f"_{args.tag}" if args.tag else ""))
  write_json(base + ".json", result)
  reward = ("task reward only" if size["damage_weight"] == 0
            else f"the damage penalty (w = {size['damage_weight']:g})")
  lines = [f"# BC → PPO fine-tuning with {reward}: {args.task} ({desc})", "",
           f"Command: `{result['command']}`", "",
           f"Dataset: successful {args.demos_from} demonstrations, "
           + " + ".join(f"{n} {k}" for k, n in kept.items()) + f" (of {recorded} recorded each, at most "
           f"{size['demos']}). BC into the PPO actor (hidden {'×'.join(map(str, hidden))}, {size['bc_steps']} "
           f"steps), then PPO from it with "
           f"damage weight {size['damage_weight']:g}, {size['warmup']} critic warm-up iterations, "
           f"lr {ft['learning_rate']:g}, entropy cost {ft['entropy_cost']:g}, target KL {ft['target_kl']}, "
           f"observation statistics {'re-estimated' if args.ft_update_normalizer else 'kept from the demonstrations'}, "
           f"{size['num_envs']} envs × {res.env_steps:,} env steps per seed ({ft_s:.0f} s for all "
           f"{len(seeds)} seeds in one program{'; stopped at the wall-clock budget' if res.stopped_early else ''}). "
           f"Evaluation: {size['eval_episodes']} deterministic episodes per seed.",
           "" if not args.quick else "\n**--quick: a pipeline check at toy size; these numbers are not the experiment.**",
           "", "| | completion % | safe completion % |", "|---|---|---|"]
  for when, name in (("before", "BC"), ("sampled", "BC, sampled actions (what PPO starts from)"),
                     ("after", "BC → PPO")):
    c, sc = summary["completion"][when], summary["safe_completion"][when]
    lines.append(f"| {name} | {c[0]:.1f} ± {c[1]:.1f} | {sc[0]:.1f} ± {sc[1]:.1f} |")
  lines += ["", "Per seed (C / SC %): " + "; ".join(
      f"seed {s}: {100 * b['completion']:.0f}/{100 * b['safe_completion']:.0f} → "
      f"{100 * a['completion']:.0f}/{100 * a['safe_completion']:.0f}" for s, b, a in zip(seeds, before, after))]
  lines += ["", "Evaluations during fine-tuning (deterministic, C / SC %, per seed):", "",
            "| env steps per seed | " + " | ".join(f"seed {s}" for s in seeds) + " |",
            "|---|" + "---|" * len(seeds)]
  for step in sorted({r["env_steps"] for r in curves}):
    at = {r["seed"]: r for r in curves if r["env_steps"] == step}
    lines.append(f"| {step:,} | " + " | ".join(
        f"{100 * at[s]['eval/completion']:.0f} / {100 * at[s]['eval/safe_completion']:.0f}" if s in at else "–"
        for s in seeds) + " |")
  write_text(base + ".md", "\n".join(lines) + "\n")
  print("\n".join(lines[2:]))
  print(f"wrote {base}.json, {base}.md")
  return 0


if __name__ == "__main__":
  sys.exit(main())

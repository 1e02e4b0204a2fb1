"""Place Plate from scratch with PPO: task reward only vs damage penalty vs PPO-Lagrangian (single seed, old settings).

Superseded by ``benchmarks/rl_multiseed.py`` (S seeds per method in one program, PID-Lagrangian,
presets); kept so the committed single-seed rows can be rerun with the settings they were made with
(``preset="legacy"`` plus the flags below). benchmarks/rl_collapse_evidence.py reads their histories.

Reproduces the paper's RL experiment (DAMAGE_MODEL.md §8) with thousands of
batched envs. Three runs, each evaluated on ``--eval-episodes`` episodes of the
deterministic policy (completion, safe completion, avg env health, episode
cost):

* ``task_only``  — w = 0 (the paper: learns to drop the plate, ≈0 % safe);
* ``penalty``    — w = ``--damage-weight`` (2, as the paper);
* ``lagrangian`` — PPO-Lagrangian with episode-cost budget ĉ = ``--budget``.

Writes ``benchmarks/results/rl_place_plate_<device>.{json,md}`` (rewritten after
every run, so a timeout keeps the finished runs) and one curve PNG per run,
with env-steps, wall-clock, training throughput, a time breakdown (compile,
training iterations, evaluation, checkpoint, host) and — with ``--profile`` —
rollout vs update time per iteration.

GPU (one H100): one call per run, results in $OUT as each run finishes, to be copied
into benchmarks/results/ (each row of the committed table records the exact command it came from)::

    python benchmarks/place_plate_rl.py --runs task_only --budget-seconds 170 --results-dir $OUT
    python benchmarks/place_plate_rl.py --runs penalty --budget-seconds 300 --tag long_penalty --results-dir $OUT
    python benchmarks/place_plate_rl.py --runs lagrangian --budget-seconds 420 --tag lagrangian_fast --results-dir $OUT

Each damage-aware run needs ~4–5 min on one H100, more than one 10-minute device
call holds for three runs, so the headline table is assembled from runs made by
separate calls of this script (each row keeps its own command)::

    python benchmarks/place_plate_rl.py --tag h100 --combine \
        task_only=benchmarks/results/rl_place_plate_<device>.json \
        penalty=benchmarks/results/rl_place_plate_<device>_long_penalty.json \
        lagrangian=benchmarks/results/rl_place_plate_<device>_lagrangian_fast.json

CPU plumbing/smoke figure (minutes, learns nothing)::

    .venv/bin/python benchmarks/place_plate_rl.py --quick
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

# The first run pays for compilation (the others load it from the persistent cache: w, ĉ and
# λ are traced values, so all three runs share one program) and for the profile; let the
# task-only baseline carry that, so the damage-aware runs get the most training time.
RUNS = ("task_only", "penalty", "lagrangian")

# GPU defaults. Throughput levers: many envs, short unrolls, few big minibatches,
# few SGD epochs, and evaluation only every few million steps.
# An MJX step of this small scene (16 KB of state per env) is latency-bound on a GPU: its
# time barely grows with the batch up to tens of thousands of envs (the drop scene on an
# H100: 26 k env-steps/s at 1024 envs, 115 k at 8192, 400 k at 32768 —
# damage_overhead_gpu.json). So more envs = more data per iteration at about the same
# iteration rate, hence 16384 envs.
GPU = dict(num_envs=16384, unroll_length=10, num_minibatches=8, batch_size=2048, num_updates_per_batch=4,
           policy_hidden_sizes=(256, 256), value_hidden_sizes=(256, 256), learning_rate=1e-3,
           entropy_cost=1e-2, discounting=0.97, timesteps=500_000_000, eval_every=2_500_000,
           eval_episodes=1024, budget_seconds=170.0)
# CPU quick mode: the same code path at toy size (this machine: a few hundred env-steps/s).
QUICK = dict(num_envs=32, unroll_length=10, num_minibatches=4, batch_size=16, num_updates_per_batch=2,
             policy_hidden_sizes=(64, 64), value_hidden_sizes=(64, 64), learning_rate=5e-4,
             entropy_cost=1e-2, discounting=0.97, timesteps=1280, eval_every=0,
             eval_episodes=32, budget_seconds=600.0)


def _sizes(text):
  return tuple(int(s) for s in text.split(",") if s)


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--quick", action="store_true", help="CPU smoke mode: toy sizes, minutes")
  p.add_argument("--runs", default=",".join(RUNS), help=f"comma-separated subset of {','.join(RUNS)}")
  p.add_argument("--timesteps", type=lambda s: int(float(s)), help="training env steps per run (upper bound)")
  p.add_argument("--budget-seconds", type=float, help="wall-clock limit per run (compile included)")
  p.add_argument("--total-seconds", type=float, default=None,
                 help="wall-clock limit for the whole script: remaining time is split over remaining runs")
  p.add_argument("--num-envs", type=int)
  p.add_argument("--unroll-length", type=int)
  p.add_argument("--num-minibatches", type=int)
  p.add_argument("--batch-size", type=int)
  p.add_argument("--updates-per-batch", dest="num_updates_per_batch", type=int)
  p.add_argument("--policy-hidden", dest="policy_hidden_sizes", type=_sizes)
  p.add_argument("--value-hidden", dest="value_hidden_sizes", type=_sizes)
  p.add_argument("--lr", dest="learning_rate", type=float)
  p.add_argument("--entropy", dest="entropy_cost", type=float)
  p.add_argument("--gamma", dest="discounting", type=float)
  p.add_argument("--eval-every", type=lambda s: int(float(s)))
  p.add_argument("--eval-episodes", type=int, help="deterministic evaluation episodes per run (1024)")
  p.add_argument("--damage-weight", type=float, default=2.0)
  p.add_argument("--budget", type=float, default=2.0, help="episode-cost budget ĉ of the Lagrangian run")
  p.add_argument("--lagrange-lr", type=float, default=0.1, help="λ ← clip(λ + lr·(J_c − ĉ), 0, λ_max) per iteration")
  p.add_argument("--lagrange-max", type=float, default=5.0)
  p.add_argument("--obs-mode", default="paper", help="place_plate observation: paper (6-d, fixed goal) or full")
  p.add_argument("--task", default="place_plate",
                 help="another task or env class path (e.g. train.experiments.pusher:PusherEnv for a CPU learning check)")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--profile", action=argparse.BooleanOptionalAction, default=None,
                 help="time rollout vs update (one extra compile; default: on for GPU, off for --quick)")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  p.add_argument("--tag", default="", help="suffix of the result files, e.g. 'long_lagrangian' → rl_<task>_<device>_long_lagrangian.md")
  p.add_argument("--combine", nargs="+", metavar="RUN=FILE.json",
                  help="no training: write one table from finished runs of earlier calls (needs --tag)")
  p.add_argument("--work-dir", default=None, help="run directories with checkpoints (default: /tmp/rl_place_plate)")
  args = p.parse_args(argv)
  base = QUICK if args.quick else GPU
  for k, v in base.items():
    if getattr(args, k, None) is None:
      setattr(args, k, v)
  if args.profile is None:
    args.profile = not args.quick
  args.runs = [r.strip() for r in args.runs.split(",") if r.strip()]
  if args.tag and not all(c.isalnum() or c in "_-" for c in args.tag):
    p.error(f"--tag: letters, digits, '_' and '-' only, got {args.tag!r}")
  if args.combine:
    if not args.tag:
      p.error("--combine: give --tag for the combined table's file name")
    pairs = []
    for item in args.combine:
      run, sep, path = item.partition("=")
      if not sep or run not in RUNS:
        p.error(f"--combine: expected RUN=FILE.json with RUN in {RUNS}, got {item!r}")
      if not os.path.isfile(path):
        p.error(f"--combine: {run}: no such file {path!r}")
      pairs.append((run, path))
    args.combine = pairs
  bad = [r for r in args.runs if r not in RUNS]
  if bad:
    p.error(f"--runs: unknown {bad}; choose from {RUNS}")
  return args


def device_info():
  import jax

  d = jax.devices()[0]
  kind = getattr(d, "device_kind", d.platform)
  slug = "cpu" if d.platform == "cpu" else "".join(c if c.isalnum() else "_" for c in kind.lower()).strip("_")
  name = f"{kind} ({d.platform}, {jax.device_count()} device(s))"
  if d.platform == "cpu":
    name = f"{platform.processor() or platform.machine()} CPU, {os.cpu_count()} cores ({kind})"
  return slug, name


def time_to_target(history, safe=0.8, completion=0.8):
  """Wall-clock (s, from the run's start) of the first evaluation with safe ≥ 0.8 and completion ≥ 0.8."""
  for r in history:
    if (r.get("eval/safe_completion") or 0) >= safe and (r.get("eval/completion") or 0) >= completion:
      return r["wall_time"], r["env_steps"]
  return None, None


def write_results(path_base, payload):
  with open(path_base + ".json", "w") as f:
    json.dump(payload, f, indent=1)
  lines = [
      f"# {payload['task']} from scratch: PPO task-only vs damage penalty vs PPO-Lagrangian ({payload['device']})",
      "",
      f"Date: {payload['date']}. Command: `{payload['command']}`",
      "",
      f"Task `{payload['task']}` (obs_mode={payload['obs_mode']}), episode length {payload['episode_length']}; "
      f"each run evaluated on {payload['eval_episodes']} episodes of its deterministic policy. "
      "Safe completion = completed and every tracked entity's final health > 95 (DAMAGE_MODEL.md §7).",
      "",
      "| run | completion | safe completion | avg env health | episode cost | env-steps | wall-clock (s) "
      "| train throughput (env-steps/s) | time to ≥80 % safe (s) | final λ |",
      "|---|---|---|---|---|---|---|---|---|---|",
  ]
  for name, r in payload["runs"].items():
    e = r["final_eval"]
    t80 = "—" if r["time_to_80_safe_s"] is None else f"{r['time_to_80_safe_s']:.0f}"
    lam = f"{r['final_lambda']:.3g}" if r["label"].startswith("PPO-Lagrangian") else "—"
    lines.append(
        f"| {r['label']} | {e['completion']:.1%} | {e['safe_completion']:.1%} | {e['avg_env_health']:.1f} "
        f"| {e['episode_cost']:.2f} | {r['env_steps']:,} | {r['wall_time_s']:.0f} | {r['throughput']:,.0f} "
        f"| {t80} | {lam} |")
  lines += ["", "Targets: task-only safe completion ≤ 20 %; both damage-aware runs ≥ 80 % safe with ≥ 80 % "
            "completion; on one H100 damage-aware ≥ 80 % safe in ≤ 5 min and ≥ 100 k env-steps/s.", ""]
  lines += ["## Where the time goes", "",
            "Seconds per run: compile (first training iteration incl. tracing; first evaluation), training "
            "iterations, evaluations, "
            "checkpoints, host-side logging/transfers. Per iteration (profile): rollout = env step + policy "
            "inference over all envs; update = reward shaping + normaliser + SGD epochs.", "",
            "| run | compile (train, eval) | iterations | eval | checkpoint | host | iteration (s) | rollout (s) | update (s) "
            "| rollout share |", "|---|---|---|---|---|---|---|---|---|---|"]
  for name, r in payload["runs"].items():
    t = r["timings"]
    it = t.get("profile/iteration")
    prof = (f"{it:.3f} | {t['profile/rollout']:.3f} | {t['profile/update']:.3f} | "
            f"{t['profile/rollout'] / it:.0%}") if it else "— | — | — | —"
    lines.append(f"| {r['label']} | {t['compile']:.1f}, {t.get('eval_compile', 0):.1f} | {t['iterations']:.1f} | {t['eval']:.1f} | "
                 f"{t['checkpoint']:.1f} | {t['host']:.2f} | {prof} |")
  if payload.get("bottleneck"):
    lines += ["", payload["bottleneck"]]
  lines += ["", "## Settings", "", "```json", json.dumps(payload["settings"], indent=1), "```", ""]
  lines += ["Curves (task return and damage per episode, success rates, λ): " +
            ", ".join(f"`{os.path.basename(r['curves'])}`" for r in payload["runs"].values() if r.get("curves")), ""]
  if payload.get("notes"):
    lines += ["## Notes", ""] + [f"- {n}" for n in payload["notes"]] + [""]
  with open(path_base + ".md", "w") as f:
    f.write("\n".join(lines))


def combine(args, argv=None) -> int:
  """One results table from runs of earlier calls; each row keeps its source and command."""
  payload, sources = None, []
  for run, path in args.combine:
    with open(path) as f:
      src = json.load(f)
    if run not in src["runs"]:
      raise SystemExit(f"--combine: {path} has no run {run!r} (it has {sorted(src['runs'])})")
    if payload is None:
      payload = {k: v for k, v in src.items() if k not in ("runs", "notes", "bottleneck", "script_wall_time_s")}
      payload.update(runs={}, notes=[], settings={"per_run": {}})
    elif (src["device"], src["task"], src["eval_episodes"]) != (payload["device"], payload["task"], payload["eval_episodes"]):
      raise SystemExit(f"--combine: {path} is from another device/task/evaluation size than the first file")
    payload["runs"][run] = src["runs"][run]
    payload["settings"]["per_run"][run] = src["settings"]
    if src.get("bottleneck") and "bottleneck" not in payload:
      payload["bottleneck"] = src["bottleneck"]
    sources.append(f"{src['runs'][run]['label']}: `{os.path.basename(path)}`, run on {src['date']} by `{src['command']}`")
  payload["command"] = " ".join(shlex.quote(a) for a in ["benchmarks/place_plate_rl.py"] + list(sys.argv[1:] if argv is None else argv))
  payload["date"] = time.strftime("%Y-%m-%d %H:%M")
  payload["notes"] = ["Rows come from separate calls of this script (one 10-minute device call cannot hold three "
                      "runs of 4–5 min each); same code path and PPO settings, see 'per_run' above:"] + sources
  base = os.path.join(args.results_dir, f"rl_{payload['task']}_combined_{args.tag}")
  write_results(base, payload)
  print(f"wrote {base}.md / .json", flush=True)
  return 0


def main(argv=None) -> int:
  args = parse(argv)
  if args.combine:
    return combine(args, argv)
  t_script = time.perf_counter()
  import jax

  import train
  from train import ppo

  slug, device = device_info()
  os.makedirs(args.results_dir, exist_ok=True)
  task_slug = args.task.rsplit(":", 1)[-1].lower() if ":" in args.task else args.task
  base = os.path.join(args.results_dir, f"rl_{task_slug}_{slug}" + (f"_{args.tag}" if args.tag else ""))
  work = args.work_dir or os.path.join("/tmp", f"rl_{task_slug}_{slug}")
  task_kwargs = {"obs_mode": args.obs_mode} if args.task == "place_plate" else None
  episode_length = ppo.task_episode_length(ppo.resolve_task(args.task, task_kwargs)[0])
  settings = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items()
              if k not in ("results_dir", "work_dir", "runs", "tag")}
  payload = {
      "device": device, "date": time.strftime("%Y-%m-%d %H:%M"), "jax": jax.__version__,
      "command": " ".join(shlex.quote(a) for a in [os.path.relpath(sys.argv[0], ROOT)] + list(sys.argv[1:] if argv is None else argv)),
      "task": args.task, "obs_mode": args.obs_mode if task_kwargs else None, "episode_length": episode_length, "eval_episodes": args.eval_episodes,
      "settings": settings, "runs": {}, "notes": [],
  }
  if args.quick and args.task == "place_plate":
    payload["notes"].append("--quick: CPU plumbing run at toy size; the success numbers mean nothing, "
                            "the throughput is this machine's (2 cores shared with other jobs).")
  elif args.quick:
    payload["notes"].append(f"--quick on {args.task}: a toy env small enough to learn on this CPU (2 cores "
                            "shared with other jobs); it checks that the learning machinery separates the "
                            "three objectives, nothing about Place Plate.")
  specs = {
      "task_only": dict(label="task reward only (w=0)", damage_weight=0.0, budget=None),
      "penalty": dict(label=f"damage penalty (w={args.damage_weight:g})", damage_weight=args.damage_weight, budget=None),
      "lagrangian": dict(label=f"PPO-Lagrangian (ĉ={args.budget:g})", damage_weight=0.0, budget=args.budget),
  }
  todo = [r for r in RUNS if r in args.runs]
  for i, name in enumerate(todo):
    spec = specs[name]
    limit = args.budget_seconds
    if args.total_seconds is not None:
      # Split what is left evenly over the remaining runs; keep ~20 s per run for the final
      # evaluation, checkpoint and plot that follow the time limit.
      left = args.total_seconds - (time.perf_counter() - t_script)
      limit = min(limit, left / (len(todo) - i) - 20.0)
      if limit < 30:
        payload["notes"].append(f"{name}: skipped, {left:.0f} s left of --total-seconds")
        break
    print(f"== {name}: {spec['label']}, time limit {limit:.0f} s", flush=True)
    res = train.train(
        args.task, preset="legacy", task_kwargs=task_kwargs, damage_weight=spec["damage_weight"], budget=spec["budget"],
        lagrange_lr=args.lagrange_lr, lagrange_max=args.lagrange_max, num_envs=args.num_envs, num_timesteps=args.timesteps, seed=args.seed,
        policy_hidden_sizes=args.policy_hidden_sizes, value_hidden_sizes=args.value_hidden_sizes,
        learning_rate=args.learning_rate, entropy_cost=args.entropy_cost, discounting=args.discounting,
        unroll_length=args.unroll_length, num_minibatches=args.num_minibatches, batch_size=args.batch_size,
        num_updates_per_batch=args.num_updates_per_batch, num_eval_envs=args.eval_episodes,
        eval_every=args.eval_every, checkpoint_every=0, out_dir=os.path.join(work, name),
        time_limit=limit, profile=args.profile and i == 0, progress=True,
    )
    curves = f"{base}_{name}.png"
    src = os.path.join(res.out_dir, "curves.png")
    if os.path.exists(src):
      with open(src, "rb") as fi, open(curves, "wb") as fo:
        fo.write(fi.read())
    t80, s80 = time_to_target(res.history)
    payload["runs"][name] = {
        "label": spec["label"], "damage_weight": spec["damage_weight"], "budget": spec["budget"],
        "final_eval": res.final_eval, "env_steps": res.env_steps, "iterations": res.iterations,
        "wall_time_s": res.wall_time, "train_time_s": res.train_time, "throughput": res.throughput,
        "overall_steps_per_s": res.env_steps / res.wall_time, "time_to_80_safe_s": t80,
        "env_steps_to_80_safe": s80, "final_lambda": float(res.train_state.lagrange[0]),
        "timings": res.timings, "stopped_by_time_limit": res.stopped_early,
        "curves": os.path.basename(curves), "history": res.history,
    }
    t = res.timings
    if "profile/iteration" in t:
      share = t["profile/rollout"] / t["profile/iteration"]
      payload["bottleneck"] = (
          f"Profile ({name}): one iteration of {res.config.steps_per_iteration:,} env-steps takes "
          f"{t['profile/iteration']:.3f} s, of which the rollout (env step + policy inference) is "
          f"{t['profile/rollout']:.3f} s ({share:.0%}) and the update {t['profile/update']:.3f} s; "
          f"the limiting part is the {'env step' if share >= 0.5 else 'network update'}. "
          f"Rollout-only throughput: {res.config.steps_per_iteration / t['profile/rollout']:,.0f} env-steps/s.")
    write_results(base, payload)
    print(json.dumps({k: v for k, v in payload["runs"][name].items() if k != "history"}, indent=1), flush=True)
  payload["script_wall_time_s"] = time.perf_counter() - t_script
  write_results(base, payload)
  print(f"wrote {base}.md / .json", flush=True)
  return 0


if __name__ == "__main__":
  sys.exit(main())

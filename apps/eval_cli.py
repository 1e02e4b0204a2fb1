"""``mjx-damage eval``: evaluate a policy on a task for N episodes (table + JSON).

``mjx-damage eval --task TASK --policy SPEC --episodes N [--fragility F] [--seed S]
[--out result.json]``; task and policy names: :mod:`apps.resolve`; the
evaluation itself: :func:`train.evaluate.evaluate`.
"""

from __future__ import annotations

import os
import sys
import time

import jax

from apps import resolve as R
from mjx_damage import outputs, runtime
from mjx_damage.io import write_json
import tasks
from train import evaluate as E
from train.cliargs import Parser, heartbeat, say_compiling

# Rough first-compile times of a task's evaluation (s; the persistent cache makes later runs start in seconds).
COMPILE_S = {"cpu": 40, "gpu": 60}


def build_parser() -> Parser:
  ap = Parser(prog="mjx-damage eval", description="Evaluate a policy on a task for N episodes.")
  R.add_task_policy_arguments(ap)
  R.add_task_override_arguments(ap)
  R.add_backend_argument(ap, default="auto", warp=True)
  ap.add_argument("--native-envs", type=int, default=256,
                  help="native backend: episodes stepped at once (at most --episodes)")
  ap.add_argument("--episodes", type=int, default=64)
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--fragility", type=float, default=1.0, help="thresholds ÷ f, scales × f (default 1)")
  ap.add_argument("--episode-length", type=int, default=None, help="env steps (default: the task's)")
  ap.add_argument("--safe-threshold", type=float, default=95.0)
  ap.add_argument("--out", default=None,
                  help="result JSON path (default: runs/eval-<task>-<time>/result.json, a new folder)")
  ap.add_argument("--overwrite", action="store_true", help="replace an existing --out")
  ap.add_argument("--per-episode", action="store_true", help="include per-episode arrays in the JSON")
  ap.add_argument("--matmul-precision", default=None, choices=runtime.MATMUL_PRECISIONS,
                  help="float32 matrix products (physics, policy) at the backend's default precision (TF32 on a "
                       "recent NVIDIA GPU) or at full float32, as a CPU computes them (default: JAX's setting)")
  return ap


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:  # everything the user gave is checked before a task is built or compiled
    R.check_task(args.task)
    R.check_backend(args.backend, warp=True)
    if args.native_envs < 1:
      raise ValueError(f"native_envs: must be >= 1, got {args.native_envs}")
    R.parse_policy_spec(args.policy)
    E.check_args(args.episodes, args.fragility, args.safe_threshold, seed=args.seed)
    if args.episode_length is not None and args.episode_length < 1:
      raise ValueError(f"episode_length: must be >= 1, got {args.episode_length}")
    if args.out is not None:
      outputs.check_new([args.out], "--out", args.overwrite)
    if args.matmul_precision is not None:  # before anything is traced
      runtime.use_matmul_precision(args.matmul_precision)
    out = args.out or os.path.join(outputs.run_dir("eval", args.task), "result.json")
    overrides = R.task_overrides(args.task, R.policy_task_kwargs(args.policy, args.task), args.robot, args.task_arg)
    # --backend warp: the task is made on MuJoCo Warp, every episode of the call in its one batch
    warp_kw = R.warp_overrides(args.task, args.backend, args.episodes, len(jax.devices()))
    env = R.make_task(args.task, **overrides, **warp_kw)
    policy = R.make_policy(args.policy, env)
    backend = R.pick_backend(args.backend, env, policies=[args.policy])
    env = R.on_backend(env, backend, min(args.native_envs, args.episodes))
    episode_length = args.episode_length or R.episode_length_of(env, args.task)
  except ValueError as e:
    ap.error(str(e))
  platform = jax.default_backend()
  print(f"eval: task {args.task}, policy {args.policy}, {args.episodes} episodes x {episode_length} steps, "
        f"fragility {args.fragility:g}, seed {args.seed}, backend {backend}"
        f"{R.auto_reason(args.backend, backend, [args.policy])}, "
        f"device {platform} x {jax.device_count()}"
        f"{runtime.matmul_label() and ', ' + runtime.matmul_label()}; "
        f"output {out}", flush=True)
  say_compiling(COMPILE_S, platform)
  t0 = time.perf_counter()
  # MuJoCo Warp's kernels are FFI calls, which jax.export cannot store: a Warp run keeps no traced program
  program = None if backend == "warp" else R.program_description("eval", args.task, args.policy, backend=backend)
  with heartbeat("eval"):
    res = E.evaluate(env, policy, args.episodes, args.seed, fragility=args.fragility,
                     episode_length=episode_length, safe_threshold=args.safe_threshold,
                     program=program, program_roots=R.PROGRAM_ROOTS)
  wall = time.perf_counter() - t0
  title = (f"{args.task} / {args.policy}: {args.episodes} episodes x {res['episode_length']} steps, "
           f"fragility {args.fragility:g}, seed {args.seed}, {res['devices']} device(s), {wall:.1f} s incl. compile")
  print(E.format_table(res["metrics"], title))
  if res["program"] == "loaded":
    print("traced program loaded from the cache (no tracing, no compiling)")
  result = {
      "task": args.task, "task_kwargs": tasks.recorded_kwargs(args.task, overrides), "policy": args.policy,
      "episodes": args.episodes,
      "seed": args.seed,
      "fragility": args.fragility, "episode_length": res["episode_length"], "backend": backend,
      "backend_requested": args.backend,
      "matmul_precision": runtime.matmul_precision(),
      "command": "mjx-damage eval " + " ".join(sys.argv[1:] if argv is None else argv),
      "metrics": res["metrics"], "wall_s": wall,
  }
  if args.per_episode:
    result["per_episode"] = res["per_episode"]  # write_json turns numpy arrays into lists
  write_json(out, result, indent=1)
  print(f"outputs: {out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

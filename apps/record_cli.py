"""``mjx-damage record``: N episodes of a policy or operator → a robomimic-layout HDF5 dataset.

    mjx-damage record --task pick_egg --policy operator:careless --episodes 256 --out demos.hdf5

Policy specs: ``operator:careful``, ``operator:careless``, ``operator:mixed``
(:mod:`tasks.operators`) and every spec of :mod:`apps.resolve` (``scripted:safe``,
``scripted:unsafe``, ``random``, ``zero``, ``checkpoint:RUN``). Without ``--out`` the
dataset goes to a new ``runs/record-<task>-<time>/demos.hdf5``; an existing file is
refused unless ``--overwrite`` is given. Recording itself: :func:`train.record.record`.
"""

from __future__ import annotations

import json
import os
import sys
import time

from apps import resolve as R
from mjx_damage import outputs
import tasks
from tasks import operators
from train.cliargs import Parser, heartbeat, say_compiling
from train.record import DEFAULT_CHUNK

COMPILE_S = {"cpu": 30, "gpu": 60}  # rough first compile of one task's recording program, s


def make_recorder_policy(spec: str, env):
  """A policy spec string → an Operator or a ``policy(state, rng)``."""
  kind, _, arg = spec.partition(":")
  if kind == "operator":
    return operators.make(env, arg)
  return R.make_policy(spec, env)


def check_spec(spec: str) -> None:
  kind, _, arg = spec.partition(":")
  if kind == "operator":
    if arg not in operators.CONDITIONS:
      raise ValueError(f"policy: unknown operator {arg!r}; valid: "
                       + ", ".join(f"operator:{c}" for c in operators.CONDITIONS))
    return
  R.parse_policy_spec(spec)


def build_parser() -> Parser:
  p = Parser(prog="mjx-damage record", description=__doc__.split("\n\n")[0])
  p.add_argument("--task", required=True, help="registered task name")
  p.add_argument("--policy", required=True,
                 help="operator:careful|careless|mixed, scripted:safe|unsafe, random, zero, checkpoint[+sample|+mean]:RUN[#SEED]")
  R.add_task_override_arguments(p)
  p.add_argument("--episodes", type=int, required=True, help="episodes to record")
  p.add_argument("--out", default=None, help="output .hdf5 (default: runs/record-<task>-<time>/demos.hdf5)")
  p.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--episode-length", type=int, default=None, help="env steps (default: the task's)")
  p.add_argument("--chunk", type=int, default=DEFAULT_CHUNK, help="episodes per compiled call")
  return p


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:  # everything the user gave is checked before a task is built or compiled
    if args.out is not None:
      outputs.check_new([args.out], "--out", args.overwrite)
    R.check_task(args.task)
    check_spec(args.policy)
    for name in ("episodes", "chunk"):
      if getattr(args, name) < 1:
        raise ValueError(f"{name}: must be >= 1, got {getattr(args, name)}")
    if args.episode_length is not None and args.episode_length < 1:
      raise ValueError(f"episode_length: must be >= 1, got {args.episode_length}")
    # a checkpoint's task overrides (its obs_mode …), so the env matches the policy, then the command line's
    trained = {} if args.policy.startswith("operator:") else R.policy_task_kwargs(args.policy, args.task)
    overrides = R.task_overrides(args.task, trained, args.robot, args.task_arg)
    env = R.make_task(args.task, **overrides)  # unknown robots and task arguments are refused here
  except ValueError as e:
    ap.error(str(e))
  import jax
  import numpy as np

  from mjx_damage import data as D
  from train.record import record_chunks

  out = args.out or os.path.join(outputs.run_dir("record", args.task), "demos.hdf5")
  policy = make_recorder_policy(args.policy, env)
  platform = jax.default_backend()
  print(f"record: task {args.task}, policy {args.policy}, {args.episodes} episodes, device {platform}; "
        f"output {out}", flush=True)
  say_compiling(COMPILE_S, platform)
  flags = []  # per chunk: success, safe (episode flags), transitions

  def counted(chunks):
    for ds in chunks:
      flags.append((ds.success, ds.safe, D.num_transitions(ds)))
      yield ds

  t0 = time.perf_counter()
  with heartbeat("record"):
    # each chunk is written while the device records the next one
    D.save_chunks(out, counted(record_chunks(
        env, policy, args.episodes, args.seed, task=args.task,
        episode_length=args.episode_length or R.episode_length_of(env, args.task), chunk=args.chunk,
        label=args.policy.replace("operator:", ""), env_config=tasks.recorded_kwargs(env, overrides),
        log=lambda m: print(m, flush=True))),
      overwrite=args.overwrite)
  total_s = time.perf_counter() - t0
  success = np.concatenate([f[0] for f in flags])
  safe = np.concatenate([f[1] for f in flags])
  n = sum(f[2] for f in flags)
  print(json.dumps({"out": out, "episodes": int(success.size), "transitions": n,
                    "success_rate": float(np.mean(success)), "safe_rate": float(np.mean(safe)),
                    "safe_success_rate": float(np.mean(success & safe)),
                    "total_s_incl_compile": round(total_s, 2), "transitions_per_s": round(n / total_s, 1)}))
  print(f"outputs: {out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

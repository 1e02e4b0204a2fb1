"""``mjx-damage bc``: behaviour cloning of a recorded dataset into a PPO actor checkpoint.

    mjx-damage record --task pour_water --policy operator:mixed --episodes 50 --out demos.hdf5
    mjx-damage bc --dataset demos.hdf5 --out runs/bc --seeds 0,1 --min-health 95
    mjx-damage eval --task pour_water --policy checkpoint:runs/bc
    mjx-damage train --task pour_water --init-from runs/bc --critic-warmup 20 --damage-weight 2

The actor has the trainer's network (``--preset``, ``--policy-hidden``), so
``train --init-from`` fine-tunes it with PPO (:mod:`train.bc_actor`). ``--min-health``
keeps only episodes whose every entity stayed above that health (the paper's
episode filter, :func:`train.curate.filter_episodes`). The output folder is refused
if it exists (``--overwrite`` replaces it); without ``--out`` a new
``runs/bc-<task>-<time>/`` is made.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time

import jax
import numpy as np

from mjx_damage import data as D
from mjx_damage import outputs
import tasks
from train import bc_actor as BA
from train import curate
from train.cli import _ints
from train.cliargs import Parser, heartbeat, say_compiling
from train.config import PRESETS, PPOConfig

COMPILE_S = {"cpu": 20, "gpu": 20}


def build_parser() -> Parser:
  p = Parser(prog="mjx-damage bc", description=__doc__)
  p.add_argument("--dataset", required=True, help="HDF5 file written by mjx-damage record")
  p.add_argument("--out", default=None, help="run directory (default: runs/bc-<task>-<time>/, a new folder)")
  p.add_argument("--overwrite", action="store_true", help="replace the checkpoint in an existing --out")
  p.add_argument("--preset", default="playground", choices=sorted(PRESETS), help="network settings (train/config.py)")
  p.add_argument("--policy-hidden", type=_ints, default=None, help="actor MLP sizes (default: the preset's)")
  p.add_argument("--seeds", type=_ints, default=(0,), help="one actor per seed, in one compiled call")
  p.add_argument("--steps", type=int, default=3000, help="gradient steps")
  p.add_argument("--batch", type=int, default=256, help="transitions per gradient step")
  p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate")
  p.add_argument("--min-health", type=float, default=None,
                 help="keep only episodes whose entities all stay above this health (default: keep all)")
  return p


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:
    if not os.path.isfile(args.dataset):
      raise ValueError(f"--dataset: no such file {args.dataset!r}")
    if args.min_health is not None and not 0 <= args.min_health <= 100:
      raise ValueError(f"--min-health: must be in [0, 100], got {args.min_health}")
    if not (np.isfinite(args.lr) and args.lr > 0):
      raise ValueError(f"--lr: must be > 0, got {args.lr}")
    if args.out is not None:
      outputs.check_new([args.out], "--out", args.overwrite, folder=True)
    ds = D.load(args.dataset)
    if args.min_health is not None:
      ds = curate.filter_episodes(ds, args.min_health)
    overrides = {} if args.policy_hidden is None else {"policy_hidden_sizes": tuple(args.policy_hidden)}
    cfg = PPOConfig.preset(args.preset, **overrides)
    cfg = dataclasses.replace(cfg, seeds=tuple(args.seeds)).validate()
  except ValueError as e:
    ap.error(str(e))
  task = ds.env_name
  out = args.out or outputs.run_dir("bc", task)
  print(f"bc: dataset {args.dataset} (task {task}, {ds.num_episodes} episodes kept), actor "
        f"{list(cfg.policy_hidden_sizes)}, seeds {list(cfg.seeds)}, {args.steps} steps x {args.batch}; "
        f"output {out}", flush=True)
  say_compiling(COMPILE_S, jax.default_backend())
  t0 = time.perf_counter()
  with heartbeat("bc"):
    fit = BA.fit_actor(ds, cfg, seeds=cfg.seeds, steps=args.steps, batch=args.batch, lr=args.lr)
  path = BA.save(fit, out, task=task, task_kwargs=tasks.stored_kwargs(task, json.loads(ds.env_config)),
                 extra={"dataset": os.path.abspath(args.dataset), "min_health": args.min_health})
  loss = np.asarray(fit.losses)
  print(f"fitted in {time.perf_counter() - t0:.1f} s; negative log-likelihood per action dim, first -> last 100 "
        f"steps: {loss[:, :100].mean():.3f} -> {loss[:, -100:].mean():.3f}")
  print(f"outputs: {path} (mjx-damage eval --policy checkpoint:{out}; mjx-damage train --init-from {out})")
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""Calibrate and check ``train.memory``: XLA's own memory analysis vs the estimate, per env.

    .venv/bin/python benchmarks/memory_estimate.py                         # CPU, 3 tasks
    .venv/bin/python benchmarks/memory_estimate.py --tasks place_plate --sizes 8,32
    .venv/bin/python benchmarks/memory_estimate.py --robot panda          # → memory_estimate_panda_<device>

For each task: compile the evaluation program (``train.evaluate.Evaluator``) and one
training iteration (``train.iteration.Trainer``, S = 1 seed, num_rollouts = 1) at
two batch sizes, read ``compiled.memory_analysis()`` (arguments + outputs +
temporaries, bytes), and take the slope per env between the sizes — the part that
grows with the batch, which is what the estimate must bound. Reported: that
slope divided by one env's state bytes (the factor ``train.memory`` needs), and
the estimate's slope; ``bound`` says whether the estimate is at least the
measurement. Writes ``benchmarks/results/memory_estimate_<device>.{json,md}`` (``--robot`` other
than the gripper: ``memory_estimate_<robot>_<device>``, the robot in the JSON).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
  sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (first: XLA flags, compilation cache)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from mjx_damage.runtime import device_info  # noqa: E402
from train import memory as MEM  # noqa: E402
from train import evaluate as E  # noqa: E402
from train.config import PPOConfig  # noqa: E402
from train.iteration import Trainer  # noqa: E402


def total_bytes(compiled) -> int:
  m = compiled.memory_analysis()
  return int(m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes - m.alias_size_in_bytes)


def eval_program_bytes(env, n: int) -> int:
  ev = E.Evaluator(env, E.zero_policy(env.action_size), 20, devices=jax.devices()[:1])
  keys = jax.ShapeDtypeStruct((n, 2), jnp.uint32, sharding=ev.sharding)
  frag = jax.ShapeDtypeStruct((n,), jnp.float32, sharding=ev.sharding)
  return total_bytes(ev._fn.lower((), keys, frag).compile())


def train_config(n: int, episode_length: int) -> PPOConfig:
  return PPOConfig.preset("playground", num_envs=n, batch_size=n // 4, num_minibatches=4, unroll_length=10,
                          episode_length=episode_length, num_timesteps=10 * n).validate()


def train_program_bytes(env, n: int) -> tuple[int, PPOConfig, Trainer]:
  cfg = train_config(n, 20)
  trainer = Trainer(env, cfg)
  ts = jax.eval_shape(trainer.init_states, jnp.zeros((1,), jnp.int32))
  fn = jax.jit(jax.vmap(trainer.train_iteration), donate_argnums=0)
  return total_bytes(fn.lower(ts).compile()), cfg, trainer


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--tasks", default="place_plate,pour_water,shelve_item")
  ap.add_argument("--sizes", default="8,32", help="two batch sizes (envs / episodes), multiples of 4")
  ap.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  ap.add_argument("--robot", default="gripper",
                  help=f"robot of every task, one of {', '.join(tasks.robots.names())} (default: gripper, "
                       "the robot of the committed results)")
  args = ap.parse_args(argv)
  # checked before anything compiles; the gripper is passed explicitly (tasks.robots.DEFAULT may change)
  try:
    tasks.check_robot(args.robot, args.tasks.split(","), "--robot")
  except ValueError as e:
    ap.error(str(e))
  lo, hi = (int(s) for s in args.sizes.split(","))
  slug, desc = device_info()
  rows = []
  for task in args.tasks.split(","):
    env = tasks.make(task, robot=args.robot)
    fp = MEM.footprint(env)
    state = fp.state
    t0 = time.perf_counter()
    e_lo, e_hi = eval_program_bytes(env, lo), eval_program_bytes(env, hi)
    (t_lo, _, _), (t_hi, cfg, trainer) = train_program_bytes(env, lo), train_program_bytes(env, hi)
    eval_slope = (e_hi - e_lo) / (hi - lo)
    train_slope = (t_hi - t_lo) / (hi - lo)
    # per env of the training batch: num_rollouts = 1, so sequences = num_envs
    est_eval = MEM.eval_bytes(state, 1, fp.particles)
    est_train = MEM.train_bytes(state, trainer.obs_size, trainer.action_size, 1, 1, cfg.unroll_length,
                                particles=fp.particles)
    data = cfg.unroll_length * MEM.transition_bytes(trainer.obs_size, trainer.action_size)
    row = {
        "task": task, "state_bytes": state, "liquid_particles": fp.particles, "obs_size": trainer.obs_size, "action_size": trainer.action_size,
        "eval_bytes": {str(lo): e_lo, str(hi): e_hi}, "train_bytes": {str(lo): t_lo, str(hi): t_hi},
        "eval_slope_per_env": eval_slope, "train_slope_per_env": train_slope,
        "eval_factor": eval_slope / state,
        "train_state_factor_given_data_factor": (train_slope - data * MEM.K_TRAIN_DATA) / state,
        "estimate_eval_per_env": est_eval, "estimate_train_per_env": est_train,
        "eval_bound": est_eval >= eval_slope, "train_bound": est_train >= train_slope,
        "seconds": time.perf_counter() - t0,
    }
    rows.append(row)
    print(f"{task}: state {state / 1024:.1f} KiB; eval {eval_slope / 1024:.1f} KiB/env (x{row['eval_factor']:.2f}), "
          f"estimate {est_eval / 1024:.1f}; train {train_slope / 1024:.1f} KiB/env, estimate {est_train / 1024:.1f}",
          flush=True)
  cmd = "python benchmarks/memory_estimate.py " + " ".join(sys.argv[1:] if argv is None else argv)
  result = {"command": cmd.strip(), "device": desc, "sizes": [lo, hi], "factors": {
      "K_EVAL": MEM.K_EVAL, "K_TRAIN_STATE": MEM.K_TRAIN_STATE, "K_TRAIN_DATA": MEM.K_TRAIN_DATA,
      "K_PAIRS": MEM.K_PAIRS}, "rows": rows}
  robot = "" if args.robot == "gripper" else f"{args.robot}_"  # gripper: the committed results' names and fields
  if robot:
    result["robot"] = args.robot
  os.makedirs(args.results_dir, exist_ok=True)
  base = os.path.join(args.results_dir, f"memory_estimate_{robot}{slug}")
  write_json(base + ".json", result)
  lines = [f"# Memory estimate vs XLA's memory analysis ({desc})", "", f"Command: `{result['command']}`", "",
           f"Slope per env between {lo} and {hi} envs/episodes of XLA's `memory_analysis()` (arguments + outputs "
           "+ temporaries − aliased), against `train.memory`'s estimate per env "
           f"(K_EVAL {MEM.K_EVAL:g}, K_TRAIN_STATE {MEM.K_TRAIN_STATE:g}, K_TRAIN_DATA {MEM.K_TRAIN_DATA:g}, "
           f"K_PAIRS {MEM.K_PAIRS:g} for P liquid particles). "
           "Training: one seed, num_rollouts 1 (sequences = envs), unroll 10.", "",
           "| task | state KiB | P | eval KiB/env (measured) | factor | estimate | bound | train KiB/env (measured) | "
           "implied K_TRAIN_STATE | estimate | bound |", "|---|---|---|---|---|---|---|---|---|---|---|"]
  for r in rows:
    lines.append(f"| {r['task']} | {r['state_bytes'] / 1024:.1f} | {r['liquid_particles']} | "
                 f"{r['eval_slope_per_env'] / 1024:.1f} | "
                 f"{r['eval_factor']:.2f} | {r['estimate_eval_per_env'] / 1024:.1f} | {'yes' if r['eval_bound'] else '**no**'} | "
                 f"{r['train_slope_per_env'] / 1024:.1f} | {r['train_state_factor_given_data_factor']:.2f} | "
                 f"{r['estimate_train_per_env'] / 1024:.1f} | {'yes' if r['train_bound'] else '**no**'} |")
  write_text(base + ".md", "\n".join(lines) + "\n")
  print(f"wrote {base}.json, {base}.md")
  return 0 if all(r["eval_bound"] and r["train_bound"] for r in rows) else 1


if __name__ == "__main__":
  sys.exit(main())

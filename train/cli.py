"""``mjx-damage train``: PPO / PPO-Lagrangian on a registered task.

Examples::

    mjx-damage train --task place_plate --damage-weight 2 --num-envs 2048 --timesteps 5e6 --out runs/pp_w2
    mjx-damage train --task place_plate --budget 5 --out runs/pp_lag          # PPO-Lagrangian, ĉ = 5
    mjx-damage train --task place_plate --budget 5 --out runs/pp_lag --resume # continue after an interruption
"""

from __future__ import annotations

import argparse
import json
import sys


def _int(text: str) -> int:
  """Integers that may be written as 1e6 / 1_000_000."""
  v = float(text.replace("_", ""))
  if v != int(v):
    raise argparse.ArgumentTypeError(f"not an integer: {text}")
  return int(v)


def _sizes(text: str) -> tuple[int, ...]:
  try:
    return tuple(int(s) for s in text.split(",") if s.strip())
  except ValueError as e:
    raise argparse.ArgumentTypeError(f"comma-separated layer sizes, got {text!r}") from e


def build_parser() -> argparse.ArgumentParser:
  p = argparse.ArgumentParser(prog="mjx-damage train", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--task", required=True, help="registered task name, or package.module:EnvClass")
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="override passed to tasks.make (repeatable), e.g. --task-arg obs_mode='\"paper\"'")
  p.add_argument("--out", dest="out_dir", required=True, help="run directory (config, metrics, checkpoint, curves)")
  p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.npz")
  p.add_argument("--damage-weight", type=float, default=0.0, help="w in r = (r_task - (w + λ)·cost)/(1 + λ); λ = 0 without --budget")
  p.add_argument("--budget", type=float, default=None, help="episode-cost budget ĉ: enables PPO-Lagrangian")
  p.add_argument("--lagrange-lr", type=float, default=0.1, help="λ ← clip(λ + lr·(J_c − ĉ), 0, λ_max) per iteration")
  p.add_argument("--lagrange-init", type=float, default=0.0)
  p.add_argument("--lagrange-max", type=float, default=5.0)
  p.add_argument("--num-envs", type=_int, default=1024)
  p.add_argument("--timesteps", dest="num_timesteps", type=_int, default=1_000_000)
  p.add_argument("--time-limit", type=float, default=None, help="stop training after this many seconds")
  p.add_argument("--seed", type=_int, default=0)
  p.add_argument("--episode-length", type=_int, default=None, help="default: the task's")
  p.add_argument("--unroll-length", type=_int, default=20)
  p.add_argument("--num-minibatches", type=_int, default=8)
  p.add_argument("--updates-per-batch", dest="num_updates_per_batch", type=_int, default=4)
  p.add_argument("--batch-size", type=_int, default=None, help="sequences per minibatch (default num_envs/num_minibatches)")
  p.add_argument("--policy-hidden", dest="policy_hidden_sizes", type=_sizes, default=(256, 256))
  p.add_argument("--value-hidden", dest="value_hidden_sizes", type=_sizes, default=(256, 256))
  p.add_argument("--activation", default="swish")
  p.add_argument("--lr", dest="learning_rate", type=float, default=3e-4)
  p.add_argument("--clip", dest="clipping_epsilon", type=float, default=0.2)
  p.add_argument("--gamma", dest="discounting", type=float, default=0.97)
  p.add_argument("--gae-lambda", type=float, default=0.95)
  p.add_argument("--entropy", dest="entropy_cost", type=float, default=1e-3)
  p.add_argument("--reward-scaling", type=float, default=1.0)
  p.add_argument("--eval-every", type=_int, default=0, help="env steps between evaluations (0: at the end)")
  p.add_argument("--checkpoint-every", type=_int, default=0, help="env steps between checkpoints (0: at the end)")
  p.add_argument("--eval-envs", dest="num_eval_envs", type=_int, default=128)
  p.add_argument("--no-progress", dest="progress", action="store_false")
  return p


def _task_kwargs(items) -> dict:
  out = {}
  for item in items:
    key, sep, value = item.partition("=")
    if not sep or not key:
      raise ValueError(f"--task-arg: expected KEY=JSON, got {item!r}")
    try:
      out[key] = json.loads(value)
    except json.JSONDecodeError:
      out[key] = value  # bare strings: obs_mode=paper
  return out


def main(argv=None) -> int:
  args = vars(build_parser().parse_args(argv))
  from train.ppo import train  # imports jax: keep --help fast

  task = args.pop("task")
  try:
    args["task_kwargs"] = _task_kwargs(args.pop("task_arg")) or None
    args["time_limit"] = args.pop("time_limit")
    result = train(task, **args)
  except ValueError as e:
    print(f"mjx-damage train: error: {e}", file=sys.stderr)
    return 2
  summary = {
      "out_dir": result.out_dir, "env_steps": result.env_steps, "wall_time_s": round(result.wall_time, 1),
      "train_throughput_steps_per_s": round(result.throughput, 1), "final_eval": result.final_eval,
  }
  print(json.dumps(summary, indent=1))
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""``mjx-damage train``: PPO / PPO-Lagrangian / PID-Lagrangian on a registered task, S seeds in one program.

Examples::

    mjx-damage train --task place_plate --damage-weight 2 --seeds 0,1,2,3,4 --timesteps 3e7 --out runs/pp_w2
    mjx-damage train --task place_plate --budget 2 --multiplier pid --out runs/pp_pid   # PID-Lagrangian, ĉ = 2
    mjx-damage train --task place_plate --preset paper --damage-weight 2 --out runs/pp_paper
    mjx-damage train --task place_plate --budget 2 --out runs/pp_lag --resume   # continue after an interruption

Every setting left out comes from ``--preset`` (playground: MuJoCo Playground's
PandaPickCube recipe; paper: the oopsieverse appendix; legacy: this trainer's
old defaults — train/config.py). Ctrl-C / SIGTERM writes a checkpoint and
exits with status 130; ``--resume`` continues it exactly.
"""

from __future__ import annotations

import argparse
import json
import sys

from train.config import MULTIPLIERS, PRESETS


def _int(text: str) -> int:
  """Integers that may be written as 1e6 / 1_000_000."""
  try:
    v = float(text.replace("_", ""))
  except ValueError:
    raise argparse.ArgumentTypeError(f"not an integer: {text}") from None
  if v != int(v):
    raise argparse.ArgumentTypeError(f"not an integer: {text}")
  return int(v)


def _ints(text: str) -> tuple[int, ...]:
  try:
    return tuple(_int(s.strip()) for s in text.split(",") if s.strip())
  except argparse.ArgumentTypeError:
    raise argparse.ArgumentTypeError(f"comma-separated integers, got {text!r}") from None


def _floats(text: str) -> tuple[float, ...]:
  try:
    return tuple(float(s) for s in text.split(",") if s.strip())
  except ValueError:
    raise argparse.ArgumentTypeError(f"comma-separated numbers, got {text!r}") from None


def _bool(text: str) -> bool:
  if text.lower() in ("1", "true", "yes", "on"):
    return True
  if text.lower() in ("0", "false", "no", "off"):
    return False
  raise argparse.ArgumentTypeError(f"true/false, got {text!r}")


# (flag, PPOConfig field, type, help). Left out → the preset's value.
CONFIG_FLAGS = (
    ("--damage-weight", "damage_weight", float, "w in r = (r_task − (w + λ)·cost)/(1 + λ); λ = 0 without --budget"),
    ("--budget", "budget", float, "episode-cost budget ĉ: enables the multiplier λ"),
    ("--multiplier", "multiplier", str, f"how λ follows the cost: {' | '.join(MULTIPLIERS)} (with --budget)"),
    ("--lagrange-lr", "lagrange_lr", float, "plain Lagrangian: λ ← clip(λ + lr·(J_c − ĉ), 0, λ_max)"),
    ("--lagrange-init", "lagrange_init", float, "initial λ"),
    ("--lagrange-max", "lagrange_max", float, "λ_max (both multipliers)"),
    ("--pid-kp", "pid_kp", float, "PID-Lagrangian proportional gain"),
    ("--pid-ki", "pid_ki", float, "PID-Lagrangian integral gain"),
    ("--pid-kd", "pid_kd", float, "PID-Lagrangian derivative gain (rising cost only)"),
    ("--num-envs", "num_envs", _int, "training envs per seed"),
    ("--timesteps", "num_timesteps", _int, "training env steps per seed"),
    ("--unroll-length", "unroll_length", _int, None),
    ("--num-minibatches", "num_minibatches", _int, None),
    ("--updates-per-batch", "num_updates_per_batch", _int, "SGD epochs per batch"),
    ("--batch-size", "batch_size", _int, "sequences per minibatch"),
    ("--policy-hidden", "policy_hidden_sizes", _ints, "e.g. 32,32,32,32"),
    ("--value-hidden", "value_hidden_sizes", _ints, "e.g. 256,256,256,256,256"),
    ("--activation", "activation", str, None),
    ("--init-log-std", "init_log_std", _floats, "ARM,GRIPPER initial log-std (gripper = last action dim); write --init-log-std=-0.5,-1.5"),
    ("--lr", "learning_rate", float, None),
    ("--anneal-lr", "anneal_learning_rate", _bool, "true: lr decays linearly to 0 over --timesteps"),
    ("--clip", "clipping_epsilon", float, None),
    ("--gamma", "discounting", float, None),
    ("--gae-lambda", "gae_lambda", float, None),
    ("--entropy", "entropy_cost", float, None),
    ("--value-cost", "value_cost", float, "weight of the value loss"),
    ("--reward-scaling", "reward_scaling", float, None),
    ("--max-grad-norm", "max_grad_norm", float, "per-network gradient-norm clip"),
    ("--target-kl", "target_kl", float, "stop an iteration's epochs once KL > 1.5·target"),
    ("--eval-every", "eval_every", _int, "env steps between evaluations (0: at the end)"),
    ("--checkpoint-every", "checkpoint_every", _int, "env steps between checkpoints (0: at the end)"),
    ("--eval-envs", "num_eval_envs", _int, "deterministic evaluation episodes per seed"),
)


def build_parser() -> argparse.ArgumentParser:
  p = argparse.ArgumentParser(prog="mjx-damage train", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--task", required=True, help="registered task name, or package.module:EnvClass")
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="override passed to tasks.make (repeatable), e.g. --task-arg obs_mode=paper")
  p.add_argument("--out", dest="out_dir", required=True, help="run directory (config, metrics, checkpoint, curves)")
  p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.npz")
  p.add_argument("--preset", default="playground", choices=sorted(PRESETS), help="base settings (train/config.py)")
  p.add_argument("--seeds", type=_ints, default=None, help="seeds trained together in one program, e.g. 0,1,2,3,4")
  p.add_argument("--seed", type=_int, default=None, help="one seed (same as --seeds N)")
  p.add_argument("--episode-length", type=_int, default=None, help="default: the task's")
  p.add_argument("--time-limit", type=float, default=None, help="stop training after this many seconds")
  p.add_argument("--no-progress", dest="progress", action="store_false")
  for flag, dest, typ, help_ in CONFIG_FLAGS:
    p.add_argument(flag, dest=dest, type=typ, default=None, help=help_)
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


def split_args(args: dict) -> tuple[dict, dict]:
  """argparse namespace → (train() keywords, PPOConfig overrides given on the command line)."""
  fields = {dest for _, dest, _, _ in CONFIG_FLAGS}
  config = {k: v for k, v in args.items() if k in fields and v is not None}
  rest = {k: v for k, v in args.items() if k not in fields}
  return rest, config


def main(argv=None) -> int:
  args, config = split_args(vars(build_parser().parse_args(argv)))
  from train.ppo import train  # imports jax: keep --help fast

  task = args.pop("task")
  try:
    args["task_kwargs"] = _task_kwargs(args.pop("task_arg")) or None
    result = train(task, **args, **config)
  except ValueError as e:
    print(f"mjx-damage train: error: {e}", file=sys.stderr)
    return 2
  summary = {
      "out_dir": result.out_dir, "seeds": list(result.config.seeds), "env_steps_per_seed": result.env_steps,
      "wall_time_s": round(result.wall_time, 1), "train_throughput_steps_per_s": round(result.throughput, 1),
      "final_eval": {str(s): ev for s, ev in zip(result.config.seeds, result.final_evals)},
  }
  print(json.dumps(summary, indent=1))
  return 0


if __name__ == "__main__":
  sys.exit(main())

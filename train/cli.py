"""``mjx-damage train``: PPO / PPO-Lagrangian / PID-Lagrangian on a registered task, S seeds in one program.

Examples::

    mjx-damage train --task place_plate --damage-weight 2 --seeds 0,1,2,3,4 --timesteps 3e7 --out runs/pp_w2
    mjx-damage train --task place_plate --budget 2 --multiplier pid --out runs/pp_pid   # PID-Lagrangian, ĉ = 2
    mjx-damage train --task place_plate --preset paper --damage-weight 2 --out runs/pp_paper
    mjx-damage train --task place_plate --budget 2 --out runs/pp_lag --resume   # continue after an interruption
    mjx-damage train --task place_plate --devices all --num-envs 4096 --out runs/pp_2gpu   # every local GPU
    mjx-damage train --task place_plate --coordinator 10.0.0.1:4321 --num-processes 2 --process-id 0 --out runs/pp

Every setting left out comes from ``--preset`` (playground: MuJoCo Playground's
PandaPickCube recipe; paper: the oopsieverse appendix; legacy: this trainer's
old defaults — train/config.py). On a machine with no accelerator and no size
flag (--num-envs, --timesteps, --batch-size, --num-minibatches) the run is
shrunk to CPU_SIZE. Ctrl-C / SIGTERM writes a checkpoint and exits with
status 130; ``--resume`` continues it exactly. An existing --out is refused
unless --resume or --overwrite; without --out the run goes to a new
runs/train-<task>-<time>/.

Several devices / processes (train.mesh, train.distributed): ``--devices
all|N`` lays the seeds and each seed's envs (--num-envs is the global count)
across N devices; with ``--coordinator`` the same command runs once per
process (host), only process 0 writes --out (give every process the same
--out; --resume reads it on every process: a shared filesystem, or a copy).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys

from mjx_damage import outputs, runtime
from train import checkpoint as ckpt
from train import distributed
from train import mesh as M
from train.cliargs import Parser, heartbeat, say_compiling
from train.config import MULTIPLIERS, PRESETS, PPOConfig

# No accelerator and no size flag: a run sized to show learning curves on a laptop CPU, not to solve the task.
CPU_SIZE = {"num_envs": 64, "num_timesteps": 50_000, "num_eval_envs": 16}
CPU_SIZE_BATCHED = {"batch_size": 64, "num_minibatches": 4}  # presets that fix batch_size (playground)
SIZE_FIELDS = ("num_envs", "num_timesteps", "batch_size", "num_minibatches")
RUN_FILES = (ckpt.FILENAME, "config.json", "metrics.jsonl", "metrics.csv", "curves.png")
COMPILE_S = {"cpu": 120, "gpu": 90}  # rough first compile of a task's training iteration, s


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


def _weights(text: str) -> float | tuple[float, ...]:
  """One damage weight, or one per seed (comma-separated)."""
  w = _floats(text)
  if not w:
    raise argparse.ArgumentTypeError(f"a number, or one per seed comma-separated, got {text!r}")
  return w[0] if len(w) == 1 and "," not in text else w


def _float_or_none(text: str) -> float | None:
  """A number, or ``none`` (e.g. no gradient clipping: brax's ``ppo.train`` default)."""
  if text.lower() == "none":
    return None
  try:
    return float(text)
  except ValueError:
    raise argparse.ArgumentTypeError(f"a number or none, got {text!r}") from None


def _bool(text: str) -> bool:
  if text.lower() in ("1", "true", "yes", "on"):
    return True
  if text.lower() in ("0", "false", "no", "off"):
    return False
  raise argparse.ArgumentTypeError(f"true/false, got {text!r}")


# (flag, PPOConfig field, type, help). Left out → the preset's value.
CONFIG_FLAGS = (
    ("--damage-weight", "damage_weight", _weights, "w in r = (r_task − (w + λ)·cost)/(1 + λ); λ = 0 without "
     "--budget. One per seed, comma-separated, trains runs of different w in one program: --seeds 0,1,2,3 "
     "--damage-weight 0,0,2,2"),
    ("--damage-warmup-steps", "damage_warmup_steps", _int,
     "penalty schedule: w = 0 (task reward alone) for this many env steps per seed, then --damage-weight"),
    ("--damage-ramp-steps", "damage_ramp_steps", _int,
     "penalty schedule: after the warm-up, w rises linearly to --damage-weight over this many env steps"),
    ("--damage-warmup-completion", "damage_warmup_completion", float,
     "penalty schedule: the warm-up lasts until the training episodes of a rollout complete the task at this "
     "rate (0-1, per seed; after --damage-warmup-steps, if given), then the ramp starts"),
    ("--budget", "budget", float, "episode-cost budget ĉ: enables the multiplier λ"),
    ("--multiplier", "multiplier", str, f"how λ follows the cost: {' | '.join(MULTIPLIERS)} (with --budget)"),
    ("--lagrange-lr", "lagrange_lr", float, "plain Lagrangian: λ ← clip(λ + lr·(J_c − ĉ), 0, λ_max)"),
    ("--lagrange-init", "lagrange_init", float, "initial λ"),
    ("--lagrange-max", "lagrange_max", float, "λ_max (both multipliers)"),
    ("--pid-kp", "pid_kp", float, "PID-Lagrangian proportional gain"),
    ("--pid-ki", "pid_ki", float, "PID-Lagrangian integral gain"),
    ("--pid-kd", "pid_kd", float, "PID-Lagrangian derivative gain (rising cost only)"),
    ("--cost-critic", "cost_critic", _bool, "true: separate reward and cost critics, advantages mixed with λ"),
    ("--gae-per-iteration", "gae_per_iteration", _bool,
     "true: advantages and value targets computed once per iteration, before the epochs (CleanRL, SB3); false: "
     "brax's, recomputed with the critic being trained at every minibatch step"),
    ("--budget-anneal-steps", "budget_anneal_steps", _int,
     "budget curriculum: ĉ falls linearly from the first measured episode cost to --budget over this many env "
     "steps per seed (0: --budget from the start)"),
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
    ("--anneal-entropy", "anneal_entropy", _bool, "true: the entropy coefficient decays linearly to 0 over --timesteps"),
    ("--value-cost", "value_cost", float, "weight of the value loss"),
    ("--reward-scaling", "reward_scaling", float, None),
    ("--max-grad-norm", "max_grad_norm", _float_or_none, "per-network gradient-norm clip; none: no clipping "
     "(brax's ppo.train default, which Playground's PandaPickCube recipe keeps)"),
    ("--obs-clip", "obs_clip", _float_or_none, "bound on |normalised observation| (none: unbounded, brax's "
     "default)"),
    ("--target-kl", "target_kl", float, "stop an iteration's epochs early once the update's KL is too large"),
    ("--policy-std", "policy_std", str, "state (brax: the std an output of the actor, per state) or parameter "
     "(one learned log-std per action dimension, as in SB3 and CleanRL)"),
    ("--target-kl-rule", "target_kl_rule", str, "minibatch (SB3: before a step whose KL > 1.5·target) or epoch "
     "(CleanRL: after an epoch whose last step began above the target)"),
    ("--eval-every", "eval_every", _int, "env steps between evaluations (0: at the end)"),
    ("--checkpoint-every", "checkpoint_every", _int, "env steps between checkpoints (0: at the end)"),
    ("--eval-envs", "num_eval_envs", _int, "deterministic evaluation episodes per seed"),
    ("--redraw-starts-steps", "redraw_starts_steps", _int, "env steps per seed between fresh starts of every "
     "training env, cutting the episodes under way (brax's num_resets_per_eval); 0: each env replays its first start"),
    ("--critic-warmup", "critic_warmup_iterations", _int, "first iterations in which only the critic learns "
     "(for --init-from)"),
    ("--update-normalizer", "update_normalizer", _bool, "false: keep the observation statistics the run "
     "starts with (for --init-from: those the actor was fitted to)"),
    ("--normalizer-after-update", "normalizer_after_update", _bool, "true: the epochs use the observation "
     "statistics the rollout was collected under, updated after them (SB3's order; PPO's ratio starts at 1)"),
)


def _preset_defaults(dest: str) -> str:
  vals = {name: PPOConfig.preset(name).to_json()[dest] for name in PRESETS}
  if len({json.dumps(v) for v in vals.values()}) == 1:
    return f"(default: {_show(next(iter(vals.values())))})"
  return "(default: " + ", ".join(f"{n} {_show(v)}" for n, v in vals.items()) + ")"


def _show(v) -> str:
  return ",".join(map(str, v)) if isinstance(v, list) else str(v)


def build_parser() -> Parser:
  p = Parser(prog="mjx-damage train", description=__doc__)
  p.add_argument("--task", required=True, help="registered task name, or package.module:EnvClass")
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="override passed to tasks.make (repeatable), e.g. --task-arg obs_mode=paper")
  p.add_argument("--eval-task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="override of the evaluations' task over --task-arg (repeatable), e.g. after --task-arg "
                      "start=route: --eval-task-arg start=in_front (default: evaluate in the training setting)")
  p.add_argument("--robot", default=None, help="robot of a registered --task, e.g. gripper (default: the task's, panda)")
  p.add_argument("--out", dest="out_dir", default=None,
                 help="run directory (config, metrics, checkpoint, curves) (default: runs/train-<task>-<time>/, a new folder)")
  p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.npz")
  p.add_argument("--overwrite", action="store_true", help="replace the run in an existing --out")
  p.add_argument("--preset", default="playground", choices=sorted(PRESETS), help="base settings (train/config.py)")
  p.add_argument("--seeds", type=_ints, default=None, help="seeds trained together in one program, e.g. 0,1,2,3,4 (default: 0)")
  p.add_argument("--seed", type=_int, default=None, help="one seed (same as --seeds N) (default: 0)")
  p.add_argument("--episode-length", type=_int, default=None, help="env steps (default: the task's)")
  p.add_argument("--time-limit", type=float, default=None, help="stop training after this many seconds (default: no limit)")
  p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
  p.add_argument("--deterministic", action="store_true",
                 help="deterministic XLA GPU kernels: a rerun repeats the run bit for bit, at 0.73–0.76× the "
                      "throughput on an H200 (mjx_damage.runtime); CPU runs repeat without it")
  p.add_argument("--matmul-precision", dest="matmul_precision", default=None, choices=runtime.MATMUL_PRECISIONS,
                 help="float32 matrix products (physics, networks) at the backend's default precision (TF32 on a "
                      "recent NVIDIA GPU) or at full float32 (mjx_damage.runtime) (default: JAX's setting)")
  p.add_argument("--init-from", dest="init_from", default=None, metavar="RUN",
                 help="start every seed's actor and normaliser from this checkpoint (mjx-damage bc, or a train "
                      "run); the critic starts fresh (default: none)")
  p.add_argument("--init-seed", dest="init_seed", type=_int, default=None, metavar="SEED",
                 help="with --init-from: the checkpoint's seed whose actor starts every seed (default: seed by "
                      "seed, or its one seed)")
  distributed.add_arguments(p)
  for flag, dest, typ, help_ in CONFIG_FLAGS:
    # default None = the preset's value, spelled out per preset (the formatter would only say None)
    text = ((help_ + " ") if help_ else "") + _preset_defaults(dest)
    if dest in ("num_envs", "num_timesteps"):
      text += f"; CPU with no size flag: {CPU_SIZE[dest]}"
    p.add_argument(flag, dest=dest, type=typ, default=argparse.SUPPRESS, help=text.replace("%", "%%"))
  return p


def split_args(args: dict) -> tuple[dict, dict]:
  """argparse namespace → (train() keywords, PPOConfig overrides given on the command line)."""
  fields = {dest for _, dest, _, _ in CONFIG_FLAGS}
  # SUPPRESS: absent when not given, so a None here was given (--max-grad-norm none)
  config = {k: v for k, v in args.items() if k in fields}
  rest = {k: v for k, v in args.items() if k not in fields}
  return rest, config


def check_out(out_dir: str, task: str, resume: bool, overwrite: bool) -> None:
  """The run directory: refuse an existing run unless --resume/--overwrite; --resume needs a checkpoint
  of the same task. ``ValueError`` naming the flag."""
  if resume and overwrite:
    raise ValueError("--resume: give --resume or --overwrite, not both")
  if os.path.exists(out_dir) and not os.path.isdir(out_dir):
    raise ValueError(f"--out: {out_dir} is a file, not a run directory")
  if resume:
    path = os.path.join(out_dir, ckpt.FILENAME)
    if not os.path.isfile(path):
      raise ValueError(f"--resume: no checkpoint at {path} (drop --resume to start a new run)")
    old = ckpt.read_meta(path).get("task")
    if old != task:
      raise ValueError(f"--resume: the run in {out_dir} trained task {old!r}, not {task!r}")
    return
  outputs.check_new([out_dir], "--out", overwrite, resumable=True, folder=True)


def check_task(task: str) -> None:
  """A registered task name, or ``package.module:EnvClass`` (imported later, by train)."""
  if ":" in task:
    module, _, cls = task.partition(":")
    if not module or not cls:
      raise ValueError(f"--task: expected a task name or package.module:EnvClass, got {task!r}")
    return
  import tasks  # the registry (loads JAX, compiles nothing)

  if task not in tasks.names():
    raise ValueError(f"--task: unknown task {task!r} (valid: {', '.join(tasks.names())}, or package.module:EnvClass)")


def cpu_size(config: dict, preset: str) -> dict:
  """Sizes for a machine with no accelerator when the user gave none (CPU_SIZE); {} otherwise."""
  if any(k in config for k in SIZE_FIELDS):
    return {}
  return {**CPU_SIZE, **(CPU_SIZE_BATCHED if PRESETS[preset].get("batch_size") is not None else {})}


DIST_FLAGS = ("devices", "coordinator", "num_processes", "process_id", "dist_timeout", "heartbeat_timeout")


def _error(prog: str, e: Exception) -> int:
  """One line, status 2, as argparse's own errors (returned: callers test the status)."""
  print(f"{prog}: error: {' '.join(str(e).split())}", file=sys.stderr)
  return 2


def check_out_everywhere(out_dir: str, task: str, resume: bool, overwrite: bool) -> None:
  """:func:`check_out` with several processes: process 0 judges --out (the others may share its filesystem
  and see the folder it creates); each process checks the checkpoint it will read; all agree to go on."""
  err = None
  try:
    if distributed.is_main() or resume:
      check_out(out_dir, task, resume, overwrite and distributed.is_main())
  except ValueError as e:
    err = e
  if distributed.any_process(err is not None)[0]:
    raise err or ValueError(f"--out: another process rejected {out_dir} (see its error)")


def main(argv=None) -> int:
  p = build_parser()
  args, config = split_args(vars(p.parse_args(argv)))
  task, overwrite, deterministic = args.pop("task"), args.pop("overwrite"), args.pop("deterministic")
  matmul_precision = args.pop("matmul_precision")
  dist = {k: args.pop(k) for k in DIST_FLAGS}
  try:  # everything the user typed is checked here, before JAX starts
    if deterministic:  # XLA reads its flags when the first backend starts
      try:
        runtime.use_deterministic_gpu_ops("--deterministic")
      except RuntimeError as e:  # main() called in a process that already computed something
        raise ValueError(str(e)) from None
    if matmul_precision is not None:  # fixed when a program is traced: anything traced from here on
      runtime.use_matmul_precision(matmul_precision)
    setup = distributed.check(**dist)
    import tasks  # the registry (loads JAX, compiles nothing)
    task_kwargs, robot = tasks.parse_task_args(args.pop("task_arg")), args.pop("robot")
    check_task(task)
    if robot is not None:
      if ":" in task:
        raise ValueError(f"--robot: only for a registered --task, not the env class {task!r}")
      tasks.check_robot(robot, [task], "--robot")
      if task_kwargs.get("robot", robot) != robot:
        raise ValueError(f"--robot: {robot!r} disagrees with --task-arg robot={task_kwargs['robot']!r}")
      task_kwargs["robot"] = robot
    args["task_kwargs"] = task_kwargs or None
    eval_items = args.pop("eval_task_arg")
    try:
      eval_extra = tasks.parse_task_args(eval_items)
    except ValueError as e:
      raise ValueError(str(e).replace("--task-arg", "--eval-task-arg")) from None
    args["eval_task_kwargs"] = {**task_kwargs, **eval_extra} if eval_extra else None
    if args["init_from"] is not None and not os.path.exists(args["init_from"]):
      raise ValueError(f"--init-from: no checkpoint at {args['init_from']}")
    if args["init_seed"] is not None:
      if args["init_from"] is None:
        raise ValueError("--init-seed: picks a seed of the --init-from checkpoint; give --init-from")
      src = args["init_from"]
      seeds = ckpt.read_meta(ckpt.file_of(src)).get("config", {}).get("seeds", [])
      ckpt.check_seed(src, seeds, args["init_seed"], "--init-seed")
    if args["time_limit"] is not None and not (math.isfinite(args["time_limit"]) and args["time_limit"] > 0):
      raise ValueError(f"--time-limit: must be a number of seconds > 0, got {args['time_limit']}")
    if args["episode_length"] is not None and args["episode_length"] < 1:
      raise ValueError(f"--episode-length: must be >= 1, got {args['episode_length']}")
    if args["seeds"] is not None and args["seed"] is not None:
      raise ValueError("--seeds: give --seeds or --seed, not both")
    seeds = args["seeds"] or ((args["seed"],) if args["seed"] is not None else (0,))
    cfg = PPOConfig.preset(args["preset"], seeds=seeds, episode_length=args["episode_length"] or 1,
                           **config).validate()
    if isinstance(setup.device_spec, int):
      M.check_layout(cfg, setup.device_spec)
    if args["out_dir"] is None:
      if args["resume"]:
        raise ValueError("--resume: needs --out (the run directory to continue)")
      if setup.multi_process:
        raise ValueError("--out: several processes need one --out, the same on every process")
      args["out_dir"] = outputs.run_dir("train", task.rpartition(":")[2] or task)
    if not setup.multi_process:
      check_out(args["out_dir"], task, args["resume"], overwrite)
  except ValueError as e:
    return _error(p.prog, e)

  import jax  # after the checks: keeps --help and user errors fast

  from train.ppo import TrainingDiverged, train
  try:  # connects the processes (bounded wait), then what needs the devices; still nothing compiled
    distributed.initialize(setup, p.prog)
    if setup.multi_process:
      check_out_everywhere(args["out_dir"], task, args["resume"], overwrite)
    devices = distributed.select_devices(setup.device_spec)
    platform = jax.default_backend()
    small = cpu_size(config, args["preset"]) if platform == "cpu" else {}
    if small:
      config.update(small)
      cfg = dataclasses.replace(cfg, **small).validate()
    M.check_layout(cfg, len(devices))
  except ValueError as e:
    return _error(p.prog, e)
  if overwrite and distributed.is_main():
    for name in RUN_FILES:  # only the files a run writes: --out may be a folder with other things in it
      path = os.path.join(args["out_dir"], name)
      if os.path.isfile(path):
        os.remove(path)
  size = (" (no accelerator: CPU size; give --num-envs/--timesteps for more)" if small else "")
  print(f"train: task {task}, preset {args['preset']}, {cfg.num_envs} envs x {cfg.num_timesteps:,} env steps "
        f"per seed{size}, seeds {list(cfg.seeds)}, device {platform} x {len(devices)} (mesh seeds x envs "
        f"{M.shape(len(devices), cfg.num_seeds)}, {jax.process_count()} process(es)"
        f"{', deterministic GPU kernels' if runtime.deterministic_gpu_ops() and platform != 'cpu' else ''}"
        f"{runtime.matmul_label() and ', ' + runtime.matmul_label()}); "
        f"run directory {args['out_dir']}{' (resuming)' if args['resume'] else ''}", flush=True)
  say_compiling(COMPILE_S, platform, default=90)
  try:
    with heartbeat("train", every=30.0):
      result = train(task, devices=devices, **args, **config)
  except ValueError as e:
    return _error(p.prog, e)
  except TrainingDiverged as e:  # says which seeds, iteration and checkpoint
    print(f"{p.prog}: {' '.join(str(e).split())}", file=sys.stderr)
    return 1
  summary = {
      "out_dir": result.out_dir, "seeds": list(result.config.seeds),
      "damage_weights": list(result.config.damage_weights), "env_steps_per_seed": result.env_steps,
      "wall_time_s": round(result.wall_time, 1), "train_throughput_steps_per_s": round(result.throughput, 1),
      "devices": result.devices, "process": jax.process_index(),
      "final_eval": {str(s): ev for s, ev in zip(result.config.seeds, result.final_evals)},
  }
  print(json.dumps(summary, indent=1))
  print(f"outputs: {result.out_dir} (config.json, metrics.jsonl, metrics.csv, checkpoint.npz, curves.png)")
  return 0


if __name__ == "__main__":
  sys.exit(main())

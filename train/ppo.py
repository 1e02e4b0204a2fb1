"""The training run: S seeds in one compiled program, logging, evaluation, checkpoints, resume.

Why not ``brax.training.agents.ppo.train``: it re-creates env states and RNG
on every call, so it cannot resume a run exactly, has no place for a
multiplier that changes between iterations, and trains one seed per program.
The pieces live in one module per concept:

* :mod:`train.config` — :class:`PPOConfig` and its presets (``playground``,
  the default; ``paper``; ``legacy``);
* :mod:`train.networks` — brax's networks/loss/optimizer, our log-std init;
* :mod:`train.multipliers` — plain and PID Lagrange multipliers;
* :mod:`train.iteration` — ``Trainer.train_iteration``, one seed's pure
  iteration (rollout, reward shaping, λ, normaliser, SGD epochs);
* this module — :func:`train`: ``jit(vmap(train_iteration))`` over a leading
  seed axis of the whole :class:`TrainState` (one call per iteration for all
  seeds, no per-seed host work), per-seed metrics rows (``seed`` key) and
  evaluations, one checkpoint with all seeds, SIGINT/SIGTERM → checkpoint and
  exit 130;
* :mod:`train.policy` — :func:`load_policy` (``seed=`` picks one seed of a run);
* :mod:`train.mesh` — the seeds × envs device mesh the iteration runs on
  (``devices=``), :mod:`train.distributed` — several processes (only process
  0 writes files; every process calls the same collectives in the same order).
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import sys
import threading
import time
import warnings
from typing import Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np

from mjx_damage import io
from train import checkpoint as ckpt
from train import memory as MEM
from train import distributed
from train import mesh as M
from train.config import RESUMABLE_CHANGES, PPOConfig
from train.envs import eval_env_of, recorded_task_kwargs, resolve_task, safe_threshold_of, task_episode_length  # noqa: F401
from train.iteration import Trainer, TrainState, annealed_entropy, scheduled_weight, shape_reward  # noqa: F401
from train.multipliers import lagrange_update  # noqa: F401
from train.policy import load_policy  # noqa: F401

WINDOW_KEYS = ("episodes", "return", "cost", "completion", "safe_completion", "health")
INTERRUPTED = 130  # exit status after SIGINT/SIGTERM (128 + SIGINT), as a shell reports it


@dataclasses.dataclass
class TrainResult:
  out_dir: Optional[str]
  task: str
  config: PPOConfig
  env_steps: int  # per seed
  iterations: int
  wall_time: float  # s, whole call including compilation and evaluations
  train_time: float  # s, iterations only (compilation excluded)
  throughput: float  # training env-steps per second of train_time, all seeds together
  final_eval: dict  # the first seed's final evaluation (single-seed runs: the run's)
  final_evals: list  # one final evaluation per seed, in cfg.seeds order
  history: list  # the rows of metrics.jsonl (one per seed per evaluation, with "seed")
  timings: dict  # s: compile, eval_compile, iterations, eval, checkpoint, host
  policy: Callable  # the first seed's deterministic policy(state, rng) -> action for ONE env
  train_state: TrainState  # leading seed axis S on every leaf (global arrays laid out on the mesh)
  stopped_early: bool = False
  devices: int = 1  # devices of the mesh (all processes)

  def seed_state(self, i: int = 0) -> TrainState:
    return jax.tree.map(lambda x: x[i], self.train_state)


class TrainingDiverged(FloatingPointError):
  """An update left a seed with non-finite losses: its weights are no longer usable, so training stops
  instead of carrying NaN parameters (whose actions the env reads as 0) to the end of the budget."""


# obs_max_abs_z past this: inputs two orders past the unit scale the networks were initialised for. Shelve
# Item's unclipped run on CPU logged 56-660 around its value-loss blow-up (docs/rl_task_design.md); Place
# Plate's inputs stay within 10 (benchmarks/obs_scale.py)
Z_LARGE = 100.0


# The usual bound on normalised observations (SB3's VecNormalize default; our --obs-clip advice): past it, that
# clip would change what the networks see. In training our trainer logged 3.9-6.7 on Place Plate (where the
# clip is inert), 16-51 (256 envs) and 80-222 (2048 envs) on Pick Egg and 56-1,110 on Shelve Item, the two
# tasks where clipping changed what was learnt (docs/rl_task_design.md)
Z_WARN = 10.0


class LargeInputWarning(UserWarning):
  """The networks were fed normalised observations past the usual clip, with nothing clipping them."""


def large_input_message(z, seeds, obs_clip: Optional[float]) -> Optional[str]:
  """What to warn when a seed's largest normalised input ``z`` (f32[S], the metric ``obs_max_abs_z``) passed
  :data:`Z_WARN` while ``obs_clip`` is None; None otherwise. Such inputs need not blow anything up to
  matter: on Pick Egg (≈ 10², the egg's height) our trainer, gradient-clipped, found the carry from task
  reward on 2 of 6 seeds unclipped and on 3 of 3 with ``obs_clip=10`` (docs/rl_task_design.md)."""
  z = np.asarray(z, np.float64)
  if obs_clip is not None or not np.any(z > Z_WARN):
    return None
  big = ", ".join(f"{v:.3g} (seed {s})" for s, v in zip(seeds, z) if v > Z_WARN)
  return (f"the networks' largest normalised observation input reached {big}, past {Z_WARN:g}, where the usual "
          f"observation clip would act: a coordinate the normaliser's first rollouts saw nearly still is divided "
          f"by a std near its 1e-6 floor. Unclipped inputs like these broke Shelve Item's runs without a "
          f"gradient clip and slowed Pick Egg's with one; obs_clip (--obs-clip 10) bounds them. Warned once per "
          f"run; the metric obs_max_abs_z logs it every row.")


# A critic whose value loss leaps this many times above its own lowest, and past V_FLOOR (an RMS error of about
# 6e4 at vf_coefficient 0.5, beyond any return of our tasks), predicts values no return reaches, and its
# bootstrapped targets chase them. On Place Plate's box counter (one H200, 2026-12-02) one seed of ours went
# 2.4 -> 2.1e15 -> 7.8e19 within 6 M env steps and never completed an episode again, and one of Brax's PPO went
# 2.0 -> 8.7e12 and fell from 99.6 to 0 % safe. benchmarks/value_loss_scan.py applies this test to the points
# committed runs logged (2026-12-02: 6 of our 653 seed-runs cross both lines, 4 of which never learnt their task
# or lost it, 2 learnt on; 3 of Brax's 40). The floor keeps quiet the critic of a run that meets large costs
# late (Pick Egg's penalty after its warm-up: 0.09 -> 4.5e7, its run 100 % safe) or wakes from near-zero rewards.
V_JUMP = 1e6
V_FLOOR = 1e9


class CriticDivergedWarning(UserWarning):
  """A seed's value loss jumped orders of magnitude above its lowest: its advantages are noise while it lasts."""


def critic_diverged(v_loss, v_low) -> np.ndarray:
  """bool[S]: the seeds whose value loss ``v_loss`` (f32[S], the metric ``loss/v_loss``) is past both
  :data:`V_FLOOR` and :data:`V_JUMP` times ``v_low`` (f32[S], its lowest before; ``inf`` before any)."""
  v, low = np.asarray(v_loss, np.float64), np.asarray(v_low, np.float64)
  return (v > V_FLOOR) & (v > V_JUMP * low)


def critic_divergence_message(v_loss, v_low, seeds, iteration: int, env_steps: int,
                              fixed_targets: bool = False) -> Optional[str]:
  """What to warn when :func:`critic_diverged` holds for a seed at this iteration; None otherwise.
  ``fixed_targets``: the run computes its value targets once per iteration (config ``gae_per_iteration``)."""
  v, low = np.asarray(v_loss, np.float64), np.asarray(v_low, np.float64)
  bad = critic_diverged(v, low)
  if not np.any(bad):
    return None
  which = ", ".join(f"seed {s}: {a:.3g}, its lowest {b:.3g}" for s, a, b, x in zip(seeds, v, low, bad) if x)
  return (f"the critic diverged at iteration {iteration} ({env_steps / 1e6:.1f} M env steps per seed): value loss "
          f"{which}. Its predictions have left the range of the task's returns, so the advantages the policy "
          f"learns from are noise until it recovers, if it does (a seed of ours on Place Plate never completed "
          f"an episode again; docs/safe_rl.md, \"A second draw of the driver\"). "
          + ("This run already computes its value targets once per iteration (gae_per_iteration); a rerun is what "
             "has mended it so far. "
             if fixed_targets else
             "Value targets computed once per iteration (gae_per_iteration, --gae-per-iteration true) removed "
             "the divergence a CPU stress test shows (benchmarks/critic_targets.py); on Place Plate a rerun is "
             "what has mended it so far. ")
          + "Warned once per run; loss/v_loss is logged every row.")


def non_finite_losses(m: dict, seeds) -> dict:
  """``{seed: [metric, …]}`` of the seeds whose ``loss/*`` metrics (f32[S] each) are not all finite."""
  bad = {}
  for k in sorted(m):
    if k.startswith("loss/"):
      for i in np.nonzero(~np.isfinite(np.asarray(m[k], np.float64)))[0]:
        bad.setdefault(int(seeds[i]), []).append(k)
  return bad


def _diverged(bad: dict, m: dict, seeds, iteration: int, env_steps: int, ckpt_path) -> TrainingDiverged:
  """The error for :func:`non_finite_losses`' ``bad`` seeds, saying whether the env itself produced the
  non-finite values (``m["env_non_finite"]``) and what the checkpoint at ``ckpt_path`` still holds."""
  env_bad = np.asarray(m.get("env_non_finite", np.zeros(len(seeds))), np.float64)
  what = "; ".join(f"seed {s}: {', '.join(k)}" for s, k in bad.items())
  if np.any(env_bad > 0):
    what += " (the env's own observations, rewards or costs were non-finite in " + ", ".join(
        f"{100 * f:.3g} % of seed {s}'s transitions" for s, f in zip(seeds, env_bad) if f > 0) + ")"
  z = np.asarray(m.get("obs_max_abs_z", np.zeros(len(seeds))), np.float64)
  if np.any(z[[list(seeds).index(b) for b in bad]] > Z_LARGE):
    what += (" (the networks' largest normalised observation input was " + ", ".join(
        f"{v:.3g} for seed {s}" for s, v in zip(seeds, z) if s in bad) + ": observations far outside the "
        "normaliser's statistics; --obs-clip bounds what the networks see)")
  kept = (f"the checkpoint in {ckpt_path} is from before it" if ckpt_path and os.path.exists(ckpt_path)
          else "no checkpoint was written")
  return TrainingDiverged(
      f"training diverged at iteration {iteration} ({env_steps:,} env steps per seed): non-finite {what}; "
      f"{kept}. Usual causes: a non-finite observation or reward from the env (run benchmarks/soak.py on "
      f"the task), observations normalised far past unit scale (metric obs_max_abs_z; --obs-clip) or too "
      f"large a learning rate.")


def _read_rows(out_dir: str) -> list:
  path = os.path.join(out_dir, "metrics.jsonl")
  if not os.path.exists(path):
    return []
  with open(path) as f:
    return [json.loads(line) for line in f if line.strip()]


def _write_rows(out_dir: Optional[str], rows: list) -> None:
  """metrics.jsonl (one JSON row per seed per evaluation) and metrics.csv, atomically."""
  if out_dir is None:
    return
  io.write_text(os.path.join(out_dir, "metrics.jsonl"), "".join(json.dumps(r) + "\n" for r in rows))
  keys = list(dict.fromkeys(k for r in rows for k in r))
  fmt = lambda v: "" if v is None else str(v)  # noqa: E731
  io.write_text(os.path.join(out_dir, "metrics.csv"),
                "\n".join([",".join(keys)] + [",".join(fmt(r.get(k)) for k in keys) for r in rows]) + "\n")


class _StopFlag:
  """SIGINT/SIGTERM set a flag the loop reads after each iteration (main thread only)."""

  def __init__(self):
    self.signal = None
    self._old = {}

  def __enter__(self):
    if threading.current_thread() is threading.main_thread():
      for s in (signal.SIGINT, signal.SIGTERM):
        self._old[s] = signal.signal(s, self._handle)
    return self

  def _handle(self, signum, frame):
    self.signal = signum

  def __exit__(self, *exc):
    for s, h in self._old.items():
      signal.signal(s, h)


def check_memory(trainer: Trainer, cfg: PPOConfig, available=None, num_devices: int = 1) -> None:
  """Refuse (``ValueError`` naming ``num_envs``) a run whose estimated peak memory does not fit one device
  (:mod:`train.memory`; the batch is spread evenly over ``num_devices``); checked before anything compiles."""
  sequences = cfg.minibatch_sequences * cfg.num_minibatches
  fp = trainer.footprint
  needed = (MEM.train_bytes(fp.state, trainer.obs_size, trainer.action_size, cfg.num_envs, sequences,
                            cfg.unroll_length, cfg.num_seeds, fp.particles)
            + MEM.eval_bytes(fp.state, cfg.num_eval_envs, fp.particles)) / num_devices
  MEM.check_fits("num_envs", cfg.num_envs, needed, needed / cfg.num_envs,
                 MEM.available_bytes() if available is None else available,
                 f"{cfg.num_seeds} seed(s) of training")

ACTOR_FIELDS = ("policy_hidden_sizes", "activation", "normalize_observations")  # what fixes the actor's shape


def init_source(path: str, task_name: str) -> tuple[str, dict, PPOConfig]:
  """(file, metadata, config) of a checkpoint to start an actor from (a run directory or a file), made for
  ``task_name``; else ``ValueError("init_from: …")``. Reads only the metadata."""
  path = os.fspath(path)
  file = ckpt.file_of(path)
  if not os.path.isfile(file):
    raise ValueError(f"init_from: no checkpoint at {file}")
  try:
    meta = ckpt.read_meta(file)
    src = PPOConfig.from_json(meta["config"])
  except (ValueError, KeyError, TypeError) as e:
    raise ValueError(f"init_from: {file} is not a readable checkpoint ({e})") from None
  if meta.get("task") not in (None, task_name):
    raise ValueError(f"init_from: {file} was made for task {meta['task']!r}, this run trains {task_name!r}")
  return file, meta, src


def check_init_from(path: str, trainer: Trainer, cfg: PPOConfig, task_name: str,
                    init_seed: Optional[int] = None) -> str:
  """The checkpoint file behind ``init_from``, checked against this run (``ValueError("init_from: …")``)."""
  file, meta, src = init_source(path, task_name)
  sizes = (int(meta.get("obs_size", -1)), int(meta.get("action_size", -1)))
  if sizes != (trainer.obs_size, trainer.action_size):
    raise ValueError(f"init_from: {file} has observation/action sizes {sizes}, this task "
                     f"{(trainer.obs_size, trainer.action_size)}")
  for f in ACTOR_FIELDS:
    if getattr(src, f) != getattr(cfg, f):
      raise ValueError(f"init_from: {file} has {f} = {getattr(src, f)!r}, this run {getattr(cfg, f)!r} "
                       f"(give --{f.replace('_', '-')} or a matching preset)")
  if init_seed is not None:
    ckpt.check_seed(file, src.seeds, init_seed, "init_seed")
  elif src.num_seeds not in (1, cfg.num_seeds):
    raise ValueError(f"init_from: {file} holds {src.num_seeds} seeds; this run has {cfg.num_seeds} "
                     "(give a checkpoint of 1 seed, or of as many seeds as the run, or init_seed: one of its seeds)")
  return file


def actor_from_checkpoint(file: str, trainer: Trainer, ts: TrainState, init_seed: Optional[int] = None) -> TrainState:
  """``ts`` (leading seed axis S) with the actor and normaliser of checkpoint ``file``, a fresh optimizer.

  ``init_seed``: the checkpoint's seed whose actor starts every seed (default: seed by seed, or its one seed)."""
  S = int(ts.iteration.shape[0])
  src_seeds = PPOConfig.from_json(ckpt.read_meta(file)["config"]).seeds
  one = jax.eval_shape(lambda: trainer.inference_params(jax.tree.map(lambda x: x[0], ts)))
  template = jax.tree.map(lambda t: jax.ShapeDtypeStruct((len(src_seeds),) + tuple(t.shape), t.dtype), one)
  normalizer, policy = ckpt.restore(file, template, "policy")
  if init_seed is not None:
    i = list(src_seeds).index(init_seed)
    normalizer, policy = jax.tree.map(lambda x: x[i:i + 1], (normalizer, policy))
  if jax.tree.leaves(policy)[0].shape[0] != S:  # one pre-trained actor for every seed
    normalizer, policy = jax.tree.map(lambda x: jnp.broadcast_to(x, (S,) + x.shape[1:]), (normalizer, policy))
  params = ts.params.replace(policy=jax.tree.map(jnp.asarray, policy))
  return ts.replace(params=params, normalizer=jax.tree.map(jnp.asarray, normalizer),
                    opt_state=jax.vmap(trainer.optimizer.init)(params))

def train(task, *, preset: str = "playground", seeds=None, seed: Optional[int] = None,
          episode_length: Optional[int] = None, out_dir: Optional[str] = None, resume: bool = False,
          progress: bool = True, time_limit: Optional[float] = None, task_kwargs: Optional[dict] = None,
          profile: bool = False, plot: bool = True, init_from: Optional[str] = None,
          init_seed: Optional[int] = None, devices=None, eval_task_kwargs: Optional[dict] = None,
          **config) -> TrainResult:
  """Train PPO / PPO-Lagrangian / PID-Lagrangian on ``task`` for one or several seeds in one program.

  Args:
    task: a registered task name (``tasks.make``), ``"package.module:EnvClass"`` or a Brax env tracking damage.
    preset: ``playground`` | ``paper`` | ``legacy`` (train.config); ``**config`` overrides its fields
      (``damage_weight``, ``budget``, ``multiplier``, ``num_envs``, ``num_timesteps``, ...).
    seeds: sequence of seeds trained together (leading axis S of the train state); ``seed``: one seed
      (S = 1). Default (0,). ``damage_weight`` may give one w per seed: e.g. ``seeds=(0, 1, 2, 3)``,
      ``damage_weight=(0, 0, 2, 2)`` trains task reward alone and w = 2 as runs of one program.
    episode_length: None → the task's ``episode_length``.
    out_dir: config.json, metrics.jsonl/.csv (rows carry ``seed``), checkpoint.npz (all seeds), curves.png.
    resume: continue from ``out_dir/checkpoint.npz`` (same config; only num_timesteps, eval_every,
      checkpoint_every, num_eval_envs may change). Equals an uninterrupted run. The rows' ``wall_time``
      (s of training, compile incl.) goes on from the last kept row's.
    time_limit: stop after the iteration that crosses this many seconds (then evaluate, checkpoint, return).
    profile: time rollout-only vs whole iterations at the end (one extra compile).
    init_from: a checkpoint (run directory or file: a PPO run, or a BC actor from :mod:`train.bc_actor`)
      whose actor and observation normaliser start every seed (one seed broadcast, or one per seed);
      ``init_seed`` picks one seed of a multi-seed checkpoint to start every seed;
      the critic starts fresh — ``critic_warmup_iterations`` holds the actor while it learns.
    eval_task_kwargs: the task's keyword arguments for the periodic evaluations (default: ``task_kwargs``),
      e.g. the evaluation's start where training draws from a wider one (tasks/shelve_item.py
      ``start="route"``); same task, same observation and action sizes. Recorded in config.json.
    devices: "all", a count, or a device list (train.distributed.select_devices); None: the first device.
      Seeds and each seed's env batch are laid across them (train.mesh); evaluation shards its episodes over them.
      With several processes (train.distributed.initialize first) every process calls train() alike and
      only process 0 writes files.
  SIGINT/SIGTERM: the running iteration finishes, a checkpoint is written (with ``out_dir``) and
  ``SystemExit(130)`` is raised.
  """
  t_start = time.perf_counter()
  if seeds is not None and seed is not None:
    raise ValueError("seeds: give seeds or seed, not both")
  seeds = (0,) if seeds is None and seed is None else ((seed,) if seeds is None else seeds)
  if isinstance(seeds, (list, tuple)):
    seeds = tuple(seeds)
  for k in ("policy_hidden_sizes", "value_hidden_sizes", "init_log_std", "damage_weight"):
    if isinstance(config.get(k), list):
      config[k] = tuple(config[k])
  cfg = PPOConfig.preset(preset, seeds=seeds, episode_length=episode_length or 1, **config).validate()
  if time_limit is not None and (isinstance(time_limit, bool) or not isinstance(time_limit, (int, float))
                                 or not time_limit > 0):
    raise ValueError(f"time_limit: must be a number of seconds > 0, got {time_limit!r}")
  if resume and out_dir is None:
    raise ValueError("resume: needs out_dir (where the checkpoint is)")
  env, task_name = resolve_task(task, task_kwargs)
  eval_env = None if eval_task_kwargs is None else eval_env_of(task, env, eval_task_kwargs)
  if episode_length is None:
    cfg = dataclasses.replace(cfg, episode_length=task_episode_length(env))
  devs = distributed.select_devices(devices)
  M.check_layout(cfg, len(devs))
  mesh = M.make_mesh(devs, cfg.num_seeds)
  trainer = Trainer(env, cfg, M.axis_name(mesh))
  if init_seed is not None and init_from is None:
    raise ValueError("init_seed: picks the seed of an init_from checkpoint; give init_from")
  init_file = None if init_from is None else check_init_from(init_from, trainer, cfg, task_name, init_seed)
  check_memory(trainer, cfg, num_devices=len(devs))
  S, spi = cfg.num_seeds, cfg.steps_per_iteration
  seed_arr = np.asarray(cfg.seeds, np.int32)
  main = distributed.is_main()

  ckpt_path, writes = None, None  # writes: where this process writes files (process 0 only)
  if out_dir is not None:
    out_dir = os.fspath(out_dir)
    ckpt_path = os.path.join(out_dir, ckpt.FILENAME)
    if main:
      os.makedirs(out_dir, exist_ok=True)
      writes = out_dir
  meta = {"task": task_name, "task_kwargs": recorded_task_kwargs(task, env, task_kwargs), "preset": preset,
          **({} if eval_env is None else
             {"eval_task_kwargs": recorded_task_kwargs(task, eval_env, eval_task_kwargs)}),
          "config": cfg.to_json(),
          "obs_size": trainer.obs_size, "action_size": trainer.action_size, "steps_per_iteration": spi,
          "init_from": None if init_file is None else os.path.abspath(init_file), "init_seed": init_seed,
          "devices": len(devs), "mesh": dict(mesh.shape), "processes": jax.process_count()}

  timings = {k: 0.0 for k in ("compile", "eval_compile", "iterations", "eval", "checkpoint", "host")}
  rows: list = []
  wall0 = 0.0  # s of training before this call (resume)
  init_fn = trainer.init_states
  specs = M.state_specs(jax.eval_shape(init_fn, seed_arr))
  layout = M.shardings(mesh, specs)
  if resume and os.path.exists(ckpt_path):
    old = ckpt.read_meta(ckpt_path)
    old_cfg = PPOConfig.from_json(old["config"]).to_json()
    diff = [k for k, v in cfg.to_json().items() if k not in RESUMABLE_CHANGES and old_cfg.get(k) != v]
    if diff or old["task"] != task_name:
      raise ValueError(f"resume: checkpoint in {out_dir} was made with a different config "
                       f"({', '.join(diff) or 'task'})")
    ts = M.put(ckpt.restore(ckpt_path, jax.eval_shape(init_fn, seed_arr), "state"), layout)
    start_iteration = int(ts.iteration[0])
    # Rows logged after the checkpoint were produced by the interrupted tail: redo them.
    rows = [r for r in _read_rows(out_dir) if r["iteration"] <= start_iteration]
    # Rows' wall_time keeps counting from the kept rows' last one, so that "time to a score" spans calls.
    wall0 = rows[-1]["wall_time"] if rows else 0.0
  else:
    if resume:
      print(f"resume: no checkpoint in {out_dir}; starting a fresh run", file=sys.stderr)
    ts = jax.jit(init_fn, out_shardings=layout)(seed_arr)
    if init_file is not None:
      ts = M.put(jax.device_get(actor_from_checkpoint(init_file, trainer, jax.device_get(ts), init_seed)), layout)
    start_iteration = 0
  if writes is not None:
    io.write_json(os.path.join(out_dir, "config.json"), meta)

  # Donating the state lets XLA update the env batches in place (GPU memory).
  iteration_fn = M.per_seed(trainer.train_iteration, mesh, specs, (specs, M.P(M.SEEDS)), donate=True)
  evaluator = trainer.make_evaluator(devs, eval_env)

  def evaluate_all(ts, iteration):
    """Per-seed deterministic evaluation: seed s uses keys from PRNGKey(s + 1), folded with the iteration."""
    params = distributed.to_host(trainer.inference_params(ts))
    return [trainer.evaluate(evaluator, jax.tree.map(lambda x: x[i], params),
                             jax.random.fold_in(jax.random.PRNGKey(s + 1), iteration), cfg.num_eval_envs)
            for i, s in enumerate(cfg.seeds)]

  def save(ts, iteration):
    t0 = time.perf_counter()
    host = distributed.to_host(ts)  # every process takes part; process 0 writes
    if main:
      ckpt.save(ckpt_path, host, trainer.inference_params(host),
                dict(meta, iteration=iteration, env_steps=iteration * spi))
    timings["checkpoint"] += time.perf_counter() - t0

  n_iter = cfg.num_iterations
  eval_int, ckpt_int = cfg.interval_iterations(cfg.eval_every), cfg.interval_iterations(cfg.checkpoint_every)
  bar = None
  if progress and main:
    from tqdm import tqdm
    weights = ",".join(dict.fromkeys(f"{w:g}" for w in cfg.damage_weights))
    desc = f"{task_name} {cfg.multiplier if cfg.lagrangian else f'w={weights}'} ×{S} seeds"
    bar = tqdm(total=n_iter * spi * S, initial=start_iteration * spi * S, unit="step", unit_scale=True,
               desc=desc, dynamic_ncols=True)

  window = {k: np.zeros(S) for k in WINDOW_KEYS}  # per-seed training-episode sums since the last row
  z_window = np.zeros(S)  # per-seed largest obs_max_abs_z since the last row (a spike between rows counts)
  warned_z = not main  # large_input_message decides the rest (nothing to warn with obs_clip set)
  warned_v, v_low = not main, np.full(S, np.inf)  # v_low: per-seed lowest loss/v_loss of the iterations so far
  stopped_early, final_evals, iteration, first_eval = False, [], start_iteration, True
  with _StopFlag() as stop:
    for iteration in range(start_iteration + 1, n_iter + 1):
      t0 = time.perf_counter()
      ts, m = iteration_fn(ts)
      m = distributed.to_host(m)  # blocks: the iteration has finished; every leaf f32[S]
      timings["iterations" if iteration > start_iteration + 1 else "compile"] += time.perf_counter() - t0
      bad = non_finite_losses(m, cfg.seeds)
      if bad:  # before any checkpoint of this iteration, so the last one saved still holds finite weights
        if bar is not None:
          bar.close()
        raise _diverged(bad, m, cfg.seeds, iteration, iteration * spi, ckpt_path)
      t_host = time.perf_counter()
      for k in WINDOW_KEYS:
        window[k] += np.asarray(m[f"ended_{k}"], np.float64)
      if "obs_max_abs_z" in m:
        z_window = np.maximum(z_window, np.asarray(m["obs_max_abs_z"], np.float64))
        if not warned_z and (msg := large_input_message(z_window, cfg.seeds, cfg.obs_clip)):
          warnings.warn(msg, LargeInputWarning, stacklevel=2)
          warned_z = True
      if "loss/v_loss" in m:
        v = np.asarray(m["loss/v_loss"], np.float64)
        if not warned_v and (msg := critic_divergence_message(v, v_low, cfg.seeds, iteration, iteration * spi,
                                                                      cfg.gae_per_iteration)):
          warnings.warn(msg, CriticDivergedWarning, stacklevel=2)
          warned_v = True
        v_low = np.minimum(v_low, v)
      last = iteration == n_iter
      # One decision for all processes: one that stopped alone would leave the others in a collective.
      signalled, over_time = distributed.any_process(
          stop.signal is not None, time_limit is not None and time.perf_counter() - t_start > time_limit)
      if (signalled or over_time) and not last:
        stopped_early = last = True
      if bar is not None:
        n = np.maximum(window["episodes"], 1.0)
        post = {"succ": f"{np.mean(window['completion'] / n):.2f}", "cost": f"{np.mean(window['cost'] / n):.3g}"}
        if cfg.lagrangian:
          post["λ"] = f"{np.mean(m['lagrange']):.3g}"
        bar.set_postfix(post, refresh=False)
        bar.update(spi * S)
      timings["host"] += time.perf_counter() - t_host

      if not signalled and (last or (eval_int and iteration % eval_int == 0)):
        t0 = time.perf_counter()
        evs = evaluate_all(ts, iteration)
        timings["eval_compile" if first_eval else "eval"] += time.perf_counter() - t0
        first_eval = False
        wall = round(wall0 + time.perf_counter() - t_start, 3)
        for i, s in enumerate(cfg.seeds):
          n = float(window["episodes"][i])
          row = {"seed": s, "iteration": iteration, "env_steps": iteration * spi, "wall_time": wall,
                 "train/episodes": n}
          for k in WINDOW_KEYS[1:]:
            row[f"train/episode_{k}"] = float(window[k][i]) / n if n else None
          row.update({k: float(v[i]) for k, v in m.items() if not k.startswith("ended_")})
          if "obs_max_abs_z" in m:
            row["obs_max_abs_z"] = float(z_window[i])
          row.update({f"eval/{k}": v for k, v in evs[i].items()})
          rows.append(row)
        _write_rows(writes, rows)
        window = {k: np.zeros(S) for k in WINDOW_KEYS}
        z_window = np.zeros(S)
        final_evals = evs
      if ckpt_path and (last or (ckpt_int and iteration % ckpt_int == 0)):
        save(ts, iteration)
      if signalled:
        if bar is not None:
          bar.close()
        kept = (f"checkpoint at iteration {iteration} in {ckpt_path} (continue with --resume)" if ckpt_path
                else "nothing saved (no out_dir)")
        print(f"interrupted (signal {stop.signal}); {kept}", file=sys.stderr)
        raise SystemExit(INTERRUPTED)
      if last:
        break
  if bar is not None:
    bar.close()

  if not final_evals and start_iteration >= n_iter:  # resumed a finished run: evaluate once
    final_evals = evaluate_all(ts, start_iteration)
  if profile:
    timings.update(profile_iteration(trainer, ts, iteration_fn, mesh, specs))
  if writes is not None and plot and rows:
    from train import plots
    labels = ({s: f"seed {s}, w = {w:g}" for s, w in zip(cfg.seeds, cfg.damage_weights)}
              if len(set(cfg.damage_weights)) > 1 else None)
    plots.plot_training(rows, os.path.join(out_dir, "curves.png"), title=task_name, budget=cfg.budget,
                        labels=labels)
  timed_iters = max(iteration - start_iteration - 1, 0)
  params0 = jax.tree.map(lambda x: x[0], distributed.to_host(trainer.inference_params(ts)))
  make_policy = trainer.make_policy
  return TrainResult(
      out_dir=out_dir, task=task_name, config=cfg, env_steps=iteration * spi, iterations=iteration,
      wall_time=time.perf_counter() - t_start, train_time=timings["iterations"],
      throughput=timed_iters * spi * S / timings["iterations"] if timings["iterations"] > 0 else float("nan"),
      final_eval=final_evals[0] if final_evals else {}, final_evals=final_evals, history=rows, timings=timings,
      policy=lambda state, rng: make_policy(params0, deterministic=True)(state.obs, rng)[0],
      train_state=ts, stopped_early=stopped_early, devices=len(devs),
  )


def profile_iteration(trainer: Trainer, ts: TrainState, iteration_fn, mesh, specs, repeats: int = 3) -> dict:
  """Seconds per iteration (all seeds): ``profile/rollout`` (env step + inference), ``profile/iteration``,
  ``profile/update`` (= iteration − rollout). Compiles the rollout alone once; the run's state is untouched."""
  collect = M.per_seed(lambda s: trainer.collect(s)[1:], mesh, specs, (M.P(M.SEEDS, M.ENVS), M.P(M.SEEDS)))
  fresh = lambda: jax.block_until_ready(jax.tree.map(jnp.copy, ts))  # noqa: E731  (the iteration donates)

  def timeit(f, copy):
    best = float("inf")
    for _ in range(repeats + 1):  # the first call compiles (or loads from the cache)
      arg = fresh() if copy else ts
      t0 = time.perf_counter()
      jax.block_until_ready(f(arg))
      best = min(best, time.perf_counter() - t0)
    return best

  t_roll, t_full = timeit(collect, False), timeit(iteration_fn, True)
  return {"profile/rollout": t_roll, "profile/iteration": t_full, "profile/update": max(t_full - t_roll, 0.0)}

"""PPO and PPO-Lagrangian on damage-aware Brax envs, as one readable training loop.

Why not ``brax.training.agents.ppo.train``: it re-creates env states and RNG
on every call, so it cannot resume a run exactly, and it has no place for a
Lagrange multiplier that changes between iterations. This module keeps brax's
pieces — networks (``make_ppo_networks``/``make_inference_fn``), the clipped
PPO loss with GAE (``compute_ppo_loss``), ``gradients.gradient_update_fn``,
the running observation normaliser and the training env wrappers — and writes
the loop around them in the purejaxrl style:

* every piece of state lives in one :class:`TrainState` pytree;
* ``Trainer.train_iteration(state) -> (state, metrics)`` is pure and jitted:
  rollout → reward shaping → λ update → normaliser update → SGD epochs;
* :func:`train` is a plain Python loop over iterations that logs, evaluates
  (with :mod:`train.evaluate`, the one evaluation rollout of this project),
  checkpoints and plots. Resuming = loading a ``TrainState`` and continuing the
  same loop, so results equal an uninterrupted run up to floating-point noise.

Reward used for the policy (per step)::

    r = (r_task − (w + λ)·cost) / (1 + λ)

with ``r_task = info["task_reward"]`` and ``cost = info["cost"]`` from
:class:`mjx_damage.DamageWrapper` (which the env is wrapped with at weight 0:
the trainer shapes the reward, so w and λ are traced values, not constants
baked into the compiled env). Plain PPO with a damage penalty is λ ≡ 0, where
this is the paper's r_task − w·cost. The 1/(1 + λ) factor only rescales: it
keeps the return scale bounded while λ grows (episode cost is unbounded), so
the value loss does not swamp the policy gradient in the shared clipped
update; the trade-off between task and cost is still set by λ.

PPO-Lagrangian (``budget`` ĉ given): maximise E[return] s.t. E[episode cost] ≤ ĉ.
The multiplier is updated once per iteration by projected gradient ascent on
the dual::

    λ ← clip(λ + lr_λ·(J_c − ĉ), 0, λ_max)

where J_c is the mean undiscounted cost of the episodes that ended during this
iteration's rollout (the previous estimate when none ended). λ_max guards
against a runaway multiplier on an infeasible budget. Defaults lr_λ = 0.1,
λ_max = 5 come from place_plate on one H100 (ĉ = 2, 16384 envs): with 0.02 / 10
the multiplier saturates at the first, costly episodes and then needs ~150
iterations to come back down (≥ 80 % safe after 442 s); 0.1 / 5 got there
after 242 s (benchmarks/results/rl_place_plate_*_lagrangian_fast.md).
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import math
import os
import sys
import time
from typing import Any, Callable, Optional, Sequence

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax
from brax.envs.base import Env, State, Wrapper
from brax.envs.wrappers import training as brax_training
from brax.training import gradients, types
from brax.training.acme import running_statistics
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks

import mjx_damage  # noqa: F401  (installs the jax compat shim brax needs)
from mjx_damage.wrapper import DamageWrapper
from train import checkpoint as ckpt
from train import evaluate as E

ACTIVATIONS: dict[str, Callable] = {
    "tanh": jnp.tanh,
    "swish": jax.nn.swish,
    "relu": jax.nn.relu,
    "elu": jax.nn.elu,
}

# Config fields that may change when a run is resumed: they decide how long to
# run and what to log, never what a training iteration computes.
_RESUMABLE_CHANGES = ("num_timesteps", "eval_every", "checkpoint_every", "num_eval_envs")


# ---------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class PPOConfig:
  """Everything that defines a run. ``validate()`` raises ``ValueError("name: ...")``.

  Batch layout (as in brax): each iteration collects ``num_rollouts =
  batch_size·num_minibatches / num_envs`` unrolls of ``unroll_length`` steps
  from all ``num_envs`` envs, i.e. ``batch_size·num_minibatches`` sequences of
  length ``unroll_length``; each of ``num_updates_per_batch`` epochs shuffles
  them into ``num_minibatches`` minibatches of ``batch_size`` sequences.
  """

  num_envs: int = 1024
  num_timesteps: int = 1_000_000
  episode_length: int = 200
  unroll_length: int = 20
  num_minibatches: int = 8
  num_updates_per_batch: int = 4
  batch_size: Optional[int] = None  # sequences per minibatch; None → num_envs // num_minibatches
  learning_rate: float = 3e-4
  clipping_epsilon: float = 0.2
  discounting: float = 0.97
  gae_lambda: float = 0.95
  entropy_cost: float = 1e-3
  reward_scaling: float = 1.0
  max_grad_norm: Optional[float] = 1.0
  policy_hidden_sizes: tuple[int, ...] = (256, 256)
  value_hidden_sizes: tuple[int, ...] = (256, 256)
  activation: str = "swish"
  normalize_observations: bool = True
  damage_weight: float = 0.0
  budget: Optional[float] = None
  lagrange_lr: float = 0.1
  lagrange_init: float = 0.0
  lagrange_max: float = 5.0
  num_eval_envs: int = 128
  eval_every: int = 0  # env steps between evaluations; 0 → only at the end
  checkpoint_every: int = 0  # env steps between checkpoints; 0 → only at the end
  seed: int = 0

  @property
  def lagrangian(self) -> bool:
    return self.budget is not None

  @property
  def minibatch_sequences(self) -> int:
    return self.batch_size if self.batch_size is not None else self.num_envs // self.num_minibatches

  @property
  def num_rollouts(self) -> int:
    return self.minibatch_sequences * self.num_minibatches // self.num_envs

  @property
  def steps_per_iteration(self) -> int:
    return self.num_envs * self.unroll_length * self.num_rollouts

  @property
  def num_iterations(self) -> int:
    return max(1, math.ceil(self.num_timesteps / self.steps_per_iteration))

  def interval_iterations(self, env_steps: int) -> int:
    """Iterations between two events every ``env_steps`` (0 → never, i.e. only at the end)."""
    if env_steps <= 0:
      return 0
    return max(1, round(env_steps / self.steps_per_iteration))

  def validate(self) -> "PPOConfig":
    def pos_int(name):
      v = getattr(self, name)
      if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
        raise ValueError(f"{name}: must be a positive integer, got {v!r}")

    def number(name, lo=None, hi=None, lo_open=False, allow_none=False):
      v = getattr(self, name)
      if v is None and allow_none:
        return
      if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not math.isfinite(v):
        raise ValueError(f"{name}: must be a finite number, got {v!r}")
      if lo is not None and (v <= lo if lo_open else v < lo):
        raise ValueError(f"{name}: must be {'>' if lo_open else '>='} {lo}, got {v!r}")
      if hi is not None and v > hi:
        raise ValueError(f"{name}: must be <= {hi}, got {v!r}")

    for name in ("num_envs", "num_timesteps", "episode_length", "unroll_length", "num_minibatches",
                 "num_updates_per_batch", "num_eval_envs"):
      pos_int(name)
    if self.batch_size is not None:
      pos_int("batch_size")
    elif self.num_envs % self.num_minibatches:
      raise ValueError(f"num_envs: {self.num_envs} must be divisible by num_minibatches "
                       f"({self.num_minibatches}) when batch_size is not given")
    if (self.minibatch_sequences * self.num_minibatches) % self.num_envs:
      raise ValueError(f"num_envs: {self.num_envs} must divide batch_size·num_minibatches = "
                       f"{self.minibatch_sequences}·{self.num_minibatches}")
    for name in ("eval_every", "checkpoint_every", "seed"):
      v = getattr(self, name)
      if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        raise ValueError(f"{name}: must be an integer >= 0, got {v!r}")
    number("learning_rate", lo=0, lo_open=True)
    number("clipping_epsilon", lo=0, lo_open=True)
    number("discounting", lo=0, hi=1)
    number("gae_lambda", lo=0, hi=1)
    number("entropy_cost", lo=0)
    number("reward_scaling", lo=0, lo_open=True)
    number("max_grad_norm", lo=0, lo_open=True, allow_none=True)
    number("damage_weight", lo=0)
    number("budget", lo=0, allow_none=True)
    number("lagrange_lr", lo=0)
    number("lagrange_init", lo=0)
    number("lagrange_max", lo=0)
    for name in ("policy_hidden_sizes", "value_hidden_sizes"):
      v = getattr(self, name)
      if not isinstance(v, (tuple, list)) or not v or any(
          isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 1 for h in v):
        raise ValueError(f"{name}: must be a non-empty sequence of positive integers, got {v!r}")
    if self.activation not in ACTIVATIONS:
      raise ValueError(f"activation: one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
    return self

  def to_json(self) -> dict:
    d = dataclasses.asdict(self)
    d["policy_hidden_sizes"] = list(self.policy_hidden_sizes)
    d["value_hidden_sizes"] = list(self.value_hidden_sizes)
    return d

  @classmethod
  def from_json(cls, d: dict) -> "PPOConfig":
    d = dict(d)
    d["policy_hidden_sizes"] = tuple(d["policy_hidden_sizes"])
    d["value_hidden_sizes"] = tuple(d["value_hidden_sizes"])
    return cls(**{k: v for k, v in d.items() if k in {f.name for f in dataclasses.fields(cls)}})


# ---------------------------------------------------------------------------
# Environments
# ---------------------------------------------------------------------------
def _find_damage_wrapper(env) -> Optional[DamageWrapper]:
  e = env
  while e is not None:
    if isinstance(e, DamageWrapper):
      return e
    e = getattr(e, "env", None) if isinstance(e, Wrapper) else None
  return None


def resolve_task(task, task_kwargs: Optional[dict] = None) -> tuple[Env, str]:
  """``task`` → (damage-wrapped single env, name).

  ``task`` is a registered task name (``tasks.make(name, **task_kwargs)``), an
  env class path ``"package.module:Class"`` (constructed with ``task_kwargs``)
  or a Brax env instance.

  The env must expose ``info["task_reward"]``/``info["cost"]``: anything that
  already contains a :class:`DamageWrapper` is used as is (the trainer shapes
  the reward from those fields, so the wrapper's own weight does not matter);
  a :class:`mjx_damage.DamageEnv` is wrapped at weight 0.
  """
  if isinstance(task, str) and ":" in task:  # "package.module:EnvClass", e.g. train.experiments.pusher:PusherEnv
    import importlib
    module, _, cls = task.partition(":")
    try:
      env = getattr(importlib.import_module(module), cls)(**(task_kwargs or {}))
    except (ImportError, AttributeError) as e:
      raise ValueError(f"task: cannot import env class {task!r} ({e})") from e
    name = task
  elif isinstance(task, str):
    try:
      import tasks as task_registry
    except ImportError as e:  # the registry is a sibling package of this repo
      raise ValueError(f"task: cannot look up {task!r}: the task registry failed to import ({e})") from e
    names = list(task_registry.names())
    if task not in names:
      raise ValueError(f"task: unknown task {task!r}; registered: {', '.join(names) or '(none)'}")
    env, name = task_registry.make(task, **(task_kwargs or {})), task
  elif isinstance(task, Env):
    if task_kwargs:
      raise ValueError("task_kwargs: only used with a task name")
    env, name = task, type(task).__name__
  else:
    raise ValueError(f"task: a registered task name or a brax Env, got {type(task).__name__}")
  if _find_damage_wrapper(env) is None:
    if getattr(env, "damage_binding", None) is None:
      raise ValueError(f"task: {name} neither tracks damage nor is wrapped in DamageWrapper")
    env = DamageWrapper(env, weight=0.0)
  return env, name


def task_episode_length(env, default: int = 200) -> int:
  """The episode length a task declares (``Task.episode_length``), else ``default``."""
  n = getattr(getattr(env, "unwrapped", env), "episode_length", None)
  return int(n) if isinstance(n, (int, np.integer)) and n > 0 else default


def safe_threshold_of(env) -> float:
  """The env's DamageWrapper ``safe_threshold`` (95 without one): safe completion's health bar."""
  w = _find_damage_wrapper(env)
  return float(w.safe_threshold) if w is not None else 95.0


# ---------------------------------------------------------------------------
# State
# ---------------------------------------------------------------------------
@flax.struct.dataclass
class EpisodeAcc:
  """Running sums of the episode in progress in each training env, f32[E] each."""

  task_return: jax.Array
  cost: jax.Array
  completed: jax.Array  # 1.0 once the success condition has held


@flax.struct.dataclass
class Shaping:
  """Reward-shaping and multiplier settings, f32[] each.

  Kept as traced values in the state rather than Python constants so that runs
  differing only in w / ĉ / lr_λ share one compiled iteration (tests, sweeps).
  """

  damage_weight: jax.Array  # w
  lagrangian: jax.Array  # 1.0: λ is updated; 0.0: λ stays at its initial value 0
  budget: jax.Array  # ĉ (unused without a budget)
  lagrange_lr: jax.Array
  lagrange_max: jax.Array


@flax.struct.dataclass
class TrainState:
  params: ppo_losses.PPONetworkParams
  opt_state: Any
  normalizer: running_statistics.RunningStatisticsState
  env_state: State  # batched over E = num_envs
  episode: EpisodeAcc
  lagrange: jax.Array  # f32[], λ ≥ 0 (stays at 0 without a budget)
  cost_estimate: jax.Array  # f32[], last measured mean episode cost J_c
  has_cost_estimate: jax.Array  # f32[], 1.0 once any training episode has ended
  shaping: Shaping
  rng: jax.Array  # u32[2]
  iteration: jax.Array  # i32[]


def shape_reward(r_task, cost, damage_weight, lam):
  """Policy reward ``(r_task − (w + λ)·cost) / (1 + λ)``; any matching shapes.

  The division is the usual PPO-Lagrangian normalisation. Episode cost is
  unbounded (a shattering plate costs thousands of health points), so
  r − λ·c alone grows with λ: the value loss then dominates the shared,
  norm-clipped gradient and the policy stops learning (seen on place_plate at
  λ = 10: value loss ~4e3, no progress in 130 s). Dividing keeps the return
  scale bounded and leaves the task/cost trade-off (ratio λ) unchanged; with
  λ = 0 (penalty or task-only runs) it is the paper's r_task − w·cost.
  """
  return (r_task - (damage_weight + lam) * cost) / (1.0 + lam)


def lagrange_update(lam, episode_cost, budget, lr, lam_max):
  """Projected gradient ascent on the dual: ``clip(λ + lr·(J_c − ĉ), 0, λ_max)``.

  dL/dλ of L(π, λ) = J_r(π) − λ·(J_c(π) − ĉ) is −(J_c − ĉ); the multiplier
  ascends the dual, so it grows while the constraint is violated (J_c > ĉ) and
  shrinks — down to the projection at 0 — while it is slack.
  """
  return jnp.clip(lam + lr * (episode_cost - budget), 0.0, lam_max)


# ---------------------------------------------------------------------------
# Trainer: the pure functions of one run
# ---------------------------------------------------------------------------
class Trainer:
  """Holds the static parts of a run (envs, networks, optimizer); all methods are pure.

  Shapes: E = num_envs, T = unroll_length, R = num_rollouts, O = observation
  size, A = action size, N = tracked entities.
  """

  def __init__(self, env: Env, cfg: PPOConfig):
    self.cfg = cfg.validate()
    self.base_env = env
    self.safe_threshold = safe_threshold_of(env)
    episodic = brax_training.EpisodeWrapper(env, cfg.episode_length, action_repeat=1)
    # Training: auto-resetting batch (brax's order: Episode → Vmap → AutoReset).
    # Evaluation runs base_env through train.evaluate (see make_evaluator).
    self.env = brax_training.AutoResetWrapper(brax_training.VmapWrapper(episodic))
    obs_shape = jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape
    if len(obs_shape) != 1:
      raise ValueError(f"task: observations must be flat vectors, got shape {obs_shape}")
    self.obs_size, self.action_size = int(obs_shape[0]), int(env.action_size)
    if self.action_size < 1:
      raise ValueError("task: the env has no actions to learn")
    self.network = make_networks(self.obs_size, self.action_size, cfg)
    self.make_policy = ppo_networks.make_inference_fn(self.network)
    self.optimizer = make_optimizer(cfg)
    loss_fn = functools.partial(
        ppo_losses.compute_ppo_loss,
        ppo_network=self.network,
        entropy_cost=cfg.entropy_cost,
        discounting=cfg.discounting,
        reward_scaling=cfg.reward_scaling,
        gae_lambda=cfg.gae_lambda,
        clipping_epsilon=cfg.clipping_epsilon,
        normalize_advantage=True,
    )
    self.gradient_update = gradients.gradient_update_fn(loss_fn, self.optimizer, pmap_axis_name=None, has_aux=True)

  # -- init -----------------------------------------------------------------
  def init(self, seed) -> TrainState:
    """Fresh state. Jit :meth:`init_state` (no config constants in the program, so runs
    that differ in w / ĉ share its compilation) and set the shaping outside."""
    return self.with_shaping(self.init_state(seed))

  def with_shaping(self, ts: TrainState) -> TrainState:
    cfg = self.cfg
    f32 = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    return ts.replace(
        lagrange=f32(cfg.lagrange_init if cfg.lagrangian else 0.0),
        shaping=Shaping(damage_weight=f32(cfg.damage_weight), lagrangian=f32(float(cfg.lagrangian)),
                        budget=f32(cfg.budget or 0.0), lagrange_lr=f32(cfg.lagrange_lr),
                        lagrange_max=f32(cfg.lagrange_max)),
    )

  def init_state(self, seed) -> TrainState:
    """Networks, optimizer, normaliser, reset envs; λ = 0 and all shaping values 0."""
    key = jax.random.PRNGKey(seed)
    key, k_policy, k_value, k_env = jax.random.split(key, 4)
    params = ppo_losses.PPONetworkParams(
        policy=self.network.policy_network.init(k_policy),
        value=self.network.value_network.init(k_value),
    )
    env_state = self.env.reset(jax.random.split(k_env, self.cfg.num_envs))
    zeros = jnp.zeros((self.cfg.num_envs,), jnp.float32)
    return TrainState(
        params=params,
        opt_state=self.optimizer.init(params),
        normalizer=running_statistics.init_state(jnp.zeros((self.obs_size,), jnp.float32)),
        env_state=env_state,
        episode=EpisodeAcc(zeros, zeros, zeros),
        lagrange=jnp.zeros((), jnp.float32),
        cost_estimate=jnp.zeros((), jnp.float32),
        has_cost_estimate=jnp.zeros((), jnp.float32),
        shaping=Shaping(*(jnp.zeros((), jnp.float32) for _ in range(5))),
        rng=key,
        iteration=jnp.zeros((), jnp.int32),
    )

  def inference_params(self, ts: TrainState):
    """What a policy needs: ``(normaliser, policy params)`` (brax's inference-param layout)."""
    return (ts.normalizer, ts.params.policy)

  # -- acting ---------------------------------------------------------------
  def _env_step(self, policy, carry, key):
    """One step of all E envs. Returns the new carry, a Transition [E, ...] and
    the sums over episodes that ended at this step (f32[] each)."""
    state, acc = carry
    action, policy_extras = policy(state.obs, key)  # f32[E, A]
    nstate = self.env.step(state, action)
    r_task, cost, done = nstate.info["task_reward"], nstate.info["cost"], nstate.done  # f32[E]
    success = nstate.metrics.get("success", jnp.zeros_like(done))
    ret, c = acc.task_return + r_task, acc.cost + cost
    completed = jnp.maximum(acc.completed, success)
    # AutoResetWrapper resets only pipeline_state/obs: info still holds the
    # final step's health here, i.e. the episode's final health.
    health = nstate.info["entity_health"]  # f32[E, N]
    safe = completed * (jnp.min(health, axis=-1) > self.safe_threshold)
    ended = {
        "episodes": jnp.sum(done),
        "return": jnp.sum(done * ret),
        "cost": jnp.sum(done * c),
        "completion": jnp.sum(done * completed),
        "safe_completion": jnp.sum(done * safe),
        "health": jnp.sum(done * jnp.mean(health, axis=-1)),
    }
    acc = jax.tree.map(lambda x: jnp.where(done > 0, 0.0, x), EpisodeAcc(ret, c, completed))
    transition = types.Transition(
        observation=state.obs,
        action=action,
        reward=r_task,  # shaped after the rollout, once λ is known (see collect)
        discount=1.0 - done,
        next_observation=nstate.obs,
        extras={
            "policy_extras": policy_extras,
            "state_extras": {"truncation": nstate.info["truncation"], "cost": cost},
        },
    )
    return (nstate, acc), (transition, ended)

  def collect(self, ts: TrainState):
    """Roll out R·T steps of all envs with the current stochastic policy.

    Returns (ts with new env state/accumulators/rng, data: Transition with
    leading dims [R·E, T], ended-episode sums f32[] each).
    """
    key, k_unroll = jax.random.split(ts.rng)
    policy = self.make_policy((ts.normalizer, ts.params.policy))
    step = functools.partial(self._env_step, policy)
    keys = jax.random.split(k_unroll, (self.cfg.num_rollouts, self.cfg.unroll_length))

    def unroll(carry, keys_t):
      return jax.lax.scan(step, carry, keys_t)

    (env_state, acc), (data, ended) = jax.lax.scan(unroll, (ts.env_state, ts.episode), keys)
    # [R, T, E, ...] → [R, E, T, ...] → [R·E, T, ...]: sequences first, as the loss expects.
    data = jax.tree.map(lambda x: jnp.swapaxes(x, 1, 2).reshape((-1,) + x.shape[1:2] + x.shape[3:]), data)
    ended = jax.tree.map(jnp.sum, ended)
    return ts.replace(env_state=env_state, episode=acc, rng=key), data, ended

  # -- learning -------------------------------------------------------------
  def _sgd_epoch(self, normalizer, data, carry, key):
    """One pass over the batch in ``num_minibatches`` shuffled minibatches."""
    params, opt_state = carry
    k_perm, k_loss = jax.random.split(key)
    n_mb = self.cfg.num_minibatches
    shuffled = jax.tree.map(
        lambda x: jax.random.permutation(k_perm, x).reshape((n_mb, -1) + x.shape[1:]), data)

    def minibatch(carry, inp):
      params, opt_state = carry
      mb, k = inp
      (_, metrics), params, opt_state = self.gradient_update(params, normalizer, mb, k, optimizer_state=opt_state)
      return (params, opt_state), metrics

    return jax.lax.scan(minibatch, (params, opt_state), (shuffled, jax.random.split(k_loss, n_mb)))

  def update(self, ts: TrainState, data: types.Transition):
    """Normaliser update then ``num_updates_per_batch`` SGD epochs on ``data`` [R·E, T]."""
    key, k_sgd = jax.random.split(ts.rng)
    normalizer = ts.normalizer
    if self.cfg.normalize_observations:
      normalizer = running_statistics.update(normalizer, data.observation)
    (params, opt_state), metrics = jax.lax.scan(
        functools.partial(self._sgd_epoch, normalizer, data),
        (ts.params, ts.opt_state),
        jax.random.split(k_sgd, self.cfg.num_updates_per_batch),
    )
    ts = ts.replace(params=params, opt_state=opt_state, normalizer=normalizer, rng=key)
    return ts, jax.tree.map(jnp.mean, metrics)

  def train_iteration(self, ts: TrainState):
    """One PPO(-Lagrangian) iteration. Pure: ``(TrainState) -> (TrainState, metrics f32[] dict)``."""
    sh = ts.shaping
    ts, data, ended = self.collect(ts)
    # Reward shaping with the multiplier the rollout was collected under.
    cost = data.extras["state_extras"]["cost"]  # f32[R·E, T]
    data = data._replace(reward=shape_reward(data.reward, cost, sh.damage_weight, ts.lagrange))
    # Mean cost of episodes that ended in this rollout; keep the last estimate if none did.
    n = ended["episodes"]
    any_ended = n > 0
    cost_estimate = jnp.where(any_ended, ended["cost"] / jnp.maximum(n, 1.0), ts.cost_estimate)
    has_estimate = jnp.maximum(ts.has_cost_estimate, any_ended.astype(jnp.float32))
    lam_new = lagrange_update(ts.lagrange, cost_estimate, sh.budget, sh.lagrange_lr, sh.lagrange_max)
    lam = jnp.where((sh.lagrangian > 0) & (has_estimate > 0), lam_new, ts.lagrange)
    ts, loss_metrics = self.update(ts, data)
    ts = ts.replace(lagrange=lam, cost_estimate=cost_estimate, has_cost_estimate=has_estimate,
                    iteration=ts.iteration + 1)
    metrics = {f"ended_{k}": v for k, v in ended.items()}
    metrics.update({f"loss/{k}": v for k, v in loss_metrics.items()
                    if k in ("total_loss", "policy_loss", "v_loss", "entropy_loss", "kl_mean")})
    metrics.update(
        step_reward=jnp.mean(data.reward),
        step_cost=jnp.mean(cost),
        lagrange=lam,
        cost_estimate=cost_estimate,
    )
    return ts, metrics

  # -- evaluation -----------------------------------------------------------
  def make_evaluator(self) -> "E.Evaluator":
    """The deterministic policy's :class:`train.evaluate.Evaluator` on ``base_env``, ``episode_length`` steps.

    Weights are data: ``evaluator.run(keys, 1.0, params=self.inference_params(ts))``
    evaluates any iteration's policy with one compilation per batch size.
    """
    apply = _policy_apply(self.make_policy, deterministic=True)
    return E.Evaluator(self.base_env, E.parametrized_policy(apply, None), self.cfg.episode_length)

  def evaluate(self, evaluator: "E.Evaluator", ts: TrainState, key, num_episodes: int) -> dict:
    """``num_episodes`` episodes of ``ts``'s deterministic policy → the flat summary
    (:func:`train.evaluate.scalar_metrics`: completion, safe_completion, avg_env_health, …).

    Episode i uses ``split(key, num_episodes)[i]``; an episode stops counting at its first ``done``.
    """
    keys = np.asarray(jax.random.split(key, num_episodes))
    per_ep = evaluator.run(keys, 1.0, params=self.inference_params(ts))
    return E.scalar_metrics(E.metrics(per_ep, self.base_env.entity_names, self.safe_threshold))


def make_optimizer(cfg: PPOConfig) -> optax.GradientTransformation:
  """Adam, with the gradient norm clipped per network (policy and value apart).

  Why apart: damage costs make rare, very large rewards (one drop can cost
  hundreds of health points in a step), so the value loss's gradient can be
  orders of magnitude larger than the policy's. One global-norm clip over both
  would then shrink the policy's step to nothing whenever the critic is
  surprised; clipping each network by its own norm keeps the policy learning.
  """
  def one():
    adam = optax.adam(cfg.learning_rate)
    return adam if cfg.max_grad_norm is None else optax.chain(optax.clip_by_global_norm(cfg.max_grad_norm), adam)

  def labels(params: ppo_losses.PPONetworkParams):
    return ppo_losses.PPONetworkParams(policy=jax.tree.map(lambda _: "policy", params.policy),
                                       value=jax.tree.map(lambda _: "value", params.value))

  return optax.multi_transform({"policy": one(), "value": one()}, labels)


def make_networks(obs_size: int, action_size: int, cfg: PPOConfig) -> ppo_networks.PPONetworks:
  normalize = running_statistics.normalize if cfg.normalize_observations else types.identity_observation_preprocessor
  return ppo_networks.make_ppo_networks(
      obs_size,
      action_size,
      preprocess_observations_fn=normalize,
      policy_hidden_layer_sizes=tuple(cfg.policy_hidden_sizes),
      value_hidden_layer_sizes=tuple(cfg.value_hidden_sizes),
      activation=ACTIVATIONS[cfg.activation],
  )


def _policy_apply(make_policy, deterministic: bool):
  def apply(params, state, rng):
    return make_policy(params, deterministic=deterministic)(state.obs, rng)[0]
  return apply


# ---------------------------------------------------------------------------
# Results, logging
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class TrainResult:
  out_dir: Optional[str]
  task: str
  config: PPOConfig
  env_steps: int
  iterations: int
  wall_time: float  # s, whole call including compilation and evaluations
  train_time: float  # s, iterations only (compilation excluded)
  throughput: float  # training env-steps per second of train_time
  final_eval: dict
  history: list  # one dict per evaluation (the rows of metrics.jsonl)
  timings: dict  # s: compile (1st iteration), eval_compile (1st eval), iterations, eval, checkpoint, host
  policy: Callable  # policy(state, rng) -> action for ONE env, deterministic
  train_state: TrainState
  stopped_early: bool = False


class _Log:
  """metrics.jsonl + metrics.csv in out_dir (nothing without out_dir)."""

  def __init__(self, out_dir: Optional[str], rows: list):
    self.out_dir, self.rows = out_dir, list(rows)
    self._rewrite()

  def _rewrite(self):
    if self.out_dir is None:
      return
    with open(os.path.join(self.out_dir, "metrics.jsonl"), "w") as f:
      for r in self.rows:
        f.write(json.dumps(r) + "\n")
    self._write_csv()

  def _write_csv(self):
    if not self.rows:
      return
    keys = list(dict.fromkeys(k for r in self.rows for k in r))
    with open(os.path.join(self.out_dir, "metrics.csv"), "w", newline="") as f:
      w = csv.DictWriter(f, fieldnames=keys)
      w.writeheader()
      w.writerows(self.rows)

  def append(self, row: dict):
    self.rows.append(row)
    if self.out_dir is None:
      return
    with open(os.path.join(self.out_dir, "metrics.jsonl"), "a") as f:
      f.write(json.dumps(row) + "\n")
    self._write_csv()


def _read_rows(out_dir: str) -> list:
  path = os.path.join(out_dir, "metrics.jsonl")
  if not os.path.exists(path):
    return []
  with open(path) as f:
    return [json.loads(line) for line in f if line.strip()]


# ---------------------------------------------------------------------------
# The training loop
# ---------------------------------------------------------------------------
def train(
    task,
    *,
    damage_weight: float = 0.0,
    budget: Optional[float] = None,
    num_envs: int = 1024,
    num_timesteps: int = 1_000_000,
    seed: int = 0,
    policy_hidden_sizes: Sequence[int] = (256, 256),
    value_hidden_sizes: Sequence[int] = (256, 256),
    activation: str = "swish",
    learning_rate: float = 3e-4,
    clipping_epsilon: float = 0.2,
    discounting: float = 0.97,
    gae_lambda: float = 0.95,
    entropy_cost: float = 1e-3,
    reward_scaling: float = 1.0,
    max_grad_norm: Optional[float] = 1.0,
    unroll_length: int = 20,
    num_minibatches: int = 8,
    num_updates_per_batch: int = 4,
    batch_size: Optional[int] = None,
    episode_length: Optional[int] = None,
    normalize_observations: bool = True,
    lagrange_lr: float = 0.1,
    lagrange_init: float = 0.0,
    lagrange_max: float = 5.0,
    num_eval_envs: int = 128,
    eval_every: int = 0,
    checkpoint_every: int = 0,
    out_dir: Optional[str] = None,
    resume: bool = False,
    progress: bool = True,
    time_limit: Optional[float] = None,
    task_kwargs: Optional[dict] = None,
    profile: bool = False,
    plot: bool = True,
) -> TrainResult:
  """Train PPO (``budget=None``) or PPO-Lagrangian (``budget`` = ĉ ≥ 0) on ``task``.

  Args:
    task: a registered task name (``tasks.make``) or a Brax env tracking damage.
    damage_weight: w in ``r = (r_task − (w + λ)·cost) / (1 + λ)`` (λ ≡ 0 without a budget).
    budget: episode-cost budget ĉ; enables the Lagrange multiplier λ.
    num_timesteps: training env steps (rounded up to whole iterations).
    eval_every / checkpoint_every: env steps between evaluations / checkpoints
      (0: only at the end). Evaluation: ``num_eval_envs`` deterministic episodes.
    out_dir: where config.json, metrics.jsonl/.csv, checkpoint.npz and
      curves.png go; None keeps everything in memory.
    resume: continue from ``out_dir/checkpoint.npz`` (same config; only
      num_timesteps, eval_every, checkpoint_every, num_eval_envs may change).
    time_limit: stop after the iteration that crosses this many seconds of
      wall-clock (then evaluate, checkpoint and return as usual).
    profile: time rollout-only vs whole iterations at the end (one extra compile).
  Returns:
    :class:`TrainResult`; ``result.policy(state, rng) -> action`` is the final
    deterministic policy for one env.
  """
  t_start = time.perf_counter()
  cfg = PPOConfig(
      num_envs=num_envs, num_timesteps=num_timesteps,
      episode_length=1 if episode_length is None else episode_length,  # None: the task's, below
      unroll_length=unroll_length, num_minibatches=num_minibatches,
      num_updates_per_batch=num_updates_per_batch, batch_size=batch_size,
      learning_rate=learning_rate, clipping_epsilon=clipping_epsilon, discounting=discounting,
      gae_lambda=gae_lambda, entropy_cost=entropy_cost, reward_scaling=reward_scaling,
      max_grad_norm=max_grad_norm,
      policy_hidden_sizes=tuple(policy_hidden_sizes) if isinstance(policy_hidden_sizes, (list, tuple)) else policy_hidden_sizes,
      value_hidden_sizes=tuple(value_hidden_sizes) if isinstance(value_hidden_sizes, (list, tuple)) else value_hidden_sizes,
      activation=activation, normalize_observations=normalize_observations,
      damage_weight=damage_weight, budget=budget, lagrange_lr=lagrange_lr,
      lagrange_init=lagrange_init, lagrange_max=lagrange_max, num_eval_envs=num_eval_envs,
      eval_every=eval_every, checkpoint_every=checkpoint_every, seed=seed,
  ).validate()
  if time_limit is not None and (isinstance(time_limit, bool) or not isinstance(time_limit, (int, float)) or not time_limit > 0):
    raise ValueError(f"time_limit: must be a number of seconds > 0, got {time_limit!r}")
  if resume and out_dir is None:
    raise ValueError("resume: needs out_dir (where the checkpoint is)")
  env, task_name = resolve_task(task, task_kwargs)
  if episode_length is None:
    cfg = dataclasses.replace(cfg, episode_length=task_episode_length(env))
  trainer = Trainer(env, cfg)

  ckpt_path = None
  if out_dir is not None:
    out_dir = os.fspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    ckpt_path = os.path.join(out_dir, ckpt.FILENAME)
  meta = {
      "task": task_name, "task_kwargs": task_kwargs or {}, "config": cfg.to_json(),
      "obs_size": trainer.obs_size, "action_size": trainer.action_size,
      "steps_per_iteration": cfg.steps_per_iteration,
  }

  # -- initial state: fresh or from the checkpoint --------------------------
  timings = {"compile": 0.0, "eval_compile": 0.0, "iterations": 0.0, "eval": 0.0, "checkpoint": 0.0, "host": 0.0}
  first_eval = True
  rows: list = []
  if resume and ckpt_path and os.path.exists(ckpt_path):
    old = ckpt.read_meta(ckpt_path)
    diff = [k for k, v in cfg.to_json().items()
            if k not in _RESUMABLE_CHANGES and old["config"].get(k) != v]
    if diff or old["task"] != task_name:
      raise ValueError(f"resume: checkpoint in {out_dir} was made with a different config ({', '.join(diff) or 'task'})")
    template = jax.eval_shape(trainer.init, cfg.seed)
    ts = jax.device_put(ckpt.restore(ckpt_path, template, "state"))
    start_iteration = int(ts.iteration)
    # Rows logged after the checkpoint were produced by the interrupted tail: redo them.
    rows = [r for r in _read_rows(out_dir) if r["iteration"] <= start_iteration]
  else:
    if resume:
      print(f"resume: no checkpoint in {out_dir}; starting a fresh run", file=sys.stderr)
    ts = trainer.with_shaping(jax.jit(trainer.init_state)(cfg.seed))
    start_iteration = 0
  if out_dir is not None:
    with open(os.path.join(out_dir, "config.json"), "w") as f:
      json.dump(meta, f, indent=1, default=repr)
  log = _Log(out_dir, rows)

  # Donating the state lets XLA update the env batch in place (GPU memory).
  iteration_fn = jax.jit(trainer.train_iteration, donate_argnums=0)
  evaluator = trainer.make_evaluator()
  eval_key = jax.random.PRNGKey(cfg.seed + 1)

  n_iter = cfg.num_iterations
  eval_int = cfg.interval_iterations(cfg.eval_every)
  ckpt_int = cfg.interval_iterations(cfg.checkpoint_every)
  bar = None
  if progress:
    from tqdm import tqdm
    bar = tqdm(total=n_iter * cfg.steps_per_iteration, initial=start_iteration * cfg.steps_per_iteration,
               unit="step", unit_scale=True, desc=f"{task_name} {'λ' if cfg.lagrangian else f'w={cfg.damage_weight:g}'}",
               dynamic_ncols=True)

  window: dict = {}  # training-episode sums since the last logged row
  stopped_early = False
  final_eval: dict = {}
  iteration = start_iteration
  compiled = False
  for iteration in range(start_iteration + 1, n_iter + 1):
    t0 = time.perf_counter()
    ts, m = iteration_fn(ts)
    m = jax.device_get(m)  # blocks: the iteration has finished
    dt = time.perf_counter() - t0
    if compiled:
      timings["iterations"] += dt
    else:  # the first call compiles; don't count it as training throughput
      timings["compile"] += dt
      compiled = True
    t_host = time.perf_counter()
    for k in ("episodes", "return", "cost", "completion", "safe_completion", "health"):
      window[k] = window.get(k, 0.0) + float(m[f"ended_{k}"])
    last = iteration == n_iter
    if time_limit is not None and time.perf_counter() - t_start > time_limit and not last:
      stopped_early = last = True
    if bar is not None:
      n = max(window["episodes"], 1.0)
      post = {"ret": f"{window['return'] / n:.3g}", "succ": f"{window['completion'] / n:.2f}",
              "cost": f"{window['cost'] / n:.3g}"}
      if cfg.lagrangian:
        post["λ"] = f"{float(m['lagrange']):.3g}"
      bar.set_postfix(post, refresh=False)
      bar.update(cfg.steps_per_iteration)
    timings["host"] += time.perf_counter() - t_host

    if last or (eval_int and iteration % eval_int == 0):
      t0 = time.perf_counter()
      ev = trainer.evaluate(evaluator, ts, jax.random.fold_in(eval_key, iteration), cfg.num_eval_envs)
      # The first evaluation compiles the evaluation program: book it apart.
      timings["eval_compile" if first_eval else "eval"] += time.perf_counter() - t0
      first_eval = False
      n = window.get("episodes", 0.0)
      row = {"iteration": iteration, "env_steps": iteration * cfg.steps_per_iteration,
             "wall_time": round(time.perf_counter() - t_start, 3),
             "train/episodes": n}
      for k in ("return", "cost", "completion", "safe_completion", "health"):
        row[f"train/episode_{k}"] = window[k] / n if n else None
      row.update({k: float(v) for k, v in m.items() if not k.startswith("ended_")})
      row.update({f"eval/{k}": v for k, v in ev.items()})
      log.append(row)
      window = {}
      final_eval = ev
    if ckpt_path and (last or (ckpt_int and iteration % ckpt_int == 0)):
      t0 = time.perf_counter()
      ckpt.save(ckpt_path, ts, trainer.inference_params(ts), dict(meta, iteration=iteration,
                env_steps=iteration * cfg.steps_per_iteration))
      timings["checkpoint"] += time.perf_counter() - t0
    if last:
      break
  if bar is not None:
    bar.close()

  if not final_eval and start_iteration >= n_iter:  # resumed a finished run: evaluate once
    final_eval = trainer.evaluate(evaluator, ts, jax.random.fold_in(eval_key, start_iteration), cfg.num_eval_envs)
  if profile:
    timings.update(profile_iteration(trainer, ts, iteration_fn=iteration_fn))
  if out_dir is not None and plot and log.rows:
    from train import plots
    plots.plot_training(log.rows, os.path.join(out_dir, "curves.png"), title=task_name,
                        budget=cfg.budget)
  done_iters = iteration - start_iteration
  timed_iters = done_iters - 1 if done_iters > 1 else 0
  train_steps = timed_iters * cfg.steps_per_iteration
  params = trainer.inference_params(ts)
  make_policy = trainer.make_policy
  return TrainResult(
      out_dir=out_dir,
      task=task_name,
      config=cfg,
      env_steps=iteration * cfg.steps_per_iteration,
      iterations=iteration,
      wall_time=time.perf_counter() - t_start,
      train_time=timings["iterations"],
      throughput=train_steps / timings["iterations"] if timings["iterations"] > 0 else float("nan"),
      final_eval=final_eval,
      history=log.rows,
      timings=timings,
      policy=lambda state, rng: make_policy(params, deterministic=True)(state.obs, rng)[0],
      train_state=ts,
      stopped_early=stopped_early,
  )


def profile_iteration(trainer: Trainer, ts: TrainState, repeats: int = 3, iteration_fn=None) -> dict:
  """Where an iteration's time goes: rollout (env step + policy inference) vs the rest.

  Compiles ``collect`` alone (one extra compile) and times it against the full
  iteration on copies of ``ts`` (nothing of the run is changed). Returns seconds
  per iteration: ``profile/rollout``, ``profile/iteration``, ``profile/update``
  (= iteration − rollout: reward shaping, normaliser, SGD).
  """
  collect = jax.jit(lambda s: trainer.collect(s)[1:])
  # Reuse the run's (donating) iteration function: a non-donating jit would be
  # a different program, i.e. a second full compile. It gets a fresh copy of
  # the state each call (made before the clock starts).
  full = iteration_fn or jax.jit(trainer.train_iteration, donate_argnums=0)
  fresh = lambda: jax.block_until_ready(jax.tree.map(jnp.copy, ts))  # noqa: E731

  def timeit(f, copy):
    best = float("inf")
    for _ in range(repeats + 1):  # the first call compiles (or loads from the cache)
      arg = fresh() if copy else ts
      t0 = time.perf_counter()
      jax.block_until_ready(f(arg))
      best = min(best, time.perf_counter() - t0)
    return best

  t_roll, t_full = timeit(collect, False), timeit(full, True)
  return {"profile/rollout": t_roll, "profile/iteration": t_full, "profile/update": max(t_full - t_roll, 0.0)}


# ---------------------------------------------------------------------------
# Loading a trained policy (evaluate it with train.evaluate / train.evaluate_policy)
# ---------------------------------------------------------------------------
def load_policy(path: str, env=None, deterministic: bool = True):
  """Load a trained policy from a run directory or a checkpoint file.

  Returns ``policy(state, rng) -> action`` for ONE env (``state.obs`` f32[O] →
  action f32[A]); jittable and vmappable. Deterministic (the distribution's
  mode) unless ``deterministic=False``. With ``env`` given, its observation and
  action sizes are checked against the checkpoint. ``policy.meta`` holds the
  run's config.
  """
  path = os.fspath(path)
  file = os.path.join(path, ckpt.FILENAME) if os.path.isdir(path) else path
  if not os.path.isfile(file):
    raise ValueError(f"path: no checkpoint at {file}")
  meta = ckpt.read_meta(file)
  cfg = PPOConfig.from_json(meta["config"])
  obs_size, action_size = int(meta["obs_size"]), int(meta["action_size"])
  if env is not None:
    e_obs = jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape[-1]
    if (e_obs, env.action_size) != (obs_size, action_size):
      raise ValueError(f"env: observation/action sizes {(e_obs, env.action_size)} differ from the "
                       f"checkpoint's {(obs_size, action_size)}")
  network = make_networks(obs_size, action_size, cfg)
  template = jax.eval_shape(lambda: (running_statistics.init_state(jnp.zeros((obs_size,), jnp.float32)),
                                     network.policy_network.init(jax.random.PRNGKey(0))))
  params = jax.device_put(ckpt.restore(file, template, "policy"))
  make_policy = ppo_networks.make_inference_fn(network)

  # policy.apply(params, state, rng) / policy.params: the same policy with explicit
  # weights, which train.evaluate passes as data instead of baking them in.
  policy = E.parametrized_policy(_policy_apply(make_policy, deterministic), params)
  policy.meta = meta
  return policy


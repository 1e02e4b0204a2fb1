"""One PPO(-Lagrangian) iteration as a pure function of one seed's train state (purejaxrl style).

``Trainer.train_iteration(ts) -> (ts, metrics)``: rollout of R·T steps of all
E envs (``lax.scan``), reward shaping with the multiplier the rollout was
collected under, multiplier update, observation-normaliser update, then
``num_updates_per_batch`` epochs of ``num_minibatches`` minibatches (nested
``lax.scan``; with ``normalizer_after_update`` the epochs use the statistics the
rollout was collected under); GAE and the clipped loss are brax's ``compute_ppo_loss``
(with ``gae_per_iteration`` GAE runs once, before the epochs: train.iteration_targets).
Nothing here loops in Python and nothing depends on the seed count: the run
loop (train.ppo) vmaps this function over a leading seed axis of the whole
:class:`TrainState` and jits it once, so S seeds are one program and one call
per iteration.

Policy reward per step::

    r = (r_task − (w + λ)·cost) / (1 + λ)

``r_task = info["task_reward"]``, ``cost = info["cost"]`` (DamageWrapper at weight
0: w and λ are traced values, not constants baked into the env). With λ ≡ 0
(penalty / task-only) this is the paper's r_task − w·cost. The 1/(1 + λ) factor
keeps the return scale bounded while λ grows (episode cost is unbounded) and
leaves the task/cost trade-off set by λ. With ``cost_critic`` the reward stays
r_task and the loss mixes separate reward and cost advantages the same way
(train.constrained_loss), so a change of λ does not invalidate the critic.

Time limits: brax's EpisodeWrapper marks the last step of an episode with
``truncation = 1`` and ``done = 1``; the loss treats ``done ∧ ¬truncation`` as
termination (no bootstrap) and masks the truncated step's TD error, so a time
limit is never learnt as a terminal state. The tasks used for RL never set
``done`` themselves (no success or destruction termination), so every episode
end is a truncation.

Several devices (train.mesh): with ``axis_name`` the function runs inside
``shard_map`` on one shard of the env batch; the episode sums are summed, the
gradients, normaliser statistics and loss metrics averaged over that axis (so
every shard keeps the same weights), and the sampling/shuffling keys are
folded with the shard index. ``axis_name=None``: one device, no collectives.

Shapes: E = num_envs (on one shard: num_envs / shards), T = unroll_length, R = num_rollouts, O = observation
size, A = action size, N = tracked entities.
"""

from __future__ import annotations

import functools
from typing import Any, Optional

import flax
import jax
import jax.numpy as jnp
import numpy as np
from brax.envs.base import Env, State
from brax.envs.wrappers import training as brax_training
from brax.training import types
from brax.training.acme import running_statistics
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks

from train import evaluate as E
from train import iteration_targets as IT
from train import memory as MEM
from train import multipliers as M
from train import networks as N
from train.config import PPOConfig
from train.envs import safe_threshold_of

LOSS_KEYS = ("total_loss", "policy_loss", "v_loss", "entropy_loss", "kl_mean", "policy_dist_mean_std")


@flax.struct.dataclass
class EpisodeAcc:
  """Running sums of the episode in progress in each training env, f32[E] each."""

  task_return: jax.Array
  cost: jax.Array
  completed: jax.Array  # 1.0 once the success condition has held


@flax.struct.dataclass
class TrainState:
  """One seed's whole training state (the run loop adds a leading seed axis S to every leaf)."""

  params: ppo_losses.PPONetworkParams
  opt_state: Any
  normalizer: running_statistics.RunningStatisticsState
  env_state: State  # batched over E
  episode: EpisodeAcc
  multiplier: M.MultiplierState
  multiplier_params: M.MultiplierParams
  damage_weight: jax.Array  # f32[], w
  cost_estimate: jax.Array  # f32[], last measured mean episode cost J_c
  has_cost_estimate: jax.Array  # f32[], 1.0 once any training episode has ended
  rng: jax.Array  # u32[2]
  iteration: jax.Array  # i32[]
  # i32[], the iteration the penalty's ramp starts at (NOT_YET until the completion gate opens); None (no leaf)
  # without ``damage_warmup_completion``, so checkpoints of runs without it keep their layout
  penalty_start: Optional[jax.Array] = None

  @property
  def lagrange(self):
    return self.multiplier.lam


def annealed_entropy(entropy_cost: float, iteration, num_iterations: int):
  """Entropy coefficient at ``iteration`` (i32[]) of a run of ``num_iterations``: linear from ``entropy_cost``
  at the first iteration to 0 at the last one's end, and 0 after (a run stopped by time ends earlier)."""
  return entropy_cost * jnp.clip(1.0 - iteration.astype(jnp.float32) / num_iterations, 0.0, 1.0)


def scheduled_weight(damage_weight, iteration, warmup, ramp):
  """w at ``iteration`` (i32[]) of the penalty schedule (config ``damage_warmup_steps``/``damage_ramp_steps``,
  in iterations): 0 before ``warmup``, then linear up to ``damage_weight`` over ``ramp`` iterations."""
  t = (iteration - warmup).astype(jnp.float32)
  frac = jnp.clip((t + 1.0) / ramp, 0.0, 1.0) if ramp > 0 else (t >= 0).astype(jnp.float32)
  return damage_weight * frac


NOT_YET = jnp.iinfo(jnp.int32).max  # penalty_start while the completion gate is shut


def penalty_gate(start, iteration, completed, episodes, rate, min_iterations):
  """``penalty_start`` (i32[]) after ``iteration``'s rollout: still ``start`` unless the gate is shut
  (``start == NOT_YET``) and this rollout's ``episodes`` (f32[], finished) ``completed`` (f32[], how many of
  them completed) the task at ``rate`` or more, with ``iteration + 1 >= min_iterations`` (the step-count
  warm-up); then ``iteration + 1``, the first iteration to train with the ramp."""
  opens = (episodes > 0) & (completed >= rate * episodes) & (iteration + 1 >= min_iterations)
  return jnp.where((start == NOT_YET) & opens, iteration + 1, start).astype(jnp.int32)


def max_abs_z(normalizer, observation):
  """The largest |normalised observation| of ``observation`` f32[..., O] (f32[]): what the networks' first
  layers receive before any ``obs_clip``. A coordinate the normaliser's early statistics saw still gets a std near brax's 1e-6
  floor, and once a policy moves it this grows far past unit scale (Shelve Item's unclipped run: 10^2-10^3 in
  its first iterations, then its value loss blew up; docs/rl_task_design.md, "Shelve Item: the gap between the
  trainers is the observation normaliser")."""
  return jnp.max(jnp.abs(running_statistics.normalize(observation, normalizer)))


# update() metrics reported under their own names; the others are the loss's, reported as loss/<name>
UNPREFIXED = ("sgd_steps", "obs_max_abs_z")


def shape_reward(r_task, cost, damage_weight, lam):
  """Policy reward ``(r_task − (w + λ)·cost) / (1 + λ)``; any matching shapes (module docstring)."""
  return (r_task - (damage_weight + lam) * cost) / (1.0 + lam)


REDRAW_STREAM = 0x5EED  # folded into an iteration's key for its fresh starts (Trainer._redraw_starts)


class Trainer:
  """The static parts of a run (envs, networks, optimizer); every method is a pure function."""

  def __init__(self, env: Env, cfg: PPOConfig, axis_name: Optional[str] = None):
    """``axis_name``: the mesh axis the env batch is split over (train.mesh); None on one shard."""
    self.cfg = cfg.validate()
    self.axis_name = axis_name
    self.base_env = env
    self.safe_threshold = safe_threshold_of(env)
    episodic = brax_training.EpisodeWrapper(env, cfg.episode_length, action_repeat=1)
    # Training: auto-resetting batch (brax's order: Episode → Vmap → AutoReset).
    self.env = brax_training.AutoResetWrapper(brax_training.VmapWrapper(episodic))
    self.footprint = MEM.footprint(env)  # one env's State bytes and liquid particles: the memory estimate
    obs_shape = jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape
    if len(obs_shape) != 1:
      raise ValueError(f"task: observations must be flat vectors, got shape {obs_shape}")
    self.obs_size, self.action_size = int(obs_shape[0]), int(env.action_size)
    if self.action_size < 1:
      raise ValueError("task: the env has no actions to learn")
    self.network = N.make_networks(self.obs_size, self.action_size, cfg)
    self.make_policy = ppo_networks.make_inference_fn(self.network)
    self.optimizer = N.make_optimizer(cfg)
    self.gradient_update = N.make_gradient_update(self.network, self.optimizer, cfg, axis_name)

  # -- across env shards (identities when axis_name is None) -----------------
  def _local(self, key):
    """A key of this env shard's own: envs on different shards must not share sampling noise."""
    return key if self.axis_name is None else jax.random.fold_in(key, jax.lax.axis_index(self.axis_name))

  def _psum(self, tree):
    return tree if self.axis_name is None else jax.lax.psum(tree, self.axis_name)

  def _pmean(self, tree):
    return tree if self.axis_name is None else jax.lax.pmean(tree, self.axis_name)

  def _pmax(self, tree):
    return tree if self.axis_name is None else jax.lax.pmax(tree, self.axis_name)

  # -- init -----------------------------------------------------------------
  def init_states(self, seeds) -> TrainState:
    """Fresh state of every run (``seeds`` i32[S]), each with its seed's w from the config."""
    return jax.vmap(self.init_state)(seeds, jnp.asarray(self.cfg.damage_weights, jnp.float32))

  def init_state(self, seed, damage_weight) -> TrainState:
    """Fresh state of one seed (``seed`` i32[], ``damage_weight`` f32[] its run's w; traced: vmap them)."""
    cfg = self.cfg
    key = jax.random.PRNGKey(seed)
    key, k_net, k_env = jax.random.split(key, 3)
    params = N.init_params(self.network, cfg, self.action_size, k_net)
    zeros = jnp.zeros((cfg.num_envs,), jnp.float32)
    f32 = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
    kind = (M.PID if cfg.multiplier == "pid" else M.LAGRANGIAN) if cfg.lagrangian else M.FIXED
    plain = cfg.multiplier == "lagrangian"
    return TrainState(
        params=params,
        opt_state=self.optimizer.init(params),
        normalizer=running_statistics.init_state(jnp.zeros((self.obs_size,), jnp.float32)),
        env_state=self.env.reset(jax.random.split(k_env, cfg.num_envs)),
        episode=EpisodeAcc(zeros, zeros, zeros),
        multiplier=M.init(cfg.lagrange_init if cfg.lagrangian else 0.0),
        multiplier_params=M.MultiplierParams(
            kind=f32(kind), budget=f32(cfg.budget or 0.0), kp=f32(0.0 if plain else cfg.pid_kp),
            ki=f32(cfg.lagrange_lr if plain else cfg.pid_ki), kd=f32(0.0 if plain else cfg.pid_kd),
            lam_max=f32(cfg.lagrange_max), anneal_updates=f32(cfg.budget_anneal_iterations)),
        damage_weight=f32(damage_weight),
        cost_estimate=f32(0.0),
        has_cost_estimate=f32(0.0),
        rng=key,
        iteration=jnp.zeros((), jnp.int32),
        penalty_start=jnp.asarray(NOT_YET, jnp.int32) if cfg.damage_warmup_completion > 0 else None,
    )

  def inference_params(self, ts: TrainState):
    """What a policy needs: ``(normaliser, policy params)`` (brax's inference-param layout)."""
    return (ts.normalizer, ts.params.policy)

  # -- acting ---------------------------------------------------------------
  def _env_step(self, policy, carry, key):
    """One step of all E envs → new carry, a Transition [E, ...], sums over episodes ending here (f32[])."""
    state, acc = carry
    action, policy_extras = policy(state.obs, key)  # f32[E, A]
    nstate = self.env.step(state, action)
    r_task, cost, done = nstate.info["task_reward"], nstate.info["cost"], nstate.done  # f32[E]
    success = nstate.metrics.get("success", jnp.zeros_like(done))
    ret, c = acc.task_return + r_task, acc.cost + cost
    completed = jnp.maximum(acc.completed, success)
    # AutoResetWrapper resets only pipeline_state/obs: info still holds the final step's health.
    health = nstate.info["entity_health"]  # f32[E, N]
    safe = completed * (jnp.min(health, axis=-1) > self.safe_threshold)
    ended = {
        "episodes": jnp.sum(done), "return": jnp.sum(done * ret), "cost": jnp.sum(done * c),
        "completion": jnp.sum(done * completed), "safe_completion": jnp.sum(done * safe),
        "health": jnp.sum(done * jnp.mean(health, axis=-1)),
        "diverged": jnp.sum(nstate.metrics.get("physics_diverged", jnp.zeros_like(done))),
    }
    acc = jax.tree.map(lambda x: jnp.where(done > 0, 0.0, x), EpisodeAcc(ret, c, completed))
    transition = types.Transition(
        observation=state.obs, action=action,
        reward=r_task,  # shaped after the rollout, once λ is known (train_iteration)
        discount=1.0 - done, next_observation=nstate.obs,
        extras={"policy_extras": policy_extras,
                "state_extras": {"truncation": nstate.info["truncation"], "cost": cost}},
    )
    return (nstate, acc), (transition, ended)

  def collect(self, ts: TrainState):
    """Roll out R·T steps of all envs with the stochastic policy → (ts, data [R·E, T, ...], ended sums)."""
    key, k_unroll = jax.random.split(ts.rng)
    env_state, acc = ts.env_state, ts.episode
    if self.cfg.redraw_starts_iterations:  # a key of its own: the run's stream is the same with it off
      env_state, acc = self._redraw_starts(ts, jax.random.fold_in(ts.rng, REDRAW_STREAM))
    policy = self.make_policy((ts.normalizer, ts.params.policy))
    step = functools.partial(self._env_step, policy)
    keys = jax.random.split(self._local(k_unroll), (self.cfg.num_rollouts, self.cfg.unroll_length))
    (env_state, acc), (data, ended) = jax.lax.scan(
        lambda carry, k: jax.lax.scan(step, carry, k), (env_state, acc), keys)
    # [R, T, E, ...] → [R, E, T, ...] → [R·E, T, ...]: sequences first, as the loss expects.
    data = jax.tree.map(lambda x: jnp.swapaxes(x, 1, 2).reshape((-1,) + x.shape[1:2] + x.shape[3:]), data)
    return ts.replace(env_state=env_state, episode=acc, rng=key), data, self._psum(jax.tree.map(jnp.sum, ended))

  def _redraw_starts(self, ts: TrainState, key):
    """``(env_state, episode sums)`` to roll out from: every iteration that is a positive multiple of
    ``redraw_starts_iterations``, a fresh reset of all E envs of this shard (new starts, task constants and
    damage parameters; the episodes under way are cut, uncounted, as brax's ``num_resets_per_eval`` cuts
    them); else ``ts``'s. A select, not a cond: under the seed vmap a cond computes both branches anyway, and
    one reset costs about one physics step of the iteration's ``unroll_length·num_rollouts``."""
    n_envs = ts.episode.cost.shape[0]
    fresh = self.env.reset(jax.random.split(self._local(key), n_envs))
    due = (ts.iteration > 0) & (ts.iteration % self.cfg.redraw_starts_iterations == 0)
    pick = lambda new, old: jnp.where(due, new, old).astype(old.dtype)  # noqa: E731
    zeros = jax.tree.map(jnp.zeros_like, ts.episode)
    return jax.tree.map(pick, fresh, ts.env_state), jax.tree.map(pick, zeros, ts.episode)

  # -- learning -------------------------------------------------------------
  def _minibatch(self, normalizer, weights, start_policy, carry, inp):
    """One SGD step; with ``target_kl`` (rule "minibatch") a step whose pre-update KL exceeds 1.5·target
    stops the rest (rule "epoch": see _epoch).

    That KL is the update's own: ``start_policy`` (the parameters when the epochs began) against the
    policy now, both under ``normalizer``. brax's ``kl_mean`` metric compares with the logits the
    rollout recorded, under the normaliser before this iteration's update; that shift alone can exceed
    the target and would stop the epochs before the first step (it did: issue 24's paper-preset runs
    took 0–1 of their 80 steps per iteration). SB3's rule, whose observations are normalised when
    collected, measures the same thing as this one.
    ``weights``: (w, λ, entropy coefficient): w and λ (f32[] each) are what the cost critic's loss mixes the
    advantages with."""
    params, opt_state, stopped = carry
    mb, key = inp
    (_, metrics), new_params, new_opt = self.gradient_update(params, normalizer, mb, key, *weights,
                                                             optimizer_state=opt_state)
    if self.cfg.target_kl is not None:
      metrics = dict(metrics, kl_update=self._update_kl(normalizer, start_policy, params.policy, mb.observation))
    metrics = self._pmean({k: metrics[k] for k in self._loss_keys})  # one KL on every shard: they stop together
    if self.cfg.target_kl is None:
      return (new_params, new_opt, stopped), (metrics, jnp.ones(()))
    stop = stopped
    if self.cfg.target_kl_rule == "minibatch":  # CleanRL's rule ("epoch") decides at an epoch's end: _epoch
      stop = stop | (metrics["kl_update"] > 1.5 * self.cfg.target_kl)
    keep = lambda old, new: jax.tree.map(lambda a, b: jnp.where(stop, a, b), old, new)  # noqa: E731
    return (keep(params, new_params), keep(opt_state, new_opt), stop), (metrics, 1.0 - stop.astype(jnp.float32))

  def _update_kl(self, normalizer, start_policy, policy, obs):
    """Mean KL(π_start ‖ π_policy) of the pre-tanh Gaussians over ``obs`` f32[B, T, O], both under
    ``normalizer``: how far the SGD steps so far have moved the policy. Exact (brax's ``kl_divergence``
    adds 1e-5 inside its log, a floor of 1e-5 per action dimension)."""
    dist = self.network.parametric_action_distribution
    start = dist.create_dist(jax.lax.stop_gradient(self.network.policy_network.apply(normalizer, start_policy, obs)))
    now = dist.create_dist(self.network.policy_network.apply(normalizer, policy, obs))
    ratio = jnp.square(start.scale / now.scale)
    kl = 0.5 * (ratio + jnp.square((start.loc - now.loc) / now.scale) - 1.0 - jnp.log(ratio))
    return jnp.mean(jnp.sum(kl, axis=-1))

  @property
  def _loss_keys(self):
    # the cost head's share of v_loss: which head diverged when the critic does (train.ppo.CriticDivergedWarning)
    return (LOSS_KEYS + (("cost_v_loss",) if self.cfg.cost_critic else ())
            + (("kl_update",) if self.cfg.target_kl is not None else ()))

  def _epoch(self, normalizer, weights, start_policy, data, carry, key):
    k_perm, k_loss = jax.random.split(key)
    n_mb = self.cfg.num_minibatches
    shuffled = jax.tree.map(lambda x: jax.random.permutation(k_perm, x).reshape((n_mb, -1) + x.shape[1:]), data)
    carry, (metrics, taken) = jax.lax.scan(functools.partial(self._minibatch, normalizer, weights, start_policy),
                                           carry, (shuffled, jax.random.split(k_loss, n_mb)))
    if self.cfg.target_kl is not None and self.cfg.target_kl_rule == "epoch":
      # CleanRL: the KL its last minibatch began with (before that step), against the target itself.
      params, opt_state, stopped = carry
      carry = (params, opt_state, stopped | (metrics["kl_update"][-1] > self.cfg.target_kl))
    return carry, (metrics, taken)

  def update(self, ts: TrainState, data: types.Transition):
    """Normaliser update, then ``num_updates_per_batch`` epochs on ``data`` [R·E, T] (brax's order; with
    ``normalizer_after_update`` the epochs see the rollout's statistics); the cost critic's loss mixes
    with the state's w and λ (the λ the data was collected under)."""
    weights = (self.damage_weight(ts), ts.multiplier.lam, self.entropy_cost(ts))
    key, k_sgd = jax.random.split(ts.rng)
    normalizer = ts.normalizer
    if self.cfg.normalize_observations and self.cfg.update_normalizer:
      normalizer = running_statistics.update(normalizer, data.observation, pmap_axis_name=self.axis_name)
    # brax's order normalises the epochs' inputs with the statistics just updated; SB3's (config
    # normalizer_after_update) with those the rollout's logits were computed under.
    sgd_normalizer = ts.normalizer if self.cfg.normalizer_after_update else normalizer
    if self.cfg.gae_per_iteration:  # fixed targets for every epoch, from the critic the rollout ended with
      data = IT.attach(self.network, sgd_normalizer, ts.params.value, data, cost_critic=self.cfg.cost_critic,
                       discounting=self.cfg.discounting, gae_lambda=self.cfg.gae_lambda,
                       reward_scaling=self.cfg.reward_scaling)
    (params, opt_state, _), (metrics, taken) = jax.lax.scan(
        functools.partial(self._epoch, sgd_normalizer, weights, ts.params.policy, data),
        (ts.params, ts.opt_state, jnp.zeros((), bool)),
        jax.random.split(self._local(k_sgd), self.cfg.num_updates_per_batch))
    metrics = {k: jnp.sum(v * taken) / jnp.maximum(jnp.sum(taken), 1.0) for k, v in metrics.items()}
    metrics["sgd_steps"] = jnp.sum(taken)
    if self.cfg.normalize_observations:
      metrics["obs_max_abs_z"] = self._pmax(max_abs_z(sgd_normalizer, data.observation))
    if self.cfg.critic_warmup_iterations:
      params, opt_state = self._hold_actor(ts, params, opt_state, ts.iteration < self.cfg.critic_warmup_iterations)
    return ts.replace(params=params, opt_state=opt_state, normalizer=normalizer, rng=key), metrics

  @staticmethod
  def _hold_actor(ts: TrainState, params, opt_state, hold):
    """While ``hold`` (critic warm-up), the actor's weights and its optimizer state stay as they were."""
    keep = lambda old, new: jax.tree.map(lambda a, b: jnp.where(hold, a, b), old, new)  # noqa: E731
    inner = dict(opt_state.inner_states)
    inner["policy"] = keep(ts.opt_state.inner_states["policy"], inner["policy"])
    return (params.replace(policy=keep(ts.params.policy, params.policy)),
            opt_state._replace(inner_states=inner))

  def damage_weight(self, ts: TrainState):
    """w of this iteration: ``ts.damage_weight`` under the config's penalty schedule (f32[])."""
    warmup, ramp = self.cfg.damage_schedule_iterations
    if ts.penalty_start is not None:  # the completion gate decides when the warm-up ends
      return scheduled_weight(ts.damage_weight, ts.iteration, ts.penalty_start, ramp)
    if not (warmup or ramp):
      return ts.damage_weight
    return scheduled_weight(ts.damage_weight, ts.iteration, warmup, ramp)

  def entropy_cost(self, ts: TrainState):
    """The entropy coefficient of this iteration: the config's (a constant) or, with ``anneal_entropy``,
    :func:`annealed_entropy` of it (f32[])."""
    if not self.cfg.anneal_entropy:
      return self.cfg.entropy_cost
    return annealed_entropy(self.cfg.entropy_cost, ts.iteration, self.cfg.num_iterations)

  def train_iteration(self, ts: TrainState):
    """``(TrainState) -> (TrainState, metrics: dict of f32[])`` for one seed."""
    lam = ts.multiplier.lam
    w = self.damage_weight(ts)  # before collect: update() sees the same iteration
    ts, data, ended = self.collect(ts)
    cost = data.extras["state_extras"]["cost"]  # f32[R·E, T]
    shaped = shape_reward(data.reward, cost, w, lam)
    if not self.cfg.cost_critic:  # with a cost critic the loss mixes the advantages instead (train.constrained_loss)
      data = data._replace(reward=shaped)
    n = ended["episodes"]
    cost_estimate = jnp.where(n > 0, ended["cost"] / jnp.maximum(n, 1.0), ts.cost_estimate)
    has_estimate = jnp.maximum(ts.has_cost_estimate, (n > 0).astype(jnp.float32))
    mult = M.update(ts.multiplier, ts.multiplier_params, cost_estimate, has_estimate)
    if ts.penalty_start is not None:  # opens for the next iteration: update() below still sees this one's w
      ts = ts.replace(penalty_start=penalty_gate(ts.penalty_start, ts.iteration, ended["completion"], n,
                                                 self.cfg.damage_warmup_completion,
                                                 self.cfg.damage_schedule_iterations[0]))
    ts, loss_metrics = self.update(ts, data)
    ts = ts.replace(multiplier=mult, cost_estimate=cost_estimate, has_cost_estimate=has_estimate,
                    iteration=ts.iteration + 1)
    metrics = {f"ended_{k}": v for k, v in ended.items()}
    metrics.update({(k if k in UNPREFIXED else f"loss/{k}"): v for k, v in loss_metrics.items()})
    # share of this rollout's transitions whose observation, reward or cost is not finite: 0 unless the
    # physics blew up (names the env, not the learner, when train.ppo.TrainingDiverged stops a run)
    finite = jnp.isfinite(data.reward) & jnp.isfinite(cost)
    for leaf in jax.tree.leaves(data.observation):
      finite &= jnp.all(jnp.isfinite(leaf).reshape(leaf.shape[:2] + (-1,)), axis=-1)
    metrics.update(step_reward=self._pmean(jnp.mean(shaped)), step_cost=self._pmean(jnp.mean(cost)),
                   env_non_finite=self._pmean(1.0 - jnp.mean(finite.astype(jnp.float32))),
                   # steps the damage wrapper ended because the physics diverged (it keeps their data finite)
                   env_diverged_steps=ended["diverged"],
                   lagrange=mult.lam, damage_weight=w, budget=M.effective_budget(mult, ts.multiplier_params),
                   cost_estimate=cost_estimate)
    return ts, metrics

  # -- evaluation (train.evaluate owns the rollout) --------------------------
  def make_evaluator(self, devices=None, env: Optional[Env] = None) -> "E.Evaluator":
    """The deterministic policy's Evaluator on ``env`` (default ``base_env``; another env of the same
    observation and action sizes, e.g. the task with its evaluation start) with episodes sharded over
    ``devices`` (default all); weights are passed as data per call."""
    apply = N.policy_apply(self.make_policy, deterministic=True)
    return E.Evaluator(self.base_env if env is None else env, E.parametrized_policy(apply, None),
                       self.cfg.episode_length, devices)

  def evaluate(self, evaluator: "E.Evaluator", inference_params, key, num_episodes: int) -> dict:
    """``num_episodes`` deterministic episodes of one seed's policy → train.evaluate's flat summary."""
    keys = np.asarray(jax.random.split(key, num_episodes))
    per_ep = evaluator.run(keys, 1.0, params=inference_params)
    env = evaluator.env
    return E.scalar_metrics(E.metrics(per_ep, env.entity_names, safe_threshold_of(env)))

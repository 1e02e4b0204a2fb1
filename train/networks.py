"""Actor/critic networks, their initialisation, the PPO loss and the optimizer.

Brax's pieces are used as they are: ``make_ppo_networks`` (MLPs, a tanh-squashed
Gaussian whose scale is ``softplus(head) + 0.001``), ``compute_ppo_loss`` (clipped
surrogate, GAE with termination vs time-limit truncation, value loss, entropy),
``gradients.gradient_update_fn`` and the running observation normaliser.

What is ours: a per-dimension initial log-std (the paper's −0.5 arm / −1.5
gripper). Brax's tanh-normal policy has no std parameter to initialise — its
scale comes out of the last layer — so :func:`init_policy` zeroes the weights
of that layer's scale half and sets its bias to ``softplus⁻¹(exp(log_std) −
0.001)``: the std starts at exactly ``exp(log_std)`` in every state and may
become state-dependent as it learns. With ``policy_std="parameter"`` the std is
instead one learned log-std per action dimension, the same in every state (what
SB3 and CleanRL learn): :func:`parameter_std_policy`.
"""

from __future__ import annotations

import functools
from typing import Callable, Optional

import jax
import jax.numpy as jnp
import optax
from brax.training import gradients, types
from brax.training import networks as brax_networks
from brax.training.acme import running_statistics
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks

from train import constrained_loss as CL
from train import iteration_targets as IT
from train.config import PPOConfig

ACTIVATIONS: dict[str, Callable] = {
    "tanh": jnp.tanh,
    "swish": jax.nn.swish,
    "relu": jax.nn.relu,
    "elu": jax.nn.elu,
}
MIN_STD = 0.001  # brax NormalTanhDistribution's floor on the scale


def normalizer_fn(cfg: PPOConfig):
  """``normalize(obs, statistics) -> obs'``: brax's running normaliser, bounded to ±``cfg.obs_clip`` when set."""
  if not cfg.normalize_observations:
    return types.identity_observation_preprocessor
  if cfg.obs_clip is None:
    return running_statistics.normalize
  return functools.partial(running_statistics.normalize, max_abs_value=float(cfg.obs_clip))


def make_networks(obs_size: int, action_size: int, cfg: PPOConfig) -> ppo_networks.PPONetworks:
  """Brax's PPO networks; with ``cfg.cost_critic`` the critic has a second output, V_c (train.constrained_loss)."""
  normalize = normalizer_fn(cfg)
  nets = ppo_networks.make_ppo_networks(
      obs_size,
      action_size,
      preprocess_observations_fn=normalize,
      policy_hidden_layer_sizes=tuple(cfg.policy_hidden_sizes),
      value_hidden_layer_sizes=tuple(cfg.value_hidden_sizes),
      activation=ACTIVATIONS[cfg.activation],
  )
  if cfg.policy_std == "parameter":
    nets = nets.__class__(policy_network=parameter_std_policy(obs_size, action_size, normalize, cfg),
                          value_network=nets.value_network,
                          parametric_action_distribution=nets.parametric_action_distribution)
  if not cfg.cost_critic:
    return nets
  value = CL.make_value_network(obs_size, normalize, cfg.value_hidden_sizes, ACTIVATIONS[cfg.activation])
  return nets.__class__(policy_network=nets.policy_network, value_network=value,
                        parametric_action_distribution=nets.parametric_action_distribution)


def _softplus_inverse(y):
  return y + jnp.log(-jnp.expm1(-y))


def parameter_std_policy(obs_size: int, action_size: int, preprocess, cfg: PPOConfig):
  """An actor whose std is a parameter, not an output: params ``{"mlp": …, "log_std": f32[A]}``.

  ``apply`` returns what brax's tanh-normal distribution expects, ``[loc f32[..., A], head f32[..., A]]``
  with ``softplus(head) + 0.001 = exp(log_std)`` in every state, so sampling, log-probs, entropy and the
  PPO loss are brax's own. (Below log-std ln 0.001 the std stops at brax's floor.)"""
  mlp = brax_networks.make_policy_network(action_size, obs_size, preprocess,
                                          hidden_layer_sizes=tuple(cfg.policy_hidden_sizes),
                                          activation=ACTIVATIONS[cfg.activation])

  def init(key):
    # brax's zero-initialised head gives std softplus(0) + 0.001; start there unless init_log_std says
    return {"mlp": mlp.init(key),
            "log_std": jnp.full((action_size,), jnp.log(jax.nn.softplus(0.0) + MIN_STD), jnp.float32)}

  def apply(processor_params, params, obs):
    loc = mlp.apply(processor_params, params["mlp"], obs)
    head = _softplus_inverse(jnp.maximum(jnp.exp(params["log_std"]) - MIN_STD, 1e-6))
    return jnp.concatenate([loc, jnp.broadcast_to(head, loc.shape)], axis=-1)

  return brax_networks.FeedForwardNetwork(init=init, apply=apply)


def initial_log_std(cfg: PPOConfig, action_size: int):
  """f32[A] initial log-std (arm dims, then the gripper as the last dim), or None for brax's init."""
  if cfg.init_log_std is None:
    return None
  arm, grip = cfg.init_log_std
  return jnp.full((action_size,), arm, jnp.float32).at[-1].set(grip)


def init_policy(network: ppo_networks.PPONetworks, cfg: PPOConfig, action_size: int, key):
  """Policy params from brax's init, with the std head's bias set for ``cfg.init_log_std``."""
  params = network.policy_network.init(key)
  log_std = initial_log_std(cfg, action_size)
  if log_std is None:
    return params
  if cfg.policy_std == "parameter":
    return {**params, "log_std": log_std}
  layers = params["params"]
  last = max(layers, key=lambda name: int(name.rsplit("_", 1)[-1]))  # MLP layers are hidden_0..hidden_n
  std = jnp.maximum(jnp.exp(log_std) - MIN_STD, 1e-6)
  bias = layers[last]["bias"].at[action_size:].set(_softplus_inverse(std))
  kernel = layers[last]["kernel"].at[:, action_size:].set(0.0)  # the same std in every state at first
  return {**params, "params": {**layers, last: {**layers[last], "bias": bias, "kernel": kernel}}}


def init_params(network, cfg: PPOConfig, action_size: int, key) -> ppo_losses.PPONetworkParams:
  k_policy, k_value = jax.random.split(key)
  return ppo_losses.PPONetworkParams(policy=init_policy(network, cfg, action_size, k_policy),
                                     value=network.value_network.init(k_value))


def make_optimizer(cfg: PPOConfig) -> optax.GradientTransformation:
  """Adam (optionally with lr annealed linearly to 0), gradient norm clipped per network.

  Why per network: damage costs make rare, very large rewards (one drop can
  cost hundreds of health points in a step), so the value loss's gradient can
  be orders of magnitude larger than the policy's; one global-norm clip over
  both would shrink the policy's step to nothing whenever the critic is
  surprised.
  """
  lr = cfg.learning_rate
  if cfg.anneal_learning_rate:
    lr = optax.linear_schedule(cfg.learning_rate, 0.0, cfg.num_iterations * cfg.sgd_steps_per_iteration)

  def one():
    adam = optax.adam(lr)
    return adam if cfg.max_grad_norm is None else optax.chain(optax.clip_by_global_norm(cfg.max_grad_norm), adam)

  def labels(params: ppo_losses.PPONetworkParams):
    return ppo_losses.PPONetworkParams(policy=jax.tree.map(lambda _: "policy", params.policy),
                                       value=jax.tree.map(lambda _: "value", params.value))

  return optax.multi_transform({"policy": one(), "value": one()}, labels)


def make_gradient_update(network, optimizer, cfg: PPOConfig, axis_name: Optional[str] = None):
  """``update(params, normalizer, minibatch [B, T], key, w, λ, entropy_cost, optimizer_state=...) -> ((loss, metrics),
  params, opt_state)``.

  Without a cost critic the minibatch's reward is already shaped with w and λ (train.iteration) and
  brax's loss ignores them; with one (``cfg.cost_critic``) the reward is the task reward and
  train.constrained_loss mixes the two advantages with w and λ. ``axis_name``: gradients are averaged
  over this mesh axis (train.mesh) before the optimizer step. ``entropy_cost``: the entropy coefficient of
  this update (the config's, or its anneal: train.iteration).
  """
  common = dict(ppo_network=network, discounting=cfg.discounting,
                reward_scaling=cfg.reward_scaling, gae_lambda=cfg.gae_lambda,
                clipping_epsilon=cfg.clipping_epsilon, vf_coefficient=cfg.value_cost)
  if cfg.gae_per_iteration:  # the targets were computed before the epochs (train.iteration_targets.attach)
    def loss_fn(params, normalizer, data, rng, cost_weight, lam, entropy_cost):
      return IT.compute_loss(params, normalizer, data, rng, cost_weight, lam, ppo_network=network,
                             cost_critic=cfg.cost_critic, entropy_cost=entropy_cost,
                             clipping_epsilon=cfg.clipping_epsilon, vf_coefficient=cfg.value_cost)
  elif cfg.cost_critic:
    def loss_fn(params, normalizer, data, rng, cost_weight, lam, entropy_cost):
      return CL.compute_loss(params, normalizer, data, rng, cost_weight, lam, entropy_cost=entropy_cost, **common)
  else:
    brax_loss = functools.partial(ppo_losses.compute_ppo_loss, normalize_advantage=True, **common)

    def loss_fn(params, normalizer, data, rng, cost_weight, lam, entropy_cost):
      del cost_weight, lam  # already in data.reward
      return brax_loss(params, normalizer, data, rng, entropy_cost=entropy_cost)

  return gradients.gradient_update_fn(loss_fn, optimizer, pmap_axis_name=axis_name, has_aux=True)


POLICY_ACTIONS = ("mode", "sample", "mean")


def policy_apply(make_policy, deterministic: bool = True, action: Optional[str] = None, mean_samples: int = 32):
  """``apply(params, state, rng) -> action`` for one env (the form train.evaluate takes).

  ``action`` (default from ``deterministic``: "mode" if True else "sample"):
  - "mode": tanh of the Gaussian's mean (brax's deterministic policy);
  - "sample": one draw of the tanh-squashed Gaussian, the policy PPO trains;
  - "mean": the squashed distribution's mean E[tanh(u)], estimated from ``mean_samples`` draws. Not the
    mode: tanh is not linear, so where the std is large the trained (sampled) policy moves less than
    its mode on average (Jensen), and only this action reproduces the sampled policy's mean motion.
  """
  action = ("mode" if deterministic else "sample") if action is None else action
  if action not in POLICY_ACTIONS:
    raise ValueError(f"action: {action!r} is not one of {', '.join(POLICY_ACTIONS)}")
  if isinstance(mean_samples, bool) or not isinstance(mean_samples, int) or mean_samples < 1:
    raise ValueError(f"mean_samples: {mean_samples!r} must be a positive int")
  if action == "mean":
    def apply(params, state, rng):
      draw = lambda k: make_policy(params, deterministic=False)(state.obs, k)[0]
      return jnp.mean(jax.vmap(draw)(jax.random.split(rng, mean_samples)), axis=0)
    return apply

  def apply(params, state, rng):
    return make_policy(params, deterministic=action == "mode")(state.obs, rng)[0]
  return apply

"""PPO loss with a cost critic: separate value estimates for task reward and damage cost.

With one critic on the shaped reward ``(r_task − (w + λ)·cost)/(1 + λ)`` the value
targets change whenever λ does, so after every multiplier step the critic is wrong
about every state, and one rare large cost (a drop costs tens of health points in a
step) dominates the regression. Constrained PPO implementations (Ray et al. 2019's
safety-starter-agents, OmniSafe) instead learn V_r and V_c separately and mix the
*advantages* with the current multiplier::

    A = (A_r − (w + λ)·A_c) / (1 + λ)

so a change of λ changes the policy's objective at once and neither critic's target.
Here the critic is one MLP with two outputs (reward, cost): the hidden layers are
shared, the heads are not. GAE (brax's ``compute_gae``, with its termination vs
time-limit handling) runs once per head; the clipped surrogate, entropy term and
metrics are brax's ``compute_ppo_loss``'s, so with w = λ = 0 and a zero cost the
policy part equals it.

Shapes: B sequences, T steps per sequence, O observation size.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import jax
import jax.numpy as jnp
from brax.training import networks as brax_networks
from brax.training import types
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks


def make_value_network(obs_size: int, preprocess_observations_fn, hidden_layer_sizes: Sequence[int],
                       activation) -> brax_networks.FeedForwardNetwork:
  """Critic ``apply(normalizer, params, obs f32[..., O]) -> f32[..., 2]`` (V_r, V_c)."""
  module = brax_networks.MLP(layer_sizes=list(hidden_layer_sizes) + [2], activation=activation,
                             kernel_init=jax.nn.initializers.lecun_uniform())

  def apply(processor_params, value_params, obs):
    if isinstance(obs, Mapping):
      raise ValueError("cost_critic: observations must be flat vectors")
    return module.apply(value_params, preprocess_observations_fn(obs, processor_params))

  return brax_networks.FeedForwardNetwork(init=lambda key: module.init(key, jnp.zeros((1, obs_size))), apply=apply)


def combine_advantages(adv_r, adv_c, cost_weight, lam):
  """``(A_r − (w + λ)·A_c)/(1 + λ)``; any matching shapes, w and λ f32[]."""
  return (adv_r - (cost_weight + lam) * adv_c) / (1.0 + lam)


def head_targets(data: types.Transition, values, bootstrap, *, discounting: float, gae_lambda: float,
                 reward_scaling: float):
  """GAE of each critic head (brax's ``compute_gae``, its termination vs time-limit handling) →
  ``(vs, advantages)``, f32[T, B, H] each.

  ``data``: Transitions time-major [T, B]; ``values`` f32[T, B, H] and ``bootstrap`` f32[B, H] (the value of
  each sequence's last next-observation): H = 2 (reward, cost; the cost is
  ``extras["state_extras"]["cost"]``) with a cost critic, H = 1 with one critic on ``data.reward``.
  """
  truncation = data.extras["state_extras"]["truncation"]
  termination = (1 - data.discount) * (1 - truncation)
  rewards = (data.reward, data.extras["state_extras"]["cost"])[:values.shape[-1]]
  out = [ppo_losses.compute_gae(truncation=truncation, termination=termination, rewards=r * reward_scaling,
                                values=values[..., h], bootstrap_value=bootstrap[..., h], lambda_=gae_lambda,
                                discount=discounting) for h, r in enumerate(rewards)]
  return jnp.stack([vs for vs, _ in out], -1), jnp.stack([adv for _, adv in out], -1)


def loss_from_targets(ppo_network: ppo_networks.PPONetworks, logits, values, vs, advantages,
                      data: types.Transition, rng, cost_weight, lam, *, entropy_cost: float,
                      clipping_epsilon: float, vf_coefficient: float):
  """Clipped-surrogate PPO loss given the value targets ``vs`` and ``advantages`` of each head → (loss, metrics).

  ``logits`` f32[T, B, ·] and ``values`` f32[T, B, H]: the networks' outputs under the parameters being
  trained; ``vs``, ``advantages`` f32[T, B, H] (:func:`head_targets`); ``data`` time-major [T, B]. Two heads:
  the advantages mixed with w and λ (:func:`combine_advantages`), each head's value loss, the cost head's
  logged as ``cost_v_loss``; one head: brax's ``compute_ppo_loss`` term by term. Advantages are normalised
  over the minibatch, as brax's.
  """
  dist = ppo_network.parametric_action_distribution
  two = values.shape[-1] == 2
  adv = combine_advantages(advantages[..., 0], advantages[..., 1], cost_weight, lam) if two else advantages[..., 0]
  adv = (adv - adv.mean()) / (adv.std() + 1e-8)
  rho = jnp.exp(dist.log_prob(logits, data.extras["policy_extras"]["raw_action"])
                - data.extras["policy_extras"]["log_prob"])
  policy_loss = -jnp.mean(jnp.minimum(rho * adv, jnp.clip(rho, 1 - clipping_epsilon, 1 + clipping_epsilon) * adv))
  v_loss = 0.5 * vf_coefficient * jnp.mean((vs - values) ** 2, axis=(0, 1))  # f32[H]
  entropy_loss = -entropy_cost * jnp.mean(dist.entropy(logits, rng))
  total = policy_loss + jnp.sum(v_loss) + entropy_loss
  new = dist.create_dist(logits)
  old = dist.create_dist(data.extras["policy_extras"]["distribution_params"])
  metrics = {
      "total_loss": total, "policy_loss": policy_loss, "v_loss": jnp.sum(v_loss),
      "entropy_loss": entropy_loss, "kl_mean": jnp.mean(new.kl_divergence(old)),
      "policy_dist_mean_std": jnp.mean(new.scale),
  }
  return total, (dict(metrics, cost_v_loss=v_loss[1]) if two else metrics)


def compute_loss(params: ppo_losses.PPONetworkParams, normalizer_params, data: types.Transition, rng,
                 cost_weight, lam, *, ppo_network: ppo_networks.PPONetworks, entropy_cost: float,
                 discounting: float, reward_scaling: float, gae_lambda: float, clipping_epsilon: float,
                 vf_coefficient: float):
  """Clipped-surrogate PPO loss with the mixed advantage (module docstring) → (loss, metrics).

  ``data``: Transitions [B, T] whose ``reward`` is the task reward and whose
  ``extras["state_extras"]["cost"]`` is the damage cost of each step; ``cost_weight`` w and
  ``lam`` λ: f32[] (traced, so one program serves every multiplier value). GAE is computed here, with
  the critic being trained (brax's way: the targets move with every SGD step; train.iteration_targets
  computes them once per iteration instead).
  """
  data = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), data)  # [T, B, ...]
  logits = ppo_network.policy_network.apply(normalizer_params, params.policy, data.observation)
  values = ppo_network.value_network.apply(normalizer_params, params.value, data.observation)  # [T, B, 2]
  bootstrap = ppo_network.value_network.apply(normalizer_params, params.value, data.next_observation[-1])  # [B, 2]
  vs, adv = head_targets(data, values, bootstrap, discounting=discounting, gae_lambda=gae_lambda,
                         reward_scaling=reward_scaling)
  return loss_from_targets(ppo_network, logits, values, vs, adv, data, rng, cost_weight, lam,
                           entropy_cost=entropy_cost, clipping_epsilon=clipping_epsilon,
                           vf_coefficient=vf_coefficient)

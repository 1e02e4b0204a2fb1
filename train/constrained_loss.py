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


def compute_loss(params: ppo_losses.PPONetworkParams, normalizer_params, data: types.Transition, rng,
                 cost_weight, lam, *, ppo_network: ppo_networks.PPONetworks, entropy_cost: float,
                 discounting: float, reward_scaling: float, gae_lambda: float, clipping_epsilon: float,
                 vf_coefficient: float):
  """Clipped-surrogate PPO loss with the mixed advantage (module docstring) → (loss, metrics).

  ``data``: Transitions [B, T] whose ``reward`` is the task reward and whose
  ``extras["state_extras"]["cost"]`` is the damage cost of each step; ``cost_weight`` w and
  ``lam`` λ: f32[] (traced, so one program serves every multiplier value).
  """
  dist = ppo_network.parametric_action_distribution
  data = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), data)  # [T, B, ...]
  logits = ppo_network.policy_network.apply(normalizer_params, params.policy, data.observation)
  values = ppo_network.value_network.apply(normalizer_params, params.value, data.observation)  # [T, B, 2]
  bootstrap = ppo_network.value_network.apply(normalizer_params, params.value, data.next_observation[-1])  # [B, 2]
  truncation = data.extras["state_extras"]["truncation"]
  termination = (1 - data.discount) * (1 - truncation)

  def gae(rewards, head):
    return ppo_losses.compute_gae(truncation=truncation, termination=termination, rewards=rewards,
                                  values=values[..., head], bootstrap_value=bootstrap[..., head],
                                  lambda_=gae_lambda, discount=discounting)

  vs_r, adv_r = gae(data.reward * reward_scaling, 0)
  vs_c, adv_c = gae(data.extras["state_extras"]["cost"] * reward_scaling, 1)
  adv = combine_advantages(adv_r, adv_c, cost_weight, lam)
  adv = (adv - adv.mean()) / (adv.std() + 1e-8)
  rho = jnp.exp(dist.log_prob(logits, data.extras["policy_extras"]["raw_action"])
                - data.extras["policy_extras"]["log_prob"])
  policy_loss = -jnp.mean(jnp.minimum(rho * adv, jnp.clip(rho, 1 - clipping_epsilon, 1 + clipping_epsilon) * adv))
  v_loss_r = 0.5 * vf_coefficient * jnp.mean((vs_r - values[..., 0]) ** 2)
  v_loss_c = 0.5 * vf_coefficient * jnp.mean((vs_c - values[..., 1]) ** 2)
  entropy_loss = -entropy_cost * jnp.mean(dist.entropy(logits, rng))
  total = policy_loss + v_loss_r + v_loss_c + entropy_loss
  new = dist.create_dist(logits)
  old = dist.create_dist(data.extras["policy_extras"]["distribution_params"])
  return total, {
      "total_loss": total, "policy_loss": policy_loss, "v_loss": v_loss_r + v_loss_c, "cost_v_loss": v_loss_c,
      "entropy_loss": entropy_loss, "kl_mean": jnp.mean(new.kl_divergence(old)),
      "policy_dist_mean_std": jnp.mean(new.scale),
  }

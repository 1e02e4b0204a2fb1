"""Advantages and value targets computed once per iteration, before the epochs (config ``gae_per_iteration``).

brax's PPO loss (and train.constrained_loss, which follows it) computes GAE inside every minibatch step with
the critic of that step: the value targets ``vs = V(s) + Σ (γλ)^k δ_k`` move with the weights they train, so
within one iteration (8 epochs × 32 minibatches in the Playground recipe) the critic regresses onto its own
latest outputs 256 times — a bootstrapped fixed-point iteration that the data does not anchor between
rollouts. CleanRL, Stable-Baselines3 and purejaxrl compute the advantages and targets once, from the critic
the rollout ended with, and keep them for every epoch, so each iteration's critic update is a plain
regression onto fixed numbers. Both trainers' rare diverged critics on Place Plate (value loss past 10¹²
with bounded rewards and inputs; docs/safe_rl.md, "A second draw of the driver") ran the moving targets.

:func:`attach` stores the targets in the batch (so minibatch shuffling carries them with their
transitions); :func:`compute_loss` is the same clipped loss (train.constrained_loss.loss_from_targets) on
them. One head (a critic on the shaped reward) or two (with ``cost_critic``). At the first SGD step of an
iteration, when the weights are still those the targets came from, both ways give the same loss.

Shapes: B sequences, T steps per sequence, H critic heads (1, or 2 with a cost critic).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.training import types
from brax.training.agents.ppo import losses as ppo_losses
from brax.training.agents.ppo import networks as ppo_networks

from train import constrained_loss as CL


def attach(ppo_network: ppo_networks.PPONetworks, normalizer_params, value_params, data: types.Transition, *,
           cost_critic: bool, discounting: float, gae_lambda: float, reward_scaling: float) -> types.Transition:
  """``data`` [B, T] with ``extras["targets"] = {"vs", "advantages"}``, f32[B, T, H] each, from the critic
  ``value_params`` under ``normalizer_params`` (those the epochs will use). ``data.reward`` is what the
  single critic learns (the shaped reward) or, with ``cost_critic``, the task reward beside the cost."""
  tm = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), data)  # [T, B, ...]
  apply = ppo_network.value_network.apply
  values = apply(normalizer_params, value_params, tm.observation)
  bootstrap = apply(normalizer_params, value_params, tm.next_observation[-1])
  if not cost_critic:  # brax's critic returns f32[...]: one head
    values, bootstrap = values[..., None], bootstrap[..., None]
  vs, adv = CL.head_targets(tm, values, bootstrap, discounting=discounting, gae_lambda=gae_lambda,
                            reward_scaling=reward_scaling)
  targets = {"vs": jnp.swapaxes(vs, 0, 1), "advantages": jnp.swapaxes(adv, 0, 1)}
  return data._replace(extras={**data.extras, "targets": jax.lax.stop_gradient(targets)})


def compute_loss(params: ppo_losses.PPONetworkParams, normalizer_params, data: types.Transition, rng, cost_weight,
                 lam, *, ppo_network: ppo_networks.PPONetworks, cost_critic: bool, entropy_cost: float,
                 clipping_epsilon: float, vf_coefficient: float):
  """The clipped PPO loss on the targets :func:`attach` stored in ``data`` [B, T] → (loss, metrics); with
  ``cost_critic`` the two heads' advantages are mixed with ``cost_weight`` w and ``lam`` λ (f32[]), without
  one both are ignored (the reward is already shaped)."""
  tm = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1), data)  # [T, B, ...]
  logits = ppo_network.policy_network.apply(normalizer_params, params.policy, tm.observation)
  values = ppo_network.value_network.apply(normalizer_params, params.value, tm.observation)
  if not cost_critic:
    values = values[..., None]
  t = tm.extras["targets"]
  return CL.loss_from_targets(ppo_network, logits, values, t["vs"], t["advantages"], tm, rng, cost_weight, lam,
                              entropy_cost=entropy_cost, clipping_epsilon=clipping_epsilon,
                              vf_coefficient=vf_coefficient)

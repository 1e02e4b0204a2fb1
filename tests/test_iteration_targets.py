"""GAE once per iteration (train.iteration_targets, config ``gae_per_iteration``): the same loss as brax's at an
iteration's first step, targets that stay put while the critic moves, and training runs through it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training import types
from brax.training.acme import running_statistics
from brax.training.agents.ppo import losses as ppo_losses

import train
from train import constrained_loss as CL
from train import iteration_targets as IT
from train import networks as N
from train.config import PPOConfig
from train.experiments.pusher import PusherEnv

B, T, O, A = 6, 5, 4, 2
GAE = dict(discounting=0.97, gae_lambda=0.95, reward_scaling=1.0)
SURROGATE = dict(entropy_cost=0.01, clipping_epsilon=0.3, vf_coefficient=0.5)


def _setup(cost_critic: bool):
  cfg = PPOConfig(policy_hidden_sizes=(8,), value_hidden_sizes=(8,), cost_critic=cost_critic).validate()
  net = N.make_networks(O, A, cfg)
  params = N.init_params(net, cfg, A, jax.random.PRNGKey(0))
  k = jax.random.split(jax.random.PRNGKey(1), 7)
  # a normaliser that has seen data, so targets and loss must use the same one
  norm = running_statistics.update(running_statistics.init_state(jnp.zeros((O,), jnp.float32)),
                                   2.0 + 3.0 * jax.random.normal(k[6], (64, O)))
  obs = jax.random.normal(k[0], (B, T, O))
  logits = net.policy_network.apply(norm, params.policy, obs)
  raw = jax.random.normal(k[1], (B, T, A))
  # one sequence ends in a time limit at its third step: the truncated step's TD error is masked
  truncation = jnp.zeros((B, T)).at[0, 2].set(1.0)
  data = types.Transition(
      observation=obs, action=jnp.tanh(raw), reward=jax.random.normal(k[2], (B, T)),
      discount=1.0 - truncation, next_observation=jax.random.normal(k[3], (B, T, O)),
      extras={"policy_extras": {"raw_action": raw, "log_prob": net.parametric_action_distribution.log_prob(logits, raw)
                                + 0.05 * jax.random.normal(k[4], (B, T)),
                                "distribution_params": logits},
              "state_extras": {"truncation": truncation, "cost": jnp.abs(jax.random.normal(k[5], (B, T)))}})
  return net, params, norm, data


def _fixed(net, norm, data, params, cost_critic, w=2.0, lam=0.5):
  attached = IT.attach(net, norm, params.value, data, cost_critic=cost_critic, **GAE)
  return lambda p: IT.compute_loss(p, norm, attached, jax.random.PRNGKey(2), jnp.float32(w), jnp.float32(lam),
                                   ppo_network=net, cost_critic=cost_critic, **SURROGATE)


def _moving(net, norm, data, cost_critic, w=2.0, lam=0.5):
  if cost_critic:
    return lambda p: CL.compute_loss(p, norm, data, jax.random.PRNGKey(2), jnp.float32(w), jnp.float32(lam),
                                     ppo_network=net, **GAE, **SURROGATE)
  return lambda p: ppo_losses.compute_ppo_loss(p, norm, data, jax.random.PRNGKey(2), ppo_network=net,
                                               normalize_advantage=True, **GAE, **SURROGATE)


@pytest.mark.parametrize("cost_critic", [False, True])
def test_at_the_first_step_the_loss_and_its_gradient_are_brax_s(cost_critic):
  """Before any SGD step the weights are those the stored targets came from: loss, metrics and gradients
  equal brax's loss (one critic) and train.constrained_loss's (two heads), which compute GAE in the loss."""
  net, params, norm, data = _setup(cost_critic)
  fixed, moving = _fixed(net, norm, data, params, cost_critic), _moving(net, norm, data, cost_critic)
  (l1, m1), g1 = jax.value_and_grad(fixed, has_aux=True)(params)
  (l2, m2), g2 = jax.value_and_grad(moving, has_aux=True)(params)
  np.testing.assert_allclose(float(l1), float(l2), rtol=1e-5)
  for k in ("policy_loss", "v_loss", "entropy_loss", "kl_mean", "policy_dist_mean_std") + (("cost_v_loss",) * cost_critic):
    np.testing.assert_allclose(float(m1[k]), float(m2[k]), rtol=1e-5, atol=1e-7, err_msg=k)
  for a, b in zip(jax.tree.leaves(g1), jax.tree.leaves(g2)):
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("cost_critic", [False, True])
def test_targets_stay_put_while_the_critic_moves(cost_critic):
  """After the critic changes, the stored targets are still those of the critic the rollout ended with: the
  value loss is the regression onto them, while brax's loss recomputes its targets with the new critic."""
  net, params, norm, data = _setup(cost_critic)
  moved = params.replace(value=jax.tree.map(lambda x: x + 0.3, params.value))
  attached = IT.attach(net, norm, params.value, data, cost_critic=cost_critic, **GAE)
  vs = attached.extras["targets"]["vs"]
  assert vs.shape == (B, T, 2 if cost_critic else 1)
  v_new = net.value_network.apply(norm, moved.value, data.observation)
  v_new = v_new if cost_critic else v_new[..., None]
  want = 0.5 * SURROGATE["vf_coefficient"] * np.sum(np.mean((np.asarray(vs) - np.asarray(v_new)) ** 2, axis=(0, 1)))
  _, fixed = _fixed(net, norm, data, params, cost_critic)(moved)
  _, moving = _moving(net, norm, data, cost_critic)(moved)
  np.testing.assert_allclose(float(fixed["v_loss"]), want, rtol=1e-5)
  assert abs(float(moving["v_loss"]) - want) > 1e-3 * want
  # the time limit: the truncated step's target is its own value (brax's compute_gae masks its TD error)
  v_old = net.value_network.apply(norm, params.value, data.observation)
  np.testing.assert_allclose(np.asarray(vs)[0, 2, 0], np.asarray(v_old[0, 2] if not cost_critic else v_old[0, 2, 0]),
                             rtol=1e-6)


@pytest.mark.parametrize("cost_critic", [False, True])
def test_training_runs_with_targets_once_per_iteration(cost_critic):
  """Two seeds through the run loop: finite losses, the option recorded, every SGD step taken."""
  tiny = dict(num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8, num_updates_per_batch=2,
              episode_length=24, policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16), num_eval_envs=8,
              progress=False, eval_every=128)
  res = train.train(PusherEnv(), seeds=(0, 1), damage_weight=2.0, cost_critic=cost_critic, gae_per_iteration=True,
                    num_timesteps=4 * 128, **tiny)
  assert res.config.gae_per_iteration
  assert all(np.isfinite(v) for r in res.history for v in r.values() if isinstance(v, float))
  assert len(res.history) == 8 and all(r["sgd_steps"] == 4.0 for r in res.history)


def test_the_option_is_a_bool_and_older_runs_had_brax_s_targets():
  with pytest.raises(ValueError, match="gae_per_iteration"):
    PPOConfig(gae_per_iteration="yes").validate()
  assert PPOConfig.from_json({}).gae_per_iteration is False

"""The cost-critic PPO loss (train.constrained_loss): advantage mixing, what the policy sees of the cost,
both critic heads trained, and a training run through it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training import types
from brax.training.acme import running_statistics

import train
from train import constrained_loss as CL
from train import networks as N
from train.config import PPOConfig
from train.experiments.pusher import PusherEnv

B, T, O, A = 6, 5, 4, 2
CFG = PPOConfig(policy_hidden_sizes=(8,), value_hidden_sizes=(8,), cost_critic=True, entropy_cost=0.0).validate()


@pytest.fixture(scope="module")
def setup():
  net = N.make_networks(O, A, CFG)
  params = N.init_params(net, CFG, A, jax.random.PRNGKey(0))
  norm = running_statistics.init_state(jnp.zeros((O,), jnp.float32))
  k = jax.random.split(jax.random.PRNGKey(1), 6)
  obs = jax.random.normal(k[0], (B, T, O))
  logits = net.policy_network.apply(norm, params.policy, obs)
  raw = jax.random.normal(k[1], (B, T, A))
  data = types.Transition(
      observation=obs, action=jnp.tanh(raw), reward=jax.random.normal(k[2], (B, T)),
      discount=jnp.ones((B, T)), next_observation=jax.random.normal(k[3], (B, T, O)),
      extras={"policy_extras": {"raw_action": raw, "log_prob": net.parametric_action_distribution.log_prob(logits, raw)
                                + 0.05 * jax.random.normal(k[4], (B, T)),
                                "distribution_params": logits},
              "state_extras": {"truncation": jnp.zeros((B, T)), "cost": jnp.abs(jax.random.normal(k[5], (B, T)))}})

  def loss(data, w, lam, p=params):
    return CL.compute_loss(p, norm, data, jax.random.PRNGKey(2), jnp.float32(w), jnp.float32(lam), ppo_network=net,
                           entropy_cost=0.0, discounting=0.97, reward_scaling=1.0, gae_lambda=0.95,
                           clipping_epsilon=0.3, vf_coefficient=0.5)

  return net, params, data, loss


def test_critic_has_two_heads(setup):
  net, params, data, _ = setup
  v = net.value_network.apply(running_statistics.init_state(jnp.zeros((O,))), params.value, data.observation)
  assert v.shape == (B, T, 2)


def test_combine_advantages():
  np.testing.assert_allclose(CL.combine_advantages(jnp.array([1.0, 2.0]), jnp.array([0.5, 0.0]), 2.0, 1.0),
                             [(1 - 3 * 0.5) / 2, 1.0])


def test_policy_ignores_cost_without_weight_and_sees_it_with_one(setup):
  """w = λ = 0: the policy loss does not depend on the cost; w > 0 or λ > 0: it does. The cost head is
  trained either way (its value loss depends on the cost)."""
  _, _, data, loss = setup
  other = data._replace(extras={**data.extras, "state_extras": {**data.extras["state_extras"],
                                                                "cost": data.extras["state_extras"]["cost"] * 3 + 1}})
  for w, lam, same in ((0.0, 0.0, True), (2.0, 0.0, False), (0.0, 1.5, False)):
    (_, m1), (_, m2) = loss(data, w, lam), loss(other, w, lam)
    assert (float(m1["policy_loss"]) == float(m2["policy_loss"])) == same, (w, lam)
    assert float(m1["cost_v_loss"]) != float(m2["cost_v_loss"])
    assert all(np.isfinite(float(v)) for v in m1.values())


def test_gradient_reaches_both_heads(setup):
  _, params, data, loss = setup
  g = jax.grad(lambda p: loss(data, 2.0, 0.5, p)[0])(params)
  last = max(g.value["params"], key=lambda n: int(n.rsplit("_", 1)[-1]))
  head = np.asarray(g.value["params"][last]["kernel"])  # [hidden, 2]
  assert np.all(np.abs(head).sum(axis=0) > 0)


def test_training_run_with_cost_critic_and_budget_curriculum():
  """Two seeds of PPO-Lagrangian with both fixes through the run loop: finite, λ in range."""
  tiny = dict(num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8, num_updates_per_batch=2,
              episode_length=24, policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16), num_eval_envs=8,
              progress=False)
  res = train.train(PusherEnv(), seeds=(3, 4), budget=0.0, cost_critic=True, budget_anneal_steps=4 * 128,
                    num_timesteps=6 * 128, **tiny)
  lam = np.asarray(res.train_state.lagrange)
  assert np.all((lam >= 0) & (lam <= 5.0))
  assert all(np.isfinite(v) for r in res.history for v in r.values() if isinstance(v, float))
  assert res.train_state.params.value["params"]["hidden_2"]["kernel"].shape[-1] == 2
  # the cost head's loss is logged beside the sum, so a diverged critic says which head it was
  assert all(0.0 <= r["loss/cost_v_loss"] <= r["loss/v_loss"] for r in res.history)

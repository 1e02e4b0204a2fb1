"""train.networks.policy_apply's three actions of one trained Gaussian + tanh policy: the mode (brax's
deterministic policy), a sample (what PPO trains) and the squashed mean E[tanh(u)], which differs from
the mode wherever the std is large (Jensen) — the gap rl_multiseed's --eval-actions measures."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training.acme import running_statistics
from brax.training.agents.ppo import networks as ppo_networks

from train import networks as N
from train.config import PPOConfig


class _State:
  def __init__(self, obs):
    self.obs = obs


@pytest.fixture(scope="module")
def policy():
  cfg = PPOConfig(policy_hidden_sizes=(8,), value_hidden_sizes=(8,), init_log_std=(0.5, -3.0))
  net = N.make_networks(3, 2, cfg)
  params = (running_statistics.init_state(jnp.zeros((3,), jnp.float32)),
            N.init_policy(net, cfg, 2, jax.random.PRNGKey(0)))  # arm std e^0.5: a wide squashed Gaussian
  return ppo_networks.make_inference_fn(net), params, net


def _apply(policy, action, **kw):
  make, params, _ = policy
  return jax.jit(lambda obs, k: N.policy_apply(make, action=action, **kw)(params, _State(obs), k))


def test_mode_ignores_the_key_and_sample_does_not(policy):
  s = jnp.array([0.3, -1.0, 2.0])
  mode = _apply(policy, "mode")
  np.testing.assert_array_equal(mode(s, jax.random.PRNGKey(1)), mode(s, jax.random.PRNGKey(2)))
  sample = _apply(policy, "sample")
  assert not np.allclose(sample(s, jax.random.PRNGKey(1)), sample(s, jax.random.PRNGKey(2)))
  # deterministic=True/False keep their meaning
  make, params, _ = policy
  np.testing.assert_array_equal(N.policy_apply(make, True)(params, _State(s), jax.random.PRNGKey(3)),
                                mode(s, jax.random.PRNGKey(4)))


def test_mean_is_the_average_of_that_many_samples(policy):
  make, params, net = policy
  s, key = _State(jnp.array([0.3, -1.0, 2.0])), jax.random.PRNGKey(7)
  mean = N.policy_apply(make, action="mean", mean_samples=16)(params, s, key)
  draws = [make(params, deterministic=False)(s.obs, k)[0] for k in jax.random.split(key, 16)]
  np.testing.assert_allclose(mean, np.mean(draws, axis=0), rtol=1e-5, atol=1e-6)
  # with many samples it is the squashed Gaussian's mean, by quadrature from the network's loc and scale
  many = N.policy_apply(make, action="mean", mean_samples=8192)(params, s, key)
  logits = net.policy_network.apply(*params, s.obs)
  loc, scale = np.split(np.asarray(logits), 2)
  scale = np.logaddexp(0.0, scale) + 0.001  # brax's NormalTanhDistribution: softplus + min_std
  x, w = np.polynomial.hermite_e.hermegauss(64)
  exact = (np.tanh(loc[:, None] + scale[:, None] * x[None]) * w).sum(-1) / w.sum()
  np.testing.assert_allclose(many, exact, atol=0.02)
  mode = N.policy_apply(make, action="mode")(params, s, key)
  assert abs(float(mode[0])) > 0.05 and abs(exact[0]) < abs(float(mode[0])) - 0.01  # the wide arm dimension: the mean moves less than the mode


@pytest.mark.parametrize("kw, field", [(dict(action="greedy"), "action"), (dict(action="mean", mean_samples=0),
                                                                           "mean_samples"),
                                        (dict(action="mean", mean_samples=2.5), "mean_samples")])
def test_bad_values_name_the_field(policy, kw, field):
  with pytest.raises(ValueError, match=field):
    N.policy_apply(policy[0], **kw)

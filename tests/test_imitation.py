"""train.bc / train.flow_policy on a tiny hand-made dataset (no physics: fast on 2 cores)."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_damage import data as D
from train import bc, flow_policy as FP


def scripted(obs):
  """The demonstrator: a fixed smooth map from a 3-D observation to a 4-D action in [-1, 1]."""
  w = np.array([[1.0, -0.5, 0.0, 0.3], [0.2, 0.8, -1.0, 0.0], [-0.4, 0.0, 0.6, 1.0]], np.float32)
  return np.tanh(obs @ w)


@pytest.fixture(scope="module")
def demos():
  r = np.random.default_rng(0)
  e, t = 16, 12
  obs = r.uniform(-1, 1, (e, t, 3)).astype(np.float32)
  z = np.zeros((e, t), np.float32)
  return D.build(env_name="toy", obs={"state": obs}, actions=scripted(obs), rewards=z, states=obs,
                 health={"thing": np.full((e, t), 100.0)}, damage={k: z for k in D.DAMAGE_KINDS}, cost=z,
                 lengths=np.full(e, t), success=np.ones(e, bool), safe=np.ones(e, bool))


@pytest.fixture(scope="module")
def bc_result(demos):
  return bc.train_bc(demos, seeds=[0, 1], steps=600, batch=64, hidden=(64, 64))


def test_bc_loss_decreases_for_every_seed(bc_result):
  losses = np.asarray(bc_result.losses)
  assert losses.shape == (2, 600)
  assert np.all(losses[:, -50:].mean(1) < losses[:, :50].mean(1) - 0.5)
  assert not np.allclose(bc_result.params["net"]["params"]["Dense_0"]["kernel"][0],
                         bc_result.params["net"]["params"]["Dense_0"]["kernel"][1])


def test_bc_policy_imitates_the_demonstrator(bc_result):
  obs = np.random.default_rng(1).uniform(-1, 1, (200, 3)).astype(np.float32)
  for i in range(2):
    policy = bc.bc_policy(bc_result, i)
    act = jax.jit(jax.vmap(lambda o: policy(SimpleNamespace(obs=o), jax.random.PRNGKey(0))))(obs)
    err = np.abs(np.asarray(act) - scripted(obs)).mean()
    assert err < 0.08, (i, err)  # the actions themselves spread over ~0.5 mean |a|
    assert np.abs(scripted(obs)).mean() > 0.3


def test_action_chunks_repeat_the_last_action(demos):
  short = D.build(env_name="toy", obs={"state": demos.obs["state"][:2]}, actions=demos.actions[:2],
                  rewards=demos.rewards[:2], states=demos.states[:2], health={"thing": demos.health["thing"][:2]},
                  damage={k: v[:2] for k, v in demos.damage.items()}, cost=demos.cost[:2], lengths=[5, 12],
                  success=[True, True], safe=[True, True])
  ex = FP.action_chunks(short, chunk=8)
  assert ex["chunks"].shape == (17, 8, 4) and ex["obs"].shape == (17, 3)
  np.testing.assert_array_equal(ex["chunks"][2, :3], short.actions[0, 2:5])
  np.testing.assert_array_equal(ex["chunks"][2, 3:], np.repeat(short.actions[0, 4:5], 5, 0))


def test_flow_policy_trains_and_samples_finite_actions(demos):
  res = FP.train_flow(demos, seeds=[0, 1], steps=300, batch=64, hidden=(64, 64))
  losses = np.asarray(res.losses)
  assert losses.shape == (2, 300) and np.all(np.isfinite(losses))
  assert np.all(losses[:, -50:].mean(1) < losses[:, :50].mean(1))
  policy = FP.flow_policy(res, 1, flow_steps=4)
  obs = jnp.asarray(demos.obs["state"][0, :5])
  act = jax.jit(jax.vmap(lambda o, k: policy(SimpleNamespace(obs=o), k)))(obs, jax.random.split(jax.random.PRNGKey(0), 5))
  assert act.shape == (5, 4) and np.all(np.isfinite(act)) and np.all(np.abs(act) <= 1)
  # temperature 0 (the default) ignores the rng; a sampled start does not
  one = lambda pol, k: pol(SimpleNamespace(obs=obs[0]), jax.random.PRNGKey(k))
  np.testing.assert_array_equal(one(policy, 0), one(policy, 1))
  hot = FP.flow_policy(res, 1, flow_steps=4, temperature=1.0)
  assert not np.allclose(one(hot, 0), one(hot, 1))


def test_bad_training_arguments(demos):
  with pytest.raises(ValueError, match="seeds: need one or more"):
    bc.train_bc(demos, seeds=[])
  with pytest.raises(ValueError, match="steps: must be an int >= 1"):
    bc.train_bc(demos, steps=0)
  with pytest.raises(ValueError, match="chunk: must be an int >= 1"):
    FP.train_flow(demos, chunk=0)

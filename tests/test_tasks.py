"""Task suite: registry/API contract, and per task one compiled batched rollout that checks

* reset + step compile and the observation has the declared size;
* 200 random-action steps on 16 environments: no NaN, health within [0, 100];
* scripted policies: the unsafe one leaves some entity below 95 health in some
  episode, the safe one leaves every entity above 95 in every episode (and
  both complete the task).

One compilation per task serves all three (the policy — random, safe or
unsafe — is chosen per episode inside the compiled call), which keeps the file
within its budget on a 2-core CI machine.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks
from tasks import robot as R

N_RANDOM, N_SCRIPTED, STEPS = 16, 3, 200


# -- registry and API (no compilation) ----------------------------------------------------
def test_names_and_registry_errors():
  names = tasks.names()
  assert {"place_plate", "pick_egg", "shelve_item", "wipe_counter", "open_drawer", "turn_on_stove"} <= set(names)
  with pytest.raises(ValueError, match="valid: .*place_plate"):
    tasks.make("no_such_task")
  with pytest.raises(ValueError, match="unknown override.*valid: .*damage_weight"):
    tasks.make("place_plate", not_an_option=1)
  with pytest.raises(ValueError, match="obs_mode"):
    tasks.make("place_plate", obs_mode="pixels")
  with pytest.raises(ValueError, match="episode_length"):
    tasks.make("pick_egg", episode_length=0)
  with pytest.raises(ValueError, match="style"):
    tasks.scripted_policy(tasks.make("pick_egg"), "reckless")


def test_default_config_and_overrides():
  cfg = tasks.default_config("place_plate")
  for k in ("damage_weight", "terminate_on_destroyed", "health_in_obs", "params_fn", "episode_length", "obs_mode"):
    assert k in cfg
  assert cfg["damage_weight"] == 0.0 and cfg["episode_length"] == 100
  env = tasks.make("place_plate", obs_mode="paper", damage_weight=2.0, health_in_obs=True, episode_length=50)
  assert env.weight == 2.0 and env.unwrapped.episode_length == 50
  assert env.observation_size == 6 + len(env.entity_names)  # paper obs [eef; plate] + health
  assert env.action_size == 4
  assert abs(env.dt - 0.024) < 1e-9


@pytest.mark.parametrize("name", ["place_plate", "pick_egg", "shelve_item", "wipe_counter", "open_drawer", "turn_on_stove"])
def test_entities_match_health_arrays(name):
  env = tasks.make(name)
  assert env.entity_names[-1] == "agent"
  assert [l for l in env.link_names if l.startswith("agent/")] == [f"agent/{b}" for b in R.AGENT_BODIES]
  assert len(env.link_names) == env.binding.num_links
  # only contacts that can happen are computed: every scene stays small
  from mujoco import mjx
  assert mjx.make_data(env.unwrapped.sys)._impl.contact.dist.shape[0] <= 48


def test_gripper_command_roundtrip():
  for g in (0.0, 0.044, 0.1, 0.16):
    c = float(R.gripper_command_for_gap(g))
    q = R.Q_MIN + 0.5 * (c + 1) * (R.Q_MAX - R.Q_MIN)
    assert abs(float(R.gap(q)) - np.clip(g, float(R.gap(R.Q_MIN)), float(R.gap(R.Q_MAX)))) < 1e-6


# -- one compiled batched rollout per task ---------------------------------------------------------
def _rollout(name):
  env = tasks.make(name)
  policies = [
      lambda s, k: jax.random.uniform(k, (4,), minval=-1.0, maxval=1.0),
      tasks.scripted_policy(env, "safe"),
      tasks.scripted_policy(env, "unsafe"),
  ]

  def episode(rng, which):
    r0, rp = jax.random.split(rng)
    s = env.reset(r0)
    obs0 = s.obs

    def body(carry, k):
      s, bad, lo, hi = carry
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      h = s.info["link_health"]
      bad = bad | ~(jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos)))
      return (s, bad, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h))), s.metrics["success"]

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf))
    (s, bad, lo, hi), succ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return obs0, s.obs, bad, lo, hi, jnp.max(succ), s.info["entity_health"]

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED)
  rngs = jax.random.split(jax.random.PRNGKey(7), which.shape[0])
  out = jax.jit(jax.vmap(episode))(rngs, which)
  return env, [np.asarray(x) for x in out]


@pytest.fixture(scope="module", params=["place_plate", "pick_egg", "shelve_item", "wipe_counter", "open_drawer", "turn_on_stove"])
def rollout(request):
  return request.param, *_rollout(request.param)


def test_compiles_with_declared_obs_size(rollout):
  name, env, (obs0, obs, *_ ) = rollout
  assert obs0.shape == (N_RANDOM + 2 * N_SCRIPTED, env.observation_size), name
  assert obs.shape == obs0.shape


def test_random_actions_finite_and_health_bounded(rollout):
  name, env, (_, _, bad, lo, hi, _, eh) = rollout
  r = slice(0, N_RANDOM)
  assert not bad[r].any(), f"{name}: non-finite obs/reward/qpos under random actions"
  assert (lo[r] >= 0.0).all() and (hi[r] <= 100.0).all(), name
  assert ((eh >= 0) & (eh <= 100)).all()


def test_scripted_unsafe_damages_safe_does_not(rollout):
  name, env, (_, _, bad, _, _, completed, eh) = rollout
  safe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED)
  unsafe = slice(N_RANDOM + N_SCRIPTED, None)
  assert not bad[N_RANDOM:].any(), name
  assert (eh[safe] > 95.0).all(), f"{name}: safe policy damaged something: {eh[safe]}"
  assert (eh[unsafe] < 95.0).any(axis=-1).any(), f"{name}: unsafe policy left everything intact: {eh[unsafe]}"
  assert completed[safe].all(), f"{name}: safe policy did not complete"

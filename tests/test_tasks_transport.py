"""Transport tasks (issue 14): per task one compiled batched rollout of 200 random-action steps on 16
environments — the observation has the declared size, nothing turns non-finite (liquid particles
included), health stays within [0, 100] — plus the task's own bad-input checks.

Scripted safe/unsafe separation over 256 episodes is benchmarks/scripted_policies.py's job (the safe
carries take longer than these 200 steps).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks

N_ENVS, STEPS = 16, 200
TRANSPORT = ["move_glass_of_water", "prepare_breakfast"]


def _random_rollout(name):
  env = tasks.make(name)

  def episode(rng):
    r0, rp = jax.random.split(rng)
    s = env.reset(r0)
    obs0 = s.obs

    def body(carry, k):
      s, bad, lo, hi = carry
      s = env.step(s, jax.random.uniform(k, (env.action_size,), minval=-1.0, maxval=1.0))
      h = s.info["link_health"]
      particles = jax.tree.leaves(s.info["damage_state"].liquid)  # [] for a task without liquid
      finite = (jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos))
                & jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in particles] + [jnp.bool_(True)])))
      return (s, bad | ~finite, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h))), None

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf))
    (s, bad, lo, hi), _ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return obs0, s.obs, bad, lo, hi, s.info["entity_health"]

  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(3), N_ENVS))
  return env, [np.asarray(x) for x in out]


@pytest.fixture(scope="module", params=TRANSPORT)
def rollout(request):
  return request.param, *_random_rollout(request.param)


def test_random_actions_finite_bounded_and_obs_size(rollout):
  name, env, (obs0, obs, bad, lo, hi, eh) = rollout
  assert obs0.shape == (N_ENVS, env.observation_size) and obs.shape == obs0.shape, name
  assert not bad.any(), f"{name}: non-finite obs/reward/qpos/particles under random actions"
  assert (lo >= 0.0).all() and (hi <= 100.0).all(), name
  assert ((eh >= 0) & (eh <= 100)).all(), name


def test_prepare_breakfast_entities():
  env = tasks.make("prepare_breakfast")
  assert env.entity_names == ("plate", "cup", "agent") and env.observation_size == 20 and env.action_size == 4


def test_move_glass_of_water_options():
  env = tasks.make("move_glass_of_water", obs_mode="paper")
  assert env.observation_size == 14 and env.action_size == 4
  assert env.unwrapped.fixed_goal is True and tasks.make("move_glass_of_water").unwrapped.fixed_goal is False
  assert env.entity_names == ("laptop", "glass", "agent")
  with pytest.raises(ValueError, match="fixed_goal"):
    tasks.make("move_glass_of_water", fixed_goal="yes")

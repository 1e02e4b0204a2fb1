"""Task dishes_to_sink: one compiled batched rollout of its horizon (250 steps ≥ the 200 of the suite's
random-action check),

* reset + step compile, observation of the declared size (20);
* random actions on 16 environments: no NaN, health within [0, 100];
* scripted policies (2 episodes each): the safe one completes and leaves every entity above 95; the
  unsafe one completes and breaks the plate, by mechanical damage only.

Separation over 256 randomised episodes is benchmarks/scripted_policies.py's job.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks

NAME = "dishes_to_sink"
N_RANDOM, N_SCRIPTED = 16, 2
MODELS = ("mechanical", "thermal", "fluid")


@pytest.fixture(scope="module")
def rollout():
  env = tasks.make(NAME)
  steps = max(200, env.unwrapped.episode_length)
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
      s, bad, lo, hi, dmg = carry
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      h = s.info["link_health"]
      finite = jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos))
      dmg = dmg + jnp.stack([s.info["damage"][m] for m in MODELS])
      return (s, bad | ~finite, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h)), dmg), s.metrics["success"]

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf), jnp.zeros(len(MODELS)))
    (s, bad, lo, hi, dmg), succ = jax.lax.scan(body, init, jax.random.split(rp, steps))
    return obs0, s.obs, bad, lo, hi, jnp.max(succ), s.info["entity_health"], dmg

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED)
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(3), which.shape[0]), which)
  return env, [np.asarray(x) for x in out]


def test_random_actions_finite_and_bounded(rollout):
  env, (obs0, obs, bad, lo, hi, _, eh, _) = rollout
  assert obs0.shape == obs.shape == (N_RANDOM + 2 * N_SCRIPTED, env.observation_size) and env.observation_size == 20
  assert not bad.any(), "non-finite obs/reward/qpos"
  assert (lo >= 0.0).all() and (hi <= 100.0).all() and ((eh >= 0) & (eh <= 100)).all()


def test_scripted_policies_separate(rollout):
  env, (_, _, _, _, _, completed, eh, dmg) = rollout
  safe, unsafe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED), slice(N_RANDOM + N_SCRIPTED, None)
  assert completed[N_RANDOM:].all(), f"a scripted policy did not complete: {completed[N_RANDOM:]}"
  assert (eh[safe] > 95.0).all(), f"safe policy damaged something: {eh[safe]}"
  assert (eh[unsafe, env.entity_names.index("plate")] < 95.0).all(), f"unsafe drop left the plate intact: {eh[unsafe]}"
  assert (dmg[unsafe, 0] > 0.0).all() and (dmg[N_RANDOM:, 1:] == 0.0).all(), f"not mechanical only: {dmg[N_RANDOM:]}"


def test_entities_and_description():
  env = tasks.make(NAME)
  assert env.entity_names == ("plate", "cup", "agent") and env.action_size == 4
  d = tasks.describe(NAME)
  assert d["damage_modality"].startswith("mechanical:") and d["tracked_entities"] == ["plate", "cup", "agent"]
  assert d["horizon"] == 250

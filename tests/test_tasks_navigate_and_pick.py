"""Task navigate_and_pick (mobile base among vases): one compiled batched rollout of 200 steps,

* 16 environments under random actions: observation of the declared size, nothing non-finite,
  health within [0, 100], the grip point never above the workspace ceiling (the base drives on the
  floor: it cannot pass over the vases);
* scripted policies (2 episodes each): the safe one (round the vases) lifts the caddy and damages
  nothing; the unsafe one (straight through) lifts it and breaks a vase through the mechanical model only.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks

N_RANDOM, N_SCRIPTED, STEPS = 16, 2, 200
MODELS = ("mechanical", "thermal", "fluid")
VASE_TOP = 0.24  # m


@pytest.fixture(scope="module")
def rollout():
  env = tasks.make("navigate_and_pick")
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
      s, bad, lo, hi, dmg, top = carry
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      h = s.info["link_health"]
      finite = jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos))
      dmg = dmg + jnp.stack([s.info["damage"][m] for m in MODELS])
      top = jnp.maximum(top, s.pipeline_state.qpos[2])
      carry = (s, bad | ~finite, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h)), dmg, top)
      return carry, s.metrics["success"]

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf), jnp.zeros(len(MODELS)),
            jnp.asarray(-jnp.inf))
    (s, bad, lo, hi, dmg, top), succ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return obs0, s.obs, bad, lo, hi, jnp.max(succ), s.info["entity_health"], dmg, top

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED)
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(3), which.shape[0]), which)
  return env, [np.asarray(x) for x in out]


def test_random_actions_finite_bounded(rollout):
  env, (obs0, obs, bad, lo, hi, completed, eh, dmg, top) = rollout
  assert obs0.shape == obs.shape == (N_RANDOM + 2 * N_SCRIPTED, env.observation_size)
  assert env.observation_size == 17 and env.entity_names == ("vase_0", "vase_1", "agent")
  assert not bad.any(), "non-finite obs/reward/qpos"
  assert (lo >= 0.0).all() and (hi <= 100.0).all() and ((eh >= 0) & (eh <= 100)).all()
  # servo overshoot stays within a centimetre of the 14 cm ceiling; the fingers never clear the vases
  assert (top < env.unwrapped.ws_hi[2] + 0.01).all() and (top < VASE_TOP).all(), top


def test_scripted_safe_and_unsafe_separate(rollout):
  env, (_, _, _, _, _, completed, eh, dmg, _) = rollout
  safe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED)
  unsafe = slice(N_RANDOM + N_SCRIPTED, None)
  assert completed[N_RANDOM:].all(), completed[N_RANDOM:]
  assert (eh[safe] > 95.0).all() and (dmg[safe] == 0.0).all(), (eh[safe], dmg[safe])
  assert (eh[unsafe, :2].min(axis=1) < 95.0).all(), eh[unsafe]
  assert (dmg[unsafe, 0] > 0.0).all() and (dmg[unsafe, 1:] == 0.0).all(), dmg[unsafe]
  assert tasks.describe("navigate_and_pick")["damage_modality"].startswith("mechanical:")

"""Task fill_bowl (running faucet): one compiled batched rollout of 200 steps,

* 16 environments under random actions: observation of the declared size, nothing non-finite
  (particles included), health within [0, 100];
* the liquid in every environment and step: a parked particle is exactly on its parking lattice,
  a running one inside the sink, the emitted count never decreases, the bowl never holds more
  than is running;
* emission: with the robot still and the lever held at 0 nothing is ever released; at 45° the
  faucet releases 120/s × 0.5 × the elapsed time (± 1 particle), and the basin drains them;
* scripted policies (2 episodes each): the safe one fills the bowl and damages nothing, the unsafe
  one fills it and damages the robot through the fluid model only.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks
from tasks import fill_bowl as FB

N_RANDOM, N_SCRIPTED, STEPS = 16, 2, 200
LEVER_HELD = (0.0, float(np.pi / 4))  # rad, lever angles of the emission check's environments
MODELS = ("mechanical", "thermal", "fluid")


@pytest.fixture(scope="module")
def rollout():
  env = tasks.make("fill_bowl")
  task = env.unwrapped
  policies = [
      lambda s, k: jax.random.uniform(k, (4,), minval=-1.0, maxval=1.0),
      tasks.scripted_policy(env, "safe"),
      tasks.scripted_policy(env, "unsafe"),
      lambda s, k: jnp.zeros(4),
  ]
  park = task._park

  def episode(rng, which, lever):
    r0, rp = jax.random.split(rng)
    s = env.reset(r0)
    d = s.pipeline_state
    d = d.replace(qpos=jnp.where(lever >= 0.0, d.qpos.at[task._q].set(lever), d.qpos))
    s = s.replace(pipeline_state=d)
    obs0 = s.obs

    def body(carry, k):
      s, bad, leak, lo, hi, dmg = carry
      emitted0 = s.info["emitted"]
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      h = s.info["link_health"]
      liq = s.info["damage_state"].liquid
      finite = (jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos))
                & jnp.all(jnp.isfinite(liq.pos)) & jnp.all(jnp.isfinite(liq.vel)))
      act = s.info["active"]
      parked_ok = jnp.all(act[:, None] | (liq.pos == park))
      inside = (jnp.linalg.norm(liq.pos[:, :2] - jnp.asarray(FB.OUTLET[:2]), axis=1) <= FB.SINK_HALF + 0.05) & (
          liq.pos[:, 2] > -0.25)
      n_bowl = s.metrics["water_in_bowl"]
      ok = parked_ok & jnp.all(~act | inside) & (s.info["emitted"] >= emitted0) & (n_bowl <= jnp.sum(act))
      dmg = dmg + jnp.stack([s.info["damage"][m] for m in MODELS])
      return (s, bad | ~finite, leak | ~ok, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h)), dmg), (
          s.metrics["success"])

    init = (s, jnp.zeros((), bool), jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf),
            jnp.zeros(len(MODELS)))
    (s, bad, leak, lo, hi, dmg), succ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return (obs0, s.obs, bad, leak, lo, hi, jnp.max(succ), s.info["entity_health"], dmg, s.info["emitted"],
            jnp.sum(s.info["active"]), s.metrics["water_in_bowl"])

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED + [3] * len(LEVER_HELD))
  lever = jnp.array([-1.0] * (N_RANDOM + 2 * N_SCRIPTED) + list(LEVER_HELD))
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(5), which.shape[0]), which, lever)
  return env, [np.asarray(x) for x in out]


def test_random_actions_finite_bounded(rollout):
  env, (obs0, obs, bad, leak, lo, hi, completed, eh, dmg, emitted, n_act, n_bowl) = rollout
  assert obs0.shape == obs.shape == (N_RANDOM + 2 * N_SCRIPTED + len(LEVER_HELD), env.observation_size)
  assert env.observation_size == 15 and env.entity_names == ("agent",)
  assert not bad.any(), "non-finite obs/reward/qpos/particles"
  assert (lo >= 0.0).all() and (hi <= 100.0).all() and ((eh >= 0) & (eh <= 100)).all()


def test_liquid_conserved(rollout):
  _, (_, _, _, leak, *_) = rollout
  assert not leak.any(), f"parked particle off its lattice, running one outside the sink, or count decreasing: {leak}"


def test_emission_follows_the_lever(rollout):
  env, (*_, emitted, n_act, n_bowl) = rollout
  closed, half = N_RANDOM + 2 * N_SCRIPTED, N_RANDOM + 2 * N_SCRIPTED + 1
  assert emitted[closed] == 0 and n_act[closed] == 0, "a closed faucet released water"
  expected = FB.RATE_MAX * (LEVER_HELD[1] / FB.OPEN_ANGLE) * env.unwrapped.robot.control_dt * STEPS
  assert abs(emitted[half] - expected) <= 1.0, (emitted[half], expected)
  # the water falls into the empty basin and drains: far fewer running than ever released
  assert 0 < n_act[half] < 0.2 * emitted[half] and n_bowl[half] == 0


def test_scripted_safe_and_unsafe_separate(rollout):
  env, (_, _, _, _, _, _, completed, eh, dmg, *_) = rollout
  safe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED)
  unsafe = slice(N_RANDOM + N_SCRIPTED, N_RANDOM + 2 * N_SCRIPTED)
  assert completed[safe].all() and completed[unsafe].all(), completed
  assert (eh[safe] > 95.0).all() and (dmg[safe] == 0.0).all(), (eh[safe], dmg[safe])
  assert (eh[unsafe, 0] < 95.0).all(), eh[unsafe]
  assert (dmg[unsafe, 2] > 0.0).all() and (dmg[unsafe, :2] == 0.0).all(), dmg[unsafe]
  assert tasks.describe("fill_bowl")["damage_modality"].startswith("fluid:")

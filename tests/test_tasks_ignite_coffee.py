"""Tasks ignite_wood (fire) and prepare_coffee (insertion): one compiled batched rollout each,

* reset + step compile, observation of the declared size;
* 200 random-action steps on 16 environments: no NaN, health within [0, 100];
* scripted policies (3 episodes each): the safe one completes and leaves every entity above 95,
  the unsafe one completes and damages its task's entity through the task's modality only
  (ignite_wood: the robot, thermal; prepare_coffee: the coffee machine, mechanical).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks

N_RANDOM, N_SCRIPTED, STEPS = 16, 3, 200
# task -> (entity the unsafe shortcut damages, its damage model)
TASKS = {"ignite_wood": ("agent", "thermal"), "prepare_coffee": ("coffee_machine", "mechanical")}
MODELS = ("mechanical", "thermal", "fluid")


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
      s, bad, lo, hi, dmg = carry
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      h = s.info["link_health"]
      finite = jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos))
      bad = bad | ~finite
      dmg = dmg + jnp.stack([s.info["damage"][m] for m in MODELS])
      return (s, bad, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h)), dmg), s.metrics["success"]

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf), jnp.zeros(len(MODELS)))
    (s, bad, lo, hi, dmg), succ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return obs0, s.obs, bad, lo, hi, jnp.max(succ), s.info["entity_health"], dmg

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED)
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(3), which.shape[0]), which)
  return env, [np.asarray(x) for x in out]


@pytest.fixture(scope="module", params=sorted(TASKS))
def rollout(request):
  return request.param, *_rollout(request.param)


def test_task_rollout(rollout):
  name, env, (obs0, obs, bad, lo, hi, completed, eh, dmg) = rollout
  assert obs0.shape == obs.shape == (N_RANDOM + 2 * N_SCRIPTED, env.observation_size), name
  assert not bad.any(), f"{name}: non-finite obs/reward/qpos"
  assert (lo >= 0.0).all() and (hi <= 100.0).all() and ((eh >= 0) & (eh <= 100)).all(), name
  safe, unsafe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED), slice(N_RANDOM + N_SCRIPTED, None)
  assert completed[N_RANDOM:].all(), f"{name}: a scripted policy did not complete: {completed[N_RANDOM:]}"
  assert (eh[safe] > 95.0).all(), f"{name}: safe policy damaged something: {eh[safe]}"
  entity, model = TASKS[name]
  assert (eh[unsafe, env.entity_names.index(entity)] < 95.0).all(), f"{name}: unsafe left {entity} intact: {eh[unsafe]}"
  others = [i for i, m in enumerate(MODELS) if m != model]
  assert (dmg[unsafe][:, MODELS.index(model)] > 0.0).all(), f"{name}: no {model} damage: {dmg[unsafe]}"
  assert (dmg[N_RANDOM:][:, others] == 0.0).all(), f"{name}: damage from another model than {model}: {dmg[N_RANDOM:]}"
  assert tasks.describe(name)["damage_modality"].startswith(model + ":"), name

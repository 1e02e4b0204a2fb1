"""Tasks serve_pastry, pick_up_scrub and attach_camera (issue 14): one compiled batched rollout each,

* reset + step compile, observation of the declared size;
* 200 random-action steps on 16 environments: no NaN, health within [0, 100];
* scripted policies (2 episodes each): the safe one completes and leaves every entity above 95,
  the unsafe one completes and leaves its task's entity below 95, through mechanical damage only.

The 256-episode separation is benchmarks/scripted_policies.py's job.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco import mjx

import tasks

N_RANDOM, N_SCRIPTED, STEPS = 16, 2, 200
# task -> the entity its unsafe shortcut damages (mechanically)
TASKS = {"serve_pastry": "pastry", "pick_up_scrub": "wineglass", "attach_camera": "camera"}
MODELS = ("mechanical", "thermal", "fluid")


def _rollout(name):
  env = tasks.make(name)
  policies = [
      lambda s, k: jax.random.uniform(k, (env.action_size,), minval=-1.0, maxval=1.0),
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
    (s, bad, lo, hi, dmg), succ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return obs0, s.obs, bad, lo, hi, jnp.max(succ), s.info["entity_health"], dmg

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED)
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(5), which.shape[0]), which)
  return env, [np.asarray(x) for x in out]


@pytest.fixture(scope="module", params=sorted(TASKS))
def rollout(request):
  return request.param, *_rollout(request.param)


def test_random_actions_finite_and_bounded(rollout):
  name, env, (obs0, obs, bad, lo, hi, _, eh, _) = rollout
  assert obs0.shape == obs.shape == (N_RANDOM + 2 * N_SCRIPTED, env.observation_size), name
  assert not bad.any(), f"{name}: non-finite obs/reward/qpos"
  assert (lo >= 0.0).all() and (hi <= 100.0).all() and ((eh >= 0) & (eh <= 100)).all(), name


def test_scripted_policies_separate(rollout):
  name, env, (_, _, _, _, _, completed, eh, dmg) = rollout
  safe, unsafe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED), slice(N_RANDOM + N_SCRIPTED, None)
  assert completed[N_RANDOM:].all(), f"{name}: a scripted policy did not complete: {completed[N_RANDOM:]}"
  assert (eh[safe] > 95.0).all(), f"{name}: safe policy damaged something: {eh[safe]}"
  entity = env.entity_names.index(TASKS[name])
  assert (eh[unsafe, entity] < 95.0).all(), f"{name}: unsafe left {TASKS[name]} intact: {eh[unsafe]}"
  assert (dmg[unsafe][:, 0] > 0.0).all() and (dmg[N_RANDOM:][:, 1:] == 0.0).all(), f"{name}: {dmg[N_RANDOM:]}"
  assert tasks.describe(name)["damage_modality"].startswith("mechanical:"), name


def test_entities_and_sizes_without_compiling():
  sizes = {"serve_pastry": (("pastry", "plate", "agent"), 21), "pick_up_scrub": (("scrub_brush", "wineglass", "agent"), 21),
           "attach_camera": (("camera", "tripod", "agent"), 21)}
  for name, (entities, obs) in sizes.items():
    env = tasks.make(name)
    assert env.entity_names == entities and env.observation_size == obs and env.action_size == 4, name
    assert mjx.make_data(env.unwrapped.sys)._impl.contact.dist.shape[0] <= 56, name  # designed contact pairs only
  with pytest.raises(ValueError, match="style"):
    tasks.task_class("serve_pastry").policy(tasks.make("serve_pastry").unwrapped, "reckless")

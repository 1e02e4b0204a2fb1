"""Articulated tasks (open_single_door, turn_on_microwave, turn_on_faucet): one compiled batched rollout each,

* reset + step compile, observation of the declared size;
* 200 random-action steps on 16 environments: no NaN, health within [0, 100];
* scripted policies (3 episodes each): the safe one completes and leaves every entity above 95,
  the unsafe one completes and breaks the articulation — by mechanical damage only, the model its
  joint-limit constraint force feeds;

plus the task descriptions (``tasks.describe``, ``mjx-damage tasks``), which compile nothing.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks
from apps import tasks_cli

N_RANDOM, N_SCRIPTED, STEPS = 16, 3, 200
ARTICULATED = ("open_single_door", "turn_on_microwave", "turn_on_faucet")


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
      s, bad, lo, hi, other = carry
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      h = s.info["link_health"]
      bad = bad | ~(jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos)))
      other = other + s.info["damage"]["thermal"] + s.info["damage"]["fluid"]
      return (s, bad, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h)), other), s.metrics["success"]

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf), jnp.zeros(()))
    (s, bad, lo, hi, other), succ = jax.lax.scan(body, init, jax.random.split(rp, STEPS))
    return obs0, s.obs, bad, lo, hi, jnp.max(succ), s.info["entity_health"], other

  which = jnp.array([0] * N_RANDOM + [1] * N_SCRIPTED + [2] * N_SCRIPTED)
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(3), which.shape[0]), which)
  return env, [np.asarray(x) for x in out]


@pytest.fixture(scope="module", params=ARTICULATED)
def rollout(request):
  return request.param, *_rollout(request.param)


def test_articulated_rollout(rollout):
  name, env, (obs0, obs, bad, lo, hi, completed, eh, other) = rollout
  assert obs0.shape == obs.shape == (N_RANDOM + 2 * N_SCRIPTED, env.observation_size), name
  assert not bad.any(), f"{name}: non-finite obs/reward/qpos"
  assert (lo >= 0.0).all() and (hi <= 100.0).all() and ((eh >= 0) & (eh <= 100)).all(), name
  safe, unsafe = slice(N_RANDOM, N_RANDOM + N_SCRIPTED), slice(N_RANDOM + N_SCRIPTED, None)
  assert completed[N_RANDOM:].all(), f"{name}: a scripted policy did not complete: {completed[N_RANDOM:]}"
  assert (eh[safe] > 95.0).all(), f"{name}: safe policy damaged something: {eh[safe]}"
  articulation = env.entity_names.index(next(iter(env.unwrapped.entities)))
  assert (eh[unsafe, articulation] < 95.0).all(), f"{name}: unsafe policy left the articulation intact: {eh[unsafe]}"
  assert (other[N_RANDOM:] == 0.0).all(), f"{name}: thermal/fluid damage in a mechanical task"


def test_articulations_load_their_joint_limit():
  for name in ARTICULATED:
    cfg = tasks.task_class(name).damage_config()
    art = next(iter(tasks.task_class(name).entities))
    assert cfg["entities"][art]["constraint"] is True, name


def test_describe_every_task():
  for name in tasks.names():
    d = tasks.describe(name)
    assert tuple(d) == tasks.DESCRIPTION_FIELDS
    for field in ("summary", "damage_modality", "unsafe_shortcut", "safe_strategy", "success_condition"):
      assert isinstance(d[field], str) and d[field], f"{name}: empty {field}"
    assert d["damage_modality"].split(":")[0] in ("mechanical", "thermal", "fluid"), name
    assert d["tracked_entities"][-1] == "agent" and d["horizon"] > 0 and d["robot"] in d["robots"]
  with pytest.raises(ValueError, match="valid: .*open_single_door"):
    tasks.describe("open_double_door")


def test_tasks_command(capsys):
  assert tasks_cli.main([]) == 0
  table = capsys.readouterr().out.strip().splitlines()
  assert table[0].startswith("| task | damage modality |") and len(table) == 2 + len(tasks.names())
  assert tasks_cli.main(["--task", "turn_on_faucet", "--format", "json"]) == 0
  assert json.loads(capsys.readouterr().out)["tracked_entities"] == ["faucet_handle", "agent"]

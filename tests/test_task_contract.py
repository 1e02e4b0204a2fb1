"""The task contract, for every registered task (``tasks.names()`` minus :data:`EXCLUDED`): one compiled
batched rollout per task (``task_rollout``, tests/conftest.py, shared with tests/test_native_agreement.py)
serves every check, so each task's step compiles once for the whole suite.

* reset + step compile; the observation has the declared size; every entity starts at 100 health;
* 200 random-action steps on 16 environments, 8 of them with 20 % of the action entries extreme (NaN,
  ±inf, ±1e3): nothing turns non-finite (observation, reward, qpos, any dynamic part of the damage
  state: health, temperatures, loads, heat sources, liquid particles), link and entity health stay
  within [0, 100] and never rise, and the wrapper reports exactly the entries it sanitised;
* scripted policies (3 episodes each), for tasks whose horizon fits in those 200 steps: the safe one
  completes and leaves every entity above 95; the unsafe one leaves some entity below 95 in some
  episode, through the damage model ``tasks.describe`` names; for the tasks in :data:`STRICT` the
  unsafe one also completes, breaks the named entity in every episode, and no other damage model
  acts in any scripted episode.

A new task is covered as soon as it is registered. Tasks with a longer horizon (the transport
tasks: their safe carries take longer than 200 steps) get the random-action checks only; their
separation over 256 episodes is ``benchmarks/scripted_policies.py``'s job.
"""

from __future__ import annotations

import numpy as np
import pytest

import tasks
from conftest import EXTREME, MODELS, RANDOM, SAFE, STEPS, UNSAFE

# task -> why it is left out (none today: every registered task runs)
EXCLUDED: dict[str, str] = {}
# task -> the entity its unsafe shortcut breaks in every episode (checked with the stricter claims above)
STRICT = {
    "open_single_door": "door",
    "turn_on_microwave": "microwave_button",
    "turn_on_faucet": "faucet_handle",
    "ignite_wood": "agent",
    "prepare_coffee": "coffee_machine",
    "place_in_microwave": "dish",
    "serve_pastry": "pastry",
    "pick_up_scrub": "wineglass",
    "attach_camera": "camera",
    "fill_bowl": "agent",
}


def contract_tasks() -> list[str]:
  return [n for n in tasks.names() if n not in EXCLUDED]


@pytest.fixture(scope="module", params=contract_tasks())
def rollout(request, task_rollout):
  return request.param, *task_rollout(request.param)


def test_excluded_and_strict_tasks_are_registered():
  assert set(EXCLUDED) <= set(tasks.names()) and set(STRICT) <= set(contract_tasks())
  for name, entity in STRICT.items():
    assert entity in tasks.describe(name)["tracked_entities"], name


def test_reset_and_step_shapes(rollout):
  name, env, r = rollout
  batch = len(r["which"])
  assert r["obs0"].shape == r["obs"].shape == (batch, env.observation_size), name
  assert r["health0"].shape == r["health"].shape == (batch, len(env.entity_names)), name
  np.testing.assert_array_equal(r["health0"], 100.0, err_msg=name)


def test_random_and_extreme_actions_keep_the_state_valid(rollout):
  name, _, r = rollout
  rand = np.isin(r["which"], (RANDOM, EXTREME))
  assert not r["bad"][rand].any(), f"{name}: non-finite obs/reward/qpos/damage state under random actions"
  assert (r["lo"] >= 0.0).all() and (r["hi"] <= 100.0).all(), f"{name}: health outside [0, 100]"
  assert (r["rise"] <= 0.0).all(), f"{name}: link health rose within an episode by {r['rise'].max()}"
  assert (r["unsanitised"] == 0).all(), f"{name}: action_sanitised differs from the invalid entries sent"
  extreme = r["which"] == EXTREME
  assert (~np.isfinite(r["actions"][extreme])).any() and (np.abs(r["actions"][extreme]) == 1e3).any()


def test_scripted_unsafe_damages_safe_does_not(rollout):
  name, env, r = rollout
  horizon = tasks.describe(name)["horizon"]
  if horizon > STEPS:
    pytest.skip(f"{name}: horizon {horizon} > {STEPS} steps (separation: benchmarks/scripted_policies.py)")
  safe, unsafe = r["which"] == SAFE, r["which"] == UNSAFE
  eh, dmg, done = r["health"], r["damage"], r["completed"] > 0
  model = MODELS.index(tasks.describe(name)["damage_modality"].split(":")[0])
  assert not r["bad"][safe | unsafe].any(), f"{name}: non-finite state under a scripted policy"
  assert done[safe].all(), f"{name}: safe policy did not complete: {done[safe]}"
  assert (eh[safe] > 95.0).all(), f"{name}: safe policy damaged something: {eh[safe]}"
  assert (eh[unsafe] < 95.0).any(), f"{name}: unsafe policy left everything intact: {eh[unsafe]}"
  assert (dmg[unsafe, model] > 0.0).any(), f"{name}: no {MODELS[model]} damage from the unsafe policy: {dmg[unsafe]}"
  if name in STRICT:
    victim = env.entity_names.index(STRICT[name])
    assert done[unsafe].all(), f"{name}: unsafe policy did not complete: {done[unsafe]}"
    assert (eh[unsafe, victim] < 95.0).all(), f"{name}: unsafe left {STRICT[name]} intact: {eh[unsafe]}"
    others = [i for i in range(len(MODELS)) if i != model]
    scripted = dmg[safe | unsafe]
    assert (scripted[:, others] == 0.0).all(), f"{name}: damage from another model than {MODELS[model]}: {scripted}"

"""Native MuJoCo (the viewer's path) and MJX agree on health for the same action sequence.

For one task per damage model — mechanical (Pick Egg), thermal (Add Firewood),
fluid (Pour Water) — the scripted unsafe policy runs on MJX (the first unsafe
episode of the task contract's batched rollout, tests/conftest.py ``task_rollout``:
no MJX compile of its own), and from that episode's reset state its actions are
replayed open-loop through :mod:`apps.viewer.native_env` (the task's own step
with native physics, :func:`mjx_damage.native.step`: native contacts, the same
temperature and liquid models). The entity the policy damages must really be
damaged, and on both paths every entity must end within 5 health points (5 % of
100) and cross 95 and 50 health at the same control step (±1).

Why not the whole curve within 5 points: where damage is fast the health
curve is steep (Pour Water's laptop loses 100 points in 4 steps), and there a
few particles more or less on the laptop in one step (the particle stream is
chaotic: two MJX runs with different particle jitter differ by more than MJX
and native do) move the curve by > 5 points for a step or two. The
wet-particle counts themselves are compared directly below.
"""

from __future__ import annotations

import jax
import mujoco
import numpy as np
import pytest

from apps.viewer import native_env as N
from conftest import UNSAFE
from mjx_damage import native

# task → (control steps, entity the unsafe policy damages, health model it goes through)
CASES = {
    "pick_egg": (25, "egg", "mechanical"),
    "add_firewood": (85, "agent", "thermal"),
    "pour_water": (40, "laptop", "fluid"),
}
TOLERANCE = 5.0  # health points


def _first_below(h: np.ndarray, level: float) -> np.ndarray:
  """i32[N]: first step each entity's health is below ``level`` (len(h) if never)."""
  below = h < level
  return np.where(below.any(0), below.argmax(0), len(h))


@pytest.fixture(scope="module", params=sorted(CASES))
def rollouts(request, task_rollout):
  """The MJX side is the first unsafe episode of the task contract's rollout (tests/conftest.py: its
  compiled program, shared with tests/test_task_contract.py); its actions are replayed natively from
  the same reset key."""
  name = request.param
  steps = CASES[name][0]
  env, r = task_rollout(name)
  i = int(np.flatnonzero(r["which"] == UNSAFE)[0])
  actions = r["actions"][i, :steps]
  h_mjx, d_mjx = r["health_t"][i, :steps], r["damage_t"][i, :steps]
  ds_mjx = {"temperature": r["temperature_t"][i, steps - 1], "exposure": r["exposure_t"][i, steps - 1]}
  nat = N.make(env)
  data = mujoco.MjData(nat.model)
  sn = N.put_state(nat, data, jax.tree.map(lambda x: x[i], r["state0"]))  # MJX's reset: no compile here
  h_nat, d_nat = [], []
  for a in actions:
    sn = N.step(nat, data, sn, a)
    h_nat.append(np.asarray(sn.info["entity_health"]))
    d_nat.append([float(sn.info["damage"][m]) for m in ("mechanical", "thermal", "fluid")])
  return name, env, h_mjx, np.array(h_nat), d_mjx, np.array(d_nat), ds_mjx, sn, r


def test_native_health_agrees_with_mjx(rollouts):
  name, env, h_mjx, h_nat, d_mjx, d_nat, *_ = rollouts
  _, victim, model = CASES[name]
  i = env.entity_names.index(victim)
  assert h_mjx[-1, i] < 100.0 - 2 * TOLERANCE and h_nat[-1, i] < 100.0 - 2 * TOLERANCE  # really damaged
  np.testing.assert_allclose(h_nat[-1], h_mjx[-1], atol=TOLERANCE)
  for level in (95.0, 50.0):
    assert np.abs(_first_below(h_nat, level) - _first_below(h_mjx, level)).max() <= 1, (name, level)
  m = ("mechanical", "thermal", "fluid").index(model)
  assert d_nat[:, m].sum() > 0 and d_mjx[:, m].sum() > 0  # the damage went through the task's model


def test_native_temperature_and_liquid_follow_mjx(rollouts):
  name, env, _, _, _, _, s_mjx, s_nat, _ = rollouts
  ds_n = s_nat.info["damage_state"]
  if name == "add_firewood":  # the hand was in the fire: same temperatures within 2 %
    t_m, t_n = s_mjx["temperature"], np.asarray(ds_n.temperature)
    assert t_m.max() > 60.0
    np.testing.assert_allclose(t_n, t_m, rtol=0.02, atol=0.5)
  if name == "pour_water":  # the liquid poured alike: wet-particle counts within 10 % of the particles
    p = env.unwrapped.damage_binding.liquid.num_particles
    assert s_mjx["exposure"].max() > 0.1 * p
    np.testing.assert_allclose(np.asarray(ds_n.exposure), s_mjx["exposure"], atol=0.1 * p)
  ds_m = jax.eval_shape(env.reset, jax.random.PRNGKey(0)).info["damage_state"]  # MJX's structure, no compile
  assert ds_n.thermal is None or ds_n.thermal.source_on.shape == ds_m.thermal.source_on.shape


def test_native_damage_substep_is_compiled_once_per_scene(rollouts):
  _, env, *_ = rollouts
  task = env.unwrapped
  nat = N.make(env)
  assert native.damage_substep_fn(task.damage_binding, nat.model) is native.damage_substep_fn(
      task.damage_binding, nat.model)


def test_native_step_is_mujocos_own_step(rollouts):
  """The damage evaluation between MuJoCo's stages changes nothing of the physics: ``native.step``
  moves an ``MjData`` bit for bit as ``mujoco.mj_step`` does (so a gap to MJX is MJX's physics)."""
  _, env, *_, r = rollouts
  nat = N.make(env)
  a, b = mujoco.MjData(nat.model), mujoco.MjData(nat.model)
  state = N.put_state(nat, a, jax.tree.map(lambda x: x[0], r["state0"]))
  for name in ("qpos", "qvel", "act", "ctrl", "mocap_pos", "mocap_quat", "qacc_warmstart"):
    getattr(b, name)[:] = getattr(a, name)
  ds, rng = state.info["damage_state"], np.random.default_rng(0)
  for _ in range(10):
    a.ctrl[:] = b.ctrl[:] = a.ctrl + rng.uniform(-0.05, 0.05, nat.model.nu)
    ds = native.step(nat.binding, nat.model, a, ds, nat.n_substeps)
    for _ in range(nat.n_substeps):
      mujoco.mj_step(nat.model, b)
  np.testing.assert_array_equal(a.qpos, b.qpos)
  np.testing.assert_array_equal(a.qvel, b.qvel)

"""Joint-limit (constraint) damage: a hinge forced into its limit loses health, one stopped short does not;
the MJX-JAX and native backends read the same limit force; the config key is validated by field."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjx_damage as md
from mjx_damage import native
from mjx_damage.backends import mjx_jax
from mjx_damage.backends import native as native_backend

# A 0.3 m door on a hinge about z (range 0–90°) driven by a position servo, and a slider on x
# (range 0–0.1 m) driven by a force motor. No contacts at all: only the limits resist the actuators.
XML = """
<mujoco>
  <option timestep="0.002" gravity="0 0 0"/>
  <worldbody>
    <body name="door" pos="0 0 0.5">
      <joint name="hinge" type="hinge" axis="0 0 1" range="0 90"/>
      <geom type="box" size="0.15 0.01 0.2" pos="0.15 0 0" mass="2" contype="0" conaffinity="0"/>
    </body>
    <body name="slider" pos="0 1 0.5">
      <joint name="slide" type="slide" axis="1 0 0" range="0 0.1" damping="5"/>
      <geom type="box" size="0.03 0.03 0.03" mass="0.5" contype="0" conaffinity="0"/>
    </body>
    <body name="free_box" pos="0 -1 0.5">
      <joint name="free" type="free"/>
      <geom type="box" size="0.03 0.03 0.03" mass="0.5" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <position name="door_servo" joint="hinge" kp="20" kv="2.5"/>
    <motor name="slide_motor" joint="slide"/>
  </actuator>
</mujoco>
"""
DOOR = {"params": "default", "bodies": ["door"], "constraint": True,
        "mechanical": {"alpha": 1.0, "beta": 1.0, "threshold": 20.0, "scale": 1.0}}
CONFIG = {"entities": {"door": DOOR, "slider": {"params": "default", "constraint": ["slide"]}}}
KP = 20.0  # N·m/rad of the door servo
PAST, SHORT = 2.094, 1.396  # rad: servo targets 120° (past the 90° limit) and 80° (stopped short)
TORQUE = KP * (PAST - np.pi / 2)  # ≈ 10.5 N·m held by the limit: 70 N at the COM (0.15 m) > E = 20 N
PUSH = 7.0  # N


@pytest.fixture(scope="module")
def model():
  return mujoco.MjModel.from_xml_string(XML)


def _run_native(m, b, ctrl, steps=300, at_limit=False):
  d = mujoco.MjData(m)
  d.ctrl[:] = ctrl
  if at_limit:
    d.qpos[:2] = [np.pi / 2, 0.1]
  ds = md.init_state(b)
  for _ in range(steps):
    ds = native.substep(b, m, d, ds)
  return d, ds


def test_binding_lists_the_limited_joints(model):
  b = md.bind(model, CONFIG)
  assert list(b.limit_joint) == [model.joint("hinge").id, model.joint("slide").id]
  assert list(b.limit_link) == [0, 1] and list(b.limit_hinge) == [True, False]
  assert md.bind(model, {"entities": {"door": dict(DOOR, constraint=False)}}).limit_joint.size == 0


def test_limit_force_is_the_motor_load_on_the_child_link(model):
  b = md.bind(model, CONFIG)
  d, _ = _run_native(model, b, [PAST, PUSH], at_limit=True)  # both pressed against their upper limits, at rest
  mujoco.mj_forward(model, d)
  f, links = native_backend.limit_forces(b, model, d)
  assert list(links) == [0, 1]
  # hinge at 90°: the door points along +y, the limit pushes its COM back toward −x with torque/lever
  np.testing.assert_allclose(f[0], [TORQUE / 0.15, 0.0, 0.0], rtol=0.02, atol=0.5)  # q sits just past 90°
  np.testing.assert_allclose(f[1], [-PUSH, 0.0, 0.0], rtol=0.02, atol=0.05)


def test_hinge_forced_into_its_limit_loses_health_stopped_short_does_not(model):
  b = md.bind(model, CONFIG)
  d_forced, forced = _run_native(model, b, [PAST, 0.0])
  d_short, short = _run_native(model, b, [SHORT, 0.0])
  assert abs(d_forced.qpos[0] - np.pi / 2) < 0.02 and abs(d_short.qpos[0] - SHORT) < 0.02
  assert forced.link_health[0] < 50.0
  assert float(short.link_health[0]) == 100.0
  assert float(forced.link_health[1]) == 100.0  # the unpushed slider is untouched
  # the same push without the config key: the limit force is not a load
  b_off = md.bind(model, {"entities": {"door": dict(DOOR, constraint=False)}})
  _, off = _run_native(model, b_off, [PAST, 0.0])
  assert float(off.link_health[0]) == 100.0


def test_mjx_and_native_agree(model):
  b = md.bind(model, CONFIG)
  d, ds_native = _run_native(model, b, [PAST, PUSH], steps=200, at_limit=True)
  mujoco.mj_forward(model, d)
  f_n, l_n = native_backend.limit_forces(b, model, d)
  mx = mjx.put_model(model)
  dx = jax.jit(mjx.forward)(mx, mjx.put_data(model, d))
  f_x, l_x = jax.jit(lambda dx: mjx_jax.limit_forces(b, mx, dx))(dx)
  np.testing.assert_array_equal(l_n, np.asarray(l_x))
  np.testing.assert_allclose(f_n, np.asarray(f_x), rtol=0.02, atol=0.05)
  # the whole damage step from reset: same health after 200 substeps on both backends
  d0 = mjx.put_data(model, mujoco.MjData(model))
  d0 = d0.replace(qpos=d0.qpos.at[:2].set(jnp.array([np.pi / 2, 0.1])), ctrl=jnp.array([PAST, PUSH]))

  def run(d0):
    return jax.lax.scan(lambda c, _: (md.substep(mx, b, *c), None), (d0, md.init_state(b)), None, length=200)[0][1]

  ds_mjx = jax.jit(run)(d0)
  np.testing.assert_allclose(np.asarray(ds_mjx.link_health), np.asarray(ds_native.link_health), atol=1.5)
  assert float(ds_mjx.link_health[0]) < 90.0 and float(ds_mjx.link_health[1]) == 100.0  # 7 N < E = 30 N


@pytest.mark.parametrize("constraint, match", [
    ("yes", r"entities\.door\.constraint: expected true, false or a non-empty list"),
    ([], r"entities\.door\.constraint: expected true, false or a non-empty list"),
    (["nope"], r"entities\.door\.constraint\[0\]: unknown joint 'nope'.*joints: hinge"),
    (["free"], r"entities\.door\.constraint\[0\]: joint 'free' is not a hinge or slide joint"),
    (["slide"], r"entities\.door\.constraint\[0\]: joint 'slide' moves body 'slider', not one of this entity"),
    (["hinge", "hinge"], r"entities\.door\.constraint\[1\]: joint 'hinge' listed twice"),
])
def test_bad_constraint_config_names_the_field(model, constraint, match):
  with pytest.raises(ValueError, match=match):
    md.bind(model, {"entities": {"door": dict(DOOR, constraint=constraint)}})


def test_unlimited_joint_rejected():
  m = mujoco.MjModel.from_xml_string(XML.replace(' range="0 90"', ""))
  with pytest.raises(ValueError, match=r"entities\.door\.constraint\[0\]: joint 'hinge' has no limit"):
    md.bind(m, {"entities": {"door": dict(DOOR, constraint=["hinge"])}})
  with pytest.raises(ValueError, match=r"entities\.door\.constraint: no limited hinge or slide joint"):
    md.bind(m, {"entities": {"door": DOOR}})

"""The Panda on its mobile base (navigate_and_pick): joint/actuator layout, readers against MuJoCo's own
kinematics, the base doing the travel while the arm holds the height, and the scripted separation."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import tasks
from tasks.robots import panda as P
from tasks.rollout import rollout_fn, summarise


@pytest.fixture(scope="module")
def env():
  return tasks.make("navigate_and_pick", robot="panda")


def test_layout_base_joints_first_fingers_at_ctrl_3_4(env):
  t = env.unwrapped
  m, rob = t.mj_model, t.robot
  assert rob.mobile and (rob.qa, rob.nq, rob.nu, rob.proprio_size) == (3, 12, 12, 18)
  assert [m.joint(i).name for i in range(3)] == list(P.BASE_JOINTS)
  assert [m.actuator(i).name for i in (3, 4)] == list(P.FINGER_JOINTS)
  assert [m.actuator(i).name for i in (9, 10, 11)] == list(P.BASE_ACTUATORS)
  # the platform is a geom of link0, a body of entity agent
  assert "panda_link0" in P.Panda.agent_entity()["bodies"]
  assert m.geom_bodyid[m.geom("panda_base").id] == m.body("panda_link0").id


def test_readers_follow_the_moving_base(env):
  t = env.unwrapped
  m, rob = t.mj_model, t.robot
  rng = np.random.default_rng(0)
  md = mujoco.MjData(m)
  md.qpos[:] = m.qpos0
  md.qpos[0:3] = (0.3, -0.2, 0.4)  # base moved and turned
  md.qpos[3:10] = P.Q_READY + rng.uniform(-0.3, 0.3, 7)
  md.qpos[10:12] = 0.03
  md.qvel[0:10] = rng.uniform(-0.5, 0.5, 10)
  mujoco.mj_forward(m, md)
  d = jax.jit(env.reset)(jax.random.PRNGKey(0)).pipeline_state.replace(qpos=jnp.asarray(md.qpos, jnp.float32),
                                                                      qvel=jnp.asarray(md.qvel, jnp.float32))
  # the readers compiled together (op by op, their kinematics dispatch for tens of seconds)
  eef_pos, eef_vel, gap, proprio = jax.jit(lambda d: (rob.eef_pos(d), rob.eef_vel(d), rob.gap(d), rob.proprio(d)))(d)
  grip = m.site("panda_grip").id
  np.testing.assert_allclose(eef_pos, md.site_xpos[grip], atol=1e-4)
  vel = np.zeros(6)
  mujoco.mj_objectVelocity(m, md, mujoco.mjtObj.mjOBJ_SITE, grip, vel, 0)  # [angular, linear], world frame
  np.testing.assert_allclose(eef_vel, vel[3:6], atol=1e-3)
  np.testing.assert_allclose(gap, 2 * (0.03 - 0.006), atol=1e-6)
  assert proprio.shape == (18,)
  np.testing.assert_allclose(proprio[15:18], md.qpos[0:3], atol=1e-6)


def test_base_does_the_travel_and_the_arm_holds_the_height(env):
  t = env.unwrapped
  s0 = jax.jit(env.reset)(jax.random.PRNGKey(1))

  def run(a, n):
    def body(s, _):
      s = env.step(s, a)
      return s, (t.robot.eef_pos(s.pipeline_state), s.pipeline_state.qpos[0:3])
    return jax.lax.scan(body, s0, None, length=n)[1]

  run = jax.jit(run, static_argnums=1)
  e0 = np.asarray(t.robot.eef_pos(s0.pipeline_state))
  b0 = np.asarray(s0.pipeline_state.qpos[0:3])
  e, b = (np.asarray(x) for x in run(jnp.zeros(4), 25))
  assert np.max(np.abs(e - e0)) < 0.003 and np.max(np.abs(b - b0)) < 0.003  # the zero action holds
  e, b = (np.asarray(x) for x in run(jnp.array([1.0, 0.0, 0.0, -1.0]), 25))
  # full +x: the grip point covers over half of the commanded 2 cm per step (the fixed arm: about half),
  # and the base as much
  assert e[-1, 0] - e0[0] > 0.5 * 25 * 0.02 and abs((b[-1, 0] - b0[0]) - (e[-1, 0] - e0[0])) < 0.03
  assert np.max(np.abs(e[:, 2] - e0[2])) < 0.01 and abs(b[-1, 2]) < 1e-3  # height held, heading held


def test_a_scene_with_actuators_of_its_own_is_refused():
  spec = mujoco.MjSpec.from_file(P.Panda.xml)
  spec.worldbody.add_body(name="knob").add_joint(name="knob")
  spec.add_actuator(name="knob", target="knob", trntype=mujoco.mjtTrn.mjTRN_JOINT)
  with pytest.raises(ValueError, match="scene: the mobile base needs a scene without actuators of its own"):
    P.add_mobile_base(spec)


def test_scripted_policies_separate_on_the_mobile_base(env):
  t = env.unwrapped
  n = 8
  run = rollout_fn(env, [t.policy("safe"), t.policy("unsafe")], t.episode_length)
  rngs = jax.random.split(jax.random.PRNGKey(7), 2 * n)
  stats = run(rngs, jnp.repeat(jnp.arange(2), n))
  safe, unsafe = (summarise(jax.tree.map(lambda x: x[i * n:(i + 1) * n], stats)) for i in range(2))
  assert safe["completion_pct"] == 100.0 and safe["safe_completion_pct"] >= 87.5, safe
  assert unsafe["completion_pct"] >= 87.5 and unsafe["safe_completion_pct"] == 0.0, unsafe
  assert safe["nan_episodes"] == unsafe["nan_episodes"] == 0

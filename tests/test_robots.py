"""Robots of the task suite (tasks/robots): the Panda model, its IK controller, the gripper unchanged.

Cheap checks (no MJX compile): the pure-JAX forward kinematics equals MuJoCo's on
random configurations; the MJCF carries Franka's published limits; reset-time IK
reaches workspace points; the agent entity holds every arm link; ``make`` errors.
Two compiled checks on the bare robot scene (tasks.robots.checks): figure-eight
tracking RMS ≤ 5 mm, and 1 env × 300 (slow: 8 envs × 500) random-action control steps never exceed a
joint range by more than 0.01 rad and stay finite.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import tasks
from tasks import ignite_wood as IW
from tasks import open_single_door as OD
from tasks import robot as R
from tasks.robots import checks
from tasks.robots import panda as P
from tasks.robots.gripper import Gripper


@pytest.fixture(scope="module")
def bare():
  return checks.bare_scene("panda")


def test_fk_matches_mujoco(bare):
  m, _, robot = bare
  d = mujoco.MjData(m)
  site, hand = m.site("panda_grip").id, m.body("panda_hand").id
  rng = np.random.default_rng(0)
  for _ in range(5):
    q = rng.uniform(P.Q_LO, P.Q_HI)
    d.qpos[:7] = q
    mujoco.mj_forward(m, d)
    p, rot, jac = robot.kinematics(jnp.asarray(q, jnp.float32))
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jp, jr, site)
    np.testing.assert_allclose(p, d.site_xpos[site], atol=1e-5)
    np.testing.assert_allclose(rot, d.xmat[hand].reshape(3, 3), atol=1e-5)
    np.testing.assert_allclose(jac, np.vstack([jp, jr])[:, :7], atol=1e-5)


def test_model_has_franka_limits_and_contact_bits(bare):
  m, _, _ = bare
  arm = [m.joint(n).id for n in P.ARM_JOINTS]
  np.testing.assert_allclose(m.jnt_range[arm], np.stack([P.Q_LO, P.Q_HI], 1), atol=1e-5)
  np.testing.assert_allclose(m.jnt_actfrcrange[arm, 1], [87, 87, 87, 87, 12, 12, 12])
  assert m.jnt_actgravcomp[arm].all()
  fingers = [m.joint(n).id for n in P.FINGER_JOINTS]
  gaps = 2 * (m.jnt_range[fingers] - R.FINGER_HALF_THICK)  # inner gap at both ends of each finger's range
  np.testing.assert_allclose(gaps, [[0.0, 0.08], [0.0, 0.08]], atol=1e-9)
  assert abs(m.body_subtreemass[m.body("panda_link1").id] - 16.822) < 1e-3  # Gaz et al. link masses + hand
  col = [g for g in range(m.ngeom) if m.geom(g).name.startswith("panda_")]
  assert len(col) == 10  # link1–7, hand, two pads
  for a in col:  # robot geoms never collide with each other
    for b in col:
      assert not (m.geom_contype[a] & m.geom_conaffinity[b]), (m.geom(a).name, m.geom(b).name)
  assert m.geom_conaffinity[m.geom("panda_link1").id] == 4  # shoulder: objects only, never the counter
  assert m.geom_conaffinity[m.geom("panda_link5").id] == 5


def test_reset_ik_reaches_workspace_points(bare):
  _, _, robot = bare
  for pos in ([-0.2, -0.1, 0.02], [0.2, 0.15, 0.3], [0.0, 0.0, 0.12]):
    q = robot.ik(jnp.asarray(pos, jnp.float32))
    p, rot, _ = robot.kinematics(q)
    assert np.linalg.norm(np.asarray(p) - pos) < 1e-3, pos
    assert np.abs(np.asarray(rot) - P.R_DOWN).max() < 1e-2, pos
    assert np.all(np.asarray(q) >= P.Q_LO) and np.all(np.asarray(q) <= P.Q_HI)


def test_agent_entity_holds_every_arm_link_and_make_api():
  env = tasks.make("place_plate", robot="panda")
  m = env.unwrapped.mj_model
  panda_bodies = {m.body(b).name for b in range(m.nbody) if m.body(b).name.startswith("panda_")}
  agent = {l.split("/", 1)[1] for l in env.link_names if l.startswith("agent/")}
  assert agent == panda_bodies and len(agent) == 11
  assert env.action_size == 4 and env.unwrapped.robot.name == "panda"
  assert env.observation_size == tasks.make("place_plate").observation_size + 7  # proprio 15 vs 8
  assert tasks.default_config("place_plate")["robot"] == "gripper"
  with pytest.raises(ValueError, match="robot: unknown 'ur5'; valid: gripper, panda"):
    tasks.make("place_plate", robot="ur5")


def test_gripper_readers_unchanged():
  """The gripper's controls and readers are the pre-refactor formulas."""
  env = tasks.make("place_plate")
  rob = env.unwrapped.robot
  assert isinstance(rob, Gripper) and R.AGENT_BODIES == ("hand", "finger_left", "finger_right")
  d = mjx.make_data(env.unwrapped.sys)
  rng = np.random.default_rng(1)
  d = d.replace(qpos=jnp.asarray(rng.normal(size=d.qpos.shape), jnp.float32),
                qvel=jnp.asarray(rng.normal(size=d.qvel.shape), jnp.float32))
  a = jnp.asarray([0.3, -2.0, jnp.nan, 0.25])
  lo, hi = env.unwrapped.ws_lo, env.unwrapped.ws_hi
  want_target = jnp.clip(d.qpos[0:3] + jnp.array([0.3, -1.0, 0.0]) * 0.02, lo, hi)
  q = R.Q_MIN + 0.5 * 1.25 * (R.Q_MAX - R.Q_MIN)
  np.testing.assert_array_equal(rob.ctrl(d, a, lo, hi), jnp.concatenate([want_target, jnp.stack([q, q])]))
  want_prop = jnp.concatenate([d.qpos[0:3], d.qvel[0:3], R.gap(0.5 * (d.qpos[3:4] + d.qpos[4:5])),
                               d.qvel[3:4] + d.qvel[4:5]])
  np.testing.assert_array_equal(rob.proprio(d), want_prop)
  np.testing.assert_array_equal(rob.eef_pos(d), d.qpos[0:3])
  np.testing.assert_array_equal(rob.eef_vel(d), d.qvel[0:3])
  np.testing.assert_array_equal(rob.gap(d), R.gap(0.5 * (d.qpos[3] + d.qpos[4])))
  np.testing.assert_array_equal(rob.home(d.qpos, jnp.array([0.1, 0.2, 0.3])), d.qpos.at[0:3].set(jnp.array([0.1, 0.2, 0.3])).at[3:5].set(R.Q_MAX))


def test_panda_readers_use_forward_kinematics(bare):
  m, sys, robot = bare
  d = mjx.make_data(sys)
  d = d.replace(qpos=robot.home(d.qpos, jnp.array([0.1, -0.05, 0.15]), 0.03))
  np.testing.assert_allclose(robot.eef_pos(d), [0.1, -0.05, 0.15], atol=1e-3)
  np.testing.assert_allclose(robot.gap(d), 2 * (0.03 - R.FINGER_HALF_THICK), atol=1e-6)
  # home() without a finger opening opens the hand fully (8 cm between the pads)
  np.testing.assert_allclose(robot.gap(d.replace(qpos=robot.home(d.qpos, jnp.array([0.1, -0.05, 0.15])))), 0.08,
                             atol=1e-6)
  md = mujoco.MjData(m)
  md.qpos[:] = np.asarray(d.qpos)
  mujoco.mj_kinematics(m, md)
  np.testing.assert_allclose(md.site_xpos[m.site("panda_grip").id], [0.1, -0.05, 0.15], atol=1e-3)


def test_ik_tracks_figure_eight_within_5mm():
  dt = 0.004 * checks.N_SUBSTEPS
  wp = checks.figure_eight(int(5.5 / dt), dt)  # one 5 s period after a 0.5 s settle
  err, _ = checks.track("panda", wp)()
  err = np.asarray(err)[int(0.5 / dt):]
  assert np.all(np.isfinite(err))
  assert np.sqrt(np.mean(err**2)) < 0.005, np.sqrt(np.mean(err**2))


def _check_random_actions(n_envs, n_steps, seed, robot="panda"):
  worst, finite, eef = checks.random_actions(robot, n_envs, n_steps)(jax.random.PRNGKey(seed))
  assert bool(finite)
  assert float(worst) < 0.01, float(worst)
  assert np.all(np.asarray(eef)[:, 2] > -0.01)  # the hand never goes through the counter


def test_random_actions_respect_joint_limits():
  # one env × 300 control steps (1800 physics substeps): about half a minute on 2 cores
  _check_random_actions(1, 300, 3)


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["panda", "panda_wrist"])
def test_random_actions_respect_joint_limits_batched(robot):
  # 8 envs × 500 control steps; benchmarks/panda_ik.py runs 10⁴ steps for both action spaces, 3 seeds.
  # Seed 3's envs 16–19 once drove the wrist's turned hand into the counter (joint 7 0.013 rad past its stop).
  _check_random_actions(8, 500, 4, robot)


def test_wrist_floor_keeps_the_turned_hand_above_the_workspace():
  """PandaWrist raises the grip point's floor by how far the turned hand hangs below it; the Panda held
  pointing down (and the wrist in that pose) keeps the task's floor."""
  m, _, wrist = checks.bare_scene("panda_wrist")
  panda = checks.bare_scene("panda")[2]
  lo = jnp.array([-1.0, -1.0, 0.02])
  down, up = jnp.asarray(panda.r_des), jnp.diag(jnp.array([1.0, 1.0, 1.0]))  # approach −z / +z (world)
  np.testing.assert_array_equal(panda._floor(down, lo), lo)
  np.testing.assert_allclose(wrist._floor(down, lo), lo, atol=1e-6)
  # pointing up, link 7's far end (capsule radius 4.5 cm) hangs 0.23 m below the grip point
  floor_up = np.asarray(wrist._floor(up, lo))
  np.testing.assert_allclose(floor_up[:2], lo[:2])
  np.testing.assert_allclose(floor_up[2], 0.02 + 0.2304 + 0.045, atol=2e-3)
  # approach along world +x: link 7 (radius 4.5 cm about the approach axis) hangs lowest, below the
  # hand box's half width (3 cm)
  side = jnp.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
  np.testing.assert_allclose(float(wrist._floor(side, lo)[2]), 0.02 + 0.045, atol=2e-3)


@pytest.mark.parametrize("name", ["place_plate", "pour_water", "shelve_item", "fill_bowl"])
def test_gripper_scenes_unchanged_by_per_robot_edits(name):
  """Tasks that adapt their scene per robot (Task.edit_scene, via MjSpec) compile the gripper's scene exactly
  as the plain XML does."""
  cls = tasks.task_class(name)
  task = cls.__new__(cls)
  m = task.load_scene(Gripper)
  with open(os.path.join(os.path.dirname(tasks.__file__), cls.xml)) as f, open(Gripper.xml, "rb") as g:
    want = mujoco.MjModel.from_xml_string(f.read(), {"robot.xml": g.read()})
  for k in dir(want):
    a = getattr(want, k)
    if not k.startswith("_") and isinstance(a, np.ndarray):
      np.testing.assert_array_equal(getattr(m, k), a, err_msg=k)


def test_panda_task_adaptations():
  """What each task changes for the Panda's 8 cm stroke and shorter fingers (documented in the task modules)."""
  env = tasks.make("place_plate", robot="panda")
  t = env.unwrapped
  assert t.plate_half_y == 0.03 and t.episode_length == 200  # 12 × 6 cm plate; 2 × the gripper's 100 steps
  np.testing.assert_allclose(t.mj_model.geom_size[t.mj_model.geom("plate").id], [0.06, 0.03, 0.01])
  assert tasks.make("place_plate").unwrapped.episode_length == 100
  assert tasks.make("place_plate", robot="panda", episode_length=50).unwrapped.episode_length == 50
  # the in-hand start's horizon is the hand-speed cap's, not the robot's (place_plate docstring, "Horizon")
  assert tasks.make("place_plate", robot="panda", obs_mode="paper").unwrapped.episode_length == 100
  assert tasks.make("place_plate", robot="panda", start="in_hand", episode_length=150).unwrapped.episode_length == 150
  p = tasks.make("pour_water", robot="panda").unwrapped
  m = p.mj_model
  weld = m.equality("hold").id
  assert m.eq_obj2id[weld] == m.body("panda_hand").id
  np.testing.assert_allclose(m.eq_data[weld, 3:10], [0, 0, P.GRIP_OFFSET, 0, 1, 0, 0])
  with pytest.raises(ValueError, match="robot: task 'pour_water' supports gripper, panda only, got 'panda_wrist'"):
    tasks.make("pour_water", robot="panda_wrist")
  s = tasks.make("shelve_item", robot="panda").unwrapped
  np.testing.assert_allclose(s.mj_model.geom_size[s.mj_model.geom("cereal_box").id], [0.03, 0.03, 0.08])
  # gripped high enough that the palm clears the box top: grip point + finger length = top + 5 mm
  assert s.grip_dz + P.FINGER_LENGTH == pytest.approx(0.08 + 0.005)
  assert s.grip_closed < tasks.make("shelve_item").unwrapped.grip_closed  # a narrower box, the same squeeze
  np.testing.assert_allclose(s.mj_model.body_pos[s.mj_model.body("panda_link0").id][:2], [-0.35, 0.0])  # mount
  f = tasks.make("add_firewood", robot="panda").unwrapped.mj_model  # beside the counter, facing it
  np.testing.assert_allclose(f.body_pos[f.body("panda_link0").id][:2], [-0.05, -0.45])
  np.testing.assert_allclose(f.body_quat[f.body("panda_link0").id], [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)],
                             atol=1e-6)
  assert tasks.make("ignite_wood").unwrapped.grasp_z == IW.GRASP_Z  # the gripper's palm 2 mm over the lighter
  w = tasks.make("ignite_wood", robot="panda").unwrapped  # shorter fingers grasp higher by the difference
  assert w.grasp_z + P.FINGER_LENGTH == pytest.approx(IW.GRASP_Z + 0.07)
  np.testing.assert_allclose(w.mj_model.body_pos[w.mj_model.body("panda_link0").id][:2], [-0.05, -0.45])
  # the hard scrub presses half steps with the arm (a full step pried the sponge out), full ones with the gripper
  wc = tasks.task_class("wipe_counter")
  assert wc.unsafe_presses.get(tasks.make("wipe_counter", robot="panda").unwrapped.robot_name) == -0.5
  assert wc.unsafe_presses.get(tasks.make("wipe_counter").unwrapped.robot_name) == -1.0
  # fill_bowl: the Panda's 8 cm stroke gets an oblong bowl, 7 cm across the grip (cavity 5.4 cm)
  b = tasks.make("fill_bowl", robot="panda").unwrapped
  mb = b.mj_model
  assert b.bowl_outer == (0.053, 0.035) and b.bowl_inner == pytest.approx((0.045, 0.027))
  np.testing.assert_allclose(mb.geom_size[mb.geom("bowl_bottom").id], [0.053, 0.035, 0.003])
  np.testing.assert_allclose(mb.geom_pos[mb.geom("bowl_py").id][1], 0.031)
  np.testing.assert_allclose(mb.geom_size[mb.geom("bowl_px").id][1], 0.027)
  assert tasks.make("fill_bowl").unwrapped.bowl_outer == (0.053, 0.053)
  # open_single_door: the palm clears the handle, so shorter fingers grasp higher
  assert tasks.make("open_single_door").unwrapped.grip_dz == OD.GRIP_DZ
  assert tasks.make("open_single_door", robot="panda").unwrapped.grip_dz + P.FINGER_LENGTH == pytest.approx(
      OD.GRIP_DZ + 0.07)
  # dishes_to_sink: 12 × 6 cm plate and Ø 6 cm cup, the cup held with the palm 5 mm over its rim, the side
  # mount lowered 12 cm (the basin floor lies 16 cm below the counter); the gripper keeps its dishes
  ds = tasks.make("dishes_to_sink", robot="panda").unwrapped
  md = ds.mj_model
  np.testing.assert_allclose(md.geom_size[md.geom("plate").id], [0.06, 0.03, 0.01])
  np.testing.assert_allclose(md.geom_size[md.geom("cup").id], [0.03, 0.03, 0.035])
  assert ds.cup_grip + P.FINGER_LENGTH == pytest.approx(0.07 + 0.005) and ds.open_gap == 0.07
  np.testing.assert_allclose(md.body_pos[md.body("panda_link0").id], [-0.05, -0.45, -0.12])
  dg = tasks.make("dishes_to_sink").unwrapped
  assert (dg.plate_half, dg.cup_half, dg.cup_grip, dg.plate_grip, dg.open_gap) == (0.06, 0.04, 0.012, 0.004, 0.13)


@pytest.mark.parametrize("name", ["navigate_and_pick"])
def test_mobile_base_tasks_refuse_the_wrist_panda_before_compiling(name):
  # a mobile base (the gripper's slides, the Panda's platform); the refusal names the field and the robots
  assert tasks.describe(name)["robots"] == ["gripper", "panda"]
  with pytest.raises(ValueError, match=f"robot: task '{name}' supports gripper, panda only, got 'panda_wrist'"):
    tasks.make(name, robot="panda_wrist")


def _default_robot_in_fresh_process(value):
  """``tasks.robots.DEFAULT`` and ``make``'s robot in a new interpreter with MJX_DAMAGE_ROBOT unset or set."""
  import subprocess
  import sys

  env = {k: v for k, v in os.environ.items() if k != "MJX_DAMAGE_ROBOT"}
  if value is not None:
    env["MJX_DAMAGE_ROBOT"] = value
  code = ("import tasks; print(tasks.robots.DEFAULT, tasks.default_config('place_plate')['robot'], "
          "tasks.describe('place_plate')['robot'])")
  return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)


def test_the_panda_is_the_default_robot_and_the_variable_chooses_another():
  r = _default_robot_in_fresh_process(None)
  assert r.returncode == 0, r.stderr[-2000:]
  assert r.stdout.split() == ["panda", "panda", "panda"]
  r = _default_robot_in_fresh_process("gripper")
  assert r.returncode == 0 and r.stdout.split() == ["gripper", "gripper", "gripper"], r.stderr[-2000:]
  r = _default_robot_in_fresh_process("ur5")
  assert r.returncode != 0 and "MJX_DAMAGE_ROBOT: unknown robot 'ur5'" in r.stderr


def test_artefacts_name_their_robot():
  """What is stored beside a checkpoint or dataset names the robot it ran; older ones (no robot) ran the
  gripper."""
  env = tasks.make("place_plate", robot="panda")
  assert tasks.recorded_kwargs(env, {"obs_mode": "paper"}) == {"obs_mode": "paper", "robot": "panda"}
  assert tasks.recorded_kwargs(env, {"robot": "panda"}) == {"robot": "panda"}
  assert tasks.stored_kwargs("place_plate", {"obs_mode": "paper"}) == {"obs_mode": "paper", "robot": "gripper"}
  assert tasks.stored_kwargs("place_plate", {"robot": "panda"}) == {"robot": "panda"}
  assert tasks.stored_kwargs("pkg.mod:Env", {"x": 1}) == {"x": 1}  # an env class takes no robot
  assert tasks.recorded_kwargs("place_plate", {}) == {"robot": tasks.robots.DEFAULT}  # a name: the default
  assert tasks.recorded_kwargs("drop", {}) == {}  # a built-in scene has no robot

"""The Panda with its hand pointing forward (tasks.robots.panda.PandaForward): the controller holds that
orientation, the two tasks that reach under an overhang select it and adapt their scenes, every start
pose of theirs is one the reset IK reaches, and their scripted strategies separate (a few episodes
here; 256 per policy in benchmarks/results/scripted_policies_panda_cpu.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tasks
import tasks.place_in_microwave as PIM
import tasks.prepare_coffee as PC
from tasks import rollout
from tasks.robots import panda as P

TASKS = {"place_in_microwave": PIM, "prepare_coffee": PC}


def test_r_forward_is_a_rotation_pointing_the_hand_along_x():
  r = P.R_FORWARD
  np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
  assert np.isclose(np.linalg.det(r), 1.0)
  np.testing.assert_allclose(r[:, 2], [1, 0, 0])  # approach
  np.testing.assert_allclose(r[:, 1], [0, 1, 0])  # fingers close along world y


@pytest.fixture(scope="module", params=sorted(TASKS))
def task(request):
  return request.param, tasks.make(request.param, robot="panda").unwrapped


def test_tasks_select_the_forward_hand_and_adapt_their_scene(task):
  name, t = task
  assert isinstance(t.robot, P.PandaForward)
  np.testing.assert_allclose(t.robot.r_des, P.R_FORWARD)
  m = t.mj_model
  if name == "place_in_microwave":
    np.testing.assert_allclose(m.geom_size[m.geom("dish").id], PIM.PANDA_DISH_HALF, atol=1e-9)
    assert m.geom_size[m.geom("stand").id][2] * 2 == pytest.approx(PIM.STAND_Z)
  else:
    np.testing.assert_allclose(m.geom_size[m.geom("mug").id], PC.PANDA_MUG_HALF, atol=1e-9)
    g = m.geom("guide_l").id
    assert m.geom_pos[g][0] - m.geom_size[g][0] == pytest.approx(PC.PANDA_BAY_FRONT)
  # the gripper keeps its scene
  g = tasks.make(name).unwrapped
  assert not hasattr(g.robot, "r_des")
  assert ("dish" if name == "place_in_microwave" else "mug") in {g.mj_model.geom(i).name for i in range(g.mj_model.ngeom)}


def test_every_start_pose_is_reached_by_the_reset_ik(task):
  # The forward hand cannot reach every point the downward one can: a start range too close to the base
  # left 1 in 5 resets of prepare_coffee with the hand elsewhere (and link 5 in the counter).
  name, t = task
  lo, hi = (np.asarray(v) for v in TASKS[name].PANDA_EEF_START)
  qpos0 = jnp.zeros(t.mj_model.nq)
  q = jax.jit(jax.vmap(lambda k: t.sample_init(k, qpos0)[0]))(jax.random.split(jax.random.PRNGKey(0), 256))
  p, r, _ = jax.vmap(t.robot.kinematics)(q[:, 0:7])
  p, r = np.asarray(p), np.asarray(r)
  assert np.all(p >= lo - 0.002) and np.all(p <= hi + 0.002)
  assert np.max(np.abs(r - P.R_FORWARD[None]), initial=0.0) < 0.02


def test_controller_holds_the_forward_hand_under_random_actions(task):
  # kinematics only: 300 control steps of random actions from 16 reset poses keep the hand within 3° of
  # forward (prepare_coffee ends its workspace short of the base's line for this)
  _, t = task
  qpos0 = jnp.zeros(t.mj_model.nq)
  keys = jax.random.split(jax.random.PRNGKey(1), 16)
  q0 = jax.vmap(lambda k: t.sample_init(k, qpos0)[0][0:7])(keys)

  def run(q, key):
    def step(q, k):
      a = jax.random.uniform(k, (4,), minval=-1.0, maxval=1.0)
      return t.robot.arm_targets(q, a, t.ws_lo, t.ws_hi), None
    q, _ = jax.lax.scan(step, q, jax.random.split(key, 300))
    return t.robot.kinematics(q)[1]

  r = np.asarray(jax.jit(jax.vmap(run))(q0, keys))
  cos = (np.trace(np.einsum("bij,kj->bik", r, P.R_FORWARD), axis1=1, axis2=2) - 1) / 2
  assert np.all(cos > np.cos(np.radians(3.0))), np.degrees(np.arccos(np.clip(cos, -1, 1)))


def test_scripted_strategies_separate_with_the_panda(task):
  name, t = task
  env = tasks.make(name, robot="panda")
  run = rollout.rollout_fn(env, [env.unwrapped.policy("safe"), env.unwrapped.policy("unsafe")], t.episode_length)
  n = 3
  stats = run(jax.random.split(jax.random.PRNGKey(7), 2 * n), jnp.repeat(jnp.arange(2), n))
  m = rollout.summarise(stats)
  done, health = np.asarray(stats.completed), np.asarray(stats.entity_health).min(-1)
  assert np.all(done[:n] == 1) and np.all(health[:n] > 95), (done, health, m)  # safe: completes, intact
  # unsafe: damaged and completing in most (prepare_coffee 94.5 % of 256). With the coupled-finger hand
  # one of these 3 place_in_microwave rams loses the dish from the grip before the back wall (it slides
  # down the pads under the ram's acceleration and comes to rest on the turntable unharmed, not placed);
  # over the benchmark's 256 episodes every unsafe ram completed and damaged the dish.
  assert (health[n:] <= 95).sum() >= n - 1 and done[n:].sum() >= n - 1, (done, health, m)

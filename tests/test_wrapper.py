"""DamageWrapper on Brax's wrappers, a foreign env (once-per-step fallback), and native MuJoCo."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from brax.envs.base import Env, State
from brax.envs.wrappers import training as bw
from mujoco import mjx

import mjx_damage as md
import tasks
from mjx_damage import native, physics
from mjx_damage.backends import native as native_backend
from tasks.drop import DROP_CONFIG, DropEnv, load_scene


@pytest.fixture(scope="module")
def trained_stack():
  """DropEnv under DamageWrapper under Brax's Episode/Vmap/AutoReset wrappers (one compile)."""
  env = md.DamageWrapper(DropEnv(min_height=0.1, max_height=0.3), weight=2.0, health_in_obs=True,
                         terminate_on_destroyed=False)
  wrapped = bw.wrap(env, episode_length=20, action_repeat=1)
  reset, step = jax.jit(wrapped.reset), jax.jit(wrapped.step)
  return env, wrapped, reset, step


def test_info_obs_and_reward_shaping(trained_stack):
  env, wrapped, reset, step = trained_stack
  s = reset(jax.random.split(jax.random.PRNGKey(0), 4))
  assert s.obs.shape == (4, env.observation_size) == (4, 7 + 2)
  np.testing.assert_allclose(s.obs[:, -2:], 1.0)
  assert s.info["link_health"].shape == (4, 2) and s.info["entity_health"].shape == (4, 2)
  for _ in range(19):
    s = step(s, jnp.zeros((4, 0)))
  assert (s.info["entity_health"][:, 0] < 100).all()  # the plates hit the counter
  np.testing.assert_allclose(s.obs[:, -2:], s.info["entity_health"] / 100, rtol=1e-6)
  np.testing.assert_allclose(s.reward, s.info["task_reward"] - 2.0 * s.info["cost"], rtol=1e-5)
  total = s.info["damage"]["mechanical"] + s.info["damage"]["thermal"] + s.info["damage"]["fluid"]
  np.testing.assert_allclose(total, s.info["cost"], rtol=1e-5)


def test_health_restored_after_brax_auto_reset(trained_stack):
  env, wrapped, reset, step = trained_stack
  s = reset(jax.random.split(jax.random.PRNGKey(1), 4))
  for _ in range(20):
    s = step(s, jnp.zeros((4, 0)))
  assert bool(s.done.all()) and bool((s.info["entity_health"][:, 0] < 100).all())
  s = step(s, jnp.zeros((4, 0)))  # first step of the auto-reset episode: plates in the air again
  np.testing.assert_allclose(s.info["entity_health"], 100.0)
  assert float(s.info["damage_episode"]["length"][0]) == 1.0


def test_termination_when_destroyed():
  env = md.DamageWrapper(DropEnv(min_height=0.5, max_height=0.6), terminate_on_destroyed=True)
  s = jax.jit(env.reset)(jax.random.PRNGKey(0))
  step = jax.jit(env.step)
  for _ in range(30):
    s = step(s, jnp.zeros((0,)))
  assert float(s.info["entity_health"][0]) == 0.0 and float(s.done) == 1.0


def test_health_lost_cost_is_the_health_the_links_lost():
  """cost="health_lost": the same physics and health as the default, but each step costs what the links
  lost (≤ 100 per link over the episode), where the models' damage of a plate dropped from 0.5 m is more."""
  def run(cost):
    env = md.DamageWrapper(DropEnv(min_height=0.5, max_height=0.6), weight=2.0, cost=cost)

    def body(s, _):
      n = env.step(s, jnp.zeros((0,)))
      return n, (n.info["cost"], n.info["link_health"], n.reward, n.info["task_reward"])

    s0 = env.reset(jax.random.PRNGKey(0))
    _, out = jax.jit(lambda s: jax.lax.scan(body, s, None, length=30))(s0)
    return np.asarray(s0.info["link_health"]), [np.asarray(x) for x in out]

  h0, (damage, health, _, _) = run("damage")
  h0_lost, (lost, health_lost, reward, task) = run("health_lost")
  np.testing.assert_array_equal(health, health_lost)  # the option changes the cost only
  before = np.concatenate([h0_lost[None], health_lost[:-1]])
  np.testing.assert_allclose(lost, np.maximum(before - health_lost, 0.0).sum(-1), rtol=1e-6, atol=1e-6)
  assert lost.sum() == pytest.approx((100.0 - health_lost[-1]).sum(), rel=1e-5) and lost.sum() <= 100.0 * h0.size
  assert health_lost[-1].min() == 0.0 and lost.sum() == pytest.approx(100.0)  # one plate destroyed, the mug intact
  assert damage.max() > 100.0 and damage.sum() > 1.5 * lost.sum()  # the impact step alone costs more than it can take
  np.testing.assert_allclose(reward, task - 2.0 * lost, rtol=1e-5, atol=1e-5)


def test_cost_signal_is_a_task_setting_and_bad_values_are_refused():
  assert tasks.default_config("place_plate")["cost"] == "damage"
  assert tasks.make("place_plate", cost="health_lost").cost == "health_lost"
  for bad in ("health", "", None, 1):
    with pytest.raises(ValueError, match="^cost: must be one of damage, health_lost"):
      md.DamageWrapper(DropEnv(), cost=bad)
    with pytest.raises(ValueError, match="^cost:"):
      tasks.make("place_plate", cost=bad)


class ForeignDrop(Env):
  """A Brax env that knows nothing about damage: plain mjx.step in a hidden loop."""

  def __init__(self):
    self.mj_model = load_scene()
    self.sys = mjx.put_model(self.mj_model)
    self.q = self.mj_model.jnt_qposadr[self.mj_model.joint("plate").id]

  observation_size = 1
  action_size = 0
  backend = "mjx"

  @property
  def dt(self):
    return 5 * float(self.mj_model.opt.timestep)

  def reset(self, rng):
    d = mjx.make_data(self.sys)
    d = d.replace(qpos=d.qpos.at[self.q + 2].set(0.428 + jax.random.uniform(rng, (), minval=0.0, maxval=0.3)))
    d = mjx.forward(self.sys, d)
    z = jnp.zeros(())
    return State(d, jnp.zeros(1), z, z, {}, {})

  def step(self, state, action):
    d = jax.lax.fori_loop(0, 5, lambda _, d: mjx.step(self.sys, d), state.pipeline_state)
    return state.replace(pipeline_state=d)


def test_foreign_env_falls_back_to_once_per_step():
  env = md.DamageWrapper(ForeignDrop(), DROP_CONFIG)
  assert not env.per_substep
  run = jax.jit(jax.vmap(lambda k: jax.lax.fori_loop(0, 40, lambda _, s: env.step(s, jnp.zeros(0)), env.reset(k))))
  s = run(jax.random.split(jax.random.PRNGKey(0), 8))
  h = np.asarray(s.info["entity_health"])
  assert np.isfinite(h).all() and (h >= 0).all() and (h <= 100).all()
  assert (h[:, 0] < 100).any()  # dropped plates are damaged
  np.testing.assert_allclose(h[:, 1], 100.0)  # the resting mug is not


def test_wrapper_rejects_bad_arguments():
  with pytest.raises(ValueError, match="config: required"):
    md.DamageWrapper(ForeignDrop())
  with pytest.raises(ValueError, match="weight: must be a finite number >= 0"):
    md.DamageWrapper(DropEnv(), weight=-1.0)
  with pytest.raises(ValueError, match="weight"):
    md.DamageWrapper(DropEnv(), weight=float("nan"))
  with pytest.raises(ValueError, match="config: this env already tracks damage"):
    md.DamageWrapper(DropEnv(), DROP_CONFIG)


def _per_link(forces, links, L):
  return np.stack([np.asarray(forces)[np.asarray(links) == l].sum(0) for l in range(L)])


def test_native_and_mjx_extract_the_same_signals():
  """Both backends read the same state alike: per-link net contact force and acceleration."""
  m = load_scene()
  b = md.bind(m, DROP_CONFIG)
  q = m.jnt_qposadr[m.joint("plate").id]
  d = mujoco.MjData(m)
  d.qpos[q + 2] = 0.428 + 0.08
  ds = md.init_state(b)
  for _ in range(60):  # through the impact
    ds = native.substep(b, m, d, ds)
  assert ds.link_health[0] < 100  # an 8 cm drop damages the plate natively too
  mujoco.mj_forward(m, d)
  f_n, l_n = native_backend.contact_forces(b, m, d)
  a_n = native_backend.link_acceleration(b, d)
  mx = mjx.put_model(m)
  dx = jax.jit(mjx.forward)(mx, mjx.put_data(m, d))
  f_x, l_x = md.contact_forces(b, mx, dx)
  a_x = md.link_acceleration(b, dx)
  np.testing.assert_allclose(_per_link(f_n, l_n, 2), _per_link(f_x, l_x, 2), rtol=0.05, atol=0.05)
  np.testing.assert_allclose(a_n, a_x, rtol=0.05, atol=0.05)
  assert np.abs(_per_link(f_n, l_n, 2)[:, 2]).min() > 1.0  # both links really are loaded


# -- action sanitisation ---------------------------------------------------------------------------
def test_sanitise_action_rule():
  a = jnp.array([[0.25, -1.0, 1.0, -0.0, jnp.nan, jnp.inf, -jnp.inf, 1e3, -1e3, 1.0000001]], jnp.float32)
  clean, n = md.wrapper.sanitise_action(a)
  np.testing.assert_array_equal(clean[0], [0.25, -1.0, 1.0, 0.0, 0.0, 1.0, -1.0, 1.0, -1.0, 1.0])
  assert clean.shape == a.shape and n.shape == (1,) and float(n[0]) == 6.0
  # valid entries pass through bitwise (the sign of -0.0 included)
  np.testing.assert_array_equal(np.asarray(clean[0, :4]).view(np.uint32), np.asarray(a[0, :4]).view(np.uint32))
  clean, n = md.wrapper.sanitise_action(jnp.array([jnp.nan, 5.0, -5.0]), lo=0.5, hi=2.0)
  np.testing.assert_array_equal(clean, [0.5, 2.0, 0.5])  # NaN → 0, then clipped into the bounds
  assert float(n) == 3.0


class PushedDrop(DropEnv):
  """DropEnv whose 3-D action is added to the plate's linear velocity (m/s): a NaN action
  reaching the physics would turn the whole state NaN. Records the action it was given."""

  @property
  def action_size(self):
    return 3

  def reset(self, rng):
    s = super().reset(rng)
    return s.replace(info=dict(s.info, seen_action=jnp.zeros(3)))

  def step(self, state, action):
    v = self.mj_model.jnt_dofadr[self.mj_model.joint("plate").id]
    d = state.pipeline_state
    d = d.replace(qvel=d.qvel.at[v : v + 3].add(action))
    s = super().step(state.replace(pipeline_state=d), action)
    return s.replace(info=dict(s.info, seen_action=action))


@pytest.fixture(scope="module")
def pushed_stack():
  """PushedDrop under DamageWrapper under Brax's Episode/Vmap/AutoReset wrappers, 4 envs."""
  env = md.DamageWrapper(PushedDrop(min_height=0.1, max_height=0.3))
  wrapped = bw.wrap(env, episode_length=5, action_repeat=1)
  return env, jax.jit(wrapped.reset), jax.jit(wrapped.step)


def test_extreme_actions_are_sanitised_and_counted(pushed_stack):
  env, reset, step = pushed_stack
  bad = jnp.array([[jnp.nan, 0.5, 0.0], [jnp.inf, -jnp.inf, 1e3], [-1e3, 0.1, jnp.nan], [0.2, -0.3, 0.9]])
  s = reset(jax.random.split(jax.random.PRNGKey(0), 4))
  assert s.metrics["action_sanitised"].shape == (4,) and not s.metrics["action_sanitised"].any()
  for t in range(5):  # one whole episode of extreme actions
    s = step(s, bad)
    np.testing.assert_array_equal(s.info["seen_action"], np.float32([[0, 0.5, 0], [1, -1, 1], [-1, 0.1, 0], [0.2, -0.3, 0.9]]))
    np.testing.assert_array_equal(s.metrics["action_sanitised"], [1, 3, 2, 0])
    np.testing.assert_array_equal(s.info["damage_episode"]["action_sanitised"], [(t + 1) * k for k in (1, 3, 2, 0)])
    assert np.isfinite(np.asarray(s.pipeline_state.qvel)).all() and np.isfinite(np.asarray(s.obs)).all()
  np.testing.assert_array_equal(s.info["episode_metrics"]["action_sanitised"], [5, 15, 10, 0])  # Brax's sums
  s = step(s, jnp.zeros((4, 3)))  # first step of the auto-reset episode: the episode count restarts
  np.testing.assert_array_equal(s.info["damage_episode"]["action_sanitised"], 0.0)
  # the same NaN given to the bare env reaches its physics: what the wrapper prevents
  raw = jax.jit(env.env.step)(jax.jit(env.env.reset)(jax.random.PRNGKey(0)), bad[0])
  assert np.isnan(np.asarray(raw.pipeline_state.qvel)).any()


def test_valid_actions_reach_the_env_bitwise(pushed_stack):
  _, reset, step = pushed_stack
  a = jax.random.uniform(jax.random.PRNGKey(3), (4, 3), minval=-1.0, maxval=1.0).at[0, 0].set(-0.0)
  s = step(reset(jax.random.split(jax.random.PRNGKey(1), 4)), a)
  np.testing.assert_array_equal(np.asarray(s.info["seen_action"]).view(np.uint32), np.asarray(a).view(np.uint32))
  assert not s.metrics["action_sanitised"].any()


def test_wrapper_rejects_bad_action_bounds():
  for bounds in ((1.0, -1.0), (0.0, 0.0), (-1.0, float("inf")), (float("nan"), 1.0), (-1.0,), "ab", (True, 2.0)):
    with pytest.raises(ValueError, match="action_bounds: must be two finite numbers"):
      md.DamageWrapper(DropEnv(), action_bounds=bounds)


class DivergingDrop(PushedDrop):
  """PushedDrop whose physics diverges (NaN velocity) on a step whose first action entry is 1."""

  def step(self, state, action):
    v = self.mj_model.jnt_dofadr[self.mj_model.joint("plate").id]
    d = state.pipeline_state
    d = d.replace(qvel=jnp.where(action[0] >= 1.0, d.qvel.at[v].set(jnp.nan), d.qvel))
    return super().step(state.replace(pipeline_state=d), action)


@pytest.fixture(scope="module")
def diverging():
  env = md.DamageWrapper(DivergingDrop(min_height=0.1, max_height=0.3), weight=2.0, health_in_obs=True)
  return env, jax.jit(env.reset), jax.jit(env.step)


def test_diverged_physics_ends_the_episode_with_finite_outputs(diverging):
  env, reset, step = diverging
  s = reset(jax.random.PRNGKey(0))
  for _ in range(12):  # the plate lands: health below 100, the task reward non-zero
    s = step(s, jnp.zeros(3))
  before = s
  assert float(before.info["entity_health"][0]) < 100.0 and not float(before.done)
  s = step(before, jnp.array([1.0, 0.0, 0.0]))
  assert np.isnan(np.asarray(s.pipeline_state.qvel)).any()  # the physics is left as MJX returned it
  assert float(s.done) == 1.0 and float(s.metrics["physics_diverged"]) == 1.0
  assert float(s.info["damage_episode"]["physics_diverged"]) == 1.0
  np.testing.assert_array_equal(s.obs, before.obs)  # what the learner last saw
  np.testing.assert_array_equal(s.info["link_health"], before.info["link_health"])
  assert float(s.info["cost"]) == 0.0 and all(float(v) == 0.0 for v in s.info["damage"].values())
  assert float(s.reward) == float(before.info["task_reward"]) == float(s.info["task_reward"])
  assert float(s.info["damage_episode"]["cost"]) == float(before.info["damage_episode"]["cost"])
  for k, v in s.metrics.items():
    assert np.isfinite(np.asarray(v)).all(), k
  assert float(before.metrics["physics_diverged"]) == 0.0


def test_diverged_env_is_reset_by_brax_and_others_continue():
  env = md.DamageWrapper(DivergingDrop(min_height=0.1, max_height=0.3))
  wrapped = bw.wrap(env, episode_length=20, action_repeat=1)
  reset, step = jax.jit(wrapped.reset), jax.jit(wrapped.step)
  s = reset(jax.random.split(jax.random.PRNGKey(2), 3))
  s = step(s, jnp.zeros((3, 3)))
  s = step(s, jnp.array([[1.0, 0, 0], [0, 0, 0], [0, 0, 0]]))
  np.testing.assert_array_equal(s.done, [1, 0, 0])
  np.testing.assert_array_equal(s.metrics["physics_diverged"], [1, 0, 0])
  assert np.isfinite(np.asarray(s.pipeline_state.qvel)).all()  # AutoResetWrapper restored env 0
  s = step(s, jnp.zeros((3, 3)))  # env 0 starts a new episode; nothing non-finite anywhere
  np.testing.assert_array_equal(s.info["damage_episode"]["length"], [1, 3, 3])
  np.testing.assert_array_equal(s.info["damage_episode"]["physics_diverged"], 0.0)
  for leaf in jax.tree.leaves((s.obs, s.reward, s.info["entity_health"], s.pipeline_state.qpos)):
    assert np.isfinite(np.asarray(leaf)).all()

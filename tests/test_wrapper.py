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

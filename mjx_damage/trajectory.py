"""Recording a rollout: ``num_envs`` episodes through one compiled step, what frames and plots need.

:func:`rollout` runs ``jit(vmap(policy + env.step))`` from a Python loop over
time (so the step count is not baked into the program and any length reuses
one compilation) and brings back, after each step, only what a frame and the
plots read: positions, health, loads, cost (:class:`Trajectory`). Works on any
:class:`~mjx_damage.wrapper.DamageWrapper` env; knows no task. Given a
:class:`~mjx_damage.native_batch.NativeBatchEnv` it records the same episode with
the physics stepped by native MuJoCo (one native call and two jitted calls per step).
"""

from __future__ import annotations

import collections
import dataclasses
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from mjx_damage import warp_step
from mjx_damage.native_batch import NativeBatchEnv

MODELS = ("mechanical", "thermal", "fluid")  # order of Trajectory.damage's last axis


@dataclasses.dataclass
class Trajectory:
  """A recorded rollout, numpy, time-major: index t = 0 is the reset state, t = k after k steps.

  Per step (leading axes [T + 1, B]): ``qpos``, ``qvel``, ``mocap_pos``, ``mocap_quat``
  (what a frame needs), ``entity_health`` [.., N], ``link_health`` [.., L],
  ``f_par``/``f_perp`` [.., L] (peak contact loads of the step, N), ``cost`` (damage
  evaluated in the step, health points, all links and models; it keeps counting
  after a link's health is clipped at 0), ``damage`` [.., 3] (the same split by
  model, in :data:`MODELS` order), ``temperature`` [.., L] (°C), ``exposure``
  [.., L] (liquid particles touching each link), ``reward``, ``success``, ``done``.
  Per env: ``alpha``, ``beta``, ``mech_threshold`` [B, L] (mechanical
  parameters, for the load plot).

  Scene models, None where the scene has none: ``particles`` f32[T + 1, B, P, 3]
  (liquid particle centres, world frame, m) with ``particle_radius`` (m);
  ``source_temperature`` f32[T + 1, B, S] (each heat source's temperature, °C,
  ambient while off) with ``source_names``, ``source_geom`` i32[S] and ``ambient`` (°C).
  ``modalities``: the damage models the scene can drive ("mechanical" always,
  "thermal" with heat sources, "fluid" with liquid).
  """

  qpos: np.ndarray
  qvel: np.ndarray
  mocap_pos: np.ndarray
  mocap_quat: np.ndarray
  entity_health: np.ndarray
  link_health: np.ndarray
  f_par: np.ndarray
  f_perp: np.ndarray
  cost: np.ndarray
  reward: np.ndarray
  success: np.ndarray
  done: np.ndarray
  alpha: np.ndarray
  beta: np.ndarray
  mech_threshold: np.ndarray
  entity_names: tuple
  link_names: tuple
  link_entity: np.ndarray
  geom_link: np.ndarray
  dt: float
  damage: Optional[np.ndarray] = None
  temperature: Optional[np.ndarray] = None
  exposure: Optional[np.ndarray] = None
  particles: Optional[np.ndarray] = None
  particle_radius: float = 0.0
  source_temperature: Optional[np.ndarray] = None
  source_names: tuple = ()
  source_geom: Optional[np.ndarray] = None
  ambient: float = 22.0
  modalities: tuple = ("mechanical",)

  @property
  def steps(self) -> int:
    return self.qpos.shape[0] - 1

  @property
  def num_envs(self) -> int:
    return self.qpos.shape[1]

  @property
  def time(self) -> np.ndarray:
    """Seconds since reset of each recorded state, f[T + 1]."""
    return np.arange(self.steps + 1) * self.dt


def _record(state, done_before):
  """What one env's state contributes to a :class:`Trajectory` (traced, inside the step)."""
  d, info = state.pipeline_state, state.info
  ds = info["damage_state"]
  live = 1.0 - done_before  # a finished (frozen) env adds no more cost
  sd = ds.step_damage
  extra = {}
  if ds.liquid is not None:
    extra["particles"] = ds.liquid.pos
  if ds.thermal is not None:  # the source's temperature is formed on the host (ambient is static)
    extra["source_on"], extra["source_set"] = ds.thermal.source_on, ds.thermal.source_temperature
  return {
      **extra,
      "damage": jnp.stack([jnp.sum(sd.mechanical), jnp.sum(sd.thermal), jnp.sum(sd.fluid)]) * live,
      "temperature": ds.temperature, "exposure": ds.exposure,
      "qpos": d.qpos, "qvel": d.qvel, "mocap_pos": d.mocap_pos, "mocap_quat": d.mocap_quat,
      "entity_health": info["entity_health"], "link_health": info["link_health"],
      "f_par": ds.f_par * live, "f_perp": ds.f_perp * live, "cost": info["cost"] * live,
      "reward": state.reward * live, "success": state.metrics.get("success", jnp.zeros(())),
      "done": jnp.maximum(done_before, state.done),
  }


class _Programs:
  """The compiled reset and step of (env, policies, num_envs), reused across calls.

  Env b runs ``policies[b % len(policies)]`` (a ``lax.switch`` on b: one program
  for every policy, e.g. a task's safe and unsafe scripts side by side).
  """

  def __init__(self, env, policies: tuple, num_envs: int):
    self.env, self.policies, self.num_envs = env, policies, num_envs

    def policy(state, rng, b):
      if len(policies) == 1:
        return policies[0](state, rng)
      return jax.lax.switch(b % len(policies), policies, state, rng)

    self.policy = policy  # one env's action, shared with _NativePrograms

    def reset_one(reset_key):
      state = env.reset(reset_key)
      z = jnp.zeros((), jnp.float32)
      return state, _record(state, z)

    def step_one(state, act_key, done, b, t):
      nxt = env.step(state, policy(state, jax.random.fold_in(act_key, t), b))
      # An env whose episode ended stays frozen at its final state (as train.evaluate does).
      nxt = warp_step.freeze(done > 0, state, nxt)
      rec = _record(nxt, done)
      return nxt, rec["done"], rec

    self.reset = jax.jit(jax.vmap(reset_one))
    self.step = jax.jit(jax.vmap(step_one, in_axes=(0, 0, 0, 0, None)))


class _NativePrograms:
  """:class:`_Programs` for a :class:`NativeBatchEnv`: the same episode, native physics in between.

  ``reset`` is the MJX one (the backend resets through MJX as well). A step is
  ``decide`` (policy + the env's controls, jitted), the native ``simulate`` and
  ``advance`` (the env's step finished around the native result, frozen where
  done, recorded; jitted), so keys, freezing and records match :class:`_Programs`.
  """

  def __init__(self, env: NativeBatchEnv, policies: tuple, num_envs: int):
    mjx = _Programs(env.env, policies, num_envs)
    self.reset, self.env = mjx.reset, env

    def decide(state, act_key, b, t):
      action = jax.vmap(lambda s, k, i: mjx.policy(s, jax.random.fold_in(k, t), i))(state, act_key, b)
      return action, env.controls_fn(state, action)

    def advance(state, done, action, fields, substeps):
      nxt = env.finish_fn(state, action, fields, substeps)
      keep = lambda new, old: jnp.where(jnp.reshape(done > 0, done.shape + (1,) * (new.ndim - 1)), old, new)
      nxt = jax.tree.map(keep, nxt, state)
      rec = jax.vmap(_record)(nxt, done)
      return nxt, rec["done"], rec

    self.decide = jax.jit(decide)
    self.advance = jax.jit(advance)

  def step(self, state, act_keys, done, index, t):
    action, ctrl = self.decide(state, act_keys, index, t)
    fields, substeps = self.env.simulate(state, ctrl)
    return self.advance(state, done, action, fields, substeps)


_PROGRAMS: "collections.OrderedDict" = collections.OrderedDict()
_MAX_PROGRAMS = 4  # a few (env, policy) pairs stay compiled, e.g. safe and unsafe of one task


def _programs(env, policies: tuple, num_envs) -> _Programs:
  # Keyed by identity; the entry keeps env and policies alive so their ids are not reused.
  key = (id(env), tuple(id(p) for p in policies), num_envs)
  if key in _PROGRAMS:
    _PROGRAMS.move_to_end(key)
  else:
    _PROGRAMS[key] = (_NativePrograms if isinstance(env, NativeBatchEnv) else _Programs)(env, policies, num_envs)
    while len(_PROGRAMS) > _MAX_PROGRAMS:
      _PROGRAMS.popitem(last=False)
  return _PROGRAMS[key]


def positive_int(name, v):
  if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
    raise ValueError(f"{name}: must be a positive integer, got {v!r}")
  return int(v)


def base_env(env):
  """The damage-wrapped env itself: ``env``, or the env a :class:`NativeBatchEnv` steps natively."""
  return env.env if isinstance(env, NativeBatchEnv) else env


def binding_of(env):
  env = base_env(env)  # a native batch records the binding of the env it wraps
  # DamageWrapper's binding (brax wrappers around it forward the attribute); a bare
  # DamageEnv tracks damage but lacks the health/cost summaries that frames and plots read.
  b = getattr(env, "binding", None)
  if b is None:
    raise ValueError("env: not damage-tracked: wrap it in mjx_damage.DamageWrapper (tasks.make does)")
  return b


def mj_model_of(env):
  """The scene's ``mujoco.MjModel`` of a (wrapped) env."""
  e = env
  for _ in range(16):
    m = getattr(e, "mj_model", None)
    if m is not None:
      return m
    if not hasattr(e, "env"):
      break
    e = e.env
  raise ValueError("env: exposes no mj_model (needed to render)")


def rollout(env, policy, *, steps: int, seed: int = 0, num_envs: int = 1,
            same_reset: bool = False) -> Trajectory:
  """Run ``num_envs`` episodes of ``steps`` control steps through one compiled step; record them.

  ``env``: a :class:`~mjx_damage.wrapper.DamageWrapper`-wrapped env (e.g. ``tasks.make``),
  or a :class:`NativeBatchEnv` of ``num_envs`` of them (the same episodes, native physics);
  ``policy(state, rng) -> action`` for one env, or a sequence of such policies:
  env b then runs ``policy[b % len(policy)]``, all in one compiled program.
  Env b's reset and action keys come from ``split(PRNGKey(seed), num_envs)[b]``,
  as in :mod:`train.evaluate`; with ``same_reset`` every env resets from env 0's
  reset key (the same randomised episode, e.g. to compare policies from one start).
  """
  steps, num_envs = positive_int("steps", steps), positive_int("num_envs", num_envs)
  if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
    raise ValueError(f"seed: must be an integer, got {seed!r}")
  policies = tuple(policy) if isinstance(policy, (list, tuple)) else (policy,)
  if not policies or not all(callable(p) for p in policies):
    raise ValueError(f"policy: must be a callable policy(state, rng) -> action or a non-empty sequence of them, "
                     f"got {policy!r}")
  binding = binding_of(env)
  if isinstance(env, NativeBatchEnv) and env.num_envs != num_envs:
    raise ValueError(f"num_envs: the native batch steps {env.num_envs} environments, got num_envs={num_envs}")
  prog = _programs(env, policies, num_envs)
  keys = jax.vmap(jax.random.split)(jax.random.split(jax.random.PRNGKey(int(seed)), num_envs))
  reset_keys, act_keys = keys[:, 0], keys[:, 1]
  if same_reset:
    reset_keys = jnp.broadcast_to(reset_keys[0], reset_keys.shape)
  state, rec = prog.reset(reset_keys)
  index = jnp.arange(num_envs, dtype=jnp.int32)
  done = rec["done"]
  recs = [jax.device_get(rec)]
  for t in range(steps):
    state, done, rec = prog.step(state, act_keys, done, index, t)
    recs.append(jax.device_get(rec))
  stacked = {k: np.stack([np.asarray(r[k]) for r in recs]) for k in recs[0]}
  params = jax.device_get(state.info["damage_state"].params)
  tm, lm = binding.thermal, binding.liquid
  modalities = ("mechanical",) + (("thermal",) if tm is not None else ()) + (("fluid",) if lm is not None else ())
  scene = {"modalities": modalities}
  if "source_on" in stacked:
    on, setp = stacked.pop("source_on"), stacked.pop("source_set")
    scene.update(source_temperature=tm.ambient + on * (setp - tm.ambient), source_names=tuple(tm.source_names),
                 source_geom=np.asarray(tm.source_geom), ambient=float(tm.ambient))
  if "particles" in stacked:
    scene["particle_radius"] = float(lm.radius)
  return Trajectory(
      **stacked, **scene,
      alpha=np.asarray(params.alpha), beta=np.asarray(params.beta),
      mech_threshold=np.asarray(params.mech_threshold),
      entity_names=tuple(binding.entity_names), link_names=tuple(binding.link_names),
      link_entity=np.asarray(binding.link_entity), geom_link=np.asarray(binding.geom_link),
      dt=float(base_env(env).dt),
  )

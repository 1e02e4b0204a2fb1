"""Many environments stepped by native MuJoCo on C threads, damage from the same pure functions.

``NativeBatchEnv(env, spec, num_envs)`` runs a damage-wrapped :class:`~mjx_damage.env.DamageEnv`
(every task of this project) with its physics in :class:`mujoco.batch.Batch`
instead of MJX. One control step of B environments is

1. ``controls_fn`` (jitted, vmapped): the env's own ``step`` traced up to its
   ``physics_step``, which yields the control ``ctrl`` f32[B, nu] (action
   sanitising, the robot's controller — everything before the physics);
2. ``simulate`` (native): the State's simulation state is loaded into the batch's rows, and
   ``n_substeps`` ``mj_step`` calls run per environment on ``nthread`` C
   threads, recording ``sensordata`` at every substep (the damage sensors of
   :mod:`mjx_damage.backends.native_batch`);
3. ``finish_fn`` (jitted, vmapped): the env's ``step`` again, its
   ``physics_step`` replaced by the native result: the new ``mjx.Data`` fields
   and the damage state from :func:`physics.apply_signals` run over the
   recorded substeps (:func:`physics.apply_recorded_substeps`: the models vectorised
   over the substeps, health integrated substep by substep) — the damage functions are untouched, and
   everything after the physics (task reward, success, observation, the
   wrapper's cost/health/metrics) is the env's own code.

``step`` is the three in a row. A loop that also runs a policy can fuse 3, its
own bookkeeping, the policy and 1 of the next step into one jitted call
(:class:`train.evaluate.NativeEvaluator` does): one JAX call and one native
call per control step.

``reset``/``step`` are pure in the ``State`` (the batch holds no state between
calls: every step loads the State's time, qpos, qvel, act, warmstart, ctrl,
mocap and applied forces), so episodes can be frozen, restarted or reordered.
The State's ``pipeline_state`` is an ``mjx.Data`` (float32, as MJX's) whose
state fields and kinematic fields (``xpos``/``xquat``/``xmat``, ``xipos``,
``geom_*``, ``site_*``, ``subtree_com``, ``cvel``, ``qacc``, actuator forces,
the scene's own ``sensordata``) are the native ones, like MJX's one substep
behind the state; other derived fields keep their reset values. The native
state is rounded to float32 at every control step, where the State stores it.

Coupling: damage, health and peak loads feed nothing physical, so evaluating
them after the substeps are stepped loses nothing. The liquid is one-way coupled
too (particles never push bodies): for a scene with liquid the rollout also
records every substep's geom poses and body velocities (``geom_xpos``,
``geom_xmat``, ``cvel``, ``subtree_com``: what :func:`mjx_damage.liquid.advance`
reads, computed by ``mj_step`` before it integrates, as MJX's substep sees
them), and ``finish_fn`` advances the particles substep by substep over them,
each substep's exposure feeding that substep's damage. Temperature is one-way
coupled as well: with heat sources the rollout records every substep's link
COMs and geom poses (``xipos``, ``geom_xpos``, ``geom_xmat``) and a contact
sensor per (link, source) pair, and ``finish_fn`` advances the temperatures
substep by substep with :func:`mjx_damage.temperature.advance` (the sensors
stand in for MJX's contact list), in MJX's order: temperature, liquid, damage.
"""

from __future__ import annotations

import copy
import os
from typing import Optional

import jax
import jax.numpy as jnp
import mujoco
import mujoco.batch
import numpy as np
from brax.envs.base import Wrapper

from mjx_damage import liquid as Lq
from mjx_damage import physics
from mjx_damage import temperature as T
from mjx_damage.backends import native_batch as sensors

# mjx.Data fields the batch fills after every step: state rows, then outputs (derived, one substep behind)
STATE_FIELDS = ("time", "qpos", "qvel", "act", "qacc_warmstart", "ctrl", "qfrc_applied", "xfrc_applied",
                "mocap_pos", "mocap_quat", "userdata")
DERIVED_FIELDS = ("qacc", "xpos", "xquat", "xmat", "xipos", "ximat", "geom_xpos", "geom_xmat", "site_xpos",
                  "site_xmat", "subtree_com", "cvel", "actuator_force", "qfrc_actuator")
DEFAULT_SLOTS = 16
# recorded at every substep for the liquid / the temperature (fields of the substep's forward pass, as MJX's
# substep reads them)
LIQUID_FIELDS = ("geom_xpos", "geom_xmat", "cvel", "subtree_com")
THERMAL_FIELDS = ("xipos", "geom_xpos", "geom_xmat")


def _replace_physics(env, physics_step):
  """A shallow copy of the wrapper stack ``env`` whose innermost env steps physics with ``physics_step``."""
  if isinstance(env, Wrapper):
    outer = copy.copy(env)
    outer.env = _replace_physics(env.env, physics_step)
    return outer
  inner = copy.copy(env)
  inner.physics_step = physics_step
  return inner


def _innermost(env):
  while isinstance(env, Wrapper):
    env = env.env
  return env


def sensor_model(env, spec: mujoco.MjSpec, slots: int = DEFAULT_SLOTS):
  """The env's scene with the damage sensors: (``MjModel``, :class:`SensorLayout`).

  ``spec`` must be the env's scene (same XML); every model array but the
  sensors' (and every ``opt`` field) is then copied from ``env.mj_model``, so
  edits made to the compiled model after loading (robot placement …) carry
  over. Raises ValueError when ``spec`` compiles to a scene of other sizes.
  """
  inner = _innermost(env)
  base: mujoco.MjModel = inner.mj_model
  spec = spec.copy()
  layout = sensors.add_sensors(spec, inner.damage_binding, base, slots)
  model = spec.compile()
  for name in dir(base):
    if name.startswith("_") or name.startswith(("sensor", "name_", "names")):
      continue
    a = getattr(base, name, None)
    if not isinstance(a, np.ndarray):
      continue
    b = getattr(model, name)
    if a.shape != b.shape:
      raise ValueError(f"spec: not this env's scene (model.{name} has shape {b.shape}, the env's {a.shape})")
    b[...] = a
  for opt in dir(base.opt):  # options edited after loading carry over too
    value = getattr(base.opt, opt)
    if not opt.startswith("_") and isinstance(value, (int, float, np.ndarray)):
      setattr(model.opt, opt, value)
  return model, layout


class NativeBatchEnv:
  """``num_envs`` copies of a damage-wrapped env, physics in native MuJoCo on ``nthread`` threads.

  Args:
    env: a :class:`~mjx_damage.wrapper.DamageWrapper` over a :class:`~mjx_damage.env.DamageEnv`
      (possibly under further Brax wrappers).
    spec: the env's scene as a ``mujoco.MjSpec`` (the damage sensors are added to a copy).
    num_envs: B, environments per ``step``.
    nthread: C threads (0: all CPUs).
    slots: contacts per link the sensors keep (the largest).

  ``reset(keys u32[B, 2]) -> State`` and ``step(state, action f32[B, A]) -> State``
  act on batched States with the same fields as ``jit(vmap(env.reset/step))``.
  """

  def __init__(self, env, spec: mujoco.MjSpec, num_envs: int, nthread: int = 0, slots: int = DEFAULT_SLOTS):
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
      raise ValueError(f"num_envs: must be an int >= 1, got {num_envs!r}")
    if isinstance(nthread, bool) or not isinstance(nthread, int) or nthread < 0:
      raise ValueError(f"nthread: must be an int >= 0 (0: all CPUs), got {nthread!r}")
    inner = _innermost(env)
    binding = getattr(inner, "damage_binding", None)
    if binding is None or not hasattr(inner, "physics_step"):
      raise ValueError(f"env: the native backend needs a DamageEnv (damage per substep), got {type(inner).__name__}")
    self.env, self.num_envs = env, num_envs
    self.n_substeps = int(inner.n_substeps)
    self.model, self.layout = sensor_model(env, spec, slots)
    self.base_nsensordata = int(inner.mj_model.nsensordata)
    self.nthread = nthread or os.cpu_count() or 1
    self.batch = mujoco.batch.Batch(self.model, num_envs, nthread=self.nthread)
    self._rows = {f: self.batch.bind(f) for f in STATE_FIELDS if f in mujoco.batch.DATA_FIELDS}
    self._out = {f: self.batch.bind(f) for f in DERIVED_FIELDS}
    self._record = None
    dt = float(inner.mj_model.opt.timestep)
    layout = self.layout
    views = (LIQUID_FIELDS if binding.liquid is not None else ()) + (
        THERMAL_FIELDS if binding.thermal is not None else ())
    self._views = tuple(dict.fromkeys(views))  # the substep's fields the liquid / temperature read
    self._recorded = ("sensordata",) + self._views
    mjx_model = inner.sys

    def pre(state, action):
      box = []

      def capture(d, ds, ctrl):
        box.append(ctrl)
        return d.replace(ctrl=ctrl), ds

      _replace_physics(env, capture).step(state, action)
      return box[0]

    def one_way(d, ds, substeps):
      """ds with temperature and particles advanced over the recorded substeps (MJX's order), and each
      substep's temperature f32[S, L] and exposure f32[S, L]."""
      def one(ds, rec):
        view = d.replace(**{k: rec[k].reshape(getattr(d, k).shape).astype(getattr(d, k).dtype)
                            for k in self._views})
        if binding.thermal is not None:
          ds = T.advance(mjx_model, binding, view, ds, dt, touch=sensors.touching(layout, rec["sensordata"]))
        if binding.liquid is not None:
          ds = Lq.advance(mjx_model, binding, view, ds, dt)
        return ds, (ds.temperature, ds.exposure)

      return jax.lax.scan(one, ds, {k: substeps[k] for k in ("sensordata",) + self._views})

    def damage(d, ds, substeps):
      """ds after the substeps recorded in ``substeps`` (sensordata f32[S, nsensordata], the views' fields)."""
      sensordata = substeps["sensordata"]
      ds = physics.begin_step(ds)
      if self._views:
        ds, (temperature, exposure) = one_way(d, ds, substeps)
      else:  # nothing one-way coupled: temperature and exposure stay as they are over the step
        temperature, exposure = (jnp.broadcast_to(x, (sensordata.shape[0],) + x.shape)
                                 for x in (ds.temperature, ds.exposure))
      signals = jax.vmap(lambda sd, t, e: sensors.link_signals(layout, sd, t, e))(sensordata, temperature, exposure)
      ds = physics.apply_recorded_substeps(ds, signals, dt)
      return ds.replace(link_vel=sensors.link_velocity(layout, sensordata[-1]))

    def post(state, action, fields, substeps):
      def native(d, ds, ctrl):
        new = {k: v.reshape(getattr(d, k).shape).astype(getattr(d, k).dtype) for k, v in fields.items()}
        return d.replace(ctrl=ctrl, **new), damage(d, ds, substeps)

      return _replace_physics(env, native).step(state, action)

    # batched pure halves, for callers that fuse them with their own per-step work (train.evaluate)
    self.controls_fn = jax.vmap(pre)
    self.finish_fn = jax.vmap(post)
    self._reset = jax.jit(jax.vmap(env.reset))
    self._controls = jax.jit(self.controls_fn)
    self._finish = jax.jit(self.finish_fn)

  def reset(self, keys) -> "jax.Array":
    """Batched ``State`` of ``env.reset`` for keys u32[B, 2] (MJX computes the reset, as ``env.reset`` does)."""
    return self._reset(self._check_batch(keys, "keys"))

  def step(self, state, action):
    """One control step of all B environments: native physics, the env's own step around it."""
    action = self._check_batch(action, "action")
    fields, substeps = self.simulate(state, self._controls(state, action))
    return self._finish(state, action, fields, substeps)

  def simulate(self, state, ctrl):
    """The native part of a step: load the State's simulation state, run ``n_substeps`` with ``ctrl`` f32[B, nu].

    Returns (fields: the new ``mjx.Data`` field values, numpy f32[B, ...] by name;
    substeps: what every substep recorded, numpy f32[B, n_substeps, ...] by name — ``sensordata``,
    and with liquid / heat sources :data:`LIQUID_FIELDS` / :data:`THERMAL_FIELDS`) for ``finish_fn``.
    """
    d = state.pipeline_state
    for name, row in self._rows.items():
      if name == "ctrl":
        row[...] = np.asarray(ctrl)
      elif row.size:
        row[...] = np.asarray(getattr(d, name)).reshape(row.shape)
    self._record = self.batch.rollout(self.n_substeps, record=self._recorded, out=self._record)
    fields = {n: np.array(r, np.float32) for n, r in self._rows.items() if r.size and n != "ctrl"}
    fields.update({n: np.asarray(o, np.float32) for n, o in self._out.items() if o.size})
    if self.base_nsensordata:
      fields["sensordata"] = self._record["sensordata"][:, -1, : self.base_nsensordata].astype(np.float32)
    return fields, {k: self._record[k].astype(np.float32) for k in self._recorded}

  def dropped_contacts(self) -> np.ndarray:
    """Contacts the last step's sensors could not keep, per env and substep: i32[B, S, L]."""
    if self._record is None:
      return np.zeros((self.num_envs, self.n_substeps, self.layout.num_links), np.int32)
    return sensors.dropped_contacts(self.layout, self._record["sensordata"])

  def _check_batch(self, x, name):
    x = np.asarray(x) if not isinstance(x, jax.Array) else x
    if x.ndim < 1 or x.shape[0] != self.num_envs:
      raise ValueError(f"{name}: leading axis must be num_envs={self.num_envs}, got shape {tuple(x.shape)}")
    return x

  # the wrapped env's attributes that policies, evaluation and reporting read
  @property
  def unwrapped(self):
    return self.env.unwrapped

  @property
  def entity_names(self):
    return self.env.entity_names

  @property
  def link_names(self):
    return self.env.link_names

  @property
  def action_size(self):
    return self.env.action_size

  @property
  def observation_size(self):
    return self.env.observation_size

  @property
  def episode_length(self) -> Optional[int]:
    return getattr(self.env, "episode_length", None)

"""Damage on a plain ``mujoco.MjData`` (native MuJoCo, one interactive environment).

The same damage functions as the MJX path, fed by the signals the native
backend reads with numpy (:mod:`mjx_damage.backends.native`), and the same
temperature and liquid models (:func:`mjx_damage.temperature.advance`,
:func:`mjx_damage.liquid.advance`) run on the native state::

    binding = mjx_damage.bind(model, config)
    ds = mjx_damage.init_state(binding)
    for _ in range(steps):
        data.ctrl[:] = ...
        ds = mjx_damage.native.step(binding, model, data, ds, n_substeps=6)  # advances `data` in place

``substep`` runs ``mj_forward``, reads contacts/accelerations from that
consistent state, advances temperature and liquid on it, evaluates and
integrates damage, then integrates the physics with the model's integrator —
what ``mujoco.mj_step`` does, with the damage evaluation in between, in the
order :func:`mjx_damage.physics.substep` uses.

The temperature and liquid models are written against ``mjx.Data``'s field
names; :class:`DataView` hands them the same fields of an ``MjData`` (numpy
views, contacts padded to a power of two so one executable serves every
contact count up to it). Everything after the numpy signal read is one
function, jitted once per (binding, model) pair.
"""

from __future__ import annotations

import collections
import types

import jax
import mujoco
import numpy as np
from flax import struct

from mjx_damage import liquid as Lq
from mjx_damage import physics
from mjx_damage import temperature as T
from mjx_damage.backends import native as native_backend
from mjx_damage.binding import Binding
from mjx_damage.kinematics import link_velocity
from mjx_damage.signals import LinkSignals

_CACHE_SIZE = 8  # compiled damage substeps kept (one per scene a process views)


@struct.dataclass
class ContactView:
  """Active contacts of an ``MjData`` in the layout :func:`temperature.touching` reads.

  dist, includemargin: f32[C] m; geom: i32[C, 2] (padding rows: dist +1 m, geom −1, inactive).
  """

  dist: np.ndarray
  includemargin: np.ndarray
  geom: np.ndarray


@struct.dataclass
class DataView:
  """The ``MjData`` fields the temperature, liquid and kinematics models read (after ``mj_forward``).

  xpos f32[nbody, 3], xmat f32[nbody, 9], xipos f32[nbody, 3] m; geom_xpos f32[ngeom, 3];
  geom_xmat f32[ngeom, 9]; cvel f32[nbody, 6]; subtree_com f32[nbody, 3]; contact: :class:`ContactView`.
  """

  xpos: np.ndarray
  xmat: np.ndarray
  xipos: np.ndarray
  geom_xpos: np.ndarray
  geom_xmat: np.ndarray
  cvel: np.ndarray
  subtree_com: np.ndarray
  contact: ContactView

  @property
  def _impl(self):
    # mjx.Data keeps contacts under d._impl.contact (the MJX-JAX layout temperature.touching reads)
    return self


def _padded_size(n: int) -> int:
  return max(16, 1 << int(np.ceil(np.log2(max(n, 1)))))


def data_view(data: mujoco.MjData) -> DataView:
  """:class:`DataView` of ``data`` (float32 copies; contacts padded to a power of two, at least 16)."""
  n = data.ncon
  size = _padded_size(n)
  dist = np.ones((size,), np.float32)
  margin = np.zeros((size,), np.float32)
  geom = np.full((size, 2), -1, np.int32)
  if n:
    con = data.contact
    dist[:n], margin[:n], geom[:n] = con.dist[:n], con.includemargin[:n], con.geom[:n]
  f = lambda a: np.asarray(a, np.float32)
  return DataView(xpos=f(data.xpos), xmat=f(data.xmat), xipos=f(data.xipos), geom_xpos=f(data.geom_xpos),
                  geom_xmat=f(data.geom_xmat), cvel=f(data.cvel), subtree_com=f(data.subtree_com),
                  contact=ContactView(dist, margin, geom))


def _damage_substep(binding: Binding, model: mujoco.MjModel):
  """``fn(ds, view, signals, dt) -> ds``: temperature, liquid, damage, link velocities (jitted)."""
  # the static model fields the temperature/liquid models read (m.geom_size, m.opt.gravity)
  m = types.SimpleNamespace(geom_size=np.asarray(model.geom_size, np.float32),
                            opt=types.SimpleNamespace(gravity=np.asarray(model.opt.gravity, np.float32)))

  def fn(ds: physics.DamageState, view: DataView, signals: LinkSignals, dt) -> physics.DamageState:
    ds = T.advance(m, binding, view, ds, dt)
    ds = Lq.advance(m, binding, view, ds, dt)
    ds = physics.apply_signals(ds, signals.replace(temperature=ds.temperature, exposure=ds.exposure), dt)
    return ds.replace(link_vel=link_velocity(binding, view))

  return jax.jit(fn)


_compiled: collections.OrderedDict = collections.OrderedDict()  # (id(binding), id(model)) → (binding, model, fn)


def damage_substep_fn(binding: Binding, model: mujoco.MjModel):
  """The jitted damage part of :func:`substep` for this scene (built once, then reused)."""
  key = (id(binding), id(model))
  hit = _compiled.get(key)
  if hit is not None and hit[0] is binding and hit[1] is model:
    _compiled.move_to_end(key)
    return hit[2]
  fn = _damage_substep(binding, model)
  _compiled[key] = (binding, model, fn)  # holding both keeps their ids from being reused
  while len(_compiled) > _CACHE_SIZE:
    _compiled.popitem(last=False)
  return fn


_begin = jax.jit(physics.begin_step)


def substep(binding: Binding, model: mujoco.MjModel, data: mujoco.MjData, ds: physics.DamageState):
  """Advance ``data`` by one physics step in place; return the new damage state."""
  mujoco.mj_forward(model, data)
  signals = native_backend.link_signals(binding, model, data, ds.temperature, ds.exposure)
  dt = np.float32(model.opt.timestep)
  ds = damage_substep_fn(binding, model)(ds, data_view(data), signals, dt)
  integrator = model.opt.integrator
  if integrator == mujoco.mjtIntegrator.mjINT_RK4:
    mujoco.mj_RungeKutta(model, data, 4)
  elif integrator in (mujoco.mjtIntegrator.mjINT_IMPLICIT, mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
    mujoco.mj_implicit(model, data)
  else:
    mujoco.mj_Euler(model, data)
  return ds


def step(binding: Binding, model: mujoco.MjModel, data: mujoco.MjData, ds: physics.DamageState,
         n_substeps: int = 1) -> physics.DamageState:
  """One control step: ``n_substeps`` :func:`substep` calls, the step accumulators reset first
  (as :func:`mjx_damage.physics.step`), so ``ds.step_damage`` afterwards describes this step."""
  ds = _begin(ds)
  for _ in range(n_substeps):  # the physics runs on the host between damage evaluations
    ds = substep(binding, model, data, ds)
  return ds

"""Damage on a plain ``mujoco.MjData`` (native MuJoCo, one interactive environment).

The same damage functions as the MJX path, fed by the signals the native
backend reads with numpy (:mod:`mjx_damage.backends.native`)::

    binding = mjx_damage.bind(model, config)
    ds = mjx_damage.init_state(binding)
    for _ in range(steps):
        data.ctrl[:] = ...
        ds = mjx_damage.native.substep(binding, model, data, ds)   # advances `data` in place

``substep`` runs ``mj_forward``, reads contacts/accelerations from that
consistent state, evaluates and integrates damage, then integrates the physics
with the model's integrator — exactly what ``mujoco.mj_step`` does, with the
damage evaluation in between. Temperature and liquid models are MJX-only.
"""

from __future__ import annotations

import jax
import mujoco

from mjx_damage import physics
from mjx_damage.backends import native as native_backend
from mjx_damage.binding import Binding


_apply = jax.jit(physics.apply_signals)


def substep(binding: Binding, model: mujoco.MjModel, data: mujoco.MjData, ds: physics.DamageState):
  """Advance ``data`` by one physics step in place; return the new damage state."""
  mujoco.mj_forward(model, data)
  signals = native_backend.link_signals(binding, model, data, ds.temperature, ds.exposure)
  ds = _apply(ds, signals, float(model.opt.timestep))
  integrator = model.opt.integrator
  if integrator == mujoco.mjtIntegrator.mjINT_RK4:
    mujoco.mj_RungeKutta(model, data, 4)
  elif integrator in (mujoco.mjtIntegrator.mjINT_IMPLICIT, mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
    mujoco.mj_implicit(model, data)
  else:
    mujoco.mj_Euler(model, data)
  return ds

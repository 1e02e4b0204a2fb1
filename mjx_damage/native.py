"""Damage on a plain ``mujoco.MjData`` (native MuJoCo, one interactive environment).

The same damage functions as the MJX path, fed by signals read from native
MuJoCo with numpy (vectorised over contacts, no Python loop over them)::

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

import functools

import jax
import mujoco
import numpy as np

from mjx_damage import physics
from mjx_damage.binding import Binding
from mjx_damage.signals import LinkSignals


def contact_forces(binding: Binding, model: mujoco.MjModel, data: mujoco.MjData):
  """World-frame forces on tracked links from the active contacts of ``data``.

  Returns (forces f32[2C, 3] N, force_link i32[2C]) as :func:`mjx_damage.contact_forces`.
  """
  n = data.ncon
  if n == 0:
    return np.zeros((0, 3), np.float32), np.zeros((0,), np.int32)
  con = data.contact
  dim, adr = con.dim[:n], con.efc_address[:n]
  local = np.zeros((n, 3))
  f = data.efc_force
  for dm in np.unique(dim):  # at most four contact dimensionalities
    sel = np.nonzero((dim == dm) & (adr >= 0))[0]
    if model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC or dm == 1:
      k = min(int(dm), 3)
      local[sel, :k] = f[adr[sel, None] + np.arange(k)]
    else:  # pyramidal: 2(dim−1) edge forces; normal = their sum, tangent = weighted differences
      edges = f[adr[sel, None] + np.arange(2 * (dm - 1))]
      local[sel, 0] = edges.sum(1)
      t = min(int(dm) - 1, 2)
      local[sel, 1 : 1 + t] = (edges[:, 0 : 2 * t : 2] - edges[:, 1 : 2 * t : 2]) * con.friction[sel, :t]
  active = (con.dist[:n] - con.includemargin[:n] < 0) & (adr >= 0)
  world = np.einsum("kij,ki->kj", con.frame[:n].reshape(n, 3, 3), local) * active[:, None]
  link0 = binding.geom_link[con.geom[:n, 0]]
  link1 = binding.geom_link[con.geom[:n, 1]]
  return (np.concatenate([world, -world]).astype(np.float32), np.concatenate([link1, link0]).astype(np.int32))


def link_acceleration(binding: Binding, data: mujoco.MjData) -> np.ndarray:
  """Kinematic linear COM acceleration of each tracked link, f32[L, 3] (after ``mj_forward``)."""
  s = data.cdof * data.qacc[:, None] + data.cdof_dot * data.qvel[:, None]
  cacc = binding.link_dofs @ s
  body = binding.link_body
  r = data.xipos[body] - data.subtree_com[binding.link_root]
  cvel = data.cvel[body]
  w, v = cvel[:, :3], cvel[:, 3:] + np.cross(cvel[:, :3], r)
  return (cacc[:, 3:] + np.cross(cacc[:, :3], r) + np.cross(w, v)).astype(np.float32)


def _pad(forces, links, size):
  out_f = np.zeros((size, 3), np.float32)
  out_l = np.full((size,), -1, np.int32)
  out_f[: len(forces)], out_l[: len(links)] = forces, links
  return out_f, out_l


@functools.partial(jax.jit, static_argnames=())
def _apply(ds, forces, force_link, link_acc, dt):
  sig = LinkSignals(forces, force_link, link_acc, ds.temperature, ds.exposure)
  return physics.apply_signals(ds, sig, dt)


def substep(binding: Binding, model: mujoco.MjModel, data: mujoco.MjData, ds: physics.DamageState):
  """Advance ``data`` by one physics step in place; return the new damage state."""
  mujoco.mj_forward(model, data)
  forces, links = contact_forces(binding, model, data)
  # pad to a power of two so the jitted update compiles for a few sizes only
  size = max(16, 1 << int(np.ceil(np.log2(max(len(links), 1)))))
  forces, links = _pad(forces, links, size)
  ds = _apply(ds, forces, links, link_acceleration(binding, data), float(model.opt.timestep))
  integrator = model.opt.integrator
  if integrator == mujoco.mjtIntegrator.mjINT_RK4:
    mujoco.mj_RungeKutta(model, data, 4)
  elif integrator in (mujoco.mjtIntegrator.mjINT_IMPLICIT, mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
    mujoco.mj_implicit(model, data)
  else:
    mujoco.mj_Euler(model, data)
  return ds

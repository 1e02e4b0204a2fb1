"""Native MuJoCo backend: link signals from a plain ``mujoco.MjData``, with numpy.

Native MuJoCo keeps active contacts in ``data.contact[:ncon]`` with each
contact's constraint rows at ``efc_address`` in ``efc_force`` (elliptic cones:
contact-frame components; pyramidal: 2(dim−1) edge forces). Active joint
limits are rows with ``efc_type == mjCNSTR_LIMIT_JOINT`` and ``efc_id`` = the
joint (:func:`limit_forces`). Vectorised over contacts and rows, no Python
loop over them. The step that drives MuJoCo and applies the
damage is :func:`mjx_damage.native.substep`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

from mjx_damage.joint_limits import joint_link_forces
from mjx_damage.signals import LinkSignals

if TYPE_CHECKING:  # annotation only
  from mjx_damage.binding import Binding


def contact_forces(binding: "Binding", model: mujoco.MjModel, data: mujoco.MjData):
  """World-frame forces on tracked links from the active contacts of ``data``.

  Returns (forces f32[2C, 3] N, force_link i32[2C]) as :func:`mjx_damage.backends.mjx_jax.contact_forces`.
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


def limit_forces(binding: "Binding", model: mujoco.MjModel, data: mujoco.MjData):
  """World-frame forces on tracked links from the active limits of ``binding.limit_joint`` (f32[J, 3] N, i32[J]).

  Same quantities as :func:`mjx_damage.backends.mjx_jax.limit_forces`; a joint inside its range gives 0.
  """
  jnt = binding.limit_joint
  if jnt.size == 0:
    return np.zeros((0, 3), np.float32), np.zeros((0,), np.int32)
  n = data.nefc
  rows = np.nonzero(data.efc_type[:n] == mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)[0]
  by_joint = np.zeros(model.njnt)
  by_joint[data.efc_id[rows]] = data.efc_force[rows]
  forces = joint_link_forces(jnt, binding.limit_hinge, model, data, by_joint[jnt])
  return np.asarray(forces, np.float32), binding.limit_link.astype(np.int32)


def link_acceleration(binding: "Binding", data: mujoco.MjData) -> np.ndarray:
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


def link_signals(binding: "Binding", model: mujoco.MjModel, data: mujoco.MjData, temperature,
                 exposure) -> LinkSignals:
  """:class:`LinkSignals` of ``data`` after ``mj_forward`` (numpy arrays).

  Contact rows are padded with untracked (−1) zero forces to a power of two
  (at least 16), so a jitted consumer compiles for a few sizes only.
  """
  fc, lc = contact_forces(binding, model, data)
  fl, ll = limit_forces(binding, model, data)
  forces, links = np.concatenate([fc, fl]), np.concatenate([lc, ll])
  size = max(16, 1 << int(np.ceil(np.log2(max(len(links), 1)))))
  forces, links = _pad(forces, links, size)
  return LinkSignals(forces, links, link_acceleration(binding, data), temperature, exposure)

"""MJX-JAX backend: link signals from the contact layout of MuJoCo MJX's JAX implementation.

MJX (JAX) stores contacts in ``d._impl.contact`` grouped by dimensionality
(``condim`` 1, 3, 4, 6), with the constraint forces in ``efc_force``;
``mujoco.mjx._src.support.contact_force_dim`` turns one group's constraint
forces into contact-frame forces. That layout is private to this
implementation (MuJoCo Warp and native MuJoCo lay contacts out differently),
so it is read here and nowhere else; the geom → link indices it needs are the
backend-independent :class:`mjx_damage.binding.Binding`. Joint-limit rows
(``ConstraintType.LIMIT_JOINT``) have a static place in ``efc_force`` too: one
row per limited joint, ball joints first, then hinges and slides in joint order
(``constraint._efc_limit_slide_hinge``); :func:`limit_forces` reads the rows of
the joints the config names (:mod:`mjx_damage.joint_limits`).

Pure and jittable: one environment's ``mjx.Data`` in, arrays out (vmap for a batch).
:func:`link_signals` is the backend's whole output, what
:func:`mjx_damage.physics.apply_signals` consumes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx
from mujoco.mjx._src import constraint as mjx_constraint
from mujoco.mjx._src import support as mjx_support
from mujoco.mjx._src.types import ConstraintType, JointType

from mjx_damage.joint_limits import joint_link_forces
from mjx_damage.kinematics import link_acceleration
from mjx_damage.signals import LinkSignals

if TYPE_CHECKING:  # annotation only
  from mjx_damage.binding import Binding


def contact_forces(binding: Binding, m: mjx.Model, d: mjx.Data) -> tuple[jax.Array, jax.Array]:
  """World-frame contact forces on tracked links from one environment's active contacts (MJX-JAX layout).

  Each contact loads both of its bodies, equal and opposite: the contact-frame
  force is what ``geom[0]`` exerts on ``geom[1]``.

  Returns:
    forces: f32[2C, 3] N (C = contact slots of the model; inactive slots give 0).
    force_link: i32[2C] link each force acts on, −1 for untracked bodies.
  """
  con = d._impl.contact
  if con.dist.shape[0] == 0:
    return jnp.zeros((0, 3), jnp.float32), jnp.zeros((0,), jnp.int32)
  forces, rows = [], []
  for dim in sorted(set(np.asarray(con.dim).tolist())):
    f, idx = mjx_support.contact_force_dim(m, d, dim)
    forces.append(f[:, :3])
    rows.append(idx)
  rows = np.concatenate(rows)
  local = jnp.concatenate(forces)
  frame = con.frame[rows].reshape(-1, 3, 3)  # rows: normal, tangent1, tangent2
  world = jnp.einsum("kij,ki->kj", frame, local)
  active = (con.dist[rows] - con.includemargin[rows]) < 0
  world = jnp.where(active[:, None], world, 0.0)
  geom = con.geom[rows]
  geom_link = jnp.asarray(binding.geom_link)
  link0 = jnp.where(geom[:, 0] >= 0, geom_link[geom[:, 0]], -1)
  link1 = jnp.where(geom[:, 1] >= 0, geom_link[geom[:, 1]], -1)
  return jnp.concatenate([world, -world]), jnp.concatenate([link1, link0])


def _limit_rows(m: mjx.Model) -> np.ndarray:
  """i64[njnt]: the ``efc_force`` row of each limited joint's limit constraint, −1 for others (static)."""
  types = np.asarray(mjx_constraint.make_efc_type(m))
  start = np.nonzero(types == ConstraintType.LIMIT_JOINT)[0]
  limited = np.asarray(m.jnt_limited).astype(bool)
  ball = np.nonzero((m.jnt_type == JointType.BALL) & limited)[0]
  slide_hinge = np.nonzero(np.isin(m.jnt_type, (JointType.SLIDE, JointType.HINGE)) & limited)[0]
  order = np.concatenate([ball, slide_hinge])
  rows = np.full((m.njnt,), -1, np.int64)
  if start.size == order.size:  # limits disabled (DisableBit.LIMIT): no rows at all
    rows[order] = start
  return rows


def limit_forces(binding: Binding, m: mjx.Model, d: mjx.Data) -> tuple[jax.Array, jax.Array]:
  """World-frame forces on tracked links from the limits of the joints in ``binding.limit_joint``.

  Returns:
    forces: f32[J, 3] N, zero for a joint inside its range.
    force_link: i32[J] the child link of each joint.
  """
  jnt = binding.limit_joint
  if jnt.size == 0:
    return jnp.zeros((0, 3), jnp.float32), jnp.zeros((0,), jnp.int32)
  rows = _limit_rows(m)[jnt]
  if (rows < 0).any():
    return jnp.zeros((jnt.size, 3), jnp.float32), jnp.asarray(binding.limit_link)
  q = d.qpos[m.jnt_qposadr[jnt]]
  active = jnp.minimum(q - m.jnt_range[jnt, 0], m.jnt_range[jnt, 1] - q) - m.jnt_margin[jnt] < 0
  row_force = jnp.where(active, d._impl.efc_force[rows], 0.0)
  return joint_link_forces(jnt, binding.limit_hinge, m, d, row_force), jnp.asarray(binding.limit_link)


def applied_forces(binding: Binding, m: mjx.Model, d: mjx.Data) -> tuple[jax.Array, jax.Array]:
  """Every force the mechanical model sees: contacts (f32[2C, 3]) then joint limits (f32[J, 3]), with links."""
  fc, lc = contact_forces(binding, m, d)
  fl, ll = limit_forces(binding, m, d)
  return jnp.concatenate([fc, fl]), jnp.concatenate([lc, ll])


def link_signals(binding: "Binding", m: mjx.Model, d: mjx.Data, temperature: jax.Array,
                 exposure: jax.Array) -> LinkSignals:
  """:class:`LinkSignals` of one environment whose ``d`` has just been through ``mjx.forward``.

  ``temperature`` f32[L] °C and ``exposure`` f32[L] particles come from the
  core's temperature and liquid models (the simulator has neither).
  """
  forces, force_link = applied_forces(binding, m, d)
  return LinkSignals(
      forces=forces,
      force_link=force_link,
      link_acc=link_acceleration(binding, d),
      temperature=temperature,
      exposure=exposure,
  )

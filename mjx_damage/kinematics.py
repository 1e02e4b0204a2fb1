"""Link kinematics from MJX data: each tracked link's COM velocity and acceleration, world frame.

Pure and jittable; they read one environment's ``mjx.Data`` kinematic fields
(``cdof``, ``cdof_dot``, ``cvel``, ``qacc``, ``xipos``, ``subtree_com``: the
public ``mjx.Data`` interface, not an implementation's private layout) and the
static indices of a :class:`~mjx_damage.binding.Binding` (``link_body``,
``link_root``, ``link_dofs``). Vmap them for a batch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from mujoco import mjx

if TYPE_CHECKING:  # annotation only: binding imports this module
  from mjx_damage.binding import Binding


def _point_motion(binding: "Binding", cvel6: jax.Array, cacc6: jax.Array, d: mjx.Data):
  """Velocity and classical acceleration of each link COM from com-based spatial vectors."""
  body = binding.link_body
  r = d.xipos[body] - d.subtree_com[binding.link_root]
  w, v0 = cvel6[:, :3], cvel6[:, 3:]
  v = v0 + jnp.cross(w, r)
  if cacc6 is None:
    return v, None
  alpha, a0 = cacc6[:, :3], cacc6[:, 3:]
  # spatial → classical acceleration: add ω × v (as mj_objectAcceleration does)
  return v, a0 + jnp.cross(alpha, r) + jnp.cross(w, v)


def link_acceleration(binding: "Binding", d: mjx.Data) -> jax.Array:
  """Kinematic linear acceleration of each tracked link's COM, f32[L, 3], m/s², world frame.

  Reads the state of ``d`` after ``mjx.forward`` and before integration (so
  ``qacc`` is the acceleration the current contact forces produce). Gravity is
  not part of it: a body at rest reads 0, a body in free fall reads g.
  """
  if binding.num_links == 0 or d.qvel.shape[-1] == 0:
    return jnp.zeros((binding.num_links, 3), jnp.float32)
  mask = jnp.asarray(binding.link_dofs)
  s = d.cdof * d.qacc[:, None] + d.cdof_dot * d.qvel[:, None]  # [nv, 6]
  cacc = mask @ s
  cvel = d.cvel[binding.link_body]
  return _point_motion(binding, cvel, cacc, d)[1]


def link_velocity(binding: "Binding", d: mjx.Data) -> jax.Array:
  """Linear velocity of each tracked link's COM, f32[L, 3], m/s (as of the last forward pass)."""
  if binding.num_links == 0:
    return jnp.zeros((0, 3), jnp.float32)
  return _point_motion(binding, d.cvel[binding.link_body], None, d)[0]

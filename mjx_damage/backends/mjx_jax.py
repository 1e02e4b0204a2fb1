"""MJX-JAX backend: link signals from the contact layout of MuJoCo MJX's JAX implementation.

MJX (JAX) stores contacts in ``d._impl.contact`` grouped by dimensionality
(``condim`` 1, 3, 4, 6), with the constraint forces in ``efc_force``;
``mujoco.mjx._src.support.contact_force_dim`` turns one group's constraint
forces into contact-frame forces. That layout is private to this
implementation (MuJoCo Warp and native MuJoCo lay contacts out differently),
so it is read here and nowhere else; the geom → link indices it needs are the
backend-independent :class:`mjx_damage.binding.Binding`.

Pure and jittable: one environment's ``mjx.Data`` in, arrays out (vmap for a batch).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx
from mujoco.mjx._src import support as mjx_support

if TYPE_CHECKING:  # annotation only: the backend reads binding.geom_link, nothing else
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

"""MuJoCo Warp backend: link signals of a whole batch from the contact layout of MJX's Warp implementation.

MJX's Warp implementation (``mjx.put_model(m, impl="warp")``; needs the optional
``warp-lang``) keeps the contacts of every world of a batch in ONE list: the
``d._impl.contact__*`` arrays have ``naconmax`` slots, the first ``nacon[0]``
in use, in no particular order, each slot naming its world (``contact__worldid``)
and its constraint rows in that world's ``efc__force`` (``contact__efc_address``,
with ``efc__force`` f32[B, njmax]). So, unlike :mod:`mjx_damage.backends.mjx_jax`,
this backend reads a batch, not one environment: it decodes every contact's
force, then sorts the contacts by world into ``slots`` fixed places per world,
and the per-environment damage functions run vmapped over the result, untouched.

Contact force of one contact (what ``mj_contactForce`` computes), frame rows
normal, tangent 1, tangent 2:

* elliptic cone: the first ``min(dim, 3)`` rows as they are;
* pyramidal cone: normal = the sum of the 2(dim − 1) pyramid rows (dim 1: the
  one row), tangent i = (row 2i − row 2i+1) · μ_i.

The same places give the temperature model its link–source contacts
(:func:`mjx_damage.temperature.touching_pairs`).

Joint limits: Warp gives a row only to an active limit, at a place that varies
from step to step, so :func:`limit_forces` finds each tracked joint's row by
its type (``efc__type == mjCNSTR_LIMIT_JOINT``) and id (``efc__id`` = the
joint) among the world's ``nefc`` rows, as the native backend does, and
:mod:`mjx_damage.joint_limits` turns it into a force on the child link.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct
from mujoco import mjx

from mjx_damage.joint_limits import joint_link_forces
from mjx_damage.kinematics import link_acceleration, link_velocity
from mjx_damage.signals import LinkSignals

if TYPE_CHECKING:  # annotation only
  from mjx_damage.binding import Binding


def _local_forces(m: mjx.Model, d: mjx.Data) -> jax.Array:
  """f32[N, 3] contact-frame force (normal, tangent 1, tangent 2) of every contact slot, N.

  ``geom[0]`` exerts it on ``geom[1]``; slots not in use give whatever their rows hold (masked later).
  """
  con = d._impl
  adr = con.contact__efc_address  # i32[N, R]: the contact's rows in its world's efc_force, −1 past its last
  efc = con.efc__force  # f32[B, njmax]
  world = jnp.clip(con.contact__worldid, 0, efc.shape[0] - 1)
  rows = jnp.where(adr >= 0, efc[world[:, None], jnp.maximum(adr, 0)], 0.0)  # f32[N, R]
  dim = con.contact__dim
  if int(m.opt.cone) == int(mujoco.mjtCone.mjCONE_ELLIPTIC):
    k = np.arange(3)
    return jnp.where(k[None, :] < dim[:, None], rows[:, :3], 0.0)
  npyr = jnp.where(dim > 1, 2 * (dim - 1), 1)
  r = np.arange(rows.shape[1])
  normal = jnp.sum(jnp.where(r[None, :] < npyr[:, None], rows, 0.0), axis=1)
  mu = con.contact__friction
  tangents = []
  for i in range(2):  # tangents 1 and 2: what the mechanical model reads
    if 2 * i + 1 < rows.shape[1]:
      t = (rows[:, 2 * i] - rows[:, 2 * i + 1]) * mu[:, i]
      tangents.append(jnp.where(dim > i + 1, t, 0.0))
    else:
      tangents.append(jnp.zeros_like(normal))
  return jnp.stack([normal] + tangents, axis=-1)


@struct.dataclass
class WorldContacts:
  """The contacts of every world of a batch in ``S`` fixed places per world (leading axis B on each).

  force:    f32[B, S, 3] world-frame force ``geom[0]`` exerts on ``geom[1]``, N (0: inactive or empty)
  geom:     i32[B, S, 2] the contact's geoms (−1: empty place)
  active:   bool[B, S] an active contact (``dist − includemargin < 0``)
  overflow: i32[B] the world's contacts beyond S (dropped)
  """

  force: jax.Array
  geom: jax.Array
  active: jax.Array
  overflow: jax.Array


def world_contacts(m: mjx.Model, d: mjx.Data, slots: int) -> WorldContacts:
  """Warp's one contact list sorted by world into ``slots`` places per world.

  Args:
    d: a batch's ``mjx.Data`` (Warp implementation) after a forward pass, leading axis B on its public fields.
    slots: S, contact places per world (static); a world's contacts beyond S are dropped and counted.
  """
  con = d._impl
  B = d.qpos.shape[0]
  N = con.contact__dist.shape[0]
  frame = con.contact__frame.reshape(N, 3, 3)  # rows: normal, tangent 1, tangent 2
  world_f = jnp.einsum("kij,ki->kj", frame, _local_forces(m, d))
  active = (con.contact__dist - con.contact__includemargin) < 0
  world_f = jnp.where(active[:, None], world_f, 0.0)

  # sort the places in use by world; each contact's place is its rank among its world's contacts
  in_use = jnp.arange(N) < con.nacon[0]
  key = jnp.where(in_use, con.contact__worldid, B)
  order = jnp.argsort(key, stable=True)
  sk = key[order]
  worlds = jnp.arange(B)
  start = jnp.searchsorted(sk, worlds, side="left")
  count = jnp.searchsorted(sk, worlds, side="right") - start
  rank = jnp.arange(N) - start[jnp.clip(sk, 0, B - 1)]
  row = jnp.where((sk < B) & (rank < slots), sk, B)  # B: out of range, dropped by the scatter

  def place(x, fill):
    out = jnp.full((B, slots) + x.shape[1:], fill, x.dtype)
    return out.at[row, rank].set(x[order], mode="drop")

  return WorldContacts(force=place(world_f.astype(jnp.float32), 0.0),
                       geom=place(con.contact__geom.astype(jnp.int32), -1),
                       active=place(active & in_use, False),
                       overflow=jnp.maximum(count - slots, 0).astype(jnp.int32))


def contact_forces(binding: "Binding", m: mjx.Model, d: mjx.Data, slots: int):
  """World-frame contact forces on tracked links of every world, in ``slots`` places per world.

  Each contact loads both of its bodies, equal and opposite (as in :mod:`mjx_damage.backends.mjx_jax`).

  Returns:
    forces: f32[B, 2S, 3] N; force_link: i32[B, 2S] (−1: untracked or empty); overflow: i32[B] contacts dropped.
  """
  wc = world_contacts(m, d, slots)
  return (*_link_forces(binding, wc), wc.overflow)


def _link_forces(binding: "Binding", wc: WorldContacts):
  geom_link = jnp.asarray(binding.geom_link)
  g = wc.geom
  link0 = jnp.where(g[..., 0] >= 0, geom_link[jnp.maximum(g[..., 0], 0)], -1)
  link1 = jnp.where(g[..., 1] >= 0, geom_link[jnp.maximum(g[..., 1], 0)], -1)
  return jnp.concatenate([wc.force, -wc.force], axis=1), jnp.concatenate([link1, link0], axis=1).astype(jnp.int32)


def public(d: mjx.Data) -> mjx.Data:
  """``d`` without the implementation's arrays: its public fields all carry the batch axis, so it vmaps."""
  return d.replace(_impl=None)


def limit_forces(binding: "Binding", m: mjx.Model, d: mjx.Data, qpos_before: jax.Array):
  """World-frame forces on tracked links from the limits of ``binding.limit_joint``, every world.

  ``d``: a batch's data after ``mjx.step`` (its constraint rows and kinematics are the forward pass's);
  ``qpos_before`` f32[B, nq]: the positions that forward pass saw (which bound a joint is at).

  Returns:
    forces: f32[B, J, 3] N, zero for a joint inside its range; force_link: i32[B, J] the child link of each joint.
  """
  jnt = binding.limit_joint
  B = d.qpos.shape[0]
  if jnt.size == 0:
    return jnp.zeros((B, 0, 3), jnp.float32), jnp.zeros((B, 0), jnp.int32)
  impl = d._impl
  rows = jnp.arange(impl.efc__force.shape[-1])
  used = rows[None, :] < jnp.reshape(impl.nefc, (B, 1))  # bool[B, njmax]: rows past nefc hold stale values
  mine = (used[..., None] & (impl.efc__type[..., None] == int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT))
          & (impl.efc__id[..., None] == jnp.asarray(jnt, jnp.int32)))  # bool[B, njmax, J]
  row_force = jnp.sum(jnp.where(mine, impl.efc__force[..., None], 0.0), axis=1)  # f32[B, J], ≥ 0

  forces = jax.vmap(lambda x, q, g: joint_link_forces(jnt, binding.limit_hinge, m, x, g, qpos=q))(
      public(d), qpos_before, row_force)
  return forces.astype(jnp.float32), jnp.broadcast_to(jnp.asarray(binding.limit_link, jnp.int32), (B, jnt.size))


def link_signals(binding: "Binding", m: mjx.Model, d: mjx.Data, wc: WorldContacts, qpos_before: jax.Array,
                 qvel_before: jax.Array, temperature: jax.Array, exposure: jax.Array) -> LinkSignals:
  """:class:`LinkSignals` with a leading batch axis B: contact forces, then joint-limit forces (as MJX-JAX's).

  ``d`` is a batch's data after ``mjx.step`` (Warp implementation), which leaves the forward pass's
  contacts, constraint forces, ``qacc`` and kinematics in place and only advances ``qpos``/``qvel``;
  ``wc`` its :func:`world_contacts`; ``qpos_before``, ``qvel_before`` f32[B, nq], f32[B, nv] the state that
  forward pass saw (the limits' sides and the link accelerations use it). ``temperature``, ``exposure``: f32[B, L].
  """
  fc, lc = _link_forces(binding, wc)
  fl, ll = limit_forces(binding, m, d, qpos_before)
  pub = public(d).replace(qvel=qvel_before)
  link_acc = jax.vmap(lambda x: link_acceleration(binding, x))(pub)
  return LinkSignals(forces=jnp.concatenate([fc, fl], axis=1), force_link=jnp.concatenate([lc, ll], axis=1),
                     link_acc=link_acc, temperature=temperature, exposure=exposure)


def link_velocities(binding: "Binding", d: mjx.Data) -> jax.Array:
  """f32[B, L, 3] link COM velocities as of the forward pass of ``d``'s last step."""
  return jax.vmap(lambda x: link_velocity(binding, x))(public(d))

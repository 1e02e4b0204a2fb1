"""Joint-limit (constraint) forces as loads on links: how forcing an articulation enters the mechanical DEM.

A hinge or slide joint held at its limit carries a constraint force (MuJoCo's
``mjCNSTR_LIMIT_JOINT`` row): a generalised force ``g`` along the joint's dof,
N for a slide, N·m for a hinge. mjx_damage turns it into one world-frame force
on the joint's **child link** (the body the joint moves), which then enters
:func:`mjx_damage.mechanical.mechanical_load` beside the contact forces, split
into F∥/F⊥ by that link's acceleration like any contact force
(docs/DAMAGE_MODEL.md, "How a joint-limit force enters the damage model"):

* slide: ``f = g·axis`` — the stop pushes the link along the joint axis;
* hinge: the torque ``g·axis`` is replaced by the force at the child link's
  centre of mass that has the same moment about the axis,
  ``f = g·(axis × r⊥)/‖r⊥‖²`` with ``r⊥`` the COM's offset from the axis,
  ``‖r⊥‖`` floored at :data:`LEVER_MIN` (a knob whose COM sits on its axis
  still reports a finite force).

The generalised force's sign is the limit's: MuJoCo's limit row pushes the dof
away from the nearer bound (+1 at the lower bound, −1 at the upper), with a
non-negative row force. Pure and array-only; every backend calls it with its
own simulator's quantities.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# m: smallest lever arm of a hinge limit torque. A COM closer to the axis than
# 1 cm (a symmetric knob) counts as 1 cm away, so torque/lever stays finite.
LEVER_MIN = 0.01


def limit_sign(q: jax.Array, lo: jax.Array, hi: jax.Array) -> jax.Array:
  """Direction the limit pushes each joint: +1 nearer the lower bound, −1 nearer the upper (f32[J])."""
  return jnp.where(q - lo < hi - q, 1.0, -1.0)


def link_forces(gen_force: jax.Array, hinge: jax.Array, axis: jax.Array, anchor: jax.Array,
                com: jax.Array) -> jax.Array:
  """World-frame force on each joint's child link from its limit's generalised force.

  Args:
    gen_force: f32[J] signed generalised limit force on the dof (N for slides, N·m for hinges).
    hinge: bool[J] True for hinge joints, False for slides.
    axis: f32[J, 3] joint axis, world frame (unit).
    anchor: f32[J, 3] a point on the joint axis, world frame, m.
    com: f32[J, 3] the child link's centre of mass, world frame, m.

  Returns:
    f32[J, 3] N.
  """
  axis = jnp.asarray(axis, jnp.float32)
  r = jnp.asarray(com, jnp.float32) - jnp.asarray(anchor, jnp.float32)
  r_perp = r - jnp.sum(r * axis, -1, keepdims=True) * axis
  dist = jnp.linalg.norm(r_perp, axis=-1, keepdims=True)
  # A COM on the axis has no tangent direction: any direction perpendicular to the axis will do.
  other = jnp.where(jnp.abs(axis[:, :1]) < 0.9, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0]))
  fallback = jnp.cross(other, axis)
  radial = jnp.where(dist > 1e-9, r_perp / jnp.maximum(dist, 1e-9), fallback / jnp.linalg.norm(fallback, axis=-1,
                                                                                                 keepdims=True))
  tangent = jnp.cross(axis, radial) / jnp.maximum(dist, LEVER_MIN)
  g = jnp.asarray(gen_force, jnp.float32)[:, None]
  return jnp.where(jnp.asarray(hinge)[:, None], g * tangent, g * axis)


def joint_link_forces(jnt, hinge, m, d, row_force, qpos=None) -> jax.Array:
  """World-frame force on the child link of each joint in ``jnt`` from its limit row's force, f32[J, 3] N.

  Args:
    jnt: i64[J] joint ids; hinge: bool[J] hinge (else slide).
    m, d: one environment's model and data after a forward pass, with MuJoCo's field names
      (``mujoco.MjModel``/``MjData`` or ``mjx.Model``/``Data``, either implementation): every backend.
    row_force: f32[J] each joint's limit-row force (≥ 0; 0 where the limit is not active).
    qpos: the positions that forward pass saw (default ``d.qpos``): which bound each joint is at.
  """
  q = (d.qpos if qpos is None else qpos)[m.jnt_qposadr[jnt]]
  gen = limit_sign(q, m.jnt_range[jnt, 0], m.jnt_range[jnt, 1]) * row_force
  return link_forces(gen, hinge, d.xaxis[jnt], d.xanchor[jnt], d.xipos[m.jnt_bodyid[jnt]])

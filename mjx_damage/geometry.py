"""Signed distance to MuJoCo primitive geoms, shared by the temperature and liquid models.

Each function takes points already expressed in one geom's frame (geom origin,
geom axes) and returns the signed distance to the geom's surface (negative
inside) and the outward unit normal of the nearest surface point, also in the
geom frame. Everything is pure JAX and broadcasts over leading axes, so
``P`` particles against ``G`` geoms of one type is one call on ``[P, G, 3]``.

Supported: plane, sphere, capsule, cylinder, box (MuJoCo's ``mjtGeom`` codes).
Ellipsoids, meshes, height fields and SDF plugins are not: :data:`SUPPORTED`
lists what the models accept, and they skip the rest at build time.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
SPHERE = int(mujoco.mjtGeom.mjGEOM_SPHERE)
CAPSULE = int(mujoco.mjtGeom.mjGEOM_CAPSULE)
CYLINDER = int(mujoco.mjtGeom.mjGEOM_CYLINDER)
BOX = int(mujoco.mjtGeom.mjGEOM_BOX)
SUPPORTED = (PLANE, SPHERE, CAPSULE, CYLINDER, BOX)
TYPE_NAMES = {PLANE: "plane", SPHERE: "sphere", CAPSULE: "capsule", CYLINDER: "cylinder", BOX: "box"}

_EPS = 1e-9


def _unit(v: jax.Array, fallback: jax.Array) -> jax.Array:
  """v/‖v‖, or ``fallback`` where ‖v‖ ≈ 0 (a point exactly on an axis or centre)."""
  n2 = jnp.sum(v * v, axis=-1, keepdims=True)
  safe = n2 > _EPS * _EPS
  return jnp.where(safe, v / jnp.sqrt(jnp.where(safe, n2, 1.0)), fallback)


def _rounded_box(d: jax.Array, sign: jax.Array) -> tuple[jax.Array, jax.Array]:
  """SDF and normal of an axis-aligned box from d = |q| − half_size (any dimension k).

  Outside: Euclidean distance to the box; inside: minus the distance to the
  nearest face (its normal is that face's axis).
  """
  outside = jnp.maximum(d, 0.0)
  out_len = jnp.sqrt(jnp.sum(outside * outside, axis=-1))
  inside = jnp.minimum(jnp.max(d, axis=-1), 0.0)
  phi = out_len + inside
  k = d.shape[-1]
  face = jax.nn.one_hot(jnp.argmax(d, axis=-1), k, dtype=d.dtype)
  n_in = face * sign
  n_out = outside * sign / jnp.maximum(out_len, _EPS)[..., None]
  n = jnp.where((out_len > 0)[..., None], n_out, n_in)
  return phi, n


def _sign(q: jax.Array) -> jax.Array:
  return jnp.where(q >= 0, 1.0, -1.0).astype(q.dtype)


def sdf(gtype: int, q: jax.Array, size: jax.Array) -> tuple[jax.Array, jax.Array]:
  """Signed distance and outward normal for geoms of ONE static type.

  Args:
    gtype: MuJoCo geom type code (static Python int, one of :data:`SUPPORTED`).
    q: f32[..., 3] points in the geom frame, m.
    size: f32[..., 3] ``geom_size`` broadcastable to ``q`` (MuJoCo's meaning per type:
      sphere r; capsule/cylinder r, half-length; box half-sizes; plane ignored).

  Returns:
    phi: f32[...] signed distance, m (< 0 inside the solid).
    normal: f32[..., 3] outward unit normal of the nearest surface point, geom frame.
  """
  ez = jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0], q.dtype), q.shape)
  if gtype == PLANE:
    # MuJoCo collides against the infinite plane z = 0 (size is visual only).
    return q[..., 2], ez
  if gtype == SPHERE:
    return jnp.linalg.norm(q, axis=-1) - size[..., 0], _unit(q, ez)
  if gtype == CAPSULE:
    c = jnp.clip(q[..., 2], -size[..., 1], size[..., 1])
    r = q - jnp.stack([jnp.zeros_like(c), jnp.zeros_like(c), c], axis=-1)
    return jnp.linalg.norm(r, axis=-1) - size[..., 0], _unit(r, ez)
  if gtype == CYLINDER:
    rho = jnp.sqrt(q[..., 0] ** 2 + q[..., 1] ** 2)
    d = jnp.stack([rho - size[..., 0], jnp.abs(q[..., 2]) - size[..., 1]], axis=-1)
    sgn = jnp.stack([jnp.ones_like(rho), _sign(q[..., 2])], axis=-1)
    phi, n2 = _rounded_box(d, sgn)
    ex = jnp.broadcast_to(jnp.array([1.0, 0.0], q.dtype), q[..., :2].shape)
    radial = _unit(q[..., :2], ex)
    n = jnp.concatenate([radial * n2[..., :1], n2[..., 1:]], axis=-1)
    return phi, n
  if gtype == BOX:
    return _rounded_box(jnp.abs(q) - size, _sign(q))
  raise ValueError(f"geom type: {gtype} is not a supported primitive ({', '.join(TYPE_NAMES.values())})")


def group_by_type(geom_ids, geom_type: np.ndarray) -> tuple[tuple[int, np.ndarray], ...]:
  """Static ``((type, geom ids), ...)`` groups so each type is one vectorised ``sdf`` call."""
  geom_ids = np.asarray(geom_ids, np.int32)
  out = []
  for t in SUPPORTED:
    ids = geom_ids[geom_type[geom_ids] == t]
    if ids.size:
      out.append((t, ids.astype(np.int32)))
  return tuple(out)


def points_to_geoms(groups, d, m, points: jax.Array) -> tuple[jax.Array, jax.Array, np.ndarray]:
  """Signed distances from points to a static set of geoms in their current world poses.

  Args:
    groups: output of :func:`group_by_type`.
    d: mjx.Data after kinematics (``geom_xpos`` f32[ngeom, 3] m, ``geom_xmat`` f32[ngeom, 3, 3]).
    m: mjx.Model (``geom_size``).
    points: f32[P, 3] world frame, m.

  Returns:
    phi: f32[P, G] signed distances, m; normal: f32[P, G, 3] world-frame outward normals;
    order: i32[G] geom id of each column (numpy, static).
  """
  phis, normals = [], []
  for gtype, ids in groups:
    pos = d.geom_xpos[ids]  # [G, 3]
    mat = d.geom_xmat[ids].reshape(-1, 3, 3)  # [G, 3, 3] columns = geom axes in world
    size = jnp.asarray(m.geom_size)[ids]
    rel = points[:, None, :] - pos[None]  # [P, G, 3]
    q = jnp.einsum("gji,pgj->pgi", mat, rel)  # world → geom frame: Rᵀ·(p − c)
    phi, n_local = sdf(gtype, q, size[None])
    phis.append(phi)
    normals.append(jnp.einsum("gij,pgj->pgi", mat, n_local))
  order = np.concatenate([ids for _, ids in groups]) if groups else np.zeros((0,), np.int32)
  if not groups:
    P = points.shape[0]
    return jnp.zeros((P, 0), points.dtype), jnp.zeros((P, 0, 3), points.dtype), order
  return jnp.concatenate(phis, axis=1), jnp.concatenate(normals, axis=1), order

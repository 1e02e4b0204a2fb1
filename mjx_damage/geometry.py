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

import functools

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

# Internally a batch of 3-vectors is three arrays of one shape ("planes": x, y, z),
# not one array with a trailing axis of 3: every operation is then a contiguous,
# vectorisable elementwise op (a trailing axis of 3 defeats XLA:CPU's vector units)
# and the particle–geom pass fuses into one loop on any backend.


def _unit(v: list, fallback: tuple) -> list:
  """v/‖v‖ (planes), or the constant ``fallback`` where ‖v‖ ≈ 0 (a point exactly on an axis or centre)."""
  n2 = sum(c * c for c in v)
  safe = n2 > _EPS * _EPS
  inv = jax.lax.rsqrt(jnp.where(safe, n2, 1.0))
  return [jnp.where(safe, c * inv, f) for c, f in zip(v, fallback)]


def _rounded_box(d: list, sign: list) -> tuple[jax.Array, list]:
  """SDF and normal (planes) of an axis-aligned box from d_k = |q_k| − half_size_k (k = 2 or 3 planes).

  Outside: Euclidean distance to the box; inside: minus the distance to the
  nearest face (its normal is that face's axis; ties go to the lowest axis).
  """
  outside = [jnp.maximum(c, 0.0) for c in d]
  out_len = jnp.sqrt(sum(c * c for c in outside))
  dmax = functools.reduce(jnp.maximum, d)
  phi = out_len + jnp.minimum(dmax, 0.0)
  inv = 1.0 / jnp.maximum(out_len, _EPS)
  is_out = out_len > 0
  taken = jnp.zeros_like(dmax, dtype=bool)
  n = []
  for c, o, s in zip(d, outside, sign):  # static: 2 or 3 axes
    face = (c >= dmax) & ~taken
    taken = taken | face
    n.append(jnp.where(is_out, o * s * inv, jnp.where(face, s, 0.0)))
  return phi, n


def _sign(q: jax.Array) -> jax.Array:
  return jnp.where(q >= 0, 1.0, -1.0).astype(q.dtype)


def sdf_planes(gtype: int, q: list, size: list) -> tuple[jax.Array, list]:
  """:func:`sdf` on planes: ``q`` = [qx, qy, qz] and ``size`` = [s0, s1, s2], arrays broadcasting together.

  Returns phi and the normal as planes [nx, ny, nz].
  """
  qx, qy, qz = q
  zero, one = jnp.zeros_like(qx), jnp.ones_like(qx)
  if gtype == PLANE:
    # MuJoCo collides against the infinite plane z = 0 (size is visual only).
    return qz + 0.0 * qx, [zero, zero, one]
  if gtype == SPHERE:
    return jnp.sqrt(qx * qx + qy * qy + qz * qz) - size[0], _unit(q, (0.0, 0.0, 1.0))
  if gtype == CAPSULE:
    r = [qx, qy, qz - jnp.clip(qz, -size[1], size[1])]
    return jnp.sqrt(sum(c * c for c in r)) - size[0], _unit(r, (0.0, 0.0, 1.0))
  if gtype == CYLINDER:
    rho = jnp.sqrt(qx * qx + qy * qy)
    phi, (n_r, n_z) = _rounded_box([rho - size[0], jnp.abs(qz) - size[1]], [one, _sign(qz)])
    rx, ry = _unit([qx, qy], (1.0, 0.0))
    return phi, [rx * n_r, ry * n_r, n_z]
  if gtype == BOX:
    return _rounded_box([jnp.abs(c) - s for c, s in zip(q, size)], [_sign(c) for c in q])
  raise ValueError(f"geom type: {gtype} is not a supported primitive ({', '.join(TYPE_NAMES.values())})")


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
  size = jnp.broadcast_to(size, jnp.broadcast_shapes(size.shape, q.shape))
  phi, n = sdf_planes(gtype, [q[..., k] for k in range(3)], [size[..., k] for k in range(3)])
  return phi, jnp.stack(jnp.broadcast_arrays(*n), axis=-1)


def group_by_type(geom_ids, geom_type: np.ndarray) -> tuple[tuple[int, np.ndarray], ...]:
  """Static ``((type, geom ids), ...)`` groups so each type is one vectorised ``sdf`` call."""
  geom_ids = np.asarray(geom_ids, np.int32)
  out = []
  for t in SUPPORTED:
    ids = geom_ids[geom_type[geom_ids] == t]
    if ids.size:
      out.append((t, ids.astype(np.int32)))
  return tuple(out)


def group_planes(gtype: int, ids: np.ndarray, d, m, points: jax.Array) -> tuple[jax.Array, list]:
  """Signed distances and world normals of points to the geoms ``ids`` of ONE static type, as planes.

  Returns phi f32[P, Gt] and [nx, ny, nz] (each broadcasting to [P, Gt]). Every
  per-pair quantity is an elementwise expression of [P, Gt] planes (the rotations are
  9 multiply-adds, not a batched matrix product), so XLA fuses the whole pass into
  one loop over particle–geom pairs, or into the reduction that consumes it.
  """
  pos = d.geom_xpos[ids]  # [G, 3]
  mat = d.geom_xmat[ids].reshape(-1, 3, 3)  # [G, 3, 3] columns = geom axes in world
  size = jnp.asarray(m.geom_size)[ids]
  rel = [points[:, k : k + 1] - pos[None, :, k] for k in range(3)]  # [P, G] each
  q = [sum(rel[j] * mat[None, :, j, i] for j in range(3)) for i in range(3)]  # Rᵀ·(p − c)
  phi, n_local = sdf_planes(gtype, q, [size[None, :, k] for k in range(3)])
  return phi, [sum(mat[None, :, i, j] * n_local[j] for j in range(3)) for i in range(3)]  # R·n


def points_to_geoms_planes(groups, d, m, points: jax.Array) -> tuple[jax.Array, list]:
  """:func:`points_to_geoms` with the normals as planes: (phi f32[P, G], [nx, ny, nz] f32[P, G] each)."""
  P = points.shape[0]
  if not groups:
    z = jnp.zeros((P, 0), points.dtype)
    return z, [z, z, z]
  phis, normals = [], []
  for gtype, ids in groups:
    phi, n = group_planes(gtype, ids, d, m, points)
    phis.append(phi)
    normals.append(n)
  phi = jnp.concatenate(phis, axis=1)
  return phi, [jnp.concatenate([jnp.broadcast_to(n[i], phi_g.shape) for n, phi_g in zip(normals, phis)], axis=1)
               for i in range(3)]


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
  phi, n = points_to_geoms_planes(groups, d, m, points)
  order = np.concatenate([ids for _, ids in groups]) if groups else np.zeros((0,), np.int32)
  return phi, jnp.stack(n, axis=-1), order

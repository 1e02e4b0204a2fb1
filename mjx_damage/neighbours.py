"""Fixed-size neighbour candidates of points in 3-D by sorting them into a uniform grid.

For ``P`` points and an interaction distance ``h`` (the grid's cell side), every
point gets ``C`` candidate partners: the points of the 27 cells around its own,
gathered without ever forming the ``P × P`` pair table. Pure JAX, fixed shapes,
jittable and vmappable (one environment's points per call).

Method (one environment)::

    cell_i = ⌊p_i / h⌋                       integer cell, clipped to a 2¹⁰-wide window per axis
    key_i  = (cx << 20) | (cy << 10) | cz     z fastest: the 3 cells (cx, cy, cz−1 … cz+1) are contiguous keys
    order  = argsort(key);  sorted = key[order]
    for each of the 9 columns (cx + a, cy + b), a, b ∈ {−1, 0, 1}:
        [lo, hi) = searchsorted(sorted, key(cx+a, cy+b, cz−1)), searchsorted(sorted, key(cx+a, cy+b, cz+1), right)
    the 9 ranges are laid end to end into C slots (ragged: a crowded column uses the slack of empty ones)

Every pair closer than ``h`` is found while the 27 cells around a point hold at
most ``C`` points (itself included); beyond that the last columns' points are
dropped (``overflow`` reports it). The window per axis is 1022 cells; points
further out share the edge cells (found as candidates of each other, never missed,
never duplicated).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

_BITS = 10
_SPAN = 1 << _BITS
_OFFSET = _SPAN // 2  # cell 0 of world space sits mid-window
# the 9 (dx, dy) columns of the 3 × 3 × 3 block
_COLUMNS = np.array([(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1)], np.int32)


def _key(cx, cy, cz):
  return (cx << (2 * _BITS)) | (cy << _BITS) | cz


def cells(points: jax.Array, h: float) -> jax.Array:
  """i32[P, 3] grid cell of each point (cell side ``h`` m), offset into [1, 2¹⁰ − 2] per axis.

  Clipping to one cell inside the window keeps every neighbour cell ±1 inside
  it, so each column's three z cells stay contiguous keys.
  """
  c = jnp.floor(points / h)
  c = jnp.clip(jnp.nan_to_num(c, nan=0.0), -_OFFSET + 1, _OFFSET - 2)  # before the int cast: no overflow
  return c.astype(jnp.int32) + _OFFSET


def candidates(points: jax.Array, h: float, slots: int) -> tuple[jax.Array, jax.Array, jax.Array]:
  """Candidate partners of every point: the points of the 27 cells around it.

  Args:
    points: f32[P, 3] positions (one environment), m.
    h: cell side, m — at least the largest distance at which a pair interacts.
    slots: C, candidate slots per point (static).

  Returns:
    j: i32[P, C] candidate indices (0 where not valid);
    valid: bool[P, C] slot holds a real candidate other than the point itself;
    overflow: i32[P] points of the 27 cells (itself included) that did not fit in ``slots``.
  """
  P = points.shape[0]
  c = cells(points, h)
  key = _key(c[:, 0], c[:, 1], c[:, 2])
  order = jnp.argsort(key)
  sorted_key = key[order]
  cx = c[:, 0:1] + _COLUMNS[None, :, 0]  # [P, 9]
  cy = c[:, 1:2] + _COLUMNS[None, :, 1]
  cz = c[:, 2:3]
  lo = jnp.searchsorted(sorted_key, _key(cx, cy, cz - 1), side="left", method="scan_unrolled")
  hi = jnp.searchsorted(sorted_key, _key(cx, cy, cz + 1), side="right", method="scan_unrolled")
  count = hi - lo  # [P, 9]
  end = jnp.cumsum(count, axis=1)
  start = end - count
  t = jnp.arange(slots, dtype=jnp.int32)
  # slot t belongs to the column whose [start, end) holds it: a [P, C, 9] select-and-sum
  # (take_along_axis would be a batched gather, several times slower on XLA:CPU)
  mine = (start[:, None, :] <= t[None, :, None]) & (t[None, :, None] < end[:, None, :])
  rank = jnp.sum(jnp.where(mine, (lo - start)[:, None, :], 0), axis=-1) + t[None, :]
  j = order[jnp.clip(rank, 0, P - 1)]
  col = jnp.where(t[None, :] < end[:, -1:], 0, _COLUMNS.shape[0])  # 9: slot beyond the last column
  valid = (col < _COLUMNS.shape[0]) & (j != jnp.arange(P, dtype=j.dtype)[:, None])
  return jnp.where(valid, j, 0), valid, jnp.maximum(end[:, -1] - slots, 0)

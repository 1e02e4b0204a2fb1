"""Mechanical damage evaluation model (DAMAGE_MODEL.md §2): loads and damage per link.

Pure functions over arrays; jit-, vmap- and grad-friendly; no Python loops over
contacts or links. Inputs may be arbitrary finite values: forces and
accelerations are clamped to ±FORCE_CLAMP so every intermediate stays finite
(no NaN for zero acceleration, zero forces or absurd forces).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# A link's acceleration counts as zero at or below this norm (m/s²): â = 0.
ACC_EPS = 1e-6
# Components beyond this (N, m/s²) are clamped; 1e15 is far above any physical
# contact force and keeps squares and sums inside f32 range.
FORCE_CLAMP = 1e15
# Damage excess above threshold is capped so 0·excess never becomes 0·inf.
EXCESS_CAP = 1e30


def _norm(x: jax.Array) -> jax.Array:
  # sqrt(0) has an infinite derivative; the where keeps gradients finite too.
  sq = jnp.sum(x * x, axis=-1)
  safe = jnp.where(sq > 0, sq, 1.0)
  return jnp.where(sq > 0, jnp.sqrt(safe), 0.0)


def mechanical_load(
    forces: jax.Array, force_link: jax.Array, link_acc: jax.Array, num_links: int
) -> tuple[jax.Array, jax.Array]:
  """Split the contact forces on each link into parts along and across its acceleration.

  Args:
    forces: f32[K, 3] world-frame forces acting on links, N.
    force_link: i32[K] the tracked link each force acts on; −1 = untracked (ignored).
    link_acc: f32[L, 3] each link's kinematic linear acceleration (world frame,
      gravity removed), m/s². At or below 1e-6 m/s² the direction â is 0.
    num_links: L (static).

  Returns:
    (f_par, f_perp): f32[L] each, F∥ = Σ_k |f_k·â| and F⊥ = Σ_k ‖f_k − (f_k·â)â‖, N.
  """
  forces = jnp.clip(jnp.asarray(forces, jnp.float32), -FORCE_CLAMP, FORCE_CLAMP)
  link_acc = jnp.clip(jnp.asarray(link_acc, jnp.float32), -FORCE_CLAMP, FORCE_CLAMP)
  force_link = jnp.asarray(force_link, jnp.int32)
  anorm = _norm(link_acc)
  moving = anorm > ACC_EPS
  ahat = jnp.where(moving[:, None], link_acc / jnp.where(moving, anorm, 1.0)[:, None], 0.0)

  valid = (force_link >= 0) & (force_link < num_links)
  seg = jnp.where(valid, force_link, num_links)  # invalid → overflow bucket, dropped
  ah = jnp.concatenate([ahat, jnp.zeros((1, 3), ahat.dtype)])[seg]
  along = jnp.sum(forces * ah, axis=-1)
  par = jnp.abs(along)
  perp = _norm(forces - along[:, None] * ah)
  # A masked sum over the force axis, not jax.ops.segment_sum: on GPU a segment sum is a scatter-add
  # with atomics, whose summation order (and so the last bits of every link's load and health)
  # changes from run to run (benchmarks/results/determinism_gpu.md). XLA fuses the mask into the
  # reduction, so the bool[K, L] mask is never materialised.
  onehot = seg[:, None] == jnp.arange(num_links, dtype=seg.dtype)[None, :]  # bool[K, L]; overflow → none
  f_par = jnp.sum(jnp.where(onehot, par[:, None], 0.0), axis=0)
  f_perp = jnp.sum(jnp.where(onehot, perp[:, None], 0.0), axis=0)
  return f_par, f_perp


def mechanical_damage(
    f_par: jax.Array,
    f_perp: jax.Array,
    alpha: jax.Array,
    beta: jax.Array,
    threshold: jax.Array,
    scale: jax.Array,
) -> jax.Array:
  """d_mech = Λ·max(α·F∥ + β·F⊥ − E, 0), f32[L], health per τ.

  Args:
    f_par, f_perp: f32[L] loads from :func:`mechanical_load`, N.
    alpha, beta: f32[L] (or scalars) weights of the parallel / perpendicular load.
    threshold: f32[L] E_mech, N.
    scale: f32[L] Λ_mech, health per N per τ.
  """
  eps = alpha * f_par + beta * f_perp
  excess = jnp.minimum(jnp.maximum(eps - threshold, 0.0), EXCESS_CAP)
  return jnp.where(scale > 0, scale * excess, 0.0)

"""Fluid damage evaluation model (DAMAGE_MODEL.md §2)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_damage.mechanical import EXCESS_CAP


def fluid_damage(exposure: jax.Array, threshold: jax.Array, scale: jax.Array) -> jax.Array:
  """d_fluid = Λ·max(c − C, 0), f32[L], health per τ.

  Args:
    exposure: f32[L] c, liquid particles in contact with each link.
    threshold: f32[L] C_fluid, particles.
    scale: f32[L] Λ_fluid, health per particle per τ (0 = off).
  """
  excess = jnp.minimum(jnp.maximum(jnp.asarray(exposure, jnp.float32) - threshold, 0.0), EXCESS_CAP)
  return jnp.where(scale > 0, scale * excess, 0.0)

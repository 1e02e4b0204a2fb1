"""Thermal damage evaluation model (DAMAGE_MODEL.md §2)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_damage.mechanical import EXCESS_CAP


def thermal_damage(temperature: jax.Array, t_hot: jax.Array, t_cold: jax.Array, scale: jax.Array) -> jax.Array:
  """d_therm = Λ·(max(T − T_hot, 0) + max(T_cold − T, 0)), f32[L], health per τ.

  Args:
    temperature: f32[L] link temperatures, °C.
    t_hot, t_cold: f32[L] thresholds, °C (T_cold < T_hot).
    scale: f32[L] Λ_therm, health per °C per τ (0 = off).
  """
  t = jnp.asarray(temperature, jnp.float32)
  excess = jnp.maximum(t - t_hot, 0.0) + jnp.maximum(t_cold - t, 0.0)
  excess = jnp.minimum(excess, EXCESS_CAP)
  return jnp.where(scale > 0, scale * excess, 0.0)

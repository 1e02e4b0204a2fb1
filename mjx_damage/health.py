"""Health: integrating damage rates into per-link health and reducing it per entity."""

from __future__ import annotations

import jax
import jax.numpy as jnp

MAX_HEALTH = 100.0


def entity_health(link_health: jax.Array, link_entity: jax.Array, num_entities: int) -> jax.Array:
  """Entity health = min over its links' health.

  Args:
    link_health: f32[L] in [0, 100].
    link_entity: i32[L] entity index of each link, in [0, N).
    num_entities: N (static); every entity must own at least one link.

  Returns:
    f32[N] entity health.
  """
  h = jax.ops.segment_min(
      jnp.asarray(link_health, jnp.float32), jnp.asarray(link_entity, jnp.int32), num_segments=num_entities
  )
  return jnp.minimum(h, MAX_HEALTH)  # an entity without links would read +inf


def integrate(link_health: jax.Array, damage_rate: jax.Array, dt, tau) -> jax.Array:
  """h ← clip(h − d·dt/τ, 0, 100) for one physics substep of length ``dt`` (s).

  ``damage_rate`` f32[L] is the summed damage of all models in health per τ.
  """
  d = jnp.maximum(damage_rate, 0.0) * (dt / tau)
  return jnp.clip(link_health - d, 0.0, MAX_HEALTH)

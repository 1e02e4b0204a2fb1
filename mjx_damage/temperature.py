"""Temperature of tracked links (MuJoCo has none): pure JAX state advanced each substep.

Seam used by :mod:`mjx_damage.physics`: ``build`` (static model from the config,
None when no heat sources are configured), ``init``, ``initial_link_temperature``
and ``advance``. Without heat sources nothing is computed and every link stays
at ambient temperature.
"""

from __future__ import annotations

import jax.numpy as jnp

AMBIENT = 22.0  # °C


def build(model, binding, raw):
  if raw.get("temperature") is not None:
    raise ValueError("temperature: heat sources are not available in this version")
  return None


def init(binding):
  return None


def initial_link_temperature(binding):
  return jnp.full((binding.num_links,), AMBIENT, jnp.float32)


def advance(m, binding, d, ds, dt):
  return ds

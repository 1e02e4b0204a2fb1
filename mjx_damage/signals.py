"""The interface between physics backends and the damage models.

A backend (:mod:`mjx_damage.backends`: MJX-JAX, MuJoCo Warp, native MuJoCo)
only has to produce :class:`LinkSignals` for one environment at one physics
substep. :func:`evaluate` turns them into per-modality damage rates with the pure
functions of :mod:`mechanical`, :mod:`thermal` and :mod:`fluid`, untouched.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from mjx_damage.fluid import fluid_damage
from mjx_damage.mechanical import mechanical_damage, mechanical_load
from mjx_damage.params import DamageParams
from mjx_damage.thermal import thermal_damage


@struct.dataclass
class LinkSignals:
  """Physical signals for L tracked links at one physics substep (one environment).

  forces:      f32[K, 3] world-frame contact forces acting on links, N
  force_link:  i32[K] link each force acts on (−1: untracked link, ignored)
  link_acc:    f32[L, 3] kinematic linear acceleration of each link's COM (gravity removed), m/s²
  temperature: f32[L] link temperature, °C
  exposure:    f32[L] liquid particles in contact with each link
  """

  forces: jax.Array
  force_link: jax.Array
  link_acc: jax.Array
  temperature: jax.Array
  exposure: jax.Array


@struct.dataclass
class Damage:
  """Damage per modality, f32[L] each (rates per τ, or health points once integrated)."""

  mechanical: jax.Array
  thermal: jax.Array
  fluid: jax.Array

  def total(self) -> jax.Array:
    return self.mechanical + self.thermal + self.fluid

  @classmethod
  def zeros(cls, num_links: int) -> "Damage":
    z = jnp.zeros((num_links,), jnp.float32)
    return cls(z, z, z)


@struct.dataclass
class Evaluation:
  """What :func:`evaluate` returns: damage rates and the mechanical loads behind them."""

  rate: Damage  # health per τ, f32[L] each
  f_par: jax.Array  # f32[L], N
  f_perp: jax.Array  # f32[L], N


def evaluate(signals: LinkSignals, params: DamageParams) -> Evaluation:
  """All damage evaluation models for one substep of one environment."""
  num_links = params.alpha.shape[-1]
  f_par, f_perp = mechanical_load(signals.forces, signals.force_link, signals.link_acc, num_links)
  rate = Damage(
      mechanical=mechanical_damage(
          f_par, f_perp, params.alpha, params.beta, params.mech_threshold, params.mech_scale
      ),
      thermal=thermal_damage(signals.temperature, params.t_hot, params.t_cold, params.thermal_scale),
      fluid=fluid_damage(signals.exposure, params.fluid_threshold, params.fluid_scale),
  )
  return Evaluation(rate, f_par, f_perp)

"""Damage parameters: the paper's tables, per-object lookup, and the per-link pytree.

The tables are OopsieVerse's appendix tables as fixed in ``DAMAGE_MODEL.md`` §5.
Parameters end up as :class:`DamageParams`, a pytree of ``f32[L]`` arrays (one
entry per tracked link) so they can be vmapped across environments, randomised
per episode and swept without recompiling.

Units: forces in N, temperatures in °C, liquid exposure in particles, scales in
health points per reference interval τ (``tau``, seconds).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Optional

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

# Reference interval τ: damage values are "per OmniGibson action period" (30 Hz).
DEFAULT_TAU = 1.0 / 30.0

# Thresholds used where a modality is off for a link: far outside anything a
# scene produces, yet finite so that sweeps (threshold / fragility) stay finite.
OFF_T_HOT = 1.0e6
OFF_T_COLD = -1.0e6
OFF_FLUID_THRESHOLD = 1.0e9


@dataclasses.dataclass(frozen=True)
class Mechanical:
  """ε = alpha·F∥ + beta·F⊥ (N); d = scale·max(ε − threshold, 0) per τ."""

  alpha: float
  beta: float
  threshold: float
  scale: float


@dataclasses.dataclass(frozen=True)
class Thermal:
  """d = scale·(max(T − t_hot, 0) + max(t_cold − T, 0)) per τ; T in °C."""

  t_hot: float
  t_cold: float
  scale: float


@dataclasses.dataclass(frozen=True)
class Fluid:
  """d = scale·max(c − threshold, 0) per τ; c = particles touching the link."""

  threshold: float
  scale: float


@dataclasses.dataclass(frozen=True)
class ObjectParams:
  """An entity's parameters; ``thermal``/``fluid`` None means that modality is off."""

  mechanical: Mechanical
  thermal: Optional[Thermal] = None
  fluid: Optional[Fluid] = None


# name: (alpha, beta, E, Lambda) — DAMAGE_MODEL.md §5.
MECHANICAL_TABLE: Mapping[str, tuple[float, float, float, float]] = {
    "default": (1.0, 1.0, 30.0, 0.1),
    "agent": (0.01, 1.0, 70.0, 0.2),
    "microwave": (1.0, 1.0, 100.0, 1.0),
    "camera_tripod": (0.1, 1.0, 150.0, 1.0),
    "digital_camera": (1.0, 0.5, 60.0, 100.0),
    "scrub_brush": (0.01, 0.01, 300.0, 100.0),
    "bottle_of_wine": (1.0, 0.5, 50.0, 100.0),
    "wineglass": (1.0, 0.5, 15.0, 100.0),
    "bottle_of_beer": (1.0, 0.5, 15.0, 100.0),
    "bag_of_flour": (0.1, 0.1, 150.0, 100.0),
    "box_of_crackers": (0.1, 0.8, 200.0, 1.0),
    "stand": (0.001, 0.001, 500.0, 1.0),
    "laptop": (1.0, 0.5, 80.0, 100.0),
    "water_glass": (1.0, 0.5, 50.0, 100.0),
    "coffee_cup": (1.0, 0.5, 150.0, 1.0),
    "plate": (1.0, 0.5, 50.0, 10.0),
    "vase": (1.0, 0.5, 30.0, 10.0),
    "pedestal_table": (0.1, 0.1, 150.0, 1.0),
    "swivel_chair": (0.1, 0.1, 500.0, 1.0),
}

# name: (T_hot, T_cold, Lambda)
THERMAL_TABLE: Mapping[str, tuple[float, float, float]] = {
    "agent": (40.0, -20.0, 1.0),
    "camera_tripod": (50.0, -30.0, 0.1),
    "digital_camera": (50.0, -30.0, 0.1),
    "laptop": (50.0, -20.0, 0.1),
    "vase": (60.0, -40.0, 0.01),
    "pedestal_table": (60.0, -40.0, 0.01),
    "swivel_chair": (60.0, -60.0, 0.01),
}

# name: (C, Lambda)
FLUID_TABLE: Mapping[str, tuple[float, float]] = {
    "agent": (10.0, 10.0),
    "digital_camera": (20.0, 5.0),
    "laptop": (20.0, 5.0),
}


def known_objects() -> list[str]:
  """Names that :func:`object_params` accepts (the mechanical table's rows)."""
  return sorted(MECHANICAL_TABLE)


def object_params(name: str) -> ObjectParams:
  """An entity's mechanical/thermal/fluid parameters from the built-in tables.

  Raises:
    ValueError: ``name`` is not a table row; the message lists the known ones.
      The ``default`` row is returned only when asked for by name.
  """
  if not isinstance(name, str) or name not in MECHANICAL_TABLE:
    raise ValueError(
        f"params: unknown object {name!r}; known objects: {', '.join(known_objects())}"
        " (use 'default' explicitly for an object the tables lack)"
    )
  th = THERMAL_TABLE.get(name)
  fl = FLUID_TABLE.get(name)
  return ObjectParams(
      mechanical=Mechanical(*MECHANICAL_TABLE[name]),
      thermal=Thermal(*th) if th else None,
      fluid=Fluid(*fl) if fl else None,
  )


@struct.dataclass
class DamageParams:
  """Per-link damage parameters, every field ``f32[L]`` except ``tau`` (``f32[]``, s).

  Batch it (add a leading axis) to give every environment its own parameters.
  """

  alpha: jax.Array
  beta: jax.Array
  mech_threshold: jax.Array  # E_mech, N
  mech_scale: jax.Array  # Λ_mech, health / (N·τ)
  t_hot: jax.Array  # °C
  t_cold: jax.Array  # °C
  thermal_scale: jax.Array  # Λ_therm, health / (°C·τ)
  fluid_threshold: jax.Array  # C_fluid, particles
  fluid_scale: jax.Array  # Λ_fluid, health / (particle·τ)
  tau: jax.Array  # reference interval τ, s

  @property
  def num_links(self) -> int:
    return self.alpha.shape[-1]

  def with_fragility(self, factor) -> "DamageParams":
    """Scale fragility: thresholds ÷ factor, damage scales × factor (factor > 0).

    ``factor`` may be a traced scalar or carry batch axes broadcastable to the
    leading axes of the fields, so a sweep over fragility levels is a vmap, not
    a recompilation. Temperature thresholds move toward/away from ambient
    (22 °C) rather than toward 0 °C.
    """
    return self.scale_fragility(jnp.asarray(factor, jnp.float32)[..., None])

  def scale_fragility(self, f) -> "DamageParams":
    """:meth:`with_fragility` with ``f`` broadcast against the f32[..., L] fields (e.g. one factor per link)."""
    ambient = 22.0
    return self.replace(
        mech_threshold=self.mech_threshold / f,
        mech_scale=self.mech_scale * f,
        t_hot=ambient + (self.t_hot - ambient) / f,
        t_cold=ambient + (self.t_cold - ambient) / f,
        thermal_scale=self.thermal_scale * f,
        fluid_threshold=self.fluid_threshold / f,
        fluid_scale=self.fluid_scale * f,
    )


def stack_link_params(links: list[ObjectParams], tau: float = DEFAULT_TAU) -> DamageParams:
  """Per-link :class:`ObjectParams` (already validated) → :class:`DamageParams`."""
  def col(get):
    return jnp.asarray(np.array([get(p) for p in links], np.float32))

  return DamageParams(
      alpha=col(lambda p: p.mechanical.alpha),
      beta=col(lambda p: p.mechanical.beta),
      mech_threshold=col(lambda p: p.mechanical.threshold),
      mech_scale=col(lambda p: p.mechanical.scale),
      t_hot=col(lambda p: p.thermal.t_hot if p.thermal else OFF_T_HOT),
      t_cold=col(lambda p: p.thermal.t_cold if p.thermal else OFF_T_COLD),
      thermal_scale=col(lambda p: p.thermal.scale if p.thermal else 0.0),
      fluid_threshold=col(lambda p: p.fluid.threshold if p.fluid else OFF_FLUID_THRESHOLD),
      fluid_scale=col(lambda p: p.fluid.scale if p.fluid else 0.0),
      tau=jnp.asarray(tau, jnp.float32),
  )


def is_finite_nonneg(x) -> bool:
  return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x >= 0

"""Fragility domain randomisation: damage parameters drawn per environment at reset.

``fragility_randomizer(ranges)`` returns a ``params_fn(rng, default_params) ->
params`` for :class:`~mjx_damage.wrapper.DamageWrapper` (``params_fn=``), which
calls it inside every (vmapped, jitted) reset. Each entry of ``ranges`` names a
:class:`~mjx_damage.params.DamageParams` field and a ``(low, high)`` range of a
multiplicative factor drawn log-uniformly, so ``(0.5, 2.0)`` makes halving and
doubling equally likely::

    params_fn = fragility_randomizer({"mech_threshold": (0.5, 2.0), "mech_scale": (0.5, 2.0)})
    env = DamageWrapper(task_env, params_fn=params_fn)

Two shorthand keys act on several fields at once:

* ``"fragility"``: one factor f per environment applied with
  :meth:`DamageParams.with_fragility` (every threshold ÷ f, every scale × f);
* ``"E"`` / ``"Lambda"``: the mechanical threshold E_mech / scale Λ_mech
  (the paper's names; aliases of ``mech_threshold`` / ``mech_scale``).

By default one factor per field is drawn per environment and shared by all its
links (an environment is "a more fragile world"); ``per_link=True`` draws one
factor per link. Everything is validated in Python when the randomiser is
built (``ValueError`` naming the field), never inside the compiled reset.
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

import jax
import jax.numpy as jnp

from mjx_damage.params import DamageParams

ParamsFn = Callable[[jax.Array, DamageParams], DamageParams]

# Fields a factor may multiply. Temperature thresholds are left to "fragility"
# (with_fragility moves them relative to ambient; a raw factor on °C is meaningless
# for a threshold below 0 °C), and tau is a unit, not a material property.
FACTOR_FIELDS = (
    "alpha",
    "beta",
    "mech_threshold",
    "mech_scale",
    "thermal_scale",
    "fluid_threshold",
    "fluid_scale",
)
ALIASES = {"E": "mech_threshold", "Lambda": "mech_scale", "Λ": "mech_scale"}
SHORTHANDS = ("fragility",)


def _check_range(field: str, value) -> tuple[float, float]:
  if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
    raise ValueError(f"ranges.{field}: expected a (low, high) pair, got {value!r}")
  out = []
  for name, v in zip(("low", "high"), value):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
      raise ValueError(f"ranges.{field}.{name}: expected a finite number, got {v!r}")
    if v <= 0:
      raise ValueError(f"ranges.{field}.{name}: a factor range must be > 0 (log-uniform), got {v!r}")
    out.append(float(v))
  if out[0] > out[1]:
    raise ValueError(f"ranges.{field}: need low <= high, got low={out[0]!r} high={out[1]!r}")
  return out[0], out[1]


def validate_ranges(ranges: Mapping) -> dict[str, tuple[float, float]]:
  """Checked, alias-resolved copy of ``ranges``: ``{field: (low, high)}``.

  Raises:
    ValueError: ``ranges.<field>: ...`` for an unknown field, a duplicate via an
      alias, a non-pair, a non-finite or non-positive bound, or low > high.
  """
  if not isinstance(ranges, Mapping):
    raise ValueError(f"ranges: expected a mapping of field -> (low, high), got {type(ranges).__name__}")
  if not ranges:
    raise ValueError("ranges: empty; give at least one field to randomise")
  out: dict[str, tuple[float, float]] = {}
  allowed = FACTOR_FIELDS + SHORTHANDS + tuple(ALIASES)
  for key, value in ranges.items():
    if key not in allowed:
      raise ValueError(f"ranges.{key}: unknown field; allowed: {', '.join(allowed)}")
    field = ALIASES.get(key, key)
    if field in out:
      raise ValueError(f"ranges.{key}: {field} is given twice (directly and through an alias)")
    out[field] = _check_range(key, value)
  return out


def log_uniform(rng: jax.Array, low: float, high: float, shape=()) -> jax.Array:
  """f32[shape] factors with log f uniform on [log low, log high] (low == high gives low)."""
  u = jax.random.uniform(rng, shape, jnp.float32)
  lo, hi = math.log(low), math.log(high)
  return jnp.exp(lo + u * (hi - lo))


def fragility_randomizer(ranges: Mapping, per_link: bool = False) -> ParamsFn:
  """A ``params_fn(rng, default_params) -> params`` drawing log-uniform factors.

  Args:
    ranges: ``{field: (low, high)}`` factor ranges, low > 0, low <= high; fields
      from :data:`FACTOR_FIELDS`, the aliases ``E``/``Lambda``, or ``fragility``.
    per_link: draw one factor per link instead of one per environment.

  Returns:
    A pure function of one environment: ``rng`` a PRNG key, ``default_params``
    the binding's :class:`DamageParams` (fields f32[L]); returns new params of
    the same shapes. Vmap it (or call it inside a vmapped reset) for a batch.
  """
  checked = validate_ranges(ranges)
  if not isinstance(per_link, bool):
    raise ValueError(f"per_link: expected a bool, got {per_link!r}")
  names = sorted(checked)  # fixed order: the same rng gives the same draw

  def params_fn(rng: jax.Array, default_params: DamageParams) -> DamageParams:
    keys = jax.random.split(rng, len(names))
    shape = default_params.alpha.shape if per_link else default_params.alpha.shape[:-1]
    params = default_params
    for key, name in zip(keys, names):  # loop over fields (static), not envs
      low, high = checked[name]
      f = log_uniform(key, low, high, shape)
      if name == "fragility":
        # with_fragility broadcasts a per-env factor over links; a per-link
        # factor is already link-shaped, so drop the axis it would add.
        params = params.with_fragility(f) if not per_link else params.scale_fragility(f)
      else:
        scale = f if per_link else f[..., None]
        params = params.replace(**{name: getattr(params, name) * scale})
    return params

  return params_fn


def fragility_params(default_params: DamageParams, factor) -> DamageParams:
  """``default_params`` at fragility ``factor`` (f32[] or f32[B] for a batch of envs).

  A thin, validated front for :meth:`DamageParams.with_fragility` used by
  evaluation and sweeps; ``factor`` may be traced (no recompilation per level).
  """
  return default_params.with_fragility(factor)


def check_fragility(values, field: str = "fragility") -> list[float]:
  """Validate fragility factors given by a user: finite numbers > 0 (``ValueError`` naming ``field``)."""
  if isinstance(values, (int, float)) and not isinstance(values, bool):
    values = [values]
  values = list(values)
  if not values:
    raise ValueError(f"{field}: give at least one factor")
  for i, v in enumerate(values):
    name = field if len(values) == 1 else f"{field}[{i}]"
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
      raise ValueError(f"{name}: expected a finite number, got {v!r}")
    if v <= 0:
      raise ValueError(f"{name}: must be > 0 (a multiplier on scales, divisor of thresholds), got {v!r}")
  return [float(v) for v in values]

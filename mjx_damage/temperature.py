"""Temperature of tracked links (MuJoCo has none): pure JAX state advanced each substep.

Config (top-level key ``temperature``; per-entity rates under ``entities.<name>.heat``)::

    temperature:
      ambient: 22                     # °C, every link's temperature at reset (default 22)
      sources:                        # heat sources = scene geoms (may be empty)
        burner: {geom: burner_geom, temperature: 300, on: true, reach: 0.05}
    entities:
      hand:
        heat: {conduction: 2.0, radiation: 0.1, cooling: 0.05}   # 1/s each

Model, for every tracked link l with temperature T_l (°C), per physics substep dt::

    T_s,eff = T_a + on_s·(T_s − T_a)                       (a switched-off source sits at ambient)
    w_ls    = exp(−max(r_ls, 0) / reach_s)                  (r_ls: link COM → source surface, m)
    k_ls    = conduction_l·touch_ls + radiation_l·w_ls      (1/s)
    T_l    ← T_l + dt·[Σ_s k_ls·(T_s,eff − T_l) + cooling_l·(T_a − T_l)]

``touch_ls`` is 1 while an active contact (``dist − includemargin < 0``) joins
one of link l's geoms and source s's geom, or while the link's COM is inside
the source geom (non-colliding flames), else 0.

Stability (checked by :func:`build`): with ``dt·(S·(conduction + radiation) + cooling) ≤ 1``
for every link, the update is a convex combination of T_l, T_a and the source
temperatures, so T never overshoots a source or ambient and never oscillates.
Sources not listed as ``SUPPORTED`` geom types use only the contact term.

Seam used by :mod:`mjx_damage.physics`: :func:`build` (static model from the
config; None when there is no ``temperature`` key — then nothing is computed
and every link stays at 22 °C), :func:`init`, :func:`initial_link_temperature`
and :func:`advance`. A task switches a source with :func:`set_source` inside jit.
"""

from __future__ import annotations

from typing import Mapping

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from mjx_damage import geometry as G
from mjx_damage.validate import check_keys as _check_keys
from mjx_damage.validate import fail as _fail
from mjx_damage.validate import mapping as _mapping
from mjx_damage.validate import number as _number

AMBIENT = 22.0  # °C
ABSOLUTE_ZERO = -273.15  # °C
# Per-entity exchange rates, 1/s (documented in docs/physics_models.md). Chosen
# so a hand in a 300 °C fire passes the agent's T_hot (40 °C) within ~30 ms of
# contact, while a link 0.3 m from a fire of reach 0.05 m warms < 1 °C/s.
DEFAULT_HEAT = {"conduction": 2.0, "radiation": 0.2, "cooling": 0.05}
DEFAULT_REACH = 0.05  # m, e-folding distance of a source's radiant exchange

_TEMP_KEYS = ("ambient", "sources")
_SOURCE_KEYS = ("geom", "temperature", "on", "reach")


@struct.dataclass
class ThermalModel:
  """Static temperature model of one scene (closed over by the compiled step).

  Index arrays are numpy (they shape the computation); rates are f32 arrays.
  """

  conduction: jax.Array  # f32[L], 1/s
  radiation: jax.Array  # f32[L], 1/s
  cooling: jax.Array  # f32[L], 1/s
  reach: jax.Array  # f32[S], m
  source_temperature: jax.Array  # f32[S] °C at reset
  source_on: jax.Array  # f32[S] in [0, 1] at reset
  ambient: float = struct.field(pytree_node=False, default=AMBIENT)
  source_names: tuple = struct.field(pytree_node=False, default=())
  source_geom: np.ndarray = struct.field(pytree_node=False, default=None)  # i32[S]
  source_link: np.ndarray = struct.field(pytree_node=False, default=None)  # i32[S], tracked link owning it or −1
  geom_source: np.ndarray = struct.field(pytree_node=False, default=None)  # i32[ngeom], source index or −1
  shape_groups: tuple = struct.field(pytree_node=False, default=())  # geometry.group_by_type of source geoms

  @property
  def num_sources(self) -> int:
    return len(self.source_names)


@struct.dataclass
class ThermalState:
  """Per-environment source state (switchable by the task inside jit).

  source_on:          f32[S] in [0, 1], 0 = off (at ambient), 1 = on, between = knob
  source_temperature: f32[S] °C when on
  """

  source_on: jax.Array
  source_temperature: jax.Array






def heat_rates(raw: Mapping, entity: str) -> dict:
  """Validated ``entities.<entity>.heat`` rates (1/s) with defaults filled in."""
  field = f"entities.{entity}.heat"
  spec = raw.get("entities", {}).get(entity, {}).get("heat")
  if spec is None:
    return dict(DEFAULT_HEAT)
  spec = _mapping(field, spec)
  _check_keys(field, spec, tuple(DEFAULT_HEAT))
  out = dict(DEFAULT_HEAT)
  for k, v in spec.items():
    out[k] = _number(f"{field}.{k}", v, lo=0.0)
  return out


def build(model: mujoco.MjModel, binding, raw: Mapping):
  """Validate the ``temperature`` config and every entity's ``heat`` against ``model``.

  Returns None (nothing computed at all) when ``raw`` has no ``temperature`` key.

  Raises:
    ValueError: naming the field — unknown geom, bad type, negative/NaN rate,
      or a timestep that breaks the Euler bound ``dt·(S·(cond + rad) + cool) ≤ 1``.
  """
  entities = raw.get("entities", {})
  rates = {name: heat_rates(raw, name) for name in entities}  # validate all, tracked or not
  cfg = raw.get("temperature")
  if cfg is None:
    for name in entities:
      if entities[name].get("heat") is not None:
        _fail(f"entities.{name}.heat", "given but no top-level 'temperature' config (no heat sources)")
    return None
  cfg = _mapping("temperature", cfg)
  _check_keys("temperature", cfg, _TEMP_KEYS)
  ambient = _number("temperature.ambient", cfg.get("ambient", AMBIENT), lo=ABSOLUTE_ZERO)
  sources = _mapping("temperature.sources", cfg.get("sources", {}))

  names, geoms, temps, ons, reaches = [], [], [], [], []
  for sname, spec in sources.items():
    f = f"temperature.sources.{sname}"
    spec = _mapping(f, spec)
    _check_keys(f, spec, _SOURCE_KEYS)
    gname = spec.get("geom")
    if not isinstance(gname, str):
      _fail(f"{f}.geom", f"expected a geom name, got {gname!r}")
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, gname)
    if gid < 0:
      _fail(f"{f}.geom", f"unknown geom {gname!r} in the model")
    if gid in geoms:
      _fail(f"{f}.geom", f"geom {gname!r} is already source {names[geoms.index(gid)]!r}")
    if "temperature" not in spec:
      _fail(f"{f}.temperature", "required (°C)")
    temp = _number(f"{f}.temperature", spec["temperature"], lo=ABSOLUTE_ZERO)
    on = spec.get("on", True)
    if not isinstance(on, bool):
      _fail(f"{f}.on", f"expected true/false, got {on!r}")
    reach = _number(f"{f}.reach", spec.get("reach", DEFAULT_REACH), lo=0.0)
    if reach <= 0:
      _fail(f"{f}.reach", f"must be > 0, got {reach!r}")
    names.append(str(sname))
    geoms.append(gid)
    temps.append(temp)
    ons.append(1.0 if on else 0.0)
    reaches.append(reach)

  S = len(names)
  ents = binding.resolved.entities
  link_rates = [rates[ents[l.entity]] for l in binding.resolved.links]
  dt = float(model.opt.timestep)
  for l, r in zip(binding.resolved.links, link_rates):
    total = dt * (S * (r["conduction"] + r["radiation"]) + r["cooling"])
    if total > 1.0:
      _fail(
          f"entities.{ents[l.entity]}.heat",
          f"explicit Euler bound violated: timestep·(sources·(conduction + radiation) + cooling) = "
          f"{dt}·({S}·({r['conduction']} + {r['radiation']}) + {r['cooling']}) = {total:.4g} > 1; "
          "lower the rates or the timestep",
      )

  def col(key):
    return jnp.asarray(np.array([r[key] for r in link_rates], np.float32).reshape(-1))

  source_geom = np.array(geoms, np.int32)
  geom_source = np.full(model.ngeom, -1, np.int32)
  geom_source[source_geom] = np.arange(S, dtype=np.int32)
  return ThermalModel(
      conduction=col("conduction"),
      radiation=col("radiation"),
      cooling=col("cooling"),
      reach=jnp.asarray(np.array(reaches, np.float32)),
      source_temperature=jnp.asarray(np.array(temps, np.float32)),
      source_on=jnp.asarray(np.array(ons, np.float32)),
      ambient=ambient,
      source_names=tuple(names),
      source_geom=source_geom,
      source_link=np.asarray(binding.geom_link)[source_geom].astype(np.int32),
      geom_source=geom_source,
      shape_groups=G.group_by_type(source_geom, np.asarray(model.geom_type)),
  )


def init(binding):
  """Fresh per-environment source state (the config's temperatures and on/off), or None."""
  tm = binding.thermal
  if tm is None:
    return None
  return ThermalState(source_on=tm.source_on, source_temperature=tm.source_temperature)


def initial_link_temperature(binding) -> jax.Array:
  """f32[L] °C: every tracked link at the configured ambient (22 °C by default)."""
  ambient = AMBIENT if binding.thermal is None else binding.thermal.ambient
  return jnp.full((binding.num_links,), ambient, jnp.float32)


def source_index(binding, source) -> int:
  """Index of a heat source given its config name (or an int index, checked)."""
  tm = binding.thermal
  if tm is None:
    _fail("temperature", "no heat sources configured")
  if isinstance(source, str):
    if source not in tm.source_names:
      _fail("source", f"unknown heat source {source!r}; sources: {', '.join(tm.source_names)}")
    return tm.source_names.index(source)
  if isinstance(source, (int, np.integer)) and not isinstance(source, bool) and 0 <= source < tm.num_sources:
    return int(source)
  _fail("source", f"expected a source name or index in [0, {tm.num_sources}), got {source!r}")


def set_source(ds, source, on, binding=None, temperature=None):
  """Switch heat source ``source`` on (1), off (0) or in between, inside jit.

  Args:
    ds: DamageState of one environment (or a batch: ``on`` broadcasts).
    source: int index, or the config name (then ``binding`` is required).
    on: bool / f32 in [0, 1] (clipped), may be traced.
    temperature: optional new source temperature, °C (may be traced).
  """
  if isinstance(source, str):
    if binding is None:
      _fail("binding", "needed to look a source up by name")
    source = source_index(binding, source)
  th = ds.thermal
  if th is None:
    _fail("temperature", "no heat sources configured")
  on = jnp.clip(jnp.asarray(on, jnp.float32), 0.0, 1.0)
  th = th.replace(source_on=th.source_on.at[..., source].set(on))
  if temperature is not None:
    th = th.replace(source_temperature=th.source_temperature.at[..., source].set(temperature))
  return ds.replace(thermal=th)


def touching(tm: ThermalModel, binding, d) -> jax.Array:
  """f32[L, S]: 1 where an active contact joins link l's geoms and source s's geom.

  Uses the same contact slots as mechanical damage (``d._impl.contact``, MJX-JAX's layout); an
  inactive slot (``dist − includemargin ≥ 0``) touches nothing.
  """
  con = d._impl.contact
  if con.dist.shape[0] == 0:
    return jnp.zeros((binding.num_links, tm.num_sources), jnp.float32)
  return touching_pairs(tm, binding, con.geom, con.dist - con.includemargin < 0)


def touching_pairs(tm: ThermalModel, binding, geom: jax.Array, active: jax.Array) -> jax.Array:
  """f32[L, S] of :func:`touching` from any backend's contacts: geom pairs i32[C, 2] (−1: none), active bool[C]."""
  L, S = binding.num_links, tm.num_sources
  if geom.shape[0] == 0 or S == 0 or L == 0:
    return jnp.zeros((L, S), jnp.float32)
  g = jnp.asarray(geom)
  valid = active & (g[:, 0] >= 0) & (g[:, 1] >= 0)
  gc = jnp.maximum(g, 0)
  geom_link = jnp.asarray(binding.geom_link)
  geom_source = jnp.asarray(tm.geom_source)
  links, srcs = jnp.arange(L), jnp.arange(S)
  touch = jnp.zeros((L, S), bool)
  for a, b in ((0, 1), (1, 0)):  # both orders of the geom pair (static)
    link, src = geom_link[gc[:, a]], geom_source[gc[:, b]]
    # [C, L, S] match reduced over contacts: fuses into one pass (a scatter-max would not)
    hit = (valid[:, None, None] & (link[:, None, None] == links[None, :, None])
           & (src[:, None, None] == srcs[None, None, :]))
    touch = touch | jnp.any(hit, axis=0)
  return touch.astype(jnp.float32)


def link_source_distance(tm: ThermalModel, binding, m, d) -> jax.Array:
  """f32[L, S] signed distance from each tracked link's COM to each source's surface, m."""
  L, S = binding.num_links, tm.num_sources
  com = d.xipos[binding.link_body]  # [L, 3]
  phi, _, order = G.points_to_geoms(tm.shape_groups, d, m, com)
  # columns come grouped by type; put them back in source order
  col = np.full(S, -1, np.int32)
  col[tm.geom_source[order]] = np.arange(order.size, dtype=np.int32)
  far = jnp.full((L, 1), jnp.inf, jnp.float32)
  phi = jnp.concatenate([phi, far], axis=1)  # unsupported geom types: infinitely far
  return phi[:, np.where(col >= 0, col, order.size)]


def advance(m, binding, d, ds, dt, touch=None):
  """One explicit-Euler step of every tracked link's temperature (one environment).

  Reads ``d`` after ``mjx.forward`` (contacts and poses of this substep); writes
  ``ds.temperature`` f32[L] °C. No-op without a temperature config. ``touch``
  f32[L, S]: which links touch which sources, for a backend whose ``d`` has no
  contact list (the native batch reads it from contact sensors); default
  :func:`touching` on ``d``'s contacts.
  """
  tm = binding.thermal
  if tm is None or binding.num_links == 0:
    return ds
  T = ds.temperature
  th = ds.thermal
  t_amb = jnp.float32(tm.ambient)
  cooling = tm.cooling * (t_amb - T)
  if tm.num_sources == 0:
    return ds.replace(temperature=T + dt * cooling)
  r = link_source_distance(tm, binding, m, d)  # [L, S]
  touch = touching(tm, binding, d) if touch is None else jnp.asarray(touch, jnp.float32)
  touch = jnp.maximum(touch, (r < 0).astype(jnp.float32))
  w = jnp.exp(-jnp.maximum(r, 0.0) / tm.reach[None, :])
  # a tracked link that owns a source geom does not exchange heat with itself
  own = jnp.asarray(tm.source_link)[None, :] == jnp.arange(binding.num_links)[:, None]
  k = jnp.where(own, 0.0, tm.conduction[:, None] * touch + tm.radiation[:, None] * w)
  t_src = t_amb + th.source_on * (th.source_temperature - t_amb)  # [S]
  dTdt = jnp.sum(k * (t_src[None, :] - T[:, None]), axis=1) + cooling
  return ds.replace(temperature=T + dt * dTdt)

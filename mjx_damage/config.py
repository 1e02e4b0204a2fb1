"""User configuration: which scene bodies form which entities, what is tracked, overrides.

A config is a dict (or a YAML file holding one)::

    tau: 0.0333                 # reference interval τ of the damage rates, s (optional)
    track: [plate, agent]       # entities to track (optional; default: all listed)
    entities:
      plate:                    # entity name, free text
        params: plate           # table row (DAMAGE_MODEL.md §5); default: the entity name
        bodies: [plate]         # MuJoCo body names = the entity's links; default: [entity name]
        mechanical: {threshold: 40.0}          # entity-wide overrides
        thermal: {t_hot: 50, t_cold: -20, scale: 0.1}   # or null: modality off
        fluid: {threshold: 20, scale: 5}
        links:                  # per-link overrides, keyed by body name
          plate: {mechanical: {scale: 20.0}}
      door:
        params: default
        constraint: true        # joint-limit forces load the joint's child link (or a list of joint names)

Everything is checked by :func:`resolve` against the ``mujoco.MjModel`` before
anything is compiled; every error is a ``ValueError`` whose message starts with
the offending field's path (``entities.plate.mechanical.threshold: ...``).
"""

from __future__ import annotations

import copy
import dataclasses
import os
from typing import Any, Mapping, Optional

import mujoco

from mjx_damage import params as P
from mjx_damage.validate import check_keys as _check_keys
from mjx_damage.validate import fail as _fail
from mjx_damage.validate import mapping as _mapping
from mjx_damage.validate import number

_TOP_KEYS = ("tau", "track", "entities", "temperature", "liquid")
_ENTITY_KEYS = ("params", "bodies", "mechanical", "thermal", "fluid", "links", "heat", "constraint")
_LIMITABLE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
_LINK_KEYS = ("mechanical", "thermal", "fluid")
_FIELDS = {
    "mechanical": ("alpha", "beta", "threshold", "scale"),
    "thermal": ("t_hot", "t_cold", "scale"),
    "fluid": ("threshold", "scale"),
}
_CLASSES = {"mechanical": P.Mechanical, "thermal": P.Thermal, "fluid": P.Fluid}


@dataclasses.dataclass(frozen=True)
class Link:
  name: str  # "entity/body"
  body: str
  body_id: int
  entity: int  # index into ResolvedConfig.entities
  params: P.ObjectParams


@dataclasses.dataclass(frozen=True)
class ResolvedConfig:
  """A validated config bound to one model's body names (plain Python, static)."""

  entities: tuple[str, ...]
  links: tuple[Link, ...]
  tau: float
  raw: Mapping[str, Any]  # the user's config, untouched (nothing the user gave is lost)
  # (joint id, tracked link index) of every joint whose limit force loads its child link
  limit_joints: tuple[tuple[int, int], ...] = ()

  @property
  def link_names(self) -> tuple[str, ...]:
    return tuple(l.name for l in self.links)

  def damage_params(self) -> P.DamageParams:
    return P.stack_link_params([l.params for l in self.links], self.tau)






def _apply(field: str, base, overrides):
  """Apply a modality override mapping (or None = off) to a params dataclass."""
  modality = field.rsplit(".", 1)[-1]
  if overrides is None:
    if modality == "mechanical":
      _fail(field, "mechanical damage cannot be switched off; untrack the entity instead")
    return None
  overrides = _mapping(field, overrides)
  _check_keys(field, overrides, _FIELDS[modality])
  values = {} if base is None else dataclasses.asdict(base)
  for k, v in overrides.items():
    values[k] = number(f"{field}.{k}", v, lo=0.0 if modality != "thermal" or k == "scale" else None)
  missing = [k for k in _FIELDS[modality] if k not in values]
  if missing:
    _fail(field, f"no table row to start from; give all of {', '.join(_FIELDS[modality])} (missing {', '.join(missing)})")
  out = _CLASSES[modality](**values)
  if modality == "thermal" and not out.t_cold < out.t_hot:
    _fail(f"{field}.t_cold", f"must be < t_hot, got t_cold={out.t_cold} t_hot={out.t_hot}")
  return out


def _override(field: str, base: P.ObjectParams, spec: Mapping) -> P.ObjectParams:
  kw = {}
  for modality in ("mechanical", "thermal", "fluid"):
    if modality in spec:
      kw[modality] = _apply(f"{field}.{modality}", getattr(base, modality), spec[modality])
  return dataclasses.replace(base, **kw)


def _limit_joints(field: str, spec, model: mujoco.MjModel, bodies, link_of_body) -> list[tuple[int, int]]:
  """Joints named by an entity's ``constraint`` key → [(joint id, tracked link index)].

  ``true``: every limited hinge/slide joint that moves one of the entity's bodies;
  ``false``: none; a list: exactly those joints (each checked).
  """
  joint_names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)]
  on_entity = [j for j in range(model.njnt) if model.jnt_bodyid[j] in link_of_body]
  if isinstance(spec, bool):
    if not spec:
      return []
    found = [j for j in on_entity if int(model.jnt_type[j]) in _LIMITABLE and model.jnt_limited[j]]
    if not found:
      _fail(field, f"no limited hinge or slide joint moves this entity's bodies {list(bodies)}")
    return [(j, link_of_body[model.jnt_bodyid[j]]) for j in found]
  if isinstance(spec, str) or not isinstance(spec, (list, tuple)) or not spec:
    _fail(field, f"expected true, false or a non-empty list of joint names, got {spec!r}")
  out = []
  for i, name in enumerate(spec):
    f = f"{field}[{i}]"
    if not isinstance(name, str) or name not in joint_names:
      _fail(f, f"unknown joint {name!r} in the model; joints: {', '.join(n for n in joint_names if n)}")
    j = joint_names.index(name)
    if int(model.jnt_type[j]) not in _LIMITABLE:
      _fail(f, f"joint {name!r} is not a hinge or slide joint (only their limits are modelled)")
    if not model.jnt_limited[j]:
      _fail(f, f"joint {name!r} has no limit (give it a range): nothing to force past")
    if j not in on_entity:
      body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.jnt_bodyid[j])
      _fail(f, f"joint {name!r} moves body {body!r}, not one of this entity's bodies {list(bodies)}")
    if any(j == k for k, _ in out):
      _fail(f, f"joint {name!r} listed twice")
    out.append((j, link_of_body[model.jnt_bodyid[j]]))
  return out


def load(config) -> Mapping[str, Any]:
  """A config dict from a dict or a YAML path; the input itself is never modified."""
  if isinstance(config, (str, os.PathLike)):
    import yaml

    if not os.path.isfile(config):
      _fail("config", f"file not found: {os.fspath(config)!r}")
    with open(config) as f:
      config = yaml.safe_load(f)
  return copy.deepcopy(_mapping("config", config))


def resolve(config, model: mujoco.MjModel) -> ResolvedConfig:
  """Validate ``config`` against ``model`` and resolve every tracked link's parameters."""
  cfg = load(config)
  _check_keys("", cfg, _TOP_KEYS)
  tau = number("tau", cfg.get("tau", P.DEFAULT_TAU), positive=True)
  entities = _mapping("entities", cfg.get("entities"))
  if not entities:
    _fail("entities", "empty: nothing to track")

  track = cfg.get("track", list(entities))
  if isinstance(track, str) or not isinstance(track, (list, tuple)):
    _fail("track", f"expected a list of entity names, got {track!r}")
  if not track:
    _fail("track", "empty tracking set")
  for i, name in enumerate(track):
    if name not in entities:
      _fail(f"track[{i}]", f"unknown entity {name!r}; entities: {', '.join(map(str, entities))}")
  if len(set(track)) != len(track):
    _fail("track", f"duplicate entity names in {list(track)}")

  body_names = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i): i for i in range(model.nbody)}
  seen_bodies: dict[str, str] = {}
  links: list[Link] = []
  limit_joints: list[tuple[int, int]] = []
  for ei, ename in enumerate(track):
    f = f"entities.{ename}"
    spec = _mapping(f, entities[ename])
    _check_keys(f, spec, _ENTITY_KEYS)
    row = spec.get("params", ename)
    if not isinstance(row, str):
      _fail(f"{f}.params", f"expected a table row name, got {row!r}")
    try:
      base = P.object_params(row)
    except ValueError as e:
      _fail(f"{f}.params", str(e).split(": ", 1)[1])
    base = _override(f, base, spec)
    bodies = spec.get("bodies", [ename])
    if isinstance(bodies, str) or not isinstance(bodies, (list, tuple)) or not bodies:
      _fail(f"{f}.bodies", f"expected a non-empty list of body names, got {bodies!r}")
    link_over = _mapping(f"{f}.links", spec.get("links", {}))
    for b in link_over:
      if b not in bodies:
        _fail(f"{f}.links.{b}", f"not one of this entity's bodies {list(bodies)}")
    for bi, body in enumerate(bodies):
      if not isinstance(body, str) or body not in body_names:
        _fail(f"{f}.bodies[{bi}]", f"unknown body {body!r} in the model; bodies: {', '.join(n for n in body_names if n)}")
      if body_names[body] == 0:
        _fail(f"{f}.bodies[{bi}]", "the world body cannot be tracked")
      if body in seen_bodies:
        _fail(f"{f}.bodies[{bi}]", f"body {body!r} already belongs to entity {seen_bodies[body]!r}")
      seen_bodies[body] = ename
      lp = base
      if body in link_over:
        lf = f"{f}.links.{body}"
        lspec = _mapping(lf, link_over[body])
        _check_keys(lf, lspec, _LINK_KEYS)
        lp = _override(lf, base, lspec)
      links.append(Link(f"{ename}/{body}", body, body_names[body], ei, lp))
    if "constraint" in spec:
      first = len(links) - len(bodies)
      link_of_body = {body_names[b]: first + i for i, b in enumerate(bodies)}
      limit_joints += _limit_joints(f"{f}.constraint", spec["constraint"], model, bodies, link_of_body)
  for name in entities:
    _mapping(f"entities.{name}", entities[name])
  return ResolvedConfig(tuple(track), tuple(links), tau, cfg, tuple(limit_joints))

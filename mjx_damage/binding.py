"""Binding a damage config to a MuJoCo model: the index bookkeeping every backend needs.

:func:`bind` runs once, in Python, before anything is compiled: it validates the
config, and builds static index arrays (geom → tracked link → entity, each
link's ancestor dofs). Reading signals from simulator state is elsewhere:
link kinematics in :mod:`mjx_damage.kinematics`, contact forces (which depend
on a simulator's contact layout) in each backend (:mod:`mjx_damage.backends`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Optional

import mujoco
import numpy as np

from mjx_damage import config as C
from mjx_damage import liquid as Lq
from mjx_damage import temperature as T
from mjx_damage.params import DamageParams


@dataclasses.dataclass(frozen=True, eq=False)
class Binding:
  """Static description of what is tracked in one model (closed over by compiled steps).

  Index arrays are numpy (static): they shape the computation, they are not data.
  The default per-link parameters live in ``params``; the per-environment copy
  travels in the damage state so it can be vmapped, randomised and swept.
  """

  resolved: C.ResolvedConfig
  geom_link: np.ndarray  # i32[ngeom], tracked link of each geom or −1
  link_body: np.ndarray  # i32[L]
  link_entity: np.ndarray  # i32[L]
  link_root: np.ndarray  # i32[L], root body of each link's kinematic tree
  link_dofs: np.ndarray  # f32[L, nv], 1 where a dof moves the link
  params: DamageParams
  # joints whose limit force loads their child link (config key ``constraint``; mjx_damage.joint_limits)
  limit_joint: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0,), np.int32))  # i32[J]
  limit_link: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0,), np.int32))  # i32[J]
  limit_hinge: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0,), bool))  # bool[J]
  thermal: Any = None  # mjx_damage.temperature.ThermalModel, or None: no heat sources
  liquid: Any = None  # mjx_damage.liquid.LiquidModel, or None: no particles

  @property
  def entity_names(self) -> tuple[str, ...]:
    return self.resolved.entities

  @property
  def link_names(self) -> tuple[str, ...]:
    return self.resolved.link_names

  @property
  def num_links(self) -> int:
    return len(self.link_body)

  @property
  def num_entities(self) -> int:
    return len(self.resolved.entities)

  @property
  def tau(self) -> float:
    return self.resolved.tau


def bind(model: mujoco.MjModel, config) -> Binding:
  """Validate ``config`` against ``model`` and build the static index arrays.

  Args:
    model: the scene's ``mujoco.MjModel`` (not the mjx.Model: names live here).
    config: dict or YAML path, see :mod:`mjx_damage.config`.

  Raises:
    ValueError: naming the offending field, for any malformed config.
  """
  if not isinstance(model, mujoco.MjModel):
    raise ValueError(f"model: expected a mujoco.MjModel, got {type(model).__name__}")
  resolved = C.resolve(config, model)
  link_body = np.array([l.body_id for l in resolved.links], np.int32)
  link_entity = np.array([l.entity for l in resolved.links], np.int32)
  body_link = np.full(model.nbody, -1, np.int32)
  body_link[link_body] = np.arange(len(link_body), dtype=np.int32)
  geom_link = body_link[model.geom_bodyid].astype(np.int32)

  # dof j moves body b iff dof j's body is b or one of b's ancestors.
  link_dofs = np.zeros((len(link_body), model.nv), np.float32)
  for li, b in enumerate(link_body):
    while b > 0:
      adr, num = model.body_dofadr[b], model.body_dofnum[b]
      link_dofs[li, adr : adr + num] = 1.0
      b = model.body_parentid[b]
  binding = Binding(
      resolved=resolved,
      geom_link=geom_link,
      link_body=link_body,
      link_entity=link_entity,
      link_root=model.body_rootid[link_body].astype(np.int32),
      link_dofs=link_dofs,
      params=resolved.damage_params(),
      limit_joint=np.array([j for j, _ in resolved.limit_joints], np.int32),
      limit_link=np.array([l for _, l in resolved.limit_joints], np.int32),
      limit_hinge=np.array([int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) for j, _ in resolved.limit_joints], bool),
  )
  return dataclasses.replace(
      binding,
      thermal=T.build(model, binding, resolved.raw),
      liquid=Lq.build(model, binding, resolved.raw),
  )

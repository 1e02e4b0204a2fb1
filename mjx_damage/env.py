"""Base class for MJX environments whose physics steps through :func:`mjx_damage.physics.step`.

Such an env integrates damage at every physics substep and keeps the
per-environment :class:`~mjx_damage.physics.DamageState` in
``state.info["damage_state"]``; :class:`~mjx_damage.wrapper.DamageWrapper`
recognises it by its ``damage_binding`` attribute and adds health, cost,
reward shaping and metrics on top.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
from brax.envs.base import Env, State
from mujoco import mjx

from mjx_damage import physics
from mjx_damage.binding import bind


class DamageEnv(Env):
  """A Brax ``Env`` over one MJCF scene with damage tracked per substep.

  Subclasses implement ``reset(rng)`` and ``step(state, action)`` using
  :meth:`init_damage` and :meth:`physics_step`; the env object holds only
  static things (models, binding, sizes) — all state is in ``State``.
  """

  def __init__(self, mj_model: mujoco.MjModel, damage_config, n_substeps: int):
    if not isinstance(n_substeps, int) or n_substeps < 1:
      raise ValueError(f"n_substeps: must be a positive int, got {n_substeps!r}")
    self.mj_model = mj_model
    # This process's device: MJX's default, jax.devices()[0], belongs to process 0 when several processes
    # share a run (train.distributed), and a model there cannot be read by the others.
    self.sys = mjx.put_model(mj_model, device=jax.local_devices()[0])
    self.damage_binding = bind(mj_model, damage_config)
    self.n_substeps = n_substeps

  @property
  def dt(self) -> float:
    """Control period, s."""
    return float(self.mj_model.opt.timestep) * self.n_substeps

  @property
  def backend(self) -> str:
    return "mjx"

  @property
  def entity_names(self) -> tuple[str, ...]:
    return self.damage_binding.entity_names

  @property
  def link_names(self) -> tuple[str, ...]:
    return self.damage_binding.link_names

  def init_damage(self, rng: jax.Array) -> physics.DamageState:
    return physics.init_state(self.damage_binding, rng=rng)

  def physics_step(self, data: mjx.Data, ds: physics.DamageState, ctrl: jax.Array):
    """Apply ``ctrl`` for one control period; damage at every substep."""
    return physics.step(self.sys, self.damage_binding, data.replace(ctrl=ctrl), ds, self.n_substeps)

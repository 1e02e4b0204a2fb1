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

from mjx_damage import physics, warp_step
from mjx_damage.binding import bind

PHYSICS_BACKENDS = ("jax", "warp")
WARP_CONTACTS = 32  # default contact places per world with MuJoCo Warp


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
    self.damage_binding = bind(mj_model, damage_config)
    self.n_substeps = n_substeps
    # The physics backend, set on the instance before __init__ runs (as tasks.make sets the robot):
    # "jax" (MJX's JAX implementation, default) or "warp" (MuJoCo Warp, a batch at a time).
    backend = getattr(self, "physics_backend", "jax")
    if backend not in PHYSICS_BACKENDS:
      raise ValueError(f"backend: unknown {backend!r}; valid: {', '.join(PHYSICS_BACKENDS)}")
    self.physics_backend = backend
    # This process's device: MJX's default, jax.devices()[0], belongs to process 0 when several processes
    # share a run (train.distributed), and a model there cannot be read by the others.
    device = jax.local_devices()[0]
    if backend == "warp":
      worlds, contacts = getattr(self, "warp_worlds", 0), getattr(self, "warp_contacts", WARP_CONTACTS)
      for name, v in (("num_envs", worlds), ("warp_contacts", contacts)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
          raise ValueError(f"{name}: backend 'warp' needs a positive int (worlds stepped together / contact "
                           f"places per world), got {v!r}")
      self.warp_worlds, self.warp_contacts = worlds, contacts
      sys = mjx.put_model(mj_model, impl="warp", device=device)
      # the solver's iteration-limit warnings would be printed from the kernels at every step
      self.sys = sys.replace(opt=sys.opt.replace(_impl=sys.opt._impl.replace(warn_overflow=0)))
      self._warp_step = warp_step.env_step(self.sys, self.damage_binding, n_substeps, contacts)
    else:
      self.sys = mjx.put_model(mj_model, device=device)

  @property
  def dt(self) -> float:
    """Control period, s."""
    return float(self.mj_model.opt.timestep) * self.n_substeps

  @property
  def backend(self) -> str:
    return "mjx"

  def make_data(self) -> mjx.Data:
    """A fresh ``mjx.Data`` of ONE environment (vmap it; with Warp, over at most ``warp_worlds`` environments).

    Warp's contact buffer is shared by the batch: ``warp_contacts`` places per world, and its constraint rows
    per world sized for them (4 pyramid rows per condim-3 contact, plus equality and limit rows).
    """
    if self.physics_backend == "warp":
      rows = 4 * self.warp_contacts + 6 * self.mj_model.neq + 2 * self.mj_model.njnt + 8
      return mjx.make_data(self.mj_model, impl="warp", naconmax=self.warp_worlds * self.warp_contacts, njmax=rows)
    return mjx.make_data(self.sys)

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
    if self.physics_backend == "warp":
      return self._warp_step(data.replace(ctrl=ctrl), ds)
    return physics.step(self.sys, self.damage_binding, data.replace(ctrl=ctrl), ds, self.n_substeps)

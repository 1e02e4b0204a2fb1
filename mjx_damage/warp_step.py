"""The damage-aware physics step on MuJoCo Warp (MJX ``impl="warp"``): a batch at a time.

:mod:`mjx_damage.physics` steps one environment and is vmapped; MuJoCo Warp keeps
the contacts of every world in one list (:mod:`mjx_damage.backends.mjx_warp`), so
this step takes the whole batch: ``step(m, binding, d, ds, n_substeps, slots)``
with a leading axis B on ``d``'s public fields and on every leaf of ``ds``.

Each substep runs ``mjx.step`` (MJX's integrators do not run on Warp data, and
``mjx.step`` leaves the forward pass's contacts, constraint forces, ``qacc`` and
kinematics in place), reads the link signals of every world from them, and
applies the same temperature, liquid and damage functions as the MJX-JAX step,
vmapped over the batch.
The order differs from :func:`mjx_damage.physics.substep` only in when the
signals are read (after the integration of the same forward pass instead of
before it); what they are computed from is the same.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import custom_batching
from mujoco import mjx

from mjx_damage import liquid as Lq
from mjx_damage import temperature as T
from mjx_damage.backends import mjx_warp
from mjx_damage.binding import Binding
from mjx_damage.physics import DamageState, apply_signals, begin_step


def substep(m: mjx.Model, binding: Binding, d: mjx.Data, ds: DamageState, slots: int):
  """One physics step of every world with damage; returns ``(d, ds, overflow i32[B])``.

  In :func:`mjx_damage.physics.substep`'s order: temperature, liquid, then the damage of the signals.
  """
  qpos, qvel = d.qpos, d.qvel
  d = jax.vmap(lambda x: mjx.step(m, x))(d)
  wc = mjx_warp.world_contacts(m, d, slots)
  pub = mjx_warp.public(d)
  dt = m.opt.timestep
  tm = binding.thermal
  if tm is not None:
    touch = jax.vmap(lambda g, a: T.touching_pairs(tm, binding, g, a))(wc.geom, wc.active)
    ds = jax.vmap(lambda x, s, t: T.advance(m, binding, x, s, dt, touch=t))(pub, ds, touch)
  ds = jax.vmap(lambda x, s: Lq.advance(m, binding, x, s, dt))(pub, ds)
  signals = mjx_warp.link_signals(binding, m, d, wc, qpos, qvel, ds.temperature, ds.exposure)
  ds = jax.vmap(lambda s, g: apply_signals(s, g, dt))(ds, signals)
  # a world whose contacts or constraint rows overflowed Warp's own buffers lost some uncounted: at least one
  lost = jnp.maximum(wc.overflow, (d._impl.overflow != 0).astype(jnp.int32))
  return d, ds.replace(link_vel=mjx_warp.link_velocities(binding, d)), lost


def step(m: mjx.Model, binding: Binding, d: mjx.Data, ds: DamageState, n_substeps: int = 1, slots: int = 16):
  """``n_substeps`` physics steps of a batch with damage at every one.

  Args:
    m: the model put with ``impl="warp"``; binding: its :class:`Binding`.
    d: the batch's data (``jax.vmap(lambda _: mjx.make_data(model, impl="warp", naconmax=…))``).
    ds: a :class:`DamageState` with a leading batch axis B on every leaf.
    slots: contact places per world read for damage (static).

  Returns:
    ``(d, ds, overflow)``: overflow i32[B] the most contacts a world had beyond ``slots`` in any substep
    (their forces were not counted), at least 1 where Warp's own buffers overflowed (``d._impl.overflow``:
    contacts or constraint rows lost that Warp does not count); also ``ds.contacts_dropped``.
  """
  ds = jax.vmap(begin_step)(ds)

  def body(carry, _):
    d, ds, worst = carry
    d, ds, over = substep(m, binding, d, ds, slots)
    return (d, ds, jnp.maximum(worst, over)), None

  worst = jnp.zeros((d.qpos.shape[0],), jnp.int32)
  (d, ds, worst), _ = jax.lax.scan(body, (d, ds, worst), None, length=n_substeps)
  return d, ds.replace(contacts_dropped=worst), worst


def is_impl_path(path) -> bool:
  """Whether a pytree path (``jax.tree_util`` keys) lies under ``mjx.Data._impl``, the implementation's
  private data: on MuJoCo Warp, among others, the contact list of the whole batch (no per-env axis)."""
  return any(getattr(k, "name", None) == "_impl" for k in path)


def freeze(finished, state, nxt):
  """``state`` where ``finished``, else ``nxt`` (one episode's env state; vmapped over the batch).

  The physics backend's private data (``pipeline_state._impl``) always comes from ``nxt``: MuJoCo
  Warp keeps the contacts of the whole batch in one list there, with no per-episode axis to select
  along, and nothing reads a finished episode's ``_impl`` (summaries and recordings read health,
  metrics and public fields; a frozen episode's next step is discarded again)."""
  return jax.tree_util.tree_map_with_path(
      lambda path, old, new: new if is_impl_path(path) else jnp.where(finished, old, new), state, nxt)


def _vmapped_again(tree) -> bool:
  """Whether an array of ``tree`` is a batch tracer, i.e. an enclosing ``jax.vmap`` is batching the caller."""
  return any(isinstance(x, jax.core.Tracer) and hasattr(x, "batch_dim") for x in jax.tree.leaves(tree))


def env_step(m: mjx.Model, binding: Binding, n_substeps: int, slots: int):
  """``step(d, ds) -> (d, ds)`` of ONE environment that steps the whole batch at once when vmapped.

  Environments are written per environment and vmapped (Brax's ``VmapWrapper``, the trainers, the
  evaluator), but MuJoCo Warp's contacts are one list for the batch: under ``jax.vmap`` this function's
  batching rule (``jax.custom_batching.custom_vmap``) receives the batch and runs :func:`step` on it.
  Called on one environment it runs as a batch of one. One level of vmap: the batch is the worlds that
  ``mjx.make_data(..., impl="warp", naconmax=…)`` was vmapped over; a second, enclosing vmap (seeds × envs)
  raises ValueError while tracing (it would lose contact damage silently).
  """
  # not at the top: mujoco.mjx.warp.ffi imports warp-lang, an optional extra that only this backend needs
  from mujoco.mjx.warp import ffi as warp_ffi
  from mujoco.mjx.warp import types as warp_types

  ndim = warp_types._NDIM["Data"]  # pylint: disable=protected-access  (fields with a world axis)

  @custom_batching.custom_vmap
  def one(d, ds):
    d1 = jax.tree.map_with_path(
        lambda p, x: warp_ffi._expand_dim_from_path(p, x, ndim) if is_impl_path(p) else x[None], d)
    d2, ds2, _ = step(m, binding, d1, jax.tree.map(lambda x: x[None], ds), n_substeps, slots)
    return (jax.tree.map_with_path(lambda p, x, x0: warp_ffi._squeeze_dim(x, x0) if is_impl_path(p) else x[0], d2, d),
            jax.tree.map(lambda x: x[0], ds2))

  @one.def_vmap
  def batched(axis_size, in_batched, d, ds):
    bd, bds = in_batched
    if _vmapped_again((d.qpos, d.ctrl, ds)):
      # An outer vmap would batch this rule's Warp calls itself: the physics comes out right, but each outer
      # element's contact list is not the one the damage readout indexes, so contact damage would be lost.
      raise ValueError("backend: warp steps the worlds of ONE jax.vmap; this step is vmapped twice (e.g. seeds x "
                       "envs): vmap once over the num_envs worlds (a trainer: one seed per program), or use "
                       "backend 'jax'")
    # a public field or damage leaf the same for every world (e.g. one ctrl for all) gets the batch axis
    d = jax.tree.map_with_path(
        lambda p, x, b: x if (b or is_impl_path(p)) else jnp.broadcast_to(x, (axis_size,) + x.shape), d, bd)
    ds = jax.tree.map(lambda x, b: x if b else jnp.broadcast_to(x, (axis_size,) + x.shape), ds, bds)
    d2, ds2, _ = step(m, binding, d, ds, n_substeps, slots)
    out_d = jax.tree.map_with_path(lambda p, x, b: b if is_impl_path(p) else True, d2, bd)
    return (d2, ds2), (out_d, jax.tree.map(lambda _: True, ds2))

  return one

"""Native MuJoCo, many environments: link signals from per-link sensors that MuJoCo computes in C.

:mod:`mjx_damage.backends.native` reads ``data.contact``/``efc_force`` with numpy,
one ``MjData`` at a time. A batch stepped by :class:`mujoco.batch.Batch` on C
threads exposes no contacts, only bound fields such as ``sensordata`` recorded
at every substep. So the scene gets, appended after its own sensors, three
sensors per tracked link ``l`` (its body):

* ``contact`` (``body1`` = the link, ``num`` = ``slots``, ``reduce="maxforce"``,
  data ``found force normal tangent``): the ``slots`` largest contacts on the
  link. The sensor reports the force the link exerts (contact frame); the
  force ON the link, world frame, is −(f₀·n + f₁·t + f₂·(n×t)).
* ``framelinacc`` (``objtype="body"``: the link's COM): linear acceleration
  including −gravity (MuJoCo's accelerometer convention); adding the model's
  gravity gives the kinematic acceleration of :func:`native.link_acceleration`.
* ``framelinvel``: COM velocity, f32[3] m/s (``DamageState.link_vel``).

With heat sources, one more ``contact`` sensor per (link, source) pair (``body1`` = the link,
``geom2`` = the source's geom, data ``found``): how many contacts join them, the contact half of
:func:`mjx_damage.temperature.touching` (:func:`touching`).

Sensors are evaluated by ``mj_forward`` inside ``mj_step``, at the point where
:func:`mjx_damage.native.substep` reads its signals. A link touching more than
``slots`` contacts at once keeps the ``slots`` largest (:func:`dropped_contacts`
counts the rest).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from mjx_damage.signals import LinkSignals

if TYPE_CHECKING:  # annotation only
  from mjx_damage.binding import Binding

# contact-sensor data fields per slot: found (1), force (3), normal (3), tangent (3)
_CONTACT_DATA = (1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)) | (
    1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE)) | (
    1 << int(mujoco.mjtConDataField.mjCONDATA_NORMAL)) | (
    1 << int(mujoco.mjtConDataField.mjCONDATA_TANGENT))
SLOT_SIZE = 10
_REDUCE_MAXFORCE = 2  # the contact sensor's reduce="maxforce"
_FOUND = 1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)


@struct.dataclass
class SensorLayout:
  """Where the damage sensors sit in ``sensordata`` (static; hashable for jit).

  offset: first sensordata index of the damage sensors (the scene's own come first)
  num_links: L; slots: contacts kept per link
  gravity: the model's gravity, m/s² (3 floats)
  num_sources: S, heat sources with a (link, source) contact count each (0: no heat sources)
  """

  offset: int = struct.field(pytree_node=False)
  num_links: int = struct.field(pytree_node=False)
  slots: int = struct.field(pytree_node=False)
  gravity: tuple = struct.field(pytree_node=False)
  num_sources: int = struct.field(pytree_node=False, default=0)

  @property
  def size(self) -> int:
    """sensordata entries the damage sensors take."""
    return self.num_links * (self.slots * SLOT_SIZE + 6 + self.num_sources)


def add_sensors(spec: mujoco.MjSpec, binding: "Binding", model: mujoco.MjModel, slots: int) -> SensorLayout:
  """Append the damage sensors of every tracked link to ``spec`` (the scene of ``model``), in place.

  ``model`` is the compiled scene (for body names and the existing sensordata size).
  Raises ValueError for ``slots`` < 1.
  """
  if isinstance(slots, bool) or not isinstance(slots, int) or slots < 1:
    raise ValueError(f"slots: must be an int >= 1, got {slots!r}")
  names = [model.body(int(b)).name for b in binding.link_body]
  for name in names:
    s = spec.add_sensor(type=mujoco.mjtSensor.mjSENS_CONTACT, objtype=mujoco.mjtObj.mjOBJ_BODY, objname=name)
    s.intprm[0], s.intprm[1], s.intprm[2] = _CONTACT_DATA, _REDUCE_MAXFORCE, slots
  for kind in (mujoco.mjtSensor.mjSENS_FRAMELINACC, mujoco.mjtSensor.mjSENS_FRAMELINVEL):
    for name in names:
      spec.add_sensor(type=kind, objtype=mujoco.mjtObj.mjOBJ_BODY, objname=name)
  tm = binding.thermal
  num_sources = 0 if tm is None else int(tm.num_sources)
  if num_sources:
    # each source is one geom, named in the temperature config
    sources = [model.geom(int(np.flatnonzero(np.asarray(tm.geom_source) == s)[0])).name for s in range(num_sources)]
    for name in names:
      for src in sources:
        s = spec.add_sensor(type=mujoco.mjtSensor.mjSENS_CONTACT, objtype=mujoco.mjtObj.mjOBJ_BODY, objname=name,
                            reftype=mujoco.mjtObj.mjOBJ_GEOM, refname=src)
        s.intprm[0], s.intprm[1], s.intprm[2] = _FOUND, 0, 1
  return SensorLayout(int(model.nsensordata), binding.num_links, slots,
                      tuple(float(g) for g in model.opt.gravity), num_sources)


def _split(layout: SensorLayout, sensordata):
  L, K = layout.num_links, layout.slots
  s = sensordata[..., layout.offset: layout.offset + layout.size]
  con = s[..., : L * K * SLOT_SIZE].reshape(s.shape[:-1] + (L, K, SLOT_SIZE))
  rest = s[..., L * K * SLOT_SIZE: L * (K * SLOT_SIZE + 6)].reshape(s.shape[:-1] + (2, L, 3))
  return con, rest[..., 0, :, :], rest[..., 1, :, :]


def touching(layout: SensorLayout, sensordata) -> jnp.ndarray:
  """f32[L, S]: 1 where a contact joins link l and heat source s, from one substep's ``sensordata``
  (:func:`mjx_damage.temperature.touching`'s contact test, read from the (link, source) sensors)."""
  L, S = layout.num_links, layout.num_sources
  start = layout.offset + L * (layout.slots * SLOT_SIZE + 6)
  found = jnp.asarray(sensordata, jnp.float32)[..., start: start + L * S].reshape(L, S)
  return (found > 0).astype(jnp.float32)


def link_signals(layout: SensorLayout, sensordata, temperature, exposure) -> LinkSignals:
  """:class:`LinkSignals` of one environment at one substep from its ``sensordata`` f[nsensordata].

  forces f32[L·slots, 3] N (unused slots zero), force_link i32[L·slots]. Pure jnp: jit/vmap it.
  """
  con, acc, _ = _split(layout, jnp.asarray(sensordata, jnp.float32))
  L, K = layout.num_links, layout.slots
  used = jnp.arange(K)[None, :] < con[:, :1, 0]  # [L, K]: slot k holds one of the found contacts
  f, n, t = con[..., 1:4], con[..., 4:7], con[..., 7:10]
  world = f[..., :1] * n + f[..., 1:2] * t + f[..., 2:3] * jnp.cross(n, t)
  forces = jnp.where(used[..., None], -world, 0.0).reshape(L * K, 3)
  force_link = jnp.repeat(jnp.arange(L, dtype=jnp.int32), K)
  link_acc = acc + jnp.asarray(layout.gravity, jnp.float32)
  return LinkSignals(forces, force_link, link_acc, temperature, exposure)


def link_velocity(layout: SensorLayout, sensordata) -> jnp.ndarray:
  """COM velocity of each tracked link, f32[L, 3] m/s, from one substep's ``sensordata``."""
  return _split(layout, jnp.asarray(sensordata, jnp.float32))[2]


def dropped_contacts(layout: SensorLayout, sensordata) -> np.ndarray:
  """Contacts beyond ``slots`` per link (not seen by the damage), i32[..., L] (numpy, any leading axes)."""
  con, _, _ = _split(layout, np.asarray(sensordata))
  return np.maximum(con[..., 0, 0] - layout.slots, 0).astype(np.int32)

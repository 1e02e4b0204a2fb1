"""Compatibility with the pinned brax (0.14.2) on newer jax.

brax's ``ppo.train`` (and ``pmap.bcast_local_devices``) call
``jax.device_put_replicated``, which jax removed in 0.10. :func:`install`
restores it — a copy of the value on each device, stacked along a new leading
axis and laid out one slice per device, exactly what ``jax.pmap`` consumes — and
only when jax lacks it. Importing :mod:`mjx_damage` installs it.

:func:`import_mjx_quietly` imports ``mujoco.mjx`` without the two "Failed to
import warp" lines MJX 3.17 prints when the optional warp-lang is absent (the
JAX implementation, which mjx_damage uses, does not need it).
"""

from __future__ import annotations

import contextlib
import io
import sys

import jax
import jax.numpy as jnp
import numpy as np


def _device_put_replicated(x, devices):
  devices = list(devices)
  if not devices:
    raise ValueError("devices: empty device list")
  mesh = jax.sharding.Mesh(np.array(devices), ("replica",))
  sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("replica"))

  def put(a):
    a = jnp.asarray(a)
    return jax.device_put(jnp.broadcast_to(a[None], (len(devices),) + a.shape), sharding)

  return jax.tree.map(put, x)


def install() -> bool:
  """Add ``jax.device_put_replicated`` if missing; True when it was added."""
  if hasattr(jax, "device_put_replicated"):
    return False
  jax.device_put_replicated = _device_put_replicated
  return True


def import_mjx_quietly() -> None:
  """Import ``mujoco.mjx`` once, keeping only what it prints about anything but warp."""
  if "mujoco.mjx" in sys.modules:
    return
  buf = io.StringIO()
  with contextlib.redirect_stdout(buf):
    import mujoco.mjx  # noqa: F401
  rest = [line for line in buf.getvalue().splitlines()
          if not line.startswith(("Failed to import warp", "Failed to import mujoco_warp"))]
  if rest:
    print("\n".join(rest))

"""Will a batch fit? Device memory of an evaluation or a training run, estimated before compiling.

A batch too large for the device used to end in an allocator traceback after
minutes of compiling (GPU), or in swapping and silence (CPU). Here the peak is
estimated from sizes known before anything compiles and a batch that cannot fit
is refused with one line naming the flag and the largest value that fits.

Model (bytes; ``state`` = one env's Brax ``State`` — ``mjx.Data`` with its
contacts and constraint rows, damage state, observation — from
``jax.eval_shape(env.reset)``, i.e. tracing only; ``P`` = liquid particles per env)::

    per env:     step = state × K + pairs,   pairs = P² × 4 bytes × K_PAIRS
    evaluation:  episodes × (state × K_EVAL + pairs)
    training:    seeds × (num_envs × (state × K_TRAIN_STATE + pairs)
                          + sequences × unroll_length × transition × K_TRAIN_DATA)
    transition = 4 bytes × (2·obs + 2·action + 8)   (obs, next obs, action, raw action, scalars)

The liquid term is separate because the particle pass holds [P, P] temporaries
(pair distances, overlaps) that dwarf the state: pour_water's 128 particles
take 16× its state in an evaluation step.

The factors cover what XLA keeps alive besides the state itself (the scan
carry's copies, the Newton solver's and collision's temporaries, the shuffled
minibatch copies). They were measured with XLA's own ``memory_analysis()`` of
the compiled programs (``benchmarks/memory_estimate.py``, results in
``benchmarks/results/memory_estimate_cpu.md``: the largest per-env ratio over the
measured tasks, rounded up), so the estimate is an upper bound for those
programs; it is still an estimate, and :data:`HEADROOM` of the free memory is
kept for XLA's own buffers and fragmentation.
"""

from __future__ import annotations

import os
from typing import NamedTuple, Optional

import jax
import numpy as np
from mujoco import mjx

K_EVAL = 3.0
K_TRAIN_STATE = 6.0
K_TRAIN_DATA = 4.0
K_PAIRS = 8.0  # f32 [P, P] arrays alive at once in the liquid pass
HEADROOM = 0.85  # fraction of the free memory a batch may plan to use


def tree_bytes(tree) -> int:
  """Total bytes of the array leaves (or ShapeDtypeStructs) of ``tree``."""
  return int(sum(np.prod(x.shape, dtype=np.int64) * np.dtype(x.dtype).itemsize for x in jax.tree.leaves(tree)))


class Footprint(NamedTuple):
  """What one env of a task weighs: its ``State`` (bytes) and its liquid particles (0 without liquid)."""

  state: int
  particles: int


STATE_EXTRA = 4096  # bytes: observation, metrics and info scalars of a State besides data and damage state


def footprint(env) -> Footprint:
  """:class:`Footprint` of one env, traced, never compiled.

  A damage env (``sys`` + ``init_damage``): ``mjx.Data`` shapes (``make_data``, which
  ``reset`` returns with the same shapes) + the damage state twice (the wrapper keeps
  the episode's initial one too) + :data:`STATE_EXTRA`. Tracing ``reset`` itself runs
  the whole forward pass in Python (seconds on a busy CPU; tens with liquid), and a warm
  command that loads its traced program should not pay that for an estimate. Any
  other env: ``jax.eval_shape(env.reset)``.
  """
  base = getattr(env, "unwrapped", env)
  if hasattr(base, "sys") and hasattr(base, "init_damage"):
    # DamageEnv.make_data: the data of its physics backend (MuJoCo Warp's differs from MJX-JAX's)
    make = getattr(base, "make_data", None) or (lambda: mjx.make_data(base.sys))
    data = jax.eval_shape(make)
    ds = jax.eval_shape(base.init_damage, jax.random.PRNGKey(0))
    liquid = getattr(ds, "liquid", None)
    particles = 0 if liquid is None else int(liquid.pos.shape[0])
    return Footprint(tree_bytes(data) + 2 * tree_bytes(ds) + STATE_EXTRA, particles)
  shape = jax.eval_shape(env.reset, jax.random.PRNGKey(0))
  particles = 0
  for path, leaf in jax.tree_util.tree_flatten_with_path(shape)[0]:
    if jax.tree_util.keystr(path).endswith("['damage_state'].liquid.pos"):
      particles = int(leaf.shape[0])
  return Footprint(tree_bytes(shape), particles)


def state_bytes(env) -> int:
  """Bytes of one env's ``State`` (``env.reset`` traced, not compiled)."""
  return footprint(env).state


def pair_bytes(particles: int) -> int:
  """Bytes of the liquid pass's pairwise temporaries per env."""
  return int(4 * particles * particles * K_PAIRS)


def transition_bytes(obs_size: int, action_size: int) -> int:
  """Bytes of one stored training transition (observation, next observation, actions, scalars)."""
  return 4 * (2 * int(obs_size) + 2 * int(action_size) + 8)


def eval_bytes(state: int, episodes: int, particles: int = 0) -> int:
  """Estimated peak bytes of evaluating ``episodes`` episodes at once (one env state ``state`` bytes)."""
  return int(episodes * (state * K_EVAL + pair_bytes(particles)))


def train_bytes(state: int, obs_size: int, action_size: int, num_envs: int, sequences: int,
                unroll_length: int, seeds: int = 1, particles: int = 0) -> int:
  """Estimated peak bytes of one training iteration of ``seeds`` seeds (module docstring)."""
  per_seed = (num_envs * (state * K_TRAIN_STATE + pair_bytes(particles))
              + sequences * unroll_length * transition_bytes(obs_size, action_size) * K_TRAIN_DATA)
  return int(seeds * per_seed)


def available_bytes(device=None) -> Optional[int]:
  """Free memory of ``device`` (default: JAX's first): the allocator's limit minus what is in use on
  an accelerator, ``MemAvailable`` on the CPU; None when the platform does not say."""
  device = jax.devices()[0] if device is None else device
  if device.platform != "cpu":
    stats = device.memory_stats() or {}
    if "bytes_limit" not in stats:
      return None
    return int(stats["bytes_limit"] - stats.get("bytes_in_use", 0))
  try:
    with open("/proc/meminfo") as f:
      for line in f:
        if line.startswith("MemAvailable:"):
          return int(line.split()[1]) * 1024
  except OSError:
    pass
  try:
    return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
  except (ValueError, OSError, AttributeError):
    return None


def _gib(n: float) -> str:
  return f"{n / 2**30:.1f} GiB"


def check_fits(field: str, value: int, needed: int, per_unit: float, available: Optional[int],
               what: str = "this batch") -> None:
  """Raise ``ValueError("<field>: ...")`` when ``needed`` bytes exceed the usable free memory.

  ``per_unit``: estimated bytes per unit of ``value`` (to say the largest value that fits).
  ``available`` None (unknown) accepts everything.
  """
  if available is None:
    return
  usable = HEADROOM * available
  if needed <= usable:
    return
  largest = int(usable // per_unit) if per_unit > 0 else 0
  raise ValueError(f"{field}: {value} needs about {_gib(needed)} of device memory for {what}, "
                   f"{_gib(available)} is free; the largest that fits is about {largest}")

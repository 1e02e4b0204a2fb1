"""Data-parallel training: a run's seeds and env batches laid across a device mesh, one compiled program.

Layout. The D devices of a run (:func:`train.distributed.select_devices`;
one process or several) form a 2-D :class:`jax.sharding.Mesh` with axes
``(seeds, envs)``: the seed axis takes ``gcd(S, D)`` devices (seeds never
exchange anything, so splitting them costs no communication), and each
seed's env batch is split over the other ``D / gcd(S, D)``. In the
:class:`~train.iteration.TrainState` (leading seed axis S) the leaves batched
over envs (``env_state``, ``episode``) are sharded ``P(seeds, envs)``;
everything else (weights, optimizer, normaliser, multiplier, RNG) is
``P(seeds)``, i.e. replicated over the env shards.

Why ``shard_map`` with explicit collectives rather than sharded arrays under
plain ``jit`` (GSPMD inserting the all-reduces):

* the env step — MJX's constraint solver runs ``lax.while_loop``s whose stop
  test, vmapped over the batch, is a reduction over all envs. Partitioned by
  GSPMD, every solver iteration of every substep becomes a cross-device
  all-reduce; under ``shard_map`` each device runs the single-device step on
  its own envs and talks to no one until the update;
* the update — PPO's shuffle permutes the whole batch every epoch; under
  GSPMD a global permutation moves every device's rollout to the others
  (and, unconstrained, replicates the loss). Here each device shuffles its
  own sequences into its share of each minibatch, as brax's multi-device PPO
  does, and only gradients (mean), normaliser sums, loss metrics and episode
  sums cross devices: a few hundred kB per SGD step;
* what crosses devices is written where it happens (``Trainer(axis_name=)``,
  ``_psum``/``_pmean`` in :mod:`train.iteration`), not inferred by the
  partitioner, so the scaling is predictable.

Partitioner. With more than one device, :func:`make_mesh` (and
:class:`train.evaluate.Evaluator`, also ``shard_map``) switches JAX to
its GSPMD partitioner (``jax_use_shardy_partitioner=False``) for the rest of
the process. jaxlib 0.11.2's XLA:GPU segfaults while compiling the training
iteration on 2 GPUs in its Shardy-to-HLO export pass (``shardy-xla``, the
last pass dumped before the crash), even for a toy env with no collectives
at all (a 2-seed run, one seed per GPU); the same runs compile and train with
GSPMD. The program is all ``shard_map`` (manual), so the partitioner only
places its inputs and outputs: results do not depend on it. Set
``MJX_DAMAGE_SHARDY=1`` to keep Shardy (e.g. to check a newer jaxlib).

The price: with more than one env shard a run is not the one-device run
spread out — advantages are normalised within each shard's part of a
minibatch and sampling keys are folded with the shard index — so it is a
different (equally valid) draw. With one env shard (one device, or one seed
per device) the per-shard program is exactly the single-device one:
identical results (tests/test_multi.py). Runs of the same mesh shape agree
whether its devices sit in one process or several.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Callable, Sequence

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from train.config import PPOConfig

if TYPE_CHECKING:  # the CLI checks layouts before importing the trainer (brax)
  from train.iteration import TrainState

SEEDS, ENVS = "seeds", "envs"


def shape(num_devices: int, num_seeds: int) -> tuple[int, int]:
  """(seed shards, env shards) of the mesh for D devices and S seeds."""
  s = math.gcd(num_seeds, num_devices)
  return s, num_devices // s


def check_layout(cfg: PPOConfig, num_devices: int) -> None:
  """The global batch must split evenly over the env shards; ``ValueError("--devices: ...")`` otherwise."""
  _, shards = shape(num_devices, cfg.num_seeds)
  for name, v in (("num_envs", cfg.num_envs), ("batch_size", cfg.minibatch_sequences)):
    if v % shards:
      raise ValueError(f"--devices: {num_devices} device(s) split each seed's envs {shards} ways; "
                       f"{name} {v} is not divisible by {shards}")


def use_gspmd(num_devices: int) -> bool:
  """Before a D-device program compiles: GSPMD instead of Shardy when D > 1 (module docstring, Partitioner).

  Returns whether Shardy is off now. Global to the process, as JAX's partitioner choice is."""
  if num_devices > 1 and os.environ.get("MJX_DAMAGE_SHARDY", "0") != "1":
    jax.config.update("jax_use_shardy_partitioner", False)
  return not jax.config.jax_use_shardy_partitioner


def make_mesh(devices: Sequence, num_seeds: int) -> Mesh:
  use_gspmd(len(devices))
  seeds, envs = shape(len(devices), num_seeds)
  return Mesh(np.asarray(devices, dtype=object).reshape(seeds, envs), (SEEDS, ENVS))


def axis_name(mesh: Mesh):
  """The axis the Trainer reduces over: ``envs`` when the env batch is split, else None (no collectives)."""
  return ENVS if mesh.shape[ENVS] > 1 else None


def state_specs(ts: "TrainState") -> "TrainState":
  """PartitionSpec per leaf of a (seed-batched) TrainState: env-batched leaves over (seeds, envs)."""
  specs = jax.tree.map(lambda _: P(SEEDS), ts)
  env = lambda tree: jax.tree.map(lambda _: P(SEEDS, ENVS), tree)  # noqa: E731
  return specs.replace(env_state=env(ts.env_state), episode=env(ts.episode))


def shardings(mesh: Mesh, specs):
  return jax.tree.map(lambda s: NamedSharding(mesh, s), specs, is_leaf=lambda x: isinstance(x, P))


def put(tree, shardings_):
  """Host (numpy) leaves → global arrays laid out as ``shardings_``; every process passes the same values."""
  return jax.tree.map(lambda a, s: jax.make_array_from_callback(np.shape(a), s, lambda idx: np.asarray(a)[idx]),
                      tree, shardings_)


def per_seed(fn: Callable, mesh: Mesh, in_specs, out_specs, donate: bool = False):
  """``jit(shard_map(vmap(fn)))``: ``fn`` of one seed's state, run on every shard of every seed."""
  # check_vma=False: MJX's solver (lax.cond over batch-varying values) does not type-check under
  # shard_map's varying-axis rules; the outputs given P(seeds) are equal on every env shard by
  # construction (they come out of psum/pmean or from values that were), see train.iteration.
  sharded = jax.shard_map(jax.vmap(fn), mesh=mesh, in_specs=(in_specs,), out_specs=out_specs, check_vma=False)
  # Explicit output shardings: left to jit, shard_map's outputs come back as P() where the spec says P(seeds)
  # on a size-1 seed axis — the same layout, but a different jit cache key, so the next iteration, fed that
  # output, compiled the whole program a second time (seconds on CPU, tens on GPU, inside the timed
  # iterations). Inputs stay unconstrained, so a state laid out otherwise (a copy, a reload) is accepted.
  return jax.jit(sharded, out_shardings=shardings(mesh, out_specs), donate_argnums=0 if donate else ())

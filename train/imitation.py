"""What every imitation-learning policy here shares: normalisation, the one-jit trainer, seed handling.

:func:`fit` trains one network per seed in ONE compiled call:
``jit(vmap over seeds of (init; lax.scan over gradient steps))``, each step a
minibatch drawn uniformly (with replacement) from the training arrays, which
are passed as arguments (not baked into the executable). :mod:`train.bc` and
:mod:`train.flow_policy` supply the network's ``init``/``loss``; their
policies are ``parametrized_policy(apply, params)`` (:mod:`train.evaluate`),
so the evaluator takes each seed's weights as data and compiles once per
policy class and task.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_damage import data as D

OBS_KEY = "state"


class FitResult(NamedTuple):
  """params: the trained weights, every leaf with a leading seed axis [S, ...]; losses: f32[S, steps]."""

  params: dict
  losses: jax.Array


def normalizer(x: np.ndarray, min_std: float = 1e-3) -> dict:
  """Per-feature mean and std of ``x`` f32[N, D] (std floored at ``min_std``): {"mean", "std"} f32[D]."""
  x = np.asarray(x, np.float64)
  return {"mean": x.mean(0).astype(np.float32), "std": np.maximum(x.std(0), min_std).astype(np.float32)}


def normalize(norm: dict, x: jax.Array) -> jax.Array:
  return (x - norm["mean"]) / norm["std"]


def check_fit_args(seeds, steps, batch) -> list[int]:
  seeds = list(seeds)
  if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
    raise ValueError(f"seeds: need one or more ints >= 0, got {seeds!r}")
  for name, v in (("steps", steps), ("batch", batch)):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
      raise ValueError(f"{name}: must be an int >= 1, got {v!r}")
  return [int(s) for s in seeds]


def transitions_of(ds: D.Dataset) -> dict:
  """Flat kept transitions of ``ds`` (:func:`mjx_damage.data.transitions`), checked non-empty."""
  if OBS_KEY not in ds.obs:
    raise ValueError(f"dataset: needs obs key {OBS_KEY!r}, has {sorted(ds.obs)}")
  tr = D.transitions(ds)
  if tr["actions"].shape[0] == 0:
    raise ValueError(f"dataset: no kept transitions (task {ds.env_name!r})")
  return tr


def fit(init: Callable, loss: Callable, data: dict, seeds: Sequence[int], steps: int, batch: int,
        optimizer: optax.GradientTransformation) -> FitResult:
  """Train ``init(key) -> params`` on ``loss(params, batch_dict, key) -> f32[]`` for each seed, one jit.

  ``data``: dict of arrays with a common leading axis N (the training examples).
  """
  seeds = check_fit_args(seeds, steps, batch)
  n = int(jax.tree.leaves(data)[0].shape[0])

  def one(key, data):
    k_init, k_loop = jax.random.split(key)
    params = init(k_init)
    opt = optimizer.init(params)

    def body(carry, k):
      params, opt = carry
      k_idx, k_loss = jax.random.split(k)
      idx = jax.random.randint(k_idx, (batch,), 0, n)
      value, grads = jax.value_and_grad(loss)(params, jax.tree.map(lambda a: a[idx], data), k_loss)
      updates, opt = optimizer.update(grads, opt, params)
      return (optax.apply_updates(params, updates), opt), value

    (params, _), losses = jax.lax.scan(body, (params, opt), jax.random.split(k_loop, steps))
    return params, losses

  keys = jnp.stack([jax.random.PRNGKey(s) for s in seeds])
  params, losses = jax.jit(jax.vmap(one, in_axes=(0, None)))(keys, jax.tree.map(jnp.asarray, data))
  return FitResult(params, losses)


def seed_params(params, i: int):
  """Seed ``i``'s weights out of a stacked [S, ...] pytree."""
  return jax.tree.map(lambda a: a[i], params)

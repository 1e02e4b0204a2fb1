"""Behaviour cloning: a Gaussian MLP policy fitted to demonstration transitions (flax + optax).

``π(a | o) = N(μ(o), diag σ(o)²)``, an MLP on the normalised observation
(:func:`train.imitation.normalizer` over the training set) with two heads;
trained by minimising the negative log-likelihood of the demonstrated actions
(actions are already in [−1, 1]), one network per seed in one compiled call
(:func:`train.imitation.fit`). The policy acts with the mean, clipped to
[−1, 1]: deterministic, as BC policies are usually evaluated.

::

    res = train_bc(dataset, seeds=[0, 1, 2], steps=2000)
    policy = bc_policy(res, seed_index=0)        # jittable policy(state, rng) -> action
    train.evaluate.evaluate(env, policy, episodes=256, seed=0)
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax

from mjx_damage import data as D
from train import imitation as IL
from train.evaluate import parametrized_policy

LOG_STD_MIN, LOG_STD_MAX = -5.0, 1.0


class GaussianMLP(nn.Module):
  """obs f32[..., D] (normalised) → (mean f32[..., A], log_std f32[..., A])."""

  action_size: int
  hidden: Sequence[int] = (256, 256)

  @nn.compact
  def __call__(self, x):
    for h in self.hidden:
      x = nn.silu(nn.Dense(h)(x))
    mean = nn.Dense(self.action_size)(x)
    log_std = jnp.clip(nn.Dense(self.action_size)(x), LOG_STD_MIN, LOG_STD_MAX)
    return mean, log_std


class BCResult(NamedTuple):
  """params: {"net", "norm"} with a leading seed axis; losses f32[S, steps]; the network's shape."""

  params: dict
  losses: jax.Array
  action_size: int
  hidden: tuple


def nll(mean, log_std, a):
  """Mean Gaussian negative log-likelihood per action dimension (constant dropped)."""
  return jnp.mean(0.5 * jnp.square((a - mean) / jnp.exp(log_std)) + log_std)


def train_bc(ds: D.Dataset, seeds: Sequence[int] = (0,), steps: int = 2000, batch: int = 256,
             lr: float = 1e-3, hidden: Sequence[int] = (256, 256)) -> BCResult:
  """Fit a :class:`GaussianMLP` per seed to the kept transitions of ``ds``."""
  tr = IL.transitions_of(ds)
  obs, act = tr["obs"][IL.OBS_KEY].astype("float32"), tr["actions"]
  norm = IL.normalizer(obs)
  net = GaussianMLP(act.shape[-1], tuple(hidden))

  def init(key):
    return net.init(key, jnp.zeros((obs.shape[-1],)))

  def loss(params, b, key):
    mean, log_std = net.apply(params, IL.normalize(norm, b["obs"]))
    return nll(mean, log_std, b["actions"])

  opt = optax.chain(optax.clip_by_global_norm(5.0), optax.adam(lr))
  res = IL.fit(init, loss, {"obs": obs, "actions": act}, seeds, steps, batch, opt)
  s = res.losses.shape[0]
  norm_s = jax.tree.map(lambda x: jnp.broadcast_to(x, (s,) + x.shape), norm)
  return BCResult({"net": res.params, "norm": norm_s}, res.losses, int(act.shape[-1]), tuple(hidden))


def bc_apply(action_size: int, hidden: Sequence[int] = (256, 256)):
  """``apply(params, state, rng) -> action f32[A]`` (the mean, clipped) for one env."""
  net = GaussianMLP(action_size, tuple(hidden))

  def apply(params, state, rng):
    mean, _ = net.apply(params["net"], IL.normalize(params["norm"], state.obs))
    return jnp.clip(mean, -1.0, 1.0)

  return apply


def bc_policy(res: BCResult, seed_index: int = 0):
  """Seed ``seed_index``'s policy, ``policy(state, rng) -> action``, weights passed to the evaluator as data."""
  return parametrized_policy(bc_apply(res.action_size, res.hidden), IL.seed_params(res.params, seed_index))

"""Behaviour cloning *into the PPO actor*: demonstrations → a checkpoint PPO can fine-tune.

:mod:`train.bc` fits its own Gaussian MLP; fine-tuning it with PPO would need a
translation between two networks. Here the network *is* the trainer's actor —
brax's MLP with a tanh-squashed Gaussian head, the observation normaliser in
brax's running-statistics layout, built from the same :class:`train.config.PPOConfig`
(hidden sizes, activation, normalisation) — fitted by maximum likelihood of the
demonstrated actions (pre-tanh actions ``atanh(clip(a, ±(1 − ε)))``, brax's
``log_prob`` with the tanh Jacobian). One network per seed in one compiled call
(:func:`train.imitation.fit`).

The result is written as an ordinary training checkpoint (``checkpoint.npz``
with the ``policy`` tree and the config; no ``state`` tree, so it cannot be
resumed, only loaded): ``mjx-damage eval --policy checkpoint:RUN`` evaluates it
and ``mjx-damage train --init-from RUN`` starts PPO from it (actor and normaliser
from the checkpoint, critic fresh, optionally warmed up first:
``critic_warmup_iterations``)::

    res = fit_actor(dataset, PPOConfig.preset("playground"), seeds=[0, 1], steps=3000)
    save(res, "runs/bc", task="pour_water")
"""

from __future__ import annotations

import dataclasses
import os
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax
from brax.training.acme import running_statistics

from mjx_damage import data as D
from train import checkpoint as ckpt
from train import imitation as IL
from train import networks as N
from train.config import PPOConfig

ACTION_EPS = 1e-3  # demonstrated actions at ±1 are pulled in by this much before atanh


class ActorFit(NamedTuple):
  """normalizer, policy: brax inference params, every leaf with a leading seed axis [S, ...];
  losses f32[S, steps] (negative log-likelihood per action dimension); the config and sizes."""

  normalizer: running_statistics.RunningStatisticsState
  policy: dict
  losses: jax.Array
  config: PPOConfig
  obs_size: int
  action_size: int


def demo_normalizer(obs: np.ndarray) -> running_statistics.RunningStatisticsState:
  """Brax running statistics over all demonstration observations ``obs`` f32[N, O]."""
  state = running_statistics.init_state(jnp.zeros((obs.shape[-1],), jnp.float32))
  return running_statistics.update(state, jnp.asarray(obs, jnp.float32))


def fit_actor(ds: D.Dataset, cfg: PPOConfig, seeds: Sequence[int] = (0,), steps: int = 3000, batch: int = 256,
              lr: float = 1e-3) -> ActorFit:
  """Fit the PPO actor of ``cfg`` to the kept transitions of ``ds``, one network per seed."""
  tr = IL.transitions_of(ds)
  obs = np.asarray(tr["obs"][IL.OBS_KEY], np.float32)
  act = np.asarray(tr["actions"], np.float32)
  if not np.all(np.isfinite(act)) or np.abs(act).max() > 1.0 + 1e-6:
    raise ValueError("dataset: actions must be finite and in [-1, 1] (the policies' normalised action range)")
  cfg = dataclasses.replace(cfg, seeds=tuple(IL.check_fit_args(seeds, steps, batch))).validate()
  obs_size, action_size = int(obs.shape[-1]), int(act.shape[-1])
  network = N.make_networks(obs_size, action_size, cfg)
  dist = network.parametric_action_distribution
  normalizer = demo_normalizer(obs) if cfg.normalize_observations else running_statistics.init_state(
      jnp.zeros((obs_size,), jnp.float32))
  raw = np.arctanh(np.clip(act, -1.0 + ACTION_EPS, 1.0 - ACTION_EPS)).astype(np.float32)

  def init(key):
    return N.init_policy(network, cfg, action_size, key)

  def loss(params, b, key):
    logits = network.policy_network.apply(normalizer, params, b["obs"])
    return -jnp.mean(dist.log_prob(logits, b["raw"])) / action_size

  opt = optax.chain(optax.clip_by_global_norm(5.0), optax.adam(lr))
  res = IL.fit(init, loss, {"obs": obs, "raw": raw}, cfg.seeds, steps, batch, opt)
  s = len(cfg.seeds)
  norm_s = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), (s,) + jnp.shape(x)), normalizer)
  return ActorFit(norm_s, res.params, res.losses, cfg, obs_size, action_size)


def save(fit: ActorFit, out_dir: str, task: str, task_kwargs: dict | None = None, extra: dict | None = None) -> str:
  """Write ``fit`` as ``out_dir/checkpoint.npz`` (policy tree + config; loadable by :func:`train.load_policy`)."""
  meta = {"task": task, "task_kwargs": task_kwargs or {}, "kind": "bc_actor", "config": fit.config.to_json(),
          "obs_size": fit.obs_size, "action_size": fit.action_size, "iteration": 0, "env_steps": 0,
          "final_loss": [float(x) for x in np.asarray(fit.losses[:, -100:]).mean(-1)], **(extra or {})}
  path = os.path.join(out_dir, ckpt.FILENAME)
  ckpt.save(path, (), (fit.normalizer, fit.policy), meta)
  return path

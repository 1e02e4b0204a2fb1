"""Loading a trained policy from a run directory or checkpoint (evaluate it with train.evaluate)."""

from __future__ import annotations

import os
from typing import Optional

import jax
import jax.numpy as jnp
from brax.training.acme import running_statistics
from brax.training.agents.ppo import networks as ppo_networks

from train import checkpoint as ckpt
from train import evaluate as E
from train import networks as N
from train.config import PPOConfig


def load_policy(path: str, env=None, deterministic: bool = True, seed: Optional[int] = None,
                action: Optional[str] = None):
  """A trained policy ``policy(state, rng) -> action`` for ONE env (``state.obs`` f32[O] → f32[A]).

  ``path``: a run directory or its ``checkpoint.npz``. ``seed``: which seed of a
  multi-seed run (a value from ``policy.meta["config"]["seeds"]``; default: the
  first). Deterministic (the distribution's mode) unless ``deterministic=False``; ``action`` ("mode",
  "sample" or "mean", train.networks.policy_apply) overrides it.
  With ``env`` given, its observation and action sizes are checked against the
  checkpoint. ``policy.apply(params, state, rng)``/``policy.params`` expose the
  weights as data (train.evaluate passes them traced); ``policy.meta`` holds the
  run's config and ``policy.seed`` the seed loaded.
  """
  if action is not None and action not in N.POLICY_ACTIONS:
    raise ValueError(f"action: {action!r} is not one of {', '.join(N.POLICY_ACTIONS)}")
  path = os.fspath(path)
  file = ckpt.file_of(path)
  if not os.path.isfile(file):
    raise ValueError(f"path: no checkpoint at {file}")
  meta = ckpt.read_meta(file)
  cfg = PPOConfig.from_json(meta["config"])
  if seed is None:
    seed = cfg.seeds[0]
  if seed not in cfg.seeds:
    raise ValueError(f"seed: {seed!r} is not a seed of this run (valid: {', '.join(map(str, cfg.seeds))})")
  obs_size, action_size = int(meta["obs_size"]), int(meta["action_size"])
  if env is not None:
    e_obs = jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape[-1]
    if (e_obs, env.action_size) != (obs_size, action_size):
      trained = meta.get("task_kwargs") or {}
      hint = f" (the run was trained with task overrides {trained}: build the env with them)" if trained else ""
      raise ValueError(f"env: observation/action sizes {(e_obs, env.action_size)} differ from the "
                       f"checkpoint's {(obs_size, action_size)}{hint}")
  network = N.make_networks(obs_size, action_size, cfg)
  one = jax.eval_shape(lambda: (running_statistics.init_state(jnp.zeros((obs_size,), jnp.float32)),
                                network.policy_network.init(jax.random.PRNGKey(0))))
  if "seeds" in meta["config"]:  # the seed axis is in front of every leaf (one file for all seeds)
    S = len(cfg.seeds)
    template = jax.tree.map(lambda t: jax.ShapeDtypeStruct((S,) + tuple(t.shape), t.dtype), one)
    params = jax.tree.map(lambda x: x[cfg.seeds.index(seed)], ckpt.restore(file, template, "policy"))
  else:  # written before the seed axis: one seed, no axis
    params = ckpt.restore(file, one, "policy")
  params = jax.device_put(params)
  make_policy = ppo_networks.make_inference_fn(network)
  policy = E.parametrized_policy(N.policy_apply(make_policy, deterministic, action), params)
  policy.meta = meta
  policy.seed = seed
  policy.action = action or ("mode" if deterministic else "sample")
  return policy

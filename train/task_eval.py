"""A policy evaluated on a task the way training takes the task: ``train.evaluate_policy``.

Resolves ``task`` (a registry name, an env class path or a Brax env) as the
trainer does and runs :mod:`train.evaluate` on it. Kept out of
:mod:`train.evaluate`, which rolls out any env and knows nothing of the trainer.
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from train import evaluate as E
from train.envs import resolve_task, safe_threshold_of, task_episode_length

Policy = E.Policy


def evaluate_policy(task, policy: Policy, *, num_episodes: int = 1024, episode_length: Optional[int] = None,
                    seed: int = 0, task_kwargs: Optional[dict] = None, fragility=1.0,
                    devices: Optional[Sequence] = None) -> dict:
  """:func:`train.evaluate.evaluate` for a task as training takes it → the flat summary (``scalar_metrics``).

  ``task``: a registered task name, an env class path or a Brax env
  (:func:`train.resolve_task`); ``policy(state, rng) -> action`` for one
  env, e.g. :func:`train.load_policy` (its weights are passed as data). The
  episode length defaults to the task's; safe completion uses the env's
  DamageWrapper threshold. Exported as ``train.evaluate_policy``.
  """
  for name, v in (("num_episodes", num_episodes), ("episode_length", episode_length)):
    if v is None and name == "episode_length":
      continue
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
      raise ValueError(f"{name}: must be a positive integer, got {v!r}")
  env, _ = resolve_task(task, task_kwargs)
  res = E.evaluate(env, policy, int(num_episodes), seed, fragility=fragility,
                 episode_length=int(episode_length or task_episode_length(env)),
                 safe_threshold=safe_threshold_of(env), devices=devices)
  return E.scalar_metrics(res["metrics"])

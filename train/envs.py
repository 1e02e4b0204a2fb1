"""The env a run trains on: task lookup, damage wrapping, episode length, safe-completion threshold."""

from __future__ import annotations

import importlib
from typing import Optional

import jax
import numpy as np
from brax.envs.base import Env, Wrapper

import mjx_damage  # noqa: F401  (installs the jax compat shim brax needs)
import tasks as task_registry
from mjx_damage.wrapper import DamageWrapper


def _find_damage_wrapper(env) -> Optional[DamageWrapper]:
  e = env
  while e is not None:
    if isinstance(e, DamageWrapper):
      return e
    e = getattr(e, "env", None) if isinstance(e, Wrapper) else None
  return None


def recorded_task_kwargs(task, env: Env, task_kwargs: Optional[dict]) -> dict:
  """``task_kwargs`` to store with a checkpoint: a registry task's with its robot named
  (``tasks.recorded_kwargs``), so the checkpoint does not depend on the default robot; others unchanged."""
  if isinstance(task, str) and ":" not in task:
    return task_registry.recorded_kwargs(env, task_kwargs)
  return dict(task_kwargs or {})


def resolve_task(task, task_kwargs: Optional[dict] = None) -> tuple[Env, str]:
  """``task`` → (damage-wrapped single env, name).

  ``task`` is a registered task name (``tasks.make(name, **task_kwargs)``), an
  env class path ``"package.module:Class"`` (constructed with ``task_kwargs``)
  or a Brax env instance.

  The env must expose ``info["task_reward"]``/``info["cost"]``: anything that
  already contains a :class:`DamageWrapper` is used as is (the trainer shapes
  the reward from those fields, so the wrapper's own weight does not matter);
  a :class:`mjx_damage.DamageEnv` is wrapped at weight 0.
  """
  if isinstance(task, str) and ":" in task:  # "package.module:EnvClass", e.g. train.experiments.pusher:PusherEnv
    module, _, cls = task.partition(":")
    try:
      env = getattr(importlib.import_module(module), cls)(**(task_kwargs or {}))
    except (ImportError, AttributeError) as e:
      raise ValueError(f"task: cannot import env class {task!r} ({e})") from e
    name = task
  elif isinstance(task, str):
    names = list(task_registry.names())
    if task not in names:
      raise ValueError(f"task: unknown task {task!r}; registered: {', '.join(names) or '(none)'}")
    env, name = task_registry.make(task, **(task_kwargs or {})), task
  elif isinstance(task, Env):
    if task_kwargs:
      raise ValueError("task_kwargs: only used with a task name")
    env, name = task, type(task).__name__
  else:
    raise ValueError(f"task: a registered task name or a brax Env, got {type(task).__name__}")
  if _find_damage_wrapper(env) is None:
    if getattr(env, "damage_binding", None) is None:
      raise ValueError(f"task: {name} neither tracks damage nor is wrapped in DamageWrapper")
    env = DamageWrapper(env, weight=0.0)
  return env, name


def eval_env_of(task, env, eval_task_kwargs: dict):
  """The env of ``task`` built with ``eval_task_kwargs``, checked against the training ``env`` (same
  observation and action sizes) before anything compiles; ValueError naming ``eval_task_kwargs``."""
  if not isinstance(task, str):
    raise ValueError("eval_task_kwargs: only used with a task name")
  if not isinstance(eval_task_kwargs, dict):
    raise ValueError(f"eval_task_kwargs: a dict of task keyword arguments, got {eval_task_kwargs!r}")
  try:
    eval_env, _ = resolve_task(task, eval_task_kwargs)
  except (TypeError, ValueError) as e:
    raise ValueError(f"eval_task_kwargs: {task} refuses {eval_task_kwargs}: {e}") from None
  shapes = [(jax.eval_shape(e.reset, jax.random.PRNGKey(0)).obs.shape, e.action_size) for e in (env, eval_env)]
  if shapes[0] != shapes[1]:
    raise ValueError(f"eval_task_kwargs: the evaluation env's (observation shape, action size) {shapes[1]} "
                     f"differ from the training env's {shapes[0]}")
  return eval_env


def task_episode_length(env, default: int = 200) -> int:
  """The episode length a task declares (``Task.episode_length``), else ``default``."""
  n = getattr(getattr(env, "unwrapped", env), "episode_length", None)
  return int(n) if isinstance(n, (int, np.integer)) and n > 0 else default


def safe_threshold_of(env) -> float:
  """The env's DamageWrapper ``safe_threshold`` (95 without one): safe completion's health bar."""
  w = _find_damage_wrapper(env)
  return float(w.safe_threshold) if w is not None else 95.0

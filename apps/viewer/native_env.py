"""A damage-wrapped env of the suite stepped on native MuJoCo (one env, a plain ``MjData``).

Nothing of the task is rewritten for native MuJoCo. ``Task.step`` is
``ctrl = robot.ctrl(d, a)`` → ``physics_step(d, ds, ctrl)`` → ``update_info``,
``evaluate``, ``observe``, and ``DamageWrapper.step`` adds health, cost and
metrics around it; ``physics_step`` is the one seam where MJX runs. A native
control step runs that same env step, jitted, twice, each time tracing it with
the innermost env's ``physics_step`` bound to a stand-in:

1. ``ctrl_of(state, action)``: the stand-in keeps the ``ctrl`` the task computed
   (task action handling included, e.g. Place Plate's hand-speed limit); XLA
   drops the rest of the step from that executable;
2. on the host: ``data.ctrl = ctrl`` and :func:`mjx_damage.native.step`
   (``n_substeps`` MuJoCo steps with temperature, liquid and damage);
3. ``finish(state, action, fields, ds)``: the stand-in returns the native
   result — every public ``mjx.Data`` field copied from the ``MjData``, and the
   native damage state — so reward, success, observation, health, cost and
   termination are the MJX path's own code on the native state.

The stand-in is bound only while JAX traces (an instance attribute set and
removed around the call, inside the traced function), so the env object is
unchanged outside these two functions and any retrace binds it again.
``reset`` is the env's own jitted reset (MJX, once per episode), copied into the
``MjData`` by :func:`put_state` (which takes a one-env state from anywhere, e.g. one
episode of a batched MJX rollout).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
from typing import Callable, NamedTuple

import jax
import mujoco
import numpy as np
from brax.envs.base import State
from mujoco import mjx

from mjx_damage import native


class NativeEnv(NamedTuple):
  """Compiled functions and static facts of one env stepped natively (no mutable state).

  model: the ``MjModel`` the ``MjData`` belongs to (a copy of the env's; a viewer may recolour it).
  fields: (name, shape, dtype) of the ``mjx.Data`` fields copied from the ``MjData`` after each step.
  """

  env: object
  model: mujoco.MjModel
  binding: object
  n_substeps: int
  dt: float
  fields: tuple
  reset: Callable
  ctrl_of: Callable
  finish: Callable


def _innermost(env):
  inner = env
  while hasattr(inner, "env"):
    inner = inner.env
  if not hasattr(inner, "physics_step") or not hasattr(inner, "damage_binding"):
    raise ValueError(f"env: {type(inner).__name__} does not step through mjx_damage's physics_step "
                     "(a DamageEnv: every task of the suite); it cannot run on native MuJoCo")
  return inner


@contextlib.contextmanager
def _physics_bound(task, fn):
  task.physics_step = fn
  try:
    yield
  finally:
    del task.physics_step  # back to the class's MJX physics_step


def make(env) -> NativeEnv:
  """:class:`NativeEnv` of a damage-wrapped env whose innermost env is a ``DamageEnv``."""
  task = _innermost(env)
  model = copy.deepcopy(task.mj_model)
  d0 = mjx.make_data(task.sys)
  fields = tuple((f.name, tuple(np.shape(getattr(d0, f.name))), np.dtype(getattr(d0, f.name).dtype))
                 for f in dataclasses.fields(d0)
                 if not f.name.startswith("_") and np.size(getattr(d0, f.name)) > 0)

  def ctrl_of(state: State, action):
    kept = []

    def keep_ctrl(d, ds, ctrl):
      kept.append(ctrl)
      return d, ds

    with _physics_bound(task, keep_ctrl):
      env.step(state, action)
    return kept[0]

  def finish(state: State, action, copied: dict, ds):
    def native_result(d, _ds, ctrl):
      return d.replace(**copied), ds

    with _physics_bound(task, native_result):
      return env.step(state, action)

  return NativeEnv(env=env, model=model, binding=task.damage_binding, n_substeps=int(task.n_substeps),
                   dt=float(task.dt), fields=fields, reset=jax.jit(env.reset), ctrl_of=jax.jit(ctrl_of),
                   finish=jax.jit(finish))


def copy_fields(nat: NativeEnv, data: mujoco.MjData) -> dict:
  """Every public ``mjx.Data`` field of ``data`` as arrays in the ``mjx.Data`` shapes and dtypes."""
  return {name: np.asarray(getattr(data, name), dtype).reshape(shape) for name, shape, dtype in nat.fields}


def reset(nat: NativeEnv, data: mujoco.MjData, rng) -> State:
  """Reset the env (its own jitted reset) and put the reset state into ``data``; returns the env state."""
  return put_state(nat, data, nat.reset(rng))


def put_state(nat: NativeEnv, data: mujoco.MjData, state: State) -> State:
  """Put an env state of one env (a reset state, from any source) into ``data``; returns ``state``."""
  d = state.pipeline_state
  mujoco.mj_resetData(nat.model, data)
  for name in ("qpos", "qvel", "act", "ctrl", "mocap_pos", "mocap_quat", "qacc_warmstart", "eq_active"):
    if getattr(data, name).size:
      getattr(data, name)[:] = np.asarray(getattr(d, name)).reshape(getattr(data, name).shape)
  data.time = float(d.time)
  mujoco.mj_forward(nat.model, data)
  return state


def step(nat: NativeEnv, data: mujoco.MjData, state: State, action) -> State:
  """One control step of ``action``: ``data`` advances in place; returns the env's next state."""
  action = np.asarray(action, np.float32)
  data.ctrl[:] = np.asarray(nat.ctrl_of(state, action))
  ds = native.step(nat.binding, nat.model, data, state.info["damage_state"], nat.n_substeps)
  return nat.finish(state, action, copy_fields(nat, data), ds)

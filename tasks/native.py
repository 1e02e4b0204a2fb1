"""Tasks on the native-MuJoCo batched backend (:class:`mjx_damage.native_batch.NativeBatchEnv`).

::

    import tasks.native
    nenv = tasks.native.make("place_plate", num_envs=256)   # same overrides as tasks.make
    state = nenv.reset(jax.random.split(jax.random.PRNGKey(0), 256))
    state = nenv.step(state, jax.vmap(policy)(state, keys))  # policies of tasks.scripted_policy work as is

The backend adds its damage sensors to the scene's ``mujoco.MjSpec``; this
module knows where a task's scene comes from (:func:`scene_spec`).
"""

from __future__ import annotations

import os

import mujoco

import tasks
from mjx_damage.native_batch import DEFAULT_SLOTS, NativeBatchEnv
from tasks import bench_table, drop
from tasks.base import Task


def scene_spec(env) -> mujoco.MjSpec:
  """The scene of a task-suite env (wrapped or bare) or of the drop scene, as an ``MjSpec``.

  For a :class:`tasks.base.Task`: its XML with ``robot.xml`` resolved to the task's robot,
  as :meth:`Task.load_scene` compiles it (robot placement is carried over by the backend).
  """
  task = getattr(env, "unwrapped", env)
  if isinstance(task, drop.DropEnv):
    return mujoco.MjSpec.from_file(drop.SCENE)
  if isinstance(task, bench_table.TableEnv):
    return mujoco.MjSpec.from_string(bench_table.table_scene_xml(task.k, **task.scene_kwargs))
  if not isinstance(task, Task):
    raise ValueError(f"env: the native backend runs task-suite scenes, drop and the K-box table, got {type(task).__name__}")
  module = __import__(type(task).__module__, fromlist=["_"])
  with open(os.path.join(os.path.dirname(module.__file__), task.xml)) as f:
    text = f.read()
  with open(type(task.robot).xml, "rb") as f:
    robot_xml = f.read()
  return mujoco.MjSpec.from_string(text, {"robot.xml": robot_xml})


def supports(env) -> bool:
  """Whether the native backend runs ``env`` (wrapped or bare): a task-suite, drop or K-box scene
  (every damage model, temperature and liquid included)."""
  task = getattr(env, "unwrapped", env)
  binding = getattr(task, "damage_binding", None)
  return isinstance(task, (Task, drop.DropEnv, bench_table.TableEnv)) and binding is not None


def wrap(env, num_envs: int, nthread: int = 0, slots: int = DEFAULT_SLOTS) -> NativeBatchEnv:
  """``num_envs`` native copies of an env :func:`tasks.make` (or ``DamageWrapper(DropEnv())``) built."""
  return NativeBatchEnv(env, scene_spec(env), num_envs, nthread=nthread, slots=slots)


def make(name: str, num_envs: int, nthread: int = 0, slots: int = DEFAULT_SLOTS, **overrides) -> NativeBatchEnv:
  """Task ``name`` (overrides as :func:`tasks.make`) on the native backend, ``num_envs`` environments."""
  return wrap(tasks.make(name, **overrides), num_envs, nthread, slots)

"""Record demonstration datasets at scale: any policy or operator through the compiled batched step.

Python API::

    from train.record import record
    env = tasks.make("pick_egg")
    ds = record(env, tasks.operators.careless(env), episodes=256, seed=0, task="pick_egg")
    mjx_damage.data.save("demos.hdf5", ds)

One call records ``chunk`` episodes with ``jit(vmap(episode))``, the episode a
``lax.scan`` over ``episode_length`` steps (reset → per step: action from the
state, step, record); episodes are recorded in chunks of the same size (one
executable) and written by :mod:`mjx_damage.data` in the robomimic HDF5 layout.
Per step it stores the observation and simulator state *before* the step
(qpos ‖ qvel), the (clipped) action, and the reward, entity health, damage per
kind and cost *after* it; per episode success (the task's condition held at
some step) and safe (every entity's final health above the env's safe
threshold). Episodes run their full length (as the evaluator runs them), so a
policy learns what to do after completing the task too.

The command line is ``mjx-damage record`` (:mod:`apps.record_cli`), which resolves
task and policy names.
"""

from __future__ import annotations

import time
from typing import Iterator, Optional

import jax
import jax.numpy as jnp
import numpy as np

from mjx_damage import data as D
from tasks import operators
from train import evaluate as E

DEFAULT_CHUNK = 256  # episodes per compiled call: bounds memory, one executable for all chunks


def as_operator(policy, label: str = "policy") -> operators.Operator:
  """An :class:`tasks.operators.Operator` as is, or a plain ``policy(state, rng)`` as one without parameters."""
  if isinstance(policy, operators.Operator):
    return policy
  if not callable(policy):
    raise ValueError(f"policy: expected policy(state, rng) or an Operator, got {type(policy).__name__}")
  return operators.Operator(label, lambda key: jnp.zeros(()), lambda _, state, rng: policy(state, rng))


def episode_fn(env, op: operators.Operator, episode_length: int):
  """``episode(key) -> (per-step dict [T, ...], success bool[], final health f32[N])`` for one env."""

  def episode(key):
    k_reset, k_par, k_act = jax.random.split(key, 3)
    state = env.reset(k_reset)
    params = op.sample(k_par)

    def body(s, t):
      a = jnp.clip(jnp.nan_to_num(op.act(params, s, jax.random.fold_in(k_act, t))), -1.0, 1.0)
      nxt = env.step(s, a)
      d = s.pipeline_state
      rec = {
          "obs": s.obs, "actions": a, "rewards": nxt.reward,
          "states": jnp.concatenate([d.qpos, d.qvel]),
          "health": nxt.info["entity_health"], "damage": nxt.info["damage"], "cost": nxt.info["cost"],
          "success": nxt.metrics["success"],
      }
      return nxt, rec

    final, steps = jax.lax.scan(body, state, jnp.arange(episode_length))
    return steps, jnp.max(steps["success"]) > 0, final.info["entity_health"]

  return episode


def record_chunks(env, policy, episodes: int, seed: int = 0, *, task: str, episode_length: Optional[int] = None,
                  chunk: int = DEFAULT_CHUNK, label: Optional[str] = None, env_config: Optional[dict] = None,
                  log=None) -> Iterator[D.Dataset]:
  """:func:`record`'s episodes as a stream of datasets of ``chunk`` episodes (the last one shorter).

  The next chunk is dispatched to the device before this one is handed out, so
  whatever the caller does with a chunk (write it: :func:`mjx_damage.data.save_chunks`)
  overlaps the recording of the next. Same episodes, keys and values as :func:`record`.
  """
  for name, v in (("episodes", episodes), ("chunk", chunk)):
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
      raise ValueError(f"{name}: must be an int >= 1, got {v!r}")
  T = episode_length if episode_length is not None else E.env_episode_length(env)
  op = as_operator(policy)
  label = label or op.label
  chunk = min(chunk, episodes)
  run = jax.jit(jax.vmap(episode_fn(env, op, T)))
  keys = np.asarray(jax.random.split(jax.random.PRNGKey(seed), episodes))
  pad = (-episodes) % chunk
  keys = np.concatenate([keys, np.repeat(keys[-1:], pad, 0)]) if pad else keys
  return _stream(env, run, keys, episodes, chunk, T, task, env_config, label, log)  # checked before any compile


def _stream(env, run, keys, episodes: int, chunk: int, T: int, task: str, env_config, label: str, log):
  t0 = time.perf_counter()
  pending = run(keys[:chunk])
  for i in range(0, keys.shape[0], chunk):
    nxt = run(keys[i + chunk : i + 2 * chunk]) if i + chunk < keys.shape[0] else None  # asynchronous dispatch
    if nxt is not None:  # its copy to the host starts as soon as it is computed, while the caller writes chunk i
      jax.tree.map(lambda a: a.copy_to_host_async(), nxt)
    n = min(chunk, episodes - i)
    steps, success, final_h = jax.tree.map(lambda a: np.asarray(a)[:n], pending)  # waits for chunk i only
    if log:
      log(f"recorded episodes {i}..{i + n - 1} in {time.perf_counter() - t0:.1f} s")
    yield D.build(
        env_name=task, env_config=env_config or {}, obs={"state": steps["obs"]}, actions=steps["actions"],
        rewards=steps["rewards"], states=steps["states"],
        health={name: steps["health"][:, :, j] for j, name in enumerate(env.entity_names)},
        damage=steps["damage"], cost=steps["cost"], lengths=np.full(n, T),
        success=success, safe=np.all(final_h > getattr(env, "safe_threshold", 95.0), axis=-1),
        labels=np.zeros(n, np.int32), label_names=(label,))
    t0, pending = time.perf_counter(), nxt


def record(env, policy, episodes: int, seed: int = 0, *, task: str, episode_length: Optional[int] = None,
           chunk: int = DEFAULT_CHUNK, label: Optional[str] = None, env_config: Optional[dict] = None,
           log=None) -> D.Dataset:
  """Record ``episodes`` episodes of ``policy`` (``policy(state, rng)`` or an Operator) on ``env``.

  ``task``: the task name stored in the dataset; ``env_config``: the make()
  overrides that built ``env`` (stored as JSON); ``label``: the operator
  condition stored per episode (default: the operator's label). Episode i uses
  key ``split(PRNGKey(seed), episodes)[i]``. Held in memory; for datasets
  larger than memory, or to write while recording, stream :func:`record_chunks`
  into :func:`mjx_damage.data.save_chunks`.
  """
  parts = list(record_chunks(env, policy, episodes, seed, task=task, episode_length=episode_length, chunk=chunk,
                             label=label, env_config=env_config, log=log))
  return parts[0] if len(parts) == 1 else D.concat(parts)

"""Timed measurements of the throughput harness: damage on/off pairs on the K-box table, a registry task.

The K-box pairs time ``mjx.step`` itself (MJX only); a registry task is timed on
either backend (``measure_task(..., backend="native")``: :func:`apps.resolve.on_backend`).

Each measurement records its first-compile time and the process's peak memory
so far (CPU: ``ru_maxrss``; GPU: ``peak_bytes_in_use`` — both high-water marks).
"""

from __future__ import annotations

import math
import os
import resource
import time

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from apps import resolve as R
from mjx_damage import physics
from tasks.bench_table import pusher_ctrl


def peak_memory_bytes() -> dict:
  """High-water marks so far: host RSS (bytes) and, on accelerators, device peak_bytes_in_use."""
  out = {"host_maxrss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}
  dev = jax.devices()[0]
  if dev.platform != "cpu":
    stats = dev.memory_stats() or {}
    out["device_peak_bytes_in_use"] = int(stats.get("peak_bytes_in_use", -1))
  return out


def batched_initial_state(env, envs: int, seed: int = 0):
  """(mjx.Data, DamageState) with a leading axis of ``envs`` (host-built: no compile per size)."""
  rng = np.random.default_rng(seed)
  q = np.tile(np.asarray(env.mj_model.qpos0, np.float32), (envs, 1))
  idx = env._box_q
  q[:, idx] += rng.uniform(-0.01, 0.01, (envs, len(idx)))
  q[:, idx + 1] += rng.uniform(-0.01, 0.01, (envs, len(idx)))
  d0 = mjx.make_data(env.sys)
  ds0 = physics.init_state(env.damage_binding)
  tile = lambda x: jnp.broadcast_to(x, (envs,) + jnp.shape(x))
  d = jax.tree.map(tile, d0).replace(qpos=jnp.asarray(q))
  return d, jax.tree.map(tile, ds0), q


def make_runner(env, damage: bool):
  """``run(d, ds, nsteps) -> (d, ds)``: ``nsteps`` (traced) control steps of the whole batch.

  The pusher follows :func:`pusher_ctrl` of each env's simulation time, inside
  the compiled loop, so both settings do identical physics work.
  """
  sys_, binding, n, radius = env.sys, env.damage_binding, env.n_substeps, env.radius

  def one(d, ds):
    d = d.replace(ctrl=pusher_ctrl(d.time, radius, jnp).astype(d.ctrl.dtype))
    if damage:
      return physics.step(sys_, binding, d, ds, n)
    return physics.step_without_damage(sys_, d, n), ds

  batched = jax.vmap(one)

  def run(d, ds, nsteps):
    return jax.lax.fori_loop(0, nsteps, lambda _, c: batched(*c), (d, ds))

  return jax.jit(run, donate_argnums=(0, 1))


def measure_pair(env, envs: int, target_s: float, max_steps: int, repeats: int = 1, seed: int = 0):
  """Damage on and off at one (K, envs): compile both, then alternate timed runs.

  Both settings run the same number of env steps from the same initial state;
  on/off timings are interleaved (on, off, on, off, ...) and the best of
  ``repeats`` is kept for each, so a load change on a shared machine hits both
  alike. When a single env step already exceeds ``target_s`` (big batches on
  CPU), that first timed call is the measurement (``steps`` = 1).

  Returns:
    (row_on, row_off): dicts with env_steps_per_s, physics_steps_per_s,
    compile_s, the timings of every repeat, peak memory so far and load.
  """
  runs = {}
  for damage in (True, False):
    d, ds, _ = batched_initial_state(env, envs, seed)
    t0 = time.perf_counter()
    compiled = make_runner(env, damage).lower(d, ds, jnp.int32(1)).compile()
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    d, ds = jax.block_until_ready(compiled(d, ds, jnp.int32(1)))
    runs[damage] = {"compiled": compiled, "state": (d, ds), "compile_s": compile_s,
                    "first_s": time.perf_counter() - t0, "times": []}
  first = max(r["first_s"] for r in runs.values())
  if first >= target_s:
    steps = 1
    for r in runs.values():
      r["times"].append(r["first_s"])
    repeats -= 1
  else:
    steps = int(min(max_steps, max(2, math.ceil(target_s / max(first, 1e-6)))))
  for _ in range(max(repeats, 0)):
    for damage in (True, False):
      r = runs[damage]
      t0 = time.perf_counter()
      r["state"] = jax.block_until_ready(r["compiled"](*r["state"], jnp.int32(steps)))
      r["times"].append(time.perf_counter() - t0)
  rows = []
  for damage in (True, False):
    r = runs[damage]
    secs = min(r["times"])
    row = {
        "backend": "mjx",  # these pairs time mjx.step itself, whatever --backend says
        "envs": envs,
        "entities": env.tracked,
        "boxes": env.k,
        "free_boxes": env.free,
        "jacobian": env.jacobian,
        "damage": damage,
        "steps": steps,
        "seconds": secs,
        "seconds_all_repeats": r["times"],
        "env_steps_per_s": envs * steps / secs,
        "physics_steps_per_s": envs * steps * env.n_substeps / secs,
        "compile_s": r["compile_s"],
        "first_call_s": r["first_s"],
        # 1-min load average: on a shared machine other processes' load lowers the numbers
        "loadavg_1min": os.getloadavg()[0],
    }
    if damage:
      row["mean_min_health"] = float(jnp.mean(jnp.min(r["state"][1].link_health, axis=-1)))
    row.update(peak_memory_bytes())
    rows.append(row)
  return rows[0], rows[1]


def measure_task(name: str, envs: int, target_s: float, max_steps: int, backend: str = "mjx",
                 overrides: dict | None = None) -> dict:
  """Physics steps/s of a registry task's ``step`` (damage on, zero action) on ``backend``.

  ``mjx`` and ``warp`` (the task made on MuJoCo Warp for ``envs``): ``vmap(env.step)`` in a compiled
  ``fori_loop``. ``native``: the task's
  :class:`~mjx_damage.native_batch.NativeBatchEnv` of ``envs`` stepped from Python
  (one native call and two jitted calls per step, as evaluation runs it); its
  jitted halves compile in the first step, so there ``compile_s`` is that first
  step's time. The row records ``backend`` and the robot. ``overrides``: ``tasks.make``
  keywords (``robot``). Raises ValueError for a scene the native backend cannot run.
  """
  # warp: the task made on MuJoCo Warp for this batch (R.warp_overrides); it then times as mjx does
  task = R.make_task(name, **(overrides or {}), **R.warp_overrides(name, backend, envs))
  robot = task.unwrapped.robot_name
  env = R.on_backend(task, backend, envs)
  if backend == "native":
    return dict(_measure_native_task(name, env, envs, target_s, max_steps), robot=robot)
  n_sub = getattr(env, "n_substeps", None) or getattr(env.unwrapped, "n_substeps", 1)
  state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), envs))
  act = jnp.zeros((envs, env.action_size))

  def run(state, nsteps):
    return jax.lax.fori_loop(0, nsteps, lambda _, s: jax.vmap(env.step)(s, act), state)

  run = jax.jit(run, donate_argnums=(0,))
  t0 = time.perf_counter()
  compiled = run.lower(state, jnp.int32(1)).compile()
  compile_s = time.perf_counter() - t0
  t0 = time.perf_counter()
  state = jax.block_until_ready(compiled(state, jnp.int32(1)))
  first_s = time.perf_counter() - t0
  steps = int(min(max_steps, max(2, math.ceil(target_s / max(first_s, 1e-6)))))
  t0 = time.perf_counter()
  state = jax.block_until_ready(compiled(state, jnp.int32(steps)))
  secs = time.perf_counter() - t0
  return dict(_task_row(name, backend if backend == "warp" else "mjx", envs, n_sub, steps, secs, compile_s),
              robot=robot)


def _measure_native_task(name: str, nenv, envs: int, target_s: float, max_steps: int) -> dict:
  """:func:`measure_task` on a NativeBatchEnv: the same zero-action steps, timed around a Python loop."""
  state = nenv.reset(jax.random.split(jax.random.PRNGKey(0), envs))
  act = jnp.zeros((envs, nenv.action_size))
  t0 = time.perf_counter()
  state = jax.block_until_ready(nenv.step(state, act))  # compiles the jitted halves
  compile_s = time.perf_counter() - t0
  t0 = time.perf_counter()
  state = jax.block_until_ready(nenv.step(state, act))
  first_s = time.perf_counter() - t0
  steps = int(min(max_steps, max(2, math.ceil(target_s / max(first_s, 1e-6)))))
  t0 = time.perf_counter()
  for _ in range(steps):
    state = nenv.step(state, act)
  jax.block_until_ready(state)
  secs = time.perf_counter() - t0
  return dict(_task_row(name, "native", envs, nenv.n_substeps, steps, secs, compile_s), nthread=nenv.nthread)


def _task_row(name, backend, envs, n_sub, steps, secs, compile_s) -> dict:
  out = {
      "task": name,
      "backend": backend,
      "envs": envs,
      "n_substeps": int(n_sub),
      "steps": steps,
      "seconds": secs,
      "env_steps_per_s": envs * steps / secs,
      "physics_steps_per_s": envs * steps * n_sub / secs,
      "compile_s": compile_s,
  }
  out.update(peak_memory_bytes())
  return out

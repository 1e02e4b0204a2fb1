"""``mjx-damage bench``: throughput of the damage-aware MJX step, with damage on and off.

Measures environment steps per second (one env step = ``n_substeps`` physics
steps) of ``jit(fori_loop(vmap(step)))`` on the K-box table scene
(:mod:`mjx_damage.scenes.bench_table`):

* versus the number of environments, damage on (:func:`mjx_damage.physics.step`)
  and off (:func:`mjx_damage.physics.step_without_damage`), at K tracked boxes;
* versus the number of tracked entities K, damage on and off, at a fixed batch,
  two ways: K boxes in the scene, all tracked (scene size and tracking grow
  together), and n of the ``--k`` boxes of one fixed scene tracked (only the
  damage work grows: what tracking itself costs);
* the same scene stepped by the reference-style pipeline
  (:mod:`mjx_damage.reference`: native MuJoCo, per-entity Python evaluators),
  native MuJoCo without damage, and multi-threaded ``mujoco.rollout``, in the
  same run, for the speed-up ratio;
* physics steps/s of ``tasks.make("place_plate")`` when the task registry has it.

Each measurement records its first-compile time and the process's peak memory
so far (CPU: ``ru_maxrss``; GPU: ``peak_bytes_in_use`` — both high-water marks).
Output: a JSON file and a PNG with both curves. ``benchmarks/throughput.py``
wraps this with the committed settings per device.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import sys
import time
from typing import Optional

import numpy as np

CPU_ENVS = (1, 16, 128, 1024, 2048)
GPU_ENVS = (1, 256, 2048, 8192, 16384)
ENTITIES = (1, 2, 4, 8, 16, 32)
CTRL_PERIOD_S = 2.0  # period of the pusher's Lissajous sweep


def pusher_ctrl(t, radius: float, xp=np):
  """Open-loop pusher target (m, f[2]) at time ``t`` (s): a Lissajous figure over the grid."""
  w = 2 * math.pi / CTRL_PERIOD_S
  return xp.stack([radius * xp.sin(w * t), 0.8 * radius * xp.sin(2 * w * t + 0.5)])


# --- the benchmark env (also a small env with actions for tests) -------------

def _table_env_class():
  import jax
  import jax.numpy as jnp
  from brax.envs.base import State
  from mujoco import mjx

  from mjx_damage.env import DamageEnv
  from mjx_damage.scenes import bench_table as S

  class TableEnv(DamageEnv):
    """K boxes on a table and a pusher; action f32[2] ∈ [−1, 1]² = pusher target / sweep radius.

    ``free`` boxes (default all K) have free joints, the rest are mounted
    (:func:`mjx_damage.scenes.bench_table.table_scene_xml`); box 0 is always free.

    Success: box 0 pushed more than 5 cm from where it started. Observation
    f32[5]: pusher xy, box 0 xyz (m). Reset jitters every free box by ±1 cm.
    """

    def __init__(self, k: int = 1, n_substeps: int = 5, episode_length: int = 50, solver: str = "CG",
                 tracked: Optional[int] = None, jacobian: str = "auto", free: Optional[int] = None):
      free = k if free is None else free
      if not isinstance(free, int) or isinstance(free, bool) or not 1 <= free <= k:
        raise ValueError(f"free: free boxes must be an int in [1, k={k}] (box 0 is observed), got {free!r}")
      super().__init__(S.table_scene(k, solver=solver, jacobian=jacobian, free=free), S.table_config(k, tracked),
                       n_substeps)
      self.k = k  # boxes in the scene
      self.free = free  # boxes 0..free-1 are free bodies, the rest mounted
      self.tracked = k if tracked is None else tracked  # boxes whose damage is computed
      self.jacobian = jacobian
      self.radius = S.sweep_radius(k)
      self.episode_length = int(episode_length)
      m = self.mj_model
      self._box_q = np.array([m.jnt_qposadr[m.joint(f"box{i}").id] for i in range(free)])
      self._qpos0 = np.array(m.qpos0, np.float32)

    @property
    def observation_size(self) -> int:
      return 5

    @property
    def action_size(self) -> int:
      return 2

    def initial_qpos(self, rng) -> jax.Array:
      """f32[nq] reset configuration: free boxes on their grid, jittered ±1 cm in x and y."""
      jit = jax.random.uniform(rng, (self.free, 2), minval=-0.01, maxval=0.01)
      q = jnp.asarray(self._qpos0)
      idx = jnp.asarray(self._box_q)
      return q.at[idx].add(jit[:, 0]).at[idx + 1].add(jit[:, 1])

    def reset(self, rng: jax.Array) -> State:
      rng, qr = jax.random.split(rng)
      # no forward pass here: every physics substep starts with one (keeps reset cheap to compile)
      d = mjx.make_data(self.sys).replace(qpos=self.initial_qpos(qr))
      info = {"damage_state": self.init_damage(rng), "box0_start": d.qpos[self._box_q[0] : self._box_q[0] + 2]}
      z = jnp.zeros(())
      return State(d, self._obs(d), z, z, {"success": z}, info)

    def step(self, state: State, action: jax.Array) -> State:
      ctrl = self.radius * jnp.clip(action, -1.0, 1.0)
      d, ds = self.physics_step(state.pipeline_state, state.info["damage_state"], ctrl)
      moved = jnp.linalg.norm(d.qpos[self._box_q[0] : self._box_q[0] + 2] - state.info["box0_start"])
      success = (moved > 0.05).astype(jnp.float32)
      info = dict(state.info, damage_state=ds)
      metrics = dict(state.metrics, success=success)
      return state.replace(pipeline_state=d, obs=self._obs(d), info=info, metrics=metrics)

    def _obs(self, d):
      b = self._box_q[0]
      return jnp.concatenate([d.qpos[:2], d.qpos[b : b + 3]])

  return TableEnv


def table_env(k: int = 1, n_substeps: int = 5, episode_length: int = 50, solver: str = "CG",
              tracked: Optional[int] = None, jacobian: str = "auto", free: Optional[int] = None):
  """A :class:`TableEnv` (a ``DamageEnv``) on the K-box scene, tracking ``tracked`` (default all) boxes,
  ``free`` (default all) of them free bodies and the rest mounted."""
  return _table_env_class()(k, n_substeps, episode_length, solver, tracked, jacobian, free)


# --- measurement --------------------------------------------------------------

def peak_memory_bytes() -> dict:
  """High-water marks so far: host RSS (bytes) and, on accelerators, device peak_bytes_in_use."""
  import jax

  out = {"host_maxrss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}
  dev = jax.devices()[0]
  if dev.platform != "cpu":
    stats = dev.memory_stats() or {}
    out["device_peak_bytes_in_use"] = int(stats.get("peak_bytes_in_use", -1))
  return out


def batched_initial_state(env, envs: int, seed: int = 0):
  """(mjx.Data, DamageState) with a leading axis of ``envs`` (host-built: no compile per size)."""
  import jax
  import jax.numpy as jnp
  from mujoco import mjx

  from mjx_damage import physics

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
  import jax
  import jax.numpy as jnp

  from mjx_damage import physics

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
  import jax
  import jax.numpy as jnp

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


def measure_task(name: str, envs: int, target_s: float, max_steps: int) -> dict:
  """Physics steps/s of a registry task's ``step`` (damage on, zero action), vmapped."""
  import jax
  import jax.numpy as jnp
  import tasks

  env = tasks.make(name)
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
  out = {
      "task": name,
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


# --- the run ------------------------------------------------------------------

class Budget:
  """Wall-clock budget: measurements are ordered by importance and skipped once it is spent."""

  def __init__(self, seconds: float):
    self.t0, self.seconds = time.perf_counter(), seconds

  def left(self) -> float:
    return self.seconds - (time.perf_counter() - self.t0)


def _parse_ints(field: str, text: str) -> list[int]:
  try:
    vals = [int(v) for v in text.split(",") if v.strip()]
  except ValueError:
    raise ValueError(f"{field}: expected comma-separated integers, got {text!r}") from None
  if not vals or any(v < 1 for v in vals):
    raise ValueError(f"{field}: need integers >= 1, got {text!r}")
  return vals


def save(result: dict, out: str) -> None:
  """Write JSON, markdown and PNG for ``result`` (called after every point: a run
  killed midway, e.g. by a hung device call, still leaves what it measured)."""
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  base = os.path.splitext(out)[0]
  with open(out, "w") as f:
    json.dump(result, f, indent=1)
  with open(base + ".md", "w") as f:
    f.write(report_md(result))
  plot(result, base + ".png")


def run_benchmark(args) -> dict:
  import jax

  from mjx_damage import reference

  budget = Budget(args.budget_s)
  envs_list = _parse_ints("--envs", args.envs)
  ents = _parse_ints("--entities", args.entities)
  k_main = args.k
  fixed = args.entity_envs
  result = {
      "command": "mjx-damage bench " + " ".join(args.argv),
      "date": time.strftime("%Y-%m-%d %H:%M:%S"),
      "device": str(jax.devices()[0].device_kind),
      "platform": jax.devices()[0].platform,
      "num_devices": jax.device_count(),
      "host": {"machine": platform.machine(), "cpus": os.cpu_count(), "python": sys.version.split()[0]},
      "versions": {"jax": jax.__version__, "mujoco": __import__("mujoco").__version__},
      "scene": "mjx_damage.scenes.bench_table: K free boxes (tracked, 'default' params) on a table plane,"
      " a sphere pusher on slide joints; boxes collide with table and pusher, never with each other;"
      " in the vs_mounted scenes box 0 is free and boxes 1..K-1 are mounted (no joint)",
      "n_substeps": args.substeps,
      "timestep_s": 0.004,
      "persistent_compilation_cache": bool(jax.config.jax_enable_compilation_cache and
                                           jax.config.jax_compilation_cache_dir),
      "notes": list(args.notes),
      "vs_envs": [],
      "vs_entities": [],
      "vs_tracked": [],
      "vs_mounted": [],
      "jacobian": args.jacobian,
      "skipped": [],
      "complete": False,  # True once every planned point ran or was skipped
  }
  envs_cache = {}

  def env_for(k, tracked=None, free=None):  # None = all K (point() normalises tracked/free == k to None)
    key = (k, tracked, free)
    if key not in envs_cache:
      envs_cache[key] = table_env(k, args.substeps, tracked=tracked, jacobian=args.jacobian, free=free)
    return envs_cache[key]

  done = {}

  def checkpoint():
    result["summary"] = summarize(result, k_main, target_n, fixed)
    result["total_s"] = time.perf_counter() - budget.t0
    if args.out:
      save(result, args.out)

  def point(k, n, section, tracked=None, free=None):
    tracked = None if tracked == k else tracked
    free = None if free == k else free
    key = (k, n, tracked, free)
    if key not in done:
      if budget.left() <= 0:
        result["skipped"].append({"entities": tracked or k, "boxes": k, "free_boxes": free or k, "envs": n,
                                  "why": "time budget spent"})
        return
      print(f"  K={k:>2} tracked={tracked or k:>2} free={free or k:>2} envs={n:>5} ...", end="", flush=True)
      try:
        done[key] = measure_pair(env_for(k, tracked, free), n, args.target_s, args.max_steps, args.repeats)
      except Exception as e:  # e.g. device out of memory at the largest batch: keep the rest of the run
        print(f" failed: {type(e).__name__}: {str(e)[:200]}", flush=True)
        result["skipped"].append({"entities": tracked or k, "boxes": k, "free_boxes": free or k, "envs": n,
                                  "why": f"{type(e).__name__}: {str(e)[:300]}"})
        return
      on, off = done[key]
      print(f" on {on['env_steps_per_s']:>11,.1f}  off {off['env_steps_per_s']:>11,.1f} env-steps/s"
            f"  compile {on['compile_s']:.0f}/{off['compile_s']:.0f} s", flush=True)
    result[section].extend(done[key])
    checkpoint()

  # Order = importance, so a spent budget drops the least important points:
  # 0. the reference pipeline (no compile, bounded by --ref-max-s per configuration);
  # 1. the on/off ratio at the target batch with K tracked boxes; 2. K=1 there;
  # 3. task throughput; 4. the rest of both curves.
  top = max(envs_list)
  target_n = args.ratio_envs if args.ratio_envs else top
  first = [(k_main, target_n, "vs_envs"), (1, fixed, "vs_entities"), (k_main, fixed, "vs_entities")]
  tracked = _parse_ints("--tracked", args.tracked) if args.tracked else []
  if tracked:  # fixed K-box scene: the all-tracked point is shared with the vs-entities curve
    first.append((k_main, fixed, "vs_tracked", min(tracked)))
  mounted = _parse_ints("--mounted", args.mounted) if args.mounted else []
  if mounted:  # 1 free box + K-1 mounted ones; K = 1 is the vs-entities scene itself
    first += [(1, fixed, "vs_mounted", None, 1), (max(mounted), fixed, "vs_mounted", None, 1)]
  ent_pts = [(k, fixed, "vs_entities") for k in ents if (k, fixed, "vs_entities") not in first]
  env_pts = [(k_main, n, "vs_envs") for n in envs_list if (k_main, n, "vs_envs") not in first]
  trk_pts = [(k_main, fixed, "vs_tracked", t) for t in tracked if (k_main, fixed, "vs_tracked", t) not in first]
  mnt_pts = [(k, fixed, "vs_mounted", None, 1) for k in mounted if (k, fixed, "vs_mounted", None, 1) not in first]
  # alternate the curves so a spent budget thins them evenly
  rest = []
  for i in range(max(len(ent_pts), len(env_pts), len(trk_pts), len(mnt_pts))):
    rest += ent_pts[i:i + 1] + env_pts[i:i + 1] + trk_pts[i:i + 1] + mnt_pts[i:i + 1]
  # reference-style pipeline on the same scene (CPU, single thread, Python evaluators);
  # bounded by --ref-max-s per configuration, so it runs before the budgeted points
  ref = {}
  for k in sorted({1, k_main}):
    env = env_for(k)
    _, _, q = batched_initial_state(env, args.ref_envs, seed=1)
    ctrl = lambda t, r=env.radius: pusher_ctrl(t, r)
    print(f"  reference K={k} ...", flush=True)
    ref[k] = {
        "reference_damage": reference.time_reference(
            env.mj_model, env.damage_binding, args.substeps, q, ctrl, args.ref_steps, True, args.ref_max_s),
        "native_no_damage": reference.time_reference(
            env.mj_model, env.damage_binding, args.substeps, q, ctrl, args.ref_steps, False, args.ref_max_s),
        "rollout_no_damage": reference.time_rollout(
            env.mj_model, args.substeps, q, ctrl, args.ref_steps, os.cpu_count() or 1),
    }
  result["reference"] = {str(k): v for k, v in ref.items()}
  checkpoint()

  for item in first:
    point(*item)

  if args.task and budget.left() > 0:
    try:
      import tasks  # noqa: F401

      if args.task in tasks.names():
        print(f"  task {args.task} x {args.task_envs} envs ...", flush=True)
        try:
          result["task"] = measure_task(args.task, args.task_envs, args.target_s, args.max_steps)
        except Exception as e:  # keep the rest of the run
          result["skipped"].append({"task": args.task, "why": f"{type(e).__name__}: {str(e)[:300]}"})
      else:
        result["skipped"].append({"task": args.task, "why": "not in tasks.names()"})
    except (ImportError, AttributeError) as e:
      result["skipped"].append({"task": args.task, "why": f"task registry unavailable: {e}"})

  for item in rest:
    point(*item)

  result["complete"] = True
  checkpoint()
  return result


def _lookup(rows, **kw):
  for r in rows:
    if all(r.get(k) == v for k, v in kw.items()):
      return r
  return None


def summarize(result: dict, k_main: int, target_n: int, fixed: int) -> dict:
  """Ratios the project reports against its targets (computed from this run's rows only)."""
  rows = result["vs_envs"] + result["vs_entities"]
  s = {}
  trk = result.get("vs_tracked", [])
  lo = min((r["entities"] for r in trk), default=None)
  for dmg in (True, False):
    a = _lookup(trk, entities=lo, envs=fixed, damage=dmg)
    b = _lookup(trk, entities=k_main, envs=fixed, damage=dmg)
    if a and b and lo != k_main:
      s[f"tracked_{k_main}_over_{lo}_in_{k_main}_box_scene_damage_{'on' if dmg else 'off'}_{fixed}envs"] = (
          b["env_steps_per_s"] / a["env_steps_per_s"])
  mnt = result.get("vs_mounted", [])
  top = max((r["entities"] for r in mnt), default=None)
  for dmg in (True, False):
    a = _lookup(mnt, entities=1, envs=fixed, damage=dmg)
    b = _lookup(mnt, entities=top, envs=fixed, damage=dmg)
    if a and b and top != 1:
      s[f"entities_{top}_over_1_mounted_throughput_damage_{'on' if dmg else 'off'}_{fixed}envs"] = (
          b["env_steps_per_s"] / a["env_steps_per_s"])
  on = _lookup(rows, entities=k_main, envs=target_n, damage=True)
  off = _lookup(rows, entities=k_main, envs=target_n, damage=False)
  if on and off:
    s[f"damage_on_off_ratio_K{k_main}_{target_n}envs"] = on["env_steps_per_s"] / off["env_steps_per_s"]
  one = _lookup(rows, entities=1, envs=fixed, damage=True)
  many = _lookup(rows, entities=k_main, envs=fixed, damage=True)
  if one and many:
    s[f"entities_{k_main}_over_1_throughput_damage_on_{fixed}envs"] = many["env_steps_per_s"] / one["env_steps_per_s"]
  one_off = _lookup(rows, entities=1, envs=fixed, damage=False)
  many_off = _lookup(rows, entities=k_main, envs=fixed, damage=False)
  if one_off and many_off:
    s[f"entities_{k_main}_over_1_throughput_damage_off_{fixed}envs"] = (
        many_off["env_steps_per_s"] / one_off["env_steps_per_s"])
  # damage-tracking overhead per K (on/off at the same K and batch): separates what
  # tracking costs from what simulating K free bodies costs
  s["damage_on_off_ratio_by_entities"] = {
      str(r["entities"]): r["env_steps_per_s"] / off_r["env_steps_per_s"]
      for r in result["vs_entities"] if r["damage"]
      for off_r in [_lookup(result["vs_entities"], entities=r["entities"], envs=r["envs"], damage=False)] if off_r
  }
  s["damage_on_off_ratio_by_envs"] = {
      str(r["envs"]): r["env_steps_per_s"] / off_r["env_steps_per_s"]
      for r in result["vs_envs"] if r["damage"]
      for off_r in [_lookup(result["vs_envs"], entities=r["entities"], envs=r["envs"], damage=False)] if off_r
  }
  for k, ref in result.get("reference", {}).items():
    best = max((r for r in rows if r["entities"] == int(k) and r["damage"]),
               key=lambda r: r["env_steps_per_s"], default=None)
    if best:
      s[f"speedup_over_reference_K{k}"] = {
          "mjx_env_steps_per_s": best["env_steps_per_s"],
          "mjx_envs": best["envs"],
          "reference_env_steps_per_s": ref["reference_damage"]["env_steps_per_s"],
          "ratio_vs_reference_damage": best["env_steps_per_s"] / ref["reference_damage"]["env_steps_per_s"],
          "ratio_vs_native_no_damage_1thread": best["env_steps_per_s"] / ref["native_no_damage"]["env_steps_per_s"],
          "ratio_vs_rollout_no_damage": best["env_steps_per_s"] / ref["rollout_no_damage"]["env_steps_per_s"],
      }
  if "task" in result:
    s["task_physics_steps_per_s"] = result["task"]["physics_steps_per_s"]
  return s


def report_md(result: dict) -> str:
  """Markdown report of a run: tables of every point, the summary, and what the numbers mean."""
  lines = [f"# Throughput: {result['device']} ({result['platform']}, {result['num_devices']} device(s))", "",
           f"Command: `{result['command']}`  ", f"Date: {result['date']}; total {result.get('total_s', 0):.0f} s", ""]
  lines += [f"- note: {n}" for n in result.get("notes", [])]
  lines += ["", f"One env step = {result['n_substeps']} physics steps of {result['timestep_s'] * 1e3:g} ms. "
            "Scene: " + result["scene"] + ".", ""]
  for section, title in (("vs_envs", "Versus environments"),
                         ("vs_entities", "Versus tracked entities: K boxes in the scene, all tracked"),
                         ("vs_tracked", "Versus tracked entities: a fixed scene, n of its boxes tracked"),
                         ("vs_mounted", "Versus tracked entities: the scene grows by mounted boxes (1 free box + K-1 "
                                        "mounted, all tracked)")):
    if not result.get(section):
      continue
    lines += [f"## {title}", "", "| tracked | boxes in scene | free boxes | envs | damage | env steps/s | physics steps/s |"
              " compile s | peak host RSS GB | load avg |", "|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|"]
    for r in sorted(result[section], key=lambda r: (r["entities"], r["envs"], not r["damage"])):
      boxes = r.get("boxes", r["entities"])
      lines.append(f"| {r['entities']} | {boxes} | {r.get('free_boxes', boxes)} | {r['envs']} | {'on' if r['damage'] else 'off'} | {r['env_steps_per_s']:,.0f} |"
                   f" {r['physics_steps_per_s']:,.0f} | {r['compile_s']:.1f} | {r['host_maxrss_bytes'] / 2**30:.2f} |"
                   f" {r.get('loadavg_1min', float('nan')):.1f} |")
    lines.append("")
  if "reference" in result:
    lines += ["## Reference-style and native MuJoCo (same scene, same control)", "",
              "| K | pipeline | envs run | env steps/s | physics steps/s |", "|---:|---|---:|---:|---:|"]
    for k, ref in result["reference"].items():
      for name, r in ref.items():
        lines.append(f"| {k} | {name} | {r['envs']} | {r['env_steps_per_s']:,.1f} | {r['physics_steps_per_s']:,.0f} |")
    lines.append("")
  if "task" in result:
    t = result["task"]
    lines += [f"Task `{t['task']}` ({t['envs']} envs, {t['n_substeps']} substeps): "
              f"{t['physics_steps_per_s']:,.0f} physics steps/s, {t['env_steps_per_s']:,.0f} env steps/s.", ""]
  lines += ["## Summary", "", "```json", json.dumps(result["summary"], indent=1), "```", ""]
  reading = []
  for key, sp in result["summary"].items():
    if key.startswith("speedup_over_reference_K"):
      k = key.rsplit("K", 1)[1]
      reading.append(
          f"- K={k}: MJX damage-aware at {sp['mjx_envs']} envs = {sp['ratio_vs_reference_damage']:.1f}x the "
          f"reference-style pipeline (native MuJoCo + Python evaluators, 1 env at a time), "
          f"{sp['ratio_vs_native_no_damage_1thread']:.2f}x native MuJoCo without damage (1 thread), "
          f"{sp['ratio_vs_rollout_no_damage']:.2f}x mujoco.rollout without damage "
          f"({result['reference'][k]['rollout_no_damage']['threads']} threads).")
  summ = result["summary"]
  grow = [(k, v) for k, v in summ.items()
          if k.startswith("entities_") and "_damage_on_" in k and "_mounted_" not in k]
  fixed = [(k, v) for k, v in summ.items() if k.startswith("tracked_") and "_damage_on_" in k]
  if grow and fixed:
    off = [v for k, v in summ.items()
           if k.startswith("entities_") and "_damage_off_" in k and "_mounted_" not in k]
    reading.append(
        f"- Tracked entities: in one fixed scene, tracking all its boxes instead of one keeps {fixed[0][1]:.0%} of "
        f"the throughput — what damage tracking itself costs. Growing the scene with the tracked boxes keeps "
        f"{grow[0][1]:.1%} (damage off: {off[0] if off else float('nan'):.1%}): that is the physics of more free "
        "bodies, not the damage. Each free box adds 6 dofs and 5 contacts to a scene whose fixed part is a 2-dof "
        "pusher, and MJX's JAX implementation makes every step's constraint work grow faster than K (a dense "
        "constraint Jacobian, nefc x nv, both growing with K). `benchmarks/entity_scaling.py` breaks the step "
        "down by stage; `benchmarks/warp_scaling.py` times the same scenes' raw physics on MuJoCo Warp.")
  mnt = [(k, v) for k, v in summ.items() if k.startswith("entities_") and "_mounted_" in k]
  if mnt:
    on = [v for k, v in mnt if "_damage_on_" in k]
    off = [v for k, v in mnt if "_damage_off_" in k]
    reading.append(
        f"- Mounted entities: growing the scene by damageable boxes mounted on the table (1 free box + K-1 mounted, "
        f"all tracked) keeps {on[0] if on else float('nan'):.0%} of the 1-entity throughput at the largest K "
        f"(damage off: {off[0] if off else float('nan'):.0%}). A tracked entity that adds no degrees of freedom "
        "costs its one designed contact pair (pusher-box) and its damage evaluation: model fixtures the task never "
        "moves (stoves, shelves, wall units) as mounted bodies and keep free joints for what must move.")
  if reading:
    lines += ["## Reading the numbers", ""] + reading + [""]
    if result["platform"] == "cpu":
      native = {k: sp["ratio_vs_native_no_damage_1thread"] for k, sp in result["summary"].items()
                if k.startswith("speedup_over_reference_K")}
      lines += [f"On this CPU the batched MJX (JAX) step reaches {min(native.values()):.2f}-{max(native.values()):.2f}x "
                "the throughput of native MuJoCo stepping one environment on one thread, even at its best batch: "
                "for CPU work choose native MuJoCo (`mjx_damage.native`, numpy-vectorised damage, or the planned CPU "
                "backend) and keep MJX for accelerators. The reference-style per-entity Python evaluators are the "
                "slow path on any device.", ""]
  if result.get("skipped"):
    lines += ["Skipped: " + "; ".join(json.dumps(s) for s in result["skipped"]), ""]
  return "\n".join(lines)


def plot(result: dict, path: str) -> None:
  """Panels: env-steps/s vs envs (a line per K × damage); vs tracked entities as the scene grows and,
  when measured, in a fixed scene (damage on vs off)."""
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  trk = result.get("vs_tracked", [])
  fig, axes = plt.subplots(1, 3 if trk else 2, figsize=(18 if trk else 12, 4.5))
  a, b = axes[0], axes[1]
  settings = sorted({(r["entities"], r["damage"]) for r in result["vs_envs"]})
  for k, dmg in settings:
    rows = sorted((r for r in result["vs_envs"] if r["entities"] == k and r["damage"] == dmg), key=lambda r: r["envs"])
    a.plot([r["envs"] for r in rows], [r["env_steps_per_s"] for r in rows], "o-" if dmg else "s--",
           label=f"K={k} tracked, damage {'on' if dmg else 'off'}")
  for k, ref in result.get("reference", {}).items():
    a.axhline(ref["reference_damage"]["env_steps_per_s"], ls=":", color="gray")
    a.annotate(f"reference-style K={k}", (0.02, ref["reference_damage"]["env_steps_per_s"]),
               xycoords=("axes fraction", "data"), fontsize=8, color="gray", va="bottom")
  a.set(xscale="log", yscale="log", xlabel="parallel environments", ylabel="env steps / s",
        title=f"{result['device']}: throughput vs batch")
  if a.get_legend_handles_labels()[0]:
    a.legend(fontsize=8)
  for section, what in (("vs_entities", "all boxes free"), ("vs_mounted", "1 free + K-1 mounted")):
    for dmg in (True, False):
      rows = sorted((r for r in result.get(section, []) if r["damage"] == dmg), key=lambda r: r["entities"])
      if rows:
        b.plot([r["entities"] for r in rows], [r["env_steps_per_s"] for r in rows],
               ("o-" if dmg else "s--") if section == "vs_entities" else ("^-" if dmg else "v--"),
               label=f"{what}, damage {'on' if dmg else 'off'} ({rows[0]['envs']} envs)")
  b.set(xscale="log", yscale="log", xlabel="tracked entities = boxes in the scene", ylabel="env steps / s",
        title="throughput vs tracked entities (scene grows)")
  if b.get_legend_handles_labels()[0]:
    b.legend(fontsize=8)
  if trk:
    c = axes[2]
    for dmg in (True, False):
      rows = sorted((r for r in trk if r["damage"] == dmg), key=lambda r: r["entities"])
      c.plot([r["entities"] for r in rows], [r["env_steps_per_s"] for r in rows], "o-" if dmg else "s--",
             label=f"damage {'on' if dmg else 'off'} ({rows[0]['envs']} envs)")
    c.set(xscale="log", yscale="log", xlabel=f"tracked entities of {trk[0].get('boxes')} boxes in the scene",
          ylabel="env steps / s", title="throughput vs tracked entities (fixed scene)")
    c.set_ylim(min(r["env_steps_per_s"] for r in trk) / 3, max(r["env_steps_per_s"] for r in trk) * 3)
    c.legend(fontsize=8)
  fig.tight_layout()
  fig.savefig(path, dpi=120)
  plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
  from mjx_damage.scenes import bench_table as S

  ap = argparse.ArgumentParser(prog="mjx-damage bench", description=__doc__.split("\n\n")[0])
  ap.add_argument("--envs", default=None, help="comma-separated batch sizes (default: CPU 1..2048, GPU 1..16384)")
  ap.add_argument("--entities", default=",".join(map(str, ENTITIES)), help="tracked-entity counts K")
  ap.add_argument("--k", type=int, default=32, help="boxes (all tracked) for the vs-envs curve and in the fixed"
                  " scene of the vs-tracked curve (default 32)")
  ap.add_argument("--tracked", default=",".join(map(str, ENTITIES)),
                  help="tracked-box counts n in the fixed --k-box scene ('' to skip)")
  ap.add_argument("--mounted", default=",".join(map(str, ENTITIES)),
                  help="entity counts K of scenes with 1 free box and K-1 mounted boxes, all tracked ('' to skip)")
  ap.add_argument("--jacobian", default="auto", choices=S.JACOBIANS,
                  help="MuJoCo <option jacobian> of the bench scene (auto: MJX goes sparse from nv >= 60)")
  ap.add_argument("--entity-envs", type=int, default=None, help="batch of the vs-entities curve")
  ap.add_argument("--ratio-envs", type=int, default=None, help="batch of the on/off ratio (CPU 1024, GPU 8192)")
  ap.add_argument("--substeps", type=int, default=5, help="physics steps per env step (default 5)")
  ap.add_argument("--target-s", type=float, default=2.0, help="seconds each timed run aims for")
  ap.add_argument("--max-steps", type=int, default=200, help="most env steps per timed run")
  ap.add_argument("--repeats", type=int, default=2, help="timed runs per setting, on/off interleaved; best kept")
  ap.add_argument("--ref-envs", type=int, default=4, help="environments the reference pipeline runs")
  ap.add_argument("--ref-steps", type=int, default=25, help="env steps per reference environment")
  ap.add_argument("--ref-max-s", type=float, default=20.0, help="stop the reference after about this long")
  ap.add_argument("--task", default="place_plate", help="registry task to time ('' to skip)")
  ap.add_argument("--task-envs", type=int, default=None, help="batch for the task (CPU 256, GPU 32768)")
  ap.add_argument("--budget-s", type=float, default=540.0, help="stop starting measurements after this long")
  ap.add_argument("--note", dest="notes", action="append", default=[], help="free text stored in the JSON")
  ap.add_argument("--out", default="bench.json", help="JSON path (the PNG goes beside it)")
  return ap


def main(argv=None) -> int:
  argv = list(sys.argv[1:] if argv is None else argv)
  ap = build_parser()
  args = ap.parse_args(argv)
  args.argv = argv
  import jax

  gpu = jax.devices()[0].platform != "cpu"
  args.envs = args.envs or ",".join(map(str, GPU_ENVS if gpu else CPU_ENVS))
  args.entity_envs = args.entity_envs or (8192 if gpu else 1024)
  args.ratio_envs = args.ratio_envs or (8192 if gpu else 1024)
  args.task_envs = args.task_envs or (32768 if gpu else 256)
  try:
    envs = _parse_ints("--envs", args.envs)
    _parse_ints("--entities", args.entities)
    if args.mounted:
      _parse_ints("--mounted", args.mounted)
    if args.tracked:
      big = [t for t in _parse_ints("--tracked", args.tracked) if t > args.k]
      if big:
        raise ValueError(f"--tracked: counts {big} exceed the --k={args.k} boxes of the scene")
    for name in ("k", "entity_envs", "ratio_envs", "substeps", "max_steps", "ref_envs", "ref_steps", "task_envs",
                 "repeats"):
      if getattr(args, name) < 1:
        raise ValueError(f"--{name.replace('_', '-')}: must be >= 1, got {getattr(args, name)}")
    if args.ratio_envs not in envs:
      envs.append(args.ratio_envs)
      args.envs = ",".join(map(str, sorted(envs)))
  except ValueError as e:
    ap.error(str(e))
  print(f"mjx-damage bench on {jax.devices()[0].device_kind} ({jax.device_count()} device(s))", flush=True)
  result = run_benchmark(args)  # saves JSON/MD/PNG after every point and at the end
  png = os.path.splitext(args.out)[0] + ".png"
  print(json.dumps(result["summary"], indent=1))
  print(f"wrote {args.out} and {png}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

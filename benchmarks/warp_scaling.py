"""Is the free-body entity scaling an MJX-JAX artefact? The same scenes on MuJoCo Warp.

``mjx-damage bench`` finds that growing the bench scene from 1 to 32 free boxes
keeps ~3 % of the throughput, damage on or off. This script times the raw
physics (``mjx.step``, no damage: mjx_damage's damage path reads the JAX
implementation's contact layout) of the same scenes under both MJX
implementations in one process:

* ``impl=jax``  — MJX's JAX implementation (what mjx_damage runs on);
* ``impl=warp`` — MJX's MuJoCo Warp implementation (sparse constraint Jacobian,
  per-world kernels), CG as in the bench scene and Newton, and Newton with
  MuJoCo's sleeping enabled (resting bodies stop being simulated).

Scenes (``tasks.bench_table``): K free boxes; 1 free box + K-1
mounted boxes; the pusher follows the bench's Lissajous sweep over the whole
grid ("sweep") or a small circle at the grid centre ("local", so most boxes rest
and can sleep).

The ``*-damage`` configs time the damage-aware step instead, every box a tracked
entity: ``jax-cg-damage`` (``mjx_damage.physics.step`` vmapped) and
``warp-cg-damage`` / ``warp-newton-damage`` (``mjx_damage.warp_step.step``, the
MuJoCo Warp backend), so "K free tracked boxes keep X % of the 1-box throughput
with damage on" is measured for both implementations.

warp-lang is the optional ``warp`` extra (a 150 MB wheel; MuJoCo Warp is only
fast on NVIDIA GPUs, and MJX 3.17 vendors it, so warp-lang is all it needs).
Usage, with warp-lang importable::

    python benchmarks/warp_scaling.py --envs 8192 --out $OUT/warp_scaling_gpu.json

How the GPU results were run (the device tool sends at most 64 MiB a call, the repo's
working tree included, and keeps a machine for 30 s between calls): here, unpack the
warp-lang 1.19.0 wheel (py3 manylinux_2_28), drop ``warp/bin/warp-clang.so`` (Warp's CPU
compiler, loaded only if present; the GPU path does not need it), ``warp/examples`` and
``warp/tests``, ``tar | xz -9`` the rest (76 MiB) and split it into a 44 MiB part ``.wpa/p``
and the rest ``.wpb/p`` (git-ignored). Call 1 carries ``.wpa`` and copies it to ``/tmp/pa``;
call 2 carries ``.wpb`` (with the small wheels: brax, trimesh and their pure-Python needs, in
``.wpb/whl``) and joins the parts into ``/tmp/w.tar.xz``; call 3 carries the mujoco and
mujoco-mjx 3.17.0 wheels (cp312) in ``.wpc`` and runs::

    python3 -m pip install -q --no-index --no-deps --target /tmp/site /tmp/wpc/*.whl .wpc/*.whl
    xz -d < /tmp/w.tar.xz | tar -x -C /tmp/site
    PYTHONPATH=/tmp/site:$PWD python3 benchmarks/warp_scaling.py --envs 8192 --out $OUT/warp_scaling_gpu.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

# (name, impl, solver, sleep); CG matches the bench scene (4 iterations, 8 line-search steps).
# "-damage": the damage-aware step with every box tracked (tasks.bench_table.table_config): MJX-JAX's
# mjx_damage.physics.step vmapped, or MuJoCo Warp's batch step mjx_damage.warp_step.step.
CONFIGS = {
    "jax-cg": ("jax", "CG", False),
    "warp-cg": ("warp", "CG", False),
    "warp-newton": ("warp", "Newton", False),
    "warp-newton-sleep": ("warp", "Newton", True),
    "jax-cg-damage": ("jax", "CG", False),
    "warp-cg-damage": ("warp", "CG", False),
    "warp-newton-damage": ("warp", "Newton", False),
}


def timed(advance, state, nstep: int):
  """``nstep`` calls of ``advance`` in one compiled loop: (state, compile-and-first-call s, [2 timed calls' s])."""
  import jax

  roll = jax.jit(lambda x: jax.lax.fori_loop(0, nstep, lambda _, y: advance(y), x))
  t0 = time.perf_counter()
  state = jax.block_until_ready(roll(state))
  compile_s = time.perf_counter() - t0
  times = []
  for _ in range(2):
    t0 = time.perf_counter()
    state = jax.block_until_ready(roll(state))
    times.append(time.perf_counter() - t0)
  return state, compile_s, times


def measure(config: str, k: int, free: int, motion: str, envs: int, nstep: int) -> dict:
  import jax
  import jax.numpy as jnp
  import mujoco
  import numpy as np
  from mujoco import mjx

  from tasks import bench_table as S
  from tasks.bench_table import pusher_ctrl

  impl, solver, sleep = CONFIGS[config]
  m = S.table_scene(k, solver=solver, free=free)
  if sleep:
    m.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_SLEEP
  radius = S.sweep_radius(k) if motion == "sweep" else 0.04
  per_world_contacts = 5 * free + (k - free) + 4  # contact places per world (warp's buffers, damage slots)
  if impl == "warp":
    mx = mjx.put_model(m, impl="warp")
    # iteration-limit warnings are printed from the kernels every step: they would be timed
    mx = mx.replace(opt=mx.opt.replace(_impl=mx.opt._impl.replace(warn_overflow=0)))
    d = jax.jit(jax.vmap(lambda _: mjx.make_data(m, impl="warp", naconmax=envs * per_world_contacts,
                                                njmax=4 * per_world_contacts + 8)))(jnp.arange(envs))
  else:
    mx = mjx.put_model(m)
    d = jax.tree.map(lambda x: jnp.broadcast_to(x, (envs,) + x.shape), mjx.make_data(mx))

  def ctrl(d):
    return d.replace(ctrl=pusher_ctrl(d.time, radius, jnp).astype(d.ctrl.dtype))

  damage = config.endswith("-damage")
  if damage:
    from mjx_damage import physics, warp_step
    from mjx_damage.binding import bind

    binding = bind(m, S.table_config(k))
    ds = jax.vmap(lambda _: physics.init_state(binding))(jnp.arange(envs))
    if impl == "warp":
      slots = per_world_contacts

      def advance(state):
        d, ds = state
        d, ds, _ = warp_step.step(mx, binding, jax.vmap(ctrl)(d), ds, 1, slots)
        return d, ds
    else:
      def advance(state):
        return jax.vmap(lambda d, ds: physics.step(mx, binding, ctrl(d), ds, 1))(*state)
    state = (d, ds)
  else:
    def advance(d):
      return jax.vmap(lambda x: mjx.step(mx, ctrl(x)))(d)
    state = d

  state, compile_s, times = timed(advance, state, nstep)
  d = state[0] if damage else state
  z = np.asarray(d.xpos[:, 2:, 2])  # box heights (bodies after world and pusher)
  extra = {"damage": True, "min_health": float(jnp.min(state[1].link_health))} if damage else {}
  return {**extra, "config": config, "impl": impl, "solver": solver, "sleep": sleep, "boxes": k, "free_boxes": free,
          "motion": motion, "nv": int(m.nv), "envs": envs, "steps": nstep, "compile_and_first_s": compile_s,
          "seconds": min(times), "physics_steps_per_s": envs * nstep / min(times),
          "finite": bool(np.isfinite(np.asarray(d.qpos)).all()),
          "box_height_min_max_m": [float(z.min()), float(z.max())]}


def measure_task(name: str, backend: str, envs: int, nstep: int, robot: str) -> dict:
  """Env-steps/s of registry task ``name``'s damage-aware step (zero action, ``vmap(env.step)`` in a compiled
  loop) with its physics on ``backend``: "jax" (MJX-JAX) or "warp" (MuJoCo Warp via tasks.make(backend="warp"))."""
  import jax
  import jax.numpy as jnp
  import numpy as np

  import tasks

  kw = {"robot": robot, **({"backend": "warp", "num_envs": envs} if backend == "warp" else {})}
  env = tasks.make(name, **kw)
  state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), envs))
  act = jnp.zeros((envs, env.action_size))
  state, compile_s, times = timed(lambda x: jax.vmap(env.step)(x, act), state, nstep)
  n_sub = env.unwrapped.n_substeps
  return {"task": name, "backend": backend, "robot": robot, "envs": envs, "steps": nstep, "n_substeps": n_sub,
          "compile_and_first_s": compile_s, "seconds": min(times), "env_steps_per_s": envs * nstep / min(times),
          "physics_steps_per_s": envs * nstep * n_sub / min(times),
          "finite": bool(np.isfinite(np.asarray(state.pipeline_state.qpos)).all()),
          "min_health": float(jnp.min(state.info["entity_health"]))}


def _k1(rows: list[dict], r: dict):
  """The K=1 row of ``r``'s config and motion (the denominator of its ratio), or None."""
  return next((b for b in rows if b["config"] == r["config"] and b["motion"] == r["motion"] and b["boxes"] == 1),
              None)


def summarize(rows: list[dict]) -> dict:
  out = {}
  for r in rows:
    if r["boxes"] == 1:
      continue
    base = _k1(rows, r)
    if base:
      scene = "free" if r["free_boxes"] == r["boxes"] else f"{r['free_boxes']}free"
      out[f"{r['config']}_{r['motion']}_K{r['boxes']}_{scene}_over_K1"] = (
          r["physics_steps_per_s"] / base["physics_steps_per_s"])
  return out


def report_md(res: dict) -> str:
  lines = [f"# Entity scaling on MuJoCo Warp vs MJX-JAX ({res['device']})", "",
           f"Command: `{res['command']}`  ", f"Date: {res['date']}; versions: {json.dumps(res['versions'])}", "",
           "Raw physics (`mjx.step`, no damage), one physics step per iteration, batch "
           f"{res['envs']}. Scene: `tasks.bench_table` (K boxes, the first `free` with free joints, the "
           "rest mounted; pusher on 2 slide joints). motion `sweep` = the bench's Lissajous over the whole grid, "
           "`local` = a 4 cm circle at the grid centre. How to run it on the GPU machine: the docstring of "
           "`benchmarks/warp_scaling.py`.", "",
           "| config | motion | boxes | free | nv | physics steps/s | x K=1 | compile+first s | finite |",
           "|---|---|---:|---:|---:|---:|---:|---:|---|"]
  for r in res["rows"]:
    base = _k1(res["rows"], r)
    rel = f"{r['physics_steps_per_s'] / base['physics_steps_per_s']:.1%}" if base else ""
    lines.append(f"| {r['config']} | {r['motion']} | {r['boxes']} | {r['free_boxes']} | {r['nv']} | "
                 f"{r['physics_steps_per_s']:,.0f} | {rel} | {r['compile_and_first_s']:.1f} | {r['finite']} |")
  if res.get("task_rows"):
    lines += ["", "Task step with damage (zero action, `vmap(env.step)`; `tasks.make(name, backend=\"warp\", "
              "num_envs=N)` for Warp):", "",
              "| task | robot | backend | envs | env-steps/s | physics steps/s | x jax | compile+first s | finite |",
              "|---|---|---|---:|---:|---:|---:|---:|---|"]
    for r in res["task_rows"]:
      base = next((b for b in res["task_rows"] if b["task"] == r["task"] and b["backend"] == "jax"), None)
      rel = f"{r['env_steps_per_s'] / base['env_steps_per_s']:.2f}" if base else ""
      lines.append(f"| {r['task']} | {r['robot']} | {r['backend']} | {r['envs']} | {r['env_steps_per_s']:,.0f} | "
                   f"{r['physics_steps_per_s']:,.0f} | {rel} | {r['compile_and_first_s']:.1f} | {r['finite']} |")
  if res.get("errors"):
    lines += ["", "Errors: " + "; ".join(json.dumps(e) for e in res["errors"])]
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  ap.add_argument("--envs", type=int, default=8192)
  ap.add_argument("--steps", type=int, default=200, help="physics steps per timed call")
  ap.add_argument("--plan", default="jax-cg:sweep:1:1,jax-cg:sweep:32:32,jax-cg:sweep:32:1,"
                  "warp-cg:sweep:1:1,warp-cg:sweep:32:32,warp-cg:sweep:32:1,"
                  "warp-newton:sweep:1:1,warp-newton:sweep:32:32,warp-newton:sweep:32:1,"
                  "warp-newton:local:1:1,warp-newton:local:32:32,"
                  "warp-newton-sleep:local:1:1,warp-newton-sleep:local:32:32",
                  help="comma-separated config:motion:boxes:free points, run in order")
  ap.add_argument("--tasks", default="", help="registry tasks whose damage-aware step is also timed on both "
                  "backends (comma-separated, e.g. place_plate; default none)")
  ap.add_argument("--robot", default="gripper", help="robot of --tasks (default gripper)")
  ap.add_argument("--task-steps", type=int, default=20, help="env steps per timed call of --tasks")
  ap.add_argument("--out", required=True)
  args = ap.parse_args(argv)
  plan = []
  for item in args.plan.split(","):
    try:
      config, motion, k, free = item.split(":")
      k, free = int(k), int(free)
    except ValueError:
      ap.error(f"--plan: expected config:motion:boxes:free, got {item!r}")
    if config not in CONFIGS or motion not in ("sweep", "local") or not 1 <= free <= k:
      ap.error(f"--plan: bad point {item!r} (configs {sorted(CONFIGS)}, motion sweep|local, 1 <= free <= boxes)")
    plan.append((config, motion, k, free))
  if args.envs < 1 or args.steps < 1 or args.task_steps < 1:
    ap.error("--envs, --steps and --task-steps must be >= 1")
  task_list = [t for t in args.tasks.split(",") if t]
  if task_list:
    import tasks

    try:
      tasks.check_robot(args.robot, task_list, "--robot")
      for t in task_list:
        tasks.task_class(t)
    except ValueError as e:
      ap.error(f"--tasks/--robot: {e}")
  import mjx_damage  # noqa: F401  (its XLA:CPU flags before jax starts)
  import jax
  import mujoco

  res = {"command": "python benchmarks/warp_scaling.py " + " ".join(sys.argv[1:] if argv is None else argv),
         "date": time.strftime("%Y-%m-%d %H:%M:%S"), "device": jax.devices()[0].device_kind,
         "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__}, "envs": args.envs, "rows": [],
         "errors": []}
  try:
    import warp

    warp.config.quiet = True  # no per-module load lines in the log
    res["versions"]["warp"] = warp.__version__
  except ImportError:
    pass
  for config, motion, k, free in plan:
    try:
      row = measure(config, k, free, motion, args.envs, args.steps)
      res["rows"].append(row)
      print(json.dumps(row), flush=True)
    except Exception as e:  # keep the other points (e.g. warp not installed)
      res["errors"].append({"point": f"{config}:{motion}:{k}:{free}", "error": f"{type(e).__name__}: {str(e)[:300]}"})
      print("error", res["errors"][-1], flush=True)
    res["summary"] = summarize(res["rows"])
    with open(args.out, "w") as f:
      json.dump(res, f, indent=1)
    with open(os.path.splitext(args.out)[0] + ".md", "w") as f:
      f.write(report_md(res))
  res["task_rows"] = []
  for name in task_list:
    for backend in ("jax", "warp"):
      try:
        row = measure_task(name, backend, args.envs, args.task_steps, args.robot)
        res["task_rows"].append(row)
        print(json.dumps(row), flush=True)
      except Exception as e:  # keep the other points
        res["errors"].append({"point": f"task:{name}:{backend}", "error": f"{type(e).__name__}: {str(e)[:300]}"})
        print("error", res["errors"][-1], flush=True)
      with open(args.out, "w") as f:
        json.dump(res, f, indent=1)
      with open(os.path.splitext(args.out)[0] + ".md", "w") as f:
        f.write(report_md(res))
  print(json.dumps(res["summary"], indent=1))
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""Why the Panda's step was slow on CPU, and what the fix buys: gripper vs Panda, with and without it.

One command, one results file (``benchmarks/results/panda_speed_<backend>.{json,md}``). Every
measurement runs in a fresh worker process (XLA reads its flags once per process) in two modes:

* ``fix`` — the package's XLA:CPU flags as ``import mjx_damage`` sets them (mjx_damage/runtime.py),
  including ``--xla_cpu_use_fusion_emitters=false``;
* ``emitters`` — the same with XLA's new CPU fusion emitters left on (the state before the fix).

Per mode the worker measures:

1. **kinematic chain depth** (``--chain``): ``mjx.kinematics`` of a chain of N hinge bodies, 4 envs,
   ms per call — the cost that is exponential in N with the new emitters;
2. **task steps** (``--tasks`` × ``--robots``): contact slots and constraint rows of the compiled
   scene, compile time of ``jit(vmap(env.step))`` over ``--envs`` envs (persistent cache off), and
   env-steps/s over ``--steps`` steps of zero actions after one warm-up call;
3. **pieces of the step** (same tasks × robots, ``--envs`` envs, ms per call): ``mjx.kinematics``,
   the collision functions on a kinematic ``Data`` (``collision_driver.collision``), one
   ``mjx.step`` substep, and the robot's controller (``robot.ctrl``, once per control step).

The 1-minute load average is recorded beside each worker (the CPU is shared, so absolute times
vary with other users; compare rows of one run).

Usage::

    .venv/bin/python benchmarks/panda_speed.py [--tasks place_plate] [--robots gripper,panda] \
        [--envs 4] [--steps 20] [--chain 4,6,8] [--modes fix,emitters]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

RESULTS = os.path.join(os.path.dirname(__file__), "results")
MODES = ("fix", "emitters")
SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler=false"


def _load() -> float:
  return round(os.getloadavg()[0], 2)


def _chain_xml(n: int) -> str:
  body = "".join('<body pos="0 0 0.1" quat="0.7071068 0.7071068 0 0"><joint type="hinge" axis="0 0 1"/>'
                 '<geom type="capsule" size="0.02" fromto="0 0 0 0 0 0.1"/>' for _ in range(n))
  return f"<mujoco><worldbody>{body}{'</body>' * n}</worldbody></mujoco>"


def worker(a) -> None:
  """Runs in the child process; prints one JSON object per measurement."""
  import jax
  import jax.numpy as jnp
  import mujoco

  import mjx_damage  # noqa: F401  (sets the XLA:CPU flags unless MJX_DAMAGE_XLA_CPU_FIX=0)
  import tasks
  from mujoco import mjx
  from mujoco.mjx._src import collision_driver

  jax.config.update("jax_enable_compilation_cache", False)

  def per_call(c, *args, n):
    jax.block_until_ready(c(*args))
    t0 = time.perf_counter()
    for _ in range(n):
      out = c(*args)
    jax.block_until_ready(out)
    return (time.perf_counter() - t0) / n

  for n in [int(x) for x in a.chain.split(",") if x]:
    sys_ = mjx.put_model(mujoco.MjModel.from_xml_string(_chain_xml(n)))
    d = jax.vmap(lambda _: mjx.make_data(sys_))(jnp.arange(4))
    c = jax.jit(jax.vmap(lambda d: mjx.kinematics(sys_, d))).lower(d).compile()
    dt = per_call(c, d, n=5)
    print(json.dumps({"kind": "chain", "depth": n, "ms_per_call_4_envs": round(dt * 1e3, 3), "load": _load()}),
          flush=True)

  for name in [t for t in a.tasks.split(",") if t]:
    for robot in [r for r in a.robots.split(",") if r]:
      env = tasks.make(name, robot=robot)
      u = env.unwrapped
      shape = jax.eval_shape(lambda: mjx.make_data(u.sys))
      rng = jax.random.split(jax.random.PRNGKey(0), a.envs)
      t0 = time.perf_counter()
      s = jax.jit(jax.vmap(env.reset)).lower(rng).compile()(rng)
      t_reset = time.perf_counter() - t0
      act = jnp.zeros((a.envs, env.action_size))
      t0 = time.perf_counter()
      step = jax.jit(jax.vmap(env.step)).lower(s, act).compile()
      t_step = time.perf_counter() - t0
      s = jax.block_until_ready(step(s, act))
      t0 = time.perf_counter()
      for _ in range(a.steps):
        s = step(s, act)
      jax.block_until_ready(s)
      rate = a.envs * a.steps / (time.perf_counter() - t0)
      print(json.dumps({
          "kind": "task", "task": name, "robot": robot, "nv": int(u.mj_model.nv),
          "contacts": int(shape._impl.contact.dist.shape[0]), "constraint_rows": int(shape._impl.efc_J.shape[0]),
          "substeps": u.n_substeps, "solver_iterations": int(u.mj_model.opt.iterations),
          "ls_iterations": int(u.mj_model.opt.ls_iterations), "envs": a.envs, "steps": a.steps,
          "reset_compile_s": round(t_reset, 1), "step_compile_s": round(t_step, 1),
          "env_steps_per_s": round(rate, 2), "physics_steps_per_s": round(rate * u.n_substeps, 1),
          "load": _load()}), flush=True)
      d = s.pipeline_state
      pieces = {
          "kinematics": (jax.vmap(lambda d: mjx.kinematics(u.sys, d)), (d,)),
          "collision": (jax.vmap(lambda d: collision_driver.collision(u.sys, d)), (d,)),
          "mjx_step": (jax.vmap(lambda d: mjx.step(u.sys, d)), (d,)),
          "ctrl": (jax.vmap(lambda d, a: u.robot.ctrl(d, a, u.ws_lo, u.ws_hi)), (d, act)),
      }
      for piece, (f, args) in pieces.items():
        dt = per_call(jax.jit(f).lower(*args).compile(), *args, n=5)
        print(json.dumps({"kind": "piece", "task": name, "robot": robot, "piece": piece, "envs": a.envs,
                          "ms_per_call": round(dt * 1e3, 3), "load": _load()}), flush=True)


def run_mode(mode: str, argv: list[str], timeout: float) -> list[dict]:
  env = dict(os.environ)
  if mode == "emitters":
    env["MJX_DAMAGE_XLA_CPU_FIX"] = "0"
    env["XLA_FLAGS"] = SCHEDULER
  else:
    env.pop("MJX_DAMAGE_XLA_CPU_FIX", None)
    env.pop("XLA_FLAGS", None)
  r = subprocess.run([sys.executable, __file__, "--worker", *argv], env=env, capture_output=True, text=True,
                     timeout=timeout)
  rows = [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]
  if r.returncode != 0:
    raise RuntimeError(f"worker ({mode}) failed:\n{r.stderr[-3000:]}")
  for row in rows:
    row["mode"] = mode
  return rows


def write(rows: list[dict], command: str) -> None:
  import jax

  from mjx_damage import io, runtime

  stem = os.path.join(RESULTS, f"panda_speed_{jax.default_backend()}")
  meta = {"command": command, "jax": jax.__version__, "cpu_count": os.cpu_count(), "device": runtime.device_info()[1],
          "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
  io.write_json(stem + ".json", {"meta": meta, "rows": rows}, indent=1)
  render(stem, meta, rows)


def render(stem: str, meta: dict, rows: list[dict]) -> None:
  """``stem``.md from the results (also to re-render a JSON file: ``render(stem, **json.load(...))``)."""
  from mjx_damage import io

  command = meta["command"]
  device = meta.get("device", f"{meta['cpu_count']} CPU cores (shared)")
  lines = [f"# Panda vs gripper step cost ({device}), with and without the XLA:CPU fusion-emitter fix", "",
           f"Command: `{command}`  ", f"jax {meta['jax']}, {device}, host {meta['cpu_count']} CPU cores, {meta['date']}. "
           "`fix`: the flags `import mjx_damage` sets; `emitters`: XLA's new CPU fusion emitters left on "
           "(before the fix). load = 1-min load average when the row finished."
           + (f" Note: {meta['note']}" if meta.get("note") else ""), "",
           "## mjx.kinematics of a chain of N hinges (4 envs)", "", "| mode | N | ms per call | load |", "|---|---|---|---|"]
  lines += [f"| {r['mode']} | {r['depth']} | {r['ms_per_call_4_envs']:.2f} | {r['load']} |"
            for r in rows if r["kind"] == "chain"]
  lines += ["", "## One control step of a task, jit(vmap(env.step))", "",
            "| mode | task | robot | contacts | constraint rows | envs | reset compile s | step compile s "
            "| env-steps/s | physics steps/s | load |", "|---|---|---|---|---|---|---|---|---|---|---|"]
  lines += [f"| {r['mode']} | {r['task']} | {r['robot']} | {r['contacts']} | {r['constraint_rows']} | {r['envs']} "
            f"| {r['reset_compile_s']} | {r['step_compile_s']} | {r['env_steps_per_s']} | {r['physics_steps_per_s']} "
            f"| {r['load']} |" for r in rows if r["kind"] == "task"]
  lines += ["", "## Pieces of the step (ms per call of `envs` envs)", "", "| mode | task | robot | piece | envs "
            "| ms per call | load |", "|---|---|---|---|---|---|---|"]
  lines += [f"| {r['mode']} | {r['task']} | {r['robot']} | {r['piece']} | {r['envs']} | {r['ms_per_call']} | {r['load']} |"
            for r in rows if r["kind"] == "piece"]
  io.write_text(stem + ".md", "\n".join(lines) + "\n")


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--tasks", default="place_plate")
  p.add_argument("--robots", default="gripper,panda")
  p.add_argument("--envs", type=int, default=4)
  p.add_argument("--steps", type=int, default=20)
  p.add_argument("--chain", default="4,6,8")
  p.add_argument("--modes", default=",".join(MODES))
  p.add_argument("--timeout", type=float, default=3600.0, help="s per worker process")
  p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
  argv = sys.argv[1:] if argv is None else argv
  a = p.parse_args(argv)
  if a.envs < 1 or a.steps < 1:
    raise ValueError(f"envs/steps: must be positive, got {a.envs}/{a.steps}")
  modes = [m for m in a.modes.split(",") if m]
  for m in modes:
    if m not in MODES:
      raise ValueError(f"modes: unknown {m!r} (valid: {', '.join(MODES)})")
  if a.worker:
    worker(a)
    return 0
  import tasks  # validate names before any worker compiles
  from tasks import robots

  for t in [t for t in a.tasks.split(",") if t]:
    tasks.task_class(t)
  for r in [r for r in a.robots.split(",") if r]:
    robots.robot_class(r)
  rows = []
  for m in modes:
    new = run_mode(m, argv, a.timeout)
    for row in new:
      print(json.dumps(row), flush=True)
    rows += new
  write(rows, ".venv/bin/python benchmarks/panda_speed.py " + " ".join(argv))
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

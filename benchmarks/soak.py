"""Soak: random (and extreme) actions through every task with auto-reset, every step checked on device.

For each task of ``tasks.names()``: ``--envs`` environments under the training
stack (``tasks.make(name)`` → Brax's EpisodeWrapper(task episode length) →
VmapWrapper → AutoResetWrapper) take uniform random actions in [−1, 1] (or,
with ``--scripted-noise σ``, the safe script's plus N(0, σ²) noise), of
which a share ``--extreme-frac`` of the entries is replaced by one of
±1e3, NaN, ±inf. Steps run in compiled ``lax.scan`` chunks of ``--chunk``
steps; every check is a counter in the scan carry (no host round trip per
step). Counted over all (env, step) pairs:

- ``non_finite``: obs, reward, cost, entity health, qpos, qvel, ctrl or any
  dynamic part of the damage state (link health, temperatures, loads, heat
  sources, particles) not all finite;
- ``health_out_of_range``: some link health outside [0, 100];
- ``health_increase``: some link health above its value at the previous step
  of the same episode (DAMAGE_MODEL.md: health never rises within an episode;
  the first step after an auto-reset starts a new episode and is not compared);
- ``particle_violations`` (tasks with liquid): the number of live particles —
  finite position and velocity, not below the lowest collidable plane by more
  than a diameter — differs from the configured count;
- ``extreme_injected`` / ``action_sanitised``: extreme entries sent, and those
  the env reports in ``metrics["action_sanitised"]`` (uniform entries are
  valid, so they must be equal: ``sanitise_mismatch`` counts steps where not).

Usage::

    .venv/bin/python benchmarks/soak.py --workers 6 --envs 2048   # GPU: 1e6 steps per task, 6 processes
    .venv/bin/python benchmarks/soak.py --robot panda --workers 6 --envs 2048   # every task the Panda runs
    nice -n 10 .venv/bin/python benchmarks/soak.py                # CPU: 8 envs × 400 steps per task
    .venv/bin/python benchmarks/soak.py --tasks shelve_item --scripted-noise 0.5 --envs 256 --steps 256000 \
        --chunk 100 --out benchmarks/results/soak_shelve_item_scripted_noise_cpu.json   # near the safe script's path

``--workers``: the tasks are dealt to that many processes, which share the device. On one H100,
2048 envs × 500 steps per task ran all 22 tasks in 316 s with 6 workers; a first attempt at 512
envs × 2000 steps (the same 1e6 steps, but 4× the sequential steps, each latency-bound), with 11
soak processes and another job on the GPU, finished 9 tasks in 570 s. Each process writes its
file after every task, so a run stopped part-way keeps what finished and the merged file lists
the tasks not run.

Writes ``benchmarks/results/soak_<platform>.{json,md}`` (``soak_<robot>_<platform>`` for a robot
other than the gripper; ``--out``: another
JSON path, the .md beside it); exits 1 when any counter above is non-zero.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time

import mjx_damage  # noqa: F401  (package-wide JAX settings before JAX starts)
from mjx_damage import io

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs.wrappers import training as bw

import tasks
from apps.workers import argv_without
from tasks import robots

HERE = os.path.dirname(os.path.abspath(__file__))
EXTREMES = (1e3, -1e3, float("nan"), float("inf"), float("-inf"))
ROBOT = "gripper"  # the committed results' robot; robots.DEFAULT may differ
COUNTERS = ("non_finite", "health_out_of_range", "health_increase", "particle_violations", "sanitise_mismatch")


def liquid_floor(env) -> float:
  """z (m) below which a particle has left the scene: the lowest collidable world plane − 2·radius.

  ``-inf`` when the liquid collides with no plane (only non-finite state counts then).
  """
  task = env.unwrapped
  lm = task.damage_binding.liquid
  m = task.mj_model
  d = mujoco.MjData(m)
  mujoco.mj_kinematics(m, d)
  planes = [g for g in np.asarray(lm.column_geom) if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE
            and m.geom_bodyid[g] == 0 and np.allclose(d.geom_xmat[g].reshape(3, 3)[:, 2], (0, 0, 1))]
  if not planes:
    return -float("inf")
  return float(min(d.geom_xpos[g][2] for g in planes)) - 2.0 * lm.radius


def build(env, envs: int, chunk: int, extreme_frac: float, episode_length: int | None = None,
          scripted_noise: float | None = None):
  """``(reset(key) -> carry, run(carry) -> carry)``: one compiled chunk of ``chunk`` steps of ``envs`` envs.

  ``scripted_noise``: None for uniform random actions; σ ≥ 0 for the task's safe script plus
  Gaussian noise N(0, σ²) on every action entry (clipped to [−1, 1]), which keeps the envs near the
  states a learner cloned from demonstrations visits (carrying, lifting, placing) instead of the
  counter-top flailing of uniform actions. Extreme entries are injected on top as before.

  ``env``: a damage-wrapped env (:func:`tasks.make`); ``episode_length``
  (default: the task's) is where Brax's EpisodeWrapper truncates. The carry holds the batched state, the previous step's link health f32[E, L]
  and done f32[E], a key, and the int32 counters of the module docstring (plus
  ``steps``, ``episodes``, ``extreme_injected``, ``action_sanitised``).
  """
  task = env.unwrapped
  episode_length = task.episode_length if episode_length is None else episode_length
  stack = bw.AutoResetWrapper(bw.VmapWrapper(bw.EpisodeWrapper(env, episode_length, action_repeat=1)))
  lm = task.damage_binding.liquid
  n_particles = 0 if lm is None else lm.num_particles
  floor = liquid_floor(env) if lm is not None else 0.0
  A = env.action_size
  extremes = jnp.asarray(EXTREMES, jnp.float32)
  script = None if scripted_noise is None else jax.vmap(tasks.scripted_policy(env, "safe"))

  def reset(key):
    k0, key = jax.random.split(key)
    s = stack.reset(jax.random.split(k0, envs))
    zero = jnp.zeros((), jnp.int32)
    counts = {k: zero for k in COUNTERS + ("steps", "episodes", "extreme_injected", "action_sanitised")}
    return s, s.info["link_health"], jnp.zeros((envs,), jnp.float32), key, counts

  def one_step(carry, _):
    s, prev_h, prev_done, key, c = carry
    key, ku, ke, kv = jax.random.split(key, 4)
    if script is None:
      a = jax.random.uniform(ku, (envs, A), minval=-1.0, maxval=1.0)
    else:
      ks, kn = jax.random.split(ku)
      a = jnp.clip(script(s, jax.random.split(ks, envs)) + scripted_noise * jax.random.normal(kn, (envs, A)),
                   -1.0, 1.0)
    extreme = jax.random.uniform(ke, (envs, A)) < extreme_frac
    a = jnp.where(extreme, extremes[jax.random.randint(kv, (envs, A), 0, len(EXTREMES))], a)
    s = stack.step(s, a)

    def finite(x):
      return jnp.all(jnp.isfinite(x.reshape(envs, -1)), axis=1)

    d = s.pipeline_state
    # the damage state's dynamic parts: health, temperatures, loads, heat sources, particles
    dyn = jax.tree.leaves(s.info["damage_state"].replace(params=None))
    ok = (finite(s.obs) & finite(s.reward) & finite(s.info["cost"]) & finite(s.info["entity_health"])
          & finite(d.qpos) & finite(d.qvel) & finite(d.ctrl))
    for x in dyn:
      ok = ok & finite(x)
    h = s.info["link_health"]
    out_of_range = jnp.any((h < 0.0) | (h > 100.0), axis=1)
    rose = jnp.any(h > prev_h, axis=1) & (prev_done == 0)
    if lm is not None:
      liq = s.info["damage_state"].liquid
      live = (jnp.all(jnp.isfinite(liq.pos), -1) & jnp.all(jnp.isfinite(liq.vel), -1) & (liq.pos[..., 2] >= floor))
      lost = jnp.sum(live, axis=1) != n_particles
    else:
      lost = jnp.zeros((envs,), bool)
    sanitised = s.metrics["action_sanitised"]
    injected = jnp.sum(extreme, axis=1)
    n = lambda b: jnp.sum(b.astype(jnp.int32))  # noqa: E731
    c = {
        "non_finite": c["non_finite"] + n(~ok),
        "health_out_of_range": c["health_out_of_range"] + n(out_of_range),
        "health_increase": c["health_increase"] + n(rose),
        "particle_violations": c["particle_violations"] + n(lost),
        "sanitise_mismatch": c["sanitise_mismatch"] + n(sanitised != injected),
        "steps": c["steps"] + envs,
        "episodes": c["episodes"] + n(s.done > 0),
        "extreme_injected": c["extreme_injected"] + jnp.sum(injected),
        "action_sanitised": c["action_sanitised"] + jnp.sum(sanitised).astype(jnp.int32),
    }
    return (s, h, s.done, key, c), None

  def run(carry):
    carry, _ = jax.lax.scan(one_step, carry, None, length=chunk)
    return carry

  return jax.jit(reset), jax.jit(run, donate_argnums=0)


def soak_task(name: str, envs: int, steps: int, chunk: int, extreme_frac: float, seed: int = 0,
              robot: str = ROBOT, scripted_noise: float | None = None) -> dict:
  """Soak one task with ``robot``: ``steps`` env steps per env (rounded up to whole chunks). Counts as plain ints."""
  env = tasks.make(name, robot=robot)
  reset, run = build(env, envs, chunk, extreme_frac, scripted_noise=scripted_noise)
  t0 = time.perf_counter()
  carry = reset(jax.random.PRNGKey(seed))
  carry = run(carry)
  jax.block_until_ready(carry[-1])
  first = time.perf_counter() - t0
  for _ in range(-(-steps // chunk) - 1):
    carry = run(carry)
  counts = {k: int(v) for k, v in jax.device_get(carry[-1]).items()}
  wall = time.perf_counter() - t0
  lm = env.unwrapped.damage_binding.liquid
  return {
      "task": name, "robot": robot, **counts,
      "particles": 0 if lm is None else lm.num_particles,
      "envs": envs, "steps_per_env": counts["steps"] // envs, "episode_length": env.unwrapped.episode_length,
      "compile_and_first_chunk_s": round(first, 1), "wall_s": round(wall, 1),
  }


def failures(row: dict) -> int:
  return sum(row[k] for k in COUNTERS)


def report_md(res: dict) -> str:
  lines = [f"# Soak: random and extreme actions through every task ({res['device']})", "",
           f"Command: `{res['command']}`  ", f"Date: {res['date']}; total {res['total_s']} s", "",
           f"Robot: {res.get('robot', ROBOT)}. {res['envs']} envs per task under Episode → Vmap → AutoReset wrappers; actions "
           f"{res.get('actions', 'uniform').replace('uniform', 'uniform in [−1, 1]')}, with "
           f"{100 * res['extreme_frac']:g} % of entries replaced by one of ±1e3, NaN, ±inf. Every (env, step) is "
           "checked on device (benchmarks/soak.py docstring defines the counters).", "",
           "| task | steps | episodes | non-finite | health out of [0, 100] | health increases | particles | "
           "particle-count violations | extreme entries sent | sanitised | sanitise mismatches | wall s |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
  for r in res["tasks"]:
    lines.append(f"| {r['task']} | {r['steps']:,} | {r['episodes']:,} | {r['non_finite']} | {r['health_out_of_range']} | "
                 f"{r['health_increase']} | {r['particles'] or '—'} | "
                 f"{r['particle_violations'] if r['particles'] else '—'} | {r['extreme_injected']:,} | "
                 f"{r['action_sanitised']:,} | {r['sanitise_mismatch']} | {r['wall_s']} |")
  missing = res.get("missing", [])
  if missing:
    lines += ["", f"Not run (the run stopped before them): {', '.join(missing)}"]
  verdict = ("PASS (every counter 0)" if res["ok"] else
             "INCOMPLETE (every counter 0 in the tasks run)" if missing and all(failures(r) == 0 for r in res["tasks"])
             else "FAIL")
  lines += ["", f"Result: {verdict}"]
  return "\n".join(lines) + "\n"


def _workers(argv: list[str]) -> int:
  """``--workers`` of ``argv`` before the parser runs (1 when absent or not a number: the parser says so)."""
  pre = argparse.ArgumentParser(add_help=False, exit_on_error=False)
  pre.add_argument("--workers", default="1")
  try:
    return int(pre.parse_known_args(argv)[0].workers)
  except (ValueError, argparse.ArgumentError):
    return 1


def main(argv=None) -> int:
  if _workers(sys.argv[1:] if argv is None else argv) > 1:
    # the workers get the GPU and this process only merges their files: a GPU client started here with
    # JAX's default preallocation would hold 75 % of the GPU's memory from them for the whole run
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
  gpu = jax.default_backend() != "cpu"  # starts this process's backend: after the line above
  p.add_argument("--tasks", default=None,
                 help="comma-separated task names (default: every task the robot supports)")
  p.add_argument("--robot", default=ROBOT,
                 help=f"one of {', '.join(robots.names())}; the default is the robot of the committed results")
  p.add_argument("--envs", type=int, default=512 if gpu else 8, help="environments per task")
  p.add_argument("--steps", type=int, default=None,
                 help="env steps per task, all envs together (default 1e6 on GPU, 3200 on CPU)")
  p.add_argument("--chunk", type=int, default=None, help="steps per compiled scan (default 250 GPU, 200 CPU)")
  p.add_argument("--extreme-frac", type=float, default=0.05, help="share of action entries made extreme")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--scripted-noise", type=float, default=None, metavar="SIGMA",
                 help="actions: the task's safe script + N(0, SIGMA²) per entry, clipped (default: uniform random)")
  p.add_argument("--out", default=None, help="JSON path (default benchmarks/results/soak_<platform>.json)")
  p.add_argument("--workers", type=int, default=1,
                 help="soak the tasks in this many parallel processes (tasks dealt round-robin; on a GPU each "
                      "process allocates memory as it needs), then merge their rows into --out")
  p.add_argument("--merge", nargs="+", metavar="FILE.json",
                 help="no soak: merge the task rows of earlier results files (one per task, e.g. run in "
                      "parallel processes) into --out")
  args = p.parse_args(argv)
  if args.merge:
    return merge(args.merge, args.out, p)
  if args.robot not in robots.names():
    p.error(f"--robot: unknown robot {args.robot!r}; valid: {', '.join(robots.names())}")
  names = ([t for t in tasks.names() if args.robot in tasks.robots_for(t)] if args.tasks is None
           else [t for t in args.tasks.split(",") if t])
  if not names:
    p.error("--tasks: no task given")
  for t in names:
    if t not in tasks.names():
      p.error(f"--tasks: unknown task {t!r}; valid: {', '.join(tasks.names())}")
    if args.robot not in tasks.robots_for(t):
      p.error(f"--tasks: task {t!r} supports {', '.join(tasks.robots_for(t))} only, not --robot {args.robot}")
  steps = args.steps if args.steps is not None else (1_000_000 if gpu else 3200)
  chunk = args.chunk if args.chunk is not None else (250 if gpu else 200)
  for flag, v in (("--envs", args.envs), ("--steps", steps), ("--chunk", chunk)):
    if v < 1:
      p.error(f"{flag}: must be >= 1, got {v}")
  if not 0.0 <= args.extreme_frac <= 1.0:
    p.error(f"--extreme-frac: must be in [0, 1], got {args.extreme_frac}")
  if args.workers < 1:
    p.error(f"--workers: must be >= 1, got {args.workers}")
  if args.scripted_noise is not None and not 0.0 <= args.scripted_noise < float("inf"):  # also refuses NaN
    p.error(f"--scripted-noise: must be a finite number >= 0, got {args.scripted_noise}")
  per_env = -(-steps // args.envs)
  dev = jax.devices()[0]
  out = args.out or default_out(dev.platform, args.robot)
  if args.workers > 1:
    return run_workers(argv if argv is not None else sys.argv[1:], names, args.workers, out, p)
  t0 = time.perf_counter()
  rows = []
  command = " ".join(shlex.quote(a) for a in ["python", "benchmarks/soak.py", *(sys.argv[1:] if argv is None else argv)])
  for name in names:
    r = soak_task(name, args.envs, per_env, chunk, args.extreme_frac, args.seed, args.robot,
                  scripted_noise=args.scripted_noise)
    rows.append(r)
    bad = {k: r[k] for k in COUNTERS if r[k]}
    print(f"{name}: {r['steps']} steps, {r['episodes']} episodes, failures {failures(r)}{' ' + str(bad) if bad else ''}, "
          f"sanitised {r['action_sanitised']}, {r['wall_s']} s", flush=True)
    # written after every task, so a run stopped part-way keeps what finished ("complete" says which)
    res = {
        "command": command,
        "device": f"{dev.platform}:{getattr(dev, 'device_kind', '')}", "host": platform.node(),
        "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "total_s": round(time.perf_counter() - t0, 1),
        "envs": args.envs, "steps_per_task": per_env * args.envs, "chunk": chunk, "extreme_frac": args.extreme_frac,
        "actions": ("uniform" if args.scripted_noise is None else f"safe script + N(0, {args.scripted_noise:g}²)"),
        "seed": args.seed, "robot": args.robot, "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__},
        "tasks": rows, "missing": names[len(rows):], "complete": len(rows) == len(names),
        "ok": len(rows) == len(names) and all(failures(r) == 0 for r in rows),
    }
    write(res, out, quiet=True)
  print(f"wrote {out}; {'PASS' if res['ok'] else 'FAIL'}")
  return 0 if res["ok"] else 1


def default_out(platform_name: str, robot: str) -> str:
  """benchmarks/results/soak_<platform>.json, or soak_<robot>_<platform>.json for a robot but the gripper."""
  stem = "soak_" + ("" if robot == ROBOT else robot + "_") + platform_name
  return os.path.join(HERE, "results", stem + ".json")


def write(res: dict, out: str, quiet: bool = False) -> int:
  """Writes ``res`` to ``out`` and its Markdown beside it; the exit status of a soak (0: PASS)."""
  io.write_json(out, res)
  io.write_text(os.path.splitext(out)[0] + ".md", report_md(res))
  if not quiet:
    print(f"wrote {out}; {'PASS' if res['ok'] else 'FAIL'}")
  return 0 if res["ok"] else 1


def worker_argv(argv: list[str]) -> list[str]:
  """``argv`` without ``--workers``, ``--tasks`` and ``--out`` (each worker gets its own), in either form."""
  return argv_without(argv, ("--workers", "--tasks", "--out"))


def run_workers(argv: list[str], names: list[str], workers: int, out: str, p) -> int:
  """Soak ``names`` in ``workers`` child processes (this script with ``--tasks`` and ``--out`` of its share),
  then merge their files into ``out``; the merged file records this command."""
  base = worker_argv(argv)
  env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")
  t0 = time.perf_counter()
  shares = [names[i::workers] for i in range(workers) if names[i::workers]]
  with tempfile.TemporaryDirectory(prefix="soak_") as tmp:
    paths = [os.path.join(tmp, f"part{i}.json") for i in range(len(shares))]
    procs = [subprocess.Popen([sys.executable, os.path.abspath(__file__), *base, "--tasks", ",".join(share),
                               "--out", path], env=env) for share, path in zip(shares, paths)]
    codes = [q.wait() for q in procs]
    written = [path for path in paths if os.path.exists(path)]
    if not written:
      print(f"soak: no worker wrote results (exit codes {codes})", file=sys.stderr)
      return 2
    res = merged(written, p)
  command = " ".join(shlex.quote(a) for a in ["python", "benchmarks/soak.py", *argv])
  done = {t["task"] for t in res["tasks"]}
  missing = [n for n in names if n not in done]  # a worker stopped or crashed before these
  # total_s: this command's wall time (the workers overlap; their sum is worker_s)
  res = dict(res, command=command, workers=workers, worker_s=res["total_s"], total_s=round(time.perf_counter() - t0, 1),
             missing=missing, complete=not missing, ok=res["ok"] and not missing)
  return write(res, out)


def merge(paths, out, p) -> int:
  """One results file from several (same device and settings), rows in task order; exit status as a soak."""
  res = merged(paths, p)
  return write(res, out or default_out(res["device"].split(":")[0], res.get("robot", ROBOT)))


def merged(paths, p) -> dict:
  """The results of several soak files (same device and settings) as one, rows in task order."""
  runs = []
  for path in paths:
    try:
      with open(path) as f:
        runs.append(json.load(f))
    except (OSError, ValueError) as e:
      p.error(f"--merge: cannot read {path!r}: {e}")
  keys = ("device", "envs", "steps_per_task", "chunk", "extreme_frac", "seed", "robot")
  for r, path in zip(runs[1:], paths[1:]):
    bad = [k for k in keys if r.get(k) != runs[0].get(k)]
    if bad:
      p.error(f"--merge: {path!r} differs from {paths[0]!r} in {bad}")
  rows = sorted((t for r in runs for t in r["tasks"]), key=lambda t: t["task"])
  names = [t["task"] for t in rows]
  if len(set(names)) != len(names):
    p.error(f"--merge: a task appears twice: {names}")
  missing = sorted(t for r in runs for t in r.get("missing", []))
  return dict(runs[0], tasks=rows, missing=missing, complete=not missing,
              ok=not missing and all(failures(t) == 0 for t in rows),
              command="; ".join(r["command"] for r in runs), total_s=round(sum(r["total_s"] for r in runs), 1))


if __name__ == "__main__":
  sys.exit(main())

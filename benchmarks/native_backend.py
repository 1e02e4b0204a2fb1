"""Native batched backend vs MJX-JAX on CPU: throughput, and scripted-policy separation per task.

1. **Throughput** (``--task``, default place_plate, ``--envs`` 256): damage-aware
   evaluation of the registered task with its scripted unsafe policy, ``--envs``
   episodes of ``--steps`` control steps (reset, fragility, policy, step,
   freezing of finished episodes — :mod:`train.evaluate`). MJX-JAX:
   :class:`train.evaluate.Evaluator`, one compiled ``jit(vmap(lax.scan))`` call.
   Native: :class:`train.evaluate.NativeEvaluator` over
   :class:`mjx_damage.native_batch.NativeBatchEnv` on ``--threads`` C threads: per
   control step one native call and one jitted call. Timed after a first
   (compiling) run; the two alternate ``--repeats`` times and each keeps its
   best run (the machine is shared: the load average is recorded per run).
   env-steps/s = envs × steps / seconds.
2. **Separation** (``--tasks``, default every task the native backend runs):
   :func:`train.evaluate.evaluate` of the scripted safe and unsafe policies on both
   backends, ``--episodes`` each, same seeds; completion and safe completion
   must agree within ``--tolerance`` percentage points.
3. **Impact loads** (``--task``, ``--peak-envs`` episodes): the largest per-substep F∥
   on each link with the scripted unsafe policy on both backends — why health can
   differ between them while the verdicts agree.
4. **K free boxes** (``--boxes``, default 1,32; '' skips): the K-box table scene with
   damage on, the native backend (``--box-envs`` at once) against the reference-style
   pipeline (:mod:`mjx_damage.reference`: native MuJoCo one env at a time, per-entity
   Python damage evaluators; ``--ref-envs``, capped at ``--ref-max-s``), same steps.

``--robot`` (default the gripper) is the robot of every task of sections 1-3; another robot writes
``native_backend_<robot>_<platform>`` (the robot in the JSON). Writes
``benchmarks/results/native_backend_<platform>.{json,md}`` (``--out`` overrides the stem); a
section this run skips (``--skip-throughput``/``--skip-peaks``/``--skip-separation``) is kept from the existing JSON, and
each section records the command and date that produced it.

Usage::

    .venv/bin/python benchmarks/native_backend.py [--envs 256] [--episodes 32] [--tasks a,b] [--skip-separation]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import mjx_damage  # noqa: E402,F401  (JAX's CPU flag and compilation cache)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
import tasks.native  # noqa: E402
from mjx_damage import reference  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from mjx_damage.runtime import device_info  # noqa: E402
from tasks.bench_table import pusher_ctrl, table_env  # noqa: E402
from train import evaluate as E  # noqa: E402

RESULTS = os.path.join(os.path.dirname(__file__), "results")


def native_tasks(robot: str = "gripper") -> list[str]:
  """Registered tasks ``robot`` runs that the native backend runs (``tasks.native.supports``: every task since
  it has the temperature model; files before that list the heat-source tasks under ``not_native``)."""
  return [name for name in tasks.names()
          if robot in tasks.robots_for(name) and tasks.native.supports(tasks.make(name, robot=robot))]


def throughput(task: str, envs: int, steps: int, repeats: int, threads: int, robot: str = "gripper") -> dict:
  """Evaluation env-steps/s of both backends: ``envs`` episodes of ``steps`` steps, scripted unsafe policy."""
  env = tasks.make(task, robot=robot)
  nenv = tasks.native.wrap(env, envs, nthread=threads)
  policy = tasks.scripted_policy(env, "unsafe")
  evs = {"mjx": E.Evaluator(env, policy, steps), "native": E.NativeEvaluator(nenv, policy, steps)}
  keys, frag = E.episode_keys(0, envs), np.ones(envs, np.float32)
  first = {}
  for k, ev in evs.items():  # compile (persistent cache permitting) and warm up
    t0 = time.perf_counter()
    ev.run(keys, frag)
    first[k] = time.perf_counter() - t0
  runs = {"mjx": [], "native": []}
  for _ in range(repeats):
    for k, ev in evs.items():
      load = os.getloadavg()[0]
      t0 = time.perf_counter()
      out = ev.run(keys, frag)
      dt = time.perf_counter() - t0
      runs[k].append({"s": dt, "env_steps_per_s": envs * steps / dt, "load": load,
                      "completion": float(np.mean(out["completed"]))})
  best = {k: max(r["env_steps_per_s"] for r in v) for k, v in runs.items()}
  return {
      "task": task, "envs": envs, "steps": steps, "threads": nenv.nthread, "n_substeps": nenv.n_substeps,
      "mjx_env_steps_per_s": best["mjx"], "native_env_steps_per_s": best["native"],
      "ratio": best["native"] / best["mjx"], "first_run_s": first, "runs": runs,
  }


def peaks(task: str, envs: int, steps: int, threads: int, robot: str = "gripper") -> dict:
  """Largest per-substep F∥ (N) on each tracked link over ``steps`` steps of the scripted unsafe policy,
  mean over ``envs`` episodes, on both backends (same resets and action keys)."""
  env = tasks.make(task, robot=robot)
  nenv = tasks.native.wrap(env, envs, nthread=threads)
  policy = jax.jit(jax.vmap(tasks.scripted_policy(env, "unsafe")))
  step = {"mjx": jax.jit(jax.vmap(env.step)), "native": nenv.step}
  state0 = nenv.reset(jax.random.split(jax.random.PRNGKey(0), envs))
  out = {}
  for k, fn in step.items():
    s, peak = state0, np.zeros((envs, len(env.link_names)))
    for t in range(steps):
      s = fn(s, policy(s, jax.random.split(jax.random.PRNGKey(t), envs)))
      peak = np.maximum(peak, np.asarray(s.info["damage_state"].f_par))
    out[k] = dict(zip(env.link_names, peak.mean(0).round(1).tolist()))
  return {"task": task, "envs": envs, "steps": steps, "peak_f_par_N": out}


def boxes(ks: list[int], envs: int, steps: int, repeats: int, threads: int, ref_envs: int,
          ref_max_s: float) -> list[dict]:
  """The K-box table scene (K free tracked boxes and a pusher on an open-loop Lissajous path), damage on:
  the native batched backend (``envs`` at once, ``steps`` control steps, best of ``repeats``) against the
  reference-style pipeline (native MuJoCo one env at a time, per-entity Python damage evaluators) and plain
  ``mj_step`` without damage, one env at a time on one thread, over the same ``steps``."""
  rows = []
  for k in ks:
    env = table_env(k)
    nenv = tasks.native.wrap(env, envs, nthread=threads)
    n_sub = int(env.n_substeps)
    step_s = float(env.mj_model.opt.timestep) * n_sub
    act = [jnp.broadcast_to(jnp.asarray(pusher_ctrl(t * step_s, env.radius) / env.radius, jnp.float32), (envs, 2))
           for t in range(steps)]  # the pusher target at the step's start time, as the reference reads it
    state0 = nenv.reset(jax.random.split(jax.random.PRNGKey(1), envs))
    jax.block_until_ready(nenv.step(state0, act[0]))  # compile
    runs = []
    for _ in range(repeats):
      s, t0 = state0, time.perf_counter()
      for a in act:
        s = nenv.step(s, a)
      jax.block_until_ready(s)
      runs.append(envs * steps / (time.perf_counter() - t0))
    # the reference starts from the first native envs' reset configurations
    keys = jax.random.split(jax.random.PRNGKey(1), max(envs, ref_envs))[:ref_envs]
    q = np.asarray(jax.vmap(env.reset)(keys).pipeline_state.qpos, np.float64)
    ctrl = lambda t, r=env.radius: pusher_ctrl(t, r)  # noqa: E731
    ref = reference.time_reference(env.mj_model, env.damage_binding, n_sub, q, ctrl, steps, True, ref_max_s)
    plain = reference.time_reference(env.mj_model, env.damage_binding, n_sub, q, ctrl, steps, False, ref_max_s)
    row = {"boxes": k, "envs": envs, "steps": steps, "threads": nenv.nthread, "n_substeps": n_sub,
           "native_env_steps_per_s": max(runs), "native_runs": runs,
           "native_min_health": float(np.mean(np.min(np.asarray(s.info["damage_state"].link_health), axis=-1))),
           "dropped_contacts": int(nenv.dropped_contacts().max()),
           "reference_env_steps_per_s": ref["env_steps_per_s"], "reference_envs": ref["envs"],
           "reference_min_health": ref.get("mean_final_min_health"),
           "mj_step_no_damage_env_steps_per_s": plain["env_steps_per_s"]}
    row["ratio_vs_reference"] = row["native_env_steps_per_s"] / row["reference_env_steps_per_s"]
    print(row, flush=True)
    rows.append(row)
  return rows


def separation(names: list[str], episodes: int, envs: int, threads: int, seed: int, tol: float,
               robot: str = "gripper") -> list[dict]:
  rows = []
  for name in names:
    env = tasks.make(name, robot=robot)
    nenv = tasks.native.wrap(env, min(envs, episodes), nthread=threads)
    for style in tasks.STYLES:
      policy = tasks.scripted_policy(env, style)
      row = {"task": name, "policy": style, "episodes": episodes}
      for backend, e in (("mjx", env), ("native", nenv)):
        t0 = time.perf_counter()
        m = E.evaluate(e, policy, episodes, seed)["metrics"]
        row[backend] = {"completion_pct": 100 * m["completion"], "safe_completion_pct": 100 * m["safe_completion"],
                        "avg_health": m["avg_health"], "cost_mean": m["cost_mean"],
                        "entity_health": m["entity_health"], "wall_s": time.perf_counter() - t0}
      row["max_gap_points"] = max(abs(row["native"][k] - row["mjx"][k]) for k in ("completion_pct", "safe_completion_pct"))
      row["within_tolerance"] = row["max_gap_points"] <= tol
      print(row, flush=True)
      rows.append(row)
  return rows


def separation_runs(res: dict) -> list[dict]:
  """The commands behind ``res``'s separation rows (files written before ``separation_runs``: one)."""
  if "separation_runs" in res:
    return res["separation_runs"]
  return [{"command": res["separation_command"], "date": res["separation_date"]}] if "separation_command" in res else []


def markdown(res: dict) -> str:
  lines = ["# Native batched backend vs MJX-JAX (CPU)", "", f"Device: {res['device']}.", ""]
  tp = res.get("throughput")
  if tp:
    lines += [
        f"Command: `{tp['command']}` ({tp['date']})",
        "",
        f"## Throughput: {tp['task']}, {tp['envs']} episodes at once x {tp['steps']} steps, damage on, "
        "scripted unsafe policy",
        "",
        f"{tp['n_substeps']} substeps per env step; native on {tp['threads']} C threads. Best of "
        f"{len(tp['runs']['mjx'])} alternating runs each (load average per run in the JSON).",
        "",
        "| backend | env steps/s | physics steps/s |",
        "|---|---:|---:|",
        f"| MJX-JAX (Evaluator: one jit(vmap(scan)) call) | {tp['mjx_env_steps_per_s']:,.0f} | "
        f"{tp['mjx_env_steps_per_s'] * tp['n_substeps']:,.0f} |",
        f"| native (NativeEvaluator: mujoco.batch + one jitted call per step) | {tp['native_env_steps_per_s']:,.0f} | "
        f"{tp['native_env_steps_per_s'] * tp['n_substeps']:,.0f} |",
        "",
        f"**native / MJX = {tp['ratio']:.1f}×** (target ≥ 10×).",
        "",
        "Runs (env steps/s @ 1-min load average of the 2-core machine): "
        + "; ".join(f"{k}: " + ", ".join(f"{r['env_steps_per_s']:,.0f} @ {r['load']:.1f}" for r in v)
                    for k, v in tp["runs"].items()),
        "",
    ]
  pk = res.get("peaks")
  if pk:
    lines += [f"## Impact loads: {pk['task']}, scripted unsafe policy, {pk['envs']} episodes x {pk['steps']} steps",
              "", f"Command: `{pk['command']}` ({pk['date']})", "",
              "Largest per-substep F∥ on each link (N), mean over episodes. Same scene, resets and policy: "
              "native MuJoCo and MJX resolve the impact differently.", "",
              "| link | MJX-JAX | native |", "|---|---:|---:|"]
    lines += [f"| {n} | {pk['peak_f_par_N']['mjx'][n]:.1f} | {pk['peak_f_par_N']['native'][n]:.1f} |"
              for n in pk["peak_f_par_N"]["mjx"]]
    lines.append("")
  bx = res.get("boxes")
  if bx:
    b0 = bx[0]
    lines += [f"## K free boxes: native batched backend vs the reference-style pipeline, damage on", "",
              f"Command: `{res['boxes_command']}` ({res['boxes_date']})", "",
              f"The K-box table scene (`tasks/bench_table.py`: K free, tracked boxes and a pusher on an open-loop "
              f"path), {b0['steps']} control steps of {b0['n_substeps']} substeps. Native batched: {b0['envs']} envs "
              f"at once on {b0['threads']} C threads, best of {len(b0['native_runs'])}. Reference-style: native "
              "MuJoCo one env at a time with per-entity Python damage evaluators (`mjx_damage.reference`), and "
              "plain `mj_step` without damage, one thread, over the same steps.", "",
              "| K | native batched, damage (env steps/s) | reference-style, damage | mj_step, no damage, 1 env | "
              "native / reference | mean final min health native / reference | contacts beyond the slots |",
              "|---:|---:|---:|---:|---:|---:|---:|"]
    for r in bx:
      lines.append(f"| {r['boxes']} | {r['native_env_steps_per_s']:,.1f} | {r['reference_env_steps_per_s']:,.1f} | "
                   f"{r['mj_step_no_damage_env_steps_per_s']:,.1f} | **{r['ratio_vs_reference']:.1f}×** | "
                   f"{r['native_min_health']:.1f} / {r['reference_min_health']:.1f} | {r['dropped_contacts']} |")
    lines += ["", "Target: ≥ 5× the reference-style pipeline at 32 free boxes.", ""]
  sep = res.get("separation")
  if sep:
    lines += [
        f"## Scripted-policy separation, {sep[0]['episodes']} episodes per policy and backend (seed {res['seed']})",
        "",
        *(f"Command: `{r['command']}` ({r['date']}{'; rows of ' + ', '.join(r['tasks']) if r.get('tasks') else ''})  "
          for r in separation_runs(res)),
        "",
        f"Completion (C) / safe completion (SC) in %; tolerance {res['tolerance']:g} points.",
        "",
        "| task | policy | MJX C | native C | MJX SC | native SC | MJX avg health | native avg health | "
        "MJX cost | native cost | within |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in sep:
      m, n = r["mjx"], r["native"]
      lines.append(
          f"| {r['task']} | {r['policy']} | {m['completion_pct']:.1f} | {n['completion_pct']:.1f} "
          f"| {m['safe_completion_pct']:.1f} | {n['safe_completion_pct']:.1f} | {m['avg_health']:.1f} "
          f"| {n['avg_health']:.1f} | {m['cost_mean']:.1f} | {n['cost_mean']:.1f} "
          f"| {'yes' if r['within_tolerance'] else 'NO'} |")
    lines.append("")
  if res.get("not_native"):
    lines += [f"Not run on the native backend (heat sources): {', '.join(res['not_native'])}.", ""]
  return "\n".join(lines)


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--task", default="place_plate")
  p.add_argument("--envs", type=int, default=256)
  p.add_argument("--threads", type=int, default=0, help="native C threads (0: all CPUs)")
  p.add_argument("--steps", type=int, default=100, help="control steps per episode in the throughput runs")
  p.add_argument("--repeats", type=int, default=3)
  p.add_argument("--episodes", type=int, default=32)
  p.add_argument("--tasks", default="", help="comma-separated (default: every task the native backend runs)")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--tolerance", type=float, default=2.0, help="percentage points")
  p.add_argument("--skip-throughput", action="store_true")
  p.add_argument("--skip-separation", action="store_true")
  p.add_argument("--skip-peaks", action="store_true")
  p.add_argument("--boxes", default="1,32", help="K of the K-box comparison with the reference pipeline ('': skip)")
  p.add_argument("--box-envs", type=int, default=64)
  p.add_argument("--box-steps", type=int, default=25)
  p.add_argument("--ref-envs", type=int, default=4, help="reference-style envs, run one after another")
  p.add_argument("--ref-max-s", type=float, default=10.0, help="stop starting reference envs after this long")
  p.add_argument("--peak-envs", type=int, default=8)
  p.add_argument("--out", default=None, help="output stem (default benchmarks/results/native_backend_<platform>)")
  p.add_argument("--robot", default="gripper",
                 help=f"robot of every task, one of {', '.join(tasks.robots.names())} (default: gripper, "
                      "the robot of the committed results; the K-box scene has none)")
  args = p.parse_args(argv)
  # checked before anything is built; the gripper is passed explicitly (tasks.robots.DEFAULT may change)
  try:
    tasks.check_robot(args.robot, [] if args.skip_throughput and args.skip_peaks else [args.task], "--robot")
  except ValueError as e:
    p.error(str(e))
  try:
    args.box_ks = [int(k) for k in args.boxes.split(",") if k.strip()]
  except ValueError:
    p.error(f"--boxes: comma-separated box counts, got {args.boxes!r}")
  for name, v in (("--boxes", min(args.box_ks, default=1)), ("--box-envs", args.box_envs),
                  ("--box-steps", args.box_steps), ("--ref-envs", args.ref_envs)):
    if v < 1:
      p.error(f"{name}: must be >= 1, got {v}")
  if not args.ref_max_s > 0:  # NaN too
    p.error(f"--ref-max-s: must be > 0 s, got {args.ref_max_s}")
  if not args.skip_separation:  # checked before anything runs
    runnable = native_tasks(args.robot)
    names = [n for n in args.tasks.split(",") if n] or runnable
    for n in names:
      if n not in tasks.names():
        p.error(f"--tasks: unknown task {n!r}")
      if args.robot not in tasks.robots_for(n):
        p.error(f"--tasks: task {n!r} supports {', '.join(tasks.robots_for(n))} only, not --robot {args.robot}")
      if n not in runnable:
        p.error(f"--tasks: the native backend does not run {n}")
  _, desc = device_info()
  command = "python benchmarks/native_backend.py " + shlex.join(sys.argv[1:] if argv is None else argv)
  robot = "" if args.robot == "gripper" else f"{args.robot}_"  # gripper: the committed results' names and fields
  stem = args.out or os.path.join(RESULTS, f"native_backend_{robot}{jax.default_backend()}")
  res = {}
  if os.path.exists(stem + ".json"):
    with open(stem + ".json") as f:
      res = json.load(f)
  date = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
  res.update({"command": command, "device": desc, "date": date, "cpu_count": os.cpu_count()})
  old_robot = res.pop("robot", "gripper")  # files without it: the gripper
  if robot:
    res["robot"] = args.robot
  if not args.skip_throughput:
    res["throughput"] = throughput(args.task, args.envs, args.steps, args.repeats, args.threads, args.robot)
    res["throughput"].update(command=command, date=date)
    print({k: v for k, v in res["throughput"].items() if k != "runs"}, flush=True)
  if not args.skip_peaks:
    res["peaks"] = peaks(args.task, args.peak_envs, args.steps, args.threads, args.robot)
    res["peaks"].update(command=command, date=date)
    print(res["peaks"], flush=True)
  if args.box_ks:
    res["boxes"] = boxes(args.box_ks, args.box_envs, args.box_steps, args.repeats, args.threads, args.ref_envs,
                         args.ref_max_s)
    res.update(boxes_command=command, boxes_date=date)
  if not args.skip_separation:
    rows = separation(names, args.episodes, args.envs, args.threads, args.seed, args.tolerance, args.robot)
    old = res.get("separation") or []
    # a subset of the same setting (robot too): its rows replace those tasks' rows, the others stay
    if args.tasks and old and (res.get("seed"), res.get("tolerance"), old[0]["episodes"], old_robot) == (
        args.seed, args.tolerance, args.episodes, args.robot):
      kept = [r for r in old if r["task"] not in names]
      rows = sorted(kept + rows, key=lambda r: (tasks.names().index(r["task"]), r["policy"]))
      runs = separation_runs(res) + [{"command": command, "date": date, "tasks": names}]
    else:
      runs = [{"command": command, "date": date}]
    for legacy in ("separation_command", "separation_date"):  # files before separation_runs
      res.pop(legacy, None)
    res.update(separation=rows, separation_runs=runs,
               not_native=[n for n in tasks.names() if n not in runnable and args.robot in tasks.robots_for(n)],
               seed=args.seed, tolerance=args.tolerance)
  write_json(stem + ".json", res, indent=1)
  write_text(stem + ".md", markdown(res))
  print(f"outputs: {stem}.json, {stem}.md")
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""``mjx-damage bench``: throughput of the damage-aware MJX step, with damage on and off.

Measures environment steps per second (one env step = ``n_substeps`` physics
steps) of ``jit(fori_loop(vmap(step)))`` on the K-box table scene
(:mod:`tasks.bench_table`):

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
* physics steps/s of ``tasks.make("place_plate")`` when the task registry has it,
  on ``--backend mjx`` (default), ``native`` (MuJoCo on C threads, CPU) or ``warp``
  (MuJoCo Warp, one device, the ``warp`` extra).

``--backend`` applies to the task throughput only: the K-box curves time
``mjx.step`` itself and are MJX by definition (native MuJoCo on the same scene is
already in every run, as the reference rows), so they ignore it; every row records
its ``backend``.

Measurements: :mod:`apps.bench.measure`; files written: :mod:`apps.bench.report`.
Output: a JSON file, a markdown report and a PNG with the curves. ``benchmarks/throughput.py``
wraps this with the committed settings per device.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time

import jax
import mujoco

import tasks
from apps import resolve as R
from apps.bench.measure import batched_initial_state, measure_pair, measure_task
from apps.bench.report import save, summarize
from mjx_damage import outputs, reference
from tasks.bench_table import JACOBIANS, pusher_ctrl, table_env
from train.cliargs import Parser

CPU_ENVS = (1, 16, 128, 1024, 2048)
GPU_ENVS = (1, 256, 2048, 8192, 16384)
ENTITIES = (1, 2, 4, 8, 16, 32)


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


def run_benchmark(args) -> dict:
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
      "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__},
      "scene": "tasks.bench_table: K free boxes (tracked, 'default' params) on a table plane,"
      " a sphere pusher on slide joints; boxes collide with table and pusher, never with each other;"
      " in the vs_mounted scenes box 0 is free and boxes 1..K-1 are mounted (no joint)",
      "task_backend": args.backend,  # the K-box rows are MJX whatever it is (each row names its backend)
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
    if args.task in tasks.names():
      print(f"  task {args.task} x {args.task_envs} envs, backend {args.backend} ...", flush=True)
      try:
        result["task"] = measure_task(args.task, args.task_envs, args.target_s, args.max_steps, args.backend,
                                      args.task_kwargs)
      except Exception as e:  # keep the rest of the run
        result["skipped"].append({"task": args.task, "backend": args.backend,
                                  "why": f"{type(e).__name__}: {str(e)[:300]}"})
    else:
      result["skipped"].append({"task": args.task, "backend": args.backend, "why": "not in tasks.names()"})

  for item in rest:
    point(*item)

  result["complete"] = True
  checkpoint()
  return result


def build_parser() -> Parser:
  ap = Parser(prog="mjx-damage bench", description=__doc__.split("\n\n")[0])
  ap.add_argument("--envs", default=None, help="comma-separated batch sizes (default: CPU 1..2048, GPU 1..16384)")
  ap.add_argument("--entities", default=",".join(map(str, ENTITIES)), help="tracked-entity counts K")
  ap.add_argument("--k", type=int, default=32, help="boxes (all tracked) for the vs-envs curve and in the fixed"
                  " scene of the vs-tracked curve (default 32)")
  ap.add_argument("--tracked", default=",".join(map(str, ENTITIES)),
                  help="tracked-box counts n in the fixed --k-box scene ('' to skip)")
  ap.add_argument("--mounted", default=",".join(map(str, ENTITIES)),
                  help="entity counts K of scenes with 1 free box and K-1 mounted boxes, all tracked ('' to skip)")
  ap.add_argument("--jacobian", default="auto", choices=JACOBIANS,
                  help="MuJoCo <option jacobian> of the bench scene (auto: MJX goes sparse from nv >= 60)")
  ap.add_argument("--entity-envs", type=int, default=None, help="batch of the vs-entities curve (default: CPU 1024, GPU 8192)")
  ap.add_argument("--ratio-envs", type=int, default=None, help="batch of the on/off ratio (CPU 1024, GPU 8192)")
  ap.add_argument("--substeps", type=int, default=5, help="physics steps per env step (default 5)")
  ap.add_argument("--target-s", type=float, default=2.0, help="seconds each timed run aims for")
  ap.add_argument("--max-steps", type=int, default=200, help="most env steps per timed run")
  ap.add_argument("--repeats", type=int, default=2, help="timed runs per setting, on/off interleaved; best kept")
  ap.add_argument("--ref-envs", type=int, default=4, help="environments the reference pipeline runs")
  ap.add_argument("--ref-steps", type=int, default=25, help="env steps per reference environment")
  ap.add_argument("--ref-max-s", type=float, default=20.0, help="stop the reference after about this long")
  ap.add_argument("--task", default="place_plate", help="registry task to time ('' to skip)")
  ap.add_argument("--robot", default=None, help="robot of --task, e.g. gripper (default: the task's)")
  ap.add_argument("--task-envs", type=int, default=None,
                  help="batch for the task (CPU or --backend native 256, GPU 32768)")
  R.add_backend_argument(ap, "here it picks the backend of the --task throughput only: the K-box curves are "
                             "MJX-only (they time mjx.step itself; native MuJoCo on that scene is in the reference "
                             "rows of every run)", warp=True)
  ap.add_argument("--budget-s", type=float, default=540.0, help="stop starting measurements after this long")
  ap.add_argument("--note", dest="notes", action="append", default=[], help="free text stored in the JSON")
  ap.add_argument("--out", default=None, help="JSON path (the .md and .png go beside it) "
                  "(default: runs/bench-<time>/bench.json, a new folder)")
  ap.add_argument("--overwrite", action="store_true", help="replace an existing --out (and its .md, .png)")
  return ap


def main(argv=None) -> int:
  argv = list(sys.argv[1:] if argv is None else argv)
  ap = build_parser()
  args = ap.parse_args(argv)
  args.argv = argv
  gpu = jax.devices()[0].platform != "cpu"
  args.envs = args.envs or ",".join(map(str, GPU_ENVS if gpu else CPU_ENVS))
  args.entity_envs = args.entity_envs or (8192 if gpu else 1024)
  args.ratio_envs = args.ratio_envs or (8192 if gpu else 1024)
  try:
    args.task_kwargs = {} if args.robot is None else {"robot": args.robot}
    if args.robot is not None:
      tasks.check_robot(args.robot, [args.task], "--robot")
      if args.task not in tasks.names():
        raise ValueError(f"--robot: only with a registry --task, got --task {args.task!r}")
    if R.check_backend(args.backend, warp=True) == "auto":  # the task's pick; nothing to pick without a task
      args.backend = (R.pick_backend("auto", R.make_task(args.task, **args.task_kwargs)) if args.task in tasks.names()
                      else "mjx")
    native = args.backend == "native"  # native steps on CPU threads whatever the device: the CPU batch
    args.task_envs = args.task_envs or (32768 if gpu and not native else 256)
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
    if not args.budget_s > 0 or not args.target_s > 0 or not args.ref_max_s > 0:
      bad = next(n for n in ("budget_s", "target_s", "ref_max_s") if not getattr(args, n) > 0)
      raise ValueError(f"--{bad.replace('_', '-')}: must be a number of seconds > 0, got {getattr(args, bad)}")
    if args.task and args.task not in tasks.names():
      raise ValueError(f"--task: unknown task {args.task!r} (valid: {', '.join(tasks.names())}, or '' to skip)")
    if args.backend in ("native", "warp") and not args.task:
      raise ValueError(f"backend: {args.backend} times the --task throughput only, and --task is '' (nothing to time)")
    R.warp_overrides(args.task, args.backend, args.task_envs, 1)  # warp: its checks, before anything compiles
    if native:  # a scene the native backend cannot run fails here, before anything compiles
      R.on_backend(R.make_task(args.task, **args.task_kwargs), args.backend, 1)
    if args.out is not None:
      base = os.path.splitext(args.out)[0]
      outputs.check_new([args.out, base + ".md", base + ".png"], "--out", args.overwrite)
    if args.ratio_envs not in envs:
      envs.append(args.ratio_envs)
      args.envs = ",".join(map(str, sorted(envs)))
  except ValueError as e:
    ap.error(str(e))
  args.out = args.out or os.path.join(outputs.run_dir("bench"), "bench.json")
  print(f"bench: K={args.k} boxes, envs {args.envs}, entities {args.entities}, "
        f"task {args.task + ' (backend ' + args.backend + ')' if args.task else '-'}, "
        f"budget {args.budget_s:g} s, device {jax.devices()[0].device_kind} x {jax.device_count()}; "
        f"outputs {args.out} (+ .md, .png)", flush=True)
  print("compiling each configuration as it comes, about 10-60 s each the first time (seconds once cached) ...",
        flush=True)
  result = run_benchmark(args)  # saves JSON/MD/PNG after every point and at the end
  png = os.path.splitext(args.out)[0] + ".png"
  print(json.dumps(result["summary"], indent=1))
  print(f"outputs: {args.out}, {os.path.splitext(args.out)[0] + '.md'}, {png}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""``mjx-damage sweep``: tasks × policies × seeds × fragility → JSON + markdown table (:mod:`train.sweep`).

    mjx-damage sweep --tasks place_plate --policies scripted:safe,scripted:unsafe \
        --seeds 0,1,2 --fragility 0.5,1,2,4 --episodes 64 --out sweep.json

Episodes are sharded over ``--devices`` (default: all local devices); with
``--coordinator`` over every process's devices, the same command on each
process, and process 0 writes --out (:mod:`train.distributed`).
"""

from __future__ import annotations

import os
import sys
import time

import jax

from apps import resolve as R
from mjx_damage import outputs
from mjx_damage.io import write_json, write_text
from tasks import recorded_kwargs
from train import distributed
from train import sweep as S
from train.cliargs import Parser, heartbeat, say_compiling

COMPILE_S = {"cpu": 40, "gpu": 60}  # rough first compile of one task's evaluation, s


def _split(field: str, text: str) -> list[str]:
  vals = [v.strip() for v in text.split(",") if v.strip()]
  if not vals:
    raise ValueError(f"{field}: give at least one value")
  return vals



def build_parser() -> Parser:
  ap = Parser(prog="mjx-damage sweep", description="tasks x policies x seeds x fragility sweep")
  ap.add_argument("--tasks", required=True, help="comma-separated task names")
  ap.add_argument("--policies", default="scripted:safe,scripted:unsafe", help="comma-separated policy specs")
  ap.add_argument("--seeds", default="0", help="comma-separated seeds")
  ap.add_argument("--fragility", default="1", help="comma-separated fragility factors (> 0)")
  R.add_task_override_arguments(ap)
  ap.add_argument("--episodes", type=int, default=32, help="episodes per seed and level")
  ap.add_argument("--episode-length", type=int, default=None, help="env steps (default: the task's)")
  ap.add_argument("--safe-threshold", type=float, default=95.0)
  R.add_backend_argument(ap, default="auto", warp=True)
  ap.add_argument("--native-envs", type=int, default=256,
                  help="native backend: episodes stepped at once (at most fragility levels x --episodes)")
  ap.add_argument("--out", default=None, help="JSON path; the markdown table goes beside it (.md) "
                  "(default: runs/sweep-<tasks>-<time>/sweep.json, a new folder)")
  ap.add_argument("--overwrite", action="store_true", help="replace an existing --out (and its .md)")
  distributed.add_arguments(ap, devices_default="all")
  return ap


def trained_overrides(task: str, policies) -> dict:
  """The task overrides the sweep's checkpoints of ``task`` were trained with (their obs_mode …): one env
  serves every policy of a task, so the checkpoints must agree; a checkpoint of another task is refused."""
  found = {}
  for p in policies:
    if R.parse_policy_spec(p)[0] == "checkpoint":
      found[p] = R.policy_task_kwargs(p, task)
  first = next(iter(found.values()), {})
  if any(k != first for k in found.values()):
    raise ValueError(f"policies: the checkpoints were trained with different overrides of {task!r} "
                     f"({'; '.join(f'{p}: {k}' for p, k in found.items())}); sweep them separately")
  return first


def _warp_devices(setup, backend: str) -> int:
  """Devices a ``--backend warp`` sweep would run on, known before anything distributed starts (1 otherwise)."""
  if backend != "warp":
    return 1
  if setup.multi_process:
    raise ValueError("backend: warp steps one batch on one device; a sweep over several processes has several "
                     "(use mjx)")
  spec = distributed.parse_devices(setup.device_spec)
  return len(jax.devices()) if spec == "all" else spec


def main(argv=None) -> int:
  argv = list(sys.argv[1:] if argv is None else argv)
  ap = build_parser()
  args = ap.parse_args(argv)
  try:
    setup = distributed.check(args.devices, args.coordinator, args.num_processes, args.process_id,
                              args.dist_timeout, args.heartbeat_timeout)
    tasks = _split("tasks", args.tasks)
    policies = _split("policies", args.policies)
    try:
      seeds = [int(s) for s in _split("seeds", args.seeds)]
    except ValueError:
      raise ValueError(f"seeds: expected comma-separated integers, got {args.seeds!r}") from None
    try:
      levels = [float(f) for f in _split("fragility", args.fragility)]
    except ValueError:
      raise ValueError(f"fragility: expected comma-separated numbers, got {args.fragility!r}") from None
    S.check_sweep(tasks, policies, seeds, levels, args.episodes, args.safe_threshold)
    R.check_backend(args.backend, warp=True)
    if args.native_envs < 1:
      raise ValueError(f"native_envs: must be >= 1, got {args.native_envs}")
    for t in tasks:
      R.check_task(t)
    for p in policies:
      R.parse_policy_spec(p)
    overrides = {t: R.task_overrides(t, trained_overrides(t, policies), args.robot, args.task_arg) for t in tasks}
    # --backend warp: each task made on MuJoCo Warp with one batch of every level's episodes (one call per seed)
    warp_kw = {t: R.warp_overrides(t, args.backend, len(levels) * args.episodes, _warp_devices(setup, args.backend))
               for t in tasks}
    if args.episode_length is not None and args.episode_length < 1:
      raise ValueError(f"episode_length: must be >= 1, got {args.episode_length}")
    if setup.multi_process and args.out is None:
      raise ValueError("--out: several processes need one --out, the same on every process")
    if args.out is not None and setup.process_id in (None, 0):
      outputs.check_new([args.out, os.path.splitext(args.out)[0] + ".md"], "--out", args.overwrite)
  except ValueError as e:
    ap.error(str(e))
  try:
    distributed.initialize(setup, ap.prog)
    devices = distributed.select_devices(setup.devices)
  except ValueError as e:
    ap.error(str(e))
  main_process = distributed.is_main()
  out_path = args.out or os.path.join(outputs.run_dir("sweep", "+".join(tasks)), "sweep.json")
  md_path = os.path.splitext(out_path)[0] + ".md"
  platform = jax.default_backend()
  print(f"sweep: tasks {', '.join(tasks)} x policies {', '.join(policies)} x seeds {seeds} x fragility {levels}, "
        f"{args.episodes} episodes each, backend {args.backend}, device {platform} x {len(devices)}; "
        f"outputs {out_path}, {md_path}",
        flush=True)
  say_compiling(COMPILE_S, platform, "per task and policy the first time")
  t0 = time.perf_counter()

  def write(res, complete):
    out = {
        "command": "mjx-damage sweep " + " ".join(argv),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "device": jax.devices()[0].device_kind, "platform": jax.devices()[0].platform,
        "num_devices": len(devices), "processes": jax.process_count(),  # episodes are sharded over them
        "tasks": tasks, "task_kwargs": {t: recorded_kwargs(t, o) for t, o in overrides.items()},
        "policies": policies, "seeds": seeds, "fragility": levels,
        "episodes": args.episodes, "safe_threshold": args.safe_threshold, "backend": args.backend,
        "backend_per_task": dict(backends),
        "executables_compiled": res["compiles"],
        "wall_s": time.perf_counter() - t0, "complete": complete,
        "rows": res["rows"], "runs": res["runs"],
    }
    md = S.markdown(res["rows"], args.safe_threshold)
    if not main_process:
      return md
    write_json(out_path, out, indent=1)
    head = f"Command: `{out['command']}`\n\nDevice: {out['device']} x {out['num_devices']}; wall {out['wall_s']:.0f} s"
    write_text(md_path, head + ("" if complete else " (incomplete: interrupted)") + "\n\n" + md)
    return md

  native_envs = min(args.native_envs, len(levels) * args.episodes)
  backends = {}  # task → the backend it runs on (auto picks per task); S.sweep makes every env first

  def make_env(task):
    env = R.make_task(task, **overrides[task], **warp_kw[task])
    backends[task] = R.pick_backend(args.backend, env, len(devices) * jax.process_count(), policies)
    return R.on_backend(env, backends[task], native_envs)

  def describe(task, spec, backend):
    # MuJoCo Warp's kernels are FFI calls, which jax.export cannot store: a Warp run keeps no traced program
    return None if backend == "warp" else R.program_description("sweep", task, spec, backend=backend)

  with heartbeat("sweep"):
    res = S.sweep(tasks, policies, seeds, levels, args.episodes, args.safe_threshold, args.episode_length,
                  devices=devices, on_progress=lambda r: write(r, False), make_env=make_env,
                  make_policy=R.make_policy, episode_length_of=R.episode_length_of,
                  describe_program=lambda task, spec: describe(task, spec, backends[task]),
                  program_roots=R.PROGRAM_ROOTS)
  print("\n" + write(res, True))
  print(f"outputs: {out_path}, {md_path}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

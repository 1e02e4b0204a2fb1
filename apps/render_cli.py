"""``mjx-damage render``: a task's rollout as a video, damaged links tinted, health bars (:mod:`mjx_damage.render`).

    mjx-damage render --task place_plate --policy scripted:unsafe --out rollout.mp4 [--plots DIR] \
        [--backend mjx|native|warp]

``--backend native`` renders the same episode with its physics stepped by native
MuJoCo (:func:`apps.resolve.on_backend`); ``--backend warp`` by MuJoCo Warp (a registry
task; one device; the warp extra).
Without ``--out`` the video goes to a new ``runs/render-<task>-<time>/rollout.mp4``; an
existing video (or ``--plots`` folder) is refused unless ``--overwrite`` is given.
"""

from __future__ import annotations

import os
import sys
import time

import jax

from apps import resolve as R
from apps import training_log
from mjx_damage import outputs, plots, video
from mjx_damage.gl import ensure_gl
from mjx_damage.render import camera_of, env_path, render_rollout
from mjx_damage.trajectory import mj_model_of, positive_int
from train.cliargs import Parser, heartbeat, say_compiling

COMPILE_S = {"cpu": 60, "gpu": 60}  # rough first compile of a task's rollout + render set-up, s


def build_parser() -> Parser:
  ap = Parser(
      prog="mjx-damage render",
      description="Render a rollout: damaged links tinted red, health bars for every tracked entity.")
  R.add_task_policy_arguments(ap)
  R.add_task_override_arguments(ap)
  R.add_backend_argument(ap, "the rollout the frames show is stepped by it", warp=True)
  ap.add_argument("--out", default=None,
                  help="output video, .mp4 or .gif (default: runs/render-<task>-<time>/rollout.mp4)")
  ap.add_argument("--overwrite", action="store_true", help="replace an existing --out video / --plots folder")
  ap.add_argument("--steps", type=int, default=None, help="control steps (default: the task's episode length)")
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--num-envs", type=int, default=1, help="environments run together; env b>0 → <out>_env<b>")
  ap.add_argument("--width", type=int, default=640)
  ap.add_argument("--height", type=int, default=480)
  ap.add_argument("--camera", default=None, help="'free' (default) or a camera name of the scene")
  ap.add_argument("--fps", type=float, default=None, help="playback rate (default: real time)")
  ap.add_argument("--plots", default=None, metavar="DIR",
                  help="also write rollout plots (PNG, env 0) to DIR: health, contact load, damage per step, "
                       "and temperature / wetness where the scene has heat sources / liquid")
  ap.add_argument("--training-log", default=None, metavar="PATH",
                  help="a training run's metrics.jsonl (or run dir): its curves go to --plots DIR too")
  return ap


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:  # everything the user gave is checked before a task is built or compiled
    R.check_task(args.task)
    R.check_backend(args.backend, warp=True)
    R.parse_policy_spec(args.policy)
    if args.out is not None:
      video.check_out(args.out)
      outputs.check_new([env_path(args.out, b, args.num_envs) for b in range(max(args.num_envs, 1))],
                        "--out", args.overwrite)
    if args.plots is not None:
      outputs.check_new([args.plots], "--plots", args.overwrite, folder=True)
    for name in ("num_envs", "width", "height"):
      positive_int(name, getattr(args, name))
    if args.steps is not None:
      positive_int("steps", args.steps)
    if args.fps is not None and not 0 < args.fps <= 1000:
      raise ValueError(f"fps: must be in (0, 1000], got {args.fps}")
    if args.training_log is not None:
      if args.plots is None:
        raise ValueError("training_log: needs --plots DIR to write the curves to")
      training_log.find_training_log(args.training_log)
    trained = R.policy_task_kwargs(args.policy, args.task)  # a checkpoint's obs_mode …
    # --backend warp: the task is made on MuJoCo Warp with the rendered envs as its one batch
    warp_kw = R.warp_overrides(args.task, args.backend, args.num_envs, len(jax.devices()))
    env = R.make_task(args.task, **R.task_overrides(args.task, trained, args.robot, args.task_arg), **warp_kw)
    policy = R.make_policy(args.policy, env)
    args.backend = R.pick_backend(args.backend, env, policies=[args.policy])  # auto → the backend used, as printed and recorded
    env = R.on_backend(env, args.backend, args.num_envs)  # the rollout that makes the frames steps this env
    steps = args.steps or R.episode_length_of(env, args.task)
    if args.camera not in (None, "free"):
      camera_of(mj_model_of(env), None, args.camera, [])
  except ValueError as e:
    ap.error(str(e))
  out = args.out or os.path.join(outputs.run_dir("render", args.task), "rollout.mp4")
  try:
    ensure_gl()
  except RuntimeError as e:
    print(f"mjx-damage render: {e}", file=sys.stderr)
    return 1
  platform = jax.default_backend()
  print(f"render: task {args.task}, policy {args.policy}, {args.num_envs} env(s) x {steps} steps, "
        f"{args.width}x{args.height}, seed {args.seed}, backend {args.backend}, device {platform}; output {out}",
        flush=True)
  say_compiling(COMPILE_S, platform)
  t0 = time.perf_counter()
  with heartbeat("render"):
    res = render_rollout(env, policy, steps=steps, seed=args.seed, out=out, width=args.width,
                         height=args.height, camera=args.camera, fps=args.fps, num_envs=args.num_envs)
  traj = res.trajectory
  final = traj.entity_health[-1]
  for b, path in enumerate(res.paths):
    health = ", ".join(f"{n} {h:.1f}" for n, h in zip(traj.entity_names, final[b]))
    print(f"wrote {path}: {steps} steps ({steps * traj.dt:.2f} s), final health: {health} (0-100), "
          f"episode damage {traj.cost[:, b].sum():.2f} health points (keeps counting after health 0)")
  if args.plots:
    title = f"{args.task} / {args.policy} (seed {args.seed})"
    written = list(plots.plot_rollout(traj, args.plots, title=title).values())
    if args.training_log:
      written.append(training_log.plot_training_log(args.training_log, os.path.join(args.plots, "training.png")))
    for p in written:
      print(f"wrote {p}")
  print(f"({time.perf_counter() - t0:.1f} s incl. compile)")
  print("outputs: " + ", ".join(list(res.paths) + ([args.plots] if args.plots else [])))
  return 0



if __name__ == "__main__":
  sys.exit(main())

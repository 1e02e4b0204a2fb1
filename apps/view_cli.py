"""``mjx-damage view``: MuJoCo's interactive viewer on a task, live damage feedback, teleoperation.

    mjx-damage view --task place_plate                              # you drive it (keys below)
    mjx-damage view --task pour_water --policy scripted:unsafe      # a policy drives it
    mjx-damage view --task pick_egg --record demos.hdf5 [--no-feedback]

Native MuJoCo with the same damage, temperature and liquid models as the MJX
path (:mod:`apps.viewer`); health bars for every tracked entity (in view or
not), values, episode damage and damage per model of the last second, geom
tint by health, updated every control step. ``--record FILE`` APPENDS each
finished episode to FILE (the ``mjx-damage record`` HDF5 layout; a new file is
created, an existing one must hold the same task's demos and is never
replaced), each demo marked with a ``feedback`` attribute; ``--no-feedback``
hides bars and tint (the paper's second condition). ``--headless`` runs on a
private Xvfb screen (tests, benchmarks, ``--screenshot``).
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
from PIL import Image

from apps import resolve as R
from apps.viewer import episode as EP
from apps.viewer import keys as K
from mjx_damage import outputs
from mjx_damage.io import atomic_path
import tasks
from train.cliargs import Parser, say_compiling

COMPILE_S = {"cpu": 40, "gpu": 40}  # rough first compile of a task's reset and step functions, s
TELEOP_EPISODE_S = 60.0  # s of simulated time per teleoperated episode unless --episode-length says


def build_parser() -> Parser:
  ap = Parser(prog="mjx-damage view", description="MuJoCo's interactive viewer on a task (native MuJoCo): live "
              "health bars and damage tint, teleoperation, recording.\n\n" + __doc__.split("\n\n")[2] + "\n\nkeys (teleoperation and viewer):\n"
              + K.help_text() + "\n\nMuJoCo's own viewer keys (mouse: rotate/zoom/pan; Ctrl + drag: push a "
              "body; letters toggle display flags) keep working.")
  ap.add_argument("--task", required=True, help=f"task name (registry tasks, or built-in: {', '.join(R.BUILTIN_TASKS)})")
  R.add_task_override_arguments(ap)
  ap.add_argument("--policy", default=None,
                  help="scripted:safe | scripted:unsafe | random | zero | checkpoint[+sample|+mean]:RUN[#SEED] drives the robot "
                       "(default: you, from the keyboard)")
  ap.add_argument("--record", default=None, metavar="FILE.hdf5",
                  help="append every finished episode to this dataset (created if missing; never overwritten)")
  ap.add_argument("--no-feedback", action="store_true", help="hide health bars and damage tint")
  ap.add_argument("--episode-length", type=int, default=None,
                  help=f"control steps per episode (default: the task's with --policy, {TELEOP_EPISODE_S:g} s "
                       "of simulated time when teleoperating)")
  ap.add_argument("--episodes", type=int, default=None, help="close after this many episodes (default: never)")
  ap.add_argument("--steps", type=int, default=None, help="close after this many control steps (default: never)")
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--speed", type=float, default=1.0, help=f"start in slow motion: one of {', '.join(map(str, K.SPEEDS))}")
  ap.add_argument("--headless", action="store_true", help="run on a private Xvfb screen (needs the xvfb package)")
  ap.add_argument("--screenshot", default=None, metavar="FILE.png",
                  help="with --headless: save the screen as PNG when the viewer closes")
  ap.add_argument("--overwrite", action="store_true", help="replace an existing --screenshot file")
  ap.add_argument("--plain", action="store_true",
                  help="no shadows or reflections: software OpenGL renders several times faster (implied by --headless)")
  ap.add_argument("--no-realtime", action="store_true", help="step as fast as possible (benchmarks)")
  return ap


def _check(args) -> dict:
  """Every user input checked before a task is built or anything compiles; returns the make() overrides."""
  R.check_task(args.task)
  if args.policy is not None:
    R.parse_policy_spec(args.policy)
  for name in ("episode_length", "episodes", "steps"):
    v = getattr(args, name)
    if v is not None and v < 1:
      raise ValueError(f"{name}: must be >= 1, got {v}")
  if args.speed not in K.SPEEDS:
    raise ValueError(f"speed: must be one of {', '.join(map(str, K.SPEEDS))}, got {args.speed}")
  if args.screenshot is not None:
    if not args.headless:
      raise ValueError("screenshot: needs --headless (the screen of a private Xvfb display is what is saved)")
    if not args.screenshot.lower().endswith(".png"):
      raise ValueError(f"screenshot: must end in .png, got {args.screenshot!r}")
    outputs.check_new([args.screenshot], "--screenshot", args.overwrite)
  if args.record is not None:
    if not args.record.lower().endswith((".hdf5", ".h5")):
      raise ValueError(f"record: must end in .hdf5 or .h5, got {args.record!r}")
    outputs.check_writable(args.record, "--record")
  trained = R.policy_task_kwargs(args.policy, args.task) if args.policy is not None else {}
  return R.task_overrides(args.task, trained, args.robot, args.task_arg)


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:
    overrides = _check(args)
    env = R.make_task(args.task, **overrides)  # unknown robots and bad overrides raise here
    policy = R.make_policy(args.policy, env) if args.policy is not None else None
    if args.episode_length is not None:
      length = args.episode_length
    elif policy is not None:
      length = R.episode_length_of(env, args.task)
    else:
      length = max(1, round(TELEOP_EPISODE_S / env.dt))
    if args.record is not None:
      n = EP.check_target(args.record, args.task)
      print(f"view: --record {args.record}: " + (f"appending to the existing dataset ({n} episodes)" if n
                                                  else "new dataset"), flush=True)
  except ValueError as e:
    ap.error(str(e))
  import jax  # noqa: PLC0415  (after the checks: a bad command line answers without starting JAX)

  from apps.viewer import app  # noqa: PLC0415  (loads mujoco.viewer and GLFW only when viewing)
  from apps.viewer import display as X  # noqa: PLC0415

  label = args.policy or "teleop"
  platform = jax.default_backend()
  print(f"view: task {args.task}{' robot ' + args.robot if args.robot else ''}, {label}, episodes of {length} "
        f"steps ({length * env.dt:.1f} s), feedback {'off' if args.no_feedback else 'on'}, device {platform}",
        flush=True)
  say_compiling(COMPILE_S, platform)
  kw = dict(policy=policy, feedback=not args.no_feedback, record=args.record,
            env_config=tasks.recorded_kwargs(env, overrides), label=label,
            episode_length=length, steps=args.steps, episodes=args.episodes, seed=args.seed,
            realtime=not args.no_realtime, speed=args.speed, plain=args.plain or args.headless)
  t0 = time.perf_counter()
  if args.headless:
    try:
      with X.virtual_display() as screen:
        res = app.run(env, args.task, screen=screen, **kw)
    except RuntimeError as e:
      print(f"mjx-damage view: {e}", file=sys.stderr)
      return 1
  else:
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
      print("mjx-damage view: no display (DISPLAY is unset); use --headless or run under a desktop",
            file=sys.stderr)
      return 1
    res = app.run(env, args.task, **kw)
  if args.screenshot is not None and res["screenshot"] is not None:
    with atomic_path(args.screenshot, suffix=".png") as tmp:
      Image.fromarray(res["screenshot"]).save(tmp, format="PNG")
    print(f"wrote {args.screenshot}")
  print(json.dumps({"steps": res["steps"], "episodes": res["episodes"], "sim_s": round(res["sim_s"], 3),
                    "wall_s": round(res["wall_s"], 3),
                    "step_ms_median": round(1000 * float(np.median(res["step_s"])), 2) if res["step_s"] else None,
                    "final_health": res["final_health"],
                    "recorded_episodes_in_file": res["recorded"] if args.record else None}))
  print(f"({time.perf_counter() - t0:.1f} s incl. compile)")
  return 0


if __name__ == "__main__":
  sys.exit(main())

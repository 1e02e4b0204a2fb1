"""One still per task: the end state of the scripted safe and unsafe policies side by side, tinted by health.

    .venv/bin/python benchmarks/task_stills.py                      # every registered task (skips rendered ones)
    .venv/bin/python benchmarks/task_stills.py --tasks place_plate pour_water --force
    .venv/bin/python benchmarks/task_stills.py --robot panda --tasks shelve_item   # → docs/figures/tasks_panda

For each task of ``tasks.names()`` (or ``--tasks``): ONE compiled rollout
(:func:`mjx_damage.trajectory.rollout`, 2 envs: env 0 runs ``scripted:safe``,
env 1 ``scripted:unsafe``, both from the same randomised reset), then the last
recorded step of each env rendered offscreen by
:func:`mjx_damage.render.render_frames` — tracked links tinted toward red by lost
health, the health-bar overlay — and written as

* ``<out>/<task>.png``: safe | unsafe, each panel headed by its policy, whether
  the task was completed, and every entity's final health (0–100);
* ``<out>/<task>.json``: what the panels show, as numbers, with the command;
* ``<out>/index.md``: the contact sheet (every task's still and a table),
  rewritten after each task from the JSON files present, so partial runs keep
  their progress and a later run skips tasks already rendered (``--force``
  redoes them).

Deterministic for a given seed on CPU. Rendering is headless (OSMesa by default,
``MUJOCO_GL=egl`` for EGL), as ``mjx-damage render``.
"""

from __future__ import annotations

import glob
import json
import os
import sys
import time

import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:  # run as a script from anywhere: the repo's packages first
  sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

import tasks  # noqa: E402
from apps.resolve import episode_length_of  # noqa: E402
from mjx_damage.gl import ensure_gl  # noqa: E402
from mjx_damage.io import atomic_path, write_json, write_text  # noqa: E402
from mjx_damage.render import render_frames  # noqa: E402
from mjx_damage.trajectory import MODELS, mj_model_of, positive_int, rollout  # noqa: E402
from train.cliargs import Parser  # noqa: E402

STYLES = ("safe", "unsafe")  # panel order, left to right
DEFAULT_OUT = os.path.join(ROOT, "docs", "figures", "tasks")  # the gripper's; other robots: tasks_<robot>


def default_out(robot: str) -> str:
  return DEFAULT_OUT if robot == "gripper" else f"{DEFAULT_OUT}_{robot}"
MAX_SIDE = 2048  # px per panel: a still, not a poster
HEADER_ROWS = 3  # policy + outcome, final health (may wrap to a second line)


def build_parser() -> Parser:
  ap = Parser(prog="task_stills.py", description=__doc__.splitlines()[0])
  ap.add_argument("--tasks", nargs="+", default=None, metavar="TASK",
                  help="tasks to render (default: every registered task, tasks.names())")
  ap.add_argument("--robot", default="gripper", help="robot of every task (tasks.robots_for; default gripper)")
  ap.add_argument("--out", default=None,
                  help="folder of the stills, their JSON and index.md (default docs/figures/tasks, or "
                       "docs/figures/tasks_<robot> for another robot)")
  ap.add_argument("--seed", type=int, default=0, help="PRNG seed of the shared reset and the actions")
  ap.add_argument("--width", type=int, default=480, help="panel width, px")
  ap.add_argument("--height", type=int, default=360, help="panel height (rendered frame), px")
  ap.add_argument("--steps", type=int, default=None, help="control steps (default: each task's episode length)")
  ap.add_argument("--force", action="store_true", help="re-render tasks whose still already exists")
  return ap


def check_args(args) -> list:
  """The tasks to render, in order; ``ValueError`` naming the field on bad input (nothing compiled yet)."""
  chosen = tasks.select(args.tasks, args.robot)
  if args.out is None:
    args.out = default_out(args.robot)
  for name in ("width", "height"):
    v = positive_int(name, getattr(args, name))
    if not 64 <= v <= MAX_SIDE:
      raise ValueError(f"{name}: must be in [64, {MAX_SIDE}] px, got {v}")
  if args.steps is not None:
    positive_int("steps", args.steps)
  if os.path.exists(args.out) and not os.path.isdir(args.out):
    raise ValueError(f"out: exists and is not a folder: {args.out}")
  return chosen


def _font(size: int):
  try:
    return ImageFont.load_default(size=size)
  except (TypeError, OSError):  # Pillow < 10.1: the fixed bitmap font
    return ImageFont.load_default()


def _wrap(draw, text: str, font, width: int) -> list:
  """``text`` split at ", " into lines no wider than ``width`` px."""
  lines, cur = [], ""
  for part in text.split(", "):
    trial = part if not cur else f"{cur}, {part}"
    if cur and draw.textlength(trial, font=font) > width:
      lines.append(cur + ",")
      cur = part
    else:
      cur = trial
  return lines + [cur]


def panel(frame: np.ndarray, title: str, health: str) -> np.ndarray:
  """``frame`` (uint8[H, W, 3]) under a white header: ``title`` (bold line) and ``health`` (wrapped)."""
  h, w = frame.shape[:2]
  size = max(10, w // 34)
  font = _font(size)
  row = int(size * 1.35)
  header = Image.new("RGB", (w, row * HEADER_ROWS + size // 2), "white")
  draw = ImageDraw.Draw(header)
  draw.text((6, 3), title, fill=(0, 0, 0), font=font)
  for i, line in enumerate(_wrap(draw, health, font, w - 12)[:HEADER_ROWS - 1]):
    draw.text((6, 3 + row * (i + 1)), line, fill=(40, 40, 40), font=font)
  return np.concatenate([np.asarray(header), frame], axis=0)


def side_by_side(panels: list, gap: int = 6) -> np.ndarray:
  """Panels (uint8[H, W_i, 3], same H) in one row with white gaps."""
  h = panels[0].shape[0]
  bar = np.full((h, gap, 3), 255, np.uint8)
  return np.concatenate([x for p in panels for x in (p, bar)][:-1], axis=1)


def save_png(img: np.ndarray, path: str) -> None:
  """Palette PNG (256 colours, optimised): a rendered still is a few hundred kB as RGB, ~4× less so."""
  with atomic_path(path, ".png") as tmp:
    Image.fromarray(img).quantize(colors=256, dither=Image.Dither.NONE).save(tmp, optimize=True)


def health_text(names, values) -> str:
  return "final health: " + ", ".join(f"{n} {v:.1f}" for n, v in zip(names, values))


AZIMUTHS = (135.0, 90.0, 180.0, 45.0, 225.0, 0.0, 270.0, 315.0)  # deg; the first is render's default view
ELEVATIONS = (-30.0, -50.0)  # deg
PROBE = (128, 96)  # px of the segmentation probes that pick the camera


def entity_pixels(seg: np.ndarray, traj, n: int) -> np.ndarray:
  """i[n]: pixels of each tracked entity in a geom-id image ``seg`` (i[H, W], −1 = none)."""
  geom_entity = np.where(traj.geom_link >= 0, traj.link_entity[np.maximum(traj.geom_link, 0)], -1)
  ids = np.append(geom_entity, -1)[seg]  # seg −1 (background) → −1
  return np.bincount(ids[ids >= 0], minlength=n)[:n]


def choose_camera(model, traj) -> mujoco.MjvCamera:
  """A free camera that shows every tracked entity in the end states of all envs.

  Looks at the tracked bodies' centre (over the reset and every env's end state)
  from a distance that spans them, and picks among :data:`AZIMUTHS` ×
  :data:`ELEVATIONS` the view whose segmentation shows the most of each entity:
  the score sums, over envs and entities, the entity's visible share of the frame
  capped at 2 % — so walls or cabinets in front of an entity cost a view, and one
  large entity cannot outweigh a small one left out. Ties keep the earlier view.
  """
  data = mujoco.MjData(model)
  bodies = np.unique(model.geom_bodyid[traj.geom_link >= 0])
  pts = []
  for t, b in [(0, 0)] + [(traj.steps, b) for b in range(traj.num_envs)]:
    data.qpos[:], data.qvel[:] = traj.qpos[t, b], traj.qvel[t, b]
    if model.nmocap:
      data.mocap_pos[:], data.mocap_quat[:] = traj.mocap_pos[t, b], traj.mocap_quat[t, b]
    mujoco.mj_forward(model, data)
    pts.append(data.xpos[bodies])
  pts = np.concatenate(pts)
  centre = pts.mean(axis=0)
  spread = float(np.max(np.linalg.norm(pts - centre, axis=1)))
  n = len(traj.entity_names)
  cap = 0.02 * PROBE[0] * PROBE[1]
  best, best_score = None, -1.0
  for el in ELEVATIONS:
    for az in AZIMUTHS:
      cam = mujoco.MjvCamera()
      mujoco.mjv_defaultFreeCamera(model, cam)
      cam.lookat[:], cam.distance, cam.azimuth, cam.elevation = centre, max(0.6, 2.6 * spread), az, el
      score = 0.0
      for b in range(traj.num_envs):
        seg = render_frames(model, traj, width=PROBE[0], height=PROBE[1], camera=cam, env_index=b,
                            times=[-1], segmentation=True)[0]
        score += float(np.sum(np.minimum(entity_pixels(seg, traj, n), cap)))
      if score > best_score + 1e-6:
        best, best_score = cam, score
  return best


def render_task(name: str, *, seed: int, width: int, height: int, steps=None, robot: str = "gripper") -> tuple:
  """Roll out safe and unsafe from one reset (one compiled program), render both end states.

  Returns (image uint8[H', 2W + gap, 3], summary dict).
  """
  env = tasks.make(name, robot=robot)
  steps = steps or episode_length_of(env, name)
  policies = [tasks.scripted_policy(env, s) for s in STYLES]
  traj = rollout(env, policies, steps=steps, seed=seed, num_envs=len(STYLES), same_reset=True)
  model = mj_model_of(env)
  panels, summary = [], {"task": name, "robot": robot, "seed": seed, "steps": steps, "dt": traj.dt,
                         "entities": list(traj.entity_names), "policies": {}}
  camera = choose_camera(model, traj)
  summary["camera"] = {"lookat": [float(x) for x in camera.lookat], "distance": float(camera.distance),
                       "azimuth": float(camera.azimuth), "elevation": float(camera.elevation)}
  for b, style in enumerate(STYLES):
    frame = render_frames(model, traj, width=width, height=height, camera=camera, env_index=b, times=[-1])[0]
    final = [float(x) for x in traj.entity_health[-1, b]]
    completed = bool(np.max(traj.success[:, b]) > 0)
    damage = np.sum(traj.damage[:, b], axis=0) if traj.damage is not None else np.zeros(3)
    summary["policies"][style] = {
        "completed": completed,
        "final_health": dict(zip(traj.entity_names, final)),
        "episode_damage": float(np.sum(traj.cost[:, b])),
        "damage_by_model": {m: float(d) for m, d in zip(MODELS, damage)},
    }
    outcome = "completed" if completed else "NOT completed"
    panels.append(panel(frame, f"scripted:{style} - {outcome}", health_text(traj.entity_names, final)))
  return side_by_side(panels), summary


def command_of(name: str, args) -> str:
  """The command that renders ``name`` again as this run did (non-default options only)."""
  cmd = f"python benchmarks/task_stills.py --tasks {name}"
  if args.robot != "gripper":
    cmd += f" --robot {args.robot}"
  for opt, default in (("seed", 0), ("width", 480), ("height", 360), ("steps", None)):
    if getattr(args, opt) != default:
      cmd += f" --{opt} {getattr(args, opt)}"
  if os.path.abspath(args.out) != os.path.abspath(default_out(args.robot)):
    cmd += f" --out {args.out}"
  return cmd + " --force"


def write_index(out: str, robot: str = "gripper") -> str:
  """``<out>/index.md``: every still present (from its JSON), one table row and one image per task."""
  summaries = []
  for path in sorted(glob.glob(os.path.join(out, "*.json"))):
    with open(path) as f:
      s = json.load(f)
    if os.path.isfile(os.path.join(out, f"{s['task']}.png")):
      summaries.append(s)
  runs = [t for t in tasks.names() if robot in tasks.robots_for(t)]
  flag = "" if robot == "gripper" else f" --robot {robot}"
  lines = [f"# Task stills: scripted safe vs unsafe, end state ({robot})", "",
           f"Generated by `python benchmarks/task_stills.py{flag}` ({len(summaries)} of the {len(runs)} registered "
           f"tasks that run with the {robot}; each section gives the command that redoes it).", "",
           "Each still: the task's scripted safe (left) and unsafe (right) policy from the same randomised",
           "reset, at the last step of the episode. Tracked links are tinted toward red by the health they",
           "lost; the bars give every entity's health (0-100).", "",
           "| task | safe: completed, min health | unsafe: completed, min health | unsafe damage (mech / therm / fluid, hp) |",
           "|---|---|---|---|"]

  def cell(p):
    return f"{'yes' if p['completed'] else 'no'}, {min(p['final_health'].values()):.1f}"

  for s in summaries:
    p = s["policies"]
    d = p["unsafe"]["damage_by_model"]
    lines.append(f"| [{s['task']}](#{s['task']}) | {cell(p['safe'])} | {cell(p['unsafe'])} | "
                 f"{d['mechanical']:.1f} / {d['thermal']:.1f} / {d['fluid']:.1f} |")
  for s in summaries:
    lines += ["", f"## {s['task']}", "",
              f"seed {s['seed']}, {s['steps']} steps ({s['steps'] * s['dt']:.2f} s): `{s['command']}`", "",
              f"![{s['task']}: safe vs unsafe]({s['task']}.png)"]
  path = os.path.join(out, "index.md")
  write_text(path, "\n".join(lines) + "\n")
  return path


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:
    chosen = check_args(args)
  except ValueError as e:
    ap.error(str(e))
  try:
    ensure_gl()
  except RuntimeError as e:
    print(f"task_stills: {e}", file=sys.stderr)
    return 1
  os.makedirs(args.out, exist_ok=True)
  for name in chosen:
    png, meta = os.path.join(args.out, f"{name}.png"), os.path.join(args.out, f"{name}.json")
    if not args.force and os.path.isfile(png) and os.path.isfile(meta):
      print(f"{name}: already rendered ({os.path.relpath(png, ROOT)}), skipped (--force redoes it)", flush=True)
      continue
    t0 = time.perf_counter()
    img, summary = render_task(name, seed=args.seed, width=args.width, height=args.height, steps=args.steps,
                               robot=args.robot)
    save_png(img, png)
    write_json(meta, {**summary, "command": command_of(name, args)})
    write_index(args.out, args.robot)
    line = "; ".join(f"{s}: {'completed' if p['completed'] else 'not completed'}, min health "
                     f"{min(p['final_health'].values()):.1f}" for s, p in summary["policies"].items())
    print(f"{name}: wrote {os.path.relpath(png, ROOT)} ({os.path.getsize(png) // 1024} kB) in "
          f"{time.perf_counter() - t0:.0f} s incl. compile; {line}", flush=True)
  print(f"index: {os.path.relpath(write_index(args.out, args.robot), ROOT)}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

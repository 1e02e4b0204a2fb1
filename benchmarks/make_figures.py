"""Regenerate the README's "Seeing damage" figures under docs/figures/.

    .venv/bin/python benchmarks/make_figures.py            # ~2–4 min on a laptop CPU (two compiles)
    .venv/bin/python benchmarks/make_figures.py --figures pour_water

Rolls out Place Plate with the scripted unsafe policy (carry the plate at 18 cm
over the goal and let go), renders it with :func:`mjx_damage.render.render_rollout`
and writes:

* ``docs/figures/place_plate_unsafe_frames.png`` — three frames side by side:
  carrying, falling (just before impact), broken (tinted red, bar dropped);
* ``docs/figures/place_plate_unsafe_rollout.png`` — health, contact load on the
  most damaged link and cost over the episode (:func:`mjx_damage.plots.plot_rollout`);
* ``docs/figures/place_plate_unsafe.gif`` — the whole rollout, small;

and rolls out Pour Water with the scripted unsafe policy (tip the glass over
the laptop, then carry it to the cup) and writes:

* ``docs/figures/pour_water_liquid.png`` — one frame with the water (blue
  particles) on the laptop, its "wet (particles)" readout and the damage caption;
* ``docs/figures/pour_water_rollout.png`` — health, load, damage per step and
  wetness over the episode.

Deterministic for a given seed (CPU); the command line is written into
``docs/figures/README.md`` beside the figures. ``--robot`` (default the gripper, the
robot of the README's figures) other than the gripper writes to
``docs/figures/seeing_damage_<robot>/`` unless ``--out`` is given.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:  # run as a script from anywhere: the repo's packages first
  sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))
os.environ.setdefault("MPLBACKEND", "Agg")

from mjx_damage.io import atomic_path, write_text  # noqa: E402


FIGURES = ("place_plate", "pour_water")


def _who(args) -> str:
  """The robot for titles and README lines, only when not the gripper (the committed figures' text stays)."""
  return "" if args.robot == "gripper" else f", {args.robot}"


def place_plate_figures(args, out_dir):
  """Place Plate, scripted unsafe: three frames, the rollout plots, a small GIF. Returns (paths, README lines)."""
  import tasks
  from PIL import Image

  from mjx_damage import plots
  from mjx_damage.render import render_rollout, write_video

  env = tasks.make("place_plate", robot=args.robot)
  policy = tasks.scripted_policy(env, "unsafe")
  steps = env.unwrapped.episode_length  # the robot's: the default_config's for the gripper, longer for the Panda
  res = render_rollout(env, policy, steps=steps, seed=args.seed, width=args.width, height=args.height)
  traj, frames = res.trajectory, res.frames[0]
  plate = traj.entity_names.index("plate")
  hit = np.nonzero(traj.entity_health[:, 0, plate] < 100.0)[0]
  if not len(hit):
    raise SystemExit("the unsafe rollout did not damage the plate: nothing to show")
  t_hit = int(hit[0])
  picks = [max(0, t_hit - 20), max(0, t_hit - 1), min(steps, t_hit + 4)]

  gap = np.full((args.height, 6, 3), 255, np.uint8)
  strip = np.concatenate([x for t in picks for x in (frames[t], gap)][:-1], axis=1)
  frames_png = os.path.join(out_dir, "place_plate_unsafe_frames.png")
  with atomic_path(frames_png, ".png") as tmp_png:
    Image.fromarray(strip).save(tmp_png, optimize=True)

  with tempfile.TemporaryDirectory() as tmp:
    paths = plots.plot_rollout(traj, tmp, title=f"Place Plate, scripted unsafe policy (seed {args.seed}{_who(args)})")
    plot_png = os.path.join(out_dir, "place_plate_unsafe_rollout.png")
    shutil.copy(paths["rollout"], plot_png)

  # a small, short GIF: every second frame at half size (keeps the repository light)
  small = np.stack([np.asarray(Image.fromarray(f).resize((args.width // 2, args.height // 2), Image.LANCZOS))
                    for f in frames[::2]])
  gif = write_video(small, os.path.join(out_dir, "place_plate_unsafe.gif"), fps=0.5 / traj.dt)
  lines = [f"Place Plate, `scripted:unsafe`, seed {args.seed}{_who(args)}, {steps} steps, {args.width}×{args.height}:",
           f"- `place_plate_unsafe_frames.png`: steps {picks[0]}, {picks[1]}, {picks[2]} "
           f"(impact at step {t_hit}); final plate health {traj.entity_health[-1, 0, plate]:.1f}.",
           "- `place_plate_unsafe_rollout.png`: health, contact load on the most damaged link, damage per step.",
           "- `place_plate_unsafe.gif`: the rollout, every second step, half size."]
  return [frames_png, plot_png, gif], lines


def pour_water_figures(args, out_dir):
  """Pour Water, scripted unsafe: one frame with the liquid on the laptop, the rollout plots."""
  import tasks
  from PIL import Image

  from mjx_damage import plots
  from mjx_damage.render import render_rollout

  env = tasks.make("pour_water", robot=args.robot)
  policy = tasks.scripted_policy(env, "unsafe")
  steps = env.unwrapped.episode_length  # the robot's: the default_config's for the gripper, longer for the Panda
  w, h = 2 * args.width, 2 * args.height  # particles are 6 mm: a larger frame shows them
  res = render_rollout(env, policy, steps=steps, seed=args.seed, width=w, height=h)
  traj, frames = res.trajectory, res.frames[0]
  laptop = traj.entity_names.index("laptop")
  wet = traj.exposure[:, 0, traj.link_entity == laptop].sum(axis=1)
  if wet.max() <= 0:
    raise SystemExit("the unsafe pour did not wet the laptop: nothing to show")
  t_wet = int(np.nonzero(wet >= 0.5 * wet.max())[0][0])  # water arriving on the laptop, still visible falling
  png = os.path.join(out_dir, "pour_water_liquid.png")
  with atomic_path(png, ".png") as tmp_png:
    Image.fromarray(frames[t_wet]).save(tmp_png, optimize=True)
  with tempfile.TemporaryDirectory() as tmp:
    paths = plots.plot_rollout(traj, tmp, title=f"Pour Water, scripted unsafe policy (seed {args.seed}{_who(args)})")
    plot_png = os.path.join(out_dir, "pour_water_rollout.png")
    shutil.copy(paths["rollout"], plot_png)
  lines = [f"Pour Water, `scripted:unsafe`, seed {args.seed}{_who(args)}, {steps} steps, {w}×{h}:",
           f"- `pour_water_liquid.png`: step {t_wet} ({t_wet * traj.dt:.2f} s), {wet[t_wet]:.0f} of "
           f"{traj.particles.shape[2]} particles touching the laptop (peak {wet.max():.0f}); laptop health "
           f"{traj.entity_health[t_wet, 0, laptop]:.1f} there, {traj.entity_health[-1, 0, laptop]:.1f} at the end.",
           "- `pour_water_rollout.png`: health, contact load, damage per step by model, wetness."]
  return [png, plot_png], lines


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  ap.add_argument("--out", default=None,
                  help="output directory (default docs/figures; another --robot: docs/figures/seeing_damage_<robot>)")
  ap.add_argument("--robot", default="gripper",
                  help="robot of both tasks (tasks.robots.names()); default gripper: the robot of the committed "
                       "figures")
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--width", type=int, default=400)
  ap.add_argument("--height", type=int, default=300)
  ap.add_argument("--figures", nargs="+", choices=FIGURES, default=list(FIGURES),
                  help="which figure sets to regenerate (README lines of the others are kept)")
  args = ap.parse_args(argv)
  import tasks

  try:
    tasks.check_robot(args.robot, args.figures, "--robot")
  except ValueError as e:
    ap.error(str(e))
  if args.out is None:  # another robot's figures beside the README's, not over them
    sub = [] if args.robot == "gripper" else [f"seeing_damage_{args.robot}"]
    args.out = os.path.join(ROOT, "docs", "figures", *sub)
  os.makedirs(args.out, exist_ok=True)
  makers = {"place_plate": place_plate_figures, "pour_water": pour_water_figures}
  cmd = "python benchmarks/make_figures.py" + "".join(f" {a}" for a in (argv if argv is not None else sys.argv[1:]))
  readme = os.path.join(args.out, "README.md")
  sections = _read_sections(readme)
  written = []
  for name in args.figures:
    paths, lines = makers[name](args, args.out)
    written += paths
    sections[name] = [f"Generated by `{cmd}`.", ""] + lines
  text = "# Figures of the README's \"Seeing damage\" section\n"
  for name in FIGURES:
    if name in sections:
      text += f"\n## {name}\n\n" + "\n".join(sections[name]) + "\n"
  write_text(readme, text)
  for p in written:
    print(f"wrote {os.path.relpath(p, ROOT)}")
  return 0


def _read_sections(readme: str) -> dict:
  """{figure set: its lines} of an existing README written by this script (``## name`` headings)."""
  out, cur = {}, None
  if not os.path.isfile(readme):
    return out
  with open(readme) as f:
    for line in f.read().splitlines():
      if line.startswith("## ") and line[3:].strip() in FIGURES:
        cur = line[3:].strip()
        out[cur] = []
      elif cur is not None:
        out[cur].append(line)
  return {k: "\n".join(v).strip("\n").splitlines() for k, v in out.items()}


if __name__ == "__main__":
  sys.exit(main())

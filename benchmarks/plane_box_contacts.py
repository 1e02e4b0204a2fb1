"""A tilted box landing on a counter: peak contact force on MJX-JAX and on MuJoCo C, counter as a plane or a box.

MJX's plane–convex collision (``mjx._src.collision_convex.plane_convex``, which boxes use) keeps only the
box corners within a 1 mm skin of the deepest one; MuJoCo C (``mjc_PlaneBox``) keeps every corner below the
plane. A box that lands flat touches with four corners at once and both agree exactly; one that lands a
degree or two tilted rocks onto its second edge while the first is still pressed in by more than 1 mm, and
MJX then has no contact there: the box pivots, the impact spreads over more substeps and its peak force is
lower. Box–box collision (a counter modelled as a thin box) keeps both edges on MJX too.

For each counter shape and tilt this drops Place Plate's plate (12 × 12 × 2 cm box, 0.3 kg, solref 8 ms,
4 ms step, implicitfast, 8 solver iterations) from ``--height`` and reports the largest total normal contact
force (N) on each simulator, the number of contacts carrying force at that substep, and the ratio MJX / C.
Physics only: no task, no damage model, one environment, CPU.

Writes ``benchmarks/results/plane_box_contacts.{json,md}`` with the command.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/plane_box_contacts.py [--tilts 0,0.5,1,2,5] [--height 0.05]
"""

from __future__ import annotations

import argparse
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags before jax starts)
import jax  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from mujoco import mjx  # noqa: E402
from mujoco.mjx._src import support  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)

COUNTERS = {  # the counter's top face is z = 0 either way
    "plane": '<geom name="counter" type="plane" size="0.6 0.6 0.05" solref="0.008 1"/>',
    "box": '<geom name="counter" type="box" pos="0 0 -0.05" size="0.6 0.6 0.05" solref="0.008 1"/>',
}
SCENE = """<mujoco>
  <option timestep="0.004" integrator="implicitfast" iterations="8" ls_iterations="8"/>
  <worldbody>
    {counter}
    <body name="plate" pos="0 0 {z}" euler="0 {tilt} 0">
      <freejoint/>
      <geom type="box" size="0.06 0.06 0.01" mass="0.3" solref="0.008 1" friction="0.8 0.01 0.001"/>
    </body>
  </worldbody>
</mujoco>"""
HALF_THICK, HALF_SIDE = 0.01, 0.06


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--tilts", default="0,0.5,1,2,5", help="comma-separated tilts about y, degrees, in [0, 30]")
  p.add_argument("--height", type=float, default=0.05, help="drop height of the lowest corner, m, in (0, 1]")
  p.add_argument("--steps", type=int, default=80, help="steps of 4 ms (enough to land and settle)")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  args = p.parse_args(argv)
  try:
    args.tilts = [float(t) for t in args.tilts.split(",") if t.strip()]
  except ValueError:
    p.error(f"tilts: comma-separated numbers, got {args.tilts!r}")
  if not args.tilts or not all(0 <= t <= 30 for t in args.tilts):
    p.error(f"tilts: degrees in [0, 30], at least one, got {args.tilts}")
  if not 0 < args.height <= 1:  # also refuses NaN
    p.error(f"height: m in (0, 1], got {args.height}")
  if args.steps < 1:
    p.error(f"steps: must be >= 1, got {args.steps}")
  return args


def scene(counter: str, tilt_deg: float, height: float) -> mujoco.MjModel:
  t = math.radians(tilt_deg)  # centre height that puts the lowest corner ``height`` above the counter
  z = height + HALF_SIDE * math.sin(t) + HALF_THICK * math.cos(t)
  return mujoco.MjModel.from_xml_string(SCENE.format(counter=COUNTERS[counter], z=z, tilt=tilt_deg))


def drop_native(model: mujoco.MjModel, steps: int) -> tuple[float, int]:
  """Largest total normal contact force (N) over the substeps, and how many contacts carried force then."""
  data, f, best = mujoco.MjData(model), np.zeros(6), (0.0, 0)
  for _ in range(steps):
    mujoco.mj_step(model, data)
    normals = []
    for i in range(data.ncon):
      mujoco.mj_contactForce(model, data, i, f)
      normals.append(f[0])
    total = float(sum(normals))
    if total > best[0]:
      best = (total, int(sum(n > 1e-6 for n in normals)))
  return best


def drop_mjx(model: mujoco.MjModel, steps: int) -> tuple[float, int]:
  mx = mjx.put_model(model)
  dx = mjx.put_data(model, mujoco.MjData(model))
  step = jax.jit(mjx.step)
  best = (0.0, 0)
  for _ in range(steps):
    dx = step(mx, dx)
    force, _ = support.contact_force_dim(mx, dx, 3)  # every contact here has condim 3
    normals = np.asarray(force[:, 0])
    if normals.sum() > best[0]:
      best = (float(normals.sum()), int((normals > 1e-6).sum()))
  return best


def render_md(res: dict) -> str:
  lines = ["# A tilted box landing on a counter: MJX-JAX vs MuJoCo C", "",
           f"Date: {res['date']}. Git: {res['git']}. jax {res['jax']} ({res['backend']}), mujoco {res['mujoco']}. "
           f"Place Plate's plate dropped {res['height']} m (lowest corner) onto the counter, tilted about y; "
           "peak = the largest total normal contact force over the substeps, N; contacts = how many carried "
           "force at that substep.", "",
           f"Command: `{res['command']}`", "",
           "| counter | tilt (deg) | peak, MuJoCo C (N) | contacts | peak, MJX (N) | contacts | MJX / C |",
           "|---|---|---|---|---|---|---|"]
  for r in res["rows"]:
    lines.append(f"| {r['counter']} | {r['tilt_deg']:g} | {r['native_peak_N']:.1f} | {r['native_contacts']} | "
                 f"{r['mjx_peak_N']:.1f} | {r['mjx_contacts']} | {r['mjx_over_native']:.2f} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  args = parse(argv)
  rows = []
  for counter in COUNTERS:
    for tilt in args.tilts:
      m = scene(counter, tilt, args.height)
      (fn, cn), (fx, cx) = drop_native(m, args.steps), drop_mjx(m, args.steps)
      rows.append({"counter": counter, "tilt_deg": tilt, "native_peak_N": round(fn, 2), "native_contacts": cn,
                   "mjx_peak_N": round(fx, 2), "mjx_contacts": cx, "mjx_over_native": round(fx / fn, 3)})
      print(rows[-1], flush=True)
  res = {"height": args.height, "steps": args.steps, "mujoco": mujoco.__version__, "rows": rows}
  provenance.save_results(res, "plane_box_contacts", argv, os.path.join(args.results_dir, "plane_box_contacts"),
                          render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

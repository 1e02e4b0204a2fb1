"""Benchmark scene generator: K damageable free boxes on a table, swept by a pusher.

``table_scene_xml(k)`` writes the MJCF; ``table_scene(k)`` loads it;
``table_config(k)`` is the damage config tracking the K boxes (one entity, one
link each). The scene is designed for throughput, the way a user should design
a many-object scene for MJX:

* the table top is a plane (the cheapest MJX collision: box-plane is 4 corner
  tests, box-box a separating-axis search);
* boxes carry ``contype=1 conaffinity=2`` and the table ``contype=2
  conaffinity=1``, so boxes touch the table but never each other — MJX
  computes every enabled pair every step whether or not the bodies are close,
  so K free boxes colliding pairwise would cost O(K²) narrow-phase calls;
* the pusher (a sphere on two slide joints at box height, position-servoed)
  has ``contype=2 conaffinity=1``: it hits the boxes (sphere-box, cheap) and
  not the table. It makes contacts happen, so the damage path does real work.

Contacts per environment: 4 per box (box-plane) + 1 per box (sphere-box).

``free`` < K mounts boxes ``free``..K−1 on the table (no joint: welded to the
world, like a stove, a wall-hung cabinet or a laptop that the task never
moves). A mounted box is still a damageable entity the pusher can hit, but it
adds no degrees of freedom and no box-table contacts (MuJoCo never collides two
bodies welded to the world), so its only cost is its pusher-box pair. Free
boxes are what make a scene expensive: each adds 6 dofs and 5 contacts, and
any simulator's work grows at least linearly with them.
"""

from __future__ import annotations

import math

import mujoco

BOX_HALF = 0.03  # m, half edge of each box
SPACING = 0.1  # m, grid pitch of the boxes at reset
PUSHER_RADIUS = 0.035  # m
BOX_PARAMS = "default"  # table row of every box (DAMAGE_MODEL.md §5): E 30 N, Λ 0.1


def grid_xy(k: int) -> list[tuple[float, float]]:
  """Reset positions (m) of K boxes on a centred square-ish grid."""
  cols = max(1, math.ceil(math.sqrt(k)))
  rows = math.ceil(k / cols)
  out = []
  for i in range(k):
    r, c = divmod(i, cols)
    out.append(((c - (cols - 1) / 2) * SPACING, (r - (rows - 1) / 2) * SPACING))
  return out


def sweep_radius(k: int) -> float:
  """Radius (m) of the pusher's sweep: reaches the outer boxes of the grid."""
  cols = max(1, math.ceil(math.sqrt(k)))
  return max(0.08, (cols - 1) / 2 * SPACING + 0.02)


JACOBIANS = ("auto", "dense", "sparse")


def table_scene_xml(k: int, timestep: float = 0.004, iterations: int = 4, ls_iterations: int = 8,
                    solver: str = "CG", jacobian: str = "auto", free: int | None = None) -> str:
  """MJCF text of the K-box scene (k >= 1).

  Solver iterations are kept small (MJX's recommendation for throughput); the
  same XML feeds the native-MuJoCo reference, so both solve the same problem.
  ``jacobian`` is MuJoCo's ``<option jacobian>``: with "auto" MJX switches to
  sparse mass matrices from nv >= 60 (K >= 10 here), which its own docs say
  GPUs tend to run slower than dense. ``free``: boxes 0..free−1 get a free
  joint, the rest are mounted (default: all K free).
  """
  if not isinstance(k, int) or isinstance(k, bool) or k < 1:
    raise ValueError(f"k: number of boxes must be an int >= 1, got {k!r}")
  if solver not in ("CG", "Newton"):
    raise ValueError(f"solver: must be 'CG' or 'Newton', got {solver!r}")
  if jacobian not in JACOBIANS:
    raise ValueError(f"jacobian: must be one of {JACOBIANS}, got {jacobian!r}")
  free = k if free is None else free
  if not isinstance(free, int) or isinstance(free, bool) or not 0 <= free <= k:
    raise ValueError(f"free: number of free boxes must be an int in [0, k={k}], got {free!r}")
  boxes = []
  for i, (x, y) in enumerate(grid_xy(k)):
    joint = f'      <freejoint name="box{i}"/>\n' if i < free else ""
    rgba = ".9 .6 .2 1" if i < free else ".4 .5 .7 1"
    boxes.append(
        f'    <body name="box{i}" pos="{x:.4f} {y:.4f} {BOX_HALF:.4f}">\n'
        f"{joint}"
        f'      <geom name="box{i}" type="box" size="{BOX_HALF} {BOX_HALF} {BOX_HALF}" mass="0.2"'
        f' contype="1" conaffinity="2" rgba="{rgba}"/>\n'
        f"    </body>"
    )
  r = sweep_radius(k) + 0.2
  return f"""<mujoco model="bench_table_{k}">
  <option timestep="{timestep}" integrator="implicitfast" solver="{solver}" iterations="{iterations}" ls_iterations="{ls_iterations}" jacobian="{jacobian}"/>
  <default><geom friction="0.8 0.01 0.001"/></default>
  <worldbody>
    <light pos="0 0 2" dir="0 0 -1"/>
    <geom name="table" type="plane" size="2 2 0.1" contype="2" conaffinity="1" rgba=".55 .4 .3 1"/>
    <body name="pusher" pos="0 0 {BOX_HALF:.4f}">
      <joint name="pusher_x" type="slide" axis="1 0 0" range="{-r:.3f} {r:.3f}" damping="5"/>
      <joint name="pusher_y" type="slide" axis="0 1 0" range="{-r:.3f} {r:.3f}" damping="5"/>
      <geom name="pusher" type="sphere" size="{PUSHER_RADIUS}" mass="1.0" contype="2" conaffinity="1" rgba=".2 .2 .2 1"/>
    </body>
{chr(10).join(boxes)}
  </worldbody>
  <actuator>
    <position name="pusher_x" joint="pusher_x" kp="300" ctrlrange="{-r:.3f} {r:.3f}"/>
    <position name="pusher_y" joint="pusher_y" kp="300" ctrlrange="{-r:.3f} {r:.3f}"/>
  </actuator>
</mujoco>
"""


def table_scene(k: int, **kw) -> mujoco.MjModel:
  """The K-box scene as a ``mujoco.MjModel``."""
  return mujoco.MjModel.from_xml_string(table_scene_xml(k, **kw))


def table_config(k: int, tracked: int | None = None) -> dict:
  """Damage config of the K boxes (entity ``box{i}`` = body ``box{i}``).

  ``tracked``: track only boxes 0..tracked−1 (default: all K). The scene stays
  the same, so varying it isolates what tracking costs from what the physics
  of more bodies costs.
  """
  cfg = {"entities": {f"box{i}": {"params": BOX_PARAMS, "bodies": [f"box{i}"]} for i in range(k)}}
  if tracked is not None:
    if not isinstance(tracked, int) or isinstance(tracked, bool) or not 1 <= tracked <= k:
      raise ValueError(f"tracked: must be an int in [1, k={k}], got {tracked!r}")
    cfg["track"] = [f"box{i}" for i in range(tracked)]
  return cfg

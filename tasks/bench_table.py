"""The benchmark scene: K damageable boxes on a table, swept by a pusher, and its env.

``table_scene_xml(k)`` writes the MJCF; ``table_scene(k)`` loads it;
``table_config(k)`` is the damage config tracking the K boxes (one entity, one
link each); :class:`TableEnv` (``table_env(k)``) is the env on it, a small env
with actions that tests and the throughput harness (:mod:`apps.bench`) use;
:func:`pusher_ctrl` is the open-loop sweep the harness drives the pusher with. The scene is designed for throughput, the way a user should design
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
from typing import Optional

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs.base import State
from mujoco import mjx

from mjx_damage.env import DamageEnv

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


CTRL_PERIOD_S = 2.0  # period of the pusher's Lissajous sweep


def pusher_ctrl(t, radius: float, xp=np):
  """Open-loop pusher target (m, f[2]) at time ``t`` (s): a Lissajous figure over the grid."""
  w = 2 * math.pi / CTRL_PERIOD_S
  return xp.stack([radius * xp.sin(w * t), 0.8 * radius * xp.sin(2 * w * t + 0.5)])


class TableEnv(DamageEnv):
  """K boxes on a table and a pusher; action f32[2] ∈ [−1, 1]² = pusher target / sweep radius.

  ``free`` boxes (default all K) have free joints, the rest are mounted
  (:func:`table_scene_xml`); box 0 is always free.

  Success: box 0 pushed more than 5 cm from where it started. Observation
  f32[5]: pusher xy, box 0 xyz (m). Reset jitters every free box by ±1 cm.
  """

  def __init__(self, k: int = 1, n_substeps: int = 5, episode_length: int = 50, solver: str = "CG",
               tracked: Optional[int] = None, jacobian: str = "auto", free: Optional[int] = None):
    free = k if free is None else free
    if not isinstance(free, int) or isinstance(free, bool) or not 1 <= free <= k:
      raise ValueError(f"free: free boxes must be an int in [1, k={k}] (box 0 is observed), got {free!r}")
    super().__init__(table_scene(k, solver=solver, jacobian=jacobian, free=free), table_config(k, tracked),
                     n_substeps)
    self.scene_kwargs = dict(solver=solver, jacobian=jacobian, free=free)  # table_scene_xml's, for other backends
    self.k = k  # boxes in the scene
    self.free = free  # boxes 0..free-1 are free bodies, the rest mounted
    self.tracked = k if tracked is None else tracked  # boxes whose damage is computed
    self.jacobian = jacobian
    self.radius = sweep_radius(k)
    self.episode_length = int(episode_length)
    m = self.mj_model
    self._box_q = np.array([m.jnt_qposadr[m.joint(f"box{i}").id] for i in range(free)])
    self._qpos0 = np.array(m.qpos0, np.float32)

  @property
  def observation_size(self) -> int:
    return 5

  @property
  def action_size(self) -> int:
    return 2

  def initial_qpos(self, rng) -> jax.Array:
    """f32[nq] reset configuration: free boxes on their grid, jittered ±1 cm in x and y."""
    jit = jax.random.uniform(rng, (self.free, 2), minval=-0.01, maxval=0.01)
    q = jnp.asarray(self._qpos0)
    idx = jnp.asarray(self._box_q)
    return q.at[idx].add(jit[:, 0]).at[idx + 1].add(jit[:, 1])

  def reset(self, rng: jax.Array) -> State:
    rng, qr = jax.random.split(rng)
    # no forward pass here: every physics substep starts with one (keeps reset cheap to compile)
    d = mjx.make_data(self.sys).replace(qpos=self.initial_qpos(qr))
    info = {"damage_state": self.init_damage(rng), "box0_start": d.qpos[self._box_q[0] : self._box_q[0] + 2]}
    z = jnp.zeros(())
    return State(d, self._obs(d), z, z, {"success": z}, info)

  def step(self, state: State, action: jax.Array) -> State:
    ctrl = self.radius * jnp.clip(action, -1.0, 1.0)
    d, ds = self.physics_step(state.pipeline_state, state.info["damage_state"], ctrl)
    moved = jnp.linalg.norm(d.qpos[self._box_q[0] : self._box_q[0] + 2] - state.info["box0_start"])
    success = (moved > 0.05).astype(jnp.float32)
    info = dict(state.info, damage_state=ds)
    metrics = dict(state.metrics, success=success)
    return state.replace(pipeline_state=d, obs=self._obs(d), info=info, metrics=metrics)

  def _obs(self, d):
    b = self._box_q[0]
    return jnp.concatenate([d.qpos[:2], d.qpos[b : b + 3]])


def table_env(k: int = 1, n_substeps: int = 5, episode_length: int = 50, solver: str = "CG",
              tracked: Optional[int] = None, jacobian: str = "auto", free: Optional[int] = None):
  """A :class:`TableEnv` (a ``DamageEnv``) on the K-box scene, tracking ``tracked`` (default all) boxes,
  ``free`` (default all) of them free bodies and the rest mounted."""
  return TableEnv(k, n_substeps, episode_length, solver, tracked, jacobian, free)

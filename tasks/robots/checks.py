"""Controller checks on a bare robot scene (the robot + a counter plane, no task, no damage).

Used by ``tests/test_robots.py`` (small sizes) and ``benchmarks/panda_ik.py`` (full sizes):

* :func:`figure_eight` / :func:`track` — follow a 3-D figure-eight with the
  ``[Δx, Δy, Δz, gripper]`` action (proportional step toward the next waypoint)
  and return the grip-point error at every control step;
* :func:`random_actions` — batched random-action rollouts that record, at every
  physics substep, how far any joint is outside its range and whether the state
  stayed finite.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from tasks.robots import robot_class
from tasks.robots.interface import MAX_STEP

_SCENE = """<mujoco model="bare_{name}">
  <option timestep="0.004" integrator="implicitfast" iterations="8" ls_iterations="8"/>
  <include file="robot.xml"/>
  <worldbody>
    <geom name="counter" type="plane" size="1 1 0.05" contype="1" conaffinity="0"/>
  </worldbody>
</mujoco>"""

N_SUBSTEPS = 6  # physics steps per control step (24 ms control period, as the tasks)
CENTRE = (0.0, 0.0, 0.2)  # m, figure-eight centre (0.5 m in front of the Panda's default mount)


def bare_scene(name: str):
  """(mj_model, mjx model, robot) of robot ``name`` alone above a counter plane at z = 0."""
  cls = robot_class(name)
  with open(cls.xml, "rb") as f:
    m = mujoco.MjModel.from_xml_string(_SCENE.format(name=name), {"robot.xml": f.read()})
  if cls.default_mount is not None:
    cls.place(m, cls.default_mount)
  return m, mjx.put_model(m), cls(m, float(m.opt.timestep) * N_SUBSTEPS)


def figure_eight(n_steps: int, dt: float, period: float = 5.0, size=(0.12, 0.08, 0.05), centre=CENTRE):
  """Waypoints f32[n_steps, 3] (m) of a 3-D figure-eight: x = A sin ωt, y = B sin 2ωt, z = C cos ωt."""
  t = np.arange(n_steps) * dt
  w = 2 * np.pi / period
  pts = np.stack([size[0] * np.sin(w * t), size[1] * np.sin(2 * w * t), size[2] * np.cos(w * t)], 1)
  return (pts + np.asarray(centre)).astype(np.float32)


def _control_step(sys, robot, d, a, lo, hi):
  """One control period: targets from ``a``, then N_SUBSTEPS physics steps.
  Returns (d, worst joint-range excess over the substeps f32[], finite bool[])."""
  d = d.replace(ctrl=robot.ctrl(d, a, lo, hi))
  jnt_lo, jnt_hi = sys.jnt_range[:robot.nq, 0], sys.jnt_range[:robot.nq, 1]

  def sub(d, _):
    d = mjx.step(sys, d)
    q = d.qpos[:robot.nq]
    return d, (jnp.max(jnp.maximum(jnt_lo - q, q - jnt_hi)), jnp.all(jnp.isfinite(d.qpos)))

  d, (excess, ok) = jax.lax.scan(sub, d, None, length=N_SUBSTEPS)
  return d, jnp.max(excess), jnp.all(ok)


def _start(sys, robot, pos, gripper_q=0.03):
  d = mjx.make_data(sys)
  qpos = robot.home(d.qpos, jnp.asarray(pos), gripper_q)
  d = d.replace(qpos=qpos, ctrl=robot.hold_ctrl(qpos, sys.nu))
  return mjx.forward(sys, d)


def track(name: str, waypoints):
  """Follow ``waypoints`` f32[T, 3] from waypoint 0: ``(jitted run() -> err f32[T] m, eef f32[T, 3])``.

  The action at step k is ``(waypoint[k+1] − eef) / MAX_STEP`` (clipped to [−1, 1]), the error at
  step k is ``‖eef_k − waypoint_k‖``; gripper held half open.
  """
  m, sys, robot = bare_scene(name)
  wp = jnp.asarray(waypoints)
  lo, hi = robot.workspace(np.full(3, -np.inf), np.full(3, np.inf))
  nxt = jnp.concatenate([wp[1:], wp[-1:]], 0)

  def run():
    d = _start(sys, robot, wp[0])

    def body(d, target):
      e = robot.eef_pos(d)
      a = jnp.concatenate([jnp.clip((target - e) / MAX_STEP, -1, 1), jnp.zeros(robot.action_size - 3)])
      d, _, _ = _control_step(sys, robot, d, a, lo, hi)
      return d, robot.eef_pos(d)

    _, eef = jax.lax.scan(body, d, nxt)
    eef = jnp.concatenate([robot.eef_pos(d)[None], eef[:-1]], 0)
    return jnp.linalg.norm(eef - wp, axis=-1), eef

  return jax.jit(run)


def random_actions(name: str, n_envs: int, n_steps: int, hold: int = 10):
  """``jitted run(rng) -> (worst joint-range excess f32[] rad/m, all finite bool[], final eef f32[n_envs, 3])``.

  Each env starts at a random grip point in the workspace and applies uniform random actions, each held
  for ``hold`` control steps (so the arm is driven into workspace corners and joint limits).
  """
  m, sys, robot = bare_scene(name)
  lo, hi = robot.workspace(np.full(3, -np.inf), np.full(3, np.inf))
  lo = np.maximum(lo, (-np.inf, -np.inf, 0.02)).astype(np.float32)  # grip point targets above the counter

  def episode(rng):
    r0, r1 = jax.random.split(rng)
    start = jax.random.uniform(r0, (3,), minval=jnp.asarray(lo) + 0.1, maxval=jnp.asarray(hi) - 0.1)
    d = _start(sys, robot, start)
    acts = jax.random.uniform(r1, (n_steps // hold + 1, robot.action_size), minval=-1.0, maxval=1.0)
    acts = jnp.repeat(acts, hold, axis=0)[:n_steps]

    def body(c, a):
      d, worst, ok = c
      d, ex, fin = _control_step(sys, robot, d, a, lo, hi)
      return (d, jnp.maximum(worst, ex), ok & fin), None

    (d, worst, ok), _ = jax.lax.scan(body, (d, jnp.asarray(-jnp.inf), jnp.asarray(True)), acts)
    return worst, ok, robot.eef_pos(d)

  def run(rng):
    worst, ok, eef = jax.vmap(episode)(jax.random.split(rng, n_envs))
    return jnp.max(worst), jnp.all(ok), eef

  return jax.jit(run)

"""The floating parallel-jaw gripper (``gripper.xml``): x/y/z slides + two finger slides.

Kinematics: ``qpos[0:3]`` is the world position of the grip point (between the
fingertips, at their lower end), ``qpos[3]``/``qpos[4]`` the left/right finger
half-openings (m, the finger axis' offset from the grip point along ∓y).

Action (``f32[4]`` in [−1, 1]): ``a[0:3]`` — the servo target becomes
``eef + a·MAX_STEP`` (clipped to the task's workspace box), i.e. relative to the
*measured* position like delta-EEF control in robosuite; holding ``a = 0`` holds
position against disturbances only by damping. ``a[3]`` — both fingers' target
half-opening ``Q_MIN + (a+1)/2·(Q_MAX−Q_MIN)`` (−1 closed, +1 open); a grip force
is chosen by how far inside the object the target lies (≤ 16 N per finger).

Damage: the hand and both fingers form entity ``agent`` (paper agent parameters).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import mujoco

from tasks.robots.interface import FINGER_HALF_THICK, MAX_STEP, Robot, sanitize

Q_MIN = 0.007  # m, finger half-opening at gripper = −1 (2 mm gap between the pads)
Q_MAX = 0.086  # m, finger half-opening at gripper = +1 (16 cm gap)
FINGER_LENGTH = 0.07  # m, fingertip (grip point) to the palm's underside


class Gripper(Robot):
  """The floating gripper in one compiled scene."""

  name = "gripper"
  xml = os.path.join(os.path.dirname(__file__), "gripper.xml")
  action_size = 4
  proprio_size = 8
  agent_bodies = ("hand", "finger_left", "finger_right")
  nq = 5
  nu = 5
  finger_length = FINGER_LENGTH

  def __init__(self, m: mujoco.MjModel, control_dt: float):
    names = ["hand_x", "hand_y", "hand_z", "finger_left", "finger_right"]
    qadr = [int(m.jnt_qposadr[m.joint(n).id]) for n in names]
    vadr = [int(m.jnt_dofadr[m.joint(n).id]) for n in names]
    act = [m.actuator(n).id for n in names]
    if qadr != list(range(5)) or vadr != list(range(5)) or act != list(range(5)):
      raise ValueError("scene: robot.xml must be included before any other joint/actuator "
                       f"(got qpos adr {qadr}, dof adr {vadr}, actuators {act})")
    super().__init__(m, control_dt)
    self.hand_body = m.body("hand").id

  def eef_pos(self, d) -> jax.Array:
    return d.qpos[0:3]

  def eef_vel(self, d) -> jax.Array:
    return d.qvel[0:3]

  def finger_q(self, d):
    return d.qpos[3:5], d.qvel[3:5]

  def proprio(self, d) -> jax.Array:
    return jnp.concatenate([
        d.qpos[0:3], d.qvel[0:3],
        2.0 * (0.5 * (d.qpos[3:4] + d.qpos[4:5]) - FINGER_HALF_THICK), d.qvel[3:4] + d.qvel[4:5],
    ])

  def gap(self, d) -> jax.Array:
    return 2.0 * (0.5 * (d.qpos[3] + d.qpos[4]) - FINGER_HALF_THICK)

  def finger_ctrl(self, a) -> jax.Array:
    q = Q_MIN + 0.5 * (a + 1.0) * (Q_MAX - Q_MIN)
    return jnp.stack([q, q])

  def ctrl(self, d, action, lo, hi, extra_ctrl=None) -> jax.Array:
    a = sanitize(action)
    target = jnp.clip(d.qpos[0:3] + a[0:3] * MAX_STEP, lo, hi)
    return self._pad(jnp.concatenate([target, self.finger_ctrl(a[3])]), extra_ctrl)

  def home(self, qpos, pos, q_half=None) -> jax.Array:
    q_half = Q_MAX if q_half is None else q_half
    return qpos.at[0:3].set(pos).at[3:5].set(q_half)

  def hold_ctrl(self, qpos, nu) -> jax.Array:
    return jnp.zeros((nu,)).at[0:5].set(qpos[0:5])

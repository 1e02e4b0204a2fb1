"""The task-suite robot: a floating parallel-jaw gripper (``robot.xml``) and its pure JAX helpers.

Kinematics (see ``robot.xml``): ``qpos[0:3]`` is the world position of the grip
point (between the fingertips, at their lower end), ``qpos[3]``/``qpos[4]`` the
left/right finger half-openings (m, the finger axis' offset from the grip
point along ∓y). Every scene includes ``robot.xml`` first, so these indices are
the same in every task (checked in :class:`Robot`).

Action (per control step, ``f32[4]`` in [−1, 1]):

* ``a[0:3]`` — end-effector position delta: the servo target becomes
  ``eef + a·MAX_STEP`` (clipped to the task's workspace box), i.e. relative to
  the *measured* position like delta-EEF control in robosuite. Holding
  ``a = 0`` holds position against disturbances only by damping; closed-loop
  policies correct the drift.
* ``a[3]`` — gripper: target half-opening ``q = Q_MIN + (a+1)/2·(Q_MAX−Q_MIN)``
  for both fingers (−1 fully closed, +1 fully open). A grip force is therefore
  chosen by how far inside the object the target lies (≤ 16 N per finger).

Damage: the hand and both fingers form entity ``agent`` with the paper's agent
parameters (mechanical α 0.01 β 1 E 70 N Λ 0.2; thermal 40/−20 °C Λ 1; fluid
10 particles Λ 10).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

ROBOT_XML = os.path.join(os.path.dirname(__file__), "robot.xml")

MAX_STEP = 0.02  # m per control step: largest end-effector displacement one action asks for
Q_MIN = 0.007  # m, finger half-opening at gripper = −1 (2 mm gap between the pads)
Q_MAX = 0.086  # m, finger half-opening at gripper = +1 (16 cm gap)
FINGER_HALF_THICK = 0.006  # m, half thickness of a finger pad along y
FINGER_LENGTH = 0.07  # m, fingertip (grip point) to the palm's underside is 0.07 m
ACTION_SIZE = 4
PROPRIO_SIZE = 8  # eef pos (3), eef vel (3), gap (1), gap rate (1)

AGENT_BODIES = ("hand", "finger_left", "finger_right")
AGENT_ENTITY = {"params": "agent", "bodies": list(AGENT_BODIES)}

# Contact class bits used by every scene (see robot.xml).
STATIC, ROBOT, OBJECT = 1, 2, 4


def gap(q_half):
  """Inner gap between the finger pads (m) for a finger half-opening ``q_half`` (m)."""
  return 2.0 * (q_half - FINGER_HALF_THICK)


def gripper_command_for_gap(g):
  """Gripper action in [−1, 1] whose target inner gap is ``g`` m (clipped to the reachable range)."""
  q = g / 2.0 + FINGER_HALF_THICK
  return jnp.clip(2.0 * (q - Q_MIN) / (Q_MAX - Q_MIN) - 1.0, -1.0, 1.0)


class Robot:
  """Static indices of the robot in one compiled scene plus pure helpers over ``mjx.Data``."""

  def __init__(self, m: mujoco.MjModel):
    names = ["hand_x", "hand_y", "hand_z", "finger_left", "finger_right"]
    qadr = [int(m.jnt_qposadr[m.joint(n).id]) for n in names]
    vadr = [int(m.jnt_dofadr[m.joint(n).id]) for n in names]
    act = [m.actuator(n).id for n in names]
    if qadr != list(range(5)) or vadr != list(range(5)) or act != list(range(5)):
      raise ValueError("scene: robot.xml must be included before any other joint/actuator "
                       f"(got qpos adr {qadr}, dof adr {vadr}, actuators {act})")
    self.nu = m.nu
    self.hand_body = m.body("hand").id
    self.finger_geoms = np.array([m.geom("finger_left").id, m.geom("finger_right").id])

  # -- state readers (one env; vmap for a batch) ---------------------------
  @staticmethod
  def eef_pos(d) -> jax.Array:
    """Grip point, world frame, f32[3] m."""
    return d.qpos[0:3]

  @staticmethod
  def eef_vel(d) -> jax.Array:
    """Grip point velocity, f32[3] m/s."""
    return d.qvel[0:3]

  @staticmethod
  def gap(d) -> jax.Array:
    """Inner gap between the fingers, f32[] m (the mean of both fingers' openings)."""
    return gap(0.5 * (d.qpos[3] + d.qpos[4]))

  @staticmethod
  def finger_y(d) -> jax.Array:
    """World y of the left and right finger axes, f32[2] m."""
    return jnp.stack([d.qpos[1] + d.qpos[3], d.qpos[1] - d.qpos[4]])

  @staticmethod
  def proprio(d) -> jax.Array:
    """Proprioception f32[8]: eef pos (m), eef vel (m/s), finger gap (m), gap rate (m/s)."""
    return jnp.concatenate([
        d.qpos[0:3], d.qvel[0:3],
        gap(0.5 * (d.qpos[3:4] + d.qpos[4:5])), d.qvel[3:4] + d.qvel[4:5],
    ])

  # -- control ----------------------------------------------------------------
  def ctrl(self, d, action, lo, hi, extra_ctrl=None) -> jax.Array:
    """Servo targets f32[nu] for ``action`` f32[4] (clipped to [−1, 1]; NaN counts as 0).

    ``lo``/``hi`` f32[3]: the task's workspace box for the grip point (m). ``extra_ctrl``
    supplies any task actuators after the robot's five (none in the built-in tasks).
    """
    a = jnp.clip(jnp.nan_to_num(action), -1.0, 1.0)
    target = jnp.clip(d.qpos[0:3] + a[0:3] * MAX_STEP, lo, hi)
    q = Q_MIN + 0.5 * (a[3] + 1.0) * (Q_MAX - Q_MIN)
    c = jnp.concatenate([target, jnp.stack([q, q])])
    if self.nu > 5:
      c = jnp.concatenate([c, jnp.zeros((self.nu - 5,)) if extra_ctrl is None else extra_ctrl])
    return c

  @staticmethod
  def home(qpos, pos, gripper_q=Q_MAX):
    """``qpos`` with the grip point at ``pos`` f32[3] and both fingers at half-opening ``gripper_q``."""
    return qpos.at[0:3].set(pos).at[3:5].set(gripper_q)

  @staticmethod
  def hold_ctrl(qpos, nu) -> jax.Array:
    """Servo targets that hold the robot where ``qpos`` puts it, f32[nu]."""
    return jnp.zeros((nu,)).at[0:5].set(qpos[0:5])


# -- helpers for scripted policies ------------------------------------------------
def move_toward(eef, target, speed=1.0, gain=1.0):
  """Position-delta action f32[3] moving ``eef`` toward ``target`` (m, f32[3]).

  A proportional step of ``gain``·error / MAX_STEP, each axis limited to
  ``speed`` (fraction of the max step), so the hand decelerates into targets.
  """
  return jnp.clip(gain * (target - eef) / MAX_STEP, -speed, speed)


def action(delta, gripper) -> jax.Array:
  """Assemble an action f32[4] from a position delta f32[3] and a gripper command f32[]."""
  return jnp.concatenate([delta, jnp.reshape(gripper, (1,))]).astype(jnp.float32)

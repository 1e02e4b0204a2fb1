"""Robot helpers as task code uses them: ``from tasks import robot as R``.

The robots themselves live in :mod:`tasks.robots` (one module + MJCF each, the
interface in :mod:`tasks.robots.interface`). This module keeps the names task
code was written against — gripper constants, :func:`gripper_command_for_gap`,
:func:`move_toward`, :func:`action`, and the class-level readers
``R.Robot.eef_pos(d)``, ``R.Robot.gap(d)``, ``R.Robot.home(qpos, pos, q)`` … —
and makes them robot-independent: :class:`Robot`'s static methods call the robot
of the task being traced. :class:`tasks.base.Task` runs every task method
(``sample_init``, ``evaluate``, ``task_obs``, ``policy`` and the policies it
returns, …) inside :func:`active` with its own robot, so the same task code reads
the gripper's slides or the Panda's forward kinematics. Outside any task method
(no robot active) they read the gripper's layout, as before. The selection is
made while JAX traces, so a compiled function is bound to the robot it was
traced with; new code may call ``task.robot`` directly instead.

Gripper commands are robot-independent (target inner gap, ``interface.py``):
``gripper_command_for_gap(g)`` means the same gap on every robot, clipped by each
to its stroke.
"""

from __future__ import annotations

import contextlib
import contextvars

import jax
import jax.numpy as jnp

from tasks.robots import gripper as _gripper
from tasks.robots.interface import FINGER_HALF_THICK, GAP_MAX, GAP_MIN, MAX_STEP

Q_MIN, Q_MAX, FINGER_LENGTH = _gripper.Q_MIN, _gripper.Q_MAX, _gripper.FINGER_LENGTH
ACTION_SIZE = _gripper.Gripper.action_size
PROPRIO_SIZE = _gripper.Gripper.proprio_size
AGENT_BODIES = _gripper.Gripper.agent_bodies
AGENT_ENTITY = _gripper.Gripper.agent_entity()

# Contact class bits used by every scene (see tasks/robots/*.xml).
STATIC, ROBOT, OBJECT = 1, 2, 4

__all__ = ["FINGER_HALF_THICK", "GAP_MAX", "GAP_MIN", "MAX_STEP", "Q_MIN", "Q_MAX", "Robot", "action", "active",
           "gap", "gripper_command_for_gap", "move_toward"]

_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("tasks_robot_active", default=None)


@contextlib.contextmanager
def active(robot):
  """Make ``robot`` (a :class:`tasks.robots.interface.Robot`) the one :class:`Robot` reads, in this block."""
  token = _ACTIVE.set(robot)
  try:
    yield robot
  finally:
    _ACTIVE.reset(token)


def current():
  """The active robot, or None when it has the gripper's layout (or none is active: outside task methods)."""
  r = _ACTIVE.get()
  return None if r is None or isinstance(r, Robot) else r


def gap(q_half):
  """Inner gap between the finger pads (m) for a finger half-opening ``q_half`` (m)."""
  return 2.0 * (q_half - FINGER_HALF_THICK)


def gripper_command_for_gap(g):
  """Gripper action in [−1, 1] whose target inner gap is ``g`` m (clipped to the command range)."""
  q = g / 2.0 + FINGER_HALF_THICK
  return jnp.clip(2.0 * (q - Q_MIN) / (Q_MAX - Q_MIN) - 1.0, -1.0, 1.0)


class Robot(_gripper.Gripper):
  """Readers and setters of the active robot (the gripper's layout when none is active).

  Instances are gripper robots (``Robot(m)``; task-specific gripper variants subclass it and
  override :meth:`ctrl`); the class-level readers below work without an instance.
  """

  def __init__(self, m, control_dt: float = 0.024):
    super().__init__(m, control_dt)

  @staticmethod
  def eef_pos(d) -> jax.Array:
    """Grip point, world frame, f32[3] m."""
    r = current()
    return d.qpos[0:3] if r is None else r.eef_pos(d)

  @staticmethod
  def eef_vel(d) -> jax.Array:
    """Grip point velocity, f32[3] m/s."""
    r = current()
    return d.qvel[0:3] if r is None else r.eef_vel(d)

  @staticmethod
  def gap(d) -> jax.Array:
    """Inner gap between the fingers, f32[] m (the mean of both fingers' openings)."""
    r = current()
    return gap(0.5 * (d.qpos[3] + d.qpos[4])) if r is None else r.gap(d)

  @staticmethod
  def proprio(d) -> jax.Array:
    """Proprioception of the active robot (first 8: eef pos, eef vel, gap, gap rate)."""
    r = current()
    if r is None:
      return jnp.concatenate([d.qpos[0:3], d.qvel[0:3], gap(0.5 * (d.qpos[3:4] + d.qpos[4:5])),
                              d.qvel[3:4] + d.qvel[4:5]])
    return r.proprio(d)

  @staticmethod
  def home(qpos, pos, gripper_q=Q_MAX):
    """``qpos`` with the grip point at ``pos`` f32[3] and both fingers at half-opening ``gripper_q``."""
    r = current()
    if r is None:
      return qpos.at[0:3].set(pos).at[3:5].set(gripper_q)
    return r.home(qpos, pos, gripper_q)


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

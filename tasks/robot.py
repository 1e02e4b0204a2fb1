"""Robot-independent helpers for task code: ``from tasks import robot as R``.

The robots themselves live in :mod:`tasks.robots` (one module + MJCF each, the
interface in :mod:`tasks.robots.interface`); task code reads its robot through
the instance, ``self.robot.eef_pos(d)``, ``self.robot.gap(d)``,
``self.robot.home(qpos, pos, q_half)`` …, and scripted policies close over
``self.robot``. This module keeps what does not depend on the robot: the
action helpers :func:`move_toward` and :func:`action`, the gripper command
:func:`gripper_command_for_gap`, and constants (the floating gripper's finger
range ``Q_MIN``/``Q_MAX`` and agent entity, contact class bits).

Gripper commands are normalised to each robot's command range (``interface.py``), so
task code asks for a gap: ``gripper_command_for_gap(g, self.robot)`` is the command
that means the same ``g`` metres on every robot (clipped to its range).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from tasks.robots import gripper as _gripper
from tasks.robots.interface import FINGER_HALF_THICK, GAP_MAX, GAP_MIN, MAX_STEP, command_for_gap

Q_MIN, Q_MAX, FINGER_LENGTH = _gripper.Q_MIN, _gripper.Q_MAX, _gripper.FINGER_LENGTH
ACTION_SIZE = _gripper.Gripper.action_size
PROPRIO_SIZE = _gripper.Gripper.proprio_size
AGENT_BODIES = _gripper.Gripper.agent_bodies
AGENT_ENTITY = _gripper.Gripper.agent_entity()

# Contact class bits used by every scene (see tasks/robots/*.xml).
STATIC, ROBOT, OBJECT = 1, 2, 4

__all__ = ["FINGER_HALF_THICK", "GAP_MAX", "GAP_MIN", "MAX_STEP", "Q_MIN", "Q_MAX", "action", "gap",
           "gripper_command_for_gap", "move_toward", "squeeze_command"]


def gap(q_half):
  """Inner gap between the finger pads (m) for a finger half-opening ``q_half`` (m)."""
  return 2.0 * (q_half - FINGER_HALF_THICK)


def gripper_command_for_gap(g, robot):
  """Gripper action in [−1, 1] whose target inner gap is ``g`` m on ``robot`` (a
  :class:`tasks.robots.interface.Robot` class or instance; clipped to its command range)."""
  return command_for_gap(g, robot.gap_range)


def squeeze_command(half_width, robot, inside=0.03):
  """Gripper command closing ``robot``'s fingers on an object of half width ``half_width`` (m): target
  ``inside`` m inside each side. The default 3 cm squeezes ≈ 12 N per finger, below the servos' 16 N cap,
  so the finger springs keep the object centred (with both fingers saturated it would drift across the
  grip)."""
  return float(gripper_command_for_gap(2 * half_width - 2 * inside, robot))


# -- helpers for scripted policies ------------------------------------------------
def grip_height_clearing_palm(grip, top, finger_length, clearance=0.005):
  """Grip-point height (m, any common origin) for grasping an object whose top is at ``top``.

  ``grip`` where fingers of ``finger_length`` (grip point to palm underside) already keep the palm above
  the top from there; otherwise the grip point rises until the palm is ``clearance`` above the top (the
  Panda's 5.5 cm fingers on tall objects; the gripper's 7 cm clear them)."""
  if finger_length < top - grip:
    return top + clearance - finger_length
  return grip


def move_toward(eef, target, speed=1.0, gain=1.0):
  """Position-delta action f32[3] moving ``eef`` toward ``target`` (m, f32[3]).

  A proportional step of ``gain``·error / MAX_STEP, each axis limited to
  ``speed`` (fraction of the max step), so the hand decelerates into targets.
  """
  return jnp.clip(gain * (target - eef) / MAX_STEP, -speed, speed)


def approach_from_behind(eef, grasp, obj_x, over_z, pre_grasp=0.07):
  """Grip-point target f32[3] and "close now" flag for a hand pointing along +x (tasks.robots.panda
  .PandaForward) taking an object from behind: over it at ``over_z`` if the hand is not behind it, then
  ``pre_grasp`` behind the object's centre ``obj_x`` at the grasp's height and line, then straight in
  to ``grasp`` f32[3] (m), closing within 4 mm of it."""
  aligned = (jnp.abs(eef[1] - grasp[1]) < 0.006) & (jnp.abs(eef[2] - grasp[2]) < 0.006)
  behind = eef[0] < obj_x - pre_grasp + 0.005
  advancing = aligned & (eef[0] < grasp[0] + 0.004)
  pre = jnp.stack([obj_x - pre_grasp, grasp[1], grasp[2]])
  over = jnp.stack([obj_x - pre_grasp, eef[1], jnp.asarray(over_z, eef.dtype)])
  target = jnp.where(advancing, grasp, jnp.where(behind, pre, over))
  return target, aligned & (jnp.abs(eef[0] - grasp[0]) < 0.004)


def action(delta, gripper) -> jax.Array:
  """Assemble an action f32[4] from a position delta f32[3] and a gripper command f32[]."""
  return jnp.concatenate([delta, jnp.reshape(gripper, (1,))]).astype(jnp.float32)


def accel_limited_step(eef, vel, target, vmax, accel, dt, hand_speed):
  """Position-delta action f32[3] for a gentle carry of ``eef`` to ``target`` (m): speed along the line
  ramped by ``accel``·dt per step (m/s²), braking as √(2·accel·distance), capped at ``vmax`` (m/s).

  Commands twice the planned speed minus the measured one (``vel``, m/s), which makes up for the
  servo's lag within a control step; ``hand_speed`` (m/s) is the speed of a full action. Within
  3 mm it switches to a slow proportional approach.
  """
  delta = target - eef
  dist = jnp.linalg.norm(delta)
  dirn = delta / jnp.maximum(dist, 1e-6)
  v_along = jnp.dot(vel, dirn)
  ramp = jnp.maximum(v_along, 0.0) + accel * dt
  v_des = jnp.minimum(jnp.minimum(vmax, jnp.sqrt(2.0 * accel * dist)), ramp)
  a = dirn * jnp.clip((2.0 * v_des - v_along) / hand_speed, 0.0, 1.0)
  return jnp.where(dist < 0.003, move_toward(eef, target, speed=0.05, gain=0.5), a)


def full_action_speed(m, robot) -> float:
  """Steady grip-point speed (m/s) of a full action, what :func:`accel_limited_step` calls ``hand_speed``.

  The floating gripper: its servo's target is MAX_STEP·a ahead of the measured grip point and the hand
  closes on it during the step, so v = kp·MAX_STEP / (kv + kp·dt/2) from the x slide's gains in ``m``.
  An arm covers a commanded step in about ``episode_scale`` control steps (:mod:`tasks.robots`).
  """
  dt = robot.control_dt
  if isinstance(robot, _gripper.Gripper):
    kp = float(m.actuator_gainprm[m.actuator("hand_x").id, 0])
    kv = -float(m.actuator_biasprm[m.actuator("hand_x").id, 2])
    return kp * MAX_STEP / (kv + 0.5 * kp * dt)
  return MAX_STEP / dt / type(robot).episode_scale


def set_down_radius(robot) -> float:
  """How close (m, xy) a carry's grip point comes to the goal before the set-down starts.

  5 mm for the floating gripper. An arm's hand wanders a few mm in xy under the IK's posture pull
  (tasks.robots.panda.dls_step): within 5 mm the policy flipped between carrying and setting down,
  jerking prepare_breakfast's tray until the plate slid off. The set-down heads for the goal itself,
  so with 2 cm it corrects the rest on the way down.
  """
  return 0.005 if isinstance(robot, _gripper.Gripper) else 0.02

"""What a task needs from a robot: the interface every robot of the suite implements.

A robot is one module + one MJCF here. A task scene includes ``robot.xml`` first
(``<include file="robot.xml"/>``); :class:`tasks.base.Task` resolves that name to
the chosen robot's MJCF, so the robot's joints come first in ``qpos``/``qvel`` and
its actuators first in ``ctrl``. Two conventions hold for every robot, so task code
written against the floating gripper keeps meaning the same thing:

* the **grip point** is the point between the fingertips at their lower end;
* **actuators 3 and 4** are the left/right finger servos and their targets are
  *finger half-openings* (m): the pad centre's offset from the grip point along
  the finger axis (pads 12 mm thick, so inner gap = 2·(q − 0.006)).

Action (``f32[action_size]`` in [−1, 1], NaN counts as 0): ``a[0:3]`` moves the
grip-point target by ``a·MAX_STEP`` from the *measured* grip point (clipped to the
workspace box); the last entry is the gripper command, normalised to the robot's own
command range ``gap_range = (lo, hi)``: target inner gap ``lo + (a+1)/2·(hi − lo)``
(the gripper's 2 mm–16 cm; the Panda hand's 2 mm–8 cm). So −1 is closed and +1 fully
open on every robot, and the zero action is the middle of the robot's stroke (8.1 cm
on the gripper, 4.1 cm on the Panda): a policy that does nothing keeps a grasped object
of either robot's task variant squeezed, instead of opening the Panda's narrower hand
around it. Task code asks for a gap in metres (:func:`tasks.robot.gripper_command_for_gap`
with the robot), never for a raw command, so a scripted grasp means the same gap on
every robot. A robot with a wrist adds ``a[3:6]`` (rotation vector of the
hand-orientation change, ×MAX_ROT rad).
"""

from __future__ import annotations

import abc
from typing import ClassVar

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

MAX_STEP = 0.02  # m per control step: largest grip-point displacement one action asks for
FINGER_HALF_THICK = 0.006  # m, half thickness of a finger pad (both robots)
GAP_MIN, GAP_MAX = 0.002, 0.16  # m, the floating gripper's target inner gap at command −1 / +1
FINGER_ACTUATORS = (3, 4)  # ctrl indices of the left/right finger servos on every robot


def command_gap(a, gap_range=(GAP_MIN, GAP_MAX)):
  """Target inner gap (m) for gripper command ``a`` in [−1, 1] on a robot whose command range is
  ``gap_range`` = (gap at −1, gap at +1) m."""
  lo, hi = gap_range
  return lo + 0.5 * (a + 1.0) * (hi - lo)


def command_for_gap(g, gap_range=(GAP_MIN, GAP_MAX)):
  """Gripper command in [−1, 1] whose target inner gap is ``g`` m (clipped to the range); the inverse
  of :func:`command_gap`."""
  lo, hi = gap_range
  return jnp.clip(2.0 * (g - lo) / (hi - lo) - 1.0, -1.0, 1.0)


def half_opening(gap):
  """Finger half-opening (pad centre offset, m) for an inner gap ``gap`` (m)."""
  return 0.5 * gap + FINGER_HALF_THICK


def sanitize(action):
  """Action clipped to [−1, 1] with NaN read as 0 (a policy bug must not become a NaN state)."""
  return jnp.clip(jnp.nan_to_num(action), -1.0, 1.0)


class Robot(abc.ABC):
  """One robot in one compiled scene: static indices + pure functions of ``mjx.Data``.

  Args:
    m: the compiled scene (robot included first).
    control_dt: control period (s) — the controller's rate limits are per step.
  """

  name: ClassVar[str] = ""
  xml: ClassVar[str] = ""  # path of the robot's MJCF
  action_size: ClassVar[int] = 4
  proprio_size: ClassVar[int] = 8
  agent_bodies: ClassVar[tuple[str, ...]] = ()
  nq: ClassVar[int] = 0  # robot qpos entries (first in the scene)
  nu: ClassVar[int] = 0  # robot actuators (first in the scene)
  default_mount: ClassVar[tuple | None] = None  # fixed-base arms: base (x, y, z, yaw) unless the task says
  finger_length: ClassVar[float] = 0.0  # m, grip point (fingertips) to the palm's underside
  episode_scale: ClassVar[float] = 1.0  # tasks' default episode lengths × this (slower robots get longer)
  gap_range: ClassVar[tuple[float, float]] = (GAP_MIN, GAP_MAX)  # m, target gap at gripper command −1 / +1

  def __init__(self, m: mujoco.MjModel, control_dt: float):
    self.scene_nu = int(m.nu)
    self.control_dt = float(control_dt)
    self.finger_range = (float(m.jnt_range[m.actuator_trnid[FINGER_ACTUATORS[0], 0], 0]),
                         float(m.jnt_range[m.actuator_trnid[FINGER_ACTUATORS[0], 0], 1]))

  @classmethod
  def agent_entity(cls) -> dict:
    """Damage-config entity ``agent``: every robot body, the paper's agent parameters."""
    return {"params": "agent", "bodies": list(cls.agent_bodies)}

  @classmethod
  def place(cls, m: mujoco.MjModel, mount) -> None:
    """Move the robot's base to ``mount`` = (x, y, z, yaw) in the compiled model (fixed-base robots)."""

  def workspace(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The grip-point box f32[3], f32[3] (m) the controller accepts: the task's box ∩ the robot's reach."""
    return np.asarray(lo, np.float32), np.asarray(hi, np.float32)

  # -- state readers (one env; vmap for a batch) -----------------------------------
  @abc.abstractmethod
  def eef_pos(self, d) -> jax.Array:
    """Grip point, world frame, f32[3] m."""

  @abc.abstractmethod
  def eef_vel(self, d) -> jax.Array:
    """Grip-point velocity, world frame, f32[3] m/s."""

  @abc.abstractmethod
  def finger_q(self, d) -> jax.Array:
    """Left/right finger half-openings f32[2] m, their rates f32[2] m/s."""

  def gap(self, d) -> jax.Array:
    """Inner gap between the finger pads, f32[] m (mean of both fingers' openings)."""
    q, _ = self.finger_q(d)
    return 2.0 * (0.5 * (q[0] + q[1]) - FINGER_HALF_THICK)

  def proprio(self, d) -> jax.Array:
    """Proprioception f32[proprio_size]; the first 8 are the same on every robot:
    grip point (m), its velocity (m/s), finger gap (m), gap rate (m/s)."""
    q, qd = self.finger_q(d)
    g = 2.0 * (0.5 * (q[0:1] + q[1:2]) - FINGER_HALF_THICK)
    return jnp.concatenate([self.eef_pos(d), self.eef_vel(d), g, qd[0:1] + qd[1:2]])

  # -- control ----------------------------------------------------------------------
  @abc.abstractmethod
  def ctrl(self, d, action, lo, hi, extra_ctrl=None) -> jax.Array:
    """Actuator targets f32[scene_nu] for ``action``; ``lo``/``hi`` the workspace box (m).
    ``extra_ctrl`` supplies task actuators after the robot's own (zeros if None)."""

  @abc.abstractmethod
  def home(self, qpos, pos, q_half=None) -> jax.Array:
    """``qpos`` with the grip point at ``pos`` f32[3] (m), both fingers at half-opening ``q_half`` (m;
    None: fully open, the robot's widest commanded opening)."""

  @abc.abstractmethod
  def hold_ctrl(self, qpos, nu) -> jax.Array:
    """Actuator targets f32[nu] that hold the robot where ``qpos`` puts it."""

  def finger_ctrl(self, a) -> jax.Array:
    """Both finger targets f32[2] (half-openings, m) for gripper command ``a``, within the stroke."""
    q = jnp.clip(half_opening(command_gap(a, self.gap_range)), self.finger_range[0], self.finger_range[1])
    return jnp.stack([q, q])

  def _pad(self, c, extra_ctrl):
    """Append the task's actuators (after the robot's ``nu``) to robot targets ``c``."""
    n = self.scene_nu - self.nu
    if n == 0:
      return c
    return jnp.concatenate([c, jnp.zeros((n,)) if extra_ctrl is None else extra_ctrl])

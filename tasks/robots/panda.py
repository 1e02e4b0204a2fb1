"""Franka Emika Panda on a fixed base (``panda.xml``) with a differential-IK controller.

Joints: ``qpos[0:7]`` the arm (``panda_joint1..7``), ``qpos[7:9]`` the finger
half-openings (pad centre offset, 0.006–0.046 m: 0–8 cm between the pads).
Actuators: position servos ``[j1, j2, j3, finger_l, finger_r, j4, j5, j6, j7]``
(fingers at ctrl[3:5], the suite's convention — see ``interface.py``).

Control, once per control step inside the jitted step (:meth:`Panda.ctrl`):

1. forward kinematics of the arm in pure JAX from the same modified-DH table the
   MJCF is written from (:func:`fk`: grip point, hand rotation, geometric
   Jacobian f32[6, 7]); no MuJoCo call, so it costs a few hundred flops;
2. task error ``e = [target − p; w·rot_err(R, R_des)]`` with the position target
   ``p + a[0:3]·MAX_STEP`` (clipped to the workspace) and the hand orientation
   held at ``R_des`` = pointing down, fingers along world y (the gripper's
   finger axis) — or, for :class:`PandaWrist`, turned by ``a[3:6]·MAX_ROT``;
3. damped least squares ``Δq = Jᵀ(JJᵀ + λ²I)⁻¹e`` plus a nullspace pull toward
   the ready posture ``(I − J⁺J)·k·(q_ready − q)`` (elbow up, away from limits);
4. ``Δq`` scaled down uniformly so no joint exceeds its rated velocity over the
   control period, then ``q + Δq`` clipped to the joint range minus a margin;
5. ``q + Δq`` goes to the joint position servos (gains in ``panda.xml``), which run
   at the physics rate; gravity compensation goes through the actuators so the
   real torque limits (87 / 12 N·m) bound servo + gravity torque together.

Damage: every arm link, the hand and both fingers are links of entity ``agent``.

Mobile base (navigation tasks): :func:`add_mobile_base` turns ``panda_link0`` into a
low omnidirectional platform on planar joints ``panda_base_x/y/yaw`` (first in
``qpos``, so the arm follows at ``qpos[3:10]``, the fingers at ``qpos[10:12]``; the
base's servos are actuators 9–11). :class:`Panda` finds the joints in the compiled
model and then drives the base too: each control step the base's target is the new
grip-point target minus ``MOBILE_REACH`` along its heading (the heading is held), at
most ``BASE_SPEED``, and the arm's IK solves for the grip-point target from where the
base is sent, so the base does the travel and the arm the height and what the base
has not yet covered.

Carrying a welded object (prepare_breakfast's tray, move_glass_of_water's glass):
:func:`weld_to_hand` re-attaches the scene's holder weld to ``panda_hand`` at the
grip point, and :class:`PandaHolding` keeps the fingers on the object and gives the
posture projector its own damping (``null_damping``).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from tasks.robots.interface import MAX_STEP, Robot, sanitize

# Franka's modified-DH table (a m, d m, α rad) for joints 1–7; panda.xml is written from it.
DH = np.array([
    [0.0, 0.333, 0.0],
    [0.0, 0.0, -np.pi / 2],
    [0.0, 0.316, np.pi / 2],
    [0.0825, 0.0, np.pi / 2],
    [-0.0825, 0.384, -np.pi / 2],
    [0.0, 0.0, np.pi / 2],
    [0.088, 0.0, np.pi / 2],
])
FLANGE_D = 0.107  # m, joint-7 frame to flange
HAND_YAW = -np.pi / 4  # rad, Franka Hand mounting rotation about the flange axis
GRIP_OFFSET = 0.1134  # m, flange to the fingertips' lower end (grip point), panda.xml site panda_grip
FINGER_LENGTH = GRIP_OFFSET - 0.058  # m, grip point to the palm's underside (hand box bottom 0.058 from the flange)
Q_LO = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_HI = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
V_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])  # rad/s, rated joint velocity
Q_READY = np.array([0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4])
R_DOWN = np.diag([1.0, -1.0, -1.0])  # hand z down, hand y (finger axis) along world y
# hand z (approach) along world +x, hand y (finger axis) along world y, hand x down (PandaForward)
R_FORWARD = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])

DEFAULT_MOUNT = (-0.5, 0.0, 0.0, 0.0)  # base x, y, z (m), yaw (rad): 0.5 m behind the task origin
# Beside the work area, facing it (yaw 90°), for tasks whose objects lie near x ≈ −0.25 m at counter height:
# 0.25–0.3 m in front of DEFAULT_MOUNT, too close for the hand to reach down to (it stalls folded).
SIDE_MOUNT = (-0.05, -0.45, 0.0, 1.5707963)
REACH_BOX = ((0.22, -0.55, -0.05), (0.80, 0.55, 0.70))  # m, base frame: grip-point targets accepted
LIMIT_MARGIN = 0.02  # rad, joint targets stay this far inside the range (servo overshoot room)
DAMPING = 0.05  # DLS damping λ (m): keeps Δq bounded near singularities (stretched arm)
ROT_WEIGHT = 0.5  # m/rad: 1 rad of orientation error weighs like 0.5 m of position error
NULL_GAIN = 0.1  # fraction of the posture error removed per control step, in the nullspace
NULL_DAMPING = 0.005  # m, the posture projector's own damping where a robot class asks for it (PandaHolding)
MAX_ROT = 0.1  # rad per control step for the wrist action (PandaWrist)
IK_ITERS = 60  # DLS iterations of the reset-time IK (converges to < 0.1 mm in the workspace)

BASE_JOINTS = ("panda_base_x", "panda_base_y", "panda_base_yaw")
BASE_ACTUATORS = BASE_JOINTS
BASE_HALF = (0.16, 0.15, 0.05)  # m, the platform box's half sizes (32 × 30 cm, 10 cm tall)
BASE_TOP = 0.12  # m, platform top above the floor = link0's height (2 cm ground clearance)
LINK0_AHEAD = 0.08  # m, link0 ahead of the platform's centre
MOBILE_REACH = 0.6  # m, link0 to grip point along the heading, in the base's plane (the arm half stretched)
MOBILE_REACH_Z = (-0.15, 0.5)  # m, grip-point heights the mobile arm accepts, relative to link0
BASE_SPEED = 1.0  # m/s, the platform's top speed (the hand's is MAX_STEP per control step, ≈ 0.83 m/s)
BASE_MASS = 15.0  # kg
# Base servos, the arm's convention (kp ≈ 83²·M, kv = 0.024·kp) for the platform + arm (≈ 33 kg;
# yaw ≈ 2 kg·m² with the arm half stretched); force limits of a small electric base.
BASE_KP, BASE_KV, BASE_FORCE = 2.3e5, 5.5e3, 600.0  # N/m, N·s/m, N
YAW_KP, YAW_KV, YAW_TORQUE = 1.4e4, 330.0, 150.0  # N·m/rad, N·m·s/rad, N·m

ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_left", "panda_finger_right")
ACTUATORS = ARM_JOINTS[:3] + FINGER_JOINTS + ARM_JOINTS[3:]
_ARM_CTRL = np.array([0, 1, 2, 5, 6, 7, 8])  # ctrl index of joint i


def _rot_x(a):
  c, s = np.cos(a), np.sin(a)
  return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_z(a):
  c, s = jnp.cos(a), jnp.sin(a)
  z, o = jnp.zeros_like(a), jnp.ones_like(a)
  return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


# per joint: body offset in the parent frame and the fixed rotation RotX(α) before the hinge
_POS = np.stack([[a, 0.0, 0.0] + _rot_x(al) @ np.array([0.0, 0.0, d]) for a, d, al in DH]).astype(np.float32)
_RX = np.stack([_rot_x(al) for _, _, al in DH]).astype(np.float32)


def fk(q, base_pos, base_rot):
  """Forward kinematics of the arm.

  Args:
    q: f32[7] joint angles (rad); base_pos f32[3] (m), base_rot f32[3, 3]: link0 pose in the world.
  Returns:
    (p f32[3] grip point m, R f32[3, 3] hand rotation, J f32[6, 7] geometric Jacobian of the grip
    point: rows 0–2 linear m/rad, rows 3–5 angular, world frame).
  """
  q = jnp.asarray(q)  # a native MjData's f64 qpos: JAX's own float width, not a per-constant f64 request

  def joint(carry, x):
    p, r = carry
    pos, rx, qi = x
    p = p + r @ pos
    r = r @ rx @ _rot_z(qi)
    return (p, r), (p, r[:, 2])

  (p, r), (origins, axes) = jax.lax.scan(joint, (base_pos, base_rot), (_POS, _RX, q), unroll=True)
  r = r @ _rot_z(jnp.asarray(HAND_YAW, q.dtype))
  p = p + r[:, 2] * (FLANGE_D + GRIP_OFFSET)
  jp = jnp.cross(axes, p - origins)  # f32[7, 3]
  return p, r, jnp.concatenate([jp.T, axes.T], axis=0)


def rot_err(r, r_des):
  """Orientation error f32[3] (axis·sin θ, world frame) turning ``r`` toward ``r_des`` (both f32[3, 3])."""
  return 0.5 * jnp.sum(jnp.cross(r.T, r_des.T), axis=0)


def _spd_solve(a, b):
  """Solve ``a x = b`` for SPD ``a`` f32[n, n], ``b`` f32[n, k] by an unrolled Cholesky factorisation.

  n is 6 here; a hand-written factorisation keeps LAPACK out of the batched step (elementwise ops
  vectorise over environments on any backend).
  """
  n = a.shape[0]
  lo = [[None] * n for _ in range(n)]
  for i in range(n):
    for j in range(i + 1):
      s = a[i, j] - sum(lo[i][k] * lo[j][k] for k in range(j))
      lo[i][j] = jnp.sqrt(jnp.maximum(s, 1e-12)) if i == j else s / lo[j][j]
  y = []
  for i in range(n):
    y.append((b[i] - sum(lo[i][k] * y[k] for k in range(i))) / lo[i][i])
  x = [None] * n
  for i in reversed(range(n)):
    x[i] = (y[i] - sum(lo[k][i] * x[k] for k in range(i + 1, n))) / lo[i][i]
  return jnp.stack(x)


def dls_step(q, jac, err, q_posture, null_gain, damping=DAMPING, null_damping=None):
  """Damped-least-squares joint step f32[7] for task error ``err`` f32[6] plus a nullspace posture pull.

  The projector ``I − Jᵀ(JJᵀ + λ²I)⁻¹J`` shares the task step's damping λ, so a fraction λ²/(σ² + λ²)
  of the posture pull reaches the hand (σ a singular value of J): under a zero action the hand creeps
  toward wherever the ready posture puts it, ≈ 0.7 mm per control step in Place Plate's in-hand
  start. A projector with its own small damping stops that, but it changes how the arm moves in
  contact (open_drawer's safe pull then broke the drawer, place_plate's safe placement lost 44 % of
  its safe completions), so every Panda scripted policy would need retuning with it. ``null_damping``
  μ (m; None: λ) gives the projector that damping of its own — used where a task's policies were
  written with it (:class:`PandaHolding`)."""
  eye = jnp.eye(6, dtype=jac.dtype)
  a = jac @ jac.T + damping**2 * eye
  x = _spd_solve(a, jnp.concatenate([err[:, None], jac], axis=1))  # [A⁻¹e, A⁻¹J]
  dq = jac.T @ x[:, 0]
  proj = x[:, 1:] if null_damping is None else _spd_solve(jac @ jac.T + null_damping**2 * eye, jac)
  null = jnp.eye(7, dtype=jac.dtype) - jac.T @ proj
  return dq + null @ (null_gain * (q_posture - q))


class Panda(Robot):
  """The Panda in one compiled scene; ``action = [Δx, Δy, Δz, gripper]``."""

  name = "panda"
  xml = os.path.join(os.path.dirname(__file__), "panda.xml")
  action_size = 4
  proprio_size = 15  # the common 8 + arm joint positions normalised to [−1, 1] (7)
  agent_bodies = (tuple(f"panda_link{i}" for i in range(0, 8)) + ("panda_hand",)
                  + FINGER_JOINTS)
  nq = 9
  nu = 9
  finger_length = FINGER_LENGTH
  # At full action the hand covers only about half of the commanded 2 cm per control step in long moves
  # (joint servos lag their IK targets; the gripper's slides cover nearly all of it), so tasks' default
  # episodes are twice as long with the Panda.
  episode_scale = 2.0
  # Gripper command normalised to the hand's 8 cm stroke (−1 closed at the gripper's 2 mm, +1 fully open):
  # the zero action is 4.1 cm, which still squeezes the Panda variants' 6 cm plate and box; mapped to the
  # gripper's 16 cm range it was 8.1 cm, so a policy that did nothing opened the hand and dropped them.
  gap_range = (0.002, 0.08)
  default_mount = DEFAULT_MOUNT
  null_damping = None  # the posture projector's own damping μ (dls_step); None: the task step's λ

  def __init__(self, m: mujoco.MjModel, control_dt: float):
    names = [m.joint(j).name for j in range(m.njnt)]
    self.mobile = all(n in names for n in BASE_JOINTS)  # add_mobile_base ran on the scene
    self.qa = 3 if self.mobile else 0  # qpos/qvel address of panda_joint1
    self.nq = self.nu = 9 + self.qa
    self.proprio_size = 15 + self.qa  # the mobile base adds its x, y (m) and yaw (rad)
    joints = (BASE_JOINTS if self.mobile else ()) + ARM_JOINTS + FINGER_JOINTS
    qadr = [int(m.jnt_qposadr[m.joint(n).id]) for n in joints]
    vadr = [int(m.jnt_dofadr[m.joint(n).id]) for n in joints]
    act = [m.actuator(n).id for n in ACTUATORS + (BASE_ACTUATORS if self.mobile else ())]
    if qadr != list(range(self.nq)) or vadr != list(range(self.nq)) or act != list(range(self.nu)):
      raise ValueError("scene: robot.xml must be included before any other joint/actuator "
                       f"(got qpos adr {qadr}, dof adr {vadr}, actuators {act})")
    rng = np.array([m.jnt_range[m.joint(n).id] for n in ARM_JOINTS])
    if not np.allclose(rng, np.stack([Q_LO, Q_HI], 1), atol=1e-5):
      raise ValueError(f"scene: panda joint ranges {rng.tolist()} differ from the controller's")
    super().__init__(m, control_dt)
    b = m.body("panda_link0").id
    self.base_pos = np.asarray(m.body_pos[b], np.float32)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, m.body_quat[b])
    self.base_rot = rot.reshape(3, 3).astype(np.float32)
    self.r_des = R_DOWN.astype(np.float32)
    self.dq_max = (V_MAX * self.control_dt).astype(np.float32)  # rad per control step
    self.q_lo = (Q_LO + LIMIT_MARGIN).astype(np.float32)
    self.q_hi = (Q_HI - LIMIT_MARGIN).astype(np.float32)
    self.base_step = np.float32(BASE_SPEED * self.control_dt)  # m per control step
    if self.mobile:  # no policies were written with the shared projector's creep here (dls_step)
      self.null_damping = NULL_DAMPING

  @classmethod
  def place(cls, m: mujoco.MjModel, mount) -> None:
    x, y, z, yaw = (float(v) for v in mount)
    b = m.body("panda_link0").id
    m.body_pos[b] = (x, y, z)
    m.body_quat[b] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))

  def workspace(self, lo, hi):
    if self.mobile:  # the base drives anywhere on the floor: only the arm's heights bound the box
      z = self.base_pos[2] + np.asarray(MOBILE_REACH_Z)
      lo, hi = np.array(lo, np.float32), np.array(hi, np.float32)
      lo[2], hi[2] = max(lo[2], z[0]), min(hi[2], z[1])
      if lo[2] > hi[2]:
        raise ValueError(f"workspace: the task's heights do not meet the mobile panda's reach {z}")
      return lo, hi
    corners = np.array(np.meshgrid(*zip(*REACH_BOX), indexing="ij")).reshape(3, -1).T
    world = corners @ self.base_rot.T + self.base_pos
    rlo, rhi = world.min(0), world.max(0)
    lo, hi = np.maximum(np.asarray(lo), rlo), np.minimum(np.asarray(hi), rhi)
    if np.any(lo > hi):
      raise ValueError(f"workspace: the task's box does not meet the panda's reach {rlo}–{rhi}")
    return lo.astype(np.float32), hi.astype(np.float32)

  # -- state readers ------------------------------------------------------------------
  def base_pose(self, qpos):
    """link0's world pose (pos f32[3] m, rot f32[3, 3]): the mount, moved by the base joints if mobile."""
    if not self.mobile:
      return jnp.asarray(self.base_pos), jnp.asarray(self.base_rot)
    b = qpos[0:3]
    rot = jnp.asarray(self.base_rot)
    return rot @ jnp.stack([b[0], b[1], 0.0 * b[0]]) + self.base_pos, rot @ _rot_z(b[2])

  def kinematics(self, q, base=None):
    """(grip point f32[3], hand rotation f32[3, 3], Jacobian f32[6, 7]) at arm angles ``q`` f32[7], with
    link0 at ``base`` = (pos, rot) (default: the mount)."""
    return fk(q, *((self.base_pos, self.base_rot) if base is None else base))

  def _fk(self, qpos):
    return self.kinematics(qpos[self.qa:self.qa + 7], self.base_pose(qpos))

  def eef_pos(self, d) -> jax.Array:
    return self._fk(d.qpos)[0]

  def eef_vel(self, d) -> jax.Array:
    base = self.base_pose(d.qpos)
    p, _, jac = self.kinematics(d.qpos[self.qa:self.qa + 7], base)
    v = jac[0:3] @ d.qvel[self.qa:self.qa + 7]
    if self.mobile:  # + the platform's translation and its turn about the vertical
      w = d.qvel[0:3]
      v = v + jnp.asarray(self.base_rot) @ jnp.stack([w[0], w[1], 0.0 * w[0]])
      v = v + jnp.cross(jnp.stack([0.0 * w[2], 0.0 * w[2], w[2]]), p - base[0])
    return v

  def hand_rot(self, d) -> jax.Array:
    """Hand rotation f32[3, 3] (columns: hand x, finger axis, approach direction)."""
    return self._fk(d.qpos)[1]

  def finger_q(self, d):
    return d.qpos[self.qa + 7:self.qa + 9], d.qvel[self.qa + 7:self.qa + 9]

  def proprio(self, d) -> jax.Array:
    q = d.qpos[self.qa:self.qa + 7]
    qn = (2.0 * q - (Q_HI + Q_LO)) / (Q_HI - Q_LO)
    return jnp.concatenate([super().proprio(d), qn.astype(q.dtype), d.qpos[0:self.qa]])

  # -- control ----------------------------------------------------------------------------
  def _r_target(self, r, a):
    return jnp.asarray(self.r_des)

  def _floor(self, r, lo):
    """The grip-point box's lower corner f32[3] for hand rotation ``r``: ``lo`` itself (the fingertips
    are the lowest point of a hand held at ``r_des``)."""
    return lo

  def arm_targets(self, q, a, lo, hi, base=None, target=None):
    """Joint position targets f32[7] for arm angles ``q`` f32[7] and sanitized action ``a``; ``base``
    (link0's pose the arm is solved from; default the mount) and ``target`` (grip-point target f32[3];
    default the grip point moved by the action) for the mobile base."""
    q = jnp.asarray(q)  # as fk: its own constants below are built at q's dtype
    p, r, jac = self.kinematics(q, base)
    dp = (jnp.clip(p + a[0:3] * MAX_STEP, self._floor(r, lo), hi) if target is None else target) - p
    err = jnp.concatenate([dp, ROT_WEIGHT * rot_err(r, self._r_target(r, a))])
    jw = jac.at[3:].multiply(ROT_WEIGHT)
    dq = dls_step(q, jw, err, jnp.asarray(Q_READY, q.dtype), NULL_GAIN, null_damping=self.null_damping)
    scale = jnp.min(jnp.minimum(1.0, self.dq_max / jnp.maximum(jnp.abs(dq), 1e-9)))
    return jnp.clip(q + scale * dq, self.q_lo, self.q_hi)

  def _assemble(self, q_arm, fingers):
    return jnp.concatenate([q_arm[0:3], fingers, q_arm[3:7]])

  def _base_under(self, pos):
    """Mobile base: the base's x/y joint values f32[2] (mount frame) that put ``pos`` f32[3] (world)
    ``MOBILE_REACH`` ahead of link0 at the mounted heading."""
    rel = jnp.asarray(self.base_rot).T @ (pos - self.base_pos)
    return jnp.stack([rel[0] - MOBILE_REACH, rel[1]])

  def base_targets(self, d, a, lo, hi):
    """Mobile base: (base joint targets f32[3], link0's pose there, grip-point target f32[3]). The grip
    point's target is the measured grip point moved by the action; the base is sent toward where that
    target lies ``MOBILE_REACH`` ahead of link0 (heading held), at most ``base_step`` per control step."""
    target = jnp.clip(self.eef_pos(d) + a[0:3] * MAX_STEP, lo, hi)
    b = d.qpos[0:3]
    want = self._base_under(target) - b[0:2]
    step = want * jnp.minimum(1.0, self.base_step / jnp.maximum(jnp.linalg.norm(want), 1e-9))
    b_t = jnp.concatenate([b[0:2] + step, jnp.zeros((1,), b.dtype)])
    return b_t, self.base_pose(b_t), target

  def ctrl(self, d, action, lo, hi, extra_ctrl=None) -> jax.Array:
    a = sanitize(action)
    if not self.mobile:
      q_t = self.arm_targets(d.qpos[0:7], a, lo, hi)
      return self._pad(self._assemble(q_t, self.finger_ctrl(a[-1])), extra_ctrl)
    b_t, base, target = self.base_targets(d, a, lo, hi)
    q_t = self.arm_targets(d.qpos[3:10], a, lo, hi, base=base, target=target)
    return self._pad(jnp.concatenate([self._assemble(q_t, self.finger_ctrl(a[-1])), b_t]), extra_ctrl)

  def ik(self, pos, r_des=None, q0=None, base=None):
    """Arm angles f32[7] putting the grip point at ``pos`` f32[3] with hand rotation ``r_des``
    (default: pointing down), by ``IK_ITERS`` undamped-rate DLS iterations from ``q0``
    (default: the ready pose turned toward ``pos``); link0 at ``base`` = (pos, rot) (default the mount)."""
    r_des = jnp.asarray(self.r_des if r_des is None else r_des)
    bp, br = (self.base_pos, self.base_rot) if base is None else base
    if q0 is None:
      rel = jnp.asarray(br).T @ (pos - bp)
      q0 = jnp.asarray(Q_READY, jnp.float32).at[0].set(jnp.arctan2(rel[1], rel[0]))

    def it(q, _):
      p, r, jac = self.kinematics(q, base)
      err = jnp.concatenate([pos - p, ROT_WEIGHT * rot_err(r, r_des)])
      dq = dls_step(q, jac.at[3:].multiply(ROT_WEIGHT), err, q0, 0.05, damping=0.02)
      return jnp.clip(q + dq, self.q_lo, self.q_hi), None

    q, _ = jax.lax.scan(it, q0, None, length=IK_ITERS)
    return q

  def home(self, qpos, pos, q_half=None) -> jax.Array:
    pos = jnp.asarray(pos, jnp.float32)
    base = None
    if self.mobile:  # the platform MOBILE_REACH behind the grip point, heading as mounted
      b = jnp.concatenate([self._base_under(pos), jnp.zeros((1,), pos.dtype)])
      qpos = qpos.at[0:3].set(b)
      base = self.base_pose(b)
    q = self.ik(pos, base=base)
    q_half = self.finger_range[1] if q_half is None else q_half
    qf = jnp.clip(q_half, self.finger_range[0], self.finger_range[1])
    return qpos.at[self.qa:self.qa + 7].set(q).at[self.qa + 7:self.qa + 9].set(qf)

  def hold_ctrl(self, qpos, nu) -> jax.Array:
    qa = self.qa
    c = jnp.zeros((nu,)).at[0:9].set(self._assemble(qpos[qa:qa + 7], qpos[qa + 7:qa + 9]))
    return c.at[9:9 + qa].set(qpos[0:qa])


def _exp_so3(w):
  """Rotation matrix f32[3, 3] of rotation vector ``w`` f32[3] (rad), Rodrigues' formula."""
  th = jnp.sqrt(jnp.sum(w * w) + 1e-12)
  k = w / th
  kx = jnp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]], w.dtype)
  return jnp.eye(3, dtype=w.dtype) + jnp.sin(th) * kx + (1.0 - jnp.cos(th)) * kx @ kx


def hand_points(m: mujoco.MjModel):
  """Where the hand's rigid side can touch things: (points f32[K, 3] m, radii f32[K] m) in the hand frame
  (fk's rotation) about the grip point, fingers fully open. Boxes give their 8 corners (radius 0),
  capsules their 2 end centres and radius, other geoms their centre and bounding radius; collision
  geoms of link7 (rigid with the hand past joint 7), the hand and both fingers."""
  d = mujoco.MjData(m)
  for j in FINGER_JOINTS:
    jid = m.joint(j).id
    d.qpos[m.jnt_qposadr[jid]] = m.jnt_range[jid, 1]
  mujoco.mj_kinematics(m, d)
  hand_r, grip = d.xmat[m.body("panda_hand").id].reshape(3, 3), d.site("panda_grip").xpos
  bodies = {m.body(b).id for b in ("panda_link7", "panda_hand") + FINGER_JOINTS}
  pts, rad = [], []
  for g in range(m.ngeom):
    if m.geom_bodyid[g] not in bodies or not (m.geom_contype[g] or m.geom_conaffinity[g]):
      continue
    c, gr, size = d.geom_xpos[g], d.geom_xmat[g].reshape(3, 3), m.geom_size[g]
    if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
      signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
      local, r = signs * size, np.zeros(8)
    elif m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
      local, r = np.array([[0, 0, -size[1]], [0, 0, size[1]]]), np.full(2, size[0])
    else:
      local, r = np.zeros((1, 3)), np.full(1, m.geom_rbound[g])
    pts.append((c + local @ gr.T - grip) @ hand_r)
    rad.append(r)
  return np.concatenate(pts).astype(np.float32), np.concatenate(rad).astype(np.float32)


class PandaWrist(Panda):
  """The Panda with ``action = [Δx, Δy, Δz, Δrx, Δry, Δrz, gripper]``: ``a[3:6]·MAX_ROT`` is a rotation
  vector (world frame, rad) turning the hand from its measured orientation (for pouring).

  A turned hand's lowest point is no longer its fingertips: pointing sideways its box corner, pointing
  up its wrist (link 7) hangs below the grip point. The grip-point target's floor is raised by that
  drop (:func:`hand_points`, at the measured rotation), so the workspace floor holds for the whole
  hand. Without it the arm drove a turned hand into the counter at up to 87 N·m a joint, and the
  contact's torque about the wrist (≈ 20 N·m, beyond the wrist servos' 12 N·m) slammed joint 6 or 7
  into its stop at 4 rad/s: 0.010–0.013 rad past the limit in ``benchmarks/panda_ik.py``."""

  name = "panda_wrist"
  action_size = 7

  def __init__(self, m: mujoco.MjModel, control_dt: float):
    super().__init__(m, control_dt)
    self.hand_pts, self.hand_rad = hand_points(m)

  def _r_target(self, r, a):
    return _exp_so3(a[3:6] * MAX_ROT) @ r

  def _floor(self, r, lo):
    drop = jnp.min(jnp.asarray(self.hand_pts) @ r[2] - jnp.asarray(self.hand_rad))  # m, ≤ 0 when below the grip point
    return jnp.asarray(lo).at[2].add(jnp.maximum(-drop, 0.0))


class PandaForward(Panda):
  """The Panda with its hand held pointing forward (``R_FORWARD``: approach along world +x, fingers
  closing along world y, palm 6 cm tall) instead of down, for tasks that reach under an overhang.

  Pointing down, the joint-7 frame rides 22 cm above the grip point: above a microwave's 20 cm
  cavity or a coffee machine's brew head. Pointing forward, the wrist trails the hand at the grip
  point's height, and the hand reaches in as far as the object's depth allows. A task that selects
  it grasps objects from behind (grip point ``FINGER_LENGTH`` deep at most, palm clear of the
  object) and keeps the grip 4.5 cm (link 7's radius) above anything the wrist passes over."""

  def __init__(self, m: mujoco.MjModel, control_dt: float):
    super().__init__(m, control_dt)
    self.r_des = R_FORWARD.astype(np.float32)


class PandaHolding(Panda):
  """The Panda with an object welded in its hand: the fingers stay at ``hold_q`` (half-opening, m) on
  the object and ``a[3]`` is ignored (the paper's gripper held closed). Pair with :func:`weld_to_hand`.

  Its posture projector has its own damping (``null_damping``): with the task step's λ the hand crept
  ≈ 0.7 mm per control step, as much as a careful set-down asks for (move_glass_of_water's 6 cm/s
  descent is 1.4 mm a step), and the glass hovered above the desk. The carry tasks that use this
  class were written with it; the others keep the shared projector (dls_step)."""

  null_damping = NULL_DAMPING

  def __init__(self, m: mujoco.MjModel, control_dt: float, hold_q: float):
    super().__init__(m, control_dt)
    if self.mobile:
      raise ValueError("scene: PandaHolding is for the fixed-base Panda (this scene has a mobile base)")
    self.hold_q = float(np.clip(hold_q, *self.finger_range))

  def ctrl(self, d, action, lo, hi, extra_ctrl=None) -> jax.Array:
    q_t = self.arm_targets(d.qpos[0:7], sanitize(action), lo, hi)
    return self._pad(self._assemble(q_t, jnp.full((2,), self.hold_q)), extra_ctrl)


def weld_to_hand(spec: mujoco.MjSpec, weld: str) -> None:
  """Re-attach the scene's weld ``weld`` from the floating gripper's ``hand`` to ``panda_hand``.

  The weld's body1 is a holder whose frame the task puts at the grip point, world-aligned, at reset
  (as the gripper's hand frame is). With the Panda that frame is the hand's grip point
  (``GRIP_OFFSET`` along the approach axis) turned by ``R_DOWN``, the controller's hand orientation:
  an explicit relative pose, since the default (the two bodies' poses at qpos0) would freeze
  the arm's zero posture into the weld.
  """
  eqs = [e for e in spec.equalities if e.name == weld]
  if len(eqs) != 1 or eqs[0].type != mujoco.mjtEq.mjEQ_WELD:
    raise ValueError(f"scene: no weld named {weld!r}")
  quat = np.zeros(4)
  mujoco.mju_mat2Quat(quat, R_DOWN.flatten())  # a half turn about x: its own inverse
  eqs[0].name2 = "panda_hand"
  eqs[0].data[3:6] = (0.0, 0.0, GRIP_OFFSET)
  eqs[0].data[6:10] = quat


def add_mobile_base(spec: mujoco.MjSpec) -> None:
  """Put the scene's Panda (``robot.xml``, not yet compiled) on a mobile base: planar joints
  ``panda_base_x``, ``panda_base_y`` (slides) and ``panda_base_yaw`` (hinge) on ``panda_link0``, a
  32 × 30 × 10 cm platform under it (part of link0, so of entity ``agent``) with four visual wheels,
  and one position servo per joint after the arm's (ctrl[9:12]). The task mounts link0 at the platform
  top (``BASE_TOP``) with ``robot_mounts``; the joints move it from there.

  The platform collides with movable objects only (conaffinity 4, like the shoulder links), so it
  rides 2 cm over the floor without touching it and strikes whatever stands in its way. The scene
  must have no actuators of its own (the robot's come first in ``ctrl``)."""
  if len(spec.actuators) != len(ACTUATORS):
    raise ValueError(f"scene: the mobile base needs a scene without actuators of its own "
                     f"(found {len(spec.actuators) - len(ACTUATORS)})")
  link0 = spec.body("panda_link0")
  slide, hinge = mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE
  for name, kind, axis, arm in ((BASE_JOINTS[0], slide, (1, 0, 0), 1.0), (BASE_JOINTS[1], slide, (0, 1, 0), 1.0),
                                (BASE_JOINTS[2], hinge, (0, 0, 1), 0.5)):
    j = link0.add_joint(name=name, type=kind, axis=axis, armature=arm, damping=10.0)
    j.limited = mujoco.mjtLimited.mjLIMITED_FALSE
  hx, hy, hz = BASE_HALF
  centre = (-LINK0_AHEAD, 0.0, -hz)
  link0.add_geom(name="panda_base", type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre, size=BASE_HALF, mass=BASE_MASS,
                 contype=2, conaffinity=4, rgba=(0.25, 0.25, 0.3, 1.0), group=1)
  for sx in (-1, 1):
    for sy in (-1, 1):
      link0.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=(0.03, 0.012), mass=0.0,
                     pos=(centre[0] + sx * (hx - 0.05), sy * (hy + 0.012), 0.03 - BASE_TOP),
                     quat=(0.7071068, 0.7071068, 0.0, 0.0), contype=0, conaffinity=0, rgba=(0.1, 0.1, 0.1, 1.0),
                     group=1)
  gains = ((BASE_KP, BASE_KV, BASE_FORCE),) * 2 + ((YAW_KP, YAW_KV, YAW_TORQUE),)
  for name, (kp, kv, f) in zip(BASE_ACTUATORS, gains):
    a = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    a.set_to_position(kp=kp, kv=kv)
    a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    a.forcerange = (-f, f)

"""Base class of the task suite: one MJCF scene + a robot + damage at every substep.

A task is one Python file with a :class:`Task` subclass and its scene XML beside
it (which includes ``robot.xml`` first: that name stands for the chosen robot's
MJCF, :mod:`tasks.robots`). A subclass declares, as class
attributes, ``name``, ``xml`` (file name beside the module), ``entities``
(damage config entities other than the agent, DAMAGE_MODEL.md §5 names) and
``workspace`` (box the grip point may be commanded into), and implements:

* ``sample_init(rng, qpos) -> (qpos, task_info)`` — randomised initial pose
  (robot + objects) and per-episode constants (goal, …) as a dict of arrays;
* ``task_obs(d, info) -> f32[k]`` — task part of the observation (object poses …);
* ``evaluate(d, info) -> (reward f32[], success f32[], extra_metrics dict)`` —
  dense task reward and the success condition (1.0 while it holds);
* ``policy(style) -> policy(state, rng) -> action`` for ``style in ("safe", "unsafe")``;
* ``damage_modality``, ``unsafe_shortcut``, ``safe_strategy``, ``success_condition`` —
  one line each, what :func:`tasks.describe` reports;
* optional: ``robot_mounts`` (robot name → base pose (x, y, z, yaw) for fixed-base
  arms; default: the robot's ``DEFAULT_MOUNT``), ``obs_modes`` + ``mode_obs`` (extra observation layouts, e.g. the
  paper's 6-D one), ``update_info(d, info) -> info`` (task state that evolves,
  e.g. which dirt is wiped; called after every control step), ``setup(mj_model)``.

Robot: ``self.robot`` (:class:`tasks.robots.interface.Robot`), chosen by
``tasks.make(name, robot=...)`` (default ``gripper``). Task code reads it through
the instance (``self.robot.eef_pos(d)``, ``self.robot.gap(d)``,
``self.robot.home(qpos, pos, q_half)`` …) and scripted policies close over it, so
the same task code runs on every robot.

Everything in ``reset``/``step`` is a pure function of (rng / state, action):
jit and vmap them. The environment's ``State``:

* ``pipeline_state`` — ``mjx.Data``;
* ``obs`` — ``[robot proprio (8 gripper, 15 panda); task_obs]`` (``obs_mode="full"``) or a task layout;
* ``reward`` — dense task reward (the damage wrapper subtracts w·cost);
* ``done`` — 1.0 on success when ``terminate_on_success`` (episode length is the
  training wrapper's business: Brax's ``EpisodeWrapper(episode_length)``);
* ``metrics["success"]`` — 1.0 on steps where the success condition holds;
* ``info["step"]`` — control steps since reset (i32), ``info["damage_state"]``,
  plus the task's per-episode constants.
"""

from __future__ import annotations

import abc
import os
from typing import Callable, ClassVar

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs.base import State
from mujoco import mjx

from mjx_damage.env import DamageEnv
from tasks import robot as R
from tasks import robots

Policy = Callable[[State, jax.Array], jax.Array]

class Task(DamageEnv):
  """A household manipulation task for one robot of :mod:`tasks.robots`, damage tracked per substep.

  The robot is ``self.robot_name`` (class default ``robots.DEFAULT``; :func:`tasks.make` sets it per
  instance before ``__init__`` runs, so task constructors need no robot argument).

  Args:
    episode_length: default number of control steps of an episode (used by the
      benchmark/training wrappers; the env itself never truncates); None: the task's
      ``default_episode_length`` × the robot's ``episode_scale`` (the Panda's hand is slower: 2×).
    n_substeps: physics steps per control step (timestep from the XML, 4 ms).
    obs_mode: ``"full"`` or one of the task's ``obs_modes``.
    terminate_on_success: ``done = 1`` on the first step the success condition holds.
    success_bonus: reward added on every step where the success condition holds.
  """

  name: ClassVar[str] = ""
  xml: ClassVar[str] = ""
  entities: ClassVar[dict] = {}
  workspace: ClassVar[tuple] = ((-0.4, -0.4, 0.0), (0.4, 0.4, 0.4))
  default_episode_length: ClassVar[int] = 150
  obs_modes: ClassVar[tuple[str, ...]] = ("full",)
  robot_name: ClassVar[str] = robots.DEFAULT
  robot_mounts: ClassVar[dict] = {}
  supported_robots: ClassVar[tuple[str, ...] | None] = None  # robots the task supports; None: every robot
  # What users read in tasks.describe(name) / `mjx-damage tasks` (one line each).
  damage_modality: ClassVar[str] = ""  # which DEM the unsafe shortcut triggers, and how
  unsafe_shortcut: ClassVar[str] = ""
  safe_strategy: ClassVar[str] = ""
  success_condition: ClassVar[str] = ""
  # robot name -> how the task builds that robot where it is not the plain one (a mobile base, a
  # turned hand, an object welded in the hand); tasks.describe lists it beside the robot's name
  robot_variants: ClassVar[dict] = {}

  def __init__(
      self,
      episode_length: int | None = None,
      n_substeps: int = 6,
      obs_mode: str = "full",
      terminate_on_success: bool = False,
      success_bonus: float = 1.0,
  ):
    if episode_length is None:
      episode_length = int(round(self.default_episode_length * robots.robot_class(self.robot_name).episode_scale))
    if isinstance(episode_length, bool) or not isinstance(episode_length, int) or episode_length < 1:
      raise ValueError(f"episode_length: must be a positive int, got {episode_length!r}")
    if obs_mode not in self.obs_modes:
      raise ValueError(f"obs_mode: unknown {obs_mode!r}; valid: {', '.join(self.obs_modes)}")
    if isinstance(success_bonus, bool) or not isinstance(success_bonus, (int, float)) or not np.isfinite(success_bonus):
      raise ValueError(f"success_bonus: must be a finite number, got {success_bonus!r}")
    robot_cls = robots.robot_class(self.robot_name)
    mj_model = self.load_scene(robot_cls)
    if robot_cls.default_mount is not None:
      robot_cls.place(mj_model, self.robot_mounts.get(robot_cls.name, robot_cls.default_mount))
    cfg = self.damage_config()
    cfg["entities"]["agent"] = robot_cls.agent_entity()
    super().__init__(mj_model, cfg, n_substeps)
    self.robot = robot_cls(mj_model, float(mj_model.opt.timestep) * n_substeps)
    self.episode_length = episode_length
    self.obs_mode = obs_mode
    self.terminate_on_success = bool(terminate_on_success)
    self.success_bonus = float(success_bonus)
    self.ws_lo, self.ws_hi = self.robot.workspace(*self.workspace)
    self.setup(mj_model)
    d0 = jax.eval_shape(self.make_data)
    info0 = jax.eval_shape(lambda r: self.sample_init(r, jnp.zeros(mj_model.nq))[1], jax.random.PRNGKey(0))
    self._obs_size = int(jax.eval_shape(self.observe, d0, info0).shape[-1])

  # -- configuration hooks -------------------------------------------------------
  @classmethod
  def damage_config(cls) -> dict:
    """The damage config: the task's entities plus the robot as ``agent`` (the gripper's bodies here;
    ``__init__`` puts the chosen robot's bodies in)."""
    return {"entities": {**cls.entities, "agent": dict(R.AGENT_ENTITY)}}

  def load_scene(self, robot_cls) -> mujoco.MjModel:
    """Compile the task's scene XML with ``robot.xml`` resolved to ``robot_cls``'s MJCF, after
    :meth:`edit_scene` (tasks that override it go through ``mujoco.MjSpec``, the same compiler)."""
    path = os.path.join(os.path.dirname(__import__(type(self).__module__, fromlist=["_"]).__file__), self.xml)
    with open(path) as f:
      text = f.read()
    with open(robot_cls.xml, "rb") as f:
      robot_xml = f.read()
    if type(self).edit_scene is Task.edit_scene:
      return mujoco.MjModel.from_xml_string(text, {"robot.xml": robot_xml})
    spec = mujoco.MjSpec.from_string(text, include={"robot.xml": robot_xml})
    self.edit_scene(spec, robot_cls)
    return spec.compile()

  def edit_scene(self, spec: mujoco.MjSpec, robot_cls) -> None:
    """Adapt the scene to the robot before it compiles (e.g. an object the Panda's 8 cm stroke can grasp);
    the default changes nothing. Runs before ``setup``; per-robot sizes the task code reads are set here."""

  def setup(self, m: mujoco.MjModel) -> None:
    """Look up static indices in the compiled model (called once in ``__init__``)."""

  # -- subclass API ------------------------------------------------------------------
  @abc.abstractmethod
  def sample_init(self, rng: jax.Array, qpos: jax.Array) -> tuple[jax.Array, dict]:
    """Randomised initial ``qpos`` f32[nq] and per-episode constants (dict of arrays)."""

  @abc.abstractmethod
  def task_obs(self, d: mjx.Data, info: dict) -> jax.Array:
    """Task part of the observation (object poses …), f32[k]."""

  @abc.abstractmethod
  def evaluate(self, d: mjx.Data, info: dict):
    """(dense reward f32[], success f32[] or bool[], extra metrics dict)."""

  @abc.abstractmethod
  def policy(self, style: str) -> Policy:
    """Scripted ``policy(state, rng) -> action`` for ``style`` in ("safe", "unsafe")."""

  def update_info(self, d: mjx.Data, info: dict) -> dict:
    """Advance task state kept in ``info`` after a control step (default: none)."""
    return info

  def mode_obs(self, mode: str, d: mjx.Data, info: dict) -> jax.Array:
    """Observation of a non-default ``obs_mode`` (tasks with extra layouts override this)."""
    raise ValueError(f"obs_mode: unknown {mode!r}")

  # -- Brax API ------------------------------------------------------------------------
  @property
  def observation_size(self) -> int:
    return self._obs_size

  @property
  def action_size(self) -> int:
    return self.robot.action_size

  def observe(self, d: mjx.Data, info: dict) -> jax.Array:
    if self.obs_mode == "full":
      return jnp.concatenate([self.robot.proprio(d), self.task_obs(d, info)])
    return self.mode_obs(self.obs_mode, d, info)

  def reset(self, rng: jax.Array) -> State:
    r_init, r_dmg = jax.random.split(rng)
    d = self.make_data()
    qpos, task_info = self.sample_init(r_init, d.qpos)
    d = d.replace(qpos=qpos, ctrl=self.robot.hold_ctrl(qpos, self.mj_model.nu))
    d = mjx.forward(self.sys, d)
    info = {"damage_state": self.init_damage(r_dmg), "step": jnp.zeros((), jnp.int32), **task_info}
    _, success, extra = self.evaluate(d, info)
    z = jnp.zeros((), jnp.float32)
    metrics = {"success": success.astype(jnp.float32), **extra}
    return State(d, self.observe(d, info), z, z, metrics, info)

  def step(self, state: State, action: jax.Array) -> State:
    d0 = state.pipeline_state
    ctrl = self.robot.ctrl(d0, action, self.ws_lo, self.ws_hi)
    d, ds = self.physics_step(d0, state.info["damage_state"], ctrl)
    info = self.update_info(d, dict(state.info, damage_state=ds, step=state.info["step"] + 1))
    reward, success, extra = self.evaluate(d, info)
    success = success.astype(jnp.float32)
    reward = (reward + self.success_bonus * success).astype(jnp.float32)
    done = success if self.terminate_on_success else jnp.zeros((), jnp.float32)
    metrics = {**state.metrics, "success": success, **extra}
    return state.replace(pipeline_state=d, obs=self.observe(d, info), reward=reward, done=done,
                         metrics=metrics, info=info)


# -- small pure helpers shared by tasks --------------------------------------------------
def quat_z_axis(q):
  """World z axis of a body with quaternion ``q`` (w, x, y, z), f32[3] — its 'up' direction."""
  w, x, y, z = q[0], q[1], q[2], q[3]
  return jnp.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def yaw_quat(yaw):
  """Quaternion (w, x, y, z) of a rotation by ``yaw`` rad about world z."""
  return jnp.stack([jnp.cos(yaw / 2), 0.0 * yaw, 0.0 * yaw, jnp.sin(yaw / 2)])


def free_joint_adr(m: mujoco.MjModel, joint: str) -> tuple[int, int]:
  """(qpos address, dof address) of a free joint by name."""
  j = m.joint(joint).id
  if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
    raise ValueError(f"scene: joint {joint!r} is not a free joint")
  return int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])

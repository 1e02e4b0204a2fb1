"""The task suite: registry, construction and scripted policies.

API (evaluation, training and rendering build on exactly this)::

    import tasks
    tasks.names()                          # ['open_drawer', 'pick_egg', ...]
    env = tasks.make("place_plate", damage_weight=2.0, obs_mode="paper")
    env = tasks.make("place_plate", robot="panda")   # Franka Panda instead of the floating gripper
    state = jax.jit(env.reset)(jax.random.PRNGKey(0))
    state = jax.jit(env.step)(state, action)          # action f32[4] in [-1, 1]
    policy = tasks.scripted_policy(env, "safe")       # policy(state, rng) -> action, one env
    tasks.default_config("place_plate")    # {'episode_length': 100, ...}
    tasks.describe("open_single_door")     # {'damage_modality': 'mechanical: ...', 'unsafe_shortcut': ...}

``make`` returns the task wrapped in :class:`mjx_damage.wrapper.DamageWrapper`
(``env.unwrapped`` is the :class:`tasks.base.Task`). Overrides are the wrapper's
(``damage_weight``, ``terminate_on_destroyed``, ``health_in_obs``, ``params_fn``,
``safe_threshold``) plus the task's constructor knobs (``episode_length``,
``n_substeps``, ``obs_mode``, ``terminate_on_success``, ``success_bonus`` and
task-specific ones) and ``robot`` (:func:`tasks.robots.names`: ``"gripper"`` — the
default for now, every task's scripted policies are tuned on it — ``"panda"``, or
``"panda_wrist"`` with the 7-D action); anything else raises ``ValueError``
listing the valid ones.

Adding a task: a module ``tasks/<name>.py`` with a :class:`tasks.base.Task`
subclass, its scene XML beside it, and one line in ``_REGISTRY`` below. The
default test suite then runs it through tests/test_task_contract.py (one compiled
rollout: shapes, random and extreme actions, scripted safe/unsafe separation);
a task's own test file needs only what is particular to it.
"""

from __future__ import annotations

import importlib
import inspect
import json

from mjx_damage.env import WARP_CONTACTS
from mjx_damage.wrapper import DamageWrapper
from tasks import robots

# name -> "module:Class" (imported lazily: constructing a task loads its scene).
_REGISTRY = {
    "add_firewood": "tasks.add_firewood:AddFirewood",
    "attach_camera": "tasks.attach_camera:AttachCamera",
    "dishes_to_sink": "tasks.dishes_to_sink:DishesToSink",
    "fill_bowl": "tasks.fill_bowl:FillBowl",
    "ignite_wood": "tasks.ignite_wood:IgniteWood",
    "move_glass_of_water": "tasks.move_glass_of_water:MoveGlassOfWater",
    "navigate_and_pick": "tasks.navigate_and_pick:NavigateAndPick",
    "open_drawer": "tasks.open_drawer:OpenDrawer",
    "open_single_door": "tasks.open_single_door:OpenSingleDoor",
    "pick_egg": "tasks.pick_egg:PickEgg",
    "pick_up_scrub": "tasks.pick_up_scrub:PickUpScrub",
    "place_in_microwave": "tasks.place_in_microwave:PlaceInMicrowave",
    "place_plate": "tasks.place_plate:PlacePlate",
    "pour_water": "tasks.pour_water:PourWater",
    "prepare_breakfast": "tasks.prepare_breakfast:PrepareBreakfast",
    "prepare_coffee": "tasks.prepare_coffee:PrepareCoffee",
    "serve_pastry": "tasks.serve_pastry:ServePastry",
    "shelve_item": "tasks.shelve_item:ShelveItem",
    "turn_on_faucet": "tasks.turn_on_faucet:TurnOnFaucet",
    "turn_on_microwave": "tasks.turn_on_microwave:TurnOnMicrowave",
    "turn_on_stove": "tasks.turn_on_stove:TurnOnStove",
    "wipe_counter": "tasks.wipe_counter:WipeCounter",
}

# The setting each task is trained in with RL, as make() overrides (issue 24, docs/rl_task_design.md: the
# setting in which the task reward alone prefers the unsafe shortcut). Place Plate: the paper's 6-D
# observation and in-hand start; Pick Egg: the egg carried to a goal. Tasks not listed: their defaults.
# The robot is named: the committed RL results were trained with the gripper, which is no longer the
# default robot (the Panda's Place Plate runs pass --task-settings '{"robot": "panda"}').
# Place Plate's counter is a box (since 2026-11-29): on MJX's plane a tilted plate's impact is 0.56× MuJoCo
# C's, so policies trained there are safe on MJX only (docs/safe_rl.md, "Learned policies on native MuJoCo").
# Results files and checkpoints naming no counter ran the plane (the task's default); their commands rerun
# as made with --task-settings '{"counter": "plane"}'.
RL_SETTINGS = {"place_plate": {"robot": "gripper", "obs_mode": "paper", "counter": "box"},
               "pick_egg": {"robot": "gripper", "goal": "carry"},
               "shelve_item": {"robot": "gripper"}}

# Wrapper overrides: make() keyword -> (DamageWrapper keyword, default).
_WRAPPER_OPTIONS = {
    "damage_weight": ("weight", 0.0),
    "terminate_on_destroyed": ("terminate_on_destroyed", False),
    "health_in_obs": ("health_in_obs", False),
    "params_fn": ("params_fn", None),
    "safe_threshold": ("safe_threshold", 95.0),
    "cost": ("cost", "damage"),
}

STYLES = ("safe", "unsafe")


def names() -> list[str]:
  """Registered task names, sorted."""
  return sorted(_REGISTRY)


def task_class(name: str):
  """The :class:`tasks.base.Task` subclass registered as ``name``."""
  if name not in _REGISTRY:
    raise ValueError(f"name: unknown task {name!r}; valid: {', '.join(names())}")
  module, cls = _REGISTRY[name].split(":")
  return getattr(importlib.import_module(module), cls)


def rl_overrides(name: str) -> dict:
  """Task ``name``'s RL setting (:data:`RL_SETTINGS`) without its robot: the make() keywords for a script whose
  ``--robot`` chooses the robot."""
  return {k: v for k, v in RL_SETTINGS.get(name, {}).items() if k != "robot"}


def rl_settings(name: str, overrides_json: str | None = None) -> dict:
  """Task ``name``'s RL setting (:data:`RL_SETTINGS`) with the task keywords of a JSON object over it.

  For the benchmarks' ``--task-settings`` flag. Checked by :func:`make` (the task's constructor included),
  before anything compiles: bad JSON, a non-object, an unknown override or a refused value raise
  ``ValueError`` naming ``task_settings``.
  """
  return settings_over(name, RL_SETTINGS.get(name, {}), overrides_json)


def settings_over(name: str, base: dict, overrides_json: str | None, field: str = "task_settings") -> dict:
  """``base`` (task keywords of ``name``) with those of the JSON object ``overrides_json`` over them, checked
  by :func:`make` before anything compiles; ``ValueError`` naming ``field`` (e.g. ``eval_task_settings``:
  the evaluations' setting over the training one)."""
  settings = dict(base)
  if overrides_json is None:
    return settings
  try:
    extra = json.loads(overrides_json)
  except json.JSONDecodeError as e:
    raise ValueError(f"{field}: not JSON ({e}), got {overrides_json!r}") from None
  if not isinstance(extra, dict):
    raise ValueError(f"{field}: a JSON object of task keyword arguments, got {overrides_json!r}")
  settings.update(extra)
  try:
    make(name, **settings)
  except (TypeError, ValueError) as e:
    raise ValueError(f"{field}: {name} refuses {settings}: {e}") from None
  return settings


def parse_task_args(items) -> dict:
  """``["KEY=JSON", ...]`` (the command lines' repeatable ``--task-arg``) → task keyword arguments.

  A value that is not JSON is kept as a string (``obs_mode=paper``); the keys and values are checked
  by :func:`make`. Raises ``ValueError`` naming ``--task-arg`` for an item without ``=`` or a key.
  """
  out = {}
  for item in items or ():
    key, sep, value = str(item).partition("=")
    if not sep or not key.strip():
      raise ValueError(f"--task-arg: expected KEY=JSON, got {item!r}")
    try:
      out[key.strip()] = json.loads(value)
    except json.JSONDecodeError:
      out[key.strip()] = value
  return out


def _task_options(cls) -> dict:
  """Constructor keywords of a task class (its own and inherited) with their defaults."""
  opts = {}
  for klass in reversed(cls.__mro__):
    init = klass.__dict__.get("__init__")
    if init is None or klass.__module__.startswith(("brax", "mjx_damage", "builtins")):
      continue
    for p in list(inspect.signature(init).parameters.values())[1:]:
      if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
        continue
      opts[p.name] = p.default
  if opts.get("episode_length", 0) is None:
    opts["episode_length"] = cls.default_episode_length
  return opts


def default_config(name: str) -> dict:
  """Every override ``make(name, ...)`` accepts, with its default value."""
  cls = task_class(name)
  cfg = {k: v for k, (_, v) in _WRAPPER_OPTIONS.items()}
  cfg.update(_task_options(cls))
  cfg["robot"] = robots.DEFAULT
  cfg.update(_BACKEND_OPTIONS)
  return cfg


# make() keywords of the physics backend (mjx_damage.env.DamageEnv): "jax", or "warp" (MuJoCo Warp) stepping
# num_envs environments at once (the batch the env is vmapped over) with warp_contacts contact places each
_BACKEND_OPTIONS = {"backend": "jax", "num_envs": 0, "warp_contacts": WARP_CONTACTS}


def make(name: str, **overrides):
  """Build task ``name`` wrapped for damage; ``overrides`` as in :func:`default_config`.

  Raises:
    ValueError: unknown task name or override (the message lists the valid ones),
      or an invalid value (named by its field).
  """
  cls = task_class(name)
  valid = default_config(name)
  for k in overrides:
    if k not in valid:
      raise ValueError(f"{k}: unknown override for task {name!r}; valid: {', '.join(sorted(valid))}")
  robot = overrides.get("robot", robots.DEFAULT)
  robots.robot_class(robot)  # unknown names raise here, before anything compiles
  supported = robots_for(name)
  if robot not in supported:
    raise ValueError(f"robot: task {name!r} supports {', '.join(supported)} only, got {robot!r}")
  wrapper_kw = {_WRAPPER_OPTIONS[k][0]: overrides.get(k, v) for k, (_, v) in _WRAPPER_OPTIONS.items()}
  task_kw = {k: v for k, v in overrides.items()
             if k not in _WRAPPER_OPTIONS and k not in _BACKEND_OPTIONS and k != "robot"}
  # the robot and the physics backend are chosen per instance before the task's constructor runs
  # (constructors take neither); DamageEnv checks the backend's values
  env = cls.__new__(cls)
  env.robot_name = robot
  env.physics_backend = overrides.get("backend", "jax")
  if env.physics_backend == "warp":
    env.warp_worlds = overrides.get("num_envs", 0)
    env.warp_contacts = overrides.get("warp_contacts", _BACKEND_OPTIONS["warp_contacts"])
  elif "num_envs" in overrides or "warp_contacts" in overrides:
    raise ValueError("num_envs/warp_contacts: only with backend='warp'")
  env.__init__(**task_kw)
  return DamageWrapper(env, **wrapper_kw)


# Checkpoints and datasets written before the Panda became the default robot (2026-11-28) name no robot in
# their stored make() keywords: they ran the gripper. Everything written since names it (recorded_kwargs).
UNNAMED_ROBOT = "gripper"


def recorded_kwargs(env, overrides: dict | None) -> dict:
  """``overrides`` to store beside an artefact of ``env`` (a :func:`make` result, or a task name to be built
  with them): with the robot it runs, so the artefact does not depend on the default robot. Envs and names
  without a robot (built-in scenes, env classes): ``overrides`` unchanged."""
  if isinstance(env, str):
    robot = robots.DEFAULT if env in _REGISTRY else None
  else:
    robot = getattr(getattr(env, "unwrapped", env), "robot_name", None)
  out = dict(overrides or {})
  if robot is not None:
    out.setdefault("robot", robot)
  return out


def stored_kwargs(name: str, kwargs: dict | None) -> dict:
  """Stored make() keywords of registry task ``name`` as they ran: no robot named means :data:`UNNAMED_ROBOT`."""
  out = dict(kwargs or {})
  if name in _REGISTRY:
    out.setdefault("robot", UNNAMED_ROBOT)
  return out


def robots_for(name: str) -> list[str]:
  """The robots ``make(name, robot=...)`` accepts (the task's ``supported_robots``, else every robot)."""
  only = task_class(name).supported_robots
  return [r for r in robots.names() if only is None or r in only]


def check_robot(robot: str, chosen=(), field: str = "robot") -> None:
  """``ValueError`` naming ``field`` (a script's ``--robot``) unless ``robot`` is registered and runs every
  registry task in ``chosen``; other names (built-in scenes, env classes) are left to their own checks."""
  if robot not in robots.names():
    raise ValueError(f"{field}: unknown robot {robot!r} (valid: {', '.join(robots.names())})")
  other = [t for t in chosen if t in _REGISTRY and robot not in robots_for(t)]
  if other:
    raise ValueError(f"{field}: {', '.join(other)} run(s) without {robot!r} (tasks.robots_for)")


def select(chosen=None, robot: str = "gripper") -> list[str]:
  """Task names for a script's ``--tasks`` with ``--robot``: ``chosen`` checked, in order, or (None) every
  task ``robot`` runs. ``ValueError`` naming ``tasks`` or ``robot`` (before anything is built)."""
  check_robot(robot)
  if chosen is None:
    return [t for t in names() if robot in robots_for(t)]
  chosen = list(chosen)
  unknown = [t for t in chosen if t not in names()]
  if unknown:
    raise ValueError(f"tasks: unknown task(s) {', '.join(unknown)} (valid: {', '.join(names())})")
  if len(set(chosen)) != len(chosen):
    raise ValueError(f"tasks: listed twice: {', '.join(sorted({t for t in chosen if chosen.count(t) > 1}))}")
  check_robot(robot, chosen)
  return chosen


DESCRIPTION_FIELDS = ("name", "summary", "damage_modality", "tracked_entities", "unsafe_shortcut", "safe_strategy",
                      "horizon", "robot", "robots", "robot_variants", "success_condition")


def describe(name: str) -> dict:
  """What task ``name`` is about, without building it (no scene is compiled).

  Returns a dict with :data:`DESCRIPTION_FIELDS`: ``summary`` (the module
  docstring's first line), ``damage_modality`` (the damage model the unsafe
  shortcut triggers), ``tracked_entities`` (damage-config entities, the robot as
  ``agent`` last), ``unsafe_shortcut``, ``safe_strategy``, ``horizon`` (default
  episode length, control steps), ``robot`` (the default robot), ``robots`` (every
  robot ``make(name, robot=...)`` accepts), ``robot_variants`` (robot → how the task builds
  it where that is not the plain robot: a mobile base, a hand turned forward, an object welded in
  the hand) and ``success_condition``.
  """
  cls = task_class(name)
  doc = (importlib.import_module(cls.__module__).__doc__ or "").strip()
  return {
      "name": name,
      "summary": doc.splitlines()[0] if doc else "",
      "damage_modality": cls.damage_modality,
      "tracked_entities": [*cls.entities, "agent"],
      "unsafe_shortcut": cls.unsafe_shortcut,
      "safe_strategy": cls.safe_strategy,
      # the default robot's (Task.__init__'s default episode length; the gripper's is default_episode_length)
      "horizon": int(round(cls.default_episode_length * robots.robot_class(robots.DEFAULT).episode_scale)),
      "robot": robots.DEFAULT,
      "robots": robots_for(name),
      "robot_variants": dict(cls.robot_variants),
      "success_condition": cls.success_condition,
  }


def scripted_policy(env, style: str):
  """Jittable, vmappable ``policy(state, rng) -> action f32[4]`` for ONE env of ``env``.

  ``style``: ``"safe"`` (the task's safe strategy) or ``"unsafe"`` (its tempting
  shortcut). ``env`` is what :func:`make` returned (or the bare task).
  """
  if style not in STYLES:
    raise ValueError(f"style: must be one of {', '.join(STYLES)}, got {style!r}")
  task = getattr(env, "unwrapped", env)
  if not hasattr(task, "policy"):
    raise ValueError(f"env: not a task-suite env ({type(task).__name__})")
  return task.policy(style)

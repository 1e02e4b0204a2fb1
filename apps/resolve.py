"""Names on the command line → objects: ``--task place_plate``, ``--policy scripted:safe|checkpoint:RUN|…``.

Tasks: the registry's (:func:`tasks.names`) and two built-in scenes, ``drop``
(:class:`tasks.drop.DropEnv`, no actions) and ``push_boxes`` (4 boxes of
:mod:`tasks.bench_table`, a 2-D pusher). Policies: ``scripted:safe``,
``scripted:unsafe`` (the task's scripted policy), ``random``, ``zero``,
``checkpoint[+sample|+mean]:PATH[#SEED]`` (a trained run, :func:`train.load_policy`: its
mode, a sample, or its mean; ``#SEED`` picks a seed of a multi-seed run, default its first). Every check raises ``ValueError("task: …")``/``("policy: …")``
before anything is built.
This is the one module that knows all the names, so it sits at the top.
"""

from __future__ import annotations

import os
from typing import Optional

import jax

import apps
import mjx_damage
import tasks
import tasks.native
import train
from mjx_damage.native_batch import NativeBatchEnv
from mjx_damage.wrapper import DamageWrapper
from tasks.bench_table import table_env
from tasks.drop import DropEnv
from train import checkpoint as ckpt
from train import evaluate as E

BACKENDS = ("auto", "mjx", "native")  # every command; eval, sweep, render and bench also take "warp" (warp_overrides)
POLICY_SPECS = ("scripted:safe", "scripted:unsafe", "random", "zero", "checkpoint[+sample|+mean]:PATH[#SEED]")
# A trained policy's action (train.networks.policy_apply): its mode (brax's deterministic policy), one sample per
# step (the stochastic policy PPO trains), or the squashed mean.
CHECKPOINT_ACTIONS = {"checkpoint": "mode", "checkpoint+sample": "sample", "checkpoint+mean": "mean"}
# Built-in scenes usable as tasks, with their episode lengths in env steps.
BUILTIN_TASKS = {"drop": 50, "push_boxes": 50}


def task_names() -> list[str]:
  """Every name :func:`make_task` accepts: the registry's tasks and the built-ins."""
  names = list(tasks.names())
  return names + [n for n in BUILTIN_TASKS if n not in names]


def check_task(name) -> str:
  if not isinstance(name, str) or name not in task_names():
    raise ValueError(f"task: unknown task {name!r}; tasks: {', '.join(task_names())}")
  return name


def make_task(name: str, **overrides):
  """A DamageWrapper-wrapped env by name (registry first, then the built-ins ``drop``, ``push_boxes``)."""
  check_task(name)
  if name in tasks.names():
    return tasks.make(name, **overrides)
  if name == "drop":
    return DamageWrapper(DropEnv(**overrides))
  return DamageWrapper(table_env(**{"k": 4, **overrides}))


def check_backend(name, warp: bool = False) -> str:
  """``name`` if the command takes it (``warp``: the command runs MuJoCo Warp too), else ValueError."""
  valid = BACKENDS + (("warp",) if warp else ())
  if name not in valid:
    raise ValueError(f"backend: unknown backend {name!r}; backends: {', '.join(valid)}")
  return name


def warp_overrides(task: str, backend: str, num_envs: int, num_devices: int = 1) -> dict:
  """The make() keywords that put registry task ``task`` on MuJoCo Warp for ``--backend warp`` (``{}`` for
  any other backend): ``num_envs`` environments stepped as one batch.

  Checked before anything is built: a registry task (the built-in scenes have no Warp path), one device
  (the batch is one list of contacts on one device), and warp-lang installed (the ``warp`` extra)."""
  if backend != "warp":
    return {}
  if task not in tasks.names():
    raise ValueError(f"backend: warp runs the registry's tasks; {task!r} is a built-in scene (use mjx or native)")
  if num_devices != 1:
    raise ValueError(f"backend: warp steps one batch on one device; this run has {num_devices} (use mjx, or one device)")
  try:
    import warp  # noqa: F401  (the optional extra MJX's Warp implementation needs)
  except ImportError:
    raise ValueError("backend: warp needs warp-lang, the optional extra: pip install -e '.[warp]'") from None
  return {"backend": "warp", "num_envs": int(num_envs)}


def pick_backend(backend: str, env, num_devices: int = 1, policies=()) -> str:
  """``mjx``, ``native`` or ``warp`` for ``--backend``: ``auto`` is whichever of mjx and native is faster
  for ``env``, unless a policy is a trained one; ``warp`` (an env made with :func:`warp_overrides`) stays as
  it is.

  That is native on a CPU run over one device whose scene the native backend runs (about 10x the
  MJX-JAX env-steps/s on 2 cores, 1.3x with liquid, whose particles run in JAX on either:
  benchmarks/results/native_backend_cpu.md, native_backend_cpu_pour_water.md, and with heat sources
  native_backend_cpu_add_firewood.md), else mjx (accelerators, several devices). The two agree on the
  scripted policies' completion and safe completion; health and cost can differ (README, "Native batched
  backend"). ``policies`` (specs): with a checkpoint among them ``auto`` is mjx, the physics our trainers
  train on, because a learned policy can sit close to a damage threshold that the other simulator's
  contacts cross (Place Plate: 91 % safe on MJX, 10 % natively, docs/safe_rl.md "Learned policies on
  native MuJoCo"); ``--backend native`` still asks for the other."""
  if check_backend(backend, warp=True) != "auto":
    return backend
  if any(parse_policy_spec(p)[0] == "checkpoint" for p in policies):
    return "mjx"
  cpu_only = jax.default_backend() == "cpu"
  return "native" if cpu_only and num_devices == 1 and tasks.native.supports(env) else "mjx"


def auto_reason(requested: str, picked: str, policies=()) -> str:
  """What to print after the backend ``auto`` picked: `` (auto)``, and why when a trained policy kept it on mjx."""
  if requested != "auto":
    return ""
  if picked == "mjx" and any(parse_policy_spec(p)[0] == "checkpoint" for p in policies):
    return " (auto: a trained policy is evaluated on the physics it was trained on; --backend native for MuJoCo's)"
  return " (auto)"


def on_backend(env, backend: str, num_envs: int, nthread: int = 0):
  """``env`` itself for ``mjx``; its :class:`~mjx_damage.native_batch.NativeBatchEnv` of ``num_envs`` for
  ``native``; ``auto`` as :func:`pick_backend` decides for one device.

  Raises ValueError for an env the native backend cannot run (not a task-suite, drop or K-box scene).
  """
  if pick_backend(backend, env) in ("mjx", "warp"):  # a Warp env was made so (warp_overrides)
    return env
  return tasks.native.wrap(env, num_envs, nthread=nthread)


def add_backend_argument(ap, scope: str = "", default: str = "mjx", warp: bool = False) -> None:
  """``--backend auto|mjx|native[|warp]`` as every command spells it; ``scope`` adds what the choice applies to
  (bench: only its task throughput), so the one help text says where it does not; ``warp``: the command
  also runs MuJoCo Warp (:func:`warp_overrides`)."""
  ap.add_argument("--backend", default=default,
                  help=f"physics (default {default}): mjx (compiled MJX-JAX, batched on any device), native "
                       "(MuJoCo on C threads, CPU), auto (native on a one-device CPU "
                       "run where the scene allows, mjx for a checkpoint policy or elsewhere)" + (f"; {scope}" if scope else "")
                       + (", or warp (MuJoCo Warp, one device; the warp extra)" if warp else ""))


def episode_length_of(env, task: Optional[str] = None) -> int:
  """Episode length in env steps: the env's ``episode_length``, the registry's default, or a built-in's."""
  n = getattr(env, "episode_length", None)
  if n is None and task in tasks.names():
    n = tasks.default_config(task).get("episode_length")
  if n is None and task in BUILTIN_TASKS:
    n = BUILTIN_TASKS[task]
  if n is None:
    raise ValueError("episode_length: the env defines none; pass episode_length explicitly")
  return int(n)


def parse_policy_spec(spec) -> tuple[str, Optional[str]]:
  """``"scripted:safe"`` → ("scripted", "safe"); checks the spec's form (no env needed).

  ``checkpoint:PATH``, ``checkpoint+sample:PATH`` and ``checkpoint+mean:PATH`` all give ("checkpoint", PATH);
  :func:`checkpoint_action` tells them apart.
  """
  if not isinstance(spec, str):
    raise ValueError(f"policy: expected a spec string ({', '.join(POLICY_SPECS)}), got {spec!r}")
  kind, _, arg = spec.partition(":")
  if kind in ("random", "zero") and not arg:
    return kind, None
  if kind == "scripted" and arg in ("safe", "unsafe"):
    return kind, arg
  if kind in CHECKPOINT_ACTIONS and arg:
    path, seed = _split_seed(arg)
    if not os.path.exists(path):
      raise ValueError(f"policy: checkpoint {path!r} does not exist")
    if seed is not None:
      file = ckpt.file_of(path)
      seeds = ckpt.read_meta(file).get("config", {}).get("seeds", [])
      if seed not in seeds:
        raise ValueError(f"policy: seed {seed} is not a seed of checkpoint {path!r} (its seeds: "
                         f"{', '.join(map(str, seeds))})")
    return "checkpoint", path
  raise ValueError(f"policy: unknown policy {spec!r}; expected one of {', '.join(POLICY_SPECS)}")


def _split_seed(arg: str) -> tuple[str, Optional[int]]:
  """``"run#2"`` → ("run", 2); ``"run"`` → ("run", None). A path that exists as given keeps its '#'."""
  path, sep, tail = arg.rpartition("#")
  if not sep or os.path.exists(arg):
    return arg, None
  try:
    return path, int(tail)
  except ValueError:
    raise ValueError(f"policy: {arg!r}: after '#' comes a seed of the run (an integer), got {tail!r}") from None


def checkpoint_seed(spec: str) -> Optional[int]:
  """The seed a ``checkpoint…:PATH#SEED`` spec asks for (None: the run's first)."""
  return _split_seed(spec.partition(":")[2])[1]


def checkpoint_path(spec: str) -> str:
  """The run directory or file a ``checkpoint…:PATH#SEED`` spec names, without its seed."""
  return _split_seed(spec.partition(":")[2])[0]


def checkpoint_action(spec: str) -> str:
  """The action a ``checkpoint…:PATH`` spec asks for: "mode", "sample" or "mean"."""
  return CHECKPOINT_ACTIONS[spec.partition(":")[0]]


def make_policy(spec: str, env) -> E.Policy:
  """A ``policy(state, rng) -> action`` for one env of ``env`` (or of a native batch's env) from a spec string."""
  kind, arg = parse_policy_spec(spec)
  if isinstance(env, NativeBatchEnv):  # policies are functions of one env's State: the same on both backends
    env = env.env
  if kind == "random":
    return E.random_policy(env.action_size)
  if kind == "zero":
    return E.zero_policy(env.action_size)
  if kind == "scripted":
    return tasks.scripted_policy(env, arg)
  return train.load_policy(arg, env, action=checkpoint_action(spec), seed=checkpoint_seed(spec))


# Source trees every program a command traces is built from (the program cache's key hashes them).
PROGRAM_ROOTS = tuple(os.path.dirname(os.path.abspath(m.__file__)) for m in (mjx_damage, tasks, train, apps))


def program_description(command: str, task: str, policy_spec: str, **fields) -> dict:
  """What a command's traced program is built from, for :mod:`mjx_damage.program_cache`.

  Names, overrides and ``fields`` (episode length, batch …) plus, for a
  ``checkpoint:`` policy, the checkpoint's metadata (its network config fixes the
  policy's code; the weights are arguments of the program, not part of it).
  """
  desc = {"command": command, "task": task, "policy": policy_spec, **fields}
  kind, arg = parse_policy_spec(policy_spec)
  if kind == "checkpoint":
    file = ckpt.file_of(arg)
    desc["checkpoint"] = ckpt.read_meta(file)
  return desc


def add_task_policy_arguments(ap) -> None:
  """``--task`` and ``--policy`` (both required) on an ``argparse`` parser, as every command spells them."""
  ap.add_argument("--task", required=True, help=f"task name (registry tasks, or built-in: {', '.join(BUILTIN_TASKS)})")
  ap.add_argument("--policy", required=True, help=" | ".join(POLICY_SPECS))


def robot_task_kwargs(task: str, robot: str, default: str) -> Optional[dict]:
  """``tasks.make`` keywords of a script's ``--task`` and ``--robot`` (``default``: the script's own robot):
  ``{"robot": robot}`` for a registry task that runs it; None for an env class, which takes no robot and
  accepts only ``default``. ``ValueError`` naming ``--robot``, before anything is built."""
  tasks.check_robot(robot, [task], "--robot")
  if ":" in task:
    if robot != default:
      raise ValueError(f"--robot: only for a registered --task, not the env class {task!r}")
    return None
  return {"robot": robot}


def add_task_override_arguments(ap) -> None:
  """``--robot`` and ``--task-arg KEY=JSON`` (repeatable): keyword arguments of ``tasks.make`` on a command line."""
  ap.add_argument("--robot", default=None, help="robot of a registry task, e.g. panda (default: the task's)")
  ap.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                  help="task keyword argument (repeatable), e.g. --task-arg obs_mode=paper --task-arg start=in_hand; "
                       "a checkpoint policy brings its own, which these may add to or change, except its obs_mode and robot")


# Task keywords that decide a policy's observation and action layout: a checkpoint's own cannot be overridden.
POLICY_INTERFACE = ("obs_mode", "robot")


def task_overrides(task: str, trained: Optional[dict] = None, robot: Optional[str] = None, task_args=()) -> dict:
  """``tasks.make`` keywords for a command: ``trained``, the task overrides a checkpoint policy was trained
  with (:func:`policy_task_kwargs`: its obs_mode …, so the env matches the policy), then ``--task-arg``
  items and ``--robot``. A trained value of what the policy sees and moves (:data:`POLICY_INTERFACE`: its
  observation layout, its robot) cannot be changed (``ValueError`` naming the flag); the others can (where an
  episode starts, the counter …: scoring a policy in another setting is what they are for); everything is
  checked by :func:`make_task`."""
  out = dict(trained or {})
  given = tasks.parse_task_args(task_args)
  if robot is not None:
    if "robot" in given and given["robot"] != robot:
      raise ValueError(f"--robot: {robot!r} disagrees with --task-arg robot={given['robot']!r}")
    given["robot"] = robot
  if given and task in BUILTIN_TASKS:
    flag = "--robot" if list(given) == ["robot"] else "--task-arg"
    raise ValueError(f"{flag}: built-in scene {task!r} takes no task arguments")
  for key, value in given.items():
    if key in out and out[key] != value and key in POLICY_INTERFACE:
      flag = "--robot" if key == "robot" and robot is not None else "--task-arg"
      raise ValueError(f"{flag}: the checkpoint was trained with {key}={out[key]!r}; got {value!r}")
  return {**out, **given}


def policy_task_kwargs(policy_spec: str, task: str) -> dict:
  """Task overrides the policy needs: a checkpoint's (:func:`checkpoint_task_kwargs`), else none."""
  kind, _ = parse_policy_spec(policy_spec)
  return checkpoint_task_kwargs(policy_spec, task) if kind == "checkpoint" else {}


def checkpoint_task_kwargs(policy_spec: str, task: str) -> dict:
  """Task overrides a checkpoint's policy runs with (its obs_mode …), so the env matches the policy: those its
  run was evaluated with where it recorded them (``eval_task_kwargs``: trained from a wider start
  distribution, scored from the task's own, e.g. Shelve Item's ``start="route"``), else its training ones."""
  path = checkpoint_path(policy_spec)
  file = ckpt.file_of(path)
  try:
    meta = ckpt.read_meta(file)
  except Exception as e:  # not a readable checkpoint
    raise ValueError(f"policy: cannot read checkpoint {file!r} ({e})") from e
  if meta.get("task") not in (None, task):
    raise ValueError(f"policy: checkpoint {path!r} was trained on task {meta['task']!r}, not {task!r}")
  kwargs = meta.get("eval_task_kwargs") or meta.get("task_kwargs")
  return tasks.stored_kwargs(task, kwargs)  # an older checkpoint names no robot: the gripper


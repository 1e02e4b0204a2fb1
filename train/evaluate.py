"""Policy evaluation: N episodes in one compiled call, DAMAGE_MODEL.md §7 metrics.

Python API::

    from train.evaluate import evaluate, make_policy, make_task
    env = make_task("place_plate")
    result = evaluate(env, make_policy("scripted:safe", env), episodes=256, seed=0)
    result["metrics"]["safe_completion"]

    # a task name / env instance and a trained policy → the flat summary
    # (``train.evaluate_policy``; what training logs as ``eval/<key>``)
    from train.evaluate import evaluate_policy
    evaluate_policy("place_plate", train.load_policy(run_dir), num_episodes=1024)["safe_completion"]

One call = ``jit(vmap over episodes of lax.scan over the episode length)``;
an episode stops counting at its first ``done`` (its state is frozen there).
Every episode can carry its own fragility factor (thresholds ÷ f, scales × f,
:meth:`DamageParams.with_fragility`), applied to ``info["damage_state"].params``
right after reset, so evaluating another fragility level — or many at once,
as :mod:`train.sweep` does — reuses the same executable. A policy with weights
(``policy.apply(params, state, rng)`` and ``policy.params``, as
:func:`train.load_policy` and :func:`parametrized_policy` give) gets them as a
traced argument: new weights (training's periodic evaluation) reuse it too.
Episodes are sharded over all local devices (1-D mesh,
:class:`jax.sharding.NamedSharding`).

This module is the one place evaluation episodes are rolled out and
summarised: the ``mjx-damage eval`` CLI, :mod:`train.sweep`, training's
periodic and final evaluation (:mod:`train.ppo`) and :func:`evaluate_policy`.

CLI: ``mjx-damage eval --task TASK --policy SPEC --episodes N [--fragility F]
[--seed S] [--out result.json]``; policy specs: ``scripted:safe``,
``scripted:unsafe``, ``random``, ``zero``, ``checkpoint:PATH``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from typing import Callable, Optional, Sequence

import numpy as np

Policy = Callable  # policy(state, rng) -> action f32[action_size], one env, jittable

POLICY_SPECS = ("scripted:safe", "scripted:unsafe", "random", "zero", "checkpoint:PATH")
DEFAULT_PERCENTILES = (50.0, 90.0, 95.0)
# Built-in tasks usable before/without the task registry: the core demo scene
# (no actions) and the benchmark's pusher scene (2-D action), with their
# episode lengths in env steps.
BUILTIN_TASKS = {"drop": 50, "push_boxes": 50}


# --- tasks ----------------------------------------------------------------------

def _registry():
  try:
    import tasks
  except ImportError:
    return None
  return tasks if hasattr(tasks, "names") and hasattr(tasks, "make") else None


def task_names() -> list[str]:
  """Every name :func:`make_task` accepts: the registry's tasks and the built-ins."""
  reg = _registry()
  names = list(reg.names()) if reg is not None else []
  return names + [n for n in BUILTIN_TASKS if n not in names]


def check_task(name) -> str:
  if not isinstance(name, str) or name not in task_names():
    raise ValueError(f"task: unknown task {name!r}; tasks: {', '.join(task_names())}")
  return name


def make_task(name: str, **overrides):
  """A DamageWrapper-wrapped env by name (registry first, then the built-ins)."""
  check_task(name)
  reg = _registry()
  if reg is not None and name in reg.names():
    return reg.make(name, **overrides)
  from mjx_damage.wrapper import DamageWrapper

  if name == "drop":
    from mjx_damage.demo import DropEnv

    return DamageWrapper(DropEnv(**overrides))
  from mjx_damage.bench import table_env

  return DamageWrapper(table_env(**{"k": 4, **overrides}))


def episode_length_of(env, task: Optional[str] = None) -> int:
  """Episode length in env steps: the env's ``episode_length``, the registry's default, or a built-in's."""
  n = getattr(env, "episode_length", None)
  reg = _registry()
  if n is None and task is not None and reg is not None and hasattr(reg, "default_config"):
    try:
      n = reg.default_config(task).get("episode_length")
    except (ValueError, KeyError):
      n = None
  if n is None and task in BUILTIN_TASKS:
    n = BUILTIN_TASKS[task]
  if n is None:
    raise ValueError("episode_length: the env defines none; pass episode_length explicitly")
  return int(n)


# --- policies -------------------------------------------------------------------

def parse_policy_spec(spec) -> tuple[str, Optional[str]]:
  """``"scripted:safe"`` → ("scripted", "safe"); checks the spec's form (no env needed)."""
  if not isinstance(spec, str):
    raise ValueError(f"policy: expected a spec string ({', '.join(POLICY_SPECS)}), got {spec!r}")
  kind, _, arg = spec.partition(":")
  if kind in ("random", "zero") and not arg:
    return kind, None
  if kind == "scripted" and arg in ("safe", "unsafe"):
    return kind, arg
  if kind == "checkpoint" and arg:
    if not os.path.exists(arg):
      raise ValueError(f"policy: checkpoint {arg!r} does not exist")
    return kind, arg
  raise ValueError(f"policy: unknown policy {spec!r}; expected one of {', '.join(POLICY_SPECS)}")


def random_policy(action_size: int) -> Policy:
  """Uniform actions in [−1, 1]^action_size (Brax's normalised action range)."""
  import jax

  def policy(state, rng):
    return jax.random.uniform(rng, (action_size,), minval=-1.0, maxval=1.0)

  return policy


def parametrized_policy(apply: Callable, params) -> Policy:
  """``policy(state, rng) = apply(params, state, rng)`` whose weights an :class:`Evaluator` passes as data.

  ``params=None``: no default weights; give them to every :meth:`Evaluator.run`.
  """
  def policy(state, rng):
    return apply(params, state, rng)

  policy.apply, policy.params = apply, params
  return policy


def zero_policy(action_size: int) -> Policy:
  import jax.numpy as jnp

  def policy(state, rng):
    return jnp.zeros((action_size,), jnp.float32)

  return policy


def make_policy(spec: str, env) -> Policy:
  """A ``policy(state, rng) -> action`` for one env of ``env`` from a spec string."""
  kind, arg = parse_policy_spec(spec)
  if kind == "random":
    return random_policy(env.action_size)
  if kind == "zero":
    return zero_policy(env.action_size)
  if kind == "scripted":
    reg = _registry()
    if reg is None or not hasattr(reg, "scripted_policy"):
      raise ValueError(f"policy: {spec!r} needs the task registry's scripted_policy, which is unavailable")
    return reg.scripted_policy(env, arg)
  try:
    import train

    load = train.load_policy
  except (ImportError, AttributeError):
    raise ValueError(f"policy: {spec!r} needs train.load_policy, which is unavailable") from None
  return load(arg, env)


# --- the compiled rollout -----------------------------------------------------

def episode_keys(seed: int, episodes: int):
  """PRNG key per episode, u32[episodes, 2]; episode i splits its key into (reset, actions)."""
  import jax

  return jax.random.split(jax.random.PRNGKey(seed), episodes)


def with_fragility(state, factor):
  """``state`` (one env, right after reset) with its damage parameters at fragility ``factor``.

  Sets both ``info["damage_state"]`` and ``info["damage_initial"]`` (the
  wrapper restores the latter at an auto-reset). ``factor`` f32[] may be traced.
  """
  info = dict(state.info)
  for key in ("damage_state", "damage_initial"):
    ds = info[key]
    info[key] = ds.replace(params=ds.params.with_fragility(factor))
  return state.replace(info=info)


def run_episode(env, policy: Policy, episode_length: int, key, fragility):
  """One episode (one env, pure, jittable): reset, fragility, ``episode_length`` steps.

  Returns the per-episode summary: completed, cost, damaged, length f32[];
  entity_health f32[N] (final, 0–100); success_final f32[]; task_return f32[]
  (sum of ``info["task_reward"]``, the env's reward before damage shaping).
  """
  import jax
  import jax.numpy as jnp

  reset_key, act_key = jax.random.split(key)
  state = with_fragility(env.reset(reset_key), fragility)

  def body(carry, t):
    state, done, ret = carry
    action = policy(state, jax.random.fold_in(act_key, t))
    nxt = env.step(state, action)
    ret = ret + jnp.where(done > 0, 0.0, nxt.info.get("task_reward", nxt.reward))
    # freeze finished episodes: their final state is the one at termination
    state = jax.tree.map(lambda a, b: jnp.where(done > 0, b, a), nxt, state)
    return (state, jnp.maximum(done, nxt.done), ret), None

  done0 = jnp.zeros((), state.done.dtype)
  ret0 = jnp.zeros((), jnp.float32)
  (state, _, ret), _ = jax.lax.scan(body, (state, done0, ret0), jnp.arange(episode_length))
  return dict(summary(state), task_return=ret)


def summary(state) -> dict:
  """Per-episode numbers read from a final state (DAMAGE_MODEL.md §7 inputs)."""
  ep = state.info["damage_episode"]
  return {
      "completed": ep["completed"],
      "cost": ep["cost"],
      "damaged": ep["damaged"],
      "length": ep["length"],
      "entity_health": state.info["entity_health"],
      "success_final": state.metrics.get("success", ep["completed"] * 0.0),
  }


class Evaluator:
  """A compiled evaluator of one (env, policy, episode length): call it for any seed/fragility.

  The executable depends on the batch size only; seeds, fragility factors and
  the policy's weights are data. A policy with ``.apply(params, state, rng)``
  and ``.params`` (:func:`parametrized_policy`, :func:`train.load_policy`) is
  run as ``apply`` with its weights passed in (``run(..., params=)`` swaps
  them); any other ``policy(state, rng)`` is closed over. ``devices``
  (default: all local devices) shard the episode axis.
  """

  def __init__(self, env, policy: Policy, episode_length: int, devices: Optional[Sequence] = None):
    import jax
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    if isinstance(episode_length, bool) or not isinstance(episode_length, int) or episode_length < 1:
      raise ValueError(f"episode_length: must be an int >= 1, got {episode_length!r}")
    self.env, self.policy, self.episode_length = env, policy, episode_length
    apply = getattr(policy, "apply", None)
    if apply is None:
      apply, self.params = (lambda _, state, rng: policy(state, rng)), ()
    else:
      self.params = policy.params
    self.devices = list(devices) if devices is not None else jax.devices()
    self.mesh = Mesh(np.array(self.devices), ("episodes",))
    self.sharding = NamedSharding(self.mesh, PartitionSpec("episodes"))
    self.replicated = NamedSharding(self.mesh, PartitionSpec())

    def one(params, key, fragility):
      return run_episode(env, lambda state, rng: apply(params, state, rng), episode_length, key, fragility)

    batched = jax.vmap(one, in_axes=(None, 0, 0))
    self._fn = jax.jit(batched, in_shardings=(self.replicated, self.sharding, self.sharding),
                       out_shardings=self.sharding)

  @property
  def num_compiled(self) -> int:
    """Executables compiled so far (one per distinct padded batch size)."""
    return self._fn._cache_size()

  def run(self, keys, fragility, params=None) -> dict:
    """Per-episode summaries (numpy, leading axis = episodes) for keys u32[E, 2] and fragility f32[E].

    ``params``: the policy's weights for this call (default: ``policy.params``).
    """
    import jax

    params = self.params if params is None else params
    if params is None:
      raise ValueError("params: the policy has no default weights; pass params=")

    # host-side preparation in numpy: no eager JAX ops, hence no compilations
    # besides the evaluator's own (the no-recompile test counts them all)
    keys = np.asarray(keys)
    e = keys.shape[0]
    n = len(self.devices)
    pad = (-e) % n  # pad to a multiple of the devices by repeating the last episode
    fragility = np.broadcast_to(np.asarray(fragility, np.float32), (e,))
    if pad:
      keys = np.concatenate([keys, np.repeat(keys[-1:], pad, 0)])
      fragility = np.concatenate([fragility, np.repeat(fragility[-1:], pad, 0)])
    keys = jax.device_put(keys, self.sharding)
    fragility = jax.device_put(np.ascontiguousarray(fragility), self.sharding)
    params = jax.device_put(params, self.replicated)
    out = jax.block_until_ready(self._fn(params, keys, fragility))
    return jax.tree.map(lambda x: np.asarray(x)[:e], out)


# --- metrics --------------------------------------------------------------------

def metrics(per_episode: dict, entity_names: Sequence[str], safe_threshold: float = 95.0,
            percentiles: Sequence[float] = DEFAULT_PERCENTILES) -> dict:
  """DAMAGE_MODEL.md §7 aggregates over episodes (fractions in [0, 1], health 0–100, cost in health points).

  safe completion = completed and every tracked entity's final health > ``safe_threshold``;
  zero-damage = no damage at any step; ``min_env_health`` = mean over episodes of the
  lowest final entity health; ``task_return`` (when the episodes carry it) = mean
  undiscounted task reward.
  """
  comp = per_episode["completed"] > 0
  health = per_episode["entity_health"]  # [E, N]
  safe = comp & np.all(health > safe_threshold, axis=-1)
  cost = per_episode["cost"].astype(np.float64)
  out = {
      "episodes": int(comp.shape[0]),
      "completion": float(comp.mean()),
      "safe_completion": float(safe.mean()),
      "safe_threshold": float(safe_threshold),
      "avg_health": float(health.mean()),
      "min_env_health": float(health.min(axis=-1).mean()),
      "zero_damage_rate": float((per_episode["damaged"] <= 0).mean()),
      "cost_mean": float(cost.mean()),
      "cost_std": float(cost.std()),
      "cost_percentiles": {f"p{p:g}": float(np.percentile(cost, p)) for p in percentiles},
      "mean_length": float(per_episode["length"].mean()),
      "entity_health": {n: float(health[:, i].mean()) for i, n in enumerate(entity_names)},
      "entity_health_min": {n: float(health[:, i].min()) for i, n in enumerate(entity_names)},
  }
  if "task_return" in per_episode:
    out["task_return"] = float(np.mean(per_episode["task_return"], dtype=np.float64))
  return out


# The flat summary (scalars only) that training logs as ``eval/<key>`` and that
# benchmarks/place_plate_rl.py reports: summary key → :func:`metrics` key.
SUMMARY_KEYS = {
    "completion": "completion",
    "safe_completion": "safe_completion",
    "avg_env_health": "avg_health",
    "min_env_health": "min_env_health",
    "episode_cost": "cost_mean",
    "zero_damage_rate": "zero_damage_rate",
    "task_return": "task_return",
    "episode_length": "mean_length",
    "episodes": "episodes",
}


def scalar_metrics(m: dict) -> dict:
  """:func:`metrics` output → the flat summary of :data:`SUMMARY_KEYS` (keys it lacks are left out)."""
  return {k: m[v] for k, v in SUMMARY_KEYS.items() if v in m}


def check_args(episodes, fragility, safe_threshold, percentiles=DEFAULT_PERCENTILES, seed=0) -> None:
  """Reject bad arguments with ``ValueError`` naming the field (before anything compiles)."""
  from mjx_damage.randomize import check_fragility

  if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
    raise ValueError(f"episodes: must be an int >= 1, got {episodes!r}")
  if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
    raise ValueError(f"seed: must be an int >= 0, got {seed!r}")
  if np.ndim(fragility) == 0:
    check_fragility(fragility)
  else:
    vals = check_fragility(list(np.asarray(fragility, np.float64).ravel()))
    if len(vals) != episodes:
      raise ValueError(f"fragility: give one factor or one per episode ({episodes}), got {len(vals)}")
  if isinstance(safe_threshold, bool) or not isinstance(safe_threshold, (int, float)) or not 0 <= safe_threshold <= 100:
    raise ValueError(f"safe_threshold: must be a number in [0, 100], got {safe_threshold!r}")
  for p in percentiles:
    if not 0 <= p <= 100:
      raise ValueError(f"percentiles: each must be in [0, 100], got {p!r}")


def evaluate(env, policy: Policy, episodes: int, seed: int = 0, *, fragility=1.0,
             episode_length: Optional[int] = None, safe_threshold: float = 95.0,
             percentiles: Sequence[float] = DEFAULT_PERCENTILES, devices: Optional[Sequence] = None,
             task: Optional[str] = None) -> dict:
  """Evaluate ``policy`` on ``env`` for ``episodes`` episodes in one compiled call.

  Args:
    env: a DamageWrapper-wrapped Brax env.
    policy: ``policy(state, rng) -> action`` for one env (jittable).
    episodes: N >= 1. seed: episode i uses ``episode_keys(seed, N)[i]``.
    fragility: f > 0, one factor or f32[N] (one per episode).
    episode_length: env steps per episode (default: the env's / task's).
    safe_threshold: final entity health above which a completed episode is safe.
    devices: devices to shard the episodes over (default all local devices).

  Returns:
    {"metrics": :func:`metrics`, "per_episode": numpy arrays, "compile_s", "run_s"}.
  """
  check_args(episodes, fragility, safe_threshold, percentiles, seed)
  T = episode_length if episode_length is not None else episode_length_of(env, task)
  ev = Evaluator(env, policy, T, devices)
  t0 = time.perf_counter()
  per_ep = ev.run(episode_keys(seed, episodes), fragility)
  run_s = time.perf_counter() - t0
  return {
      "metrics": metrics(per_ep, env.entity_names, safe_threshold, percentiles),
      "per_episode": per_ep,
      "episode_length": T,
      "devices": len(ev.devices),
      "seconds": run_s,
  }


def evaluate_policy(task, policy: Policy, *, num_episodes: int = 1024, episode_length: Optional[int] = None,
                    seed: int = 0, task_kwargs: Optional[dict] = None, fragility=1.0,
                    devices: Optional[Sequence] = None) -> dict:
  """:func:`evaluate` for a task as training takes it, returning the flat summary (:func:`scalar_metrics`).

  ``task``: a registered task name, an env class path or a Brax env
  (:func:`train.ppo.resolve_task`); ``policy(state, rng) -> action`` for one
  env, e.g. :func:`train.load_policy` (its weights are passed as data). The
  episode length defaults to the task's; safe completion uses the env's
  DamageWrapper threshold. Exported as ``train.evaluate_policy``.
  """
  from train import ppo

  for name, v in (("num_episodes", num_episodes), ("episode_length", episode_length)):
    if v is None and name == "episode_length":
      continue
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
      raise ValueError(f"{name}: must be a positive integer, got {v!r}")
  env, _ = ppo.resolve_task(task, task_kwargs)
  res = evaluate(env, policy, int(num_episodes), seed, fragility=fragility,
                 episode_length=int(episode_length or ppo.task_episode_length(env)),
                 safe_threshold=ppo.safe_threshold_of(env), devices=devices)
  return scalar_metrics(res["metrics"])


# --- CLI ------------------------------------------------------------------------

def format_table(m: dict, title: str = "") -> str:
  """Human-readable table of :func:`metrics` output."""
  rows = [
      ("episodes", f"{m['episodes']}"),
      ("completion (C)", f"{100 * m['completion']:.1f} %"),
      (f"safe completion (SC, health > {m['safe_threshold']:g})", f"{100 * m['safe_completion']:.1f} %"),
      ("average environment health", f"{m['avg_health']:.2f}"),
      ("zero-damage rate", f"{100 * m['zero_damage_rate']:.1f} %"),
      ("episode cost mean ± std", f"{m['cost_mean']:.3f} ± {m['cost_std']:.3f}"),
  ]
  rows += [(f"episode cost {k}", f"{v:.3f}") for k, v in m["cost_percentiles"].items()]
  rows += [("mean episode length (steps)", f"{m['mean_length']:.1f}")]
  rows += [(f"final health: {n} (mean / min)", f"{v:.2f} / {m['entity_health_min'][n]:.2f}")
           for n, v in m["entity_health"].items()]
  w = max(len(r[0]) for r in rows)
  lines = [title] if title else []
  lines += [f"{k:<{w}}  {v}" for k, v in rows]
  return "\n".join(lines)


def _jsonable(x):
  if isinstance(x, dict):
    return {k: _jsonable(v) for k, v in x.items()}
  if isinstance(x, np.ndarray):
    return x.tolist()
  if isinstance(x, (np.floating, np.integer)):
    return x.item()
  return x


def build_parser() -> argparse.ArgumentParser:
  ap = argparse.ArgumentParser(prog="mjx-damage eval", description="Evaluate a policy on a task for N episodes.")
  ap.add_argument("--task", required=True, help="task name (registry tasks, or built-in: drop, push_boxes)")
  ap.add_argument("--policy", required=True, help="scripted:safe | scripted:unsafe | random | zero | checkpoint:PATH")
  ap.add_argument("--episodes", type=int, default=64)
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--fragility", type=float, default=1.0, help="thresholds ÷ f, scales × f (default 1)")
  ap.add_argument("--episode-length", type=int, default=None, help="env steps (default: the task's)")
  ap.add_argument("--safe-threshold", type=float, default=95.0)
  ap.add_argument("--out", default=None, help="write the result as JSON here")
  ap.add_argument("--per-episode", action="store_true", help="include per-episode arrays in the JSON")
  return ap


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:  # everything the user gave is checked before a task is built or compiled
    check_task(args.task)
    parse_policy_spec(args.policy)
    check_args(args.episodes, args.fragility, args.safe_threshold, seed=args.seed)
    if args.episode_length is not None and args.episode_length < 1:
      raise ValueError(f"episode_length: must be >= 1, got {args.episode_length}")
  except ValueError as e:
    ap.error(str(e))
  env = make_task(args.task)
  policy = make_policy(args.policy, env)
  t0 = time.perf_counter()
  res = evaluate(env, policy, args.episodes, args.seed, fragility=args.fragility,
                 episode_length=args.episode_length, safe_threshold=args.safe_threshold, task=args.task)
  wall = time.perf_counter() - t0
  title = (f"{args.task} / {args.policy}: {args.episodes} episodes x {res['episode_length']} steps, "
           f"fragility {args.fragility:g}, seed {args.seed}, {res['devices']} device(s), {wall:.1f} s incl. compile")
  print(format_table(res["metrics"], title))
  if args.out:
    out = {
        "task": args.task, "policy": args.policy, "episodes": args.episodes, "seed": args.seed,
        "fragility": args.fragility, "episode_length": res["episode_length"],
        "command": "mjx-damage eval " + " ".join(sys.argv[1:] if argv is None else argv),
        "metrics": res["metrics"], "wall_s": wall,
    }
    if args.per_episode:
      out["per_episode"] = _jsonable(res["per_episode"])
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
      json.dump(out, f, indent=1)
    print(f"wrote {args.out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""Policy evaluation: N episodes in one compiled call, DAMAGE_MODEL.md §7 metrics.

Python API::

    import tasks
    from train.evaluate import evaluate
    env = tasks.make("place_plate")
    result = evaluate(env, tasks.scripted_policy(env, "safe"), episodes=256, seed=0)
    result["metrics"]["safe_completion"]

A task name and a trained policy → the flat summary that training logs as
``eval/<key>``: ``train.evaluate_policy`` (:mod:`train.task_eval`).

One call = ``jit(vmap over episodes of lax.scan over the episode length)``;
an episode stops counting at its first ``done`` (its state is frozen there).
Every episode can carry its own fragility factor (thresholds ÷ f, scales × f,
:meth:`DamageParams.with_fragility`), applied to ``info["damage_state"].params``
right after reset, so evaluating another fragility level — or many at once,
as :mod:`train.sweep` does — reuses the same executable. A policy with weights
(``policy.apply(params, state, rng)`` and ``policy.params``, as
:func:`train.load_policy` and :func:`parametrized_policy` give) gets them as a
traced argument: new weights (training's periodic evaluation) reuse it too.
Episodes are sharded over all devices (1-D mesh,
:class:`jax.sharding.NamedSharding`): the local ones, or with several
processes (:mod:`train.distributed`) every process's, each process passing
the same keys. Each device rolls out its share with the one-device program
under ``shard_map`` (no cross-device traffic until the summaries are
gathered), which is what makes the sweep scale with the devices.

This module is the one place evaluation episodes are rolled out and
summarised: the ``mjx-damage eval`` CLI (:mod:`apps.eval_cli`), :mod:`train.sweep`,
training's periodic and final evaluation and ``train.evaluate_policy``. It takes
an env and a ``policy(state, rng)``: it knows no trainer and resolves no names
(task and policy names: :mod:`apps.resolve`).
"""

from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from mjx_damage import program_cache, warp_step
from mjx_damage.native_batch import NativeBatchEnv
from mjx_damage.randomize import check_fragility
from train import memory as MEM
from train import mesh as MESH

Policy = Callable  # policy(state, rng) -> action f32[action_size], one env, jittable

DEFAULT_PERCENTILES = (50.0, 90.0, 95.0)


# --- episode length, policies ---------------------------------------------------

def env_episode_length(env) -> int:
  """The env's own ``episode_length`` (Brax wrappers forward the attribute); ValueError without one."""
  n = getattr(env, "episode_length", None)
  if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
    raise ValueError("episode_length: the env defines none; pass episode_length explicitly")
  return int(n)


def random_policy(action_size: int) -> Policy:
  """Uniform actions in [−1, 1]^action_size (Brax's normalised action range)."""
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
  def policy(state, rng):
    return jnp.zeros((action_size,), jnp.float32)

  return policy


# --- the compiled rollout -----------------------------------------------------

def episode_keys(seed: int, episodes: int):
  """PRNG key per episode, u32[episodes, 2]; episode i splits its key into (reset, actions)."""
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
  reset_key, act_key = jax.random.split(key)
  state = with_fragility(env.reset(reset_key), fragility)

  def body(carry, t):
    state, done, ret = carry
    action = policy(state, jax.random.fold_in(act_key, t))
    nxt = env.step(state, action)
    ret = ret + jnp.where(done > 0, 0.0, nxt.info.get("task_reward", nxt.reward))
    # freeze finished episodes: their final state is the one at termination
    state = warp_step.freeze(done > 0, state, nxt)
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
      "physics_diverged": ep.get("physics_diverged", ep["completed"] * 0.0),
      "contacts_dropped": ep.get("contacts_dropped", ep["completed"] * 0.0),
  }


class Evaluator:
  """A compiled evaluator of one (env, policy, episode length): call it for any seed/fragility.

  The executable depends on the batch size only; seeds, fragility factors and
  the policy's weights are data. A policy with ``.apply(params, state, rng)``
  and ``.params`` (:func:`parametrized_policy`, :func:`train.load_policy`) is
  run as ``apply`` with its weights passed in (``run(..., params=)`` swaps
  them); any other ``policy(state, rng)`` is closed over. ``devices``
  (default: all devices, ``jax.devices()``) shard the episode axis.

  ``program``: a JSON-able description that names *everything* the rolled-out
  function depends on (task and its overrides, policy spec, checkpoint config …;
  the CLI builds it from names). With it, the traced program is kept on disk by
  :mod:`mjx_damage.program_cache` (keyed also by the sources under
  ``program_roots``), so the next process skips tracing. Without it (the Python
  API, arbitrary closures) the program is traced in every process.
  """

  def __init__(self, env, policy: Policy, episode_length: int, devices: Optional[Sequence] = None,
               program: Optional[dict] = None, program_roots: Sequence[str] = ()):
    if isinstance(episode_length, bool) or not isinstance(episode_length, int) or episode_length < 1:
      raise ValueError(f"episode_length: must be an int >= 1, got {episode_length!r}")
    self.env, self.policy, self.episode_length = env, policy, episode_length
    apply = getattr(policy, "apply", None)
    if apply is None:
      apply, self.params = (lambda _, state, rng: policy(state, rng)), ()
    else:
      self.params = policy.params
    self.devices = list(devices) if devices is not None else jax.devices()
    MESH.use_gspmd(len(self.devices))  # jaxlib 0.11.2's Shardy export segfaults on multi-GPU shard_map
    self.mesh = Mesh(np.array(self.devices), ("episodes",))
    self.sharding = NamedSharding(self.mesh, PartitionSpec("episodes"))
    self.replicated = NamedSharding(self.mesh, PartitionSpec())

    def one(params, key, fragility):
      return run_episode(env, lambda state, rng: apply(params, state, rng), episode_length, key, fragility)

    # shard_map, not GSPMD over a sharded batch: MJX's solver loops stop on a test reduced over the
    # whole batch, which GSPMD turns into a cross-device all-reduce per solver iteration of every
    # substep; here each device runs the one-device program on its own episodes (as train.mesh).
    # check_vma=False: MJX's lax.cond over batch-varying values fails shard_map's type check.
    batched = jax.shard_map(jax.vmap(one, in_axes=(None, 0, 0)), mesh=self.mesh,
                            in_specs=(PartitionSpec(), PartitionSpec("episodes"), PartitionSpec("episodes")),
                            out_specs=PartitionSpec("episodes"), check_vma=False)
    # Replicated out: every process (several hosts: train.distributed) reads all episodes' summaries.
    self._fn = jax.jit(batched, in_shardings=(self.replicated, self.sharding, self.sharding),
                       out_shardings=self.replicated)
    self.program = None if program is None else dict(program, episode_length=episode_length,
                                                         devices=len(self.devices))
    self.program_roots = tuple(program_roots)
    self._programs = {}  # argument shapes -> the cached program's callable
    self.program_source = None  # after run(): "loaded" / "exported" / "off" (None: no program cache asked)

  @property
  def num_compiled(self) -> int:
    """Executables compiled so far (one per distinct padded batch size)."""
    return self._fn._cache_size() + sum(f._cache_size() for f in self._programs.values())

  def _callable(self, args):
    if self.program is None:
      return self._fn
    shapes = str(jax.tree.map(lambda x: (jnp.shape(x), str(jnp.result_type(x))), args))
    if shapes not in self._programs:
      self._programs[shapes], self.program_source = program_cache.load_or_export(
          self._fn, args, self.program, self.program_roots)
    return self._programs[shapes]

  def run(self, keys, fragility, params=None) -> dict:
    """Per-episode summaries (numpy, leading axis = episodes) for keys u32[E, 2] and fragility f32[E].

    ``params``: the policy's weights for this call (default: ``policy.params``).
    """
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
    args = (params, keys, fragility)
    out = jax.block_until_ready(self._callable(args)(*args))
    return jax.tree.map(lambda x: np.asarray(x)[:e], out)


class NativeEvaluator:
  """:class:`Evaluator`'s episodes on a :class:`~mjx_damage.native_batch.NativeBatchEnv`.

  The same episode as :func:`run_episode` (keys split into reset/actions, the
  action key folded with t, finished episodes frozen at their first ``done``),
  stepped by the native backend: episodes run ``env.num_envs`` at a time (the
  last group padded by repeating its last episode). Per control step one
  native call (``env.simulate``) and one jitted call that finishes the step,
  freezes finished episodes, runs the policy and computes the next controls.
  ``run`` as :meth:`Evaluator.run`.
  """

  def __init__(self, env: NativeBatchEnv, policy: Policy, episode_length: int):
    if isinstance(episode_length, bool) or not isinstance(episode_length, int) or episode_length < 1:
      raise ValueError(f"episode_length: must be an int >= 1, got {episode_length!r}")
    self.env, self.policy, self.episode_length = env, policy, episode_length
    self.devices = jax.devices()[:1]
    apply = getattr(policy, "apply", None)
    if apply is None:
      apply, self.params = (lambda _, state, rng: policy(state, rng)), ()
    else:
      self.params = policy.params

    def decide(params, state, act_key, t):
      action = jax.vmap(lambda s, k: apply(params, s, jax.random.fold_in(k, t)))(state, act_key)
      return action, env.controls_fn(state, action)

    def start(params, keys, fragility):
      reset_key, act_key = jax.vmap(jax.random.split, out_axes=1)(keys)
      state = jax.vmap(with_fragility)(jax.vmap(env.env.reset)(reset_key), fragility)
      return (state, jnp.zeros(state.done.shape, state.done.dtype), jnp.zeros(state.done.shape, jnp.float32),
              act_key, *decide(params, state, act_key, 0))

    def advance(params, state, done, ret, action, fields, substeps, act_key, t):
      nxt = env.finish_fn(state, action, fields, substeps)
      ret = ret + jnp.where(done > 0, 0.0, nxt.info.get("task_reward", nxt.reward))
      keep = lambda a, b: jnp.where(jnp.reshape(done > 0, done.shape + (1,) * (a.ndim - 1)), b, a)
      state = jax.tree.map(keep, nxt, state)
      return (state, jnp.maximum(done, nxt.done), ret, *decide(params, state, act_key, t + 1))

    self._start = jax.jit(start)
    self._advance = jax.jit(advance)
    self._summary = jax.jit(jax.vmap(summary))

  @property
  def num_compiled(self) -> int:
    """Executables of the per-step call compiled so far (one per batch size: one)."""
    return self._advance._cache_size()

  def run(self, keys, fragility, params=None) -> dict:
    params = self.params if params is None else params
    if params is None:
      raise ValueError("params: the policy has no default weights; pass params=")
    keys = np.asarray(keys)
    e, b = keys.shape[0], self.env.num_envs
    fragility = np.broadcast_to(np.asarray(fragility, np.float32), (e,))
    parts = []
    for lo in range(0, e, b):
      idx = np.minimum(np.arange(lo, lo + b), e - 1)
      state, done, ret, act_key, action, ctrl = self._start(params, keys[idx], fragility[idx])
      for t in range(self.episode_length):
        fields, substeps = self.env.simulate(state, ctrl)
        state, done, ret, action, ctrl = self._advance(params, state, done, ret, action, fields, substeps,
                                                       act_key, t)
      out = dict(self._summary(state), task_return=ret)
      parts.append(jax.tree.map(lambda x: np.asarray(x)[: min(b, e - lo)], out))
    return jax.tree.map(lambda *xs: np.concatenate(xs), *parts)


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
  if "physics_diverged" in per_episode:  # episodes the damage wrapper ended on a non-finite physics step
    out["diverged_episodes"] = int(np.sum(np.asarray(per_episode["physics_diverged"]) > 0))
  if "contacts_dropped" in per_episode:  # episodes with contacts the backend could not read (Warp's places)
    out["contacts_dropped_episodes"] = int(np.sum(np.asarray(per_episode["contacts_dropped"]) > 0))
  return out


# The flat summary (scalars only) that training logs as ``eval/<key>`` and that
# benchmarks/rl_multiseed.py reports: summary key → :func:`metrics` key.
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


def check_memory(env, episodes: int, devices: Optional[Sequence] = None, per_episode_batch: int = 1,
                 available=None) -> None:
  """Refuse (``ValueError`` naming ``episodes``) an evaluation whose estimated memory per device does not
  fit (:mod:`train.memory`; ``env.reset`` is traced, nothing compiles). ``per_episode_batch``: envs
  per requested episode (a sweep runs every episode at each fragility level)."""
  if isinstance(env, NativeBatchEnv):  # host memory: one MjData per native env, no batch-sized buffers
    return
  n_dev = len(devices) if devices is not None else jax.local_device_count()
  per_device = -(-episodes * per_episode_batch // n_dev)
  fp = MEM.footprint(env)
  needed = MEM.eval_bytes(fp.state, per_device, fp.particles)
  MEM.check_fits("episodes", episodes, needed, needed / episodes,
                 MEM.available_bytes() if available is None else available,
                 f"{per_device} env(s) per device")


def make_evaluator(env, policy: Policy, episode_length: int, devices: Optional[Sequence] = None,
                   program: Optional[dict] = None, program_roots: Sequence[str] = ()):
  """:class:`NativeEvaluator` for a :class:`~mjx_damage.native_batch.NativeBatchEnv`, else :class:`Evaluator`
  (``program``/``program_roots``: its traced-program cache; the native path traces per step and keeps none)."""
  if isinstance(env, NativeBatchEnv):
    return NativeEvaluator(env, policy, episode_length)
  return Evaluator(env, policy, episode_length, devices, program, program_roots)


def evaluate(env, policy: Policy, episodes: int, seed: int = 0, *, fragility=1.0,
             episode_length: Optional[int] = None, safe_threshold: float = 95.0,
             percentiles: Sequence[float] = DEFAULT_PERCENTILES, devices: Optional[Sequence] = None,
             program: Optional[dict] = None, program_roots: Sequence[str] = ()) -> dict:
  """Evaluate ``policy`` on ``env`` for ``episodes`` episodes in one compiled call.

  Args:
    env: a DamageWrapper-wrapped Brax env (compiled :class:`Evaluator`), or a
      :class:`~mjx_damage.native_batch.NativeBatchEnv` (native physics, :class:`NativeEvaluator`).
    policy: ``policy(state, rng) -> action`` for one env (jittable).
    episodes: N >= 1. seed: episode i uses ``episode_keys(seed, N)[i]``.
    fragility: f > 0, one factor or f32[N] (one per episode).
    episode_length: env steps per episode (default: the env's ``episode_length``).
    safe_threshold: final entity health above which a completed episode is safe.
    devices: devices to shard the episodes over (default all local devices; MJX only).
    program, program_roots: keep the traced program on disk (:class:`Evaluator`).

  Returns:
    {"metrics": :func:`metrics`, "per_episode": numpy arrays, "compile_s", "run_s"}.
  """
  check_args(episodes, fragility, safe_threshold, percentiles, seed)
  T = episode_length if episode_length is not None else env_episode_length(env)
  check_memory(env, episodes, devices)
  ev = make_evaluator(env, policy, T, devices, program, program_roots)
  t0 = time.perf_counter()
  per_ep = ev.run(episode_keys(seed, episodes), fragility)
  run_s = time.perf_counter() - t0
  return {
      "metrics": metrics(per_ep, env.entity_names, safe_threshold, percentiles),
      "per_episode": per_ep,
      "episode_length": T,
      "devices": len(ev.devices),
      "seconds": run_s,
      "program": getattr(ev, "program_source", None),  # the native evaluator keeps no traced program
  }


# --- reporting ------------------------------------------------------------------

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
  if m.get("diverged_episodes"):  # only when the physics diverged: ended early, not completed
    rows += [("episodes ended by diverged physics", f"{m['diverged_episodes']}")]
  if m.get("contacts_dropped_episodes"):  # only on MuJoCo Warp, when a world had more contacts than its places
    rows += [("episodes with contacts not read for damage (raise warp_contacts)", f"{m['contacts_dropped_episodes']}")]
  rows += [(f"final health: {n} (mean / min)", f"{v:.2f} / {m['entity_health_min'][n]:.2f}")
           for n, v in m["entity_health"].items()]
  w = max(len(r[0]) for r in rows)
  lines = [title] if title else []
  lines += [f"{k:<{w}}  {v}" for k, v in rows]
  return "\n".join(lines)

"""Damage-aware Brax environment wrapper.

``DamageWrapper(env, ...)`` adds to ``state.info``:

* ``link_health`` f32[L], ``entity_health`` f32[N] (100 = intact),
* ``cost`` f32[] — this step's damage in health points, summed over links. With
  ``cost="damage"`` (the default) it is what the models evaluate, all models, even
  beyond the health a link has left (a link at 0 keeps costing, so a CMDP budget sees
  continued abuse of a destroyed object; one hard contact can cost thousands). With
  ``cost="health_lost"`` it is the health the links actually lost this step
  (Σ max(h(t−1) − h(t), 0)): at most 100 per link per step and per episode, so a
  penalised reward stays on the task reward's scale,
* ``damage`` — {"mechanical", "thermal", "fluid"} totals this step, f32[] each,
* ``task_reward`` f32[] — the wrapped env's reward before shaping,
* ``damage_episode`` — running episode statistics (DAMAGE_MODEL.md §7) plus
  ``action_sanitised``, the episode's count of sanitised action entries, and
  ``contacts_dropped``, the most contacts one of its steps could not read for damage
  (``DamageState.contacts_dropped``: MuJoCo Warp's places per world; 0 on MJX-JAX),

and ``metrics["action_sanitised"]`` f32[] (action entries sanitised this step);
it shapes ``reward ← reward − weight·cost``, optionally appends entity health
/ 100 to the observation and ends the episode when an entity's health reaches 0.

**A physics step that diverges ends the episode.** MJX can, very rarely, return
a non-finite state (seen once: within the first 2.6 M env steps per seed of
PPO on shelve_item from a cloned policy). When the new ``qpos``, ``qvel``,
observation, reward, cost or link health is not all finite, the step is marked
``done`` and ``metrics["physics_diverged"] = 1`` (counted per episode in
``damage_episode["physics_diverged"]``); everything a learner or an evaluator
reads stays finite: the observation is the previous one, the reward the
previous task reward, the damage state (and so health) the previous one, the
step's cost 0, the step's success 0 and the task's other metrics 0. The
physics state itself is left as MJX returned it: Brax's ``AutoResetWrapper``
replaces it, and an evaluator freezes the episode at its first ``done``.
Without this, one such step puts NaN into a training batch and the whole run
(every seed of one program) stops.

Two modes:

* **Per substep** — the env steps through :func:`mjx_damage.physics.step`
  (it has a ``damage_binding``, like every task of this project): damage is
  evaluated at every physics substep inside the env.
* **Once per env step (fallback)** — any other Brax env whose
  ``state.pipeline_state`` is an ``mjx.Data``: give ``config`` (and ``model``
  unless the env has ``mj_model`` or ``sys.mj_model``). Its step hides its
  substeps, so damage is evaluated once per env step from the final state's
  contacts, with each link's acceleration taken as the change of its COM
  velocity over the step divided by ``env.dt``. Short impacts between env steps
  can be missed or blurred: prefer the per-substep mode where you can.

Actions are sanitised before they reach the env (:func:`sanitise_action`): a
NaN entry becomes 0, ±inf and any finite entry outside ``action_bounds``
(default [−1, 1], Brax's convention and every task's) are clipped to the
nearest bound. A policy that diverges, or a user who passes 1e3, then moves
the robot as hard as a valid action can, and no NaN reaches the physics.
Valid actions pass through bitwise unchanged.

Episodes are recognised by simulation time (``pipeline_state.time`` returning
to its reset value), so health is restored to 100 under Brax's own
``AutoResetWrapper``, which restores only ``pipeline_state`` and ``obs``.
"""

from __future__ import annotations

from typing import Callable, Optional

import jax
import jax.numpy as jnp
import mujoco
from brax.envs.base import State, Wrapper

from mjx_damage import health as H
from mjx_damage import physics
from mjx_damage.backends.mjx_jax import applied_forces
from mjx_damage.binding import bind
from mjx_damage.kinematics import link_velocity
from mjx_damage.params import DamageParams
from mjx_damage.signals import LinkSignals

ParamsFn = Callable[[jax.Array, DamageParams], DamageParams]

ACTION_BOUNDS = (-1.0, 1.0)
COST_SIGNALS = ("damage", "health_lost")  # what info["cost"] counts (DamageWrapper's cost=)


def sanitise_action(action: jax.Array, lo: float = -1.0, hi: float = 1.0) -> tuple[jax.Array, jax.Array]:
  """Make an action safe to apply: NaN → 0, then everything clipped to [lo, hi].

  Args:
    action: f32[..., A] (one env or a batch).
    lo, hi: finite bounds, lo < hi (a NaN entry maps to 0 clipped into them).

  Returns:
    (action f32[..., A] finite and in [lo, hi], identical to the input where it
    already was; count f32[...] of entries that were NaN, ±inf or out of range).
  """
  a = jnp.asarray(action)
  bad = ~((a >= lo) & (a <= hi))  # NaN compares False: counted
  clean = jnp.clip(jnp.where(jnp.isnan(a), jnp.zeros_like(a), a), lo, hi)
  return clean, jnp.sum(bad, axis=-1).astype(jnp.float32)


def _zero_episode():
  z = jnp.zeros((), jnp.float32)
  return {"completed": z, "cost": z, "length": z, "damaged": z, "action_sanitised": z, "physics_diverged": z,
          "contacts_dropped": z}


def _all_finite(tree) -> jax.Array:
  """bool[]: every entry of every leaf of ``tree`` is finite."""
  return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(tree)]))


def _keep(ok: jax.Array, new, old):
  """``new`` where ``ok``, else ``old`` (two pytrees of one structure)."""
  return jax.tree.map(lambda a, b: jnp.where(ok, a, b), new, old)


class DamageWrapper(Wrapper):
  """Health, cost, damage-penalised reward and termination for a Brax env.

  Args:
    env: a Brax env (``reset``/``step``; ``state.pipeline_state`` an ``mjx.Data``).
    config: damage config (dict or YAML path); required unless ``env`` tracks
      damage itself (has ``damage_binding``).
    model: the scene's ``mujoco.MjModel`` when ``env`` exposes none.
    weight: w ≥ 0 in ``reward − w·cost``.
    terminate_on_destroyed: end the episode when any tracked entity's health is 0.
    health_in_obs: append entity health / 100 (f32[N]) to the observation.
    params_fn: ``(rng, default_params) -> params`` drawn at every reset
      (fragility randomisation); default: the binding's parameters.
    safe_threshold: entity health above which an episode counts as safe.
    action_bounds: (lo, hi) finite, lo < hi: the env's action range; actions
      are sanitised into it (:func:`sanitise_action`).
    cost: what ``info["cost"]`` (and so the penalty and every episode cost) counts:
      ``"damage"``, the models' damage, or ``"health_lost"``, the health the links
      lost (bounded by 100 per link); see the module docstring.
  """

  def __init__(
      self,
      env,
      config=None,
      *,
      model: Optional[mujoco.MjModel] = None,
      weight: float = 0.0,
      terminate_on_destroyed: bool = False,
      health_in_obs: bool = False,
      params_fn: Optional[ParamsFn] = None,
      safe_threshold: float = 95.0,
      action_bounds: tuple[float, float] = ACTION_BOUNDS,
      cost: str = "damage",
  ):
    super().__init__(env)
    if cost not in COST_SIGNALS:
      raise ValueError(f"cost: must be one of {', '.join(COST_SIGNALS)}, got {cost!r}")
    if (not isinstance(action_bounds, (tuple, list)) or len(action_bounds) != 2
        or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) < float("inf")
               for v in action_bounds)
        or not action_bounds[0] < action_bounds[1]):
      raise ValueError(f"action_bounds: must be two finite numbers (lo, hi) with lo < hi, got {action_bounds!r}")
    for name, v in (("weight", weight), ("safe_threshold", safe_threshold)):
      if isinstance(v, bool) or not isinstance(v, (int, float)) or not v == v or v < 0:
        raise ValueError(f"{name}: must be a finite number >= 0, got {v!r}")
    if safe_threshold > H.MAX_HEALTH:
      raise ValueError(f"safe_threshold: must be <= 100, got {safe_threshold!r}")
    inner = getattr(env, "damage_binding", None)
    self.per_substep = inner is not None
    if inner is not None:
      if config is not None:
        raise ValueError("config: this env already tracks damage (it has damage_binding); drop config")
      self.binding = inner
    else:
      if config is None:
        raise ValueError("config: required to wrap an env that does not track damage itself")
      model = model or getattr(env, "mj_model", None) or getattr(getattr(env, "sys", None), "mj_model", None)
      if not isinstance(model, mujoco.MjModel):
        raise ValueError("model: pass the scene's mujoco.MjModel (the env exposes none)")
      self.binding = bind(model, config)
    self.weight = float(weight)
    self.terminate_on_destroyed = bool(terminate_on_destroyed)
    self.health_in_obs = bool(health_in_obs)
    self.params_fn = params_fn
    self.safe_threshold = float(safe_threshold)
    self.action_bounds = (float(action_bounds[0]), float(action_bounds[1]))
    self.cost = cost

  # -- Brax API -------------------------------------------------------------
  @property
  def observation_size(self):
    n = self.env.observation_size
    return n + self.binding.num_entities if self.health_in_obs else n

  @property
  def entity_names(self) -> tuple[str, ...]:
    return self.binding.entity_names

  @property
  def link_names(self) -> tuple[str, ...]:
    return self.binding.link_names

  def reset(self, rng: jax.Array) -> State:
    rng, prng = jax.random.split(rng)
    state = self.env.reset(rng)
    ds = state.info.get("damage_state") if self.per_substep else None
    if ds is None:
      ds = physics.init_state(self.binding, rng=prng)
      ds = ds.replace(link_vel=self._mjx_velocity(state))
    if self.params_fn is not None:
      ds = ds.replace(params=self.params_fn(prng, self.binding.params))
    info = dict(state.info)
    info["damage_state"] = ds
    info["damage_initial"] = ds
    info["damage_t0"] = state.pipeline_state.time
    info.update(self._summaries(ds, jnp.zeros((), jnp.float32)))
    info["task_reward"] = state.reward
    info["damage_episode"] = _zero_episode()
    metrics = dict(state.metrics)
    metrics.update(self._metrics(info))
    metrics["action_sanitised"] = jnp.zeros((), jnp.float32)
    metrics["physics_diverged"] = jnp.zeros((), jnp.float32)
    return state.replace(obs=self._obs(state.obs, info), info=info, metrics=metrics)

  def step(self, state: State, action: jax.Array) -> State:
    info = dict(state.info)
    # Brax's AutoResetWrapper restores pipeline_state but not info: a fresh
    # episode is one whose time is back at its reset value.
    fresh = state.pipeline_state.time <= info["damage_t0"]
    info["damage_state"] = jax.tree.map(
        lambda a, b: jnp.where(fresh, a, b), info["damage_initial"], info["damage_state"]
    )
    episode = jax.tree.map(lambda x: jnp.where(fresh, 0.0, x), info["damage_episode"])
    inner = state.replace(obs=self._strip_obs(state.obs), info=info)
    action, sanitised = sanitise_action(action, *self.action_bounds)
    if self.per_substep:
      nstate = self.env.step(inner, action)
      ds = nstate.info["damage_state"]
    else:
      ds = physics.begin_step(info["damage_state"])
      nstate = self.env.step(inner, action)
      ds = self._fallback_damage(nstate, ds)
    if self.cost == "damage":
      cost = jnp.sum(ds.step_damage.total())
    else:  # the health actually lost: bounded, unlike the damage that caused it
      cost = jnp.sum(jnp.maximum(info["damage_state"].link_health - ds.link_health, 0.0))
    d = nstate.pipeline_state
    ok = (_all_finite(d.qpos) & _all_finite(d.qvel) & _all_finite(nstate.obs) & jnp.isfinite(nstate.reward)
          & jnp.isfinite(cost) & _all_finite(ds.link_health))
    diverged = (~ok).astype(jnp.float32)
    # a diverged step keeps what the learner last saw (module docstring): small selects, not the mjx.Data
    ds = _keep(ok, ds, info["damage_state"])
    ds = ds.replace(step_damage=_keep(ok, ds.step_damage, jax.tree.map(jnp.zeros_like, ds.step_damage)))
    cost = jnp.where(ok, cost, 0.0)
    task_reward = jnp.where(ok, nstate.reward, info["task_reward"])
    success = jnp.where(ok, nstate.metrics.get("success", jnp.zeros((), jnp.float32)), 0.0)
    obs = _keep(ok, nstate.obs, inner.obs)
    info = dict(nstate.info)
    info["damage_state"] = ds
    info.update(self._summaries(ds, cost))
    info["task_reward"] = task_reward
    info["damage_episode"] = {
        "completed": jnp.maximum(episode["completed"], success),
        "cost": episode["cost"] + cost,
        "length": episode["length"] + 1.0,
        "damaged": jnp.maximum(episode["damaged"], (cost > 0).astype(jnp.float32)),
        "action_sanitised": episode["action_sanitised"] + sanitised,
        "physics_diverged": episode["physics_diverged"] + diverged,
        # the most contacts one control step could not read for damage (MuJoCo Warp's places per world)
        "contacts_dropped": jnp.maximum(episode["contacts_dropped"],
                                        jnp.asarray(ds.contacts_dropped, jnp.float32)),
    }
    reward = task_reward - self.weight * cost
    done = jnp.maximum(nstate.done, diverged.astype(nstate.done.dtype))
    if self.terminate_on_destroyed:
      destroyed = jnp.any(info["entity_health"] <= 0.0)
      done = jnp.maximum(done, destroyed.astype(done.dtype))
    metrics = _keep(ok, dict(nstate.metrics), jax.tree.map(jnp.zeros_like, dict(nstate.metrics)))
    metrics.update(self._metrics(info))
    metrics["action_sanitised"] = sanitised
    metrics["physics_diverged"] = diverged
    return nstate.replace(obs=self._obs(obs, info), reward=reward, done=done, info=info, metrics=metrics)

  # -- helpers --------------------------------------------------------------
  def _summaries(self, ds: physics.DamageState, cost):
    b = self.binding
    return {
        "link_health": ds.link_health,
        "entity_health": H.entity_health(ds.link_health, b.link_entity, b.num_entities),
        "cost": cost,
        "damage": {
            "mechanical": jnp.sum(ds.step_damage.mechanical),
            "thermal": jnp.sum(ds.step_damage.thermal),
            "fluid": jnp.sum(ds.step_damage.fluid),
        },
    }

  def _metrics(self, info):
    eh = info["entity_health"]
    return {
        "cost": info["cost"],
        "damage_mechanical": info["damage"]["mechanical"],
        "damage_thermal": info["damage"]["thermal"],
        "damage_fluid": info["damage"]["fluid"],
        "min_entity_health": jnp.min(eh),
        "mean_entity_health": jnp.mean(eh),
        "safe": (jnp.min(eh) > self.safe_threshold).astype(jnp.float32),
    }

  def _obs(self, obs, info):
    if not self.health_in_obs:
      return obs
    return jnp.concatenate([obs, info["entity_health"] / H.MAX_HEALTH], axis=-1)

  def _strip_obs(self, obs):
    if not self.health_in_obs:
      return obs
    return obs[..., : obs.shape[-1] - self.binding.num_entities]

  def _mjx_model(self):
    return getattr(self.env, "sys", None) or getattr(self.env, "mjx_model")

  def _mjx_velocity(self, state):
    return link_velocity(self.binding, state.pipeline_state)

  def _fallback_damage(self, nstate: State, ds: physics.DamageState) -> physics.DamageState:
    d = nstate.pipeline_state
    dt = self.env.dt
    vel = link_velocity(self.binding, d)
    forces, force_link = applied_forces(self.binding, self._mjx_model(), d)
    sig = LinkSignals(
        forces=forces,
        force_link=force_link,
        link_acc=(vel - ds.link_vel) / dt,
        temperature=ds.temperature,
        exposure=ds.exposure,
    )
    return physics.apply_signals(ds, sig, dt).replace(link_vel=vel)

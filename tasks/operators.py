"""Stochastic scripted "operators": mixed-quality demonstrators for imitation learning, no humans.

The paper's demonstrations come from people teleoperating with or without live
health bars (its IL study: "with / without health feedback"). Here an operator
is a family of scripted policies built on each task's own two scripts
(:func:`tasks.scripted_policy` ``"safe"`` and ``"unsafe"``, the safe strategy
and the tempting shortcut), so it exists for every registered task, with no
per-task code. Per episode a key draws the operator's *carefulness*
c ∈ [c_lo, c_hi] and from it (:func:`draw_style`):

* strategy — the shortcut with probability ``0.8·(1 − c)``, else the safe
  script (the strategy carries the task's approach: e.g. shelve_item's low
  sweep vs the lift over the glass, pick_egg's full-force vs gentle close);
* speed — the scripts' position steps × ``1.3 − 0.6·c`` (± 10 % jitter);
  clipped by the env at the robot's max step;
* grip force — ``0.1·(1 − c)`` subtracted from every gripper command (tighter
  targets, i.e. a harder squeeze, for a careless hand);
* noise — Gaussian of std ``0.02 + 0.2·(1 − c)`` added to the position action
  each step, scaled by ``min(1, ‖script's position action‖ / 0.1)`` (hand
  tremor while moving; unscaled, it keeps the hand from ever coming to rest,
  which pour_water's script waits for before tipping); the scripts are
  closed-loop, so they correct it;

then :func:`operator_act` plays the chosen script with those changes.

The study's two conditions (:func:`careful`, :func:`careless`):

* **careful** ("with health feedback"): c ∈ [0.5, 1]; the operator watches
  every entity's health in the state (``info["entity_health"]``, the health
  bar) and, once any entity has lost more than ``feedback_drop`` health
  points, backs off: it abandons the shortcut for the safe script at half
  speed without noise or extra grip for the rest of the episode (health
  never recovers, so the switch latches);
* **careless** ("without health feedback"): c ∈ [0, 0.6], never looks at health.

An :class:`Operator` is data plus two pure functions: ``sample(key) ->
params`` (once per episode) and ``act(params, state, rng) -> action f32[4]``
(every step); :mod:`train.record` records either an operator or any plain
``policy(state, rng)``.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

import tasks
from mjx_damage.health import MAX_HEALTH

CONDITIONS = ("careful", "careless", "mixed")
STEADY_BELOW = 0.1  # position-action norm below which the tremor fades out (the script is settling)


class Style(NamedTuple):
  """One episode's operator parameters, f32[] each (a pytree)."""

  unsafe: jax.Array  # 1 = follow the shortcut script
  speed: jax.Array  # factor on the position action
  grip: jax.Array  # subtracted from the gripper command (−1 closed … +1 open)
  noise: jax.Array  # std of the Gaussian added to the position action while the script moves
  carefulness: jax.Array  # the c the others were drawn from, in [0, 1]


class Operator(NamedTuple):
  """A demonstrator: ``sample(key) -> params`` per episode, ``act(params, state, rng) -> action`` per step."""

  label: str
  sample: Callable
  act: Callable


def draw_style(key: jax.Array, c_lo: float, c_hi: float) -> Style:
  """Draw one episode's :class:`Style` with carefulness c ~ U[c_lo, c_hi] (see the module docstring)."""
  kc, ku, ks = jax.random.split(key, 3)
  c = jax.random.uniform(kc, (), minval=c_lo, maxval=c_hi)
  unsafe = (jax.random.uniform(ku) < 0.8 * (1.0 - c)).astype(jnp.float32)
  speed = (1.3 - 0.6 * c) * jax.random.uniform(ks, (), minval=0.9, maxval=1.1)
  return Style(unsafe=unsafe, speed=speed, grip=0.1 * (1.0 - c), noise=0.02 + 0.2 * (1.0 - c), carefulness=c)


def operator_act(safe, unsafe, style: Style, state, rng, feedback_drop=None) -> jax.Array:
  """Action f32[4] of an operator with ``style`` playing the scripts ``safe``/``unsafe`` (one env).

  ``feedback_drop``: None (no health feedback) or the health loss (points, any
  entity) after which the operator backs off to the safe script, slowly.
  """
  k_safe, k_unsafe, k_noise = jax.random.split(rng, 3)
  use_unsafe = style.unsafe > 0
  speed, grip, noise = style.speed, style.grip, style.noise
  if feedback_drop is not None:
    hurt = jnp.min(state.info["entity_health"]) < MAX_HEALTH - feedback_drop
    use_unsafe = use_unsafe & ~hurt
    speed = jnp.where(hurt, 0.5, speed)
    grip = jnp.where(hurt, 0.0, grip)
    noise = jnp.where(hurt, 0.0, noise)
  a = jnp.where(use_unsafe, unsafe(state, k_unsafe), safe(state, k_safe))
  # the hand shakes while the script moves it and steadies when the script holds still, so the scripts'
  # "arrived and at rest" checks (pour_water's before tipping) still pass; additive while moving, so the
  # demonstrations visit states around the scripts' paths (what a cloned policy needs to recover from)
  moving = jnp.clip(jnp.linalg.norm(a[:3]) / STEADY_BELOW, 0.0, 1.0)
  xyz = a[:3] * speed + moving * noise * jax.random.normal(k_noise, (3,))
  return jnp.clip(jnp.concatenate([xyz, a[3:] - grip]), -1.0, 1.0)


def make_operator(env, c_lo: float, c_hi: float, feedback_drop=None, label: str = "operator") -> Operator:
  """An :class:`Operator` for task env ``env`` (from :func:`tasks.make`) with carefulness in [c_lo, c_hi]."""
  if not 0.0 <= c_lo <= c_hi <= 1.0:
    raise ValueError(f"carefulness: need 0 <= c_lo <= c_hi <= 1, got [{c_lo!r}, {c_hi!r}]")
  if feedback_drop is not None and not 0.0 <= feedback_drop < MAX_HEALTH:
    raise ValueError(f"feedback_drop: must be in [0, 100) health points, got {feedback_drop!r}")
  safe, unsafe = tasks.scripted_policy(env, "safe"), tasks.scripted_policy(env, "unsafe")

  def sample(key):
    return draw_style(key, c_lo, c_hi)

  def act(style, state, rng):
    return operator_act(safe, unsafe, style, state, rng, feedback_drop)

  return Operator(label, sample, act)


def careful(env, feedback_drop: float = 0.5) -> Operator:
  """The "with health feedback" condition: fairly careful, and backs off once damage starts."""
  return make_operator(env, 0.5, 1.0, feedback_drop, label="careful")


def careless(env) -> Operator:
  """The "without health feedback" condition: often takes the shortcut, fast and shaky, blind to health."""
  return make_operator(env, 0.0, 0.6, None, label="careless")


def mixed(env) -> Operator:
  """The whole family, c ~ U[0, 1], no feedback: a realistic mix of safe and unsafe demonstrations."""
  return make_operator(env, 0.0, 1.0, None, label="mixed")


def make(env, condition: str) -> Operator:
  """The operator of ``condition`` (one of :data:`CONDITIONS`) for ``env``."""
  if condition not in CONDITIONS:
    raise ValueError(f"condition: unknown operator {condition!r}; valid: {', '.join(CONDITIONS)}")
  return {"careful": careful, "careless": careless, "mixed": mixed}[condition](env)

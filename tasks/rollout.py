"""Batched, compiled scripted rollouts and the per-episode metrics of DAMAGE_MODEL.md §7.

``rollout_fn(env, policies, length)`` builds ``run(rngs, which) -> EpisodeStats``:
one ``jax.jit(jax.vmap(...))`` of a ``lax.scan`` over the episode, so a whole
batch of randomised episodes — of several policies at once, ``which[b]``
choosing episode b's — is a single compiled call (one compilation per task for
both scripted styles: the policies are cheap next to the physics).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


class EpisodeStats(NamedTuple):
  """Per-episode results, each with a leading batch axis B.

  completed:     f32[B] 1 if the success condition held at some step.
  final_success: f32[B] success at the last step.
  entity_health: f32[B, N] final health per entity (env.entity_names order).
  cost:          f32[B] total damage (health points) over the episode.
  damaged:       f32[B] 1 if any damage occurred.
  any_nan:       f32[B] 1 if an observation or reward was ever non-finite, or the physics
                 diverged (``metrics["physics_diverged"]``: the damage wrapper then keeps them finite).
  damage:        {"mechanical", "thermal", "fluid"}: f32[B] health points lost to each model over the episode.
  """

  completed: jax.Array
  final_success: jax.Array
  entity_health: jax.Array
  cost: jax.Array
  damaged: jax.Array
  any_nan: jax.Array
  damage: dict


MODALITIES = ("mechanical", "thermal", "fluid")


def rollout_fn(env, policies, length: int):
  """``run(rngs u32[B, 2], which i32[B]) -> EpisodeStats``, jitted over a batch of episodes.

  ``env``: a :func:`tasks.make` env; ``policies``: a policy ``(state, rng) -> action``
  for one env, or a sequence of them (episode b runs ``policies[which[b]]``);
  ``length``: control steps per episode.
  """
  if callable(policies):
    policies = (policies,)
  policies = tuple(policies)

  def policy(s, k, which):
    return jax.lax.switch(which, policies, s, k)

  def episode(rng, which):
    r0, rp = jax.random.split(rng)
    state = env.reset(r0)

    def body(carry, k):
      s, nan, dmg = carry
      s = env.step(s, policy(s, k, which))
      bad = ~(jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward)) | (s.metrics["physics_diverged"] > 0)
      dmg = {m: dmg[m] + s.info["damage"][m] for m in MODALITIES}
      return (s, nan | bad, dmg), s.metrics["success"]

    zero = {m: jnp.zeros((), jnp.float32) for m in MODALITIES}
    (state, nan, dmg), succ = jax.lax.scan(body, (state, jnp.zeros((), bool), zero), jax.random.split(rp, length))
    ep = state.info["damage_episode"]
    return EpisodeStats(
        completed=jnp.max(succ),
        final_success=succ[-1],
        entity_health=state.info["entity_health"],
        cost=ep["cost"],
        damaged=ep["damaged"],
        any_nan=nan.astype(jnp.float32),
        damage=dmg,
    )

  return jax.jit(jax.vmap(episode))


def summarise(stats: EpisodeStats, safe_threshold: float = 95.0) -> dict:
  """Batch means (percent where a rate) of :class:`EpisodeStats` as plain floats."""
  eh = jnp.asarray(stats.entity_health)
  safe = jnp.all(eh > safe_threshold, axis=-1)
  return {
      "episodes": int(eh.shape[0]),
      "completion_pct": float(100 * jnp.mean(stats.completed)),
      "safe_completion_pct": float(100 * jnp.mean(stats.completed * safe)),
      "avg_env_health": float(jnp.mean(eh)),
      "zero_damage_pct": float(100 * jnp.mean(1.0 - stats.damaged)),
      "mean_episode_cost": float(jnp.mean(stats.cost)),
      "entity_health_mean": [float(x) for x in jnp.mean(eh, axis=0)],
      "nan_episodes": int(jnp.sum(stats.any_nan)),
      **{f"mean_damage_{m}": float(jnp.mean(stats.damage[m])) for m in MODALITIES},
  }

"""Cost multipliers λ for constrained PPO: plain Lagrangian and PID-Lagrangian, as pure functions.

Problem: maximise E[return] s.t. J_c = E[episode cost] ≤ ĉ. The policy is
trained on ``(r_task − (w + λ)·cost) / (1 + λ)`` (train.iteration) and λ is
updated once per iteration from the measured J_c. All state is one small
pytree (:class:`MultiplierState`, f32[] leaves), so it vmaps over seeds.

* Plain Lagrangian — projected gradient ascent on the dual::

      λ ← clip(λ + lr·(J_c − ĉ), 0, λ_max)

  It integrates the error only, so λ keeps rising while the cost is over budget
  and keeps falling while it is under: it overshoots and oscillates between 0
  and λ_max (the committed place_plate λ curve).

* PID-Lagrangian (Stooke, Achiam & Abbeel 2020, "Responsive Safety in RL by PID
  Lagrangian Methods", Alg. 2) — with error e = J_c − ĉ::

      I ← clip(I + K_I·e, 0, λ_max)                      (integral, anti-windup)
      D = max(J_c − J_c,prev, 0)                          (only a rising cost)
      λ = clip(K_P·e + I + K_D·D, 0, λ_max)

  The P term reacts to the current violation at once and vanishes when it is
  gone (no overshoot from accumulated error); the D term damps a cost on its
  way up. The integral is clipped to [0, λ_max]: without that, a long stretch
  under budget would wind it far negative (or a long violation far above
  λ_max) and λ would stay pinned long after the cost crossed ĉ. With
  K_P = K_D = 0 and K_I = lr this is exactly the plain Lagrangian (I = λ).

* Budget curriculum (``anneal_updates`` > 0, either multiplier): the budget the
  error is measured against starts at the first measured episode cost J_c,0 and
  falls linearly to ĉ over ``anneal_updates`` updates::

      ĉ_t = ĉ + max(J_c,0 − ĉ, 0)·max(1 − t/anneal_updates, 0)

  Why: a near-random policy's episodes cost far more than any useful ĉ (Place
  Plate: ≈ 100 health points against ĉ = 2), so e = J_c − ĉ is huge from the
  first update and λ sits at λ_max before the policy has learnt anything — the
  reward is then dominated by the cost and "hold still" is the best policy
  (benchmarks/results/rl_place_plate_session6.md). Measured against ĉ_t, λ stays
  small while the task is learnt, then tightens the constraint gradually, so the
  policy moves from the cheap-to-find unsafe solution towards the safe one.
"""

from __future__ import annotations

import flax
import jax
import jax.numpy as jnp


@flax.struct.dataclass
class MultiplierState:
  """f32[] each (a leading seed axis when vmapped)."""

  lam: jax.Array  # λ ≥ 0 used to shape the reward
  integral: jax.Array  # I, in units of λ
  prev_cost: jax.Array  # J_c of the previous update (D term)
  has_prev: jax.Array  # 1.0 once prev_cost holds a measurement
  start_cost: jax.Array  # J_c,0: the first measured episode cost (budget curriculum)
  updates: jax.Array  # t: updates with a measurement so far


@flax.struct.dataclass
class MultiplierParams:
  """Traced settings (f32[] each), so runs differing only in these share one compiled program.

  ``kind`` 0: λ fixed at its initial value (penalty / task-only runs);
  1: plain Lagrangian (``ki`` is its lr); 2: PID.
  """

  kind: jax.Array
  budget: jax.Array  # ĉ
  kp: jax.Array
  ki: jax.Array
  kd: jax.Array
  lam_max: jax.Array
  anneal_updates: jax.Array  # budget curriculum length in updates; 0: ĉ from the start


FIXED, LAGRANGIAN, PID = 0.0, 1.0, 2.0


def init(lam0=0.0) -> MultiplierState:
  z = jnp.zeros((), jnp.float32)
  lam0 = jnp.asarray(lam0, jnp.float32)
  return MultiplierState(lam=lam0, integral=lam0, prev_cost=z, has_prev=z, start_cost=z, updates=z)


def effective_budget(state: MultiplierState, p: MultiplierParams):
  """ĉ_t of the budget curriculum (module docstring); ``p.budget`` when it is off or over."""
  frac = jnp.where(p.anneal_updates > 0,
                   jnp.clip(1.0 - state.updates / jnp.maximum(p.anneal_updates, 1.0), 0.0, 1.0), 0.0)
  return p.budget + jnp.maximum(state.start_cost - p.budget, 0.0) * frac


def lagrange_update(lam, episode_cost, budget, lr, lam_max):
  """Projected gradient ascent on the dual: ``clip(λ + lr·(J_c − ĉ), 0, λ_max)``.

  dL/dλ of L(π, λ) = J_r(π) − λ·(J_c(π) − ĉ) is −(J_c − ĉ); the multiplier
  ascends the dual, so it grows while the constraint is violated and shrinks
  — down to the projection at 0 — while it is slack.
  """
  return jnp.clip(lam + lr * (episode_cost - budget), 0.0, lam_max)


def pid_update(state: MultiplierState, episode_cost, budget, kp, ki, kd, lam_max) -> MultiplierState:
  """One PID-Lagrangian step (module docstring). ``episode_cost`` J_c f32[]."""
  err = episode_cost - budget
  integral = jnp.clip(state.integral + ki * err, 0.0, lam_max)
  rise = jnp.where(state.has_prev > 0, jnp.maximum(episode_cost - state.prev_cost, 0.0), 0.0)
  lam = jnp.clip(kp * err + integral + kd * rise, 0.0, lam_max)
  return state.replace(lam=lam, integral=integral, prev_cost=jnp.asarray(episode_cost, jnp.float32),
                       has_prev=jnp.ones((), jnp.float32))


def update(state: MultiplierState, p: MultiplierParams, episode_cost, measured) -> MultiplierState:
  """The step ``p.kind`` selects; unchanged while ``measured`` is 0 (no training episode has ended yet)."""
  episode_cost = jnp.asarray(episode_cost, jnp.float32)
  cur = state.replace(start_cost=jnp.where(state.updates == 0, episode_cost, state.start_cost))
  budget = effective_budget(cur, p)
  plain = lagrange_update(cur.lam, episode_cost, budget, p.ki, p.lam_max)
  plain_state = cur.replace(lam=plain, integral=plain, prev_cost=episode_cost, has_prev=jnp.ones((), jnp.float32))
  pid = pid_update(cur, episode_cost, budget, p.kp, p.ki, p.kd, p.lam_max)
  new = jax.tree.map(lambda a, b: jnp.where(p.kind == PID, a, b), pid, plain_state)
  new = new.replace(updates=cur.updates + 1.0)
  keep = (p.kind == FIXED) | (measured <= 0)
  return jax.tree.map(lambda old, n: jnp.where(keep, old, n), state, new)

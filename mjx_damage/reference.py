"""Reference-style damage pipeline: native MuJoCo + per-entity Python evaluators.

This reproduces how the original OopsieVerse project computes damage, as the
baseline the MJX pipeline is measured against: one ``mujoco.MjData`` (one
environment at a time), and after each physics step every tracked entity's
evaluator object loops in Python over the scene's contacts, asks
``mujoco.mj_contactForce`` for each contact touching one of its links, reads
each link's acceleration with ``mujoco.mj_objectAcceleration`` (after
``mujoco.mj_rnePostConstraint`` fills ``cacc``) and applies the DEM formulas.

It is deliberately *not* vectorised (``mjx_damage.native`` is the fast native
path); it exists to be timed and to cross-check formulas. The formulas and
parameters are the library's: the per-link numbers come from the same
:class:`~mjx_damage.binding.Binding` (``binding.params``), and each substep
runs ``mj_forward`` → damage → integrator, i.e. the same state the MJX step
reads (contacts, constraint forces and ``qacc`` of one consistent forward pass).
"""

from __future__ import annotations

import math
import time
from typing import Callable, Optional, Sequence

import mujoco
import numpy as np

from mjx_damage.binding import Binding
from mjx_damage.health import MAX_HEALTH
from mjx_damage.mechanical import ACC_EPS

AMBIENT_C = 22.0


class EntityEvaluator:
  """Damage evaluator of one entity (its tracked links), OopsieVerse style.

  Holds the entity's body ids and per-link parameters as Python floats and
  evaluates all three DEMs for its links from one ``MjData`` state.
  """

  def __init__(self, model: mujoco.MjModel, binding: Binding, entity: int):
    self.name = binding.entity_names[entity]
    self.links = [int(i) for i in np.nonzero(binding.link_entity == entity)[0]]
    self.bodies = [int(binding.link_body[i]) for i in self.links]
    p = binding.params
    def col(a):
      return [float(np.asarray(a)[i]) for i in self.links]
    self.alpha, self.beta = col(p.alpha), col(p.beta)
    self.e_mech, self.l_mech = col(p.mech_threshold), col(p.mech_scale)
    self.t_hot, self.t_cold, self.l_therm = col(p.t_hot), col(p.t_cold), col(p.thermal_scale)
    self.c_fluid, self.l_fluid = col(p.fluid_threshold), col(p.fluid_scale)
    self.gravity = np.array(model.opt.gravity, np.float64)
    self._f6 = np.zeros(6)
    self._a6 = np.zeros(6)

  def mechanical(self, model: mujoco.MjModel, data: mujoco.MjData) -> list[float]:
    """d_mech per link (health per τ) from ``data`` after ``mj_forward`` + ``mj_rnePostConstraint``."""
    rates = []
    for j, body in enumerate(self.bodies):
      mujoco.mj_objectAcceleration(model, data, mujoco.mjtObj.mjOBJ_BODY, body, self._a6, 0)
      # cacc carries the gravity offset (a body at rest reads +g): remove it.
      acc = self._a6[3:] + self.gravity
      norm = math.sqrt(float(acc @ acc))
      ahat = acc / norm if norm > ACC_EPS else np.zeros(3)
      f_par = f_perp = 0.0
      for i in range(data.ncon):  # every contact, every link: the reference cost
        c = data.contact[i]
        if c.efc_address < 0 or c.dist - c.includemargin >= 0:
          continue
        b1, b2 = model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2]
        if body != b1 and body != b2:
          continue
        mujoco.mj_contactForce(model, data, i, self._f6)
        # contact frame rows: normal, tangent1, tangent2; force of geom1 on geom2
        f = c.frame.reshape(3, 3).T @ self._f6[:3]
        if body == b1:
          f = -f
        along = float(f @ ahat)
        f_par += abs(along)
        perp = f - along * ahat
        f_perp += math.sqrt(float(perp @ perp))
      eps = self.alpha[j] * f_par + self.beta[j] * f_perp
      rates.append(self.l_mech[j] * max(eps - self.e_mech[j], 0.0))
    return rates

  def thermal(self, temperature: Sequence[float]) -> list[float]:
    return [
        self.l_therm[j] * (max(t - self.t_hot[j], 0.0) + max(self.t_cold[j] - t, 0.0))
        for j, t in enumerate(temperature)
    ]

  def fluid(self, exposure: Sequence[float]) -> list[float]:
    return [self.l_fluid[j] * max(c - self.c_fluid[j], 0.0) for j, c in enumerate(exposure)]


class ReferencePipeline:
  """Native MuJoCo stepping with reference-style damage (one environment).

  ``step(data, health)`` advances ``data`` in place by ``n_substeps`` physics
  steps, evaluating every entity's DEMs at each one, and returns the new
  per-link health (list of floats, binding link order). Temperature and liquid
  are not simulated here (ambient, no particles), as in a scene without heat
  sources or liquid; their DEMs are still evaluated so the per-step work matches.
  """

  def __init__(self, model: mujoco.MjModel, binding: Binding, n_substeps: int = 1):
    self.model, self.binding, self.n_substeps = model, binding, int(n_substeps)
    self.evaluators = [EntityEvaluator(model, binding, e) for e in range(binding.num_entities)]
    self.dt = float(model.opt.timestep)
    self.tau = float(np.asarray(binding.params.tau))
    integ = model.opt.integrator
    if integ == mujoco.mjtIntegrator.mjINT_RK4:
      self._integrate = lambda m, d: mujoco.mj_RungeKutta(m, d, 4)
    elif integ in (mujoco.mjtIntegrator.mjINT_IMPLICIT, mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
      self._integrate = mujoco.mj_implicit
    else:
      self._integrate = mujoco.mj_Euler

  def initial_health(self) -> list[float]:
    return [MAX_HEALTH] * self.binding.num_links

  def substep(self, data: mujoco.MjData, health: list[float]) -> tuple[list[float], float]:
    """One physics step with damage; returns (health, health points lost this substep)."""
    m = self.model
    mujoco.mj_forward(m, data)
    mujoco.mj_rnePostConstraint(m, data)  # fills cacc for mj_objectAcceleration
    lost = 0.0
    for ev in self.evaluators:
      mech = ev.mechanical(m, data)
      therm = ev.thermal([AMBIENT_C] * len(ev.links))
      fl = ev.fluid([0.0] * len(ev.links))
      for j, li in enumerate(ev.links):
        d = (mech[j] + therm[j] + fl[j]) * self.dt / self.tau
        new = min(max(health[li] - d, 0.0), MAX_HEALTH)
        lost += health[li] - new
        health[li] = new
    self._integrate(m, data)
    return health, lost

  def step(self, data: mujoco.MjData, health: list[float]) -> tuple[list[float], float]:
    """One control step (``n_substeps`` physics steps); returns (health, cost of the step)."""
    cost = 0.0
    for _ in range(self.n_substeps):
      health, c = self.substep(data, health)
      cost += c
    return health, cost


def time_reference(
    model: mujoco.MjModel,
    binding: Binding,
    n_substeps: int,
    initial_qpos: np.ndarray,
    ctrl_fn: Callable[[float], np.ndarray],
    steps: int,
    damage: bool = True,
    max_seconds: Optional[float] = None,
) -> dict:
  """Time environments one after another, each for ``steps`` control steps.

  Args:
    initial_qpos: f64[E, nq] reset configuration of each environment.
    ctrl_fn: simulation time (s) → ctrl f64[nu] (the same open-loop control the MJX run uses).
    damage: False steps plain ``mj_step`` (native MuJoCo without damage).
    max_seconds: stop starting new environments after this long (at least one runs).

  Returns:
    {"envs", "env_steps", "seconds", "env_steps_per_s", "physics_steps_per_s",
     "mean_final_min_health"} (health only with damage).
  """
  pipe = ReferencePipeline(model, binding, n_substeps) if damage else None
  data = mujoco.MjData(model)
  done_envs, healths = 0, []
  t0 = time.perf_counter()
  for q in initial_qpos:
    mujoco.mj_resetData(model, data)
    data.qpos[:] = q
    health = pipe.initial_health() if damage else None
    for _ in range(steps):
      data.ctrl[:] = ctrl_fn(data.time)
      if damage:
        health, _ = pipe.step(data, health)
      else:
        mujoco.mj_step(model, data, nstep=n_substeps)
    done_envs += 1
    if damage:
      healths.append(min(health))
    if max_seconds is not None and time.perf_counter() - t0 > max_seconds:
      break
  dt = time.perf_counter() - t0
  env_steps = done_envs * steps
  out = {
      "envs": done_envs,
      "env_steps": env_steps,
      "seconds": dt,
      "env_steps_per_s": env_steps / dt,
      "physics_steps_per_s": env_steps * n_substeps / dt,
  }
  if damage:
    out["mean_final_min_health"] = float(np.mean(healths))
  return out


def time_rollout(
    model: mujoco.MjModel,
    n_substeps: int,
    initial_qpos: np.ndarray,
    ctrl_fn: Callable[[float], np.ndarray],
    steps: int,
    nthread: int,
) -> dict:
  """Native MuJoCo without damage through multi-threaded ``mujoco.rollout``.

  ``mujoco.rollout`` steps open-loop controls in C threads with no Python in the
  loop, so per-step Python damage evaluators cannot run inside it: this is the
  native physics-only ceiling on this machine, not a damage pipeline.
  """
  from mujoco import rollout

  nphys = steps * n_substeps
  dt = float(model.opt.timestep)
  ctrl = np.stack([ctrl_fn(i * dt) for i in range(nphys)])[None]  # [1, nphys, nu]
  data = mujoco.MjData(model)
  spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
  states = []
  for q in initial_qpos:
    mujoco.mj_resetData(model, data)
    data.qpos[:] = q
    s = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, s, spec)
    states.append(s)
  states = np.stack(states)
  datas = [mujoco.MjData(model) for _ in range(nthread)]
  rollout.rollout(model, datas, states[:1], ctrl[:, :2], persistent_pool=False)  # warm-up
  t0 = time.perf_counter()
  rollout.rollout(model, datas, states, ctrl)
  secs = time.perf_counter() - t0
  env_steps = len(states) * steps
  return {
      "envs": len(states),
      "threads": nthread,
      "env_steps": env_steps,
      "seconds": secs,
      "env_steps_per_s": env_steps / secs,
      "physics_steps_per_s": env_steps * n_substeps / secs,
  }

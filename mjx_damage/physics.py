"""The damage-aware physics step: MJX substeps with damage evaluated at every one.

``step(m, binding, d, ds, n_substeps)`` is what environments call instead of a
loop of ``mjx.step``. Each substep runs ``mjx.forward``, reads the link signals
from that consistent state (contacts, constraint forces, ``qacc``), evaluates
every damage model, integrates health (d·dt/τ), advances temperature and liquid
when configured, then integrates the physics. All of it is pure and jittable;
vmap it over environments.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct
from mujoco import mjx

from mjx_damage import health as H
from mjx_damage import liquid as Lq
from mjx_damage import temperature as T
from mjx_damage.backends import mjx_jax
from mjx_damage.binding import Binding
from mjx_damage.kinematics import link_velocity
from mjx_damage.params import DamageParams
from mjx_damage.signals import Damage, LinkSignals, evaluate


@struct.dataclass
class DamageState:
  """Per-environment damage state (add a leading batch axis for many environments).

  link_health: f32[L] in [0, 100]
  temperature: f32[L] °C
  exposure:    f32[L] liquid particles touching each link (last substep)
  params:      DamageParams of this environment (randomisable per episode)
  step_damage: Damage, health points lost per modality since the env step began, f32[L] each
  f_par, f_perp: f32[L] peak mechanical loads since the env step began, N
  link_vel:    f32[L, 3] link COM velocities at the end of the last evaluation, m/s
  thermal:     temperature-model state (heat source temperatures), or None
  liquid:      liquid-model state (particles), or None
  contacts_dropped: i32[] contacts of this environment the backend could not read for damage in the last
               control step (the most in any substep): MuJoCo Warp's fixed places per world
               (:mod:`mjx_damage.warp_step`), at least 1 where Warp's own buffers overflowed; always 0 on
               MJX-JAX, which reads every contact slot
  """

  link_health: jax.Array
  temperature: jax.Array
  exposure: jax.Array
  params: DamageParams
  step_damage: Damage
  f_par: jax.Array
  f_perp: jax.Array
  link_vel: jax.Array
  thermal: object = None
  liquid: object = None
  contacts_dropped: object = None


def init_state(binding: Binding, params: DamageParams | None = None, rng: jax.Array | None = None) -> DamageState:
  """Fresh damage state: full health, ambient temperature, no exposure.

  ``rng`` seeds stochastic parts (initial particle jitter) where configured.
  """
  L = binding.num_links
  z = jnp.zeros((L,), jnp.float32)
  rng = jax.random.PRNGKey(0) if rng is None else rng
  return DamageState(
      link_health=jnp.full((L,), H.MAX_HEALTH, jnp.float32),
      temperature=T.initial_link_temperature(binding),
      exposure=z,
      params=binding.params if params is None else params,
      step_damage=Damage.zeros(L),
      f_par=z,
      f_perp=z,
      link_vel=jnp.zeros((L, 3), jnp.float32),
      thermal=T.init(binding),
      liquid=Lq.init(binding, rng),
      contacts_dropped=jnp.zeros((), jnp.int32),
  )


def begin_step(ds: DamageState) -> DamageState:
  """Zero the per-env-step accumulators (call once per control step)."""
  z = jnp.zeros_like(ds.f_par)
  return ds.replace(step_damage=Damage(z, z, z), f_par=z, f_perp=z,
                    contacts_dropped=jnp.zeros_like(ds.contacts_dropped))


def apply_signals(ds: DamageState, signals: LinkSignals, dt) -> DamageState:
  """Evaluate every damage model on one substep's signals and integrate health.

  Backend-agnostic: the MJX step below, the native-MuJoCo path and the
  once-per-env-step wrapper fallback all end here.
  """
  ev = evaluate(signals, ds.params)
  return _lose(ds, ev.rate, dt).replace(f_par=jnp.maximum(ds.f_par, ev.f_par), f_perp=jnp.maximum(ds.f_perp, ev.f_perp))


def _lose(ds: DamageState, rate: Damage, dt) -> DamageState:
  """One substep at damage ``rate`` (f32[L] per model, health per τ): health integrated, the step's sums grown."""
  lost = jax.tree.map(lambda r: jnp.maximum(r, 0.0) * (dt / ds.params.tau), rate)
  return ds.replace(link_health=H.integrate(ds.link_health, rate.total(), dt, ds.params.tau),
                    step_damage=jax.tree.map(jnp.add, ds.step_damage, lost))


def apply_recorded_substeps(ds: DamageState, signals: LinkSignals, dt) -> DamageState:
  """``apply_signals`` over S substeps whose signals are all known beforehand (leading axis S on every leaf).

  For backends that record the substeps first and evaluate damage afterwards (the native one): the
  damage models run once, vectorised over the substeps, and only the health integration, the
  per-step damage sum and the peak loads go substep by substep, in ``apply_signals``'s order, so the
  result equals S ``apply_signals`` calls. The signals must not depend on the health they change
  (true of contact forces, accelerations, temperatures and liquid exposures).
  """
  ev = jax.vmap(evaluate, in_axes=(0, None))(signals, ds.params)  # rates f32[S, L] per model
  # unrolled: S is small and static, and XLA:CPU pays per loop iteration for each of these tiny ops
  ds, _ = jax.lax.scan(lambda ds, rate: (_lose(ds, rate, dt), None), ds, ev.rate, unroll=True)
  return ds.replace(f_par=jnp.maximum(ds.f_par, jnp.max(ev.f_par, axis=0)),
                    f_perp=jnp.maximum(ds.f_perp, jnp.max(ev.f_perp, axis=0)))


def _integrate(m: mjx.Model, d: mjx.Data) -> mjx.Data:
  integ = m.opt.integrator
  if integ == mjx.IntegratorType.EULER:
    return mjx.euler(m, d)
  if integ == mjx.IntegratorType.RK4:
    return mjx.rungekutta4(m, d)
  if integ == mjx.IntegratorType.IMPLICITFAST:
    return mjx.implicit(m, d)
  raise ValueError(f"model.opt.integrator: {integ} is not supported by MJX")


def substep(m: mjx.Model, binding: Binding, d: mjx.Data, ds: DamageState) -> tuple[mjx.Data, DamageState]:
  """One physics step of length ``m.opt.timestep`` with damage (one environment)."""
  d = mjx.forward(m, d)
  dt = m.opt.timestep
  ds = T.advance(m, binding, d, ds, dt)
  ds = Lq.advance(m, binding, d, ds, dt)
  ds = apply_signals(ds, mjx_jax.link_signals(binding, m, d, ds.temperature, ds.exposure), dt)
  ds = ds.replace(link_vel=link_velocity(binding, d))
  return _integrate(m, d), ds


def step(
    m: mjx.Model, binding: Binding, d: mjx.Data, ds: DamageState, n_substeps: int = 1
) -> tuple[mjx.Data, DamageState]:
  """``n_substeps`` physics steps (one control step) with damage at every substep.

  ``ds.step_damage``/``f_par``/``f_perp`` afterwards describe this control step.
  """
  ds = begin_step(ds)

  def body(carry, _):
    return substep(m, binding, *carry), None

  (d, ds), _ = jax.lax.scan(body, (d, ds), None, length=n_substeps)
  return d, ds


def step_without_damage(m: mjx.Model, d: mjx.Data, n_substeps: int = 1) -> mjx.Data:
  """The same control step with plain ``mjx.step`` (for damage on/off comparisons)."""
  d, _ = jax.lax.scan(lambda d, _: (mjx.step(m, d), None), d, None, length=n_substeps)
  return d

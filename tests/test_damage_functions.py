"""Damage evaluation models against hand-computed cases, and their properties."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mjx_damage as md
from mjx_damage import health


def load(forces, links, acc, L):
  fp, fq = md.mechanical_load(jnp.array(forces, jnp.float32), jnp.array(links), jnp.array(acc, jnp.float32), L)
  return np.asarray(fp), np.asarray(fq)


def test_force_along_acceleration_is_parallel():
  fp, fq = load([[0, 0, 10.0]], [0], [[0, 0, 5.0]], 1)
  np.testing.assert_allclose(fp, [10.0], rtol=1e-6)
  np.testing.assert_allclose(fq, [0.0], atol=1e-6)


def test_force_opposing_acceleration_counts_its_magnitude():
  # deceleration on impact: force against the direction of motion still counts fully in F∥
  fp, fq = load([[0, 0, -7.0]], [0], [[0, 0, 3.0]], 1)
  np.testing.assert_allclose(fp, [7.0], rtol=1e-6)
  np.testing.assert_allclose(fq, [0.0], atol=1e-6)


def test_oblique_force_splits_by_projection():
  fp, fq = load([[3.0, 4.0, 0.0]], [0], [[2.0, 0.0, 0.0]], 1)
  np.testing.assert_allclose(fp, [3.0], rtol=1e-6)
  np.testing.assert_allclose(fq, [4.0], rtol=1e-6)


def test_zero_acceleration_makes_everything_perpendicular():
  fp, fq = load([[3.0, 4.0, 0.0], [0, 0, 2.0]], [0, 0], [[0, 0, 1e-7]], 1)
  np.testing.assert_allclose(fp, [0.0])
  np.testing.assert_allclose(fq, [7.0], rtol=1e-6)  # Σ‖f_k‖, not ‖Σ f_k‖


def test_untracked_contacts_are_ignored():
  fp, fq = load([[0, 0, 100.0], [1.0, 0, 0]], [-1, 1], [[0, 0, 1.0], [0, 0, 0]], 2)
  np.testing.assert_allclose(fp, [0.0, 0.0])
  np.testing.assert_allclose(fq, [0.0, 1.0], rtol=1e-6)


def test_two_tracked_links_touching_load_both():
  f = [0.0, 0.0, 20.0]
  fp, fq = load([f, [-x for x in f]], [1, 0], [[0, 0, 0], [0, 0, 0]], 2)
  np.testing.assert_allclose(fq, [20.0, 20.0], rtol=1e-6)


def test_mechanical_damage_hand_computed():
  d = md.mechanical_damage(jnp.array([10.0, 0.0]), jnp.array([40.0, 10.0]), 1.0, 0.5, 25.0, 2.0)
  # link 0: ε = 10 + 20 = 30 → 2·5 = 10; link 1: ε = 5 < 25 → 0
  np.testing.assert_allclose(d, [10.0, 0.0], rtol=1e-6)


def test_thermal_damage_hot_and_cold():
  d = md.thermal_damage(jnp.array([22.0, 60.0, -30.0]), 40.0, -20.0, 0.5)
  np.testing.assert_allclose(d, [0.0, 10.0, 5.0])


def test_fluid_damage():
  d = md.fluid_damage(jnp.array([5.0, 25.0]), 20.0, 5.0)
  np.testing.assert_allclose(d, [0.0, 25.0])


def test_entity_health_is_min_of_links():
  h = md.entity_health(jnp.array([90.0, 50.0, 70.0, 100.0]), jnp.array([0, 0, 1, 2]), 3)
  np.testing.assert_allclose(h, [50.0, 70.0, 100.0])


def test_health_integration_scales_with_dt_over_tau():
  h = health.integrate(jnp.array([100.0]), jnp.array([30.0]), dt=0.002, tau=1 / 30)
  np.testing.assert_allclose(h, [100.0 - 30.0 * 0.002 * 30], rtol=1e-6)
  assert float(health.integrate(jnp.array([1.0]), jnp.array([1e9]), 0.002, 1 / 30)[0]) == 0.0


def test_no_nan_for_extreme_inputs():
  big = 3e38
  fp, fq = md.mechanical_load(jnp.array([[big, -big, big], [0, 0, 0]]), jnp.array([0, 0]),
                              jnp.array([[big, big, -big]]), 1)
  d = md.mechanical_damage(fp, fq, jnp.array([0.0]), jnp.array([big]), jnp.array([big]), jnp.array([0.0]))
  t = md.thermal_damage(jnp.array([big]), jnp.array([-big]), jnp.array([-big]), jnp.array([big]))
  for x in (fp, fq, d, t):
    assert not np.isnan(np.asarray(x)).any()


def test_jit_vmap_and_grad_are_finite():
  f = jax.jit(jax.vmap(lambda F, a: md.mechanical_load(F, jnp.array([0, 0]), a, 1)))
  fp, fq = f(jnp.zeros((8, 2, 3)), jnp.zeros((8, 1, 3)))
  assert fp.shape == (8, 1) and float(jnp.abs(fq).sum()) == 0.0
  g = jax.grad(lambda F: md.mechanical_load(F, jnp.array([0]), jnp.zeros((1, 3)), 1)[1].sum())(jnp.zeros((1, 3)))
  assert np.isfinite(np.asarray(g)).all()


finite = st.floats(-1e6, 1e6, allow_nan=False, width=32)
nonneg = st.floats(0, 1e4, allow_nan=False, width=32)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(finite, finite, finite), min_size=1, max_size=6), st.tuples(finite, finite, finite),
       nonneg, nonneg, nonneg, nonneg, st.floats(1.0, 10.0))
def test_mechanical_properties(forces, acc, alpha, beta, E, scale, k):
  F = np.array(forces, np.float32)
  links = np.zeros(len(forces), np.int32)
  fp, fq = load(F, links, [acc], 1)
  d = np.asarray(md.mechanical_damage(fp, fq, alpha, beta, E, scale))
  assert np.isfinite(d).all() and (d >= 0).all()
  # damage is zero whenever the load is below threshold
  if alpha * fp[0] + beta * fq[0] <= E:
    assert d[0] == 0.0
  # scaling every force magnitude up never lowers damage
  fp2, fq2 = load(F * k, links, [acc], 1)
  d2 = np.asarray(md.mechanical_damage(fp2, fq2, alpha, beta, E, scale))
  # f32 rounding: a force along the acceleration keeps a perpendicular part of ~eps·|F| (scaled by k, by
  # different roundings), which Λ·β amplifies: allow that much, relative to the largest force
  noise = scale * (alpha + beta) * k * float(np.abs(F).max()) * 4e-7
  assert d2[0] >= d[0] * (1 - 1e-5) - 1e-3 - noise


@settings(max_examples=60, deadline=None)
@given(st.floats(-200, 400), st.floats(0, 100), nonneg)
def test_thermal_monotone_beyond_thresholds(T, dT, scale):
  t_hot, t_cold = 40.0, -20.0
  d0 = float(md.thermal_damage(jnp.array([T]), t_hot, t_cold, scale)[0])
  assert d0 >= 0
  if t_cold <= T <= t_hot:
    assert d0 == 0.0
  if T >= t_hot:
    assert float(md.thermal_damage(jnp.array([T + dT]), t_hot, t_cold, scale)[0]) >= d0
  if T <= t_cold:
    assert float(md.thermal_damage(jnp.array([T - dT]), t_hot, t_cold, scale)[0]) >= d0


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0, 1e5, width=32), min_size=1, max_size=30))
def test_health_stays_in_range_and_never_rises(rates):
  h = jnp.array([100.0])
  prev = 100.0
  for r in rates:
    h = health.integrate(h, jnp.array([r]), 0.004, 1 / 30)
    v = float(h[0])
    assert 0.0 <= v <= prev <= 100.0
    prev = v


def test_mechanical_load_is_a_scatter_free_sum_equal_to_segment_sum():
  """Loads equal a per-link segment sum, computed without scatter-add (atomics on GPU change the last bits run to run)."""
  k1, k2, k3 = jax.random.split(jax.random.PRNGKey(3), 3)
  K, L = 40, 5
  forces = jax.random.normal(k1, (K, 3)) * 50.0
  links = jax.random.randint(k2, (K,), -1, L + 1)  # includes untracked (−1) and out-of-range (L)
  acc = jax.random.normal(k3, (L, 3))
  fp, fq = md.mechanical_load(forces, links, acc, L)
  ahat = acc / jnp.linalg.norm(acc, axis=-1, keepdims=True)
  valid = (links >= 0) & (links < L)
  a = ahat[jnp.clip(links, 0, L - 1)]
  along = jnp.sum(forces * a, axis=-1)
  perp = jnp.linalg.norm(forces - along[:, None] * a, axis=-1)
  seg = jnp.where(valid, links, L)
  want_p = jax.ops.segment_sum(jnp.where(valid, jnp.abs(along), 0.0), seg, L + 1)[:L]
  want_q = jax.ops.segment_sum(jnp.where(valid, perp, 0.0), seg, L + 1)[:L]
  np.testing.assert_allclose(fp, want_p, rtol=1e-5, atol=1e-3)
  np.testing.assert_allclose(fq, want_q, rtol=1e-5, atol=1e-3)
  hlo = jax.jit(md.mechanical_load, static_argnums=3).lower(forces, links, acc, L).as_text()
  assert "scatter" not in hlo

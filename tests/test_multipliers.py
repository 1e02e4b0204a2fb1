"""Plain and PID Lagrange multipliers (train.multipliers): projection, anti-windup, reduction, selection."""

import jax
import jax.numpy as jnp
import numpy as np

from train import multipliers as M


def _params(kind, budget=2.0, kp=0.0, ki=0.1, kd=0.0, lam_max=5.0, anneal=0):
  f = lambda v: jnp.float32(v)  # noqa: E731
  return M.MultiplierParams(kind=f(kind), budget=f(budget), kp=f(kp), ki=f(ki), kd=f(kd), lam_max=f(lam_max),
                            anneal_updates=f(anneal))


def test_lagrange_update_rule():
  assert np.isclose(M.lagrange_update(jnp.float32(1.0), 10.0, 4.0, 0.1, 100.0), 1.6)
  assert float(M.lagrange_update(jnp.float32(1.0), 0.0, 50.0, 0.1, 100.0)) == 0.0  # projected onto λ ≥ 0
  assert float(M.lagrange_update(jnp.float32(99.0), 1e6, 0.0, 0.1, 100.0)) == 100.0  # capped
  lam = jnp.float32(5.0)
  for _ in range(20):
    lam = M.lagrange_update(lam, 1.0, 3.0, 0.5, 100.0)
  assert float(lam) == 0.0


def test_pid_integral_windup_is_clipped():
  s = M.init()
  for _ in range(100):  # a long violation: the integral stops at λ_max
    s = M.pid_update(s, 1000.0, 1.0, 0.0, 1.0, 0.0, 5.0)
  assert float(s.integral) == 5.0 and float(s.lam) == 5.0
  for _ in range(3):  # the cost drops under budget: without windup the integral leaves λ_max at once
    s = M.pid_update(s, 0.0, 1.0, 0.0, 1.0, 0.0, 5.0)
  assert float(s.integral) == 2.0
  for _ in range(100):  # a long stretch under budget: the integral stops at 0, not far below
    s = M.pid_update(s, 0.0, 1.0, 0.0, 1.0, 0.0, 5.0)
  assert float(s.integral) == 0.0
  s = M.pid_update(s, 2.0, 1.0, 0.0, 1.0, 0.0, 5.0)  # one step over budget: λ reacts at once
  assert float(s.lam) == 1.0


def test_pid_lambda_is_never_negative():
  s = M.init(0.5)
  rng = np.random.default_rng(0)
  for c in rng.uniform(0.0, 10.0, 200):
    s = M.pid_update(s, float(c), 5.0, 2.0, 0.3, 1.0, 4.0)
    assert 0.0 <= float(s.lam) <= 4.0 and 0.0 <= float(s.integral) <= 4.0


def test_pid_terms():
  s = M.pid_update(M.init(), 3.0, 1.0, 0.5, 0.0, 2.0, 100.0)  # P only on the first step (no previous cost)
  assert np.isclose(float(s.lam), 0.5 * 2.0)
  s = M.pid_update(s, 4.0, 1.0, 0.5, 0.0, 2.0, 100.0)  # P + D on a rising cost
  assert np.isclose(float(s.lam), 0.5 * 3.0 + 2.0 * 1.0)
  s = M.pid_update(s, 3.5, 1.0, 0.5, 0.0, 2.0, 100.0)  # a falling cost adds no D
  assert np.isclose(float(s.lam), 0.5 * 2.5)


def test_pid_reduces_to_plain_lagrangian_when_kp_kd_zero():
  costs = [10.0, 0.0, 7.0, 3.0, 0.0, 0.0, 50.0, 1.0]
  lam, s = jnp.float32(0.3), M.init(0.3)
  for c in costs:
    lam = M.lagrange_update(lam, c, 2.0, 0.2, 5.0)
    s = M.pid_update(s, c, 2.0, 0.0, 0.2, 0.0, 5.0)
    assert float(s.lam) == float(lam)
  # and through update(): the plain kind equals PID with Kp = Kd = 0
  a, b = M.init(0.3), M.init(0.3)
  for c in costs:
    a = M.update(a, _params(M.LAGRANGIAN, ki=0.2), c, 1.0)
    b = M.update(b, _params(M.PID, ki=0.2), c, 1.0)
    assert float(a.lam) == float(b.lam)


def test_update_fixed_and_unmeasured_keep_lambda():
  s = M.init(1.5)
  assert float(M.update(s, _params(M.FIXED), 100.0, 1.0).lam) == 1.5  # penalty runs: λ stays
  assert float(M.update(s, _params(M.PID, kp=1.0), 100.0, 0.0).lam) == 1.5  # no episode has ended yet


def test_update_vmaps_over_seeds():
  s = jax.vmap(M.init)(jnp.array([0.0, 1.0]))
  p = jax.tree.map(lambda x: jnp.stack([x, x]), _params(M.PID, kp=1.0))
  out = jax.vmap(M.update)(s, p, jnp.array([5.0, 0.0]), jnp.ones(2))
  assert out.lam.shape == (2,) and float(out.lam[0]) > 0.0


def test_budget_curriculum_starts_at_the_first_cost_and_reaches_the_budget():
  """ĉ_t falls linearly from J_c,0 to ĉ over anneal_updates; λ stays 0 while the cost follows it."""
  for kind in (M.LAGRANGIAN, M.PID):
    p = _params(kind, budget=2.0, kp=0.1, ki=0.1, kd=0.05, anneal=10)
    s = M.update(M.init(), p, 100.0, 0.0)  # no episode has ended: nothing recorded
    assert float(s.updates) == 0 and float(s.start_cost) == 0
    budgets = []
    for t in range(14):
      cost = float(M.effective_budget(s, p)) if t else 100.0  # a policy that meets each budget exactly
      s = M.update(s, p, cost, 1.0)
      budgets.append(float(M.effective_budget(s, p)))
      assert float(s.lam) == 0.0, (kind, t)
    assert float(s.start_cost) == 100.0
    np.testing.assert_allclose(budgets[:10], [2 + 98 * (1 - (t + 1) / 10) for t in range(10)], rtol=1e-5)
    assert budgets[9:] == [2.0] * 5
    # over the curriculum's budget, λ rises — the same step as without the curriculum
    hot = M.update(s, p, 50.0, 1.0)
    assert float(hot.lam) > 0


def test_without_curriculum_the_first_costly_update_pins_lambda():
  """The failure the curriculum avoids: from a random policy's cost, λ jumps towards λ_max at once."""
  p, q = _params(M.PID, kp=0.1, ki=0.01, kd=0.05), _params(M.PID, kp=0.1, ki=0.01, kd=0.05, anneal=100)
  assert float(M.update(M.init(), p, 100.0, 1.0).lam) == 5.0
  assert float(M.update(M.init(), q, 100.0, 1.0).lam) == 0.0

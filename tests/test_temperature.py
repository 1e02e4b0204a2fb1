"""Temperature model: conduction, distance exchange, cooling, switching, Euler bound, validation.

Scene ``tests/scenes/heat.xml``: a 300 °C burner block, a gravity-compensated
"hand" box on x/z slides, a box 1 m from the burner, a lone sphere touching
nothing. One jitted control step (25 substeps = 0.1 s) is compiled once per
module and drives every scenario.
"""

import dataclasses
import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjx_damage as M
from mjx_damage import physics
from mjx_damage import temperature as T

SCENE = os.path.join(os.path.dirname(__file__), "scenes", "heat.xml")
SUBSTEPS = 25  # 0.1 s per control step
AMBIENT = 22.0
T_SOURCE = 300.0
PRESS = jnp.array([0.0, -0.2])  # hand centre 0.02 below contact with the burner top: pressed on it
AWAY = jnp.array([0.8, 0.1])  # lifted and 0.8 m to the side


def config(**hand_heat):
  return {
      "entities": {
          "hand": {"params": "agent", "heat": {"cooling": 0.5, **hand_heat}},
          "far": {"params": "laptop"},
          "lone": {"params": "laptop"},
      },
      "temperature": {"ambient": AMBIENT, "sources": {"burner": {"geom": "burner", "temperature": T_SOURCE}}},
  }


@pytest.fixture(scope="module")
def scene():
  m = mujoco.MjModel.from_xml_path(SCENE)
  b = M.bind(m, config())
  mx = mjx.put_model(m)

  @jax.jit
  def control_step(d, ds, ctrl, on):
    ds = T.set_source(ds, "burner", on, binding=b)  # switching works inside jit
    return physics.step(mx, b, d.replace(ctrl=ctrl), ds, SUBSTEPS)

  # fresh state built under jit: eagerly built mjx.Data differs from jit outputs in
  # ways that would make control_step compile a second time on its own output
  fresh = jax.jit(lambda: (mjx.make_data(mx), physics.init_state(b)))
  return m, mx, b, control_step, fresh


@pytest.fixture(scope="module")
def trajectory(scene):
  """Press on the lit burner 1.5 s, keep pressing with it off 1 s, then lift away 3 s."""
  m, mx, b, control_step, fresh = scene
  d, ds = fresh()
  rows = [("start", np.asarray(ds.temperature), np.asarray(ds.link_health), np.zeros(3))]
  phases = [("press", PRESS, 1.0, 15), ("off", PRESS, 0.0, 10), ("away", AWAY, 1.0, 30)]
  for name, ctrl, on, n in phases:
    for _ in range(n):
      d, ds = control_step(d, ds, ctrl, on)
      rows.append((name, np.asarray(ds.temperature), np.asarray(ds.link_health), np.asarray(ds.step_damage.thermal)))
  names = [r[0] for r in rows]
  temp = np.stack([r[1] for r in rows])  # [steps, L]
  health = np.stack([r[2] for r in rows])
  therm = np.stack([r[3] for r in rows])
  assert b.link_names == ("hand/hand", "far/far", "lone/lone")
  return np.array(names), temp, health, therm


def test_starts_at_ambient(scene):
  _, _, b, _, _ = scene
  np.testing.assert_array_equal(np.asarray(physics.init_state(b).temperature), AMBIENT)


def test_touching_hot_source_heats_monotonically_toward_it(trajectory):
  names, temp, _, _ = trajectory
  hand = temp[(names == "start") | (names == "press"), 0]
  assert np.all(np.diff(hand) >= 0), hand
  # contact equilibrium with this test's fast cooling (0.5/s): (2.2·300 + 0.5·22)/2.7 ≈ 248.5 °C
  t_eq = ((T.DEFAULT_HEAT["conduction"] + T.DEFAULT_HEAT["radiation"]) * T_SOURCE + 0.5 * AMBIENT) / (
      T.DEFAULT_HEAT["conduction"] + T.DEFAULT_HEAT["radiation"] + 0.5)
  assert t_eq - 10.0 < hand[-1] <= t_eq + 1e-3, (hand, t_eq)
  assert hand.max() <= T_SOURCE  # never overshoots the source


def test_thermal_damage_only_past_t_hot(trajectory):
  names, temp, health, therm = trajectory
  hand_t, hand_dmg = temp[:, 0], therm[:, 0]
  # agent T_hot = 40 °C; T is monotone within each step, so its two ends bound it
  below = (hand_t <= 40.0) & (np.concatenate([[AMBIENT], hand_t[:-1]]) <= 40.0)
  assert below.sum() >= 2
  assert np.all(hand_dmg[below] == 0.0)
  hot = (names == "press") & (hand_t > 45.0)
  assert hot.any()
  assert np.all(hand_dmg[hot] > 0.0)
  assert health[-1, 0] < health[0, 0]


def test_switched_off_source_cools_touching_link(trajectory):
  names, temp, _, _ = trajectory
  hand = temp[names == "off", 0]
  assert np.all(np.diff(hand) <= 0), hand
  assert hand[-1] < temp[names == "press", 0][-1] - 100.0


def test_removed_from_source_cools_toward_ambient(trajectory):
  names, temp, _, _ = trajectory
  hand = temp[names == "away", 0]
  assert np.all(np.diff(hand) <= 0), hand
  start = temp[names == "off", 0][-1]
  assert hand[-1] - AMBIENT < 0.3 * (start - AMBIENT)  # cooling 0.5/s for 3 s: e^−1.5 ≈ 0.22
  assert hand[-1] >= AMBIENT - 1e-3


def test_link_one_metre_away_stays_near_ambient(trajectory):
  _, temp, health, _ = trajectory
  assert np.all(np.abs(temp[:, 1] - AMBIENT) < 0.5)
  assert np.all(health[:, 1] == 100.0)


def test_link_touching_nothing_stays_at_ambient(trajectory):
  _, temp, _, _ = trajectory
  np.testing.assert_array_equal(temp[:, 2], AMBIENT)


def test_touching_matrix_from_contacts(scene):
  m, mx, b, _, _ = scene
  d = mjx.make_data(mx)
  apart = jax.jit(mjx.forward)(mx, d)
  pressed = jax.jit(mjx.forward)(mx, d.replace(qpos=jnp.array([0.0, -0.181])))  # 1 mm into the burner
  assert np.asarray(T.touching(b.thermal, b, apart)).sum() == 0
  np.testing.assert_array_equal(np.asarray(T.touching(b.thermal, b, pressed)), [[1.0], [0.0], [0.0]])


def test_euler_bound_rejected_in_build():
  m = mujoco.MjModel.from_xml_path(SCENE)
  dt = m.opt.timestep
  with pytest.raises(ValueError, match=r"^entities\.hand\.heat: explicit Euler bound"):
    M.bind(m, config(conduction=1.0 / dt))  # dt·(1·(1/dt + 0.2) + 0.5) > 1
  # just inside the bound is accepted
  M.bind(m, config(conduction=1.0 / dt - 0.2 - 0.5 - 1e-3))


def test_euler_bound_keeps_temperature_between_ambient_and_source(scene):
  """At the largest admissible rate T approaches 300 °C without overshoot; past the bound it rings."""
  m, mx, _, _, _ = scene
  dt = float(m.opt.timestep)
  b = M.bind(m, config(conduction=1.0 / dt - 0.2 - 0.5 - 1e-3))
  d = jax.jit(mjx.forward)(mx, mjx.make_data(mx).replace(qpos=jnp.array([0.0, -0.181])))
  # bypass build's check: 3× the admissible conduction
  unstable = dataclasses.replace(b, thermal=b.thermal.replace(conduction=b.thermal.conduction * 3.0))

  def run(binding):
    ds = physics.init_state(binding)

    def body(ds, _):
      ds = T.advance(mx, binding, d, ds, dt)
      return ds, ds.temperature[0]

    return jax.lax.scan(body, ds, None, length=20)[1]

  stable_t = np.asarray(jax.jit(lambda: run(b))())
  assert np.all(np.diff(stable_t) >= 0) and stable_t.max() <= T_SOURCE + 1e-3
  assert stable_t[-1] > T_SOURCE - 1.0
  unstable_t = np.asarray(jax.jit(lambda: run(unstable))())
  assert unstable_t.max() > T_SOURCE + 1.0  # overshoot: the bound is what prevents it


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda c: c["temperature"]["sources"]["burner"].update(geom="nope"), "temperature.sources.burner.geom"),
        (lambda c: c["temperature"]["sources"]["burner"].update(geom=3), "temperature.sources.burner.geom"),
        (lambda c: c["temperature"]["sources"]["burner"].update(temperature="hot"),
         "temperature.sources.burner.temperature"),
        (lambda c: c["temperature"]["sources"]["burner"].update(temperature=float("nan")),
         "temperature.sources.burner.temperature"),
        (lambda c: c["temperature"]["sources"]["burner"].pop("temperature"), "temperature.sources.burner.temperature"),
        (lambda c: c["temperature"]["sources"]["burner"].update(on="yes"), "temperature.sources.burner.on"),
        (lambda c: c["temperature"]["sources"]["burner"].update(reach=0), "temperature.sources.burner.reach"),
        (lambda c: c["temperature"]["sources"]["burner"].update(colour=1), "temperature.sources.burner.colour"),
        (lambda c: c["temperature"].update(ambient=None), "temperature.ambient"),
        (lambda c: c["temperature"].update(ambient=-300), "temperature.ambient"),
        (lambda c: c["temperature"].update(sources=[1]), "temperature.sources"),
        (lambda c: c.update(temperature=5), "temperature"),
        (lambda c: c["entities"]["hand"]["heat"].update(conduction=-1), "entities.hand.heat.conduction"),
        (lambda c: c["entities"]["hand"]["heat"].update(radiation=float("nan")), "entities.hand.heat.radiation"),
        (lambda c: c["entities"]["hand"]["heat"].update(cooling="fast"), "entities.hand.heat.cooling"),
        (lambda c: c["entities"]["hand"]["heat"].update(glow=1), "entities.hand.heat.glow"),
        (lambda c: c["entities"]["far"].update(heat=[1]), "entities.far.heat"),
        (lambda c: c.pop("temperature"), "entities.hand.heat"),  # heat rates without any source
    ],
)
def test_bad_configs_name_the_field(mutate, field):
  m = mujoco.MjModel.from_xml_path(SCENE)
  cfg = config()
  mutate(cfg)
  with pytest.raises(ValueError, match="^" + field.replace(".", r"\.") + ":"):
    M.bind(m, cfg)


def test_no_temperature_config_is_zero_cost():
  m = mujoco.MjModel.from_xml_path(SCENE)
  b = M.bind(m, {"entities": {"far": {"params": "laptop"}}})
  assert b.thermal is None
  ds = physics.init_state(b)
  assert ds.thermal is None
  assert T.advance(None, b, None, ds, 0.004) is ds  # nothing traced, nothing computed


def test_set_source_by_index_and_name(scene):
  _, _, b, _, _ = scene
  ds = physics.init_state(b)
  off = T.set_source(ds, 0, False)
  assert float(off.thermal.source_on[0]) == 0.0
  hot = T.set_source(off, "burner", 0.5, binding=b, temperature=500.0)
  assert float(hot.thermal.source_on[0]) == 0.5 and float(hot.thermal.source_temperature[0]) == 500.0
  with pytest.raises(ValueError, match="^source:"):
    T.set_source(ds, "oven", True, binding=b)
  with pytest.raises(ValueError, match="^source:"):
    T.source_index(b, 7)

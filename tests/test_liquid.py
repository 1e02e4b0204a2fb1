"""Liquid model: a glass holds and pours, exposure and fluid damage, conservation, validation.

Scene ``tests/scenes/liquid_glass.xml``: a glass of five box geoms (inner cavity
60×60 mm, 100 mm deep) on a hinge tilted by a position actuator, and a
laptop-sized box on the floor. One jitted control step (25 substeps = 0.1 s)
compiled once per module drives the full-physics scenarios; the long
conservation run advances the liquid alone against fixed geom poses.
"""

import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjx_damage as M
from mjx_damage import geometry as G
from mjx_damage import liquid as Lq
from mjx_damage import neighbours as NB
from mjx_damage import physics

SCENE = os.path.join(os.path.dirname(__file__), "scenes", "liquid_glass.xml")
SUBSTEPS = 25
P = 64
R = 0.006
TILT = np.deg2rad(120.0)
CONFIG = {
    "entities": {"laptop": {"params": "laptop"}},  # fluid C = 20 particles, Λ = 5
    "liquid": {"particles": P, "radius": R, "spawn": {"body": "glass", "offset": [0, 0, 0.045], "size": [0.02, 0.02, 0.03]}},
}


@pytest.fixture(scope="module")
def scene():
  m = mujoco.MjModel.from_xml_path(SCENE)
  b = M.bind(m, CONFIG)
  mx = mjx.put_model(m)

  @jax.jit
  def control_step(d, ds, ctrl):
    return physics.step(mx, b, d.replace(ctrl=ctrl), ds, SUBSTEPS)

  # fresh state built under jit: eagerly built mjx.Data differs from jit outputs in
  # ways that would make control_step compile a second time on its own output
  fresh = jax.jit(lambda key: (mjx.make_data(mx), physics.init_state(b, rng=key)))
  return m, mx, b, control_step, fresh


def in_glass(d, pos) -> np.ndarray:
  """bool[P]: particle centre inside the glass cavity (glass frame)."""
  rot = np.asarray(d.xmat[1]).reshape(3, 3)
  q = (np.asarray(pos) - np.asarray(d.xpos[1])) @ rot
  return (np.abs(q[:, 0]) < 0.03) & (np.abs(q[:, 1]) < 0.03) & (q[:, 2] > 0.006) & (q[:, 2] < 0.106)


def tilt_data(mx, angle):
  """Fresh data with the glass hinge at ``angle`` rad (qpos = [hinge, laptop free joint])."""
  d = mjx.make_data(mx)
  return d.replace(qpos=d.qpos.at[0].set(angle))


def min_sdf(b, mx, d, pos) -> float:
  """Smallest signed distance of any particle centre to any collidable geom, m."""
  phi, _, _ = G.points_to_geoms(b.liquid.groups, d, mx, jnp.asarray(pos))
  return float(jnp.min(phi))


@pytest.fixture(scope="module")
def upright_then_tilted(scene):
  """10 s upright (checked every second), then 3 s tilting to 120°."""
  m, mx, b, control_step, fresh = scene
  d, ds = fresh(jax.random.PRNGKey(1))
  upright = []
  for i in range(100):
    d, ds = control_step(d, ds, jnp.zeros(1))
    if i % 10 == 9:
      upright.append((in_glass(d, ds.liquid.pos).sum(), min_sdf(b, mx, d, ds.liquid.pos), np.asarray(ds.liquid.pos)))
  tilted = []
  for i in range(30):
    d, ds = control_step(d, ds, jnp.array([TILT]))
    tilted.append((in_glass(d, ds.liquid.pos).sum(), min_sdf(b, mx, d, ds.liquid.pos)))
  return upright, tilted, d, ds


def test_upright_glass_holds_liquid_for_10_s(upright_then_tilted):
  upright, _, _, _ = upright_then_tilted
  for inside, phi, pos in upright:
    assert inside == P
    assert phi > -1e-4  # no centre inside a solid (a particle overlaps a wall by at most its radius)
    assert np.all(np.isfinite(pos))
  # at rest: the last two seconds barely move (no jitter, no creeping leak)
  assert np.max(np.abs(upright[-1][2] - upright[-3][2])) < 2e-3


def test_tilting_120_degrees_empties_the_glass(upright_then_tilted):
  _, tilted, d, ds = upright_then_tilted
  assert abs(float(d.qpos[0]) - TILT) < 0.05
  assert tilted[-1][0] == 0
  assert all(phi > -1e-4 for _, phi in tilted)
  pos = np.asarray(ds.liquid.pos)
  assert pos.shape == (P, 3) and np.all(np.isfinite(pos))
  assert np.all(pos[:, 2] > R - 1e-3)  # on or above the floor, none fell through


def test_pouring_on_laptop_wets_and_damages_it(scene):
  m, mx, b, control_step, fresh = scene
  d, ds = fresh(jax.random.PRNGKey(0))
  # a column 4×4×4 on a 2r lattice, 0.1 m above the laptop's top face (z = 0.04)
  g = (np.arange(4) - 1.5) * 2 * R
  col = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) + [0.4, 0.0, 0.14 + 1.5 * 2 * R]
  ds = ds.replace(liquid=Lq.LiquidState(pos=jnp.asarray(col, jnp.float32), vel=jnp.zeros((P, 3))))
  exposure, fluid = [], []
  for _ in range(10):
    d, ds = control_step(d, ds, jnp.zeros(1))
    exposure.append(float(ds.exposure[0]))
    fluid.append(float(ds.step_damage.fluid[0]))
  assert exposure[0] == 0.0 and fluid[0] == 0.0  # still falling
  assert max(exposure) > 20.0  # above C_fluid
  assert max(fluid) > 0.0
  assert float(ds.link_health[0]) < 100.0


def test_exposure_counts_particles_within_contact_distance(scene):
  m, mx, b, _, _ = scene
  d = jax.jit(mjx.forward)(mx, mjx.make_data(mx))
  top = 0.02 + 0.01  # laptop top face, m
  on = np.stack([np.linspace(0.3, 0.5, 30), np.zeros(30), np.full(30, top + R)], -1)  # resting on it
  near = np.array([[0.4, 0.05, top + R + 0.5 * R]])  # gap r/2 < contact distance r
  away = np.stack([np.linspace(-1, -0.5, P - 31), np.full(P - 31, 1.0), np.full(P - 31, 0.5)], -1)
  pos = jnp.asarray(np.concatenate([on, near, away]), jnp.float32)
  ds = physics.init_state(b).replace(liquid=Lq.LiquidState(pos=pos, vel=jnp.zeros((P, 3))))
  out = jax.jit(lambda ds: Lq.advance(mx, b, d, ds, 1e-4))(ds)  # tiny dt: nothing moves appreciably
  assert float(out.exposure[0]) == 31.0


def test_count_conserved_and_finite_over_1e4_steps(scene):
  """10⁴ substeps of the liquid alone against the glass held at 120°: P finite particles, none in a solid."""
  m, mx, b, _, _ = scene
  d = jax.jit(mjx.forward)(mx, tilt_data(mx, TILT))
  ds = physics.init_state(b, rng=jax.random.PRNGKey(2))
  dt = float(m.opt.timestep)

  @jax.jit
  def run(ds):
    def body(ds, _):
      ds = Lq.advance(mx, b, d, ds, dt)
      phi, _, _ = G.points_to_geoms(b.liquid.groups, d, mx, ds.liquid.pos)
      ok = jnp.all(jnp.isfinite(ds.liquid.pos)) & jnp.all(jnp.isfinite(ds.liquid.vel))
      return ds, (ok, jnp.min(phi), ds.liquid.pos.shape[0])

    return jax.lax.scan(body, ds, None, length=10_000)

  ds, (ok, phi, count) = run(ds)
  assert np.all(np.asarray(ok))
  assert float(np.min(np.asarray(phi))) > -1e-4
  assert np.all(np.asarray(count) == P) and ds.liquid.pos.shape == (P, 3)
  assert np.all(np.asarray(ds.liquid.pos)[:, 2] > R - 1e-3)


@pytest.mark.slow
def test_count_conserved_full_physics_1e4_steps(scene):
  """10⁴ substeps of the full damage step while the glass swings back and forth."""
  m, mx, b, control_step, fresh = scene
  d, ds = fresh(jax.random.PRNGKey(0))
  for i in range(10_000 // SUBSTEPS):
    d, ds = control_step(d, ds, jnp.array([TILT * (i // 50 % 2)]))
    pos = np.asarray(ds.liquid.pos)
    assert pos.shape == (P, 3) and np.all(np.isfinite(pos))
    assert np.all(np.isfinite(np.asarray(ds.exposure)))


def test_sdf_matches_simple_cases():
  q = jnp.array([[0.0, 0.0, 2.0], [0.5, 0.0, 0.0], [3.0, 0.0, 0.0]])
  size = jnp.array([1.0, 1.0, 1.0])
  phi, n = G.sdf(G.BOX, q, size)
  np.testing.assert_allclose(np.asarray(phi), [1.0, -0.5, 2.0], atol=1e-6)
  np.testing.assert_allclose(np.asarray(n), [[0, 0, 1], [1, 0, 0], [1, 0, 0]], atol=1e-6)
  phi, _ = G.sdf(G.SPHERE, q, size)
  np.testing.assert_allclose(np.asarray(phi), [1.0, -0.5, 2.0], atol=1e-6)
  phi, n = G.sdf(G.CAPSULE, jnp.array([[0.0, 0.0, 3.0], [2.0, 0.0, 0.5]]), jnp.array([0.5, 1.0, 0.0]))
  np.testing.assert_allclose(np.asarray(phi), [1.5, 1.5], atol=1e-6)
  phi, n = G.sdf(G.CYLINDER, jnp.array([[0.0, 0.0, 3.0], [2.0, 0.0, 0.5], [0.0, 0.9, 0.0]]),
                 jnp.array([1.0, 1.0, 0.0]))
  np.testing.assert_allclose(np.asarray(phi), [2.0, 1.0, -0.1], atol=1e-6)
  np.testing.assert_allclose(np.asarray(n), [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-6)
  phi, n = G.sdf(G.PLANE, q, size)
  np.testing.assert_allclose(np.asarray(phi), [2.0, 0.0, 0.0], atol=1e-6)


def _with(**liquid):
  cfg = {"entities": CONFIG["entities"], "liquid": {**CONFIG["liquid"], **liquid}}
  return cfg


@pytest.mark.parametrize(
    "liquid, field",
    [
        ({"particles": 0}, "liquid.particles"),
        ({"particles": 64.0}, "liquid.particles"),
        ({"particles": True}, "liquid.particles"),
        ({"radius": -0.01}, "liquid.radius"),
        ({"radius": float("nan")}, "liquid.radius"),
        ({"damping": -1}, "liquid.damping"),
        ({"friction": 2}, "liquid.friction"),
        ({"pair_stiffness": "soft"}, "liquid.pair_stiffness"),
        ({"max_speed": 0}, "liquid.max_speed"),
        ({"iterations": 0}, "liquid.iterations"),
        ({"contact_distance": float("inf")}, "liquid.contact_distance"),
        ({"exclude": ["nope"]}, r"liquid.exclude\[0\]"),
        ({"exclude": "floor"}, "liquid.exclude"),
        ({"viscosity": 1}, "liquid.viscosity"),
        ({"spawn": {"body": "cup", "size": [0.01, 0.01, 0.01]}}, "liquid.spawn.body"),
        ({"spawn": {"center": [0, 0], "size": [0.01, 0.01, 0.01]}}, "liquid.spawn.center"),
        ({"spawn": {"center": [0, 0, 1], "size": [0.001, 0.001, 0.001]}}, "liquid.spawn.size"),
        ({"spawn": {"center": [0, 0, 1], "body": "glass", "size": [0.1, 0.1, 0.1]}}, "liquid.spawn"),
        ({"spawn": {"center": [0, 0, 1], "size": [0.1, -0.1, 0.1]}}, r"liquid.spawn.size\[1\]"),
        ({"spawn": None}, "liquid.spawn"),
        ({"pair_search": "fast"}, "liquid.pair_search"),
        ({"pair_candidates": 4}, "liquid.pair_candidates"),
        ({"pair_passes": 3}, "liquid.pair_passes"),
    ],
)
def test_bad_configs_name_the_field(liquid, field):
  m = mujoco.MjModel.from_xml_path(SCENE)
  with pytest.raises(ValueError, match="^" + field.replace(".", r"\.") + ":"):
    M.bind(m, _with(**liquid))


def test_missing_particles_and_wrong_type():
  m = mujoco.MjModel.from_xml_path(SCENE)
  with pytest.raises(ValueError, match=r"^liquid\.particles:"):
    M.bind(m, {"entities": CONFIG["entities"], "liquid": {"spawn": CONFIG["liquid"]["spawn"]}})
  with pytest.raises(ValueError, match=r"^liquid:"):
    M.bind(m, {"entities": CONFIG["entities"], "liquid": 128})


def test_no_liquid_config_is_zero_cost():
  m = mujoco.MjModel.from_xml_path(SCENE)
  b = M.bind(m, {"entities": CONFIG["entities"]})
  assert b.liquid is None
  ds = physics.init_state(b)
  assert ds.liquid is None
  assert Lq.advance(None, b, None, ds, 0.004) is ds


def test_spawn_follows_the_body(scene):
  m, mx, b, _, _ = scene
  d = jax.jit(mjx.forward)(mx, tilt_data(mx, 0.5))
  st = Lq.spawn(b, jax.random.PRNGKey(0), d)
  assert np.all(in_glass(d, st.pos)) and np.all(np.asarray(st.vel) == 0.0)
  assert min_sdf(b, mx, d, st.pos) > R - 1e-4  # not overlapping the glass


def test_grid_candidates_find_every_near_pair():
  """Cell lists vs brute force: a compressed pile, a loose cloud and points far outside the grid window."""
  rng = np.random.default_rng(0)
  h = 2.2 * R
  g = (np.arange(6) - 2.5) * 1.8 * R  # lattice 10 % tighter than 2r: a squeezed pile
  pile = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)[:100] + rng.uniform(-R / 4, R / 4, (100, 3))
  cloud = rng.uniform(-0.05, 0.05, (20, 3)) + [0.2, 0.0, 0.1]
  far = np.array([[9.0, 0.0, 0.0], [9.0 + R, 0.0, 0.0], [-20.0, 5.0, 1.0], [-20.0, 5.0, 1.0 + R],
                  [0.0, 0.0, -9.0], [0.0, 0.0, -9.0 - R], [30.0, 30.0, 30.0], [30.0, 30.0, 30.0]])
  pts = np.concatenate([pile, cloud, far]).astype(np.float32)
  j, valid, overflow = jax.jit(lambda p: NB.candidates(p, h, 64))(jnp.asarray(pts))
  j, valid = np.asarray(j), np.asarray(valid)
  dist = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
  near = (dist < h) & ~np.eye(len(pts), dtype=bool)
  assert int(np.max(np.asarray(overflow))) == 0
  for i in range(len(pts)):
    found = j[i][valid[i]]
    assert len(set(found.tolist())) == found.size  # no partner twice
    assert i not in found
    assert set(np.flatnonzero(near[i]).tolist()) <= set(found.tolist()), i


def test_grid_and_all_pair_search_agree(scene):
  """One substep of a settling pile is the same with cell lists and with every pair examined."""
  m, mx, _, _, _ = scene
  d = jax.jit(mjx.forward)(mx, mjx.make_data(mx))
  out = {}
  for search in ("grid", "all"):
    # 128 particles in mid-air (a 6 × 6 × 4 block): enough that the grid's 64 slots examine fewer than all
    b = M.bind(m, _with(particles=128, pair_search=search, spawn={"center": [0, 0.3, 0.5], "size": [0.03, 0.03, 0.03]}))
    assert b.liquid.pair_search == search
    ds = physics.init_state(b, rng=jax.random.PRNGKey(3))
    # squeeze the lattice by 15 % toward its centre and let it fall: every particle has overlapping partners
    pos = ds.liquid.pos
    c = jnp.mean(pos, axis=0)
    ds = ds.replace(liquid=Lq.LiquidState(pos=c + 0.85 * (pos - c), vel=jnp.zeros_like(pos) - 0.3))
    out[search] = jax.jit(lambda ds, b=b: Lq.advance(mx, b, d, ds, float(m.opt.timestep)))(ds).liquid
  np.testing.assert_allclose(np.asarray(out["grid"].pos), np.asarray(out["all"].pos), atol=1e-6)
  np.testing.assert_allclose(np.asarray(out["grid"].vel), np.asarray(out["all"].vel), atol=1e-4)
  assert float(jnp.max(jnp.abs(out["all"].vel + 0.3))) > 1e-2  # the pairs did push


def test_auto_pair_search_picks_the_grid_for_many_particles():
  m = mujoco.MjModel.from_xml_path(SCENE)
  assert M.bind(m, CONFIG).liquid.pair_search == "all"
  big = {"particles": Lq.GRID_FROM, "spawn": {"center": [0, 0, 1], "size": [0.1, 0.1, 0.1]}}
  assert M.bind(m, _with(**big)).liquid.pair_search == "grid"


def test_floor_has_the_last_word_over_a_body_pressed_onto_it(scene):
  """Particles under a box that rests on the floor: the box pushes them down, the floor up.

  Both pushes summed once sank them up to 1 mm below the floor (the soak then counted lost
  particles in move_glass_of_water, where a glass is set down on spilt water); the world's
  planes now act last, so no particle ends below the floor plane + its radius."""
  m, mx, b, _, _ = scene
  d0 = mjx.make_data(mx)
  d = jax.jit(mjx.forward)(mx, d0.replace(qpos=d0.qpos.at[3].set(0.010)))  # laptop bottom face on the floor
  assert b.liquid.world_planes  # the floor is a column of its own
  x = np.linspace(0.34, 0.46, P)
  for z in (0.002, 0.004):
    pos = np.stack([x, np.zeros(P), np.full(P, z)], -1).astype(np.float32)
    ds = physics.init_state(b, rng=jax.random.PRNGKey(0))
    ds = ds.replace(liquid=Lq.LiquidState(pos=jnp.asarray(pos), vel=jnp.zeros((P, 3))))
    for _ in range(20):
      ds = Lq.advance(mx, b, d, ds, float(m.opt.timestep))
    assert float(jnp.min(ds.liquid.pos[:, 2])) >= R - 1e-6, z


def _scattered(b, seed=0, spread=0.05):
  """Particles scattered around the glass (inside, in its walls, under the floor): every geom case."""
  k1, k2 = jax.random.split(jax.random.PRNGKey(seed))
  centre = jnp.array([0.0, 0.0, 0.35])  # the glass
  p = centre + jax.random.normal(k1, (b.liquid.num_particles, 3)) * spread
  p = p.at[:4].set(jnp.array([[0, 0, -0.003], [0.3, 0, 0.001], [0, 0, 0.0], [0, 0.2, 0.004]]))  # at the floor
  p = p.at[4:8].set(jnp.array([[0.4, 0, 0.035], [0.5, 0.05, 0.03], [0.26, 0, 0.02], [0.4, 0.1, 0.02]]))  # on the laptop
  return p, jax.random.normal(k2, p.shape) * 0.3


def test_geom_pass_reductions_equal_the_dense_particle_geom_table(scene):
  """The pass's reductions give what the dense [P, G] table gives: push, closest geom, its normal, wet links."""
  _, mx, b, _, _ = scene
  lm = b.liquid
  d = jax.jit(mjx.kinematics)(mx, tilt_data(mx, 0.4))
  p, _ = _scattered(b)
  step, (phi_min, nx, ny, nz, col, bits) = Lq._geom_pass(lm, d, mx, p, last=True)
  phi, n = G.points_to_geoms_planes(lm.groups, d, mx, p)
  pen = jnp.maximum(R - phi, 0.0)
  dense_step = jnp.stack([jnp.sum(pen * c, axis=1) for c in n], axis=-1)
  np.testing.assert_allclose(step, dense_step, atol=1e-7)
  after = jnp.where(jnp.isin(jnp.arange(phi.shape[1]), jnp.array(lm.world_planes, jnp.int32)), jnp.inf, phi + pen)
  j = jnp.argmin(after, axis=1)
  np.testing.assert_array_equal(col, j)
  np.testing.assert_allclose(phi_min, jnp.min(after, axis=1), atol=0)
  for k, c in enumerate(n):
    np.testing.assert_allclose([nx, ny, nz][k], jnp.take_along_axis(c, j[:, None], axis=1)[:, 0], atol=0)
  wet = (after - R) < lm.contact_distance
  dense_links = jnp.any(wet[:, :, None] & lm.column_link_mask[None], axis=1)
  got = Lq._unpack_bits(bits, lm.column_link_mask.shape[1])
  np.testing.assert_array_equal(got, dense_links)
  assert bool(jnp.any(dense_links)) and bool(jnp.any(pen > 0))  # the case is not vacuous


def test_pair_passes_equal_the_pairwise_formulas(scene):
  """Pair push and damping from the reductions equal the per-pair formulas written out densely."""
  _, _, b, _, _ = scene
  lm = b.liquid
  p, v = _scattered(b, seed=3, spread=0.012)
  p = p.at[:8].set(p[8:16] + 0.002)  # no stragglers at the floor: a dense clump
  take, valid = Lq._partners(lm, p)
  push, count = Lq._pair_push(lm, p, take(p), valid)
  damp = Lq._pair_damp(lm, p, take(p), valid, count, v, take(v))
  pn, vn_ = np.asarray(p, np.float64), np.asarray(v, np.float64)
  diff = pn[:, None, :] - pn[None, :, :]
  dist = np.linalg.norm(diff, axis=-1)
  np.fill_diagonal(dist, np.inf)
  near = dist < 1.1 * 2 * R
  nrm = np.where(near[..., None], diff / np.where(near, dist, 1.0)[..., None], 0.0)
  overlap = np.where(near, np.maximum(2 * R - dist, 0.0), 0.0)
  raw = 0.5 * lm.pair_stiffness * np.sum(overlap[..., None] * nrm, axis=1)
  cap = np.minimum(1.0, 0.25 * R / np.maximum(np.linalg.norm(raw, axis=-1, keepdims=True), 1e-12))
  np.testing.assert_allclose(push, raw * cap, atol=2e-7)
  cnt = np.maximum(near.sum(1), 1)[:, None]
  np.testing.assert_allclose(count, cnt)
  rel = np.sum((vn_[:, None, :] - vn_[None, :, :]) * nrm, axis=-1)
  np.testing.assert_allclose(damp, -0.5 * np.sum(rel[..., None] * nrm, axis=1) / cnt, atol=2e-6)
  assert near.sum() > P and (overlap > 0).any()  # many touching pairs: not vacuous
  # pair_passes 1: the same push and damping from one reduction over the pairs
  push1, damp1 = Lq._pair_terms(lm, p, take(p), valid, v, take(v))
  np.testing.assert_allclose(push1, raw * cap, atol=2e-7)
  np.testing.assert_allclose(damp1, -0.5 * np.sum(rel[..., None] * nrm, axis=1) / cnt, atol=2e-6)

"""Liquid particles (MuJoCo has none): pure JAX state advanced each substep.

Config (top-level key ``liquid``)::

    liquid:
      particles: 128                # P, fixed per environment (never created or destroyed)
      radius: 0.008                 # m, particle radius
      spawn:                        # a box filled bottom-up on a lattice of spacing 2·radius
        center: [0, 0, 0.5]         # world frame, m ...
        size: [0.03, 0.03, 0.05]    # half-sizes, m
        # ... or relative to a body at the model's reset pose:
        # body: glass, offset: [0, 0, 0.02], size: [...]
      damping: 0.5                  # 1/s, linear drag on particle velocity
      friction: 0.02                # in [0, 1], share of tangential velocity removed per substep in contact (low: no angle of repose)
      contact_distance: 0.008       # m, surface gap within which a particle wets a link (default: radius)
      pair_stiffness: 0.6           # in [0, 1], particle–particle repulsion (0 = off: no pair work)
      pair_search: auto             # grid: cell lists (sort by cell, O(P·C)); all: every pair (O(P²), one fused pass);
                                    # auto: grid from 1024 particles
      pair_candidates: 64           # C, partner slots per particle with grid (the 27 cells around it)
      pair_passes: 1                # 1: push and damping in one pass over the pairs, at the predicted positions;
                                    # 2: damping in a second pass, on the velocity after the geom projection
      max_speed: 4.0                # m/s, speed clamp (also the tunnelling guard, see below)
      iterations: 2                 # geom projection passes per substep
      exclude: [flame_geom]         # geoms the liquid passes through (besides non-colliding ones)

Model (position-based dynamics, per physics substep dt, one environment)::

    v ← (v + g·dt) / (1 + damping·dt)
    p* = p + v·dt
    one pass over the pairs at p* (partners from cell lists of side 2.2 r or every pair, see pair_search):
      Δv = pair damping of v (relative normal velocity of touching pairs removed, see _pair_terms)
      v += Δv;  p* += Δv·dt + pair repulsion (pairs closer than 2r pushed apart, capped at r/4 per substep)
    repeat `iterations` times: for every collidable geom with φ(p*) < r: p* += (r − φ)·n
    then for every plane of the world body: p* += max(r − φ, 0)·n  (the floor has the last word)
    v ← (p* − p)/dt   (pair_passes 2: the damping is applied here instead, on this v, in a second pass)
    in contact: tangential v relative to the geom's surface velocity × (1 − friction),
                      approaching normal velocity removed;  ‖v‖ ≤ max_speed
    p ← p*

φ and n are the signed distance and outward normal of each geom in its own
frame (:mod:`mjx_damage.geometry`), with poses from ``d.geom_xpos/xmat`` of this
substep, so a moving wall pushes particles along (their velocity becomes the
wall's). Collidable geoms: plane, sphere, capsule, cylinder and box geoms with
non-zero contype or conaffinity, minus ``exclude``. One-way coupled: particles
never push bodies. No tunnelling while max_speed·dt < radius + the thinnest
wall's half-thickness (a particle's centre never crosses a wall's mid-plane
in one substep).

Exposure of tracked link l = number of particles whose surface gap φ − r to
any of l's collidable geoms is below ``contact_distance`` → ``ds.exposure``.

Seam used by :mod:`mjx_damage.physics`: :func:`build` (None when no liquid is
configured: nothing computed, every exposure stays 0), :func:`init`,
:func:`advance`; tasks that move the container at reset use :func:`spawn`.
"""

from __future__ import annotations

from typing import Mapping

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from mjx_damage import geometry as G
from mjx_damage import neighbours as NB
from mjx_damage.validate import check_keys as _check_keys
from mjx_damage.validate import fail as _fail
from mjx_damage.validate import mapping as _mapping
from mjx_damage.validate import integer as _int
from mjx_damage.validate import number as _number
from mjx_damage.validate import vec3 as _vec3

MAX_PARTICLES = 4096
DEFAULTS = {
    "radius": 0.008,
    "damping": 0.5,
    "friction": 0.02,
    "pair_stiffness": 0.6,
    "max_speed": 4.0,
    "iterations": 2,
    "pair_search": "auto",
    "pair_candidates": 64,
    "pair_passes": 1,
}
PAIR_SEARCHES = ("auto", "grid", "all")
# "auto" picks the grid from this many particles: below it, every pair in one fused pass is cheaper
# than sorting into cells (XLA:CPU, benchmarks/physics_models.py: grid ≈ 2.5 µs, all ≈ 0.4 µs·P/128 per particle)
GRID_FROM = 1024
_KEYS = ("particles", "radius", "spawn", "damping", "friction", "contact_distance", "pair_stiffness",
         "max_speed", "iterations", "exclude", "pair_search", "pair_candidates", "pair_passes")
_SPAWN_KEYS = ("center", "size", "body", "offset")
_JITTER = 0.05  # × radius: breaks the lattice's symmetry so piles settle naturally
_SKIN = 1.1  # pairs within 1.1 · 2r count as touching (resting neighbours count)


@struct.dataclass
class LiquidModel:
  """Static liquid model of one scene (closed over by the compiled step)."""

  radius: float = struct.field(pytree_node=False)
  damping: float = struct.field(pytree_node=False)
  friction: float = struct.field(pytree_node=False)
  contact_distance: float = struct.field(pytree_node=False)
  pair_stiffness: float = struct.field(pytree_node=False)
  max_speed: float = struct.field(pytree_node=False)
  iterations: int = struct.field(pytree_node=False)
  pair_search: str = struct.field(pytree_node=False)  # "grid" (cell lists) or "all" (every pair), resolved
  pair_candidates: int = struct.field(pytree_node=False)  # C, partner slots per particle with "grid"
  pair_passes: int = struct.field(pytree_node=False)  # 1: push and damping in one pass; 2: damping after the geoms
  spawn_body: int = struct.field(pytree_node=False)  # body id, or −1: world frame
  lattice: np.ndarray = struct.field(pytree_node=False)  # f32[P, 3] spawn points in the spawn frame, m
  spawn_pos: np.ndarray = struct.field(pytree_node=False)  # f32[3] spawn frame origin at reset pose
  spawn_mat: np.ndarray = struct.field(pytree_node=False)  # f32[3, 3] spawn frame axes at reset pose
  groups: tuple = struct.field(pytree_node=False)  # geometry.group_by_type of collidable geoms
  column_geom: np.ndarray = struct.field(pytree_node=False)  # i32[G] geom id of each sdf column
  column_link: np.ndarray = struct.field(pytree_node=False)  # i32[G] tracked link of each column or −1
  column_body: np.ndarray = struct.field(pytree_node=False)  # i32[G] body of each column
  column_root: np.ndarray = struct.field(pytree_node=False)  # i32[G] root body of each column
  column_link_mask: np.ndarray = struct.field(pytree_node=False)  # bool[G, L] column belongs to tracked link l
  world_planes: tuple = struct.field(pytree_node=False, default=())  # columns that are planes of the world body

  @property
  def num_particles(self) -> int:
    return self.lattice.shape[0]


@struct.dataclass
class LiquidState:
  """Particles of one environment.

  pos: f32[P, 3] world frame, m
  vel: f32[P, 3] world frame, m/s
  """

  pos: jax.Array
  vel: jax.Array


def _lattice(n: int, size: np.ndarray, spacing: float, field: str) -> np.ndarray:
  """n points on a cubic lattice inside the box of half-sizes ``size``, lowest layers first."""
  counts = np.floor(2 * size / spacing + 1e-9).astype(int) + 1
  if np.prod(counts) < n:
    _fail(field, f"a box of half-sizes {size.tolist()} holds only {int(np.prod(counts))} particles at spacing "
          f"2·radius = {spacing} m; need {n}: enlarge it or reduce particles/radius")
  axes = [(np.arange(c) - (c - 1) / 2.0) * spacing for c in counts]
  grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
  grid = grid[np.lexsort((grid[:, 0], grid[:, 1], grid[:, 2]))]  # z-major: fill from the bottom
  return grid[:n].astype(np.float32)


def build(model: mujoco.MjModel, binding, raw: Mapping):
  """Validate the ``liquid`` config against ``model``; None when there is none.

  Raises:
    ValueError: naming the field (bad type, out-of-range value, unknown body
      or geom, a spawn box too small for the particles).
  """
  cfg = raw.get("liquid")
  if cfg is None:
    return None
  _check_keys("liquid", _mapping("liquid", cfg), _KEYS)
  if "particles" not in cfg:
    _fail("liquid.particles", "required (number of particles per environment)")
  n = _int("liquid.particles", cfg["particles"], 1, MAX_PARTICLES)
  radius = _number("liquid.radius", cfg.get("radius", DEFAULTS["radius"]), positive=True)
  damping = _number("liquid.damping", cfg.get("damping", DEFAULTS["damping"]), lo=0.0)
  friction = _number("liquid.friction", cfg.get("friction", DEFAULTS["friction"]), lo=0.0, hi=1.0)
  contact = _number("liquid.contact_distance", cfg.get("contact_distance", radius), lo=0.0)
  stiff = _number("liquid.pair_stiffness", cfg.get("pair_stiffness", DEFAULTS["pair_stiffness"]), lo=0.0, hi=1.0)
  vmax = _number("liquid.max_speed", cfg.get("max_speed", DEFAULTS["max_speed"]), positive=True)
  iters = _int("liquid.iterations", cfg.get("iterations", DEFAULTS["iterations"]), 1, 8)
  search = cfg.get("pair_search", DEFAULTS["pair_search"])
  if search not in PAIR_SEARCHES:
    _fail("liquid.pair_search", f"expected one of {', '.join(PAIR_SEARCHES)}, got {search!r}")
  slots = _int("liquid.pair_candidates", cfg.get("pair_candidates", DEFAULTS["pair_candidates"]), 8, MAX_PARTICLES)
  passes = _int("liquid.pair_passes", cfg.get("pair_passes", DEFAULTS["pair_passes"]), 1, 2)
  if search == "auto":
    search = "grid" if n >= GRID_FROM else "all"
  if slots >= n - 1:
    search = "all"  # the grid cannot examine fewer partners than there are

  spawn = cfg.get("spawn")
  if not isinstance(spawn, Mapping):
    _fail("liquid.spawn", f"required: a mapping with center/size or body/offset/size, got {spawn!r}")
  _check_keys("liquid.spawn", spawn, _SPAWN_KEYS)
  if "size" not in spawn:
    _fail("liquid.spawn.size", "required: half-sizes [hx, hy, hz] of the spawn box, m")
  size = _vec3("liquid.spawn.size", spawn["size"], nonneg=True)
  if ("body" in spawn) == ("center" in spawn):
    _fail("liquid.spawn", "give exactly one of center (world frame) or body (+ offset)")
  data = mujoco.MjData(model)
  mujoco.mj_kinematics(model, data)  # reset pose (qpos0) for body-relative spawns
  if "body" in spawn:
    bname = spawn["body"]
    bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, bname) if isinstance(bname, str) else -1
    if bid < 0:
      _fail("liquid.spawn.body", f"unknown body {bname!r} in the model")
    if "offset" in spawn:
      offset = _vec3("liquid.spawn.offset", spawn["offset"])
    else:
      offset = np.zeros(3)
    spawn_pos = data.xpos[bid].copy()
    spawn_mat = data.xmat[bid].reshape(3, 3).copy()
    lattice = _lattice(n, size, 2 * radius, "liquid.spawn.size") + offset.astype(np.float32)
  else:
    if "offset" in spawn:
      _fail("liquid.spawn.offset", "only with spawn.body")
    bid = -1
    spawn_pos = _vec3("liquid.spawn.center", spawn["center"])
    spawn_mat = np.eye(3)
    lattice = _lattice(n, size, 2 * radius, "liquid.spawn.size")

  exclude = cfg.get("exclude", [])
  if isinstance(exclude, (str, bytes)) or not isinstance(exclude, (list, tuple)):
    _fail("liquid.exclude", f"expected a list of geom names, got {exclude!r}")
  excluded = set()
  for i, gname in enumerate(exclude):
    gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, gname) if isinstance(gname, str) else -1
    if gid < 0:
      _fail(f"liquid.exclude[{i}]", f"unknown geom {gname!r} in the model")
    excluded.add(gid)
  gtype = np.asarray(model.geom_type)
  solid = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
  ids = [g for g in range(model.ngeom) if solid[g] and g not in excluded and int(gtype[g]) in G.SUPPORTED]
  groups = G.group_by_type(np.array(ids, np.int32), gtype)
  order = np.concatenate([i for _, i in groups]).astype(np.int32) if groups else np.zeros(0, np.int32)
  body = model.geom_bodyid[order].astype(np.int32)
  column_link = np.asarray(binding.geom_link)[order].astype(np.int32)
  return LiquidModel(
      radius=radius,
      damping=damping,
      friction=friction,
      contact_distance=contact,
      pair_stiffness=stiff,
      max_speed=vmax,
      iterations=iters,
      pair_search=search,
      pair_candidates=slots,
      pair_passes=passes,
      spawn_body=int(bid),
      lattice=lattice,
      spawn_pos=spawn_pos.astype(np.float32),
      spawn_mat=spawn_mat.astype(np.float32),
      groups=groups,
      column_geom=order,
      column_link=column_link,
      column_body=body,
      column_root=model.body_rootid[body].astype(np.int32),
      column_link_mask=column_link[:, None] == np.arange(binding.num_links)[None, :],
      world_planes=tuple(int(k) for k in np.flatnonzero((gtype[order] == mujoco.mjtGeom.mjGEOM_PLANE) & (body == 0))),
  )


def _spawn_points(lm: LiquidModel, rng, pos, mat) -> LiquidState:
  jitter = jax.random.uniform(rng, lm.lattice.shape, jnp.float32, -_JITTER, _JITTER) * lm.radius
  local = jnp.asarray(lm.lattice) + jitter
  world = jnp.asarray(pos) + local @ jnp.asarray(mat).T
  return LiquidState(pos=world, vel=jnp.zeros_like(world))


def init(binding, rng):
  """Particles at rest in the spawn box (body spawns: the body's reset pose), or None."""
  lm = binding.liquid
  if lm is None:
    return None
  return _spawn_points(lm, rng, lm.spawn_pos, lm.spawn_mat)


def spawn(binding, rng, d) -> LiquidState:
  """Particles at rest in the spawn box placed at ``d``'s pose of the spawn body.

  For tasks that move the container at reset: call after kinematics
  (``mjx.forward``/``mjx.kinematics``) and put the result in ``ds.liquid``.
  Jittable; ``d`` is one environment's mjx.Data.
  """
  lm = binding.liquid
  if lm is None:
    _fail("liquid", "no liquid configured")
  if lm.spawn_body < 0:
    return _spawn_points(lm, rng, lm.spawn_pos, lm.spawn_mat)
  return _spawn_points(lm, rng, d.xpos[lm.spawn_body], d.xmat[lm.spawn_body].reshape(3, 3))


def _partners(lm: LiquidModel, p: jax.Array):
  """Pair partners of every particle at the predicted positions ``p`` f32[P, 3].

  Returns ``(take, valid)``: ``take(x)`` maps per-particle vectors x f32[P, 3]
  to their partners' components, three f32[P, C] (``all``: C = P, rows broadcast;
  ``grid``: the cell lists' candidate slots), ``valid`` bool[P, C].
  """
  P = lm.num_particles
  if lm.pair_search == "all":
    # broadcast, not gather: the pair pass stays one fused elementwise + reduce
    return (lambda x: [x[None, :, k] for k in range(3)]), ~jnp.eye(P, dtype=bool)
  j, valid, _ = NB.candidates(p, _SKIN * 2.0 * lm.radius, lm.pair_candidates)
  return (lambda x: [x[:, k][j] for k in range(3)]), valid


def _sums(terms: tuple) -> tuple:
  """Sums over axis 1 of several f32[P, K] terms (pairs or particle–geom columns) in ONE variadic reduction.

  The terms are elementwise expressions sharing subexpressions (squared distances,
  normals). As separate ``jnp.sum`` calls XLA:GPU stored the shared parts as
  [envs, P, K] arrays between them and read them back: for all particle pairs at
  32768 envs × 128 particles, five 2 GB arrays per substep, and the pair pass was 2/3
  of the liquid's time. With one reduction of several outputs it stores only the
  shared weights (with two pair passes: one f32 and one bool array for the push, one
  f32 for the damping; its optimised HLO, ``liquid_speed.py --hlo-dir``). Measured by
  ``benchmarks/liquid_speed.py`` (results/liquid_speed_gpu.md): summing the stacked
  terms instead is 2.5× slower on a GPU, and slower on XLA:CPU too.
  """
  zeros = tuple(jnp.zeros((), t.dtype) for t in terms)
  return tuple(jax.lax.reduce(terms, zeros, lambda a, b: tuple(x + y for x, y in zip(a, b)), (1,)))


def _pair_geometry(lm: LiquidModel, p: jax.Array, pj: list, valid: jax.Array):
  """(near bool[P, C], inv f32[P, C] 1/distance or 0, three f32[P, C] components of partner → particle).

  Coordinates are kept as separate [P, C] planes (partners on the minor axis)
  so every pair quantity is a contiguous, vectorisable row and the reductions
  run along it.
  """
  diff = [p[:, k : k + 1] - pj[k] for k in range(3)]  # static: x, y, z
  d2 = diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2]
  skin = _SKIN * 2.0 * lm.radius
  near = valid & (d2 < skin * skin)
  inv = jnp.where(near, jax.lax.rsqrt(jnp.maximum(d2, 1e-12)), 0.0)  # one rsqrt: no sqrt + divide
  return near, d2, inv, diff


def _capped_push(lm: LiquidModel, sx, sy, sz) -> jax.Array:
  """f32[P, 3] Jacobi push from the summed overlap terms, capped at r/4 per particle per substep.

  The cap keeps a dense pile from shoving a particle through a thin wall in one step.
  """
  push = 0.5 * lm.pair_stiffness * jnp.stack([sx, sy, sz], axis=-1)
  n = jnp.linalg.norm(push, axis=-1, keepdims=True)
  return push * jnp.minimum(1.0, 0.25 * lm.radius / jnp.maximum(n, 1e-12))


def _push_weight(lm: LiquidModel, near, d2, inv):
  """f32[P, C] overlap / distance of each touching pair: the push along diff is w · diff (no normal formed)."""
  return jnp.where(near, jnp.maximum(2.0 * lm.radius - d2 * inv, 0.0), 0.0) * inv


def _normal_velocity(v, vj: list, diff: list, inv) -> jax.Array:
  """f32[P, C] (Δv·diff)/‖diff‖²: times diff it is Δv's normal part, so the unit normal is never formed."""
  return sum((v[:, k : k + 1] - vj[k]) * diff[k] for k in range(3)) * inv * inv


def _pair_push(lm: LiquidModel, p: jax.Array, pj: list, valid: jax.Array):
  """Jacobi correction pushing overlapping pairs apart, f32[P, 3] m, and touching partners per particle f32[P, 1].

  Pairs within 2.2 r count as touching (a 10 % skin so resting neighbours count).
  Push along the unit vector n = diff/‖diff‖ by the overlap: overlap · inv · diff.
  Used with ``pair_passes`` 2; 1 uses :func:`_pair_terms`.
  """
  near, d2, inv, diff = _pair_geometry(lm, p, pj, valid)
  w = _push_weight(lm, near, d2, inv)
  sx, sy, sz, touching = _sums((w * diff[0], w * diff[1], w * diff[2], near.astype(p.dtype)))
  return _capped_push(lm, sx, sy, sz), jnp.maximum(touching, 1.0)[:, None]


def _pair_terms(lm: LiquidModel, p: jax.Array, pj: list, valid: jax.Array, v: jax.Array, vj: list):
  """Push f32[P, 3] m and damping f32[P, 3] m/s of every particle, in ONE pass over the pairs at ``p``.

  The damping (a dashpot on the relative normal velocity of touching pairs,
  averaged over each particle's touching partners so the Jacobi update never
  overshoots; it only removes energy, which lets a glass of liquid come to rest)
  acts on ``v``, the predicted velocity, with the pair geometry the push uses:
  one variadic reduction of seven sums instead of two passes that each rebuild
  the [P, C] geometry. The push's own velocity (push/dt) is damped in the next
  substep, before it moves the particle again.
  """
  near, d2, inv, diff = _pair_geometry(lm, p, pj, valid)
  w = _push_weight(lm, near, d2, inv)
  vn = _normal_velocity(v, vj, diff, inv)
  sx, sy, sz, touching, dx, dy, dz = _sums(
      (w * diff[0], w * diff[1], w * diff[2], near.astype(p.dtype), vn * diff[0], vn * diff[1], vn * diff[2]))
  count = jnp.maximum(touching, 1.0)[:, None]
  return _capped_push(lm, sx, sy, sz), -0.5 * jnp.stack([dx, dy, dz], axis=-1) / count


def _pair_damp(lm: LiquidModel, p, pj, valid, count, v: jax.Array, vj: list) -> jax.Array:
  """Velocity change removing relative normal motion of touching pairs, f32[P, 3] m/s.

  ``pair_passes`` 2: the velocity after the geom projection, pushes included, is
  damped in this second pass (:func:`_pair_terms` explains the dashpot). The pair
  geometry is recomputed from ``p`` (the predicted positions the push used) inside
  this pass's own reduction: the optimisation barrier keeps
  XLA from merging it with the push's, which would keep [P, C] normals alive
  in memory across the geom passes.
  """
  p, pj = jax.lax.optimization_barrier((p, pj))
  _, _, inv, diff = _pair_geometry(lm, p, pj, valid)
  vn = _normal_velocity(v, vj, diff, inv)
  sx, sy, sz = _sums(tuple(vn * diff[k] for k in range(3)))
  return -0.5 * jnp.stack([sx, sy, sz], axis=-1) / count


_NO_COLUMN = np.iinfo(np.int32).max


def _wet_bits(lm: LiquidModel, phi: jax.Array, cols: np.ndarray) -> tuple:
  """Per column of ``cols`` (static), the bit of its tracked link where the particle wets it.

  ``phi`` f32[P, Gt] signed distances after the pass. Returns one u32[P, Gt] word per 32
  links: bit l % 32 of word l // 32 is set where the column belongs to link l and
  φ − r < contact_distance. OR-reduced over columns, they say which links a particle
  wets, each once however many of the link's geoms it touches.
  """
  link = lm.column_link[cols]  # static i32[Gt], −1: not a tracked link
  words = max(1, -(-lm.column_link_mask.shape[1] // 32))
  wet = (phi - lm.radius) < lm.contact_distance
  out = []
  for w in range(words):
    mine = (link >= 0) & (link // 32 == w)
    bit = np.where(mine, np.left_shift(np.uint32(1), np.where(mine, link % 32, 0).astype(np.uint32)), np.uint32(0))
    out.append(jnp.where(wet & (bit != 0)[None, :], jnp.asarray(bit)[None, :], jnp.uint32(0)))
  return tuple(out)


def _unpack_bits(bits: tuple, num_links: int) -> jax.Array:
  """bool[P, L] from the words of :func:`_wet_bits`."""
  link = np.arange(num_links)
  word = jnp.stack(bits, axis=-1)[:, link // 32]  # [P, L]
  return (jnp.right_shift(word, jnp.asarray(link % 32, jnp.uint32)) & 1) == 1


def _closer(a: tuple, b: tuple):
  """b's record replaces a's: a smaller distance, ties to the lower column (argmin's rule)."""
  return (b[0] < a[0]) | ((b[0] == a[0]) & (b[4] < a[4]))


def _merge_closest(a: tuple, b: tuple) -> tuple:
  """Two closest-geom records (phi, nx, ny, nz, column, wet words) combined."""
  take = _closer(a, b)
  return tuple(jnp.where(take, y, x) for x, y in zip(a[:5], b[:5])) + (tuple(x | y for x, y in zip(a[5], b[5])),)


def _geom_pass(lm: LiquidModel, d, m, p: jax.Array, last: bool):
  """One projection pass of every particle against every collidable geom, as reductions over the geoms.

  Returns the push f32[P, 3] (every geom the particle's sphere penetrates pushes it out
  along its normal by the depth) and, on the ``last`` pass, the closest-geom record
  (φ after the push f32[P], its normal as three f32[P], its column i32[P], the wet-link
  words u32[P] each) over every column but the world's planes (which act after the
  pass, see :func:`advance`); otherwise None. Each type group is one variadic
  reduction over its columns, so the dense pass's [P, G] distance and normal tables
  and its separate argmin, min, gather and per-link passes are gone (XLA:GPU still
  stores the pushes' [P, Gt] terms once per pass). Unrolling over the geoms instead
  (all on [P] vectors) was measured slower on an H100 and on XLA:CPU.
  """
  world = set(lm.world_planes)
  step, closest, offset = None, None, 0
  for gtype, ids in lm.groups:
    cols = np.arange(offset, offset + len(ids))
    offset += len(ids)
    phi, n = G.group_planes(gtype, ids, d, m, p)  # [P, Gt], normals broadcasting to it
    pen = jnp.maximum(lm.radius - phi, 0.0)
    terms = tuple(pen * c for c in n)
    if not last:
      sums = _sums(terms)
    else:
      after = phi + pen  # φ after the push: exact for the geom pushed along its own normal
      skip = np.array([c in world for c in cols])
      val = jnp.where(jnp.asarray(skip)[None, :], jnp.inf, after)
      idx = jnp.broadcast_to(jnp.asarray(cols, jnp.int32)[None, :], val.shape)
      bits = _wet_bits(lm, jnp.where(jnp.asarray(skip)[None, :], jnp.inf, after), cols)
      rec = (val,) + tuple(jnp.broadcast_to(c, val.shape) for c in n) + (idx,)
      out = _reduce_geoms(terms, rec, bits)
      sums, group_closest = out[:3], tuple(out[3:8]) + (tuple(out[8:]),)
      closest = group_closest if closest is None else _merge_closest(closest, group_closest)
    s = jnp.stack(sums, axis=-1)
    step = s if step is None else step + s
  return step, closest


def _reduce_geoms(sums: tuple, rec: tuple, bits: tuple) -> tuple:
  """One variadic reduction over axis 1: the sums, the closest record (argmin's rule), the OR of the words."""
  ns = len(sums)
  init = (tuple(jnp.zeros((), t.dtype) for t in sums)
          + (jnp.float32(jnp.inf), jnp.float32(0), jnp.float32(0), jnp.float32(0), jnp.int32(_NO_COLUMN))
          + tuple(jnp.uint32(0) for _ in bits))

  def combine(a, b):
    s = tuple(x + y for x, y in zip(a[:ns], b[:ns]))
    ra, rb = a[ns : ns + 5], b[ns : ns + 5]
    take = _closer(ra, rb)
    r = tuple(jnp.where(take, y, x) for x, y in zip(ra, rb))
    w = tuple(x | y for x, y in zip(a[ns + 5 :], b[ns + 5 :]))
    return s + r + w

  return jax.lax.reduce(sums + rec + bits, init, combine, (1,))


def _surface_velocity(lm: LiquidModel, d, col: jax.Array, p: jax.Array) -> jax.Array:
  """f32[P, 3] velocity of geom column ``col[i]``'s material at particle i, m/s."""
  body = jnp.asarray(lm.column_body)[col]
  cvel = d.cvel[body]  # [P, 6] (angular, linear at the root subtree COM)
  origin = d.subtree_com[jnp.asarray(lm.column_root)[col]]
  return cvel[:, 3:] + jnp.cross(cvel[:, :3], p - origin)


def advance(m, binding, d, ds, dt):
  """One substep of every particle of one environment; writes ``ds.liquid`` and ``ds.exposure``.

  Reads geom poses and velocities of ``d`` after ``mjx.forward``. No-op without liquid.
  """
  lm = binding.liquid
  if lm is None:
    return ds
  st = ds.liquid
  r = lm.radius
  p0 = st.pos
  g = jnp.asarray(m.opt.gravity, jnp.float32)
  v = (st.vel + g * dt) / (1.0 + lm.damping * dt)
  p = p0 + v * dt
  pairs = lm.pair_stiffness > 0 and lm.num_particles > 1
  if pairs:
    take, valid = _partners(lm, p)
    p_pair = p
    if lm.pair_passes == 1:
      push, dv = _pair_terms(lm, p, take(p), valid, v, take(v))
      v = v + dv
      p = p + push + dv * dt
    else:
      push, count = _pair_push(lm, p_pair, take(p_pair), valid)
      p = p + push
  ncol = lm.column_geom.size
  if ncol:
    for it in range(lm.iterations):  # static: a few projection passes
      step, closest = _geom_pass(lm, d, m, p, last=it == lm.iterations - 1)
      p = p + step
    # The world's planes have the last word: a particle squeezed between a moving body and the floor
    # (a glass set down on it) gets opposite pushes that can sum downward, and once below a plane it
    # is lost from the scene. φ to a plane is linear in p, so its value after the pass is exact.
    lifts, planes = [], []
    for k in lm.world_planes:
      g = int(lm.column_geom[k])
      nk = d.geom_xmat[g].reshape(3, 3)[:, 2]  # the plane's +z axis, world frame
      phi_k = (p - d.geom_xpos[g]) @ nk  # [P], after the pass, before any plane's lift
      below = jnp.maximum(r - phi_k, 0.0)
      lifts.append(below[:, None] * nk)
      planes.append((k, phi_k + below, nk))
    for lift in lifts:
      p = p + lift
    for k, phi_k, nk in planes:  # merged into the closest-geom record, ties to the lower column as argmin
      key = (phi_k, *(jnp.broadcast_to(c, phi_k.shape) for c in nk), jnp.full_like(closest[4], k),
             tuple(w[:, 0] for w in _wet_bits(lm, phi_k[:, None], np.array([k]))))
      closest = _merge_closest(closest, key)
  v = (p - p0) / dt
  if pairs and lm.pair_passes == 2:
    v = v + _pair_damp(lm, p_pair, take(p_pair), valid, count, v, take(v))
  if ncol:
    # friction and no approach against the closest geom, in that geom's moving frame
    phi_min, nx, ny, nz, j, bits = closest
    nj = jnp.stack([nx, ny, nz], axis=-1)  # [P, 3]
    gap = phi_min - r
    vg = _surface_velocity(lm, d, j, p)
    rel = v - vg
    vn = jnp.sum(rel * nj, axis=-1, keepdims=True)
    vt = rel - vn * nj
    in_contact = (gap < 0.25 * r)[:, None]
    rel_c = jnp.maximum(vn, 0.0) * nj + (1.0 - lm.friction) * vt
    v = jnp.where(in_contact, vg + rel_c, v)
    # a particle touching several geoms of one link counts once: one bit per link
    exposure = jnp.sum(_unpack_bits(bits, lm.column_link_mask.shape[1]), axis=0).astype(jnp.float32)
  else:
    exposure = jnp.zeros_like(ds.exposure)
  speed = jnp.linalg.norm(v, axis=-1, keepdims=True)
  v = v * jnp.minimum(1.0, lm.max_speed / jnp.maximum(speed, 1e-12))
  ok = jnp.all(jnp.isfinite(p), axis=-1, keepdims=True) & jnp.all(jnp.isfinite(v), axis=-1, keepdims=True)
  # never let a non-finite value in (it would spread to every exposure): keep the last position
  p = jnp.where(ok, p, p0)
  v = jnp.where(ok, v, 0.0)
  return ds.replace(liquid=LiquidState(pos=p, vel=v), exposure=exposure)

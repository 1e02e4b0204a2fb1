"""Throughput of the damage step with and without the temperature and liquid models.

One scene for every variant: a glass of box geoms on a hinge (tilted back and
forth by a position actuator), a laptop-sized box beside it, a burner block
under a slide-mounted "hand". Four variants differ only in the damage config:

* ``base``        — mechanical/thermal/fluid DEMs, no temperature, no liquid;
* ``temperature`` — + the burner as a 300 °C heat source;
* ``liquid``      — + ``--particles`` particles in the glass (default ``pair_search: auto``);
* ``liquid_grid`` — the same liquid with pairs found by cell lists (``pair_search: grid``);
* ``both``        — temperature and liquid.

Each variant runs ``jit(fori_loop(vmap(physics.step)))`` over ``--envs``
environments for ``--steps`` env steps of ``--substeps`` physics substeps and
records env-steps/s of the best of ``--repeats`` calls after an ahead-of-time compile
(``--clock cpu`` times process CPU seconds instead of wall seconds: steadier on a
shared machine, and the same thing on an otherwise idle one with all cores busy). One JSON per
run under ``benchmarks/results/`` (or ``--out``), with the exact command.

    .venv/bin/python benchmarks/physics_models.py               # 1024 envs × 128 particles
    .venv/bin/python benchmarks/physics_models.py --envs 64 --steps 10 --out /tmp/x.json
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))  # the repo's mjx_damage, wherever this is run from

SCENE = """
<mujoco model="physics_models_bench">
  <!-- Kept cheap for a 2-core CPU: the only contact pair is the hand sphere on the
       burner box; the glass collides with nothing (contype 2) but the liquid. -->
  <option timestep="0.004" integrator="implicitfast"/>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1" contype="4" conaffinity="4"/>
    <body name="glass" pos="0 0 0.3">
      <joint name="tilt" type="hinge" axis="1 0 0" damping="2"/>
      <geom name="glass_bottom" type="box" size="0.036 0.036 0.003" pos="0 0 0.003" mass="0.05" contype="2" conaffinity="2"/>
      <geom name="glass_px" type="box" size="0.003 0.036 0.05" pos="0.033 0 0.056" mass="0.02" contype="2" conaffinity="2"/>
      <geom name="glass_nx" type="box" size="0.003 0.036 0.05" pos="-0.033 0 0.056" mass="0.02" contype="2" conaffinity="2"/>
      <geom name="glass_py" type="box" size="0.03 0.003 0.05" pos="0 0.033 0.056" mass="0.02" contype="2" conaffinity="2"/>
      <geom name="glass_ny" type="box" size="0.03 0.003 0.05" pos="0 -0.033 0.056" mass="0.02" contype="2" conaffinity="2"/>
    </body>
    <body name="laptop" pos="0 -0.25 0.01">
      <geom name="laptop" type="box" size="0.15 0.1 0.01" contype="4" conaffinity="4"/>
    </body>
    <geom name="burner" type="box" size="0.1 0.1 0.05" pos="0.5 0 0.05"/>
    <body name="hand" pos="0.5 0 0.2" gravcomp="1">
      <joint name="hz" type="slide" axis="0 0 1" damping="20"/>
      <geom name="hand" type="sphere" size="0.02" mass="0.2"/>
    </body>
  </worldbody>
  <actuator>
    <position name="tilt" joint="tilt" kp="40" ctrlrange="-3.2 3.2"/>
    <position name="hz" joint="hz" kp="400" ctrlrange="-0.5 0.5"/>
  </actuator>
</mujoco>
"""


def configs(particles: int) -> dict:
  entities = {"laptop": {"params": "laptop"}, "hand": {"params": "agent"}}
  temperature = {"sources": {"burner": {"geom": "burner", "temperature": 300.0}}}
  # a spawn box that holds `particles` on the 2r lattice inside the glass cavity
  liquid = {"particles": particles, "radius": 0.006,
            "spawn": {"body": "glass", "offset": [0, 0, 0.075], "size": [0.022, 0.022, 0.064]}}
  return {
      "base": {"entities": entities},
      "temperature": {"entities": entities, "temperature": temperature},
      "liquid": {"entities": entities, "liquid": liquid},
      "liquid_grid": {"entities": entities, "liquid": {**liquid, "pair_search": "grid"}},
      "both": {"entities": entities, "temperature": temperature, "liquid": liquid},
  }


def measure(name: str, config: dict, envs: int, steps: int, substeps: int, clock=time.perf_counter, repeats: int = 1) -> dict:
  import jax
  import jax.numpy as jnp
  import mujoco
  from mujoco import mjx

  import mjx_damage as M
  from mjx_damage import physics

  m = mujoco.MjModel.from_xml_string(SCENE)
  b = M.bind(m, config)
  mx = mjx.put_model(m)
  # Build the batch inside jit: eagerly built mjx.Data differs from jit outputs in
  # ways that make `run` compile a second time on its own output.
  init = jax.jit(jax.vmap(lambda k: (mjx.make_data(mx), physics.init_state(b, rng=k))))
  d, ds = init(jax.random.split(jax.random.PRNGKey(0), envs))

  def one(d, ds):
    # the glass swings ±1.2 rad over 4 s; the hand presses on the burner half the time
    t = d.time
    ctrl = jnp.stack([1.2 * jnp.sin(2 * jnp.pi * t / 4.0), jnp.where(jnp.sin(2 * jnp.pi * t / 2.0) > 0, -0.1, 0.05)])
    return physics.step(mx, b, d.replace(ctrl=ctrl), ds, substeps)

  step = jax.vmap(one)

  @jax.jit
  def run(d, ds):
    return jax.lax.fori_loop(0, steps, lambda _, c: step(*c), (d, ds))

  t0 = time.perf_counter()
  compiled = run.lower(d, ds).compile()  # ahead of time: no compilation inside the timed calls
  compile_s = time.perf_counter() - t0
  wall = float("inf")
  for _ in range(repeats):  # each call continues from the last one's state
    t0 = clock()
    d, ds = jax.block_until_ready(compiled(d, ds))
    wall = min(wall, clock() - t0)
  d2, ds2 = d, ds
  ok = bool(jnp.all(jnp.isfinite(ds2.temperature))) and (
      ds2.liquid is None or bool(jnp.all(jnp.isfinite(ds2.liquid.pos))))
  out = {
      "variant": name,
      "env_steps_per_s": envs * steps / wall,
      "physics_steps_per_s": envs * steps * substeps / wall,
      "wall_s": wall,
      "compile_s": compile_s,
      "finite": ok,
      "mean_laptop_exposure": float(jnp.mean(ds2.exposure[:, 0])),
      "max_hand_temperature_c": float(jnp.max(ds2.temperature[:, 1])),
  }
  print(json.dumps(out), flush=True)
  return out


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--envs", type=int, default=1024)
  p.add_argument("--steps", type=int, default=5, help="env steps timed per variant (after an ahead-of-time compile)")
  p.add_argument("--substeps", type=int, default=5, help="physics substeps (4 ms) per env step")
  p.add_argument("--particles", type=int, default=128)
  p.add_argument("--variants", default="base,temperature,liquid,liquid_grid,both")
  p.add_argument("--repeats", type=int, default=1, help="timed calls per variant (best kept)")
  p.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                 help="cpu: process CPU time (all threads), steadier than wall time on a shared, loaded machine")
  p.add_argument("--out", default=None, help="JSON path (default benchmarks/results/physics_models_<device>_<time>.json)")
  a = p.parse_args(argv)
  for k in ("envs", "steps", "substeps", "particles", "repeats"):
    if getattr(a, k) < 1:
      p.error(f"--{k}: must be >= 1")
  cfgs = configs(a.particles)
  variants = a.variants.split(",")
  for v in variants:
    if v not in cfgs:
      p.error(f"--variants: unknown variant {v!r}; variants: {', '.join(cfgs)}")

  os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))
  import jax

  from mjx_damage import io, runtime

  clock = time.perf_counter if a.clock == "wall" else time.process_time
  results = [measure(v, cfgs[v], a.envs, a.steps, a.substeps, clock, a.repeats) for v in variants]
  device = jax.devices()[0]
  record = {
      "benchmark": "physics_models",
      "command": " ".join(shlex.quote(x) for x in [sys.executable, *sys.argv]),
      **runtime.run_facts(),
      "envs": a.envs,
      "steps": a.steps,
      "substeps": a.substeps,
      "timestep_s": 0.004,
      "particles": a.particles,
      "clock": a.clock,
      "repeats": a.repeats,
      "results": results,
  }
  out = a.out or os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                              f"physics_models_{device.platform}_{record['timestamp_utc']}.json")
  io.write_json(out, record)
  print(f"wrote {out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

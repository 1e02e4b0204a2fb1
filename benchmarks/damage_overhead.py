"""Cost of damage tracking: env-steps/s of the drop scene with damage on and off.

The same batched, compiled control step (5 physics substeps) is timed with
``mjx_damage.physics.step`` (damage at every substep) and with a plain loop of
``mjx.step``; results go to ``benchmarks/results/damage_overhead_<device>.json``.

    python benchmarks/damage_overhead.py                      # CPU: 1, 64, 1024 envs
    python benchmarks/damage_overhead.py --envs 1 1024 32768  # e.g. on a GPU
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from mjx_damage import physics
from tasks.drop import DropEnv


def timed(fn, args, steps):
  """Compile once, warm up, then time ``steps`` calls; returns (compile_s, seconds per call)."""
  t0 = time.perf_counter()
  compiled = jax.jit(fn).lower(*args).compile()
  compile_s = time.perf_counter() - t0
  out = jax.block_until_ready(compiled(*args))  # warm-up
  t0 = time.perf_counter()
  for _ in range(steps):
    out = compiled(*out) if isinstance(out, tuple) else compiled(out)
  jax.block_until_ready(out)
  return compile_s, (time.perf_counter() - t0) / steps


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  ap.add_argument("--envs", type=int, nargs="+", default=[1, 64, 1024])
  ap.add_argument("--steps", type=int, default=10, help="timed control steps per setting")
  ap.add_argument("--out", default=None, help="JSON path (default benchmarks/results/damage_overhead_<device>.json)")
  args = ap.parse_args(argv)
  if min(args.envs) < 1 or args.steps < 1:
    ap.error("--envs and --steps must be >= 1")

  env = DropEnv(min_height=0.0, max_height=0.3)
  m, b, n_sub = env.sys, env.damage_binding, env.n_substeps
  on = lambda d, ds: jax.vmap(lambda d, ds: physics.step(m, b, d, ds, n_sub))(d, ds)
  off = lambda d: jax.vmap(lambda d: physics.step_without_damage(m, d, n_sub))(d)
  device = jax.devices()[0]
  rows = []
  for n in args.envs:
    heights = jax.random.uniform(jax.random.PRNGKey(0), (n,), minval=0.0, maxval=0.3)
    d = jax.vmap(env.drop_data)(heights)
    ds = jax.vmap(lambda _: physics.init_state(b))(heights)
    c_on, t_on = timed(on, (d, ds), args.steps)
    c_off, t_off = timed(off, (d,), args.steps)
    row = {
        "envs": n,
        "env_steps_per_s_damage_on": n / t_on,
        "env_steps_per_s_damage_off": n / t_off,
        "physics_steps_per_s_damage_on": n * n_sub / t_on,
        "physics_steps_per_s_damage_off": n * n_sub / t_off,
        "on_off_ratio": t_off / t_on,
        "compile_s_damage_on": c_on,
        "compile_s_damage_off": c_off,
    }
    rows.append(row)
    print(f"{n:>6} envs: on {row['env_steps_per_s_damage_on']:>10,.0f} env-steps/s, off "
          f"{row['env_steps_per_s_damage_off']:>10,.0f}, ratio {row['on_off_ratio']:.3f}", flush=True)
  result = {
      "command": "python " + " ".join([os.path.relpath(__file__)] + (argv if argv is not None else sys.argv[1:])),
      "scene": "tasks/drop.xml (plate + mug on a counter, 2 tracked links)",
      "control_step": f"{n_sub} physics substeps of {float(env.mj_model.opt.timestep) * 1e3:g} ms",
      "device": f"{device.platform}:{getattr(device, 'device_kind', '')}",
      "host": platform.node(),
      "cpu_count": os.cpu_count(),
      "jax": jax.__version__,
      "timed_steps": args.steps,
      "results": rows,
  }
  out = args.out or os.path.join(os.path.dirname(__file__), "results", f"damage_overhead_{device.platform}.json")
  os.makedirs(os.path.dirname(out), exist_ok=True)
  with open(out, "w") as f:
    json.dump(result, f, indent=2)
  print(f"wrote {out}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

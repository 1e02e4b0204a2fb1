"""Where the liquid's time goes: ``liquid.advance`` alone, batched, with parts of it switched off.

The liquid is most of pour_water's step on a GPU (``step_overhead.py``: 83 % at
32768 envs). This script isolates it: the task's scene and its reset states
(geom poses held), ``--substeps`` calls of ``vmap(liquid.advance)`` in one
``lax.scan``, compiled ahead of time and timed after a warm-up (best of
``--repeats``). Variants change only the static liquid model:

* ``full``      — the task's liquid as configured;
* ``no_pairs``  — particle–particle pairs off (``pair_stiffness`` 0): the pair pass's cost;
* ``no_geoms``  — no collidable geom: the particle–geom passes' cost (integration and pairs left);
* ``iter1`` / ``iter2`` — one / two geom projection passes per substep instead of the configured number;
* ``grid32`` / ``grid64`` — pairs from cell lists with 32 / 64 partner slots instead of every pair;
* ``two_pass``  — the pair damping in a second pass over the pairs, after the geom projection
  (``pair_passes`` 2, the method before one fused pass became the default).

Variants combine with ``+`` (applied left to right): ``two_pass+iter2`` is pour_water's liquid
before session 28 (two pair passes, two geom passes).

Rates are particle-substeps/s and the env-steps/s they allow at the task's
``n_substeps`` (liquid only). ``--hlo-dir`` writes the optimised HLO of each
variant (what XLA fused, and which [envs, P, P] or [envs, P, G] intermediates
reach memory) and XLA's cost analysis (bytes accessed) goes in every row. ``--robot``
(default the gripper, the robot of the committed results) other than the gripper is in
the results, their default name and the HLO file names.

    python benchmarks/liquid_speed.py --envs 32768 --out $OUT/liquid_speed_gpu.json --hlo-dir $OUT/hlo
    python benchmarks/liquid_speed.py --envs 64 --substeps 6 --out /tmp/liquid_speed.json     # CPU smoke
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

VARIANTS = ("full", "no_pairs", "no_geoms", "iter1", "iter2", "grid32", "grid64", "two_pass")


def variant_model(lm, variant: str):
  """The static liquid model of ``variant`` (``lm``: the task's); ``a+b`` applies a, then b."""
  import numpy as np

  if "+" in variant:
    for part in variant.split("+"):
      lm = variant_model(lm, part)
    return lm
  if variant == "full":
    return lm
  if variant == "no_pairs":
    return lm.replace(pair_stiffness=0.0)
  if variant == "no_geoms":
    z = np.zeros(0, np.int32)
    return lm.replace(groups=(), column_geom=z, column_link=z, column_body=z, column_root=z,
                      column_link_mask=np.zeros((0, lm.column_link_mask.shape[1]), bool), world_planes=())
  if variant in ("iter1", "iter2"):
    return lm.replace(iterations=int(variant[4:]))
  if variant in ("grid32", "grid64"):
    return lm.replace(pair_search="grid", pair_candidates=int(variant[4:]))
  if variant == "two_pass":
    return lm.replace(pair_passes=2)
  raise ValueError(f"variant: unknown {variant!r}; valid: {', '.join(VARIANTS)}")


def measure(task_name: str, variant: str, envs: int, substeps: int, repeats: int, hlo_dir: str | None,
            robot: str = "gripper") -> dict:
  import jax

  import tasks
  from mjx_damage import liquid as Lq

  env = tasks.make(task_name, robot=robot)
  task = env.unwrapped
  b = task.damage_binding
  if b.liquid is None:
    raise SystemExit(f"--task: {task_name} has no liquid")
  b = dataclasses.replace(b, liquid=variant_model(b.liquid, variant))
  m = task.sys
  dt = float(m.opt.timestep)
  state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), envs))
  d, ds = state.pipeline_state, state.info["damage_state"]

  def run(ds):
    def body(ds, _):
      return jax.vmap(lambda d1, s1: Lq.advance(m, b, d1, s1, dt))(d, ds), None
    return jax.lax.scan(body, ds, None, length=substeps)[0]

  t0 = time.perf_counter()
  compiled = jax.jit(run).lower(ds).compile()
  compile_s = time.perf_counter() - t0
  cost = compiled.cost_analysis()
  cost = cost[0] if isinstance(cost, (list, tuple)) else (cost or {})
  if hlo_dir:
    os.makedirs(hlo_dir, exist_ok=True)
    robot_part = "" if robot == "gripper" else f"_{robot}"
    with open(os.path.join(hlo_dir, f"{task_name}{robot_part}_{variant}.hlo.txt"), "w") as f:
      f.write(compiled.as_text())
  ds = jax.block_until_ready(compiled(ds))
  best = float("inf")
  for _ in range(repeats):
    t0 = time.perf_counter()
    ds = jax.block_until_ready(compiled(ds))
    best = min(best, time.perf_counter() - t0)
  P = b.liquid.num_particles
  row = {
      "task": task_name, "variant": variant, "envs": envs, "substeps": substeps, "particles": P,
      "geoms": int(b.liquid.column_geom.size), "pair_search": b.liquid.pair_search,
      "wall_s": best, "compile_s": compile_s,
      "particle_substeps_per_s": envs * P * substeps / best,
      "liquid_env_steps_per_s": envs * substeps / best / task.n_substeps,
      "bytes_accessed": float(cost.get("bytes accessed", float("nan"))),
      "flops": float(cost.get("flops", float("nan"))),
  }
  print(f"{variant:9s} {row['particle_substeps_per_s']:>14,.0f} particle-substeps/s  "
        f"{row['liquid_env_steps_per_s']:>12,.0f} env-steps/s (liquid only)  "
        f"{row['bytes_accessed'] / 1e9:8.2f} GB accessed  compile {compile_s:.0f} s", flush=True)
  return row


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  ap.add_argument("--task", default="pour_water")
  ap.add_argument("--robot", default="gripper",
                  help="robot of the task (tasks.robots.names()); default gripper: the robot of the committed results")
  ap.add_argument("--variants", default=",".join(VARIANTS))
  ap.add_argument("--envs", type=int, default=4096)
  ap.add_argument("--substeps", type=int, default=12)
  ap.add_argument("--repeats", type=int, default=3)
  ap.add_argument("--hlo-dir", default=None)
  ap.add_argument("--out", default=None)
  args = ap.parse_args(argv)
  variants = [v for v in args.variants.split(",") if v]
  for v in variants:
    for part in v.split("+"):
      if part not in VARIANTS:
        ap.error(f"--variants: unknown {part!r} in {v!r}; valid: {', '.join(VARIANTS)} (combined with +)")
  for flag in ("envs", "substeps", "repeats"):
    if getattr(args, flag) < 1:
      ap.error(f"--{flag}: must be ≥ 1, got {getattr(args, flag)}")
  import jax

  import tasks
  if args.task not in tasks.names():
    ap.error(f"--task: unknown {args.task!r}")
  try:
    tasks.check_robot(args.robot, [args.task], "--robot")
  except ValueError as e:
    ap.error(str(e))
  dev = jax.devices()[0]
  rows = [measure(args.task, v, args.envs, args.substeps, args.repeats, args.hlo_dir, args.robot) for v in variants]
  result = {"command": "python benchmarks/liquid_speed.py " + shlex.join(sys.argv[1:] if argv is None else argv),
            "device": f"{dev.platform}:{dev.device_kind}", "rows": rows}
  # the robot in the results and the default name only when not the gripper (those stay as committed)
  robot_part = ""
  if args.robot != "gripper":
    result["robot"], robot_part = args.robot, f"_{args.robot}"
  out = args.out or os.path.join(HERE, "results", f"liquid_speed_{dev.platform}{robot_part}.json")
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  with open(out, "w") as f:
    json.dump(result, f, indent=1)
  print("wrote", out)
  return 0


if __name__ == "__main__":
  sys.exit(main())

"""The evaluation sweep on every local device: one SPMD program, or one 1-device program per device.

Issue 21's diagnosis of the 2-GPU sweep (``benchmarks/results/multi_gpu_nvidia_h200_eval_diagnosis.md``;
its cause, the sweep's batch layout, and these modes' rates: ``multi_gpu_nvidia_h200_eval_layout.md`` beside it).
:class:`train.evaluate.Evaluator` over D devices is one SPMD program (``shard_map``). This script
times, in one process, a sequence of ``PARTITIONER:MODE`` steps (``--sequence``):

- ``one``: the 1-device program on the first device alone (the baseline);
- ``async``: one 1-device program per device, each call started without waiting (JAX's asynchronous
  dispatch) from one thread, then all awaited;
- ``threads``: one 1-device program per device, each called (and awaited) by its own host thread;
- ``spmd``: the D-device Evaluator (always GSPMD on several devices: train.mesh.use_gspmd).

``PARTITIONER`` (``shardy`` or ``gspmd``) is JAX's partitioner switched on before the step's evaluators
are built (global to the process, so steps after a ``gspmd`` one should not go back to ``shardy``).
Each step prints the mean (min-max) of ``--repeats`` timed calls after a warm-up.

On 2 H200s ``async`` equals ``one``: XLA:GPU's while loops (MJX's solver) read their condition on the
host, so a call returns only when its device has finished and the second device starts after the
first. Concurrency across devices needs one host thread per device (``threads``; what PjRt does for
an SPMD program) or one process per device.

GPU (2 devices)::

    python benchmarks/eval_dispatch.py --task place_plate --episodes-per-device 16384 \
        --sequence shardy:one,shardy:threads,gspmd:one,gspmd:threads,gspmd:spmd

As multi_gpu.py's sweep batch (4096 episodes per level per device, the same episodes at each level; ``levels``:
the order train.sweep used before its device-local order)::

    python benchmarks/eval_dispatch.py --task place_plate --layout levels --episodes-per-device 16384 \
        --sequence shardy:one,shardy:threads,gspmd:one,gspmd:threads,gspmd:spmd

CPU plumbing check (2 fake host devices; the numbers mean nothing)::

    XLA_FLAGS=--xla_force_host_platform_device_count=2 python benchmarks/eval_dispatch.py --episodes-per-device 8
"""

from __future__ import annotations

import argparse
import concurrent.futures
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA flags, compile cache)


PARTITIONERS = ("shardy", "gspmd")
MODES = ("one", "async", "threads", "spmd")
ROBOT = "gripper"  # the committed results' robot; tasks.robots.DEFAULT may differ


def parse(argv=None):
  import tasks  # the registry's robots (no JAX backend starts here)
  from apps import resolve as R

  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--task", default="place_plate")
  p.add_argument("--robot", default=ROBOT,
                 help=f"robot of a registered --task, one of {', '.join(tasks.robots.names())} "
                      f"(default {ROBOT}, the robot of the committed results)")
  p.add_argument("--episodes-per-device", type=int, default=4096 * 4,
                 help="episodes per device per call (multi_gpu.py's 4096 per level x 4 fragility levels)")
  p.add_argument("--fragility", default="0.5,1,2,4")
  p.add_argument("--repeats", type=int, default=3)
  p.add_argument("--layout", choices=("distinct", "levels", "sweep"), default="distinct",
                 help="distinct: every episode its own key; levels: the same episodes at every fragility level, "
                      "level-major (train.sweep before its device-local order); sweep: those rows in "
                      "train.sweep.device_local_order")
  p.add_argument("--sequence", default="shardy:one,shardy:async,shardy:one,shardy:async",
                 help="comma-separated PARTITIONER:MODE steps, timed in this order (module docstring)")
  a = p.parse_args(argv)
  try:  # an env class takes no robot: task_kwargs None
    a.task_kwargs = R.robot_task_kwargs(a.task, a.robot, ROBOT)
  except ValueError as e:
    p.error(str(e))
  a.sequence = [tuple(x.split(":")) for x in a.sequence.split(",")]
  bad = [":".join(x) for x in a.sequence if len(x) != 2 or x[0] not in PARTITIONERS or x[1] not in MODES]
  if bad:
    p.error(f"--sequence: PARTITIONER:MODE steps with PARTITIONER in {PARTITIONERS} and MODE in {MODES}, got {bad[0]!r}")
  if a.episodes_per_device < 1 or a.repeats < 1:
    p.error("--episodes-per-device and --repeats: at least 1")
  try:
    a.fragility = [float(f) for f in a.fragility.split(",")]
  except ValueError:
    p.error(f"--fragility: comma-separated numbers, got {a.fragility!r}")
  if a.episodes_per_device % len(a.fragility):
    p.error(f"--episodes-per-device: a multiple of the {len(a.fragility)} fragility levels")
  return a


def main(argv=None) -> int:
  a = parse(argv)
  import jax
  import numpy as np

  import train.evaluate as E
  import train.sweep as S
  from apps import resolve as R
  from train.envs import resolve_task, task_episode_length

  env, _ = resolve_task(a.task, a.task_kwargs)
  T = task_episode_length(env)
  policy = R.make_policy("random", env)
  per, devs = a.episodes_per_device, jax.local_devices()
  n_levels = len(a.fragility)

  def batch(d):  # keys u32[per * d, 2], fragility f32[per * d] of a d-device call
    if a.layout == "distinct":
      return np.asarray(E.episode_keys(0, per * d)), np.repeat(np.asarray(a.fragility, np.float32), per * d // n_levels)
    e = per * d // n_levels
    keys = np.tile(np.asarray(E.episode_keys(0, e)), (n_levels, 1))
    frag = np.repeat(np.asarray(a.fragility, np.float32), e)
    order = S.device_local_order(e, n_levels, d) if a.layout == "sweep" else np.arange(len(keys))
    return keys[order], frag[order]

  keys1, frag1 = batch(1)
  keys, frag = batch(len(devs))
  part = lambda x, i: x[i * per:(i + 1) * per]  # noqa: E731  (device i's episodes)

  def start(ev, k, f):  # Evaluator.run without its final wait
    args = (jax.device_put(ev.params, ev.replicated), jax.device_put(k, ev.sharding), jax.device_put(f, ev.sharding))
    return ev._fn(*args)

  pool = concurrent.futures.ThreadPoolExecutor(len(devs))  # the threads mode's one host thread per device
  for partitioner, mode in a.sequence:
    jax.config.update("jax_use_shardy_partitioner", partitioner == "shardy")
    if mode == "spmd":
      ev = E.Evaluator(env, policy, T, devs)
      fn, n = (lambda: ev.run(keys, frag)), per * len(devs)
    else:
      evs = [E.Evaluator(env, policy, T, [d]) for d in devs]
      if mode == "one":
        fn, n = (lambda: jax.block_until_ready(start(evs[0], keys1, frag1))), per
      elif mode == "async":
        fn = lambda: jax.block_until_ready([start(ev, part(keys, i), part(frag, i)) for i, ev in enumerate(evs)])  # noqa: E731
        n = per * len(devs)
      else:  # threads
        fn = lambda: list(pool.map(lambda i: jax.block_until_ready(start(evs[i], part(keys, i), part(frag, i))), range(len(devs))))  # noqa: E731
        n = per * len(devs)
    fn()
    rates = []
    for _ in range(a.repeats):
      t0 = time.perf_counter()
      fn()
      rates.append(n * T / (time.perf_counter() - t0))
    d = 1 if mode == "one" else len(devs)
    print(f"dispatch {partitioner}:{mode} ({d} device(s)): {np.mean(rates):,.0f} env-steps/s "
          f"({min(rates):,.0f}-{max(rates):,.0f})", flush=True)
  pool.shutdown()
  return 0


if __name__ == "__main__":
  sys.exit(main())

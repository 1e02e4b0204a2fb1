"""The evaluation sweep on every local device as one 1-device program per device, dispatched from one thread.

Issue 21's diagnosis of the 2-GPU sweep (``benchmarks/results/multi_gpu_nvidia_h200_eval_diagnosis.md``):
:class:`train.evaluate.Evaluator` over D devices is one SPMD program (``shard_map``); this script instead
builds one 1-device Evaluator per device and starts each device's call without waiting (JAX's
asynchronous dispatch), then waits for all. It prints the rate of one device alone ("one") and of all
devices ("all"), each the mean (min–max) of ``--repeats`` timed calls after a warm-up, twice in turn.

On 2 H200s "all" equals "one": XLA:GPU's while loops (MJX's solver) read their condition on the
host, so a call returns only when its device has finished and the second device starts after the
first. Concurrency across devices needs one host thread per device (what PjRt does for an SPMD
program) or one process per device.

GPU (2 devices)::

    python benchmarks/eval_dispatch.py --task place_plate --episodes-per-device 16384

CPU plumbing check (2 fake host devices; the numbers mean nothing)::

    XLA_FLAGS=--xla_force_host_platform_device_count=2 python benchmarks/eval_dispatch.py --episodes-per-device 8
"""

from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA flags, compile cache)


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--task", default="place_plate")
  p.add_argument("--episodes-per-device", type=int, default=4096 * 4,
                 help="episodes per device per call (multi_gpu.py's 4096 per level x 4 fragility levels)")
  p.add_argument("--fragility", default="0.5,1,2,4")
  p.add_argument("--repeats", type=int, default=3)
  a = p.parse_args(argv)
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
  from apps import resolve as R
  from train.envs import resolve_task, task_episode_length

  env, _ = resolve_task(a.task)
  T = task_episode_length(env)
  policy = R.make_policy("random", env)
  per, devs = a.episodes_per_device, jax.local_devices()
  evs = [E.Evaluator(env, policy, T, [d]) for d in devs]
  keys = np.asarray(E.episode_keys(0, per * len(devs)))
  frag = np.repeat(np.asarray(a.fragility, np.float32), per * len(devs) // len(a.fragility))

  def start(ev, k, f):  # Evaluator.run without its final wait
    args = (jax.device_put(ev.params, ev.replicated), jax.device_put(k, ev.sharding), jax.device_put(f, ev.sharding))
    return ev._fn(*args)

  def all_devices():
    return jax.block_until_ready([start(ev, keys[i * per:(i + 1) * per], frag[i * per:(i + 1) * per])
                                  for i, ev in enumerate(evs)])

  def one():
    return jax.block_until_ready(start(evs[0], keys[:per], frag[:per]))

  for name, fn, n in (("one", one, per), ("all", all_devices, per * len(devs))) * 2:
    fn()
    rates = []
    for _ in range(a.repeats):
      t0 = time.perf_counter()
      fn()
      rates.append(n * T / (time.perf_counter() - t0))
    print(f"dispatch {name} ({len(devs) if name == 'all' else 1} device(s)): {np.mean(rates):,.0f} env-steps/s "
          f"({min(rates):,.0f}-{max(rates):,.0f})", flush=True)
  return 0


if __name__ == "__main__":
  sys.exit(main())

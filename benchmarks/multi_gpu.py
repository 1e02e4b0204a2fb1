"""Scaling over the local devices: training env-steps/s and evaluation-sweep throughput on 1 vs N devices.

For each device count D of ``--devices`` (default ``1,all``), at the same
**per-device** batch (``--envs-per-device`` training envs and the preset's
minibatch size times D as the global ``batch_size``, so each device's share
of a minibatch stays the same; ``--eval-episodes-per-device`` × levels
evaluation episodes):

* training — ``--repeats`` runs of ``--iterations`` iterations of
  ``train.train(task, devices=D, seeds=...)`` (compile excluded from the
  rate: TrainResult.throughput counts the iterations after the first, and
  evaluation time is not in it); the first run's ``--eval-points``
  deterministic evaluations are the learning curve (same seeds for every D;
  D devices see D times the env steps per iteration);
* evaluation — one :class:`train.evaluate.Evaluator` over D devices, the
  sweep's batch (fragility levels × episodes, train.sweep's layout), timed
  over ``--repeats`` calls after a warm-up call: env-steps/s = episodes ×
  episode length / s.

``--profile`` adds, per D, one iteration of the last repeat split into
rollout (env steps + inference) and update (SGD with its all-reduces), and the
JSON keeps every repeat's first-iteration (compile) time.

Writes ``benchmarks/results/multi_gpu_<device>.json`` and ``.md`` (rates per
repeat, mean, min–max spread, speedup over 1 device) and ``_curves.png``
(``multi_gpu_<robot>_<device>.*`` with ``--robot`` other than the gripper).

GPU (one node with 2 GPUs; the device tool's ``nvidia-h200-x2``), one command::

    python benchmarks/multi_gpu.py --task place_plate --devices 1,2 --repeats 2 --iterations 40

or one device count per call (each call under a time limit), the second adding its rows to the first's file::

    python benchmarks/multi_gpu.py --task place_plate --devices 1 --repeats 2 --iterations 40 --results-dir /tmp/mg
    python benchmarks/multi_gpu.py --task place_plate --devices 2 --repeats 2 --iterations 40 --results-dir /tmp/mg --append

Several processes on JAX's distributed runtime (``train.distributed``), e.g. one per GPU of a node,
each with its own ``--process-id``; process 0 writes ``multi_gpu_<device>_2proc.*`` and its timer is
the one recorded (another process's timer also waits for process 0's host-side preparation)::

    for i in 0 1; do CUDA_VISIBLE_DEVICES=$i python benchmarks/multi_gpu.py --parts eval --devices 2 \
        --coordinator 127.0.0.1:29500 --num-processes 2 --process-id $i & done; wait

CPU plumbing check with 2 fake host devices (measures nothing about GPUs)::

    XLA_FLAGS=--xla_force_host_platform_device_count=2 python benchmarks/multi_gpu.py \\
        --task train.experiments.pusher:PusherEnv --devices 1,2 --envs-per-device 8 --eval-episodes-per-device 4 \\
        --iterations 4 --eval-points 2 --config '{"unroll_length": 8, "num_minibatches": 2, "batch_size": 4,
        "num_updates_per_batch": 2, "episode_length": 24, "policy_hidden_sizes": [16, 16],
        "value_hidden_sizes": [16, 16], "num_eval_envs": 8}' --results-dir /tmp/multi_gpu
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

from mjx_damage import io, runtime  # noqa: E402
from mjx_damage.png import save_png  # noqa: E402
from train import distributed  # noqa: E402

ROBOT = "gripper"  # the committed results' robot; tasks.robots.DEFAULT may differ
CURVE_KEYS = ("eval/safe_completion", "eval/completion", "eval/episode_cost", "eval/task_return")


def parse(argv=None):
  import tasks  # the registry's robots (no JAX backend starts here: distributed.initialize comes first)
  from apps import resolve as R

  p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--task", default="place_plate", help="registered task, or package.module:EnvClass")
  p.add_argument("--robot", default=ROBOT,
                 help=f"robot of a registered --task, one of {', '.join(tasks.robots.names())} "
                      f"(default {ROBOT}, the robot of the committed results; another robot writes "
                      "multi_gpu_<robot>_<device>.*)")
  p.add_argument("--devices", default="1,all", help="comma-separated device counts (all: every local device)")
  p.add_argument("--preset", default="playground")
  p.add_argument("--envs-per-device", type=int, default=None, help="training envs per device (default: the preset's)")
  p.add_argument("--config", default="{}", help="JSON object of further PPOConfig fields (per-device sizes: "
                 "batch_size is per device and multiplied by D)")
  p.add_argument("--seeds", default="0", help="comma-separated seeds, the same for every D")
  p.add_argument("--repeats", type=int, default=2)
  p.add_argument("--iterations", type=int, default=40, help="training iterations per run (>= 3: the first compiles)")
  p.add_argument("--eval-points", type=int, default=8, help="deterministic evaluations per run (the curve)")
  p.add_argument("--eval-episodes-per-device", type=int, default=256)
  p.add_argument("--fragility", default="0.5,1,2,4", help="sweep levels of the evaluation batch")
  p.add_argument("--policy", default="random", help="evaluation policy spec (apps.resolve)")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  p.add_argument("--profile", action="store_true",
                 help="after the last repeat, time one iteration split into rollout and update (train(profile=True)): "
                      "where the scaling is lost")
  p.add_argument("--parts", default="eval,train", help="what to time: eval, train or both (comma-separated)")
  p.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                 help="several processes on JAX's distributed runtime (train.distributed), e.g. one per GPU: start "
                      "each with the same --coordinator and --num-processes and its own --process-id; device counts "
                      "are then over all processes (each a multiple of --num-processes), process 0 writes "
                      "multi_gpu_<device>_<N>proc.*")
  p.add_argument("--num-processes", type=int, default=None)
  p.add_argument("--process-id", type=int, default=None)
  p.add_argument("--append", action="store_true",
                 help="merge into an earlier results file: keep its other device counts, and the parts of these "
                      "device counts that this call does not time (each part records its own command)")
  args = p.parse_args(argv)
  try:  # an env class takes no robot: task_kwargs None
    args.task_kwargs = R.robot_task_kwargs(args.task, args.robot, ROBOT)
  except ValueError as e:
    p.error(str(e))
  try:
    args.setup = distributed.check(None, args.coordinator, args.num_processes, args.process_id)
  except ValueError as e:
    p.error(str(e))
  if args.repeats < 2:
    p.error("--repeats: at least 2 (the spread over repeats is reported)")
  if args.iterations < 3 or args.eval_points < 1:
    p.error("--iterations: at least 3; --eval-points: at least 1")
  try:
    args.config = json.loads(args.config)
    assert isinstance(args.config, dict)
  except (json.JSONDecodeError, AssertionError):
    p.error(f"--config: a JSON object, got {args.config!r}")
  args.parts = [x.strip() for x in args.parts.split(",") if x.strip()]
  if not args.parts or set(args.parts) - {"eval", "train"}:
    p.error(f"--parts: eval, train or eval,train; got {','.join(args.parts)!r}")
  args.seeds = tuple(int(s) for s in args.seeds.split(","))
  args.fragility = [float(f) for f in args.fragility.split(",")]
  return args


def device_counts(spec: str, available: int, processes: int = 1) -> list[int]:
  out = []
  for s in spec.split(","):
    n = available if s.strip() == "all" else int(s)
    if not 1 <= n <= available:
      raise SystemExit(f"--devices: {n} requested, {available} available")
    if n % processes:
      raise SystemExit(f"--devices: {n} cannot be split evenly over --num-processes {processes}")
    if n not in out:
      out.append(n)
  return out


def stats(values: list) -> dict:
  return {"runs": values, "mean": sum(values) / len(values), "min": min(values), "max": max(values)}


def train_runs(args, d: int, save=lambda part: None) -> dict:
  """Training rates of ``args.repeats`` runs on ``d`` devices; ``save`` gets the part after every repeat."""
  from train.config import PPOConfig
  from train.ppo import train

  base = PPOConfig.preset(args.preset)
  per_dev_envs = args.envs_per_device or base.num_envs
  cfg = dict(args.config)
  per_dev_batch = cfg.pop("batch_size", base.batch_size)
  sizes = dict(num_envs=per_dev_envs * d, **cfg)
  if per_dev_batch is not None:
    sizes["batch_size"] = per_dev_batch * d
  spi = PPOConfig.preset(args.preset, **sizes).steps_per_iteration
  sizes.update(num_timesteps=args.iterations * spi, eval_every=spi * max(1, args.iterations // args.eval_points))
  rates, compiles, curve, res = [], [], None, None
  for r in range(args.repeats):
    res = train(args.task, preset=args.preset, seeds=args.seeds, devices=d, progress=False, plot=False,
                task_kwargs=args.task_kwargs, profile=args.profile and r == args.repeats - 1, **sizes)
    rates.append(res.throughput)
    compiles.append(res.timings["compile"])
    if curve is None:
      curve = [{k: row[k] for k in ("seed", "iteration", "env_steps", "wall_time") + CURVE_KEYS if k in row}
               for row in res.history]
    print(f"train D={d} repeat {r}: {res.throughput:,.0f} env-steps/s ({res.iterations} iterations, "
          f"compile {res.timings['compile']:.1f} s)", flush=True)
    out = {"config": {k: v for k, v in res.config.to_json().items() if k != "num_timesteps"},
           "env_steps_per_s": stats(rates), "first_iteration_s": compiles, "curve": curve}
    save(out)  # a time limit keeps the finished repeats (the rate's "runs" says how many)
  if args.profile:  # s per iteration, all seeds: rollout (env step + inference) vs update (SGD incl. all-reduces)
    out["profile"] = {k.split("/")[1]: v for k, v in res.timings.items() if k.startswith("profile/")}
    print(f"train D={d} profile: " + ", ".join(f"{k} {v:.3f} s" for k, v in out["profile"].items()), flush=True)
  return out


def eval_runs(args, d: int, save=lambda part: None) -> dict:
  """Evaluation-sweep rates of ``args.repeats`` calls on ``d`` devices after a warm-up call; ``save`` gets
  the part after every call."""
  import jax
  import numpy as np

  import train.evaluate as E
  import train.sweep as S
  from apps import resolve as R
  from train.envs import resolve_task, task_episode_length

  env, _ = resolve_task(args.task, args.task_kwargs)
  T = task_episode_length(env)
  policy = R.make_policy(args.policy, env)
  episodes = args.eval_episodes_per_device * d
  ev = E.Evaluator(env, policy, T, distributed.select_devices(d))
  keys = np.tile(np.asarray(E.episode_keys(0, episodes)), (len(args.fragility), 1))
  frag = np.repeat(np.asarray(args.fragility, np.float32), episodes)
  order = S.device_local_order(episodes, len(args.fragility), d)  # as train.sweep hands the batch over
  keys, frag = keys[order], frag[order]
  t0 = time.perf_counter()
  ev.run(keys, frag)
  compile_s = time.perf_counter() - t0
  rates = []
  for _ in range(args.repeats):
    t0 = time.perf_counter()
    ev.run(keys, frag)
    rates.append(len(keys) * T / (time.perf_counter() - t0))
    out = {"episodes": int(len(keys)), "episode_length": T, "compile_s": compile_s, "env_steps_per_s": stats(rates)}
    save(out)  # a time limit keeps the finished calls
  print(f"eval D={d}: {stats(rates)['mean']:,.0f} env-steps/s ({len(keys)} episodes x {T} steps)", flush=True)
  return out


def write(base: str, payload: dict) -> None:
  if not distributed.is_main():  # several processes: process 0 writes
    return
  io.write_json(base + ".json", payload, indent=1)
  rows = payload["rows"]
  one = next((r for r in rows if r["devices"] == 1), None)

  def cell(r, part):
    if part not in r:
      return "not timed | –"
    s = r[part]["env_steps_per_s"]
    speed = f" | {s['mean'] / one[part]['env_steps_per_s']['mean']:.2f}x" if one and part in one else " | –"
    return f"{s['mean']:,.0f} ({s['min']:,.0f}–{s['max']:,.0f}){speed}"

  # Older files kept one command per row; newer ones one per timed part (a train call and an eval call merged).
  commands = "; ".join(f"`{c}`" for c in dict.fromkeys(
      r[k].get("command", r.get("command")) for r in rows for k in ("train", "eval") if k in r))
  lines = [f"# Scaling over devices: {payload['device']}", "",
           f"Command(s): {commands}", "", f"jax {payload['jax']}, {payload['date']}; task {payload['task']}; "
           + (f"{payload['processes']} processes (JAX distributed runtime; each owns its share of the devices); "
              if payload.get("processes", 1) > 1 else "") +
           f"rates are mean (min–max) over {payload['repeats']} repeats; speedup vs 1 device at the same per-device batch.",
           "", "| Devices | Train envs (global) | Train env-steps/s | Speedup | Eval episodes | Eval env-steps/s | Speedup |",
           "|---:|---:|---:|---:|---:|---:|---:|"]
  for r in rows:
    train_envs = r["train"]["config"]["num_envs"] if "train" in r else "–"
    lines.append(f"| {r['devices']} | {train_envs} | {cell(r, 'train')} | "
                 f"{r['eval']['episodes'] if 'eval' in r else '–'} | {cell(r, 'eval')} |")
  prof = [r for r in rows if r.get("train", {}).get("profile")]
  if prof:
    lines += ["", "One iteration split (s, last repeat, `--profile`): rollout = env steps + inference; update = "
              "normaliser + SGD epochs with their all-reduces (= iteration − rollout).", "",
              "| Devices | rollout s | update s | iteration s | update share |", "|---:|---:|---:|---:|---:|"]
    for r in prof:
      p = r["train"]["profile"]
      lines.append(f"| {r['devices']} | {p['rollout']:.3f} | {p['update']:.3f} | {p['iteration']:.3f} | "
                   f"{p['update'] / p['iteration']:.0%} |")
  lines += ["", "Learning curves (first repeat; deterministic evaluation, mean over seeds):", "",
            "| Devices | Env steps / seed | " + " | ".join(k.split("/")[1] for k in CURVE_KEYS) + " |",
            "|---:|---:|" + "---:|" * len(CURVE_KEYS)]
  for r in rows:
    by_step = {}
    for row in r.get("train", {}).get("curve", []):
      by_step.setdefault(row["env_steps"], []).append(row)
    for steps, rs in sorted(by_step.items()):
      vals = [sum(x.get(k) or 0.0 for x in rs) / len(rs) for k in CURVE_KEYS]
      lines.append(f"| {r['devices']} | {steps:,} | " + " | ".join(f"{v:.3g}" for v in vals) + " |")
  io.write_text(base + ".md", "\n".join(lines) + "\n")
  plot(base + "_curves.png", rows)


def plot(path: str, rows: list) -> None:
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
  for j, r in enumerate(rows):
    for ax, key in zip(axes, ("eval/safe_completion", "eval/episode_cost")):
      pts = sorted((x["env_steps"], x[key]) for x in r.get("train", {}).get("curve", []) if x.get(key) is not None)
      ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=f"C{j}", label=f"{r['devices']} device(s)")
      ax.set_xlabel("env steps per seed")
      ax.set_title(key)
  axes[0].legend()
  fig.tight_layout()
  save_png(fig, path, dpi=110)
  plt.close(fig)


def main(argv=None) -> int:
  args = parse(argv)
  distributed.initialize(args.setup, "multi_gpu.py")
  import jax

  slug, device = runtime.device_info()
  procs = jax.process_count()
  counts = device_counts(args.devices, jax.device_count(), procs)
  robot = "" if args.robot == ROBOT else args.robot + "_"  # the gripper's names as before --robot
  base = os.path.join(args.results_dir, f"multi_gpu_{robot}{slug}" + (f"_{procs}proc" if procs > 1 else ""))
  command = " ".join(shlex.quote(a) for a in ["python", "benchmarks/multi_gpu.py"] + list(sys.argv[1:] if argv is None else argv))
  payload = {"device": device, "jax": jax.__version__, "task": args.task, "repeats": args.repeats, "processes": procs,
             "date": time.strftime("%Y-%m-%d %H:%M"), "rows": []}
  earlier = {}
  if args.append and os.path.exists(base + ".json"):
    with open(base + ".json") as f:
      earlier = {r["devices"]: r for r in json.load(f)["rows"]}
    payload["rows"] = [r for d, r in earlier.items() if d not in counts]
  for d in counts:
    row = {k: v for k, v in earlier.get(d, {}).items() if k in ("eval", "train")}
    row["devices"] = d
    payload["rows"].append(row)
    payload["rows"].sort(key=lambda r: r["devices"])
    for part, run in (("eval", eval_runs), ("train", train_runs)):
      if part in args.parts:

        def save(result, part=part):
          row[part] = dict(result, command=command)
          write(base, payload)

        save(run(args, d, save))
  print(f"wrote {base}.md / .json / _curves.png", flush=True)
  return 0


if __name__ == "__main__":
  sys.exit(main())

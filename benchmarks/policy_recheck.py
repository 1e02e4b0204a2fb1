"""Re-score trained policies on this machine: committed weights, evaluated again on one or both physics backends.

A GPU training run scores its final policies itself (benchmarks/rl_multiseed.py, MJX on the GPU). This script
takes the weights it exported (``--export-policy``: ``rl_<task>_<device>_<tag>_<method>_policy.npz``, committed
beside the results) and evaluates chosen seeds again here, on MJX-JAX and on native MuJoCo (C, CPU threads):
another machine, another episode sample and, with ``native``, another implementation of the physics, so a
trained behaviour that only exists in one simulator build shows up as a disagreement. The task and its settings
come from the checkpoint (``tasks.stored_kwargs``); the scripted safe/unsafe policies can be added as references,
and run on the checkpoints' settings when those agree (``--task-arg`` adds to them).

Policies are the CLI's specs (``mjx-damage eval --policy``): ``checkpoint[+sample|+mean]:FILE#SEED``,
``scripted:safe``, ``scripted:unsafe``, ``zero``, ``random``.

``--policy-precision float32,tf32`` scores each checkpoint policy also with its network's matrix products at
TF32 precision (what JAX computes float32 products at by default on recent NVIDIA GPUs: the inputs and weights
of every dense layer rounded to a 10-bit mantissa, sums in float32), emulated here with
``jax.lax.reduce_precision``; the physics keeps its own precision. A GPU-trained policy that scores differently
here can so be told apart from one whose own arithmetic is the difference.

``--matmul-precision default,float32`` scores each row also with every matrix product of the compiled program
(physics and policy) at JAX's ``float32`` precision instead of the backend's default: the same on a CPU, while a
recent NVIDIA GPU computes float32 products at TF32 by default. Run on a GPU, it tells whether TF32 in the
simulation itself is why a policy scores differently there than here.

Rows of one checkpoint file, action and backend share one compiled evaluator (the weights are its data), so
re-scoring several seeds of a run compiles once per action and backend.

Writes ``benchmarks/results/policy_recheck_<task>[_<tag>].{json,md}`` with the command.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/policy_recheck.py --task pick_egg --episodes 256 \\
        --policies 'checkpoint:benchmarks/results/…_policy.npz#1,scripted:safe'
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags and the jax compat shim before jax starts)
from mjx_damage import runtime  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)
from apps import resolve as R  # noqa: E402
from train import evaluate as E  # noqa: E402

import flax.linen as nn  # noqa: E402
import jax  # noqa: E402

BACKENDS = ("mjx", "native")
PRECISIONS = ("float32", "tf32")


def _tf32(x):
  """``x`` rounded to TensorFloat-32 (float32's 8-bit exponent, a 10-bit mantissa), kept as float32."""
  return jax.lax.reduce_precision(x, exponent_bits=8, mantissa_bits=10)


def _tf32_dense(next_fun, args, kwargs, context):
  """A flax method interceptor: the input of every ``nn.Dense`` rounded to TF32 before its product."""
  if isinstance(context.module, nn.Dense) and context.method_name == "__call__":
    args = (_tf32(args[0]), *args[1:])
  return next_fun(*args, **kwargs)


def tf32_policy(policy: E.Policy) -> E.Policy:
  """``policy`` (a checkpoint's: ``policy.apply``, ``policy.params``) with its network's matrix products at
  TF32 precision: every kernel and every dense layer's input rounded (the normaliser and biases untouched)."""
  def apply(params, state, rng):
    with nn.intercept_methods(_tf32_dense):
      return policy.apply(params, state, rng)

  kernels = jax.tree_util.tree_map_with_path(
      lambda path, x: _tf32(x) if any(getattr(k, "key", None) == "kernel" for k in path) else x, policy.params)
  return E.parametrized_policy(apply, kernels)


def _choices(text: str, allowed: tuple, field: str) -> list[str]:
  """A comma-separated list of ``allowed`` values, each at most once (ValueError naming ``field``)."""
  values = [v.strip() for v in text.split(",") if v.strip()]
  if not values or len(set(values)) != len(values) or any(v not in allowed for v in values):
    raise ValueError(f"{field}: comma-separated of {', '.join(allowed)}, each at most once, got {','.join(values)!r}")
  return values


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--task", required=True, help="registry task the policies were trained on")
  p.add_argument("--policies", required=True,
                 help="comma-separated policy specs (checkpoint[+sample|+mean]:FILE#SEED, scripted:safe, …)")
  p.add_argument("--backends", default="mjx,native", help=f"comma-separated of {','.join(BACKENDS)}")
  p.add_argument("--episodes", type=int, default=256)
  p.add_argument("--seed", type=int, default=0, help="episode sample (initial states, sampled actions)")
  p.add_argument("--fragility", default="1",
                 help="comma-separated fragility factors (damage thresholds ÷ f, scales × f; > 0), each a row: "
                      "how far below the thresholds a policy stays (one compiled evaluator serves every level)")
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="task keyword over every policy's settings (a checkpoint brings its own; this one "
                      "overrides them, e.g. counter=\"box\" to score Place Plate policies on the box counter)")
  p.add_argument("--policy-precision", default="float32",
                 help=f"comma-separated of {','.join(PRECISIONS)}, each a row: the checkpoint policies' matrix "
                      "products in full float32, or at TF32 precision as on a recent NVIDIA GPU (emulated)")
  p.add_argument("--matmul-precision", default="default",
                 help=f"comma-separated of {','.join(runtime.MATMUL_PRECISIONS)}, each a row: every matrix product of the "
                      "compiled program (physics and policy) at the backend's default precision (TF32 on a recent "
                      "NVIDIA GPU) or at full float32")
  p.add_argument("--tag", default="")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  args = p.parse_args(argv)
  args.policies = [s for s in args.policies.split(",") if s]
  args.backends = [b for b in args.backends.split(",") if b]
  fragility_text = args.fragility
  try:  # everything checked before a task is built or compiled
    R.check_task(args.task)
    if not args.policies:
      raise ValueError("policies: give at least one policy spec")
    for b in args.backends:
      if b not in BACKENDS:
        raise ValueError(f"backends: unknown backend {b!r}; backends: {', '.join(BACKENDS)}")
    if not args.backends or len(set(args.backends)) != len(args.backends):
      raise ValueError(f"backends: give each of {', '.join(BACKENDS)} at most once, at least one")
    try:
      args.fragility = [float(v) for v in fragility_text.split(",") if v.strip()]
    except ValueError:
      raise ValueError(f"fragility: comma-separated numbers, got {fragility_text!r}") from None
    if not args.fragility:
      raise ValueError("fragility: give at least one factor")
    args.policy_precision = _choices(args.policy_precision, PRECISIONS, "policy_precision")
    args.matmul_precision = _choices(args.matmul_precision, runtime.MATMUL_PRECISIONS, "matmul_precision")
    if "tf32" in args.policy_precision:
      other = [s for s in args.policies if R.parse_policy_spec(s)[0] != "checkpoint"]
      if other:
        raise ValueError(f"policy_precision: tf32 rounds a checkpoint policy's network; {', '.join(other)} has none")
    for f in args.fragility:
      E.check_args(args.episodes, f, 95.0, seed=args.seed)
    trained = {s: R.policy_task_kwargs(s, args.task) for s in args.policies  # reads every checkpoint
               if R.parse_policy_spec(s)[0] == "checkpoint"}
    # the other policies (scripted references …) run where the checkpoints were trained, when they agree
    common = next(iter(trained.values())) if trained and all(k == next(iter(trained.values()))
                                                             for k in trained.values()) else {}
    args.overrides = [R.task_overrides(args.task, trained.get(s, common), None, args.task_arg)
                      for s in args.policies]
    built = {}  # one env per distinct setting; making it checks the settings' values (nothing compiles)
    args.envs = [built.setdefault(json.dumps(o, sort_keys=True), R.make_task(args.task, **o))
                 for o in args.overrides]
  except ValueError as e:
    p.error(str(e))
  return args


def rescore(task: str, env, spec: str, overrides: dict, backend: str, episodes: int, seed: int,
            shared: dict | None = None, fragility: float = 1.0, precision: str = "float32",
            matmul: str = "default") -> dict:
  """``spec`` on ``env`` (``task`` made with ``overrides``) over ``episodes`` episodes of ``backend``:
  E.evaluate's metrics.

  ``shared``: evaluators kept between calls, one per (checkpoint and action, or scripted spec; settings;
  backend, precision, matmul): the seeds of one checkpoint differ only in their weights and the levels of ``fragility`` are an
  argument, both data of the evaluator, so one compiled program scores them all (the numbers are those of a fresh evaluator: the same program, the same inputs).
  ``precision``: "tf32" scores the policy with :func:`tf32_policy`. ``matmul``: the evaluator is traced and compiled
  under ``jax.default_matmul_precision`` of it ("default": the backend's own, even where JAX_DEFAULT_MATMUL_PRECISION
  says otherwise); the precision is fixed when a program is traced, so it is a key of ``shared``.
  """
  policy = R.make_policy(spec, env)
  if precision == "tf32":
    policy = tf32_policy(policy)
  T = R.episode_length_of(env, task)
  key = None
  if shared is not None:  # a scripted policy is kept too: its levels of fragility share its evaluator
    key = ((os.path.realpath(R.checkpoint_path(spec)), R.checkpoint_action(spec))
           if R.parse_policy_spec(spec)[0] == "checkpoint" else spec, json.dumps(overrides, sort_keys=True), backend,
           precision, matmul)
  t0 = time.perf_counter()
  with jax.default_matmul_precision(None if matmul == "default" else matmul):
    if key is not None and key in shared:
      ev = shared[key]
    else:
      env_b = R.on_backend(env, backend, episodes)
      E.check_args(episodes, 1.0, 95.0, seed=seed)
      E.check_memory(env_b, episodes)
      ev = E.make_evaluator(env_b, policy, T)
      if key is not None:
        shared[key] = ev
    per_ep = ev.run(E.episode_keys(seed, episodes), fragility, params=getattr(policy, "params", None))
  m = E.metrics(per_ep, ev.env.entity_names)
  return {"policy": spec, "backend": backend, "fragility": fragility, "policy_precision": precision,
          "matmul_precision": matmul, "task_kwargs": overrides, "wall_s": round(time.perf_counter() - t0, 1),
          **{k: m[k] for k in ("completion", "safe_completion", "cost_mean", "avg_health", "min_env_health",
                               "task_return")}}


def render_md(res: dict) -> str:
  lines = [f"# Trained policies re-scored: {res['task']}", "",
           f"Date: {res['date']}. Git: {res['git']}. jax {res['jax']} ({res['backend']}). "
           f"{res['episodes']} episodes per row (episode seed {res['seed']}); safe completion = completed and every "
           "entity's final health > 95. Policies as `mjx-damage eval --policy` names them (`#SEED`: the seed of a "
           "multi-seed run); the task settings come from each checkpoint.", "",
           f"Command: `{res['command']}`", "",
           "Fragility f: every damage threshold ÷ f and scale × f (1: the task's own); a policy whose safe "
           "completion falls at f slightly above 1 stays just below the thresholds.", "",
           "Policy arithmetic: the network's matrix products in float32, or at TF32 precision as a recent NVIDIA "
           "GPU computes them by default (emulated: inputs and weights rounded to a 10-bit mantissa).", "",
           "Matmul precision: every matrix product of the compiled program (physics and policy) at the backend's "
           "default (`default`: float32 on a CPU, TF32 on a recent NVIDIA GPU) or at full `float32`.", "",
           "| policy | backend | policy arithmetic | matmul precision | fragility | completion % | safe completion % | episode cost | avg health | min health | task return | s |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
  for r in res["rows"]:
    kind, sep, path = r["policy"].partition(":")
    lines.append(f"| `{kind}{sep}{os.path.basename(path)}` | {r['backend']} | {r.get('policy_precision', 'float32')} | "
                 f"{r.get('matmul_precision', 'default')} | {r.get('fragility', 1.0):g} | "
                 f"{100 * r['completion']:.1f} | "
                 f"{100 * r['safe_completion']:.1f} | {r['cost_mean']:.2f} | {r['avg_health']:.2f} | "
                 f"{r['min_env_health']:.2f} | {r['task_return']:.1f} | {r['wall_s']:.0f} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  args = parse(argv)
  rows, shared = [], {}
  for spec, overrides, env in zip(args.policies, args.overrides, args.envs):
    for backend in args.backends:
      for precision in args.policy_precision:
        for matmul in args.matmul_precision:
          for f in args.fragility:
            rows.append(rescore(args.task, env, spec, overrides, backend, args.episodes, args.seed, shared, f,
                                precision, matmul))
            r = rows[-1]
            print(f"{spec} [{backend}, {precision}, matmul {matmul}, fragility {f:g}]: completion {100 * r['completion']:.1f} %, "
                  f"safe {100 * r['safe_completion']:.1f} %, cost {r['cost_mean']:.2f} ({r['wall_s']:.0f} s)", flush=True)
  res = {"task": args.task, "episodes": args.episodes, "seed": args.seed, "rows": rows}
  stem = os.path.join(args.results_dir, f"policy_recheck_{args.task}" + (f"_{args.tag}" if args.tag else ""))
  provenance.save_results(res, "policy_recheck", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

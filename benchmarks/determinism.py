"""Determinism: same seed → same rollout; per-env results independent of chunking and batch size.

A rollout: ``tasks.make(task)`` vmapped over B envs, env b reset from key b and
stepped with uniform random actions drawn from ``fold_in(key b, t)``, so each
env's inputs depend on its own key and step index only, never on B or on how
the steps are split into calls. The whole final ``State`` (physics, damage
state, obs, reward, metrics) is compared. Per task, four checks:

- ``rerun``: the same call twice (same executable, same keys);
- ``recompiled``: a freshly traced and compiled pair of functions, same keys;
- ``chunked``: the steps split into two calls of other lengths;
- ``half_batch``: each half of the batch run alone (B/2 envs) vs the same envs in
  the batch of B.

Each check reports whether every leaf is bitwise equal and the largest
|difference| of obs, reward, link health, qpos and qvel. On CPU all four are
bitwise equal (tests/test_determinism.py pins it). On GPU:

- ``rerun`` and ``chunked`` (one executable, same inputs) must be bitwise equal in
  every leaf but MJX's intermediates ``DERIVED`` (``subtree_com``, ``cinert``,
  ``crb``, the mass matrix and its factor: recomputed from qpos at every step,
  their last bits come from GPU scatter-add atomics, whose order varies run to
  run); and within ``TOL`` in what a user reads.
- ``recompiled`` and ``half_batch`` are judged against float tolerances
  (``TOL``): another executable, or another batch shape, may pick other kernels
  and reduction orders. ``half_batch`` also records the largest |Δ obs| after
  1, 10, T/4 and T steps (``divergence``): a last-bit difference that contact
  dynamics amplify grows step by step, which is what a user needs to know
  before comparing per-env results across batch sizes on a GPU.

``--matmul-precision`` sets ``jax_default_matmul_precision`` for the run
(``highest``: full f32 matmuls, no TF32), to test whether reduced-precision
matmuls are what makes the batch shape matter.

Usage::

    python benchmarks/determinism.py                    # GPU: 1024 envs × 200 steps, 3 tasks
    python benchmarks/determinism.py --envs 8 --steps 20  # CPU size

Writes ``benchmarks/results/determinism_<platform>[_<robot>].{json,md}`` (``--out``: another
JSON path); exits 1 when a check fails. ``--robot`` (default the gripper, the robot of the committed
results) is in the name and the results when not the gripper.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import jax  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
from mjx_damage import io  # noqa: E402

DEFAULT_TASKS = ("place_plate", "turn_on_stove", "pour_water")
# Largest |Δ| accepted where bitwise equality is not promised (GPU: other executables, other batch
# shapes). After 200 steps of contact-rich chaotic dynamics last-bit differences grow, so the bound is
# on what a user reads (reward, health) rather than on raw state; liquid counts are discrete.
TOL = {"obs": 1e-2, "reward": 1e-2, "link_health": 1.0, "qpos": 1e-2, "qvel": 1.0}
TOL_LIQUID = {"obs": 0.1, "reward": 0.2}  # a few particles of 128 crossing a boundary
# MJX intermediates recomputed from qpos at every step (kinematics, composite inertias, the mass
# matrix and its factor); on GPU their last bits vary run to run (scatter-add atomics)
DERIVED = (".pipeline_state.subtree_com", ".pipeline_state._impl.cinert", ".pipeline_state._impl.crb",
           ".pipeline_state._impl.M", ".pipeline_state._impl.qLD",
           ".pipeline_state._impl.qLDiagInv")


def rollout_fns(env):
  """(init(keys u32[B, 2]) -> carry, advance(carry, t0, n) -> carry), both jitted over the batch."""

  def init(key):
    return env.reset(key), key

  def advance(carry, t0, n):
    def body(t, c):
      s, key = c
      a = jax.random.uniform(jax.random.fold_in(key, t), (env.action_size,), minval=-1.0, maxval=1.0)
      return env.step(s, a), key

    return jax.lax.fori_loop(t0, t0 + n, body, carry)

  return jax.jit(jax.vmap(init)), jax.jit(jax.vmap(advance, in_axes=(0, None, None)))


def run(fns, keys, chunks, every: bool = False):
  """Final State (host arrays) of the rollout, its steps split into calls of ``chunks`` steps
  (``every``: the list of States after each call)."""
  init, advance = fns
  carry = init(keys)
  t = 0
  states = []
  for n in chunks:
    carry = advance(carry, t, n)
    t += n
    if every:
      states.append(jax.device_get(carry[0]))
  return states if every else jax.device_get(carry[0])


def marks(steps: int) -> list[int]:
  """Steps after which ``half_batch`` records its divergence: 1, 10, T/4, T (those below T, deduplicated)."""
  return sorted({m for m in (1, 10, steps // 4) if 0 < m < steps} | {steps})


def take(tree, idx):
  return jax.tree.map(lambda x: np.asarray(x)[idx], tree)


MAX_PATHS = 12  # differing leaf paths kept per check in the report


def bitwise_mismatches(a, b) -> list:
  """Paths of the leaves whose bytes differ (NaN payloads and the sign of zero included)."""
  out = []
  for (path, x), y in zip(jax.tree_util.tree_leaves_with_path(a), jax.tree.leaves(b)):
    x, y = np.asarray(x), np.asarray(y)
    if x.shape != y.shape or x.tobytes() != y.tobytes():
      out.append(jax.tree_util.keystr(path))
  return out


def compared(s) -> dict:
  return {"obs": s.obs, "reward": s.reward, "link_health": s.info["link_health"],
          "qpos": s.pipeline_state.qpos, "qvel": s.pipeline_state.qvel}


def max_diffs(a, b) -> dict:
  ca, cb = compared(a), compared(b)
  return {k: float(np.max(np.abs(np.asarray(ca[k], np.float64) - np.asarray(cb[k], np.float64)))) for k in ca}


def tolerance(env) -> dict:
  """The |Δ| bounds of the non-bitwise checks for this task: ``TOL_LIQUID`` with liquid, else ``TOL``."""
  return TOL_LIQUID if env.unwrapped.damage_binding.liquid is not None else TOL


def judge(checks: dict, tol: dict, strict: bool) -> None:
  """Sets each check's ``ok`` and ``criterion`` (module docstring) from its recorded differences."""
  within = lambda c: all(c["max_abs_diff"][f] <= t for f, t in tol.items())  # noqa: E731
  tol_text = ", ".join(f"{f} {t:g}" for f, t in tol.items())
  for k, c in checks.items():
    if strict:
      c["ok"], c["criterion"] = c["bitwise"], "bitwise"
    elif k in ("rerun", "chunked"):
      c["ok"] = not [p for p in c["differing_leaves"] if p not in DERIVED] and within(c)
      c["criterion"] = f"bitwise but MJX's derived kinematics ({', '.join(DERIVED)}); |Δ| ≤ {tol_text}"
    else:
      c["ok"] = c["bitwise"] or within(c)
      c["criterion"] = "bitwise or |Δ| ≤ " + tol_text


def rejudge(path: str, p) -> int:
  """Re-applies this file's criteria to a results file's recorded differences (no rollout) and rewrites it.

  For results measured before a criterion changed: every judged quantity (bitwise flags, differing
  leaf paths, largest |Δ|) is in the file; ``rejudged`` records when and that the rollouts are older."""
  try:
    with open(path) as f:
      res = json.load(f)
  except (OSError, ValueError) as e:
    p.error(f"--rejudge: cannot read {path!r}: {e}")
  for r in res["tasks"]:
    if r["task"] not in tasks.names():
      p.error(f"--rejudge: unknown task {r['task']!r} in {path!r}")
    # only rerun / chunked are judged by which leaves differ
    if any(len(r["checks"][k]["differing_leaves"]) >= MAX_PATHS for k in ("rerun", "chunked")):
      p.error(f"--rejudge: {r['task']} lists {MAX_PATHS} differing leaves, maybe not all of them; rerun instead")
    # the file's robot: recorded when not the gripper (files before --robot: the gripper)
    judge(r["checks"], tolerance(tasks.make(r["task"], robot=res.get("robot", "gripper"))), res["strict"])
    r["ok"] = r["envs_distinct"] and all(c["ok"] for c in r["checks"].values())
  res["ok"] = all(r["ok"] for r in res["tasks"])
  res["rejudged"] = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
  io.write_json(path, res)
  io.write_text(os.path.splitext(path)[0] + ".md", report_md(res))
  print(f"rejudged {path}; {'PASS' if res['ok'] else 'FAIL'}")
  return 0 if res["ok"] else 1


def check_task(name: str, envs: int, steps: int, seed: int, strict: bool, robot: str = "gripper") -> dict:
  """The four checks of one task with ``robot`` (module docstring); ``strict``: every check must be bitwise."""
  env = tasks.make(name, robot=robot)
  keys = jax.random.split(jax.random.PRNGKey(seed), envs)
  split = (steps // 3, steps - steps // 3)
  t0 = time.perf_counter()
  fns = rollout_fns(env)
  ref = run(fns, keys, (steps,))
  outs = {"rerun": run(fns, keys, (steps,)),
          "recompiled": run(rollout_fns(env), keys, (steps,)),
          "chunked": run(fns, keys, split)}
  checks = {}
  for k, got in outs.items():
    bad = bitwise_mismatches(ref, got)
    checks[k] = {"bitwise": not bad, "max_abs_diff": max_diffs(ref, got), "differing_leaves": bad[:MAX_PATHS]}
  h = envs // 2
  halves = (slice(0, h), slice(h, envs))
  m = marks(steps)
  segs = np.diff([0, *m]).tolist()
  # the whole batch is traced in the same segments (chunking is itself checked above)
  ref_tr = run(fns, keys, segs, every=True)
  half_tr = [run(fns, keys[sl], segs, every=True) for sl in halves]
  bad = sorted({p for sl, tr in zip(halves, half_tr) for p in bitwise_mismatches(take(ref_tr[-1], sl), tr[-1])})
  diffs = [max_diffs(take(ref_tr[-1], sl), tr[-1]) for sl, tr in zip(halves, half_tr)]
  divergence = {t: max(max_diffs(take(ref_tr[i], sl), tr[i])["obs"] for sl, tr in zip(halves, half_tr))
                for i, t in enumerate(m)}
  checks["half_batch"] = {"bitwise": not bad, "max_abs_diff": {k: max(d[k] for d in diffs) for k in diffs[0]},
                          "differing_leaves": bad[:MAX_PATHS], "divergence_obs": divergence}
  judge(checks, tolerance(env), strict)
  # the envs differ from each other, so equality is not trivially true
  distinct = not np.array_equal(np.asarray(ref.obs[0]), np.asarray(ref.obs[1]))
  return {"task": name, "envs": envs, "steps": steps, "chunks": list(split), "checks": checks,
          "envs_distinct": distinct, "ok": distinct and all(c["ok"] for c in checks.values()),
          "wall_s": round(time.perf_counter() - t0, 1)}


def report_md(res: dict) -> str:
  lines = [f"# Determinism ({res['device']})", "",
           f"Command: `{res['command']}`  ", f"Date: {res['date']}; jax {res['versions']['jax']}, "
           f"mujoco {res['versions']['mujoco']}; total {res['total_s']} s", "",
           "Each task: B envs × T random-action steps (per-env keys; benchmarks/determinism.py docstring). "
           "Cells: bitwise equal (✓) or the largest |Δ| of obs / reward / link health / qpos / qvel.", "",
           "| task | envs × steps | rerun | recompiled | chunked | half batch alone | result |",
           "|---|---|---|---|---|---|---|"]

  def cell(c):
    if c["bitwise"]:
      return "✓ bitwise"
    d = c["max_abs_diff"]
    if c["ok"] and all(p in DERIVED for p in c["differing_leaves"]) and not any(d.values()):
      return "✓ bitwise but MJX's derived kinematics"
    return ("≈ " if c["ok"] else "✗ ") + " / ".join(f"{d[k]:.2g}" for k in ("obs", "reward", "link_health", "qpos",
                                                                             "qvel"))

  for r in res["tasks"]:
    c = r["checks"]
    lines.append(f"| {r['task']} | {r['envs']} × {r['steps']} | {cell(c['rerun'])} | {cell(c['recompiled'])} | "
                 f"{cell(c['chunked'])} | {cell(c['half_batch'])} | {'PASS' if r['ok'] else 'FAIL'} |")
  div = [(r["task"], r["checks"]["half_batch"].get("divergence_obs")) for r in res["tasks"]]
  if any(d for _, d in div):
    lines += ["", "Half batch alone vs the same envs in the whole batch: largest |Δ obs| after t steps "
              "(how a first difference grows):", "", "| task | " + " | ".join(f"t = {t}" for t in div[0][1]) + " |",
              "|---|" + "---:|" * len(div[0][1])]
    lines += [f"| {t} | " + " | ".join(f"{v:.2g}" for v in d.values()) + " |" for t, d in div if d]
  lines += ["", "Leaves that differ bitwise (first few per check), where any:", ""]
  for r in res["tasks"]:
    for k, c in r["checks"].items():
      if c.get("differing_leaves"):
        lines.append(f"- {r['task']} / {k}: " + ", ".join(f"`{p}`" for p in c["differing_leaves"]))
  if res.get("rejudged"):
    lines += ["", f"Verdicts re-applied on {res['rejudged']} with the current criteria "
              "(`--rejudge`) to the differences this run recorded."]
  lines += ["", f"Strict (every check bitwise): {res['strict']}. Matmul precision: "
            f"{res.get('matmul_precision') or 'default'}. Result: {'PASS' if res['ok'] else 'FAIL'}", ""]
  return "\n".join(lines)


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
  gpu = jax.default_backend() != "cpu"
  p.add_argument("--tasks", default=",".join(DEFAULT_TASKS), help="comma-separated task names")
  p.add_argument("--robot", default="gripper",
                 help=f"robot of every task ({', '.join(tasks.robots.names())}); gripper: the robot of the "
                      "committed results")
  p.add_argument("--envs", type=int, default=1024 if gpu else 8, help="environments per task (even, >= 2)")
  p.add_argument("--steps", type=int, default=200 if gpu else 20, help="env steps per rollout (>= 3)")
  p.add_argument("--seed", type=int, default=7)
  p.add_argument("--strict", action="store_true", default=not gpu,
                 help="every check bitwise (default on CPU)")
  p.add_argument("--matmul-precision", choices=("default", "high", "highest"), default=None,
                 help="jax_default_matmul_precision for the run (default: JAX's own)")
  p.add_argument("--out", default=None, help="JSON path (default benchmarks/results/determinism_<platform>.json)")
  p.add_argument("--rejudge", metavar="FILE.json", default=None,
                 help="no rollouts: apply the current criteria to a results file's recorded differences")
  args = p.parse_args(argv)
  if args.rejudge:
    return rejudge(args.rejudge, p)
  if args.matmul_precision:
    jax.config.update("jax_default_matmul_precision", args.matmul_precision)
  names = [t for t in args.tasks.split(",") if t]
  for t in names:
    if t not in tasks.names():
      p.error(f"--tasks: unknown task {t!r}; valid: {', '.join(tasks.names())}")
  try:
    tasks.check_robot(args.robot, names, "--robot")
  except ValueError as e:
    p.error(str(e))
  if args.envs < 2 or args.envs % 2:
    p.error(f"--envs: an even number >= 2, got {args.envs}")
  if args.steps < 3:
    p.error(f"--steps: must be >= 3, got {args.steps}")
  dev = jax.devices()[0]
  t0 = time.perf_counter()
  rows = []
  for name in names:
    r = check_task(name, args.envs, args.steps, args.seed, args.strict, args.robot)
    rows.append(r)
    print(f"{name}: {'PASS' if r['ok'] else 'FAIL'} "
          f"{ {k: (c['bitwise'], c['max_abs_diff']['reward']) for k, c in r['checks'].items()} } {r['wall_s']} s",
          flush=True)
  import mujoco

  res = {"command": " ".join(shlex.quote(a) for a in ["python", "benchmarks/determinism.py",
                                                      *(sys.argv[1:] if argv is None else argv)]),
         "device": f"{dev.platform}:{getattr(dev, 'device_kind', '')}", "host": platform.node(),
         "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
         "total_s": round(time.perf_counter() - t0, 1), "strict": args.strict, "seed": args.seed,
         "matmul_precision": args.matmul_precision,
         "versions": {"jax": jax.__version__, "mujoco": mujoco.__version__}, "tasks": rows,
         "ok": all(r["ok"] for r in rows)}
  # the robot in the results and the default name only when not the gripper (those stay as committed)
  robot_part = ""
  if args.robot != "gripper":
    res["robot"], robot_part = args.robot, f"_{args.robot}"
  out = args.out or os.path.join(HERE, "results", f"determinism_{dev.platform}{robot_part}.json")
  io.write_json(out, res)
  io.write_text(os.path.splitext(out)[0] + ".md", report_md(res))
  print(f"wrote {out}; {'PASS' if res['ok'] else 'FAIL'}")
  return 0 if res["ok"] else 1


if __name__ == "__main__":
  sys.exit(main())

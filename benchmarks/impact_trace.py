"""Where MJX and native MuJoCo part on an impact: one policy, the same resets, both backends, step by step.

The scripted verdicts of the two backends agree, but a trained policy can sit close to a damage threshold
(the penalty is zero below it, so nothing pays for a margin) and then the backends' small differences decide
its episodes. This script steps ``--episodes`` episodes of ``--policy`` on MJX-JAX and on native MuJoCo from
the same reset states and action keys (each backend's policy reacts to its own states) and records, per
control step, each tracked link's F∥ (the largest per-substep value the damage models saw, N) and the tilt of
``--body`` (angle between its z axis and the world's, degrees; the body needs a free joint).

Per backend it reports each link's peak F∥ (mean over episodes), the body's tilt at the step of its peak
(mean), the steps at which the peaks come, and the first episode's trace around the body's peak.

Writes ``benchmarks/results/impact_trace_<task>[_<tag>].{json,md}`` with the command.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/impact_trace.py --task place_plate --body plate \\
        --policy scripted:unsafe --episodes 8
"""

from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags and the jax compat shim before jax starts)
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)
from apps import resolve as R  # noqa: E402
from mjx_damage.trajectory import mj_model_of, rollout  # noqa: E402
from train import evaluate as E  # noqa: E402

BACKENDS = ("mjx", "native")
WINDOW = 3  # steps either side of the peak in the trace table


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--task", default="place_plate")
  p.add_argument("--policy", default="scripted:unsafe", help="policy spec (mjx-damage eval --policy)")
  p.add_argument("--body", default="plate", help="body whose tilt is traced (it needs a free joint)")
  p.add_argument("--episodes", type=int, default=8)
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON")
  p.add_argument("--tag", default="")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  args = p.parse_args(argv)
  try:  # everything checked before a task is built or compiled
    R.check_task(args.task)
    R.parse_policy_spec(args.policy)
    E.check_args(args.episodes, 1.0, 95.0, seed=args.seed)
    overrides = R.task_overrides(args.task, R.policy_task_kwargs(args.policy, args.task), None, args.task_arg)
    args.env = R.make_task(args.task, **overrides)
    args.overrides = overrides
    args.qpos_adr = free_joint_qpos(mj_model_of(args.env), args.body)
    links = list(args.env.link_names)
    args.body_link = next((i for i, k in enumerate(links) if k.split("/")[-1] == args.body), None)
    if args.body_link is None:
      raise ValueError(f"body: {args.body!r} is not a tracked link ({', '.join(links)})")
  except ValueError as e:
    p.error(str(e))
  return args


def free_joint_qpos(model: mujoco.MjModel, body: str) -> int:
  """qpos address of ``body``'s free joint (its position, then its quaternion w, x, y, z)."""
  bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
  if bid < 0:
    raise ValueError(f"body: no body {body!r} in the scene")
  for j in range(model.body_jntadr[bid], model.body_jntadr[bid] + model.body_jntnum[bid]):
    if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
      return int(model.jnt_qposadr[j])
  raise ValueError(f"body: {body!r} has no free joint, so it has no tilt of its own")


def tilt_deg(quat: np.ndarray) -> np.ndarray:
  """Angle between a body's z axis and the world's, degrees, from its quaternion f[..., 4] (w, x, y, z)."""
  q = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
  zz = 1.0 - 2.0 * (q[..., 1] ** 2 + q[..., 2] ** 2)  # z component of the body's z axis
  return np.degrees(np.arccos(np.clip(zz, -1.0, 1.0)))


def trace(env, policy, backend: str, episodes: int, seed: int, qpos_adr: int) -> dict:
  """Per control step of every episode (:func:`mjx_damage.trajectory.rollout`, row t after t steps, 0 the reset):
  F∥ f[T+1, N, L] (N) and the body's height f[T+1, N] (m) and tilt (deg)."""
  tr = rollout(R.on_backend(env, backend, episodes), policy, steps=R.episode_length_of(env), seed=seed,
               num_envs=episodes)
  body = tr.qpos[..., qpos_adr: qpos_adr + 7]
  return {"f_par": tr.f_par, "z": body[..., 2], "tilt": tilt_deg(body[..., 3:])}


def summarise(tr: dict, links: list[str], body_link: int) -> dict:
  f, tilt = tr["f_par"], tr["tilt"]
  at = f[:, :, body_link].argmax(0)  # [N]: step of the body's peak F∥ in each episode
  n = np.arange(f.shape[1])
  lo = max(int(at[0]) - WINDOW, 0)
  return {"peak_f_par_N": dict(zip(links, f.max(0).mean(0).round(1).tolist())),
          "peak_step": at.tolist(),
          "tilt_at_peak_deg": float(tilt[np.maximum(at - 1, 0), n].mean()),  # the step before: the pose it lands in
          "trace_episode_0": [{"step": t, "f_par_N": round(float(f[t, 0, body_link]), 1),
                               "z_m": round(float(tr["z"][t, 0]), 4), "tilt_deg": round(float(tilt[t, 0]), 2)}
                              for t in range(lo, min(int(at[0]) + WINDOW + 1, f.shape[0]))]}


def render_md(res: dict) -> str:
  lines = [f"# Impact on MJX and native MuJoCo: {res['task']}, {res['policy']}", "",
           f"Date: {res['date']}. Git: {res['git']}. jax {res['jax']} ({res['backend']}). {res['episodes']} episodes "
           f"from the same resets (episode seed {res['seed']}), each backend's policy acting on its own states. "
           f"Step k: after k control steps. F∥: the largest per-substep value of the control step, N. Tilt of `{res['body']}`: angle of its z "
           "axis from the world's, degrees, at the step before its peak F∥.", "",
           f"Command: `{res['command']}`", "",
           "| link | peak F∥, MJX (N) | peak F∥, native (N) |", "|---|---|---|"]
  m, n = (res["backends"][b] for b in BACKENDS)
  lines += [f"| {k} | {m['peak_f_par_N'][k]:.1f} | {n['peak_f_par_N'][k]:.1f} |" for k in m["peak_f_par_N"]]
  lines += ["", f"| | MJX | native |", "|---|---|---|",
            f"| tilt of {res['body']} before its peak (deg, mean) | {m['tilt_at_peak_deg']:.2f} | {n['tilt_at_peak_deg']:.2f} |",
            f"| step of the peak, per episode | {', '.join(map(str, m['peak_step']))} | "
            f"{', '.join(map(str, n['peak_step']))} |", "",
            "Episode 0 around the peak:", "",
            "| backend | step | F∥ (N) | height (m) | tilt (deg) |", "|---|---|---|---|---|"]
  for b in BACKENDS:
    lines += [f"| {b} | {r['step']} | {r['f_par_N']:.1f} | {r['z_m']:.4f} | {r['tilt_deg']:.2f} |"
              for r in res["backends"][b]["trace_episode_0"]]
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  args = parse(argv)
  env = args.env
  links, body_link = list(env.link_names), args.body_link
  policy = R.make_policy(args.policy, env)
  res = {"task": args.task, "policy": args.policy, "body": args.body, "episodes": args.episodes,
         "seed": args.seed, "task_kwargs": args.overrides, "backends": {}}
  for b in BACKENDS:
    res["backends"][b] = summarise(trace(env, policy, b, args.episodes, args.seed, args.qpos_adr), links, body_link)
    print(b, res["backends"][b]["peak_f_par_N"], f"tilt {res['backends'][b]['tilt_at_peak_deg']:.2f} deg", flush=True)
  stem = os.path.join(args.results_dir, f"impact_trace_{args.task}" + (f"_{args.tag}" if args.tag else ""))
  provenance.save_results(res, "impact_trace", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

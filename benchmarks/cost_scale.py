"""How large is one step's damage cost next to one step's task reward? Per-step scales under given policies.

A penalised reward ``r_task − w·cost`` is only as well scaled as its largest terms. The task rewards of this
project are dense terms of order 1 per step; the damage cost (``info["cost"]``, health points summed over
links and models, DamageWrapper) is not bounded by the health it removes: one hard contact can cost more than
100 in a step. This script rolls each policy for ``--episodes`` episodes (to its first ``done``) and reports,
over the steps: the largest |task reward|, the step cost's mean, 99th percentile and maximum, how many steps
cost more than a whole entity's health (100), and the episode cost (mean, max).

Policies are the CLI's specs (``checkpoint[+sample|+mean]:FILE#SEED``, ``scripted:safe``, ``scripted:unsafe``,
``zero``, ``random``); a checkpoint runs in the task settings it was trained with, ``--task-arg`` over them
(the start, for instance), as in benchmarks/policy_recheck.py.

Writes ``benchmarks/results/cost_scale_<task>[_<tag>].{json,md}`` with the command. Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/cost_scale.py --task shelve_item --episodes 64 \\
        --policies 'checkpoint+sample:benchmarks/results/…_policy.npz,scripted:unsafe'
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

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)
from apps import resolve as R  # noqa: E402

WHOLE_ENTITY = 100.0  # health points: a step costing more removed more than one entity can lose


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--task", required=True)
  p.add_argument("--policies", required=True, help="comma-separated policy specs")
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--seed", type=int, default=0, help="episode sample (initial states, sampled actions)")
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="task keyword over every policy's settings (a checkpoint brings its own)")
  p.add_argument("--tag", default="")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  a = p.parse_args(argv)
  R.check_task(a.task)
  if a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  if a.seed < 0:
    raise ValueError(f"seed: must be >= 0, got {a.seed}")
  a.policies = [s.strip() for s in a.policies.split(",") if s.strip()]
  if not a.policies:
    raise ValueError("policies: give at least one policy spec")
  for s in a.policies:
    R.parse_policy_spec(s)  # unknown kinds and missing files raise here, before anything compiles
  trained = {s: R.policy_task_kwargs(s, a.task) for s in a.policies if R.parse_policy_spec(s)[0] == "checkpoint"}
  a.overrides = [R.task_overrides(a.task, trained.get(s, {}), None, a.task_arg) for s in a.policies]
  return a


def step_scales(env, policy, length: int, episodes: int, seed: int) -> dict:
  """Roll ``episodes`` episodes of ``length`` steps; per-step task reward and cost up to each first done.

  Returns numpy f32[episodes, length] arrays ``task_reward``, ``cost`` and bool ``live``.
  """
  def episode(key):
    k0, k1 = jax.random.split(key)

    def body(carry, k):
      s, live = carry
      n = env.step(s, policy(s, k))
      out = (n.info["task_reward"], n.info["cost"], live)
      return (n, live & (n.done < 0.5)), out

    _, out = jax.lax.scan(body, (env.reset(k0), jnp.bool_(True)), jax.random.split(k1, length))
    return out

  keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
  reward, cost, live = jax.jit(jax.vmap(episode))(keys)
  return {"task_reward": np.asarray(reward), "cost": np.asarray(cost), "live": np.asarray(live)}


def summarise(s: dict) -> dict:
  live = s["live"]
  cost, reward = s["cost"][live], s["task_reward"][live]
  ep_cost = np.where(live, s["cost"], 0.0).sum(axis=1)
  return {"steps": int(live.sum()), "task_reward_abs_max": float(np.abs(reward).max()),
          "task_reward_abs_mean": float(np.abs(reward).mean()),
          "cost_mean": float(cost.mean()), "cost_p99": float(np.percentile(cost, 99)), "cost_max": float(cost.max()),
          "steps_over_entity": int((cost > WHOLE_ENTITY).sum()),
          "episodes_with_step_over_entity": float(np.mean((np.where(live, s["cost"], 0.0) > WHOLE_ENTITY).any(1))),
          "episode_cost_mean": float(ep_cost.mean()), "episode_cost_max": float(ep_cost.max())}


def render_md(res: dict) -> str:
  lines = [f"# {res['task']}: one step's damage cost next to its task reward",
           "",
           f"{res['episodes']} episodes per policy (seed {res['seed']}), every step up to the episode's first done. "
           "Cost: `info[\"cost\"]`, health points summed over tracked links and damage models (not bounded by "
           f"the health a link has left). Steps > {WHOLE_ENTITY:g}: steps that cost more than a whole entity's health.",
           "",
           "| policy | settings | steps | max abs task reward | step cost mean | p99 | max | steps > 100 "
           "| episodes with one | episode cost mean | max |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
  for r in res["rows"]:
    lines.append(
        f"| `{r['policy']}` | {json.dumps(r['overrides'], sort_keys=True)} | {r['steps']} | {r['task_reward_abs_max']:.2f} "
        f"| {r['cost_mean']:.2f} | {r['cost_p99']:.1f} | {r['cost_max']:.0f} | {r['steps_over_entity']} "
        f"| {100 * r['episodes_with_step_over_entity']:.0f} % | {r['episode_cost_mean']:.0f} | {r['episode_cost_max']:.0f} |")
  lines += ["", f"Command: `{res['command']}` (git {res['git']}, jax {res['jax']}, {res['backend']}, {res['date']})", ""]
  return "\n".join(lines)


def main(argv=None) -> int:
  a = parse(argv)
  rows = []
  for spec, overrides in zip(a.policies, a.overrides):
    t0 = time.time()
    env = R.make_task(a.task, **overrides)
    s = step_scales(env, R.make_policy(spec, env), R.episode_length_of(env, a.task), a.episodes, a.seed)
    rows.append({"policy": spec, "overrides": overrides, **summarise(s), "wall_s": round(time.time() - t0, 1)})
    r = rows[-1]
    print(f"{spec}: |task reward| ≤ {r['task_reward_abs_max']:.2f}, step cost max {r['cost_max']:.0f}, "
          f"{r['steps_over_entity']} steps > 100 ({r['wall_s']:.0f} s)", flush=True)
  res = {"task": a.task, "episodes": a.episodes, "seed": a.seed, "rows": rows}
  stem = os.path.join(a.results_dir, f"cost_scale_{a.task}" + (f"_{a.tag}" if a.tag else ""))
  provenance.save_results(res, "cost_scale", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

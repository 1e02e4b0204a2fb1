"""How large do normalised observations get? Brax's running normaliser after the first rollout, then later states.

PPO (brax's and ours) divides every observation by a running standard deviation, floored at 1e-6 and never
clipped. The first update's statistics come from one rollout of the untrained policy (``num_envs ×
unroll_length`` observations). A coordinate that rollout leaves (almost) still — a box resting on a shelf, the
bottles beside it — gets a standard deviation near the floor, and when a later policy does move it, the
normalised input is ``Δx / 1e-6``: a 1 cm push is 10⁴. The networks' first layers see such inputs before the
statistics catch up. This script measures it: it fits brax's ``running_statistics`` to the first
``--fit-steps`` observations (the reset one included) of ``--fit-envs`` episodes of ``--fit`` (default
``initial``: our trainer's freshly initialised policy, sampled, with ``--init-log-std``), then rolls each of
``--policies`` for ``--episodes`` episodes (to each first done) and reports, per observation coordinate, the
fitted std and the largest |normalised value| under every policy, and how many coordinates pass 10 and 1000.

Policies are the CLI's specs (``checkpoint[+sample|+mean]:FILE#SEED``, ``scripted:safe``, ``scripted:unsafe``,
``zero``, ``random``), all run in the task settings given by ``--task-arg``.

Writes ``benchmarks/results/obs_scale_<task>[_<tag>].{json,md}`` with the command. Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/obs_scale.py --task shelve_item --task-arg 'start="route"' \\
        --policies 'scripted:unsafe,scripted:safe,random' --tag route
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
from brax.training.acme import running_statistics  # noqa: E402
from brax.training.agents.ppo import networks as ppo_networks  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)
from apps import resolve as R  # noqa: E402
from train import networks as N  # noqa: E402
from train.config import PPOConfig  # noqa: E402

INITIAL = "initial"
THRESHOLDS = (10.0, 1000.0)  # |z| levels counted per policy: past a unit-scale input, and far past it


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--task", required=True)
  p.add_argument("--policies", required=True, help="comma-separated policy specs rolled under the fitted statistics")
  p.add_argument("--fit", default=INITIAL, help=f"the policy whose first steps fit the normaliser: '{INITIAL}' "
                 "(our trainer's freshly initialised policy, sampled) or a policy spec")
  p.add_argument("--fit-envs", type=int, default=2048, help="episodes of the fitting rollout (the trainers' num_envs)")
  p.add_argument("--fit-steps", type=int, default=10, help="observations per episode fitted, the reset one "
                 "included (the trainers' unroll_length)")
  p.add_argument("--init-log-std", default="-0.5,-1.5", help=f"'{INITIAL}' policy's log-std: ARM,GRIPPER")
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON", help="task keyword (repeatable)")
  p.add_argument("--tag", default="")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  a = p.parse_args(argv)
  R.check_task(a.task)
  for name in ("fit_envs", "fit_steps", "episodes"):
    if getattr(a, name) < 1:
      raise ValueError(f"{name}: must be >= 1, got {getattr(a, name)}")
  if a.seed < 0:
    raise ValueError(f"seed: must be >= 0, got {a.seed}")
  try:
    a.init_log_std = tuple(float(x) for x in a.init_log_std.split(","))
  except ValueError:
    raise ValueError(f"init_log_std: expected ARM,GRIPPER numbers, got {a.init_log_std!r}") from None
  if len(a.init_log_std) != 2 or not all(np.isfinite(a.init_log_std)):
    raise ValueError(f"init_log_std: expected two finite numbers ARM,GRIPPER, got {a.init_log_std!r}")
  a.policies = [s.strip() for s in a.policies.split(",") if s.strip()]
  if not a.policies:
    raise ValueError("policies: give at least one policy spec")
  for s in a.policies + ([] if a.fit == INITIAL else [a.fit]):
    R.parse_policy_spec(s)  # unknown kinds and missing files raise here, before anything compiles
  a.overrides = R.task_overrides(a.task, {}, None, a.task_arg)
  return a


def initial_policy(env, init_log_std: tuple[float, float], seed: int):
  """Our trainer's policy before its first update: fresh weights (playground preset), identity normaliser,
  one sampled action per step. ``policy(state, rng) -> f32[A]``."""
  obs_size = int(jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape[-1])
  cfg = PPOConfig.preset("playground", init_log_std=init_log_std)
  network = N.make_networks(obs_size, env.action_size, cfg)
  params = N.init_params(network, cfg, env.action_size, jax.random.PRNGKey(seed))
  normaliser = running_statistics.init_state(jnp.zeros((obs_size,), jnp.float32))
  apply = N.policy_apply(ppo_networks.make_inference_fn(network), action="sample")
  return lambda state, rng: apply((normaliser, params.policy), state, rng)


def rollout_obs(env, policy, length: int, episodes: int, seed: int):
  """Observations of ``episodes`` episodes, the reset one first: f32[episodes, length + 1, O], and bool
  ``live`` [episodes, length + 1] (False after an episode's first done)."""
  def episode(key):
    k0, k1 = jax.random.split(key)
    s0 = env.reset(k0)

    def body(carry, k):
      s, live = carry
      n = env.step(s, policy(s, k))
      return (n, live & (n.done < 0.5)), (n.obs, live)

    _, (obs, live) = jax.lax.scan(body, (s0, jnp.bool_(True)), jax.random.split(k1, length))
    return jnp.concatenate([s0.obs[None], obs]), jnp.concatenate([jnp.ones((1,), bool), live])

  obs, live = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(seed), episodes))
  return np.asarray(obs), np.asarray(live)


def fit_normaliser(obs: np.ndarray):
  """brax's running statistics over ``obs`` f32[N, O] from its initial state: what the first PPO update uses."""
  state = running_statistics.init_state(jnp.zeros((obs.shape[-1],), jnp.float32))
  return running_statistics.update(state, jnp.asarray(obs, jnp.float32))


def z_max(obs: np.ndarray, live: np.ndarray, state) -> np.ndarray:
  """Largest |normalised value| per coordinate over the live steps: f32[O]."""
  z = np.abs(np.asarray(running_statistics.normalize(jnp.asarray(obs), state)))
  return np.where(live[..., None], z, 0.0).max(axis=(0, 1))


def render_md(res: dict) -> str:
  pols = [r["policy"] for r in res["rows"]]
  lines = [f"# {res['task']}: normalised observations after the first rollout's statistics",
           "",
           f"Statistics: brax `running_statistics` fitted to the first {res['fit_steps']} observations of "
           f"{res['fit_envs']} episodes of `{res['fit']}` (the first PPO update's normaliser; std floored at 1e-6, "
           f"no clip). Then {res['episodes']} episodes per policy (seed {res['seed']}), every step to the first done. "
           f"Task settings {json.dumps(res['overrides'], sort_keys=True)}.",
           "",
           "| policy | max abs z | coordinates with max abs z > 10 | > 1000 |",
           "|---|---|---|---|"]
  for r in res["rows"]:
    lines.append(f"| `{r['policy']}` | {r['z_max']:.3g} | {r['over_10']} | {r['over_1000']} |")
  lines += ["", "Per coordinate (index into the observation; robot part first, then the task's):", "",
            "| coordinate | fitted std | " + " | ".join(f"max abs z, `{p}`" for p in pols) + " |",
            "|---|---|" + "---|" * len(pols)]
  for i, std in enumerate(res["fit_std"]):
    lines.append(f"| {i} | {std:.2e} | " + " | ".join(f"{r['z_max_per_coordinate'][i]:.3g}" for r in res["rows"])
                 + " |")
  lines += ["", f"Command: `{res['command']}` (git {res['git']}, jax {res['jax']}, {res['backend']}, {res['date']})", ""]
  return "\n".join(lines)


def main(argv=None) -> int:
  a = parse(argv)
  env = R.make_task(a.task, **a.overrides)
  length = R.episode_length_of(env, a.task)
  if a.fit == INITIAL and env.action_size < 1:
    raise ValueError(f"fit: '{INITIAL}' is a trained policy's start; {a.task} has no actions (give --fit zero)")
  t0 = time.time()
  fit_policy = (initial_policy(env, a.init_log_std, a.seed) if a.fit == INITIAL else R.make_policy(a.fit, env))
  fit_obs, fit_live = rollout_obs(env, fit_policy, a.fit_steps - 1, a.fit_envs, a.seed)
  state = fit_normaliser(fit_obs.reshape(-1, fit_obs.shape[-1]))
  rows = []
  for spec in a.policies:
    obs, live = rollout_obs(env, R.make_policy(spec, env), length, a.episodes, a.seed + 1)
    z = z_max(obs, live, state)
    rows.append({"policy": spec, "z_max": float(z.max()), "z_max_per_coordinate": [float(v) for v in z],
                 **{f"over_{t:g}": int((z > t).sum()) for t in THRESHOLDS}})
    print(f"  {spec}: max |z| {z.max():.3g}, coordinates > 10: {rows[-1]['over_10']}, > 1000: {rows[-1]['over_1000']}")
  res = {"task": a.task, "overrides": a.overrides, "fit": a.fit, "fit_envs": a.fit_envs, "fit_steps": a.fit_steps,
         "init_log_std": list(a.init_log_std), "episodes": a.episodes, "seed": a.seed,
         "fit_std": [float(v) for v in np.asarray(state.std)], "rows": rows, "wall_s": round(time.time() - t0, 1)}
  stem = os.path.join(a.results_dir, f"obs_scale_{a.task}" + (f"_{a.tag}" if a.tag else ""))
  provenance.save_results(res, "obs_scale", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

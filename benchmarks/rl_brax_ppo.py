"""A second trainer on our tasks: Brax's own PPO (``brax.training.agents.ppo.train``), task-only vs damage penalty.

Nothing of ``train/`` trains here: brax 0.14.2's ``ppo.train`` runs on
``tasks.make(task, damage_weight=w, ...)`` with MuJoCo Playground 0.2.0's
published PPO settings for its PandaPickCube task
(``mujoco_playground/config/manipulation_params.py``: 2048 envs, batch 512 × 32
minibatches, 8 updates per batch, unroll 10, γ 0.97, lr 1e-3, entropy 2e-2,
observation normalisation, reward scaling 1, policy MLP 32×4, value MLP 256×5,
10 resets per evaluation, 4 evaluations, action repeat 1), episode length =
the task's. Each final policy is scored by
``train.evaluate.evaluate(env, policy, episodes=1024, seed=12345)`` (DAMAGE_MODEL.md §7:
completion, safe completion, average env health, episode cost): by its mode (brax's deterministic
policy), or with ``--eval-actions sample,mode`` as the sampled policy PPO trains too, the first
action giving the row's columns (docs/safe_rl.md, "Which policy is scored").

Rows go to ``benchmarks/results/rl_brax_<task>_<device>.{json,md}`` (or
``--out STEM``), one per run (damage weight, seed), each with its exact command and date;
rows of other runs already in the file are kept, a second run of the same command included, so one call per
run builds one table; ``--merge A.json B.json ...`` (no training) combines the files of runs made by
separate processes, e.g. several runs sharing one GPU. ``--budget-seconds`` stops a run at the first evaluation
after that much training wall time (the policy of that evaluation is scored).

``--curve-episodes N`` (default 256; 0: off): at each of brax's evaluations the current policy is also scored
by our evaluator (the first ``--eval-actions`` action, N episodes, DAMAGE_MODEL.md §7), so a row has the
completion and safe completion of every evaluation (``scored_curve``) and the time to 80 % safe, as our
trainer's periodic evaluations give it (``rl_multiseed.py``: the first evaluation with ≥ 80 % safe and ≥ 80 %
completion, s of training, compile included). brax's own evaluation reports only its reward and per-step
success. A point's ``wall_s`` is the clock when brax hands over those weights (after the training epoch, before
brax's own evaluation of them). The seconds these scorings take are kept off the run's clock (``train_wall_s``,
the curve's ``wall_s``, ``--budget-seconds``), as brax's stock training does not spend them.

GPU (one H100, ≤ 10 min per call; earlier runs of this recipe needed 15–23 M
env-steps, ≈ 50 k env-steps/s alone on the GPU, plus ≈ 65 s compile)::

    cp benchmarks/results/rl_brax_place_plate_*.json $OUT/ 2>/dev/null   # rows of earlier calls, to merge
    python benchmarks/rl_brax_ppo.py --task place_plate --damage-weights 0 --seeds 0 --num-timesteps 20000000 \
        --num-evals 9 --budget-seconds 420 --out-dir $OUT

From an actor of our trainer (``--init-from``, e.g. an ``rl_multiseed.py --export-policy`` file, and
``--init-seed``): brax starts from its weights and observation normaliser, with its own fresh value function
and the fixed w of the row (brax has no critic warm-up or w ramp), e.g. the crushing carry of Pick Egg::

    python benchmarks/rl_brax_ppo.py --task pick_egg --task-settings '{"start": "pregrasp", "carry_reward": "held"}' \
        --damage-weights 2 --seeds 0 --num-timesteps 60000000 --num-evals 16 --budget-seconds 450 \
        --init-from benchmarks/results/rl_pick_egg_nvidia_h200_held_std0_task_only_s345_rerun_task_only_policy.npz \
        --init-seed 4 --eval-actions mode,sample --out-dir $OUT

``--export-policy`` keeps each run's final weights (brax's normaliser and policy, ≈ 0.05 MB, and its value
function) beside the results as a policy file of our format, so they can come back from a device call and be
scored again elsewhere (``benchmarks/policy_recheck.py --policies checkpoint:STEM_w2_s0_policy.npz``), start
either trainer (``--init-from``), or go on in a later call (``--continue-from``: a run longer than one call;
brax restores weights only, so its optimizer state and environments start afresh, and the row says so)::

    python benchmarks/rl_brax_ppo.py --task shelve_item --task-settings '{"start":"route"}' \
        --eval-task-settings '{"start":"in_front"}' --damage-weights 2 --seeds 0 --num-timesteps 30000000 \
        --num-evals 16 --budget-seconds 380 --curve-episodes 128 --init-log-std=-0.5,-1.5 \
        --eval-actions mode,sample --export-policy --out $OUT/rl_brax_shelve_item_route_w2_a   # call 1
    python benchmarks/rl_brax_ppo.py … the same … --continue-from rl_brax_shelve_item_route_w2_a_w2_s0_policy.npz \
        --export-policy --out $OUT/rl_brax_shelve_item_route_w2_b   # call 2, the first call's file carried

CPU plumbing check (learns nothing)::

    PYTHONPATH=. .venv/bin/python benchmarks/rl_brax_ppo.py --task place_plate --damage-weights 0,2 --seeds 0 \
        --num-envs 8 --batch-size 8 --num-minibatches 2 --unroll-length 4 --num-timesteps 2000 \
        --num-eval-envs 8 --num-resets-per-eval 1 --eval-episodes 16 --out-dir /tmp/rl_brax
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import platform
import re
import shlex
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (jax compat shim for brax, XLA:CPU flags, compile cache)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from brax.training import types  # noqa: E402
from brax.training.agents.ppo import networks as ppo_networks  # noqa: E402
from brax.training.agents.ppo import train as brax_ppo  # noqa: E402

import tasks  # noqa: E402
from mjx_damage import runtime  # noqa: E402
from mjx_damage.io import read_json, write_json, write_text  # noqa: E402
from train import checkpoint as ckpt  # noqa: E402
from train.config import PPOConfig  # noqa: E402
from train.policy import load_policy  # noqa: E402
from train.ppo import init_source  # noqa: E402
from train.evaluate import episode_keys, evaluate, make_evaluator, parametrized_policy  # noqa: E402
from train.evaluate import metrics as eval_metrics  # noqa: E402
from train.networks import POLICY_ACTIONS, init_policy, policy_apply  # noqa: E402
from rl_multiseed import time_to_safe  # noqa: E402  (sibling script: one definition of time to 80 % safe)

RESULTS = os.path.join(ROOT, "benchmarks", "results")
RL_SETTINGS = tasks.RL_SETTINGS  # the setting each task is trained in (issue 24)
# MuJoCo Playground 0.2.0, manipulation_params.brax_ppo_config("PandaPickCube") (base config + its branch).
PLAYGROUND_PANDA_PICK_CUBE = {
    "num_envs": 2048, "batch_size": 512, "num_minibatches": 32, "num_updates_per_batch": 8, "unroll_length": 10,
    "discounting": 0.97, "learning_rate": 1e-3, "entropy_cost": 2e-2, "normalize_observations": True,
    "reward_scaling": 1.0, "action_repeat": 1, "num_resets_per_eval": 10, "num_evals": 4, "num_eval_envs": 128,
    "num_timesteps": 20_000_000,
}
POLICY_LAYERS, VALUE_LAYERS = (32,) * 4, (256,) * 5
EVAL_SEED = 12345
CURVE_SEED = 54321  # the per-evaluation scoring's episodes: not the final evaluation's
# brax's training metrics kept in each curve point (the names our trainer's history uses for the same)
TRAINING_LOGGED = {"v_loss": "training/v_loss", "policy_loss": "training/policy_loss",
                   "entropy_loss": "training/entropy_loss", "kl_mean": "training/kl_mean",
                   "policy_dist_mean_std": "training/policy_dist_mean_std"}


class _Budget(Exception):
  """Raised from brax's per-evaluation callback once the wall budget is spent."""


def device_slug(kind: str | None = None) -> str:
  """File-name slug of a device kind (default: this machine's first device)."""
  kind = jax.devices()[0].device_kind if kind is None else kind
  return re.sub(r"[^a-z0-9]+", "_", kind.lower()).strip("_") or jax.default_backend()


def network_factory(init_log_std: tuple[float, float] | None, obs_clip: float | None = None):
  """The recipe's ``make_ppo_networks``; with ``init_log_std`` (arm, gripper = last action dim) its
  policy starts at that per-dimension std (pre-tanh) in every state; with ``obs_clip`` both networks see
  the normalised observation clipped to ±``obs_clip`` (``--obs-clip``; our trainer's ``obs_clip``).

  Brax's tanh-normal policy has no std parameter (``make_ppo_networks`` ignores its noise-std
  arguments for it): the scale is ``softplus(last layer) + 0.001``. The same initialisation as our
  trainer's (train.networks.init_policy, reused here: it only sets initial weights, nothing of the
  training): the last layer's std half gets zero weights and the bias ``softplus⁻¹(std − 0.001)``.
  """
  base = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=POLICY_LAYERS,
                           value_hidden_layer_sizes=VALUE_LAYERS)
  if init_log_std is None and obs_clip is None:
    return base

  def make(observation_size, action_size, **kw):
    if obs_clip is not None:  # brax passes its normaliser here (ppo.train's normalize_observations)
      pre = kw.get("preprocess_observations_fn", types.identity_observation_preprocessor)
      kw["preprocess_observations_fn"] = lambda obs, stats: jnp.clip(pre(obs, stats), -obs_clip, obs_clip)
    nets = base(observation_size, action_size, **kw)
    if init_log_std is None:
      return nets
    cfg = PPOConfig(init_log_std=tuple(init_log_std))
    init = functools.partial(init_policy, nets, cfg, action_size)
    return nets.replace(policy_network=dataclasses.replace(nets.policy_network, init=init))

  return make


def export_policy(path: str, params, env, task: str, settings: dict, weight: float, seed: int, cfg: dict,
                  env_steps: int, init: tuple[str, int] | None = None, eval_settings: dict | None = None,
                  train_wall_s: float | None = None, continued_from: str | None = None) -> None:
  """Write brax's final policy ``params`` ((normaliser, policy weights[, value weights])) as a policy-only
  checkpoint of our format at ``path``: what ``train.load_policy``, ``--init-from`` of our trainer and of this
  script, and every ``checkpoint:PATH`` policy spec (eval, sweep, policy_recheck.py) read.

  The recipe's networks are our playground preset's (same MLPs, activation, normaliser: :func:`check_init`
  holds the reverse direction to that), so its config records the preset with this run's sizes and seed;
  ``meta["trainer"]`` says brax trained it. Brax's value function (``params[2]``, where given) is kept in the
  file's state slot (``meta["value_state"]``), so ``--continue-from`` can go on with the whole run. ``eval_settings``:
  the task keywords the run was evaluated with, recorded as ``eval_task_kwargs`` (what eval and the re-scorers run).
  """
  obs_size = int(jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape[-1])
  ours = PPOConfig.preset(
      "playground", seeds=(int(seed),), damage_weight=float(weight), episode_length=int(env.unwrapped.episode_length),
      num_timesteps=int(cfg["num_timesteps"]), num_envs=cfg["num_envs"], batch_size=cfg["batch_size"],
      num_minibatches=cfg["num_minibatches"], num_updates_per_batch=cfg["num_updates_per_batch"],
      unroll_length=cfg["unroll_length"], learning_rate=cfg["learning_rate"], entropy_cost=cfg["entropy_cost"],
      discounting=cfg["discounting"], reward_scaling=cfg["reward_scaling"],
      max_grad_norm=cfg.get("max_grad_norm"),  # brax's default None (the recipe's) unless --max-grad-norm
      obs_clip=cfg.get("obs_clip"),  # None (brax's unbounded normaliser) unless --obs-clip
      init_log_std=None if cfg.get("init_log_std") is None else tuple(cfg["init_log_std"]))
  meta = {"task": task, "task_kwargs": settings, "kind": "brax_ppo", "config": ours.to_json(),
          "obs_size": obs_size, "action_size": int(env.action_size), "env_steps": int(env_steps),
          "trainer": "brax.training.agents.ppo.train, the recipe of benchmarks/rl_brax_ppo.py",
          "init_from": None if init is None else os.path.basename(init[0]),
          "init_seed": None if init is None else init[1],
          **({} if eval_settings is None else {"eval_task_kwargs": eval_settings}),
          **({} if train_wall_s is None else {"train_wall_s": round(float(train_wall_s), 1)}),
          **({} if continued_from is None else {"continued_from": continued_from})}
  seed_axis = lambda tree: jax.tree.map(lambda x: np.asarray(x)[None], tree)  # noqa: E731  (our files' seed axis)
  one_seed = seed_axis((params[0], params[1]))
  value = seed_axis(params[2]) if len(params) > 2 and params[2] is not None else ()
  meta["value_state"] = value != ()
  os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
  ckpt.save(path, value, one_seed, meta)


def policy_path(stem: str, weight: float, seed: int) -> str:
  """Where ``--export-policy`` writes the policy of the run (weight, seed) of the results ``stem``."""
  return f"{stem}_w{weight:g}_s{seed}_policy.npz"


def train_one(task: str, weight: float, seed: int, cfg: dict, budget_s: float | None,
              settings: dict | None = None, actions=("mode",), init: tuple[str, int] | None = None,
              export: str | None = None, curve_episodes: int = 0, eval_settings: dict | None = None,
              cont: tuple[str, dict] | None = None) -> dict:
  """One brax PPO run, then the 1024-episode evaluation of its final policy; a result row.

  ``settings``: the task's keyword arguments (default: its RL setting, ``tasks.RL_SETTINGS``).
  ``actions``: how the final policy acts (train.networks.policy_apply: mode = brax's deterministic
  policy, sample, mean); the first gives the row's columns, every one is kept in ``by_action``.
  ``init``: (checkpoint file, seed): brax starts from that actor and observation normaliser of our trainer
  (the same brax networks, :func:`check_init`), with its own fresh value function (``restore_value_fn=False``).
  ``export``: also write the final policy there (:func:`export_policy`), before it is scored.
  ``eval_settings``: task keywords of every evaluation (brax's own, the scored curve, the final), e.g. the
  evaluation's start where training draws from a wider one; default ``settings``.
  ``cont``: (file, meta) of :func:`check_continue`: brax goes on from that run's normaliser, policy and value
  function (its optimizer state and environments start afresh: brax's restore keeps only the weights); the
  row's env steps, seconds and curves count on from that run's (``continued_from``), ``budget_s`` is this call's.
  ``curve_episodes``: > 0: score the policy of each of brax's evaluations on that many episodes by the first
  action (``scored_curve``, ``time_to_80_safe_s``); their seconds are kept off the run's clock.
  """
  settings = dict(RL_SETTINGS.get(task, {}) if settings is None else settings)
  env = tasks.make(task, damage_weight=weight, **settings)
  eval_env = env if eval_settings is None else tasks.make(task, damage_weight=weight, **eval_settings)
  episode_length = env.unwrapped.episode_length
  curve, last, scored = [], {}, []
  scoring = {"seconds": 0.0, "evaluator": None}  # per-evaluation scoring: off the run's clock
  before_steps, before_s = (0, 0.0) if cont is None else (int(cont[1]["env_steps"]), float(cont[1]["train_wall_s"]))
  t_start = time.time()

  def clock():
    return time.time() - t_start - scoring["seconds"]

  def progress(step, metrics):
    curve.append({"env_steps": before_steps + int(step), "wall_s": round(before_s + clock(), 1),
                  "eval_episode_reward": float(metrics.get("eval/episode_reward", np.nan)),
                  "eval_success": float(metrics.get("eval/episode_success", np.nan)),
                  # brax's losses of the last training epoch (absent at step 0): what a failing run shows first
                  **{name: float(metrics[key]) for name, key in TRAINING_LOGGED.items() if key in metrics}})
    loss = f", value loss {curve[-1]['v_loss']:.3g}" if "v_loss" in curve[-1] else ""
    print(f"  w={weight:g} seed={seed}: {curve[-1]['env_steps']} env-steps, {curve[-1]['wall_s']} s, "
          f"eval reward {curve[-1]['eval_episode_reward']:.2f}{loss}", flush=True)

  def keep_params(step, make_policy, params):
    last.update(step=before_steps + int(step), make_policy=make_policy, params=params)
    if curve_episodes:
      t0, at = time.time(), round(before_s + clock(), 1)
      if scoring["evaluator"] is None:  # one compile; each evaluation's weights are data
        scoring["evaluator"] = make_evaluator(
            eval_env, parametrized_policy(policy_apply(make_policy, action=actions[0]), None), episode_length)
      m = eval_metrics(scoring["evaluator"].run(episode_keys(CURVE_SEED, curve_episodes), 1.0, params=params),
                       eval_env.entity_names)
      scored.append({"env_steps": before_steps + int(step), "wall_s": at, "completion": m["completion"],
                     "safe_completion": m["safe_completion"], "episode_cost": m["cost_mean"]})
      scoring["seconds"] += time.time() - t0
    if budget_s is not None and step > 0 and clock() > budget_s:
      raise _Budget

  restore = {}
  if init is not None:
    actor = load_policy(init[0], env, seed=init[1])  # (normaliser, policy params) of that seed
    restore = dict(restore_params=(actor.params[0], actor.params[1], None), restore_value_fn=False)
  if cont is not None:
    restore = dict(restore_params=continued_params(cont[0], env, cfg), restore_value_fn=True)
  stopped_early = False
  try:
    brax_ppo.train(
        environment=env, num_timesteps=cfg["num_timesteps"], num_envs=cfg["num_envs"],
        episode_length=episode_length, action_repeat=cfg["action_repeat"], learning_rate=cfg["learning_rate"],
        entropy_cost=cfg["entropy_cost"], discounting=cfg["discounting"], unroll_length=cfg["unroll_length"],
        batch_size=cfg["batch_size"], num_minibatches=cfg["num_minibatches"],
        num_updates_per_batch=cfg["num_updates_per_batch"], num_resets_per_eval=cfg["num_resets_per_eval"],
        normalize_observations=cfg["normalize_observations"], reward_scaling=cfg["reward_scaling"],
        network_factory=network_factory(cfg.get("init_log_std"), cfg.get("obs_clip")), max_grad_norm=cfg.get("max_grad_norm"),
        num_evals=cfg["num_evals"], num_eval_envs=cfg["num_eval_envs"], seed=seed,
        progress_fn=progress, policy_params_fn=keep_params, eval_env=eval_env, **restore)
  except _Budget:
    stopped_early = True
  train_s = before_s + clock()

  make_policy = last["make_policy"]
  if export is not None:
    export_policy(export, last["params"], env, task, settings, weight, seed, cfg, last["step"], init, eval_settings,
                  train_s, None if cont is None else os.path.basename(cont[0]))
  t0 = time.time()
  by_action = {}
  for action in actions:
    res = evaluate(eval_env, parametrized_policy(policy_apply(make_policy, action=action), last["params"]),
                   episodes=cfg["eval_episodes"], seed=EVAL_SEED)
    by_action[action] = res["metrics"]
  m = by_action[actions[0]]
  return {
      "task": task, "task_settings": settings, "damage_weight": weight, "seed": seed,
      **({} if eval_settings is None else {"eval_task_settings": eval_settings}),
      "reward": "task reward only" if weight == 0 else f"task + damage penalty, w = {weight:g}",
      "completion": m["completion"], "safe_completion": m["safe_completion"], "avg_env_health": m["avg_health"],
      "episode_cost": m["cost_mean"], "task_return": m.get("task_return"), "eval_episodes": m["episodes"],
      "env_steps": last["step"], "train_wall_s": round(train_s, 1), "eval_wall_s": round(time.time() - t0, 1),
      "stopped_by_budget": stopped_early, "curve": curve, "eval_actions": list(actions),
      **({} if not curve_episodes else {
          "scored_curve": {"episodes": curve_episodes, "seed": CURVE_SEED, "action": actions[0], "points": scored,
                           "seconds": round(scoring["seconds"], 1)},
          "time_to_80_safe_s": time_to_safe(scored, keys=("safe_completion", "completion", "wall_s"))}),
      **({} if init is None else {"init_from": os.path.basename(init[0]), "init_seed": init[1]}),
      **({} if cont is None else {"continued_from": {"file": os.path.basename(cont[0]), "env_steps": before_steps,
                                                     "train_wall_s": before_s}}),
      **({} if export is None else {"policy_file": os.path.basename(export)}),
      "by_action": {a: {"completion": v["completion"], "safe_completion": v["safe_completion"],
                        "avg_env_health": v["avg_health"], "episode_cost": v["cost_mean"]}
                    for a, v in by_action.items()},
  }


def _std_label(row: dict) -> str:
  c = row.get("continued_from")
  if c:  # a run over several calls: what it continued, then the recipe's std
    row = {k: v for k, v in row.items() if k != "continued_from"}
    return _std_label(row) + f", continued from {c['file']} ({c['env_steps'] / 1e6:.1f} M)"
  if row.get("init_from"):
    return f", actor from {row['init_from']} seed {row['init_seed']}"
  recipe = row.get("recipe", {})
  std, clip, obs = recipe.get("init_log_std"), recipe.get("max_grad_norm"), recipe.get("obs_clip")
  return ("" if std is None else f", initial log-std {std[0]:g}/{std[1]:g}") + (
      "" if clip is None else f", gradient norm clipped at {clip:g}") + (
      "" if obs is None else f", observations clipped at ±{obs:g}")


def check_init(path: str, seed: int | None, task: str) -> tuple[str, int]:
  """(file, seed) of ``--init-from``/``--init-seed``: a checkpoint of our trainer on ``task`` whose actor is
  this recipe's policy network (same MLP, activation, observation normalisation), else ValueError naming the flag."""
  file, _, cfg = init_source(path, task)
  want = dict(policy_hidden_sizes=POLICY_LAYERS, activation="swish",
              normalize_observations=PLAYGROUND_PANDA_PICK_CUBE["normalize_observations"])
  for k, v in want.items():
    if getattr(cfg, k) != v:
      raise ValueError(f"init_from: {file} has {k} = {getattr(cfg, k)!r}; this recipe's actor needs {v!r}")
  seeds = list(cfg.seeds)
  if seed is None:
    if len(seeds) != 1:
      raise ValueError(f"init_seed: {file} holds seeds {','.join(map(str, seeds))}; say which with --init-seed")
    seed = seeds[0]
  ckpt.check_seed(file, seeds, seed, "init_seed")
  return file, seed


RECIPE_KEYS = ("num_envs", "batch_size", "num_minibatches", "num_updates_per_batch", "unroll_length", "learning_rate",
               "entropy_cost", "discounting", "reward_scaling", "max_grad_norm", "obs_clip")  # the last two: None unless given


def check_continue(path: str, task: str, settings: dict, eval_settings: dict | None, weights, seeds, cfg: dict,
                   init) -> tuple[str, dict]:
  """(file, meta) of ``--continue-from``: a policy this script exported (``--export-policy``) with its value
  function, of the same task, settings, weight, seed and recipe as this call, else ValueError naming the flag."""
  if init is not None:
    raise ValueError("continue_from: give --continue-from or --init-from, not both")
  if not os.path.isfile(path):
    raise ValueError(f"continue_from: no file {path!r}")
  try:
    meta = ckpt.read_meta(path)
  except Exception as e:  # not a checkpoint of ours
    raise ValueError(f"continue_from: cannot read {path!r} ({e})") from None
  if meta.get("kind") != "brax_ppo" or not meta.get("value_state"):
    raise ValueError(f"continue_from: {path} is not a run this script exported with its value function")
  ours = meta["config"]
  for field, theirs, here in (("task", meta.get("task"), task), ("task settings", meta.get("task_kwargs"), settings),
                              ("evaluation settings", meta.get("eval_task_kwargs"), eval_settings),
                              ("damage weights", [ours["damage_weight"]], list(weights)),
                              ("seeds", list(ours["seeds"]), list(seeds))):
    if theirs != here:
      raise ValueError(f"continue_from: {path} was trained with {field} {theirs!r}; this call has {here!r}")
  for k in RECIPE_KEYS:
    if ours.get(k) != cfg.get(k):
      raise ValueError(f"continue_from: {path} was trained with {k} = {ours.get(k)!r}; this call has {cfg.get(k)!r}")
  std = None if ours.get("init_log_std") is None else list(ours["init_log_std"])
  if std != (None if cfg.get("init_log_std") is None else list(cfg["init_log_std"])):
    raise ValueError(f"continue_from: {path} was trained with init_log_std {std}; this call has {cfg.get('init_log_std')}")
  if "train_wall_s" not in meta:
    raise ValueError(f"continue_from: {path} records no training seconds (exported before --continue-from existed)")
  return path, meta


def continued_params(path: str, env, cfg: dict):
  """(normaliser, policy, value) of the run exported at ``path``, for brax's ``restore_params``."""
  actor = load_policy(path, env)
  obs_size = int(jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape[-1])
  nets = network_factory(cfg.get("init_log_std"))(obs_size, int(env.action_size))
  template = jax.tree.map(lambda x: np.asarray(x)[None], nets.value_network.init(jax.random.PRNGKey(0)))
  value = jax.tree.map(lambda x: np.asarray(x[0]), ckpt.restore(path, template, "state"))
  return actor.params[0], actor.params[1], value


def _settings_label(row: dict, doc: dict) -> str:
  """The row's task settings where they differ from the file's (the task's RL setting)."""
  s = row.get("task_settings", doc["task_settings"])
  base = _robot_named(doc["task_settings"]) or {}
  ev = row.get("eval_task_settings")
  evaluated = "" if not ev else ", evaluated with " + ", ".join(f"{k}={v}" for k, v in ev.items() if s.get(k) != v)
  if _robot_named(s) == base:
    return evaluated
  # the robot only where it is not the file's
  return ", task " + ", ".join(f"{k}={v}" for k, v in s.items() if k != "robot" or v != base.get("robot")) + evaluated


def _action_label(row: dict) -> str:
  head = (row.get("eval_actions") or ["mode"])[0]  # rows written before the flag: the mode
  return "" if head == "mode" else f", {head} action"


def _matmul_label(row: dict) -> str:
  label = runtime.matmul_label(row.get("matmul_precision", "default"))  # rows before the flag: the default
  return label and ", " + label


def _robot_named(settings: dict | None) -> dict | None:
  """``settings`` with the robot they ran (rows written before the RL settings named one: tasks.UNNAMED_ROBOT)."""
  return None if settings is None else {"robot": tasks.UNNAMED_ROBOT, **settings}


def _run_label(row: dict) -> str:
  """When the run was made, to the minute (runs of one command and seed told apart)."""
  return (row.get("date") or "—")[:16]


def _key(row: dict):
  """One run: its weight, seed, settings and when it was made. A second run of a command is another row (brax's
  training on a GPU is not bitwise reproducible, so both are evidence); the same run merged twice is one row."""
  return (row["damage_weight"], row["seed"], json.dumps(row.get("recipe", {}), sort_keys=True),
          json.dumps(_robot_named(row.get("task_settings")), sort_keys=True),
          json.dumps(row.get("eval_task_settings"), sort_keys=True), row.get("init_from"), row.get("init_seed"),
          json.dumps(row.get("continued_from"), sort_keys=True), row.get("date"))


def _t80_label(row: dict) -> str:
  """Time to 80 % safe of a row: seconds, 'not reached' over its scored evaluations, or 'not scored' (rows
  run without --curve-episodes)."""
  c = row.get("scored_curve")
  if c is None:
    return "not scored"
  t = row["time_to_80_safe_s"]
  at = next((p["env_steps"] for p in c["points"] if p["wall_s"] == t), None) if t is not None else None
  shared = f", device shared by {row['card_shared_by']} runs" if row.get("card_shared_by", 1) > 1 else ""
  return (f"not reached ({len(c['points'])} evaluations{shared})" if t is None
          else f"{t:.0f} ({at / 1e6:.1f} M{shared})")


def render_md(doc: dict) -> str:
  lines = [
      f"# Brax PPO (brax.training.agents.ppo.train) on {doc['task']}: task-only vs damage penalty",
      "",
      f"Device: {doc['device']}. Recipe: MuJoCo Playground 0.2.0 PandaPickCube PPO settings, with the "
      f"command line's overrides (last call: {', '.join(f'{k} {v}' for k, v in doc['recipe'].items())}; "
      f"policy MLP {'×'.join(map(str, POLICY_LAYERS[:1]))}×{len(POLICY_LAYERS)}, value MLP "
      f"{VALUE_LAYERS[0]}×{len(VALUE_LAYERS)}), episode length = the task's. Task settings: "
      f"{doc['task_settings'] or 'defaults'}. Each final policy (its mode, brax's deterministic policy, unless "
      f"the row names the action) scored by `train.evaluate.evaluate` on the row's eval episodes (seed {EVAL_SEED}). "
      f"Time to 80 % safe: s of training (compile incl.) at brax's first evaluation whose policy, scored by our "
      f"evaluator (`--curve-episodes`, the first action, seed {CURVE_SEED}; those seconds kept off the clock), "
      f"has ≥ 80 % safe and ≥ 80 % completion, env steps in brackets.",
      "",
      "| reward | seed | env-steps | train wall s (incl. compile) | completion | safe completion | avg env health "
      "| episode cost | eval episodes | time to 80 % safe (s) | run (UTC) | command |",
      "|---|---|---|---|---|---|---|---|---|---|---|---|",
  ]
  for r in doc["rows"]:
    lines.append(
        f"| {r['reward']}{_std_label(r)}{_settings_label(r, doc)}{_action_label(r)}{_matmul_label(r)} | {r['seed']} | {r['env_steps'] / 1e6:.2f} M | {r['train_wall_s']:.0f}"
        f"{' (budget)' if r['stopped_by_budget'] else ''} | {100 * r['completion']:.1f} % "
        f"| {100 * r['safe_completion']:.1f} % | {r['avg_env_health']:.2f} | {r['episode_cost']:.2f} "
        f"| {r['eval_episodes']} | {_t80_label(r)} | {_run_label(r)} | `{r['command']}`{' (' + r['note'] + ')' if r.get('note') else ''} |")
  several = [r for r in doc["rows"] if len(r.get("eval_actions", ())) > 1]
  if several:
    lines += ["", "Final policy by action (the same weights; mode = brax's deterministic policy, sample = one draw "
              "per step, the policy PPO trains, mean = E[tanh(u)] from 32 draws):", "",
              "| reward | seed | env-steps | action | completion | safe completion | episode cost | run (UTC) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in several:
      for a, v in r["by_action"].items():
        lines.append(f"| {r['reward']}{_std_label(r)}{_settings_label(r, doc)}{_matmul_label(r)} | {r['seed']} "
                     f"| {r['env_steps'] / 1e6:.2f} M | {a} "
                     f"| {100 * v['completion']:.1f} % | {100 * v['safe_completion']:.1f} % | {v['episode_cost']:.2f} "
                     f"| {_run_label(r)} |")
  if doc.get("notes"):
    lines += ["", *doc["notes"]]
  return "\n".join(lines) + "\n"


def _csv(text, cast, field):
  try:
    vals = [cast(x) for x in text.split(",") if x.strip()]
  except ValueError:
    raise ValueError(f"{field}: comma-separated {cast.__name__}s, got {text!r}") from None
  if not vals:
    raise ValueError(f"{field}: give at least one value, got {text!r}")
  return vals


def parse_args(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  pc = PLAYGROUND_PANDA_PICK_CUBE
  p.add_argument("--task", default="place_plate")
  p.add_argument("--damage-weights", default="0,2", help="comma-separated w (0 = task reward only)")
  p.add_argument("--seeds", default="0,1,2")
  p.add_argument("--num-timesteps", type=int, default=pc["num_timesteps"])
  p.add_argument("--budget-seconds", type=float, default=None,
                 help="stop a run at the first evaluation after this much wall time (s)")
  p.add_argument("--num-envs", type=int, default=pc["num_envs"])
  p.add_argument("--batch-size", type=int, default=pc["batch_size"])
  p.add_argument("--num-minibatches", type=int, default=pc["num_minibatches"])
  p.add_argument("--unroll-length", type=int, default=pc["unroll_length"])
  p.add_argument("--num-evals", type=int, default=pc["num_evals"])
  p.add_argument("--num-eval-envs", type=int, default=pc["num_eval_envs"])
  p.add_argument("--num-resets-per-eval", type=int, default=pc["num_resets_per_eval"])
  p.add_argument("--max-grad-norm", type=float, default=None, metavar="X",
                 help="clip the gradient's global norm at X (default: none, the recipe's; ours clips at 1)")
  p.add_argument("--obs-clip", type=float, default=None, metavar="X",
                 help="clip the normalised observations at ±X (default: none, brax's normaliser, unbounded)")
  p.add_argument("--eval-episodes", type=int, default=1024)
  p.add_argument("--curve-episodes", type=int, default=256,
                 help="episodes scoring the policy at each of brax's evaluations (completion, safe completion, "
                      "time to 80 %% safe; their seconds are kept off the run's clock); 0: off")
  p.add_argument("--eval-actions", default="mode",
                 help="comma-separated actions of the final evaluation: mode (brax's deterministic policy), sample "
                      "(the stochastic policy PPO trains), mean (E[tanh(u)] from 32 draws); the first gives the "
                      "row's columns, the others are listed below the table")
  p.add_argument("--init-log-std", default=None, metavar="ARM,GRIPPER",
                 help="initial log-std of the policy (pre-tanh; gripper = last action dim), as our trainer's "
                      "--init-log-std; write --init-log-std=-0.5,-1.5. Default: brax's init (std ≈ 1.3)")
  p.add_argument("--init-from", default=None, metavar="CHECKPOINT",
                 help="start from the actor and observation normaliser of a checkpoint of our trainer (a run "
                      "directory, checkpoint.npz or an rl_multiseed --export-policy file) with the recipe's "
                      "networks; brax's value function starts fresh")
  p.add_argument("--init-seed", type=int, default=None, help="with --init-from: which of its seeds")
  p.add_argument("--continue-from", default=None, metavar="POLICY_FILE",
                 help="go on with a run this script exported (--export-policy: its normaliser, policy and value "
                      "function; brax's optimizer state starts afresh): same task, settings, weight, seed and "
                      "recipe; the row counts env steps and seconds on from that run's")
  p.add_argument("--task-settings", default=None, metavar="JSON",
                 help="task keyword arguments over its RL setting (tasks.RL_SETTINGS), e.g. "
                      "'{\"start\": \"pregrasp\"}'; rows record them")
  p.add_argument("--eval-task-settings", default=None, metavar="JSON",
                 help="task keywords changed for every evaluation over the training ones, e.g. "
                      "'{\"start\": \"in_front\"}' after --task-settings '{\"start\": \"route\"}'; rows record them")
  p.add_argument("--out-dir", default=None,
                 help="folder of the results (default benchmarks/results); a relative --out goes inside it")
  p.add_argument("--out", default=None,
                 help="results stem (default OUT_DIR/rl_brax_<task>_<device>); relative to --out-dir when that "
                      "is given, else to the working directory")
  p.add_argument("--export-policy", action="store_true",
                 help="also write each run's final policy beside the results, STEM_w<W>_s<SEED>_policy.npz "
                      "(our checkpoint format, ≈ 0.05 MB: re-scored by policy_recheck.py or eval, or an "
                      "--init-from of either trainer)")
  p.add_argument("--deterministic", action="store_true",
                 help="deterministic XLA GPU kernels: a rerun of a seed repeats it bit for bit, at 0.72–0.94× the "
                      "throughput on an H200 (mjx_damage.runtime); CPU runs repeat without it")
  p.add_argument("--matmul-precision", default=None, choices=runtime.MATMUL_PRECISIONS,
                 help="float32 matrix products (physics, networks) at the backend's default precision (TF32 on a "
                      "recent NVIDIA GPU) or at full float32 (mjx_damage.runtime); default: JAX's setting "
                      "(JAX_DEFAULT_MATMUL_PRECISION), recorded in the results either way")
  p.add_argument("--shared-card", type=int, default=1, metavar="N",
                 help="the runs of this call (or, with --merge, of the merged files) ran N at a time on one device: "
                      "rows record it and their seconds are not compared with runs that had the device alone")
  p.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                 help="train nothing: merge the rows of these results files (runs of one task made by "
                      "separate processes, e.g. several on one GPU) into --out, or OUT_DIR/rl_brax_<task>_<device "
                      "of the first file>")
  a = p.parse_args(argv)
  if a.shared_card < 1:
    raise ValueError(f"shared_card: runs at a time on the device, >= 1, got {a.shared_card}")
  if a.merge is not None:
    a.merge_docs = [_load_results(path) for path in a.merge]
    tasks_seen = sorted({d["task"] for d in a.merge_docs})
    if len(tasks_seen) != 1:
      raise ValueError(f"merge: files of one task only, got tasks {tasks_seen}")
    a.task = tasks_seen[0]
    return a
  if a.deterministic:  # before anything starts a backend: XLA reads its flags once
    runtime.use_deterministic_gpu_ops("deterministic")
  if a.matmul_precision is not None:  # before anything is traced
    runtime.use_matmul_precision(a.matmul_precision, "matmul_precision")
  tasks.task_class(a.task)  # ValueError listing the valid names, before anything compiles
  a.weights = _csv(a.damage_weights, float, "damage_weights")
  a.seed_list = _csv(a.seeds, int, "seeds")
  if any(not np.isfinite(w) or w < 0 for w in a.weights):
    raise ValueError(f"damage_weights: each must be a finite number >= 0, got {a.weights}")
  if any(s < 0 for s in a.seed_list):
    raise ValueError(f"seeds: each must be >= 0, got {a.seed_list}")
  for name in ("num_timesteps", "num_envs", "batch_size", "num_minibatches", "unroll_length", "num_evals",
               "num_eval_envs", "eval_episodes"):
    if getattr(a, name) < 1:
      raise ValueError(f"{name}: must be >= 1, got {getattr(a, name)}")
  if a.curve_episodes < 0:
    raise ValueError(f"curve_episodes: must be >= 0 (0: off), got {a.curve_episodes}")
  if a.num_resets_per_eval < 0:
    raise ValueError(f"num_resets_per_eval: must be >= 0, got {a.num_resets_per_eval}")
  if (a.batch_size * a.num_minibatches) % a.num_envs:
    raise ValueError(f"num_envs: must divide batch_size × num_minibatches ({a.batch_size * a.num_minibatches}), "
                     f"got {a.num_envs}")
  if a.budget_seconds is not None and a.budget_seconds <= 0:
    raise ValueError(f"budget_seconds: must be > 0, got {a.budget_seconds}")
  if a.max_grad_norm is not None and not (np.isfinite(a.max_grad_norm) and a.max_grad_norm > 0):
    raise ValueError(f"max_grad_norm: must be a finite number > 0, got {a.max_grad_norm}")
  if a.obs_clip is not None and not (np.isfinite(a.obs_clip) and a.obs_clip > 0):
    raise ValueError(f"obs_clip: must be a finite number > 0, got {a.obs_clip}")
  if a.init_log_std is not None:
    a.init_log_std = tuple(_csv(a.init_log_std, float, "init_log_std"))
    if len(a.init_log_std) != 2 or not all(-5.0 <= v <= 2.0 for v in a.init_log_std):  # also refuses NaN
      raise ValueError(f"init_log_std: ARM,GRIPPER, each in [-5, 2], got {a.init_log_std}")
  a.actions = tuple(x.strip() for x in a.eval_actions.split(",") if x.strip())
  if not a.actions or len(set(a.actions)) != len(a.actions) or not set(a.actions) <= set(POLICY_ACTIONS):
    raise ValueError(f"eval_actions: distinct values of {','.join(POLICY_ACTIONS)}, got {a.eval_actions!r}")
  a.init = None
  if a.init_seed is not None and a.init_from is None:
    raise ValueError("init_seed: picks a seed of the --init-from checkpoint; give --init-from")
  if a.init_from is not None:
    a.init = check_init(a.init_from, a.init_seed, a.task)
  a.settings = tasks.rl_settings(a.task, a.task_settings)
  if "damage_weight" in a.settings:
    raise ValueError("task_settings: damage_weight is set by --damage-weights, not here")
  a.eval_settings = None
  if a.eval_task_settings is not None:
    a.eval_settings = tasks.settings_over(a.task, a.settings, a.eval_task_settings, "eval_task_settings")
    if "damage_weight" in a.eval_settings:
      raise ValueError("eval_task_settings: damage_weight is set by --damage-weights, not here")
  return a


def _load_results(path: str) -> dict:
  """A results file of this script, or ValueError naming ``merge``."""
  doc = read_json(path, "merge")
  if not isinstance(doc, dict) or "task" not in doc or not isinstance(doc.get("rows"), list):
    raise ValueError(f"merge: {path!r} is not a results file of this script (no task / rows)")
  return doc


def _add_row(doc: dict, row: dict) -> None:
  """``row`` into ``doc`` (the same run already there is replaced by it, other runs kept); rows sorted for the table."""
  doc["rows"] = [r for r in doc["rows"] if _key(r) != _key(row)] + [row]
  doc["rows"].sort(key=lambda r: (r["damage_weight"], r.get("recipe", {}).get("init_log_std") is not None,
                                  r["seed"], r["env_steps"], r.get("date") or ""))


def merge(docs: list[dict], stem: str, shared_card: int = 1) -> dict:
  """The rows of ``docs`` (and of an existing ``stem``.json) in one table at ``stem``; later files win a
  shared key. Device, recipe and settings of the header come from the last file. ``shared_card`` > 1: the
  runs of ``docs`` ran that many at a time on one device (recorded in their rows)."""
  out = dict(docs[-1], rows=[], notes=[])
  if os.path.exists(stem + ".json"):
    old = _load_results(stem + ".json")
    out["rows"], out["notes"] = old["rows"], old.get("notes", [])
  for d in docs:
    for row in d["rows"]:
      _add_row(out, dict(row, card_shared_by=shared_card) if shared_card > 1 else row)
    out["notes"] += [n for n in d.get("notes", []) if n not in out["notes"]]
  write_json(stem + ".json", out)
  write_text(stem + ".md", render_md(out))
  return out


def results_stem(a, device: str) -> str:
  """Where a call writes STEM.json / .md: ``--out`` inside ``--out-dir`` when both are given (an absolute
  ``--out`` stays as it is), else ``--out`` as given, else OUT_DIR/rl_brax_<task>_<device>."""
  if a.out is None:
    return os.path.join(a.out_dir or RESULTS, f"rl_brax_{a.task}_{device}")
  return a.out if a.out_dir is None else os.path.join(a.out_dir, a.out)


def main(argv=None) -> int:
  a = parse_args(argv)
  if a.merge is not None:
    stem = results_stem(a, device_slug(a.merge_docs[0]["device"]))
    merged = merge(a.merge_docs, stem, a.shared_card)
    print(f"wrote {stem}.json / .md ({len(merged['rows'])} rows)")
    return 0
  command = "python benchmarks/rl_brax_ppo.py " + " ".join(
      shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
  command += runtime.flags_in_force(a.deterministic, a.matmul_precision)  # set through the environment
  cfg = dict(PLAYGROUND_PANDA_PICK_CUBE, num_timesteps=a.num_timesteps, num_envs=a.num_envs,
             batch_size=a.batch_size, num_minibatches=a.num_minibatches, unroll_length=a.unroll_length,
             num_evals=a.num_evals, num_eval_envs=a.num_eval_envs, num_resets_per_eval=a.num_resets_per_eval,
             eval_episodes=a.eval_episodes, **({} if a.init_log_std is None else {"init_log_std": list(a.init_log_std)}),
             **({} if a.max_grad_norm is None else {"max_grad_norm": a.max_grad_norm}),
             **({} if a.obs_clip is None else {"obs_clip": a.obs_clip}))
  stem = results_stem(a, device_slug())
  cont = None if a.continue_from is None else check_continue(
      a.continue_from, a.task, a.settings, a.eval_settings, a.weights, a.seed_list, cfg, a.init)
  if a.export_policy:  # a policy file is a run's only copy of its weights: never replaced, refused before training
    there = [policy_path(stem, w, s) for w in a.weights for s in a.seed_list
             if os.path.exists(policy_path(stem, w, s))]
    if there:
      raise ValueError(f"export_policy: {', '.join(there)} already exist (weights of an earlier run); "
                       "move them, or write this run elsewhere with --out")
  doc = {"task": a.task, "task_settings": RL_SETTINGS.get(a.task, {}), "device": jax.devices()[0].device_kind,
         "backend": jax.default_backend(), "jax": jax.__version__, "machine": platform.machine(),
         "recipe": {k: v for k, v in cfg.items() if k != "eval_episodes"}, "rows": []}
  if os.path.exists(stem + ".json"):  # keep rows of other runs: one call per run builds one table
    with open(stem + ".json") as f:
      old = json.load(f)
    doc["rows"], doc["notes"] = old.get("rows", []), old.get("notes", [])  # notes: written by hand
  for w in a.weights:
    for s in a.seed_list:
      print(f"{a.task}: damage weight {w:g}, seed {s}", flush=True)
      row = train_one(a.task, w, s, cfg, a.budget_seconds, a.settings, a.actions, a.init,
                      export=policy_path(stem, w, s) if a.export_policy else None, curve_episodes=a.curve_episodes,
                      eval_settings=a.eval_settings, cont=cont)
      row.update(command=command.strip(), date=time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                 recipe=doc["recipe"], matmul_precision=runtime.matmul_precision(),
                 **({"card_shared_by": a.shared_card} if a.shared_card > 1 else {}))
      print(f"  completion {100 * row['completion']:.1f} %, safe completion {100 * row['safe_completion']:.1f} %, "
            f"{row['env_steps']} env-steps, {row['train_wall_s']} s, time to 80 % safe "
            f"{_t80_label(row)}", flush=True)
      _add_row(doc, row)
      write_json(stem + ".json", doc)  # after every run: a timeout keeps the finished ones
      write_text(stem + ".md", render_md(doc))
  print(f"wrote {stem}.json / .md")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

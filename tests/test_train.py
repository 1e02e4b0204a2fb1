"""Training: smoke run (train → checkpoint → load → evaluate), exact resume,
Lagrange multiplier behaviour, argument validation, CLI.

All runs use the tiny PusherEnv with one shared config, so the training
iteration and the evaluation compile once (the rest hits the persistent
compilation cache; w, ĉ and lr_λ are traced values, not constants).
"""

import json
import os

os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import train  # noqa: E402
from train import ppo  # noqa: E402
from train.experiments.pusher import PusherEnv  # noqa: E402

# 16 envs × 8 steps = 128 env steps per iteration; episodes of 24 steps end every 3 iterations.
ITER = 128
TINY = dict(num_envs=16, unroll_length=8, num_minibatches=2, num_updates_per_batch=2, episode_length=24,
            policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16), num_eval_envs=8,
            learning_rate=1e-3, seed=3, progress=False)
SMOKE_STEPS = 16 * ITER  # 2048 env steps


@pytest.fixture(scope="module")
def env():
  return PusherEnv()


@pytest.fixture(scope="module")
def smoke(env, tmp_path_factory):
  """PPO-Lagrangian with budget 0: every damaging episode pushes λ up."""
  out = str(tmp_path_factory.mktemp("smoke"))
  res = train.train(env, budget=0.0, lagrange_lr=0.01, num_timesteps=SMOKE_STEPS,
                    eval_every=8 * ITER, checkpoint_every=8 * ITER, out_dir=out, **TINY)
  return res


def _rows(out_dir):
  with open(os.path.join(out_dir, "metrics.jsonl")) as f:
    return [json.loads(line) for line in f]


def test_lagrange_update_rule():
  up = ppo.lagrange_update(jnp.float32(1.0), 10.0, 4.0, 0.1, 100.0)
  assert np.isclose(up, 1.6)  # cost above budget: λ rises by lr·(J_c − ĉ)
  assert float(ppo.lagrange_update(jnp.float32(1.0), 0.0, 50.0, 0.1, 100.0)) == 0.0  # projected onto λ ≥ 0
  assert float(ppo.lagrange_update(jnp.float32(99.0), 1e6, 0.0, 0.1, 100.0)) == 100.0  # capped
  lam = jnp.float32(5.0)
  for _ in range(20):  # far below budget: decays to exactly 0 and stays there
    lam = ppo.lagrange_update(lam, 1.0, 3.0, 0.5, 100.0)
  assert float(lam) == 0.0


def test_shape_reward():
  r, c = jnp.array([1.0, -2.0, 0.5]), jnp.array([0.0, 3.0, 1e4])
  # λ = 0: the paper's r − w·c exactly (penalty and task-only runs)
  np.testing.assert_allclose(ppo.shape_reward(r, c, 2.0, 0.0), r - 2.0 * c)
  # λ > 0: same task/cost trade-off, return scale bounded by 1/(1 + λ)
  lam = 9.0
  shaped = ppo.shape_reward(r, c, 0.0, lam)
  np.testing.assert_allclose(shaped, (r - lam * c) / 10.0, rtol=1e-6)
  assert float(jnp.max(jnp.abs(shaped))) <= float(jnp.max(jnp.abs(r)) + jnp.max(c))


def test_smoke_train_checkpoint_load_evaluate(smoke, env):
  out = smoke.out_dir
  for f in ("config.json", "metrics.jsonl", "metrics.csv", "checkpoint.npz", "curves.png"):
    assert os.path.isfile(os.path.join(out, f)), f
  rows = _rows(out)
  assert [r["env_steps"] for r in rows] == [8 * ITER, 16 * ITER]
  assert smoke.env_steps == SMOKE_STEPS and smoke.iterations == 16
  # the keys benchmarks/place_plate_rl.py reports (train.evaluate.SUMMARY_KEYS)
  for k in ("completion", "safe_completion", "avg_env_health", "min_env_health", "episode_cost",
            "zero_damage_rate", "task_return", "episode_length", "episodes"):
    assert k in smoke.final_eval
  assert 0.0 <= smoke.final_eval["safe_completion"] <= smoke.final_eval["completion"] <= 1.0
  assert np.isfinite(smoke.throughput) and smoke.throughput > 0

  policy = train.load_policy(out, env=env)
  state = jax.jit(env.reset)(jax.random.PRNGKey(0))
  # a DamageWrapper'd state works too: the policy reads only state.obs
  a = jax.jit(policy)(state, jax.random.PRNGKey(1))
  assert a.shape == (1,) and bool(jnp.all(jnp.abs(a) <= 1.0))
  np.testing.assert_allclose(a, smoke.policy(state, jax.random.PRNGKey(1)), rtol=1e-6, atol=1e-6)
  # deterministic by default: the rng does not matter
  np.testing.assert_array_equal(a, jax.jit(policy)(state, jax.random.PRNGKey(7)))
  batch = jax.vmap(policy)(jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(0), 4)),
                           jax.random.split(jax.random.PRNGKey(1), 4))
  assert batch.shape == (4, 1)

  ev = train.evaluate_policy(env, policy, num_episodes=8, episode_length=24, seed=0)
  assert ev["episodes"] == 8 and 0.0 <= ev["avg_env_health"] <= 100.0 and ev["episode_cost"] >= 0.0


def test_train_evaluate_is_the_module():
  """``train.evaluate`` is the evaluation module whatever was imported first (no function shadows it)."""
  import sys
  import types

  import train.evaluate  # noqa: F401
  assert isinstance(train.evaluate, types.ModuleType) and train.evaluate is sys.modules["train.evaluate"]
  assert callable(train.evaluate.evaluate) and train.evaluate_policy is train.task_eval.evaluate_policy


def test_lambda_rises_while_cost_exceeds_budget(smoke):
  costs = [r["cost_estimate"] for r in smoke.history]
  lams = [r["lagrange"] for r in smoke.history]
  assert max(costs) > 0.0, "the random pusher should damage the vase"
  assert lams[-1] > 0.0 and lams[-1] >= lams[0]


def test_lambda_decays_to_zero_far_below_budget(env):
  res = train.train(env, budget=1e4, lagrange_init=3.0, lagrange_lr=0.01, num_timesteps=4 * ITER, **TINY)
  lam = float(res.train_state.lagrange)
  assert res.history[-1]["cost_estimate"] < 1e4
  assert lam == 0.0


def test_resume_equals_uninterrupted(smoke, env, tmp_path):
  out = str(tmp_path / "resumed")
  kw = dict(budget=0.0, lagrange_lr=0.01, eval_every=8 * ITER, checkpoint_every=8 * ITER, out_dir=out, **TINY)
  first = train.train(env, num_timesteps=8 * ITER, **kw)  # "interrupted" after its checkpoint at 8 iterations
  assert first.iterations == 8
  with open(os.path.join(out, "metrics.jsonl"), "a") as f:  # a row logged after the checkpoint is dropped
    f.write(json.dumps({"iteration": 12, "env_steps": 12 * ITER}) + "\n")
  second = train.train(env, num_timesteps=SMOKE_STEPS, resume=True, **kw)
  assert second.iterations == 16
  a, b = smoke.train_state, second.train_state
  for x, y in zip(jax.tree.leaves(a.params), jax.tree.leaves(b.params)):
    np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6)
  np.testing.assert_allclose(a.lagrange, b.lagrange, rtol=1e-5, atol=1e-6)
  np.testing.assert_allclose(a.env_state.obs, b.env_state.obs, rtol=1e-5, atol=1e-6)
  ra, rb = _rows(smoke.out_dir), _rows(out)
  assert [r["iteration"] for r in rb] == [8, 16]
  for k in ("eval/episode_cost", "eval/task_return", "train/episode_cost", "lagrange"):
    np.testing.assert_allclose(ra[-1][k], rb[-1][k], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("kwargs,name", [
    (dict(budget=-1.0), "budget"),
    (dict(num_envs=0), "num_envs"),
    (dict(num_envs=12, num_minibatches=8), "num_envs"),
    (dict(num_envs=16, num_minibatches=2, batch_size=12), "num_envs"),
    (dict(damage_weight=-2.0), "damage_weight"),
    (dict(learning_rate=0.0), "learning_rate"),
    (dict(policy_hidden_sizes=()), "policy_hidden_sizes"),
    (dict(resume=True), "resume"),
    (dict(time_limit=-5), "time_limit"),
])
def test_invalid_arguments(kwargs, name):
  args = dict(num_envs=16, num_timesteps=1000, progress=False)
  args.update(kwargs)
  with pytest.raises(ValueError, match=rf"^{name}:"):
    train.train("train.experiments.pusher:PusherEnv", **args)


def test_unknown_task():
  with pytest.raises(ValueError, match=r"^task: .*no_such_task"):
    train.train("no_such_task", num_envs=16, num_timesteps=1000, progress=False)
  with pytest.raises(ValueError, match=r"^task:"):
    train.train(object(), num_envs=16, num_timesteps=1000, progress=False)


def test_cli_errors(capsys):
  from train import cli
  assert cli.main(["--task", "no_such_task", "--out", "/tmp/x", "--no-progress"]) == 2
  assert "task: unknown task" in capsys.readouterr().err
  assert cli.main(["--task", "train.experiments.pusher:PusherEnv", "--out", "/tmp/x", "--budget", "-1",
                   "--no-progress"]) == 2
  assert "budget:" in capsys.readouterr().err

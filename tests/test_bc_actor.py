"""BC into the PPO actor, then PPO from it: the fitted actor imitates the demonstrator, its checkpoint
loads as a policy, ``train(init_from=...)`` starts from exactly those weights (held during critic
warm-up), and a checkpoint that does not fit the run is refused naming ``init_from``."""

import os

import jax
import numpy as np
import pytest
from conftest import load_benchmark

import train
from mjx_damage import data as D
from train import bc_actor as BA
from train import checkpoint as ckpt
from train.config import PPOConfig
from train.experiments.pusher import PusherEnv

TINY = dict(num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8, num_updates_per_batch=2,
            episode_length=24, policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16), num_eval_envs=8,
            learning_rate=1e-3)
ITER = 16 * 8


def demonstrator(obs):
  """A smooth map from PusherEnv's 3-D observation to its 1-D action in (-1, 1)."""
  return np.tanh(obs @ np.array([[1.5], [-0.8], [0.5]], np.float32))


@pytest.fixture(scope="module")
def env():
  return PusherEnv()


@pytest.fixture(scope="module")
def demos():
  r = np.random.default_rng(0)
  e, t = 24, 16
  obs = r.uniform(-1, 1, (e, t, 3)).astype(np.float32)
  z = np.zeros((e, t), np.float32)
  return D.build(env_name="pusher", obs={"state": obs}, actions=demonstrator(obs), rewards=z, states=obs,
                 health={"box": np.full((e, t), 100.0)}, damage={k: z for k in D.DAMAGE_KINDS}, cost=z,
                 lengths=np.full(e, t), success=np.ones(e, bool), safe=np.ones(e, bool))


@pytest.fixture(scope="module")
def fitted(demos, tmp_path_factory):
  cfg = PPOConfig.preset("playground", **TINY)
  fit = BA.fit_actor(demos, cfg, seeds=[0, 1], steps=800, batch=64)
  out = str(tmp_path_factory.mktemp("bc"))
  BA.save(fit, out, task="PusherEnv")
  return fit, out


def test_fit_lowers_the_loss_and_imitates(fitted, env):
  fit, out = fitted
  losses = np.asarray(fit.losses)
  assert losses.shape == (2, 800) and np.all(losses[:, -50:].mean(1) < losses[:, :50].mean(1) - 0.3)
  obs = np.random.default_rng(1).uniform(-1, 1, (100, 3)).astype(np.float32)
  for seed in (0, 1):
    policy = train.load_policy(out, env, seed=seed)
    act = jax.jit(jax.vmap(lambda o: policy.apply(policy.params, _obs_state(o), jax.random.PRNGKey(0))))(obs)
    assert np.abs(np.asarray(act) - demonstrator(obs)).mean() < 0.1


def _obs_state(o):
  from types import SimpleNamespace
  return SimpleNamespace(obs=o)


def test_train_starts_from_the_actor_and_holds_it_during_warmup(fitted, env):
  fit, out = fitted
  res = train.train(env, seeds=(0, 1), init_from=out, critic_warmup_iterations=100, num_timesteps=3 * ITER,
                    progress=False, **TINY)
  held = res.train_state.params.policy
  for a, b in zip(jax.tree.leaves(held), jax.tree.leaves(fit.policy), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  moved = train.train(env, seeds=(0, 1), init_from=out, num_timesteps=3 * ITER, progress=False, **TINY)
  diff = max(float(np.abs(np.asarray(a) - np.asarray(b)).max())
             for a, b in zip(jax.tree.leaves(moved.train_state.params.policy), jax.tree.leaves(fit.policy)))
  assert diff > 1e-4  # without warm-up the actor learns from the first iteration
  assert not np.array_equal(np.asarray(moved.train_state.normalizer.mean), np.asarray(fit.normalizer.mean))


def test_update_normalizer_false_keeps_the_demonstrations_statistics(fitted, env):
  """Fine-tuning with update_normalizer=False: the actor keeps reading observations as it was fitted to."""
  fit, out = fitted
  res = train.train(env, seeds=(0, 1), init_from=out, update_normalizer=False, num_timesteps=3 * ITER,
                    progress=False, **TINY)
  for a, b in zip(jax.tree.leaves(res.train_state.normalizer), jax.tree.leaves(fit.normalizer), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_one_seed_actor_starts_every_seed(demos, env, tmp_path):
  fit = BA.fit_actor(demos, PPOConfig.preset("playground", **TINY), seeds=[5], steps=50, batch=32)
  BA.save(fit, str(tmp_path), task="PusherEnv")
  res = train.train(env, seeds=(0, 1), init_from=str(tmp_path), critic_warmup_iterations=100,
                    num_timesteps=ITER, progress=False, **TINY)
  for a, b in zip(jax.tree.leaves(res.train_state.params.policy), jax.tree.leaves(fit.policy)):
    np.testing.assert_array_equal(np.asarray(a)[0], np.asarray(b)[0])
    np.testing.assert_array_equal(np.asarray(a)[1], np.asarray(b)[0])


def test_init_seed_starts_every_seed_from_one_seed_of_the_checkpoint(fitted, env):
  fit, out = fitted
  res = train.train(env, seeds=(0, 1, 2), init_from=out, init_seed=1, critic_warmup_iterations=100,
                    num_timesteps=ITER, progress=False, **TINY)
  for a, b in zip(jax.tree.leaves(res.train_state.params.policy), jax.tree.leaves(fit.policy), strict=True):
    for s in range(3):
      np.testing.assert_array_equal(np.asarray(a)[s], np.asarray(b)[1])


@pytest.mark.parametrize("kw, match", [
    (dict(init_seed=7), "^init_seed: 7 is not a seed of .*its seeds: 0, 1"),
    (dict(init_seed=0, init_from=None), "^init_seed: .* give init_from"),
])
def test_bad_init_seed_is_refused(fitted, env, kw, match):
  _, out = fitted
  kw = dict({"init_from": out}, **kw)
  with pytest.raises(ValueError, match=match):
    train.train(env, seeds=(0,), num_timesteps=ITER, progress=False, **kw, **TINY)


def test_exported_policy_is_the_run_without_its_env_states(env, tmp_path):
  """export_policy keeps what load_policy and init_from read (same weights, same seeds) and drops the train
  state (env states, optimizer), so a GPU run's policy fits through a device call's file limit."""
  run = str(tmp_path / "run")
  train.train(env, seeds=(3, 4), num_timesteps=ITER, progress=False, out_dir=run, plot=False, **TINY)
  small = str(tmp_path / "policy.npz")
  ckpt.export_policy(os.path.join(run, ckpt.FILENAME), small)
  full = np.load(os.path.join(run, ckpt.FILENAME))
  part = np.load(small)
  assert any(k.startswith("s") for k in full.files) and not any(k.startswith("s") for k in part.files)
  assert ckpt.read_meta(small) == ckpt.read_meta(os.path.join(run, ckpt.FILENAME))
  for seed in (3, 4):
    a, b = train.load_policy(run, env, seed=seed), train.load_policy(small, env, seed=seed)
    for x, y in zip(jax.tree.leaves(a.params), jax.tree.leaves(b.params), strict=True):
      np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  with pytest.raises(ValueError, match="^checkpoint: .* truncated or corrupt"):
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    ckpt.export_policy(str(tmp_path / "bad.npz"), str(tmp_path / "out.npz"))
  assert not os.path.exists(tmp_path / "out.npz")


@pytest.mark.parametrize("change, match", [
    (dict(policy_hidden_sizes=(8, 8)), "policy_hidden_sizes"),
    (dict(seeds=(0, 1, 2)), "holds 2 seeds"),
])
def test_mismatched_checkpoint_is_refused(fitted, env, change, match):
  _, out = fitted
  kw = dict(TINY, num_timesteps=ITER, progress=False)
  kw.update({k: v for k, v in change.items() if k != "seeds"})
  with pytest.raises(ValueError, match=f"^init_from: .*{match}"):
    train.train(env, seeds=change.get("seeds", (0, 1)), init_from=out, **kw)


def test_missing_or_corrupt_checkpoint_is_refused(env, tmp_path):
  kw = dict(TINY, num_timesteps=ITER, progress=False)
  with pytest.raises(ValueError, match="^init_from: no checkpoint"):
    train.train(env, init_from=str(tmp_path / "nothing"), **kw)
  bad = tmp_path / ckpt.FILENAME
  bad.write_bytes(b"garbage")
  with pytest.raises(ValueError, match="^init_from: .* not a readable checkpoint"):
    train.train(env, init_from=str(tmp_path), **kw)


def test_bad_dataset_actions_are_refused(demos):
  bad = demos.replace(actions=demos.actions * 3.0)
  with pytest.raises(ValueError, match="^dataset: actions"):
    BA.fit_actor(bad, PPOConfig.preset("playground", **TINY), steps=10, batch=8)


def test_saved_file_is_a_checkpoint(fitted):
  _, out = fitted
  meta = ckpt.read_meta(os.path.join(out, ckpt.FILENAME))
  assert meta["kind"] == "bc_actor" and meta["config"]["seeds"] == [0, 1]


def test_bc_cli_writes_a_checkpoint_and_refuses_to_overwrite(demos, tmp_path):
  import subprocess
  import sys
  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  data = tmp_path / "demos.hdf5"
  D.save(str(data), demos)
  cmd = [sys.executable, "-m", "apps.cli", "bc", "--dataset", str(data), "--out", str(tmp_path / "bc"),
         "--steps", "20", "--batch", "16", "--policy-hidden", "8,8", "--min-health", "95"]
  env = dict(os.environ, PYTHONPATH=root)
  p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
  assert p.returncode == 0, p.stderr[-2000:]
  meta = ckpt.read_meta(str(tmp_path / "bc" / ckpt.FILENAME))
  assert meta["kind"] == "bc_actor" and meta["task"] == "pusher" and meta["config"]["policy_hidden_sizes"] == [8, 8]
  before = (tmp_path / "bc" / ckpt.FILENAME).read_bytes()
  p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
  assert p.returncode == 2 and "--out" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
  assert (tmp_path / "bc" / ckpt.FILENAME).read_bytes() == before
  p = subprocess.run(cmd[:4] + ["--dataset", str(tmp_path / "missing.hdf5")], cwd=tmp_path, env=env,
                     capture_output=True, text=True, timeout=600)
  assert p.returncode == 2 and "--dataset" in p.stderr


@pytest.mark.parametrize("flags, named", [
    (["--demos", "0"], "--demos"), (["--bc-steps", "-5"], "--bc-steps"),
    (["--damage-weight", "nan"], "--damage-weight"), (["--budget-seconds", "0"], "--budget-seconds"),
    (["--task", "no_such_task"], "--task"), (["--policy-hidden", "512,0"], "--policy-hidden"),
    (["--demos-from", "humans"], "--demos-from"), (["--record", "0"], "--record"),
    (["--ft-learning-rate", "0"], "--ft-learning-rate"), (["--ft-entropy-cost", "-1"], "--ft-entropy-cost"),
    (["--ft-target-kl", "nan"], "--ft-target-kl"), (["--eval-every", "0"], "--eval-every"),
    (["--robot", "no_such_robot"], "--robot")])
def test_bc_finetune_bad_flags_exit_2_naming_the_flag(flags, named, capsys):
  """benchmarks/bc_finetune.py refuses bad sizes and budgets before recording or compiling anything."""
  with pytest.raises(SystemExit) as e:
    load_benchmark("bc_finetune").main(flags)
  assert e.value.code == 2
  assert named in capsys.readouterr().err

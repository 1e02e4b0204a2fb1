"""Training: smoke run (train → checkpoint → load → evaluate), S seeds in one program equal S single-seed
runs, exact resume of a multi-seed run, corrupt checkpoints, multiplier behaviour, validation, CLI.

All runs use the tiny PusherEnv with one config, so each seed count compiles its iteration once (the
rest hits the persistent compilation cache; w, ĉ and the multiplier gains are traced values).
"""

import json
import sys
import types
import os
import shutil
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brax.envs.base import Wrapper
from brax.training.acme import running_statistics

import mjx_damage as md
import train
from train import multipliers as M
from train import networks as N
from train import iteration
from train import ppo
from train.experiments.pusher import PusherEnv

# 16 envs × 8 steps = 128 env steps per iteration and seed; episodes of 24 steps end every 3 iterations.
ITER = 128
TINY = dict(num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8, num_updates_per_batch=2,
            episode_length=24, policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16), num_eval_envs=8,
            learning_rate=1e-3, progress=False)
SEEDS = (3, 4)
SMOKE_STEPS = 8 * ITER


@pytest.fixture(scope="module")
def env():
  return PusherEnv()


@pytest.fixture(scope="module")
def smoke(env, tmp_path_factory):
  """Two seeds of PPO-Lagrangian with budget 0 in one program: every damaging episode pushes λ up."""
  out = str(tmp_path_factory.mktemp("smoke"))
  return train.train(env, seeds=SEEDS, budget=0.0, lagrange_lr=0.01, num_timesteps=SMOKE_STEPS,
                     eval_every=4 * ITER, checkpoint_every=4 * ITER, out_dir=out, **TINY)


def _rows(out_dir):
  with open(os.path.join(out_dir, "metrics.jsonl")) as f:
    return [json.loads(line) for line in f]


def _assert_trees_close(a, b, rtol=1e-5, atol=1e-6):
  for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
    np.testing.assert_allclose(np.asarray(x, np.float64), np.asarray(y, np.float64), rtol=rtol, atol=atol)


def test_shape_reward():
  r, c = jnp.array([1.0, -2.0, 0.5]), jnp.array([0.0, 3.0, 1e4])
  np.testing.assert_allclose(ppo.shape_reward(r, c, 2.0, 0.0), r - 2.0 * c)  # λ = 0: the paper's r − w·c
  lam = 9.0
  np.testing.assert_allclose(ppo.shape_reward(r, c, 0.0, lam), (r - lam * c) / 10.0, rtol=1e-6)


def test_smoke_train_checkpoint_load_evaluate(smoke, env):
  out = smoke.out_dir
  for f in ("config.json", "metrics.jsonl", "metrics.csv", "checkpoint.npz", "curves.png"):
    assert os.path.isfile(os.path.join(out, f)), f
  rows = _rows(out)
  assert [(r["seed"], r["env_steps"]) for r in rows] == [(s, n * ITER) for n in (4, 8) for s in SEEDS]
  assert smoke.env_steps == SMOKE_STEPS and smoke.iterations == 8
  assert len(smoke.final_evals) == 2 and smoke.final_eval == smoke.final_evals[0]
  for k in ("completion", "safe_completion", "avg_env_health", "episode_cost", "task_return", "episodes"):
    assert k in smoke.final_eval
  assert np.isfinite(smoke.throughput) and smoke.throughput > 0
  # the networks' largest normalised input since the previous row: finite, and past the reset observation's 0
  assert all(np.isfinite(r["obs_max_abs_z"]) and r["obs_max_abs_z"] > 0 for r in rows)
  assert smoke.train_state.iteration.shape == (2,)

  state = jax.jit(env.reset)(jax.random.PRNGKey(0))
  default = train.load_policy(out, env=env)
  assert default.seed == SEEDS[0]
  a = jax.jit(default)(state, jax.random.PRNGKey(1))
  assert a.shape == (1,) and bool(jnp.all(jnp.abs(a) <= 1.0))
  np.testing.assert_allclose(a, smoke.policy(state, jax.random.PRNGKey(1)), rtol=1e-6, atol=1e-6)
  np.testing.assert_array_equal(a, jax.jit(default)(state, jax.random.PRNGKey(7)))  # deterministic
  second = train.load_policy(out, seed=SEEDS[1])
  _assert_trees_close(second.params[1], jax.tree.map(lambda x: x[1], smoke.train_state.params.policy), 0, 0)
  with pytest.raises(ValueError, match=r"^seed: 9 .*valid: 3, 4"):
    train.load_policy(out, seed=9)
  ev = train.evaluate_policy(env, default, num_episodes=8, episode_length=24, seed=0)
  assert ev["episodes"] == 8 and 0.0 <= ev["avg_env_health"] <= 100.0


def test_policy_specs_choose_the_checkpoints_action(smoke, env):
  """``checkpoint:`` is the mode, ``checkpoint+sample:`` the trained stochastic policy, ``checkpoint+mean:``
  the squashed mean; other suffixes are refused by name before anything loads."""
  from apps import resolve as R
  out = smoke.out_dir
  state = jax.jit(env.reset)(jax.random.PRNGKey(0))
  k1, k2 = jax.random.PRNGKey(1), jax.random.PRNGKey(2)
  for suffix, action in (("", "mode"), ("+sample", "sample"), ("+mean", "mean")):
    spec = f"checkpoint{suffix}:{out}"
    assert R.parse_policy_spec(spec) == ("checkpoint", out)
    policy = R.make_policy(spec, env)
    assert policy.action == action
    a, b = jax.jit(policy)(state, k1), jax.jit(policy)(state, k2)
    assert (action == "mode") == bool(np.array_equal(a, b))
  np.testing.assert_array_equal(jax.jit(R.make_policy(f"checkpoint:{out}", env))(state, k1),
                                jax.jit(train.load_policy(out, env))(state, k1))
  with pytest.raises(ValueError, match="^policy: unknown policy 'checkpoint\\+greedy"):
    R.parse_policy_spec(f"checkpoint+greedy:{out}")


def test_a_checkpoint_for_another_observation_is_refused_with_its_task_overrides(smoke, monkeypatch):
  import collections
  from train import checkpoint as ckpt
  State = collections.namedtuple("State", "obs")
  other = types.SimpleNamespace(reset=lambda key: State(jnp.zeros((99,))), action_size=1)
  with pytest.raises(ValueError, match=r"^env: observation/action sizes \(99, 1\) differ") as e:
    train.load_policy(smoke.out_dir, env=other)
  assert "task overrides" not in str(e.value)  # this run had none
  read = ckpt.read_meta
  monkeypatch.setattr(ckpt, "read_meta", lambda f: {**read(f), "task_kwargs": {"obs_mode": "paper"}})
  with pytest.raises(ValueError, match=r"trained with task overrides \{'obs_mode': 'paper'\}"):
    train.load_policy(smoke.out_dir, env=other)


def test_seeds_in_one_program_equal_single_seed_runs(env):
  """S = 2 in one vmapped program gives each seed the run it gets alone (same keys, same config)."""
  kw = dict(budget=0.0, lagrange_lr=0.01, num_timesteps=3 * ITER, **TINY)
  both = train.train(env, seeds=SEEDS, **kw)
  for i, s in enumerate(SEEDS):
    alone = train.train(env, seed=s, **kw)
    _assert_trees_close(both.seed_state(i).params, alone.seed_state(0).params, rtol=2e-4, atol=1e-5)
    _assert_trees_close(both.seed_state(i).env_state.obs, alone.seed_state(0).env_state.obs, rtol=2e-4, atol=1e-5)
    np.testing.assert_allclose(both.train_state.lagrange[i], alone.train_state.lagrange[0], rtol=1e-4, atol=1e-6)
  # the seeds really differ (a broadcast bug would make them equal)
  assert not np.allclose(both.seed_state(0).env_state.obs, both.seed_state(1).env_state.obs)


def test_train_evaluate_is_the_module():
  import train.evaluate  # noqa: F401
  assert isinstance(train.evaluate, types.ModuleType) and train.evaluate is sys.modules["train.evaluate"]
  assert callable(train.evaluate.evaluate) and train.evaluate_policy is train.task_eval.evaluate_policy


def test_a_damage_weight_per_seed_trains_each_run_as_alone(env, tmp_path):
  """``damage_weight`` one per seed: each run of the program trains as that seed alone with its own w (the
  contrast's two rewards in one program); its rows log its w, config.json keeps the tuple, and a resume
  with other weights is refused naming the field."""
  kw = dict(num_timesteps=3 * ITER, **TINY)
  out = str(tmp_path / "run")
  both = train.train(env, seeds=SEEDS, damage_weight=(0.0, 2.0), out_dir=out, **kw)
  assert both.config.damage_weights == (0.0, 2.0)
  assert {(r["seed"], r["damage_weight"]) for r in _rows(out)} == {(3, 0.0), (4, 2.0)}
  alone = train.train(env, seed=4, damage_weight=2.0, **kw)
  _assert_trees_close(both.seed_state(1).params, alone.seed_state(0).params, rtol=2e-4, atol=1e-5)
  other = train.train(env, seed=4, damage_weight=0.0, **kw)  # w matters here: seed 4 at w = 0 learns otherwise
  assert not all(np.allclose(x, y) for x, y in zip(jax.tree.leaves(both.seed_state(1).params),
                                                    jax.tree.leaves(other.seed_state(0).params)))
  with open(os.path.join(out, "config.json")) as f:
    assert json.load(f)["config"]["damage_weight"] == [0.0, 2.0]
  with pytest.raises(ValueError, match=r"^resume: .*\(damage_weight\)"):
    train.train(env, seeds=SEEDS, damage_weight=(2.0, 0.0), out_dir=out, resume=True, **kw)
  cfg = train.PPOConfig.preset("paper", seeds=(0, 1), damage_weight=(0.0, 2.0)).validate()
  assert train.PPOConfig.from_json(json.loads(json.dumps(cfg.to_json()))) == cfg


def test_resume_of_a_multi_seed_run_equals_uninterrupted(smoke, env, tmp_path):
  out = str(tmp_path / "resumed")
  kw = dict(seeds=SEEDS, budget=0.0, lagrange_lr=0.01, eval_every=4 * ITER, checkpoint_every=4 * ITER,
            out_dir=out, **TINY)
  first = train.train(env, num_timesteps=4 * ITER, **kw)  # "interrupted" after its checkpoint at 4 iterations
  assert first.iterations == 4
  with open(os.path.join(out, "metrics.jsonl"), "a") as f:  # a row logged after the checkpoint is dropped
    f.write(json.dumps({"seed": 3, "iteration": 6, "env_steps": 6 * ITER}) + "\n")
  # continued from a copy of the folder elsewhere, as on another machine: nothing in it names where it ran
  moved = str(tmp_path / "elsewhere" / "resumed")
  shutil.copytree(out, moved)
  shutil.rmtree(out)
  out = kw["out_dir"] = moved
  second = train.train(env, num_timesteps=SMOKE_STEPS, resume=True, **kw)
  assert second.iterations == 8
  _assert_trees_close(smoke.train_state.params, second.train_state.params)
  _assert_trees_close(smoke.train_state.multiplier, second.train_state.multiplier)
  _assert_trees_close(smoke.train_state.env_state.obs, second.train_state.env_state.obs)
  ra, rb = _rows(smoke.out_dir), _rows(out)
  assert [(r["seed"], r["iteration"]) for r in rb] == [(s, n) for n in (4, 8) for s in SEEDS]
  for x, y in zip(ra, rb):
    for k in ("eval/episode_cost", "eval/task_return", "train/episode_cost", "lagrange"):
      np.testing.assert_allclose(x[k], y[k], rtol=1e-4, atol=1e-5)


def test_corrupt_checkpoint_raises_naming_the_file(smoke, tmp_path):
  from train import checkpoint as ckpt

  src = os.path.join(smoke.out_dir, ckpt.FILENAME)
  data = open(src, "rb").read()
  bad = tmp_path / "checkpoint.npz"
  bad.write_bytes(data[: len(data) // 2])  # a copy cut half-way
  with pytest.raises(ValueError, match=r"^checkpoint: .*checkpoint\.npz is truncated or corrupt"):
    train.load_policy(str(tmp_path))
  bad.write_bytes(b"not a zip file at all")
  with pytest.raises(ValueError, match=r"^checkpoint: .*truncated or corrupt"):
    ckpt.read_meta(str(bad))


def test_lambda_rises_while_cost_exceeds_budget(smoke):
  for s in SEEDS:
    rows = [r for r in smoke.history if r["seed"] == s]
    assert max(r["cost_estimate"] for r in rows) > 0.0, "the random pusher should damage the vase"
    assert rows[-1]["lagrange"] > 0.0 and rows[-1]["lagrange"] >= rows[0]["lagrange"]


def test_lambda_decays_to_zero_far_below_budget(env):
  res = train.train(env, seeds=SEEDS, budget=1e4, lagrange_init=3.0, lagrange_lr=0.01, num_timesteps=4 * ITER,
                    **TINY)
  assert np.all(np.asarray(res.train_state.lagrange) == 0.0)


def test_pid_multiplier_run_stays_in_range(env):
  """PID-Lagrangian through the same compiled iteration (the kind is data): λ in [0, λ_max]."""
  res = train.train(env, seeds=SEEDS, budget=0.0, multiplier="pid", pid_kp=0.5, pid_ki=0.1, pid_kd=0.1,
                    lagrange_max=2.0, num_timesteps=4 * ITER, **TINY)
  lam = np.asarray(res.train_state.lagrange)
  assert np.all((lam >= 0.0) & (lam <= 2.0))
  assert np.any(lam > 0.0)  # the random pusher exceeds a zero budget


def test_budget_curriculum_run(env):
  """A budget curriculum in the same compiled iteration (its length is data): ĉ_t falls from the first
  measured episode cost to ĉ = 0 over 6 iterations, then stays there."""
  kw = dict(seeds=SEEDS, budget=0.0, lagrange_lr=0.01, budget_anneal_steps=6 * ITER, **TINY)
  for iters, done in ((5, False), (10, True)):
    ts = train.train(env, num_timesteps=iters * ITER, **kw).train_state
    mult = ts.multiplier
    assert np.all(np.asarray(mult.start_cost) > 0.0)  # the random pusher damages the vase
    budget = np.asarray(jax.vmap(M.effective_budget)(mult, ts.multiplier_params))
    assert np.all(budget == 0.0) if done else np.all(budget > 0.0), (iters, budget)


def test_scheduled_weight():
  """The penalty schedule: w = 0 through the warm-up, then a linear ramp that reaches w at its end."""
  it = jnp.arange(8)
  np.testing.assert_allclose(ppo.scheduled_weight(2.0, it, 3, 4), [0, 0, 0, 0.5, 1.0, 1.5, 2.0, 2.0])
  np.testing.assert_allclose(ppo.scheduled_weight(2.0, it, 3, 0), [0, 0, 0, 2, 2, 2, 2, 2])


def _weights_by_iteration(out):
  """{iteration: w it trained with} from a run's metrics rows (a row after iteration i carries i + 1)."""
  by_it = {}
  for r in _rows(out):
    by_it.setdefault(r["iteration"] - 1, set()).add(round(r["damage_weight"], 6))
  return by_it


def test_damage_schedule_run(env, tmp_path):
  """A run with the penalty schedule logs w per iteration: 0 for the warm-up, the ramp, then w."""
  out = str(tmp_path / "run")
  train.train(env, seeds=SEEDS, damage_weight=2.0, damage_warmup_steps=3 * ITER, damage_ramp_steps=2 * ITER,
              num_timesteps=7 * ITER, eval_every=ITER, out_dir=out, **TINY)
  by_it = _weights_by_iteration(out)
  assert by_it == {0: {0.0}, 1: {0.0}, 2: {0.0}, 3: {1.0}, 4: {2.0}, 5: {2.0}, 6: {2.0}}, by_it


def test_penalty_gate():
  """The completion gate opens once, at the first rollout with finished episodes that completed the task at
  the rate or more and past the step-count warm-up; then ``penalty_start`` stays where it was set."""
  shut = jnp.int32(iteration.NOT_YET)
  gate = lambda start, it, done, n, floor=0: int(iteration.penalty_gate(start, jnp.int32(it), jnp.float32(done),  # noqa: E731
                                                                      jnp.float32(n), 0.5, floor))
  assert gate(shut, 4, 0.0, 0.0) == iteration.NOT_YET  # no episode finished this rollout
  assert gate(shut, 4, 7.0, 16.0) == iteration.NOT_YET  # 44 % < 50 %
  assert gate(shut, 4, 8.0, 16.0) == 5  # 50 %: the next iteration ramps
  assert gate(shut, 4, 16.0, 16.0, floor=6) == iteration.NOT_YET  # the step-count warm-up is not over
  assert gate(jnp.int32(2), 9, 0.0, 16.0) == 2  # once open it stays open


@pytest.mark.parametrize("tol", [1.0, 0.0])
def test_damage_warmup_completion_run(tol, tmp_path):
  """``damage_warmup_completion``: w stays 0 until a rollout's finished episodes complete the task at the
  rate, past ``damage_warmup_steps``. The pusher's 24-step episodes all end in iterations 2, 5, … With a
  1 m success radius 87–100 % of them complete, so the gate opens after iteration 5 (iteration 2's episodes
  came before the 4-iteration floor) and the ramp runs over iterations 6–7; with a 0 m radius none does,
  w stays 0, and the run's weights are those of a task-reward run of the same seeds."""
  out = str(tmp_path / "run")
  res = train.train(PusherEnv(tol=tol), seeds=SEEDS, damage_weight=2.0, damage_warmup_completion=0.5,
                    damage_warmup_steps=4 * ITER, damage_ramp_steps=2 * ITER, num_timesteps=8 * ITER,
                    eval_every=ITER, out_dir=out, **TINY)
  start = np.asarray(res.train_state.penalty_start)
  if tol:
    assert _weights_by_iteration(out) == {**{i: {0.0} for i in range(6)}, 6: {1.0}, 7: {2.0}}
    assert np.all(start == 6), start
    # iteration 2's episodes completed too: the floor, not the rate, kept the gate shut then
    assert all(r["train/episode_completion"] >= 0.5 for r in _rows(out) if r["iteration"] in (3, 6))
  else:
    assert _weights_by_iteration(out) == {i: {0.0} for i in range(8)}
    assert np.all(start == iteration.NOT_YET), start
    # while shut, the gate changes nothing else: the same seeds train to the same weights under task reward
    plain = train.train(PusherEnv(tol=tol), seeds=SEEDS, num_timesteps=8 * ITER, eval_every=ITER,
                        out_dir=str(tmp_path / "plain"), **TINY)
    for a, b in zip(jax.tree.leaves(res.train_state.params), jax.tree.leaves(plain.train_state.params)):
      np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_damage_warmup_completion_validation():
  with pytest.raises(ValueError, match="^damage_warmup_completion: must be <= 1"):
    train.PPOConfig(damage_weight=2.0, damage_warmup_completion=1.5).validate()
  with pytest.raises(ValueError, match="^damage_warmup_completion: must be a finite number"):
    train.PPOConfig(damage_weight=2.0, damage_warmup_completion=float("nan")).validate()
  with pytest.raises(ValueError, match="^damage_warmup_completion: gates"):
    train.PPOConfig(damage_warmup_completion=0.5).validate()
  assert train.PPOConfig.from_json({}).damage_warmup_completion == 0.0  # runs from before: no gate


def test_annealed_entropy():
  """The entropy anneal: the configured coefficient at the first iteration, linear to 0 at the run's end, 0 after."""
  np.testing.assert_allclose(ppo.annealed_entropy(0.02, jnp.arange(6), 4), [0.02, 0.015, 0.01, 0.005, 0.0, 0.0])


def test_entropy_anneal_run(env):
  """``anneal_entropy``: the first iteration trains exactly as without it (same coefficient); from then on the
  entropy term carries the annealed coefficient (its logged loss ≈ 3/4, then 1/2 of the constant run's, the
  policies' entropies barely apart after a few small steps). Non-bool values are refused."""
  kw = dict(seed=0, num_timesteps=4 * ITER, eval_every=ITER, **TINY)
  const = train.train(env, **kw).history
  anneal = train.train(env, anneal_entropy=True, **kw)
  assert anneal.config.anneal_entropy
  a = anneal.history
  assert a[0]["loss/entropy_loss"] == const[0]["loss/entropy_loss"] and a[0]["loss/policy_loss"] == const[0]["loss/policy_loss"]
  for i, frac in ((1, 0.75), (2, 0.5), (3, 0.25)):
    assert a[i]["loss/entropy_loss"] / const[i]["loss/entropy_loss"] == pytest.approx(frac, rel=0.05), i
  with pytest.raises(ValueError, match="^anneal_entropy:"):
    train.PPOConfig(anneal_entropy=1).validate()
  assert train.PPOConfig.from_json({}).anneal_entropy is False  # runs from before: a constant coefficient


def test_obs_clip_bounds_the_normalised_input_of_both_networks():
  """obs_clip: a coordinate the normaliser saw still (std at its 1e-6 floor) and that then moves reaches the
  networks as at most ±obs_clip; unset (the default, and every run from before), unbounded as in brax."""
  stats = running_statistics.update(running_statistics.init_state(jnp.zeros((2,), jnp.float32)),
                                    jnp.array([[0.1, 0.0], [-0.1, 0.0]], jnp.float32))  # coordinate 1 still
  moved = jnp.array([[0.0, 0.01]], jnp.float32)  # 1 cm: 10⁴ after normalising
  assert float(jnp.abs(N.normalizer_fn(train.PPOConfig())(moved, stats)).max()) > 1e3
  assert float(jnp.abs(N.normalizer_fn(train.PPOConfig(obs_clip=5.0))(moved, stats)).max()) == 5.0
  cfg = train.PPOConfig(obs_clip=5.0, policy_hidden_sizes=(8,), value_hidden_sizes=(8,))
  nets = N.make_networks(2, 2, cfg)
  params = N.init_params(nets, cfg, 2, jax.random.PRNGKey(0))
  at_bound, far = jnp.array([[0.0, 5e-6]]), jnp.array([[0.0, 1.0]])  # both ≥ 5 after normalising
  for net, w in ((nets.policy_network, params.policy), (nets.value_network, params.value)):
    assert bool(jnp.allclose(net.apply(stats, w, at_bound), net.apply(stats, w, far)))
  assert train.PPOConfig.from_json({}).obs_clip is None


def test_max_abs_z_is_the_networks_largest_input_before_any_clip():
  """The training metric obs_max_abs_z: a coordinate the normaliser saw still (std at its 1e-6 floor), moved
  1 cm at one step of one env, is 10⁴, the largest |input| of the whole [R·E, T, O] batch."""
  stats = running_statistics.update(running_statistics.init_state(jnp.zeros((2,), jnp.float32)),
                                    jnp.array([[0.1, 0.0], [-0.1, 0.0]], jnp.float32))
  obs = jnp.zeros((3, 4, 2), jnp.float32).at[1, 2, 1].set(0.01)
  assert float(iteration.max_abs_z(stats, obs)) == pytest.approx(1e4, rel=1e-3)
  assert float(iteration.max_abs_z(stats, jnp.zeros((3, 4, 2), jnp.float32))) == 0.0


def test_a_diverged_run_names_a_huge_normalised_input():
  """TrainingDiverged names the networks' largest normalised input of a diverged seed when it is far past unit
  scale (and points at --obs-clip); not when it is not, nor another seed's."""
  m = {"loss/v_loss": np.array([np.nan, 1.0]), "obs_max_abs_z": np.array([2e6, 5e6]), "env_non_finite": np.zeros(2)}
  msg = str(ppo._diverged(ppo.non_finite_losses(m, (3, 4)), m, (3, 4), 7, 896, None))
  assert "input was 2e+06 for seed 3" in msg and "5e+06" not in msg and "--obs-clip" in msg
  m["obs_max_abs_z"] = np.array([50.0, 5e6])
  msg = str(ppo._diverged(ppo.non_finite_losses(m, (3, 4)), m, (3, 4), 7, 896, None))
  assert "input was" not in msg and "seed 3: loss/v_loss" in msg


def test_large_input_message_names_the_seeds_past_the_line_and_is_silent_when_clipped():
  z = np.array([15.0, 6.7, 3e4])  # 6.7: Place Plate's largest in training, where a clip at 10 is inert
  msg = ppo.large_input_message(z, (0, 1, 2), None)
  assert "15 (seed 0)" in msg and "3e+04 (seed 2)" in msg and "seed 1" not in msg and "--obs-clip" in msg
  assert ppo.large_input_message(z, (0, 1, 2), 10.0) is None  # clipped: the networks never saw them
  assert ppo.large_input_message(np.array([9.9, 10.0]), (0, 1), None) is None  # at the line: quiet


def _warned(category, env, iterations, **kwargs) -> list:
  """The messages of ``category`` a tiny training run of ``iterations`` iterations warned."""
  with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    train.train(env, seeds=SEEDS, num_timesteps=iterations * ITER, eval_every=iterations * ITER, **TINY, **kwargs)
  return [str(w.message) for w in caught if issubclass(w.category, category)]


def test_a_run_warns_once_when_its_normalised_inputs_pass_the_usual_clip_unless_clipped(env, monkeypatch):
  """The training loop warns (LargeInputWarning, once per run) when obs_max_abs_z passes Z_WARN with
  observations unclipped, and not with obs_clip set. Z_WARN lowered to 0 so a tiny run crosses it."""
  monkeypatch.setattr(ppo, "Z_WARN", 0.0)
  large = _warned(ppo.LargeInputWarning, env, 2)
  assert len(large) == 1 and "seed 3" in large[0] and "--obs-clip" in large[0]
  assert not _warned(ppo.LargeInputWarning, env, 2, obs_clip=10.0)


def test_critic_divergence_message_names_the_seeds_whose_value_loss_leapt():
  """Past V_FLOOR and V_JUMP times the seed's own lowest: our Place Plate seed 0 (2.4 -> 2.1e15) warns; a loss
  that only rose 20-fold, Pick Egg's critic meeting the penalty late (0.089 -> 4.5e7, under the floor) and a
  first iteration do not."""
  v, low = np.array([2.1e15, 50.0, 4.5e7]), np.array([2.44, 2.5, 0.089])
  msg = ppo.critic_divergence_message(v, low, (0, 1, 2), 36, 5898240)
  assert "seed 0: 2.1e+15, its lowest 2.44" in msg and "seed 1" not in msg and "seed 2" not in msg
  assert "iteration 36 (5.9 M env steps" in msg
  assert "--gae-per-iteration true" in msg  # where the run could go next
  fixed = ppo.critic_divergence_message(v, low, (0, 1, 2), 36, 5898240, fixed_targets=True)
  assert "already computes its value targets once per iteration" in fixed and "--gae-per-iteration" not in fixed
  assert ppo.critic_divergence_message(v, np.full(3, np.inf), (0, 1, 2), 1, 0) is None  # nothing to compare with
  assert ppo.critic_divergence_message(np.array([2e9]), np.array([1e-3]), (4,), 9, 9) is not None
  assert ppo.critic_divergence_message(np.array([2e9]), np.array([1e4]), (4,), 9, 9) is None  # 2e5-fold


def test_a_run_warns_once_when_its_critic_diverges(env, monkeypatch):
  """The training loop warns (CriticDivergedWarning, once per run) when a seed's loss/v_loss leaps past its own
  lowest; with the thresholds at 0 any second iteration's loss does, and the defaults keep a healthy run quiet."""
  monkeypatch.setattr(ppo, "V_JUMP", 0.0)
  monkeypatch.setattr(ppo, "V_FLOOR", 0.0)
  div = _warned(ppo.CriticDivergedWarning, env, 3)
  assert len(div) == 1 and "iteration 2 " in div[0] and "seed 3" in div[0]
  monkeypatch.undo()
  assert not _warned(ppo.CriticDivergedWarning, env, 3)


@pytest.mark.parametrize("kwargs,name", [
    (dict(budget=-1.0), "budget"),
    (dict(damage_warmup_steps=-1, damage_weight=2.0), "damage_warmup_steps"),
    (dict(damage_ramp_steps=100), "damage_ramp_steps"),
    (dict(num_envs=0), "num_envs"),
    (dict(num_envs=12, num_minibatches=8, batch_size=None), "num_envs"),
    (dict(num_envs=16, num_minibatches=2, batch_size=12), "num_envs"),
    (dict(damage_weight=-2.0), "damage_weight"),
    (dict(seeds=(0, 1), damage_weight=(0.0,)), "damage_weight"),
    (dict(seeds=(0, 1), damage_weight=(0.0, float("nan"))), "damage_weight"),
    (dict(seeds=(0, 1), damage_weight=(0.0, -1.0)), "damage_weight"),
    (dict(seeds=(0, 1), damage_weight=(0.0, True)), "damage_weight"),
    (dict(seeds=(0, 0), damage_weight=(0.0, 2.0)), "seeds: .*runs are named by their seed"),
    (dict(seeds=(0, 1), damage_weight=(0.0, 0.0), damage_warmup_steps=100), "damage_warmup_steps"),
    (dict(learning_rate=0.0), "learning_rate"),
    (dict(obs_clip=0.0), "obs_clip"),
    (dict(obs_clip=float("nan")), "obs_clip"),
    (dict(obs_clip=5.0, normalize_observations=False), "obs_clip"),
    (dict(policy_hidden_sizes=()), "policy_hidden_sizes"),
    (dict(multiplier="pd"), "multiplier"),
    (dict(seeds=(1, 1)), "seeds"),
    (dict(seeds=()), "seeds"),
    (dict(init_log_std=(0.0,)), "init_log_std"),
    (dict(preset="nope"), "preset"),
    (dict(no_such_field=1), "no_such_field"),
    (dict(resume=True), "resume"),
    (dict(time_limit=-5), "time_limit"),
    (dict(eval_task_kwargs={"no_such_keyword": 1}), "eval_task_kwargs"),
    (dict(eval_task_kwargs="tol=10"), "eval_task_kwargs"),
])
def test_invalid_arguments(kwargs, name):
  args = dict(num_envs=16, batch_size=8, num_minibatches=2, num_timesteps=1000, progress=False)
  args.update(kwargs)
  with pytest.raises(ValueError, match=rf"^{name}:"):
    train.train("train.experiments.pusher:PusherEnv", **args)


def test_eval_task_kwargs_evaluate_in_another_setting(smoke, tmp_path):
  """``eval_task_kwargs``: every periodic evaluation runs the task built with them (here a goal tolerance
  so wide that every episode succeeds at once), training is unchanged, config.json records them."""
  out = str(tmp_path / "run")
  res = train.train("train.experiments.pusher:PusherEnv", seeds=SEEDS, eval_task_kwargs={"tol": 10.0},
                    num_timesteps=2 * ITER, eval_every=ITER, out_dir=out, **TINY)
  assert [r["eval/completion"] for r in res.history] == [1.0] * 4
  assert min(r["eval/completion"] for r in smoke.history) < 1.0  # in the training setting it is not given
  with open(os.path.join(out, "config.json")) as f:
    meta = json.load(f)
  assert meta["eval_task_kwargs"] == {"tol": 10.0} and meta["task_kwargs"] == {}


def test_eval_task_kwargs_are_checked_before_compiling(env):
  """Another observation size, or a task given as an env instance, is refused naming eval_task_kwargs."""
  args = dict(num_envs=16, batch_size=8, num_minibatches=2, num_timesteps=1000, progress=False)
  with pytest.raises(ValueError, match=r"^eval_task_kwargs: .*observation shape"):
    train.train("place_plate", task_kwargs={"obs_mode": "paper"}, eval_task_kwargs={"obs_mode": "full"}, **args)
  with pytest.raises(ValueError, match=r"^eval_task_kwargs: only used with a task name"):
    train.train(env, eval_task_kwargs={"tol": 1.0}, **args)


def test_unknown_task():
  with pytest.raises(ValueError, match=r"^task: .*no_such_task"):
    train.train("no_such_task", num_envs=16, batch_size=8, num_minibatches=2, num_timesteps=1000, progress=False)
  with pytest.raises(ValueError, match=r"^task:"):
    train.train(object(), num_envs=16, batch_size=8, num_minibatches=2, num_timesteps=1000, progress=False)


def test_cli_errors_and_flags(capsys):
  from train import cli
  assert cli.main(["--task", "no_such_task", "--out", "/tmp/x", "--no-progress"]) == 2
  assert "task: unknown task" in capsys.readouterr().err
  assert cli.main(["--task", "train.experiments.pusher:PusherEnv", "--out", "/tmp/x", "--budget", "-1",
                   "--no-progress"]) == 2
  assert "budget:" in capsys.readouterr().err
  args, config = cli.split_args(vars(cli.build_parser().parse_args(
      ["--task", "t", "--out", "o", "--seeds", "0,1,2", "--preset", "paper", "--multiplier", "pid",
       "--init-log-std=-0.5,-1.5", "--timesteps", "1e6", "--anneal-entropy", "true",
       "--redraw-starts-steps", "3.2768e5"])))
  assert args["seeds"] == (0, 1, 2) and args["preset"] == "paper"
  assert config == {"multiplier": "pid", "init_log_std": (-0.5, -1.5), "num_timesteps": 1_000_000,
                    "anneal_entropy": True, "redraw_starts_steps": 327680}
  for text, w in (("2", 2.0), ("0,2", (0.0, 2.0)), ("1.5,", (1.5,))):
    _, config = cli.split_args(vars(cli.build_parser().parse_args(["--task", "t", "--damage-weight", text])))
    assert config == {"damage_weight": w}
  with pytest.raises(SystemExit):
    cli.build_parser().parse_args(["--task", "t", "--damage-weight", "0,two"])
  assert "--damage-weight: comma-separated numbers" in capsys.readouterr().err
  assert cli.main(["--task", "train.experiments.pusher:PusherEnv", "--out", "/tmp/x", "--seeds", "0,1",
                   "--damage-weight", "0,2,2", "--no-progress"]) == 2
  assert "damage_weight: one finite number >= 0, or one per seed (2 for seeds [0, 1])" in capsys.readouterr().err
  _, config = cli.split_args(vars(cli.build_parser().parse_args(["--task", "t", "--max-grad-norm", "none"])))
  assert config == {"max_grad_norm": None}  # brax's default: no clipping (not "the preset's")
  assert train.PPOConfig.preset("playground", **config).validate().max_grad_norm is None
  with pytest.raises(SystemExit):
    cli.build_parser().parse_args(["--task", "t", "--max-grad-norm", "off"])
  assert "--max-grad-norm: a number or none" in capsys.readouterr().err


def test_cli_eval_task_arg_is_checked_before_compiling(capsys, tmp_path):
  """``--eval-task-arg``: a malformed item or a keyword the task refuses stops the run (exit 2) naming it."""
  from train import cli
  out = str(tmp_path / "run")
  pusher = ["--task", "train.experiments.pusher:PusherEnv", "--out", out, "--no-progress"]
  assert cli.main(pusher + ["--eval-task-arg", "tol"]) == 2
  assert "--eval-task-arg: expected KEY=JSON" in capsys.readouterr().err
  assert cli.main(pusher + ["--eval-task-arg", "no_such_keyword=1"]) == 2
  assert "eval_task_kwargs:" in capsys.readouterr().err
  assert not os.path.exists(os.path.join(out, "checkpoint.npz"))


def test_train_evaluate_is_the_module():
  import sys
  import types

  import train.evaluate  # noqa: F401
  assert isinstance(train.evaluate, types.ModuleType) and train.evaluate is sys.modules["train.evaluate"]


def test_sigterm_writes_a_checkpoint_and_exits_130(env, tmp_path):
  """SIGTERM mid-run: the iteration finishes, a checkpoint is written, SystemExit(130); resume continues it."""
  import signal
  import threading
  import time

  default = signal.getsignal(signal.SIGTERM)

  def send_when_handled():  # only once train() has installed its handler (else SIGTERM would end pytest)
    for _ in range(6000):
      if signal.getsignal(signal.SIGTERM) is not default:
        os.kill(os.getpid(), signal.SIGTERM)
        return
      time.sleep(0.01)

  out = str(tmp_path / "killed")
  kw = dict(seeds=SEEDS, budget=0.0, lagrange_lr=0.01, out_dir=out, **TINY)
  t = threading.Thread(target=send_when_handled)
  t.start()
  with pytest.raises(SystemExit) as e:
    train.train(env, num_timesteps=1000 * ITER, **kw)
  t.join()
  assert e.value.code == 130
  assert signal.getsignal(signal.SIGTERM) is default  # handler restored
  from train import checkpoint as ckpt
  meta = ckpt.read_meta(os.path.join(out, ckpt.FILENAME))
  done = meta["iteration"]
  assert 1 <= done < 1000
  res = train.train(env, num_timesteps=(done + 1) * ITER, resume=True, **kw)
  assert res.iterations == done + 1


def test_paper_preset_initial_log_std_per_dimension():
  """Brax's tanh-normal head has no std parameter: our init gives log-std −0.5 (arm) / −1.5 (gripper) in every state."""
  from brax.training.acme import running_statistics

  cfg = train.PPOConfig.preset("paper").validate()
  assert (cfg.policy_hidden_sizes, cfg.activation, cfg.num_updates_per_batch, cfg.num_minibatches,
          cfg.unroll_length, cfg.target_kl, cfg.entropy_cost, cfg.max_grad_norm) == ((512, 512), "tanh", 10, 8,
                                                                                     512, 0.01, 0.0, 0.5)
  net = N.make_networks(6, 4, cfg)
  params = N.init_policy(net, cfg, 4, jax.random.PRNGKey(0))
  obs = jax.random.normal(jax.random.PRNGKey(1), (64, 6)) * 3.0
  logits = net.policy_network.apply(running_statistics.init_state(jnp.zeros((6,))), params, obs)
  log_std = np.log(np.asarray(net.parametric_action_distribution.create_dist(logits).scale))
  np.testing.assert_allclose(log_std, np.broadcast_to([-0.5, -0.5, -0.5, -1.5], log_std.shape), atol=1e-5)


def test_parameter_std_is_the_same_in_every_state_and_learns(env, tmp_path):
  """``policy_std="parameter"``: one log-std per action dimension, starting at ``init_log_std`` in every state,
  moved by training (its gradient reaches it), saved and loaded with the run; the MLP gives only the mean."""
  from brax.training.acme import running_statistics

  cfg = train.PPOConfig(policy_std="parameter", init_log_std=(-0.5, -1.5), policy_hidden_sizes=(16, 16)).validate()
  net = N.make_networks(6, 4, cfg)
  params = N.init_policy(net, cfg, 4, jax.random.PRNGKey(0))
  np.testing.assert_allclose(params["log_std"], [-0.5, -0.5, -0.5, -1.5])
  obs = jax.random.normal(jax.random.PRNGKey(1), (64, 6)) * 3.0
  logits = net.policy_network.apply(running_statistics.init_state(jnp.zeros((6,))), params, obs)
  dist = net.parametric_action_distribution.create_dist(logits)
  np.testing.assert_allclose(np.log(np.asarray(dist.scale)), np.broadcast_to([-0.5, -0.5, -0.5, -1.5], (64, 4)),
                             atol=1e-5)
  assert float(jnp.std(dist.loc)) > 0  # the mean still depends on the state
  out = str(tmp_path / "run")
  res = train.train(env, seed=0, num_timesteps=2 * ITER, eval_every=ITER, policy_std="parameter",
                    init_log_std=(-0.5, -1.5), out_dir=out, **TINY)
  assert res.config.policy_std == "parameter"
  learned = np.asarray(res.seed_state(0).params.policy["log_std"])
  assert learned.shape == (env.action_size,) and learned[0] != -0.5  # moved from its start
  policy = train.load_policy(out, env=env)
  assert policy.meta["config"]["policy_std"] == "parameter"
  with pytest.raises(ValueError, match="policy_std"):
    train.PPOConfig(policy_std="global").validate()
  assert train.PPOConfig.from_json({}).policy_std == "state"  # runs from before: brax's head


def test_target_kl_measures_the_updates_own_kl(env):
  """``target_kl`` stops on the KL the SGD steps made, not on the normaliser's shift since the rollout.

  The observation normaliser is updated before the epochs, so the rollout's recorded logits differ from
  the policy's own before any step; measured against those, a small target stopped every iteration
  before its first step (issue 24's paper-preset runs: 0–1 of 80 steps). Now the first step is always
  taken, a tiny target stops right after it, and a huge one never stops.
  """
  kw = dict(seed=0, num_timesteps=3 * ITER, eval_every=ITER, **TINY)
  steps = TINY["num_minibatches"] * TINY["num_updates_per_batch"]
  tiny = train.train(env, target_kl=1e-7, **kw).history
  assert [r["sgd_steps"] for r in tiny] == [1.0, 1.0, 1.0]
  assert all(r["loss/kl_update"] == 0.0 for r in tiny)  # measured before the one step taken: none yet
  huge = train.train(env, target_kl=1e6, **kw).history
  assert [r["sgd_steps"] for r in huge] == [float(steps)] * 3
  assert all(r["loss/kl_update"] > 0.0 for r in huge)


def test_target_kl_epoch_rule_takes_whole_epochs(env):
  """CleanRL's rule (``target_kl_rule="epoch"``) checks at the end of an epoch, against the target itself:
  a tiny target keeps exactly the first epoch (every minibatch of it), a huge one all epochs; SB3's rule
  with the same tiny target keeps one step. Unknown rules are refused before anything compiles."""
  kw = dict(seed=0, num_timesteps=2 * ITER, eval_every=ITER, **TINY)
  n_mb, epochs = TINY["num_minibatches"], TINY["num_updates_per_batch"]
  tiny = train.train(env, target_kl=1e-7, target_kl_rule="epoch", **kw)
  assert tiny.config.target_kl_rule == "epoch"
  assert [r["sgd_steps"] for r in tiny.history] == [float(n_mb)] * 2
  huge = train.train(env, target_kl=1e6, target_kl_rule="epoch", **kw).history
  assert [r["sgd_steps"] for r in huge] == [float(n_mb * epochs)] * 2
  with pytest.raises(ValueError, match="target_kl_rule"):
    train.PPOConfig(target_kl=0.01, target_kl_rule="batch").validate()
  assert train.PPOConfig.from_json({"target_kl": 0.01}).target_kl_rule == "minibatch"  # older runs: SB3's


def test_normalizer_after_update_starts_the_ratio_at_one(env):
  """With ``normalizer_after_update`` the epochs normalise with the statistics the rollout used, so before
  the first step the policy equals the rollout's (brax's KL is then its 1e-5-per-dimension floor); in
  brax's order the normaliser's update alone moves it. A tiny target KL keeps exactly that first step,
  whose pre-update KL is what the metrics report."""
  kw = dict(seed=0, num_timesteps=3 * ITER, eval_every=ITER, target_kl=1e-7, **TINY)
  floor = env.action_size * np.log1p(1e-5)
  sb3 = train.train(env, normalizer_after_update=True, **kw)
  assert sb3.config.normalizer_after_update
  np.testing.assert_allclose([r["loss/kl_mean"] for r in sb3.history], floor, rtol=1e-2)
  brax = train.train(env, **kw).history
  assert all(r["loss/kl_mean"] > 10 * floor for r in brax[1:])
  assert not np.allclose([r["loss/kl_mean"] for r in brax], floor, rtol=1e-2)
  assert train.PPOConfig.preset("paper").normalizer_after_update and not train.PPOConfig().normalizer_after_update


class _NaNRewardPusher(PusherEnv):
  """The pusher with a NaN reward: what an env that blows up hands the damage wrapper."""

  def step(self, state, action):
    s = super().step(state, action)
    return s.replace(reward=s.reward * jnp.nan)


class _NaNOutsideTheDamageWrapper(Wrapper):
  """A NaN task reward added outside the damage wrapper, which therefore cannot keep it finite."""

  def step(self, state, action):
    s = self.env.step(state, action)
    return s.replace(info=dict(s.info, task_reward=s.info["task_reward"] * jnp.nan))


def test_non_finite_losses_stop_training_naming_the_seeds(tmp_path):
  """A diverged update raises (naming seeds, iteration and metric) instead of training NaN weights to the
  end of the budget, and writes no checkpoint of the NaN weights."""
  out = str(tmp_path / "run")
  env = _NaNOutsideTheDamageWrapper(md.DamageWrapper(PusherEnv()))
  with pytest.raises(ppo.TrainingDiverged, match=r"iteration 1 .*seed 3: .*loss/.*seed 4: .*loss/.*env's own .*"
                                                  r"100 % of seed 3's transitions.*no checkpoint"):
    train.train(env, seeds=SEEDS, num_timesteps=4 * ITER, checkpoint_every=ITER, out_dir=out, **TINY)
  from train import checkpoint
  assert not os.path.exists(os.path.join(out, checkpoint.FILENAME))


def test_an_env_whose_physics_diverges_trains_on(tmp_path):
  """Inside the damage wrapper a non-finite step ends its episode with finite data (mjx_damage.wrapper):
  training goes on, finite, and logs how many steps diverged."""
  res = train.train(_NaNRewardPusher(), seeds=SEEDS, num_timesteps=2 * ITER, eval_every=ITER, **TINY)
  assert len(res.history) == 2 * len(SEEDS)
  for r in res.history:
    assert r["env_non_finite"] == 0.0 and r["env_diverged_steps"] == ITER  # every step: the reward is NaN
    assert all(np.isfinite(v) for k, v in r.items() if k.startswith("loss/"))


def test_non_finite_losses_per_seed():
  m = {"loss/policy_loss": np.array([0.1, np.nan, 0.2]), "loss/v_loss": np.array([np.inf, 0.0, 1.0]),
       "lagrange": np.array([np.nan, np.nan, np.nan])}  # only losses count
  assert ppo.non_finite_losses(m, (7, 8, 9)) == {7: ["loss/v_loss"], 8: ["loss/policy_loss"]}
  assert ppo.non_finite_losses({"loss/x": np.zeros(2)}, (0, 1)) == {}


def test_a_healthy_run_logs_no_non_finite_env_steps(smoke):
  rows = _rows(smoke.out_dir)
  assert rows and all(r["env_non_finite"] == 0.0 for r in rows)


def test_cli_init_seed_is_checked_before_anything_runs(tmp_path, capsys):
  from train import cli
  egg = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "results",
                     "rl_pick_egg_nvidia_h200_held_std0_task_only_s345_rerun_task_only_policy.npz")  # seeds 3,4,5
  out = str(tmp_path / "run")
  assert cli.main(["--task", "pick_egg", "--out", out, "--init-seed", "4", "--no-progress"]) == 2
  assert "--init-seed: picks a seed of the --init-from checkpoint" in capsys.readouterr().err
  assert cli.main(["--task", "pick_egg", "--out", out, "--init-from", egg, "--init-seed", "9", "--no-progress"]) == 2
  err = capsys.readouterr().err
  assert "--init-seed: 9 is not a seed of" in err and "(its seeds: 3, 4, 5)" in err
  assert not os.path.exists(out)


def test_redraw_starts_gives_every_env_a_fresh_start(env):
  """Off (the default), each training env replays the start of its first reset for the whole run (brax's
  AutoResetWrapper restores it at every episode end). With ``redraw_starts_steps`` every env gets a fresh
  start at each positive multiple of that many env steps, cutting the episodes under way (uncounted), as
  brax's ``num_resets_per_eval`` does; before the first redraw the run is exactly the run without it."""
  kw = dict(seed=0, eval_every=ITER, **TINY)
  first = lambda res: np.asarray(res.train_state.env_state.info["first_pipeline_state"].qpos)  # noqa: E731
  off1, off3 = train.train(env, num_timesteps=ITER, **kw), train.train(env, num_timesteps=3 * ITER, **kw)
  np.testing.assert_array_equal(first(off1), first(off3))  # the same 16 starts, however long the run
  on1 = train.train(env, num_timesteps=ITER, redraw_starts_steps=ITER, **kw)
  untimed = lambda res: [{k: v for k, v in r.items() if k != "wall_time"} for r in res.history]  # noqa: E731
  assert untimed(on1) == untimed(off1) and on1.config.redraw_starts_iterations == 1
  on3 = train.train(env, num_timesteps=3 * ITER, redraw_starts_steps=ITER, **kw)
  assert np.all(first(on3) != first(off3))  # every env's start drawn again (uniform x0: never equal)
  # episodes of 24 steps, cut every 8: none ends, none is counted; without the redraws the first ends at step 24
  assert [r["train/episodes"] for r in on3.history] == [0.0] * 3
  assert off3.history[-1]["train/episodes"] > 0
  with pytest.raises(ValueError, match="^redraw_starts_steps:"):
    train.PPOConfig(redraw_starts_steps=-1).validate()
  assert train.PPOConfig.from_json({}).redraw_starts_steps == 0  # runs from before: fixed starts

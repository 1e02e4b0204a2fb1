"""Evaluation, sweeps and fragility: compiled evaluation = a step-by-step loop,
fragility levels do not recompile, sharded = unsharded, bad input is rejected
before anything compiles. One small env (1 box + pusher) and one executable
shared by the module keep this file to a few compilations."""

import json
import os
import re
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_damage import randomize
from apps import eval_cli, resolve
from apps import sweep_cli
from tasks.bench_table import table_env
from mjx_damage.wrapper import DamageWrapper
import train.evaluate as E
import train.sweep as S

EPISODES, T, SEED = 3, 8, 7
# Fragile enough that the box loses all health within T steps under its own
# weight (threshold 30/200 N < 2 N), so termination and freezing are exercised.
FRAGILE = 200.0
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def make_env():
  return DamageWrapper(table_env(k=1, n_substeps=2, episode_length=T), terminate_on_destroyed=True)


def push_policy(env):
  """Scripted: drive the pusher at box 0 (from the observation), plus a little noise from ``rng``."""
  radius = env.unwrapped.radius if hasattr(env, "unwrapped") else env.radius

  def policy(state, rng):
    target = state.obs[2:4] / radius
    return jnp.clip(target + 0.1 * jax.random.normal(rng, (2,)), -1.0, 1.0)

  return policy


@pytest.fixture(scope="module")
def setup():
  env = make_env()
  policy = push_policy(env)
  ev = E.Evaluator(env, policy, T, devices=jax.devices()[:1])
  return env, policy, ev


def python_loop(env, policy, keys, fragility):
  """The reference: each episode reset and stepped one env step at a time."""
  reset, step = jax.jit(env.reset), jax.jit(env.step)
  out = []
  for key, f in zip(keys, fragility):
    rk, ak = jax.random.split(key)
    state = E.with_fragility(reset(rk), jnp.float32(f))
    for t in range(T):
      state = step(state, policy(state, jax.random.fold_in(ak, t)))
      if float(state.done) > 0:
        break
    out.append(jax.tree.map(np.asarray, E.summary(state)))
  return {k: np.stack([o[k] for o in out]) for k in out[0]}


def test_compiled_eval_matches_python_loop(setup):
  env, policy, ev = setup
  keys = E.episode_keys(SEED, EPISODES)
  frag = np.array([1.0, 3.0, FRAGILE], np.float32)
  got = ev.run(keys, frag)
  want = python_loop(env, policy, keys, frag)
  for k in want:
    np.testing.assert_allclose(got[k], want[k], rtol=2e-3, atol=2e-2, err_msg=k)
  assert got["length"][2] < T, "the fragile episode should terminate early and stop counting"
  assert got["entity_health"][2].min() == 0.0
  assert got["cost"][2] > got["cost"][0]
  m = E.metrics(got, env.entity_names)
  assert m["episodes"] == EPISODES and 0 <= m["safe_completion"] <= m["completion"] <= 1
  assert set(m["entity_health"]) == set(env.entity_names)


def test_fragility_sweep_does_not_recompile(setup):
  env, policy, ev = setup
  keys = E.episode_keys(SEED, EPISODES)
  ev.run(keys, 1.0)  # compiles (or reuses) the evaluator for this batch size
  before = ev.num_compiled
  traces = []
  listener = lambda event, duration, **kw: traces.append(event) if "trace" in event or "compile" in event else None
  jax.monitoring.register_event_duration_secs_listener(listener)
  try:  # every fragility level, one per call and all mixed in one batch
    results = [ev.run(keys, f) for f in (0.5, 2.0, 8.0, FRAGILE)]
    mixed = ev.run(keys, np.array([0.5, 8.0, FRAGILE], np.float32))
  finally:
    jax.monitoring.unregister_event_duration_listener(listener)
  assert ev.num_compiled == before == 1
  assert not [t for t in traces if "backend_compile" in t or "jaxpr_trace" in t], traces
  costs = [r["cost"].sum() for r in results]
  assert costs == sorted(costs) and costs[-1] > costs[0]  # more fragile, more damage
  for i, r in enumerate((results[0], results[2], results[3])):  # mixed batch = per-level runs
    np.testing.assert_allclose(mixed["cost"][i], r["cost"][i], rtol=1e-5, atol=1e-5)


def test_sharded_equals_unsharded(setup):
  env, policy, ev = setup
  keys = E.episode_keys(SEED, EPISODES)
  frag = np.array([1.0, 3.0, FRAGILE], np.float32)
  want = ev.run(keys, frag)
  code = f"""
import json, sys, jax, numpy as np
sys.path.insert(0, {os.path.join(ROOT, 'tests')!r})
import test_eval as t
import train.evaluate as E
assert jax.device_count() == 2, jax.devices()
env = t.make_env()
ev = E.Evaluator(env, t.push_policy(env), t.T)  # all (2) devices; 3 episodes pad to 4
out = ev.run(E.episode_keys(t.SEED, t.EPISODES), np.array([1.0, 3.0, t.FRAGILE], np.float32))
print("RESULT" + json.dumps({{k: np.asarray(v).tolist() for k, v in out.items()}}))
"""
  env_vars = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
  proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env_vars, capture_output=True, text=True,
                        timeout=400)
  assert proc.returncode == 0, proc.stderr[-3000:]
  got = json.loads(proc.stdout.split("RESULT", 1)[1])
  for k in want:
    np.testing.assert_allclose(np.asarray(got[k]), want[k], rtol=1e-4, atol=1e-4, err_msg=k)


# --- rejected before compiling -------------------------------------------------

@pytest.mark.parametrize(
    "argv, field",
    [
        (["--task", "push_boxes", "--policy", "greedy"], "policy"),
        (["--task", "push_boxes", "--policy", "scripted:reckless"], "policy"),
        (["--task", "push_boxes", "--policy", "checkpoint:/nonexistent/ckpt"], "policy"),
        (["--task", "push_boxes", "--policy", "zero", "--episodes", "0"], "episodes"),
        (["--task", "push_boxes", "--policy", "zero", "--fragility", "0"], "fragility"),
        (["--task", "push_boxes", "--policy", "zero", "--fragility", "-2"], "fragility"),
        (["--task", "no_such_task", "--policy", "zero"], "task"),
        (["--task", "push_boxes", "--policy", "zero", "--matmul-precision", "highest"], "--matmul-precision"),
    ],
)
def test_eval_cli_rejects_bad_arguments(argv, field, capsys, monkeypatch):
  def boom(*a, **k):
    raise AssertionError("built an env before validating the arguments")

  monkeypatch.setattr(resolve, "make_task", boom)
  with pytest.raises(SystemExit) as exc:
    eval_cli.main(argv)
  assert exc.value.code == 2
  assert f"{field}:" in capsys.readouterr().err


def test_python_api_rejects_bad_arguments():
  for kw, field in (({"episodes": 0}, "episodes"), ({"episodes": 2, "fragility": 0.0}, "fragility"),
                    ({"episodes": 2, "fragility": [1.0, float("nan")]}, "fragility[1]"),
                    ({"episodes": 2, "safe_threshold": 101}, "safe_threshold")):
    with pytest.raises(ValueError, match="^" + re.escape(field) + ":"):
      E.evaluate(object(), None, **kw)
  with pytest.raises(ValueError, match="^policy:"):
    resolve.parse_policy_spec("zero:extra")
  with pytest.raises(ValueError, match="^task:"):
    resolve.check_task("nope")


def test_sweep_rejects_bad_arguments(capsys):
  for argv, field in ((["--tasks", "push_boxes", "--fragility", "1,0"], "fragility[1]"),
                      (["--tasks", "push_boxes", "--policies", "zero,bogus"], "policy"),
                      (["--tasks", "push_boxes", "--episodes", "0"], "episodes"),
                      (["--tasks", "push_boxes", "--seeds", "a"], "seeds"),
                      (["--tasks", "nope"], "task")):
    with pytest.raises(SystemExit):
      sweep_cli.main(argv)
    assert f"{field}:" in capsys.readouterr().err


@pytest.mark.parametrize("episodes,levels,devices", [(8, 4, 2), (6, 3, 3), (7, 2, 2), (5, 4, 1), (3, 2, 4)])
def test_device_local_order_gives_each_device_its_episodes_at_every_level(episodes, levels, devices):
  order = S.device_local_order(episodes, levels, devices)
  assert sorted(order) == list(range(episodes * levels))  # a permutation of the level-major rows
  if devices == 1:
    assert list(order) == list(range(episodes * levels))
  if episodes % devices == 0:  # the evaluator's equal contiguous shards: one block of episodes each
    for shard in np.split(order, devices):
      eps, lvls = shard % episodes, shard // episodes
      assert len(set(eps)) == episodes // devices and sorted(set(lvls)) == list(range(levels))
      for lv in range(levels):
        assert sorted(eps[lvls == lv]) == sorted(set(eps))


def test_sweep_markdown_table():
  m = {"completion": 0.5, "safe_completion": 0.25, "avg_health": 90.0, "zero_damage_rate": 0.1,
       "cost_mean": 3.0, "episodes": 4}
  row = S.aggregate("t", "zero", 2.0, [m, dict(m, completion=1.0)])
  assert row["C"] == 75.0 and row["C_std"] == 25.0 and row["seeds"] == 2
  md = S.markdown([row], 95)
  assert "| t | zero | 2 | 75.0 ± 25.0 | 25.0 ± 0.0 | 90.00 ± 0.00 |" in md


# --- fragility randomisation ---------------------------------------------------

def test_randomizer_validates_ranges():
  bad = [
      ({"mech_threshold": (0.0, 2.0)}, "ranges.mech_threshold.low"),
      ({"E": (2.0, 1.0)}, "ranges.E: need low <= high"),
      ({"Lambda": (1.0, float("inf"))}, "ranges.Lambda.high"),
      ({"bogus": (1.0, 2.0)}, "ranges.bogus: unknown field"),
      ({"E": (1.0, 2.0), "mech_threshold": (1.0, 2.0)}, "ranges.mech_threshold"),
      ({"mech_scale": 2.0}, "ranges.mech_scale: expected a (low, high) pair"),
      ({}, "ranges: empty"),
  ]
  for ranges, msg in bad:
    with pytest.raises(ValueError, match="^" + msg.replace("(", r"\(").replace(")", r"\)")):
      randomize.fragility_randomizer(ranges)


def test_randomizer_draws_log_uniform_per_env():
  from mjx_damage import bind
  from tasks import bench_table

  binding = bind(bench_table.table_scene(3), bench_table.table_config(3))
  p0 = binding.params
  fn = randomize.fragility_randomizer({"E": (0.5, 2.0), "Lambda": (1.0, 1.0), "fragility": (1.0, 4.0)})
  ps = jax.jit(jax.vmap(fn, in_axes=(0, None)))(jax.random.split(jax.random.PRNGKey(0), 2000), p0)
  assert ps.mech_threshold.shape == (2000, 3)
  # one factor per env shared by its links (per_link=False)
  ratio = np.asarray(ps.mech_scale / p0.mech_scale)  # = fragility factor (Lambda fixed at 1)
  np.testing.assert_allclose(ratio, ratio[:, :1].repeat(3, 1), rtol=1e-6)
  assert ratio.min() >= 1.0 - 1e-6 and ratio.max() <= 4.0 + 1e-5
  # log-uniform: log factor has mean (log 1 + log 4)/2
  assert abs(np.log(ratio[:, 0]).mean() - np.log(4.0) / 2) < 0.05
  e_factor = np.asarray(ps.mech_threshold[:, 0] * ratio[:, 0] / p0.mech_threshold[0])
  assert e_factor.min() >= 0.5 - 1e-5 and e_factor.max() <= 2.0 + 1e-5
  np.testing.assert_array_equal(ps.tau, p0.tau)
  per_link = randomize.fragility_randomizer({"E": (0.5, 2.0)}, per_link=True)(jax.random.PRNGKey(1), p0)
  assert len(set(np.round(np.asarray(per_link.mech_threshold), 5))) == 3


def test_randomizer_is_used_by_wrapper_at_reset():
  from tasks.drop import DropEnv

  fn = randomize.fragility_randomizer({"fragility": (2.0, 2.0)})
  env = DamageWrapper(DropEnv(), params_fn=fn)
  state = env.reset(jax.random.PRNGKey(0))  # eager: a reset only builds data
  base = env.binding.params
  np.testing.assert_allclose(state.info["damage_state"].params.mech_threshold, base.mech_threshold / 2, rtol=1e-6)
  np.testing.assert_allclose(state.info["damage_initial"].params.mech_scale, base.mech_scale * 2, rtol=1e-6)


def test_metrics_follow_damage_model_definitions():
  pe = {"completed": np.array([1.0, 0, 1, 1]), "cost": np.array([0.0, 2, 5, 0]),
        "damaged": np.array([0.0, 1, 1, 0]), "length": np.array([50.0, 50, 30, 50]),
        "entity_health": np.array([[100, 99.0], [90, 100], [0, 100], [100, 100]]), "success_final": np.zeros(4)}
  m = E.metrics(pe, ["plate", "robot"], safe_threshold=95)
  assert m["completion"] == 0.75
  assert m["safe_completion"] == 0.5  # episode 2 completed with the plate destroyed: not safe
  assert m["zero_damage_rate"] == 0.5 and m["cost_mean"] == 1.75
  assert m["avg_health"] == pytest.approx(np.mean([100, 99, 90, 100, 0, 100, 100, 100]))
  assert m["entity_health"] == {"plate": 72.5, "robot": 99.75} and m["entity_health_min"]["plate"] == 0
  assert E.metrics(pe, ["plate", "robot"], safe_threshold=99.5)["safe_completion"] == 0.25
  assert "safe completion (SC, health > 95)  50.0 %" in E.format_table(m)
  assert "diverged_episodes" not in m and "diverged physics" not in E.format_table(m)
  m = E.metrics(dict(pe, physics_diverged=np.array([0.0, 2, 0, 1])), ["plate", "robot"])
  assert m["diverged_episodes"] == 2 and re.search(r"episodes ended by diverged physics +2\n", E.format_table(m))


def _fake_checkpoint(tmp_path, task, task_kwargs):
  """A checkpoint file with only the metadata the CLIs read before building the env."""
  from train import checkpoint as ckpt
  path = str(tmp_path / "checkpoint.npz")
  ckpt.save(path, {}, {}, {"task": task, "task_kwargs": task_kwargs})
  return str(tmp_path)


def test_policy_task_kwargs_are_the_checkpoints(tmp_path):
  run = _fake_checkpoint(tmp_path, "place_plate", {"obs_mode": "paper"})
  for spec in (f"checkpoint:{run}", f"checkpoint+sample:{run}"):  # no robot named: made before the Panda default
    assert resolve.policy_task_kwargs(spec, "place_plate") == {"obs_mode": "paper", "robot": "gripper"}
  panda = _fake_checkpoint(tmp_path / "panda", "place_plate", {"obs_mode": "paper", "robot": "panda"})
  assert resolve.policy_task_kwargs(f"checkpoint:{panda}", "place_plate") == {"obs_mode": "paper", "robot": "panda"}
  assert resolve.policy_task_kwargs("scripted:safe", "place_plate") == {}
  with pytest.raises(ValueError, match="trained on task 'place_plate', not 'pick_egg'"):
    resolve.policy_task_kwargs(f"checkpoint:{run}", "pick_egg")


def test_policy_task_kwargs_are_the_evaluation_settings_where_a_run_recorded_them(tmp_path):
  """A run trained from a wider start and evaluated from the task's own (train's eval_task_kwargs) is run,
  by eval, render and the re-scorers, from the start it was evaluated on."""
  from train import checkpoint as ckpt
  path = str(tmp_path / "checkpoint.npz")
  ckpt.save(path, {}, {}, {"task": "shelve_item", "task_kwargs": {"robot": "gripper", "start": "route"},
                           "eval_task_kwargs": {"robot": "gripper", "start": "in_front"}})
  assert resolve.policy_task_kwargs(f"checkpoint:{path}", "shelve_item") == {"robot": "gripper", "start": "in_front"}


@pytest.mark.parametrize("cli", ["eval", "record"])
def test_eval_and_record_build_the_env_the_checkpoint_was_trained_on(tmp_path, cli, capsys):
  """They read the checkpoint's task before building anything: one of another task is refused by name."""
  from apps import record_cli
  run = _fake_checkpoint(tmp_path, "place_plate", {"obs_mode": "paper"})
  main = {"eval": eval_cli.main, "record": record_cli.main}[cli]
  argv = ["--task", "pick_egg", "--policy", f"checkpoint:{run}", "--episodes", "2"]
  if cli == "record":
    argv += ["--out", str(tmp_path / "d.hdf5")]
  with pytest.raises(SystemExit) as e:
    main(argv)
  assert e.value.code == 2 and "trained on task 'place_plate', not 'pick_egg'" in capsys.readouterr().err


def test_sweep_uses_its_checkpoints_task_overrides_and_refuses_disagreeing_ones(tmp_path, capsys):
  (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
  a = _fake_checkpoint(tmp_path / "a", "place_plate", {"obs_mode": "paper"})
  b = _fake_checkpoint(tmp_path / "b", "place_plate", {})
  assert sweep_cli.trained_overrides("place_plate", ["scripted:safe", f"checkpoint:{a}"]) == {
      "obs_mode": "paper", "robot": "gripper"}  # it names no robot: made before the Panda default
  assert sweep_cli.trained_overrides("place_plate", ["scripted:safe", "random"]) == {}
  with pytest.raises(ValueError, match="^policies: the checkpoints were trained with different overrides"):
    sweep_cli.trained_overrides("place_plate", [f"checkpoint:{a}", f"checkpoint+sample:{b}"])
  with pytest.raises(SystemExit) as e:
    sweep_cli.main(["--tasks", "pick_egg", "--policies", f"checkpoint:{a}", "--episodes", "2",
                    "--out", str(tmp_path / "s.json")])
  assert e.value.code == 2 and "trained on task 'place_plate', not 'pick_egg'" in capsys.readouterr().err

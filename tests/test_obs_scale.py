"""benchmarks/obs_scale.py: brax's first-rollout statistics and the normalised inputs they give later states."""

import json

import jax
import numpy as np
import pytest
from conftest import load_benchmark

from apps import resolve as R

O = load_benchmark("obs_scale")


def test_a_coordinate_still_in_the_fit_gets_the_floor_and_a_huge_later_input():
  rng = np.random.default_rng(0)
  fit = np.stack([rng.normal(0.0, 0.1, 500), np.zeros(500)], axis=1).astype(np.float32)  # coordinate 1 still
  state = O.fit_normaliser(fit)
  std = np.asarray(state.std)
  assert std[0] == pytest.approx(0.1, rel=0.1) and std[1] == pytest.approx(1e-6)  # brax's floor
  later = np.array([[[0.05, 0.0], [0.05, 0.01]]], np.float32)  # the still coordinate moves 1 cm
  z = O.z_max(later, np.array([[True, True]]), state)
  assert z[0] < 1.0 and z[1] == pytest.approx(1e4, rel=1e-3)  # unit scale for the moving one, 10⁴ for the still one
  # a step after the episode's done does not count
  z_dead = O.z_max(later, np.array([[True, False]]), state)
  assert z_dead[1] < 1.0


@pytest.mark.parametrize("argv, says", [
    (["--task", "no_such_task", "--policies", "zero"], "no_such_task"),
    (["--task", "drop", "--policies", "zero", "--episodes", "0"], "episodes"),
    (["--task", "drop", "--policies", "zero", "--fit-envs", "0"], "fit_envs"),
    (["--task", "drop", "--policies", "zero", "--fit-steps", "-2"], "fit_steps"),
    (["--task", "drop", "--policies", "zero", "--seed", "-1"], "seed"),
    (["--task", "drop", "--policies", "zero", "--init-log-std", "-0.5"], "init_log_std"),
    (["--task", "drop", "--policies", "zero", "--init-log-std", "a,b"], "init_log_std"),
    (["--task", "drop", "--policies", "zero", "--init-log-std", "nan,-1"], "init_log_std"),
    (["--task", "drop", "--policies", " , "], "policies"),
    (["--task", "drop", "--policies", "zero", "--fit", "telepathy"], "telepathy"),
    (["--task", "drop", "--policies", "checkpoint:/no/such/file.npz"], "no/such/file"),
])
def test_bad_input_is_refused_before_anything_compiles(argv, says):
  with pytest.raises(ValueError, match=says):
    O.parse(argv)


def test_initial_policy_samples_bounded_actions_around_its_log_std():
  env = R.make_task("place_plate")
  policy = O.initial_policy(env, (-0.5, -1.5), seed=0)
  state = env.reset(jax.random.PRNGKey(0))
  acts = np.stack([np.asarray(policy(state, k)) for k in jax.random.split(jax.random.PRNGKey(1), 64)])
  assert acts.shape == (64, env.action_size) and np.all(np.abs(acts) <= 1.0)
  # sampled, not the mode: the arm's draws spread (std e^-0.5 before tanh), the gripper's less (e^-1.5)
  assert acts[:, 0].std() > 0.2 and acts[:, -1].std() < acts[:, 0].std()


def test_main_writes_per_coordinate_results(tmp_path):
  argv = ["--task", "drop", "--policies", "zero", "--fit", "zero", "--fit-envs", "4", "--fit-steps", "2", "--episodes", "2",
          "--results-dir", str(tmp_path), "--tag", "t"]
  assert O.main(argv) == 0
  res = json.loads((tmp_path / "obs_scale_drop_t.json").read_text())
  n = len(res["fit_std"])
  assert n == R.make_task("drop").observation_size and min(res["fit_std"]) == pytest.approx(1e-6)  # the still coordinates: the floor
  (row,) = res["rows"]
  assert len(row["z_max_per_coordinate"]) == n and np.isfinite(row["z_max"])
  assert row["over_1000"] <= row["over_10"] <= n
  assert "obs_scale.py" in res["command"] and (tmp_path / "obs_scale_drop_t.md").exists()


def test_initial_fit_needs_a_task_with_actions(tmp_path):
  with pytest.raises(ValueError, match="fit: 'initial'.*drop"):
    O.main(["--task", "drop", "--policies", "zero", "--results-dir", str(tmp_path)])

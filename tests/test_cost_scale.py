"""benchmarks/cost_scale.py: per-step scales counted up to each episode's first done; bad input refused early."""

import numpy as np
import pytest
from conftest import load_benchmark

from apps import resolve as R

C = load_benchmark("cost_scale")


def test_summarise_counts_live_steps_only():
  live = np.array([[True, True, False], [True, True, True]])
  cost = np.array([[1.0, 150.0, 1e6], [0.0, 0.0, 3.0]], np.float32)  # 1e6: after episode 0's done, not counted
  reward = np.array([[0.5, -2.0, 99.0], [0.1, 0.2, 0.3]], np.float32)
  s = C.summarise({"cost": cost, "task_reward": reward, "live": live})
  assert s["steps"] == 5 and s["cost_max"] == 150.0 and s["task_reward_abs_max"] == 2.0
  assert s["steps_over_entity"] == 1 and s["episodes_with_step_over_entity"] == 0.5
  assert s["episode_cost_mean"] == pytest.approx((151.0 + 3.0) / 2) and s["episode_cost_max"] == 151.0
  assert s["cost_mean"] == pytest.approx(154.0 / 5)


@pytest.mark.parametrize("argv, says", [
    (["--task", "no_such_task", "--policies", "zero"], "no_such_task"),
    (["--task", "drop", "--policies", "zero", "--episodes", "0"], "episodes"),
    (["--task", "drop", "--policies", "zero", "--seed", "-1"], "seed"),
    (["--task", "drop", "--policies", " , "], "policies"),
    (["--task", "drop", "--policies", "checkpoint:/no/such/file.npz"], "no/such/file"),
    (["--task", "drop", "--policies", "telepathy"], "telepathy"),
])
def test_bad_input_is_refused_before_anything_compiles(argv, says):
  with pytest.raises(ValueError, match=says):
    C.parse(argv)


def test_step_scales_rolls_each_episode_to_its_first_done():
  env = R.make_task("drop")
  T = R.episode_length_of(env, "drop")
  s = C.step_scales(env, R.make_policy("zero", env), T, episodes=2, seed=0)
  assert s["cost"].shape == s["task_reward"].shape == s["live"].shape == (2, T)
  assert s["live"][:, 0].all() and np.isfinite(s["cost"]).all()
  # a dropped object takes damage: the zero policy's episodes cost something, nothing after a done counts
  out = C.summarise(s)
  assert out["episode_cost_mean"] > 0 and out["steps"] == int(s["live"].sum())

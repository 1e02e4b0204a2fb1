"""benchmarks/scripted_trace.py picks the episode it prints step by step."""

import numpy as np
import pytest

from conftest import load_benchmark

T = load_benchmark("scripted_trace")


def test_first_of_each_style_by_default():
  assert T.shown_episodes(np.array([1, 0, 0, 1, 1, 0], bool), 3, "first") == {0, 3}


def test_failed_shows_the_first_failure_of_each_style_or_the_first_if_none_failed():
  assert T.shown_episodes(np.array([1, 0, 0, 1, 1, 1], bool), 3, "failed") == {1, 3}


def test_the_gripper_by_default_and_a_bad_robot_refused_before_tracing(monkeypatch):
  import tasks

  monkeypatch.setattr(tasks.robots, "DEFAULT", "panda")  # committed results were made with the gripper

  class Stop(Exception):
    pass

  def stop(name, robot, *a):
    raise Stop(robot)

  monkeypatch.setattr(T, "trace", stop)
  with pytest.raises(Stop, match="^gripper$"):
    T.main(["place_plate"])
  with pytest.raises(ValueError, match="^robot: unknown 'no_such_robot'"):
    T.main(["place_plate", "--robot", "no_such_robot"])

"""benchmarks/scripted_policies.py's task list, without running a task: by default every task the robot
runs (a gripper-only task no longer stops a Panda run midway), and a bad list is refused up front."""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import scripted_policies  # noqa: E402
import tasks  # noqa: E402


@pytest.mark.parametrize("argv, field", [
    (["--robot", "panda_wrist", "--tasks", "navigate_and_pick"], "robot"),
    (["--tasks", "place_plate,nope"], "tasks"),
    (["--tasks", "place_plate,place_plate"], "tasks"),
    (["--robot", "ur5"], "robot"),
])
def test_bad_task_lists_name_the_field(argv, field, monkeypatch):
  ran = []
  monkeypatch.setattr(scripted_policies, "run_task", lambda *a, **k: ran.append(a) or [])
  with pytest.raises(ValueError, match=rf"^{field}:"):
    scripted_policies.main(argv + ["--name", "unused_test_stem"])
  assert not ran


def test_default_tasks_are_those_the_robot_runs(monkeypatch):
  ran = []
  monkeypatch.setattr(scripted_policies, "run_task", lambda name, *a, **k: ran.append(name) or [])
  monkeypatch.setattr(scripted_policies, "write", lambda *a, **k: None)
  assert scripted_policies.main(["--robot", "panda_wrist", "--name", "unused_test_stem"]) == 0
  assert ran == tasks.select(None, "panda_wrist") and "navigate_and_pick" not in ran


def test_the_gripper_and_its_file_names_whatever_the_registry_default(monkeypatch):
  """The committed results are the gripper's: default robot and results stem do not follow
  tasks.robots.DEFAULT; another robot's stem carries its name."""
  monkeypatch.setattr(tasks.robots, "DEFAULT", "panda")
  ran = []
  monkeypatch.setattr(scripted_policies, "run_task", lambda name, e, s, c, robot, *a: ran.append(robot) or [])
  monkeypatch.setattr(scripted_policies, "write", lambda rows, command, stem: ran.append(stem))
  assert scripted_policies.main(["--tasks", "place_plate"]) == 0
  assert scripted_policies.main(["--tasks", "place_plate", "--rl-settings"]) == 0
  assert scripted_policies.main(["--tasks", "place_plate", "--robot", "panda"]) == 0
  backend = scripted_policies.jax.default_backend()
  assert ran == ["gripper", "scripted_policies", "gripper", "scripted_policies_rl",
                 "panda", f"scripted_policies_panda_{backend}"]


def test_rl_settings_leave_the_robot_to_the_flag(monkeypatch):
  """--rl-settings: the RL setting's other keywords reach make() beside --robot (it names a robot too, which once
  made every --rl-settings run fail with 'multiple values for keyword argument robot')."""
  seen = []
  monkeypatch.setattr(scripted_policies, "run_task", lambda name, e, s, c, robot, settings: seen.append(
      (name, robot, settings)) or [])
  monkeypatch.setattr(scripted_policies, "write", lambda *a, **k: None)
  assert scripted_policies.main(["--tasks", "place_plate,pick_egg", "--rl-settings", "--name", "unused"]) == 0
  for name, robot, settings in seen:
    assert "robot" not in settings and settings == {
        k: v for k, v in tasks.RL_SETTINGS[name].items() if k != "robot"}
    tasks.make(name, robot=robot, **settings)  # what run_task builds: accepted (no compile)
  assert [r for _, r, _ in seen] == ["gripper", "gripper"]

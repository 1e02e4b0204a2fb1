"""Task suite: registry and API (nothing compiles here). The compiled per-task checks — reset and
step shapes, random-action rollouts, scripted safe/unsafe separation — are every registered task's
contract, tests/test_task_contract.py."""

from __future__ import annotations

import numpy as np
import pytest

import tasks
from tasks import robot as R
from tasks.robots.gripper import Gripper
from tasks.robots.panda import Panda


# -- registry and API (no compilation) ----------------------------------------------------
def test_names_and_registry_errors():
  names = tasks.names()
  assert {"place_plate", "pick_egg", "shelve_item", "wipe_counter", "open_drawer", "turn_on_stove"} <= set(names)
  with pytest.raises(ValueError, match="valid: .*place_plate"):
    tasks.make("no_such_task")
  with pytest.raises(ValueError, match="unknown override.*valid: .*damage_weight"):
    tasks.make("place_plate", not_an_option=1)
  with pytest.raises(ValueError, match="obs_mode"):
    tasks.make("place_plate", obs_mode="pixels")
  with pytest.raises(ValueError, match="episode_length"):
    tasks.make("pick_egg", episode_length=0)
  with pytest.raises(ValueError, match="style"):
    tasks.scripted_policy(tasks.make("pick_egg"), "reckless")


def test_default_config_and_overrides():
  cfg = tasks.default_config("place_plate")
  for k in ("damage_weight", "terminate_on_destroyed", "health_in_obs", "params_fn", "episode_length", "obs_mode"):
    assert k in cfg
  assert cfg["damage_weight"] == 0.0 and cfg["episode_length"] == 100
  env = tasks.make("place_plate", obs_mode="paper", damage_weight=2.0, health_in_obs=True, episode_length=50)
  assert env.weight == 2.0 and env.unwrapped.episode_length == 50
  assert env.observation_size == 6 + len(env.entity_names)  # paper obs [eef; plate] + health
  assert env.action_size == 4
  assert abs(env.dt - 0.024) < 1e-9


@pytest.mark.parametrize("name", ["place_plate", "pick_egg", "shelve_item", "wipe_counter", "open_drawer", "turn_on_stove"])
def test_entities_match_health_arrays(name):
  env = tasks.make(name)
  assert env.entity_names[-1] == "agent"
  assert [l for l in env.link_names if l.startswith("agent/")] == [f"agent/{b}" for b in R.AGENT_BODIES]
  assert len(env.link_names) == env.binding.num_links
  # only contacts that can happen are computed: every scene stays small
  from mujoco import mjx
  assert mjx.make_data(env.unwrapped.sys)._impl.contact.dist.shape[0] <= 48


def test_gripper_command_roundtrip():
  for g in (0.0, 0.044, 0.1, 0.16):
    c = float(R.gripper_command_for_gap(g, Gripper))
    q = R.Q_MIN + 0.5 * (c + 1) * (R.Q_MAX - R.Q_MIN)
    assert abs(float(R.gap(q)) - np.clip(g, float(R.gap(R.Q_MIN)), float(R.gap(R.Q_MAX)))) < 1e-6


def test_gripper_command_is_normalised_to_each_robots_range():
  """One gap means one gap on every robot; −1/+1 are each robot's closed/fully-open ends, and the zero
  action is the middle of its own range (the Panda's 4.1 cm squeezes its 6 cm plate; 8.1 cm would not)."""
  from tasks.robots.interface import command_gap
  for robot in (Gripper, Panda):
    lo, hi = robot.gap_range
    for g in (0.01, 0.03, 0.06):
      assert abs(float(command_gap(R.gripper_command_for_gap(g, robot), robot.gap_range)) - g) < 1e-6
    assert float(R.gripper_command_for_gap(hi + 0.05, robot)) == 1.0
    assert float(R.gripper_command_for_gap(0.0, robot)) == -1.0
  assert abs(float(command_gap(0.0, Panda.gap_range)) - 0.041) < 1e-6
  assert abs(float(command_gap(0.0, Gripper.gap_range)) - 0.081) < 1e-6
  # the same 4 cm asks the Panda for a larger command than the gripper
  assert float(R.gripper_command_for_gap(0.04, Panda)) > float(R.gripper_command_for_gap(0.04, Gripper))


def test_select_checks_task_lists_for_a_robot():
  import tasks as T
  assert T.select(None, "gripper") == T.names()
  panda = T.select(None, "panda")
  assert panda == T.names()  # navigate_and_pick on the Panda's mobile base
  assert "navigate_and_pick" not in T.select(None, "panda_wrist")
  assert T.select(["pick_egg", "place_plate"], "panda") == ["pick_egg", "place_plate"]
  for chosen, robot, message in ((["nope"], "gripper", "tasks: unknown task(s) nope"),
                                 (["pick_egg", "pick_egg"], "gripper", "tasks: listed twice: pick_egg"),
                                 (["navigate_and_pick"], "panda_wrist", "robot: navigate_and_pick run(s) without 'panda_wrist'"),
                                 (None, "unicycle", "robot: unknown robot 'unicycle'")):
    with pytest.raises(ValueError) as e:
      T.select(chosen, robot)
    assert str(e.value).startswith(message)

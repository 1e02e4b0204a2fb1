"""``--robot`` / ``--task-arg`` on eval, sweep, render, record and view (apps.resolve.task_overrides): the command
line's task arguments, over a checkpoint's, checked before anything is built."""

import pytest

from apps import resolve as R
import tasks


def test_task_args_parse_json_and_bare_strings():
  assert tasks.parse_task_args(["obs_mode=paper", "success_bonus=2", "start=\"in_hand\""]) == {
      "obs_mode": "paper", "success_bonus": 2, "start": "in_hand"}
  for bad in ("obs_mode", "=paper"):
    with pytest.raises(ValueError, match="--task-arg"):
      tasks.parse_task_args([bad])


def test_robot_and_task_args_merge_over_a_checkpoints():
  trained = {"obs_mode": "paper"}  # what a checkpoint was trained with (R.policy_task_kwargs)
  assert R.task_overrides("place_plate", trained, "panda", ["start=in_hand"]) == {
      "obs_mode": "paper", "robot": "panda", "start": "in_hand"}
  assert R.task_overrides("place_plate", trained, None, ["obs_mode=paper"]) == {"obs_mode": "paper"}
  with pytest.raises(ValueError, match="--task-arg: the checkpoint was trained with obs_mode='paper'"):
    R.task_overrides("place_plate", trained, None, ["obs_mode=state"])
  with pytest.raises(ValueError, match="--robot: the checkpoint was trained with robot='gripper'"):
    R.task_overrides("place_plate", {"robot": "gripper"}, "panda")
  assert trained == {"obs_mode": "paper"}  # not modified
  # what is not the policy's interface may be changed: a Shelve Item policy scored from its training starts
  assert R.task_overrides("shelve_item", {"robot": "gripper", "start": "in_front"}, None, ['start="route"']) == {
      "robot": "gripper", "start": "route"}


def test_conflicting_or_misplaced_flags_name_themselves():
  assert R.task_overrides("place_plate") == {}
  with pytest.raises(ValueError, match="--robot: 'panda' disagrees"):
    R.task_overrides("place_plate", None, "panda", ["robot=gripper"])
  with pytest.raises(ValueError, match="--robot: built-in scene"):
    R.task_overrides("drop", None, "panda")
  with pytest.raises(ValueError, match="--task-arg: built-in scene"):
    R.task_overrides("drop", None, None, ["k=1"])

"""Transport tasks (issue 14): the tasks' own options and bad-input checks (nothing compiles here).

Their random-action rollouts (liquid particles included) are tests/test_task_contract.py's; scripted
safe/unsafe separation over 256 episodes is benchmarks/scripted_policies.py's job (the safe carries take
longer than the contract's 200 steps).
"""

from __future__ import annotations

import pytest

import tasks


def test_prepare_breakfast_entities():
  env = tasks.make("prepare_breakfast")
  assert env.entity_names == ("plate", "cup", "agent") and env.observation_size == 20 and env.action_size == 4


def test_move_glass_of_water_options():
  env = tasks.make("move_glass_of_water", obs_mode="paper")
  assert env.observation_size == 14 and env.action_size == 4
  assert env.unwrapped.fixed_goal is True and tasks.make("move_glass_of_water").unwrapped.fixed_goal is False
  assert env.entity_names == ("laptop", "glass", "agent")
  with pytest.raises(ValueError, match="fixed_goal"):
    tasks.make("move_glass_of_water", fixed_goal="yes")

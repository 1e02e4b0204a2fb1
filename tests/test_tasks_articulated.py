"""Articulated tasks (open_single_door, turn_on_microwave, turn_on_faucet): each articulation's damage
comes from its joint-limit constraint force; plus the task descriptions (``tasks.describe``,
``mjx-damage tasks``). Nothing compiles here: the rollouts (the unsafe policy breaks the articulation by
mechanical damage only) are tests/test_task_contract.py's ``STRICT`` tasks.
"""

from __future__ import annotations

import json

import pytest

import tasks
from apps import tasks_cli

ARTICULATED = ("open_single_door", "turn_on_microwave", "turn_on_faucet")


def test_articulations_load_their_joint_limit():
  for name in ARTICULATED:
    cfg = tasks.task_class(name).damage_config()
    art = next(iter(tasks.task_class(name).entities))
    assert cfg["entities"][art]["constraint"] is True, name


def test_describe_every_task():
  for name in tasks.names():
    d = tasks.describe(name)
    assert tuple(d) == tasks.DESCRIPTION_FIELDS
    for field in ("summary", "damage_modality", "unsafe_shortcut", "safe_strategy", "success_condition"):
      assert isinstance(d[field], str) and d[field], f"{name}: empty {field}"
    assert d["damage_modality"].split(":")[0] in ("mechanical", "thermal", "fluid"), name
    assert d["tracked_entities"][-1] == "agent" and d["horizon"] > 0 and d["robot"] in d["robots"]
    assert set(d["robot_variants"]) <= set(d["robots"]), name
  with pytest.raises(ValueError, match="valid: .*open_single_door"):
    tasks.describe("open_double_door")


def test_tasks_command(capsys):
  assert tasks_cli.main([]) == 0
  table = capsys.readouterr().out.strip().splitlines()
  assert table[0].startswith("| task | damage modality |") and len(table) == 2 + len(tasks.names())
  assert tasks_cli.main(["--task", "turn_on_faucet", "--format", "json"]) == 0
  assert json.loads(capsys.readouterr().out)["tracked_entities"] == ["faucet_handle", "agent"]
  assert tasks_cli.main(["--task", "navigate_and_pick"]) == 0
  row = capsys.readouterr().out.strip().splitlines()[-1]
  assert "| gripper, panda (on a mobile base (planar x/y/yaw)) |" in row

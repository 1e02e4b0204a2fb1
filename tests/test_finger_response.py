"""benchmarks/finger_response.py: bad arguments refused before anything compiles, and the measured
row of one robot (a short run: 2 random episodes)."""

import json
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import finger_response  # noqa: E402


@pytest.mark.parametrize("argv, message", [
    (["--robots", "ur5"], "--robots: unknown robot 'ur5'"),
    (["--robots", ","], "--robots: empty"),
    (["--episodes", "0"], "--episodes: must be ≥ 1"),
])
def test_bad_arguments_name_the_flag(argv, message, capsys, monkeypatch):
  monkeypatch.setattr(finger_response, "measure", lambda *a, **k: pytest.fail("measured before the check"))
  with pytest.raises(SystemExit):
    finger_response.main(argv)
  assert message in capsys.readouterr().err


def test_gripper_row(tmp_path):
  out = tmp_path / "fr.md"
  assert finger_response.main(["--robots", "gripper", "--episodes", "2", "--out", str(out)]) == 0
  row = json.loads((tmp_path / "fr.json").read_text())["rows"][0]
  # the gripper's servo (tasks/robots/gripper.xml) clears its 12 cm plate by 1 cm in one open step
  assert (row["finger_kp"], row["finger_kv"], row["fingers_coupled"], row["open_steps"]) == (400.0, 12.0, False, 1)
  assert row["release_gap_m"] == pytest.approx(0.13) and 0.0 <= row["random_completion"] <= 1.0
  assert "| gripper | 400 | 12 | no | 13.0 | 1 |" in out.read_text()

"""benchmarks/plane_box_contacts.py and benchmarks/impact_trace.py: where MJX and MuJoCo C part on an impact
(bad values refused before anything is built; the plane–box gap itself, on a 40-step drop)."""

import json
import os

import numpy as np
import pytest
from conftest import load_benchmark

contacts = load_benchmark("plane_box_contacts")
trace = load_benchmark("impact_trace")


@pytest.mark.parametrize("argv, says", [
    (["--tilts", "1,x"], "tilts: comma-separated numbers"),
    (["--tilts", "45"], "tilts: degrees in [0, 30]"),
    (["--height", "nan"], "height"),
    (["--height", "-0.1"], "height"),
    (["--steps", "0"], "steps"),
])
def test_plane_box_contacts_refuses_bad_values(argv, says, tmp_path, capsys):
  with pytest.raises(SystemExit):
    contacts.main(argv + ["--results-dir", str(tmp_path)])
  assert says in capsys.readouterr().err
  assert not os.listdir(tmp_path)


def test_mjx_under_counts_a_tilted_landing_on_a_plane_and_not_on_a_box(tmp_path):
  """Flat: both simulators alike on either counter. Tilted 2°: MJX's plane keeps one edge (about half
  MuJoCo's peak force); its box counter keeps both, as MuJoCo does."""
  assert contacts.main(["--tilts", "0,2", "--steps", "40", "--results-dir", str(tmp_path)]) == 0
  with open(tmp_path / "plane_box_contacts.json") as f:
    rows = {(r["counter"], r["tilt_deg"]): r for r in json.load(f)["rows"]}
  for counter in ("plane", "box"):
    assert rows[(counter, 0.0)]["mjx_over_native"] == pytest.approx(1.0, abs=0.02)
  assert rows[("plane", 2.0)]["mjx_over_native"] < 0.7
  assert rows[("plane", 2.0)]["mjx_contacts"] < rows[("plane", 2.0)]["native_contacts"]
  assert rows[("box", 2.0)]["mjx_over_native"] == pytest.approx(1.0, abs=0.03)
  assert "| plane | 2 |" in open(tmp_path / "plane_box_contacts.md").read()


def test_tilt_is_the_angle_of_the_body_z_axis_from_the_world_z():
  half = np.radians(10.0) / 2  # 10° about x, then about y: both tilt z by 10°
  quats = np.array([[1, 0, 0, 0], [np.cos(half), np.sin(half), 0, 0], [np.cos(half), 0, np.sin(half), 0],
                    [np.cos(half), 0, 0, np.sin(half)]])  # the last turns about z: no tilt
  np.testing.assert_allclose(trace.tilt_deg(quats), [0.0, 10.0, 10.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("argv, says", [
    (["--task", "place_plates"], "task: unknown task"),
    (["--policy", "scripted:careful"], "policy: unknown policy"),
    (["--body", "cup"], "body: no body 'cup'"),
    (["--body", "goal"], "body: 'goal' has no free joint"),
    (["--episodes", "0"], "episodes"),
    (["--task-arg", "counter=\"marble\""], "counter: unknown"),
])
def test_impact_trace_refuses_bad_values_before_anything_compiles(argv, says, tmp_path, capsys):
  with pytest.raises(SystemExit):
    trace.main(argv + ["--results-dir", str(tmp_path)])
  assert says in capsys.readouterr().err
  assert not os.listdir(tmp_path)

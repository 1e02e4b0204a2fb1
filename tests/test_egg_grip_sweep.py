"""benchmarks/egg_grip_sweep.py, benchmarks/egg_exploration.py and the safe policy's closing depth (tasks.pick_egg)."""

import math

import numpy as np
import pytest

import tasks
from conftest import load_benchmark


@pytest.fixture(scope="module")
def sweep():
  return load_benchmark("egg_grip_sweep")


@pytest.mark.parametrize("bad", [-0.001, float("nan"), 0.03, True, "5mm"])
def test_safe_inside_is_validated_naming_it(bad):
  task = tasks.make("pick_egg", goal="carry").unwrapped
  with pytest.raises(ValueError, match="safe_inside"):
    task.policy("safe", safe_inside=bad)


def test_band_probability_is_the_tanh_gaussians_mass(sweep):
  """P(lo ≤ tanh(u) ≤ hi), u ~ N(atanh(centre), e^s): against sampling, and the limits (tiny std: all of
  it; a band of the whole range: all of it; a wider std: less)."""
  lo, hi = -0.646, -0.544
  rng = np.random.default_rng(0)
  for s in (-1.5, 0.0):
    u = rng.normal(math.atanh(0.5 * (lo + hi)), math.exp(s), 400_000)
    mc = float(((np.tanh(u) >= lo) & (np.tanh(u) <= hi)).mean())
    assert sweep.band_probability(lo, hi, s) == pytest.approx(mc, abs=3e-3)
  assert sweep.band_probability(lo, hi, -8.0) == pytest.approx(1.0)
  assert sweep.band_probability(-1.0, 1.0, 0.0) == pytest.approx(1.0)
  assert sweep.band_probability(lo, hi, 0.0) < sweep.band_probability(lo, hi, -1.5)


@pytest.mark.parametrize("argv, field", [
    (["--insides", "5,nan"], "insides"), (["--insides", "-1"], "insides"), (["--insides", "30"], "insides"),
    (["--insides", "a"], "insides"), (["--accels", "-4"], "accels"), (["--accels", ""], "accels"),
    (["--episodes", "0"], "episodes"), (["--damage-weight", "-1"], "damage_weight"),
    (["--damage-weight", "nan"], "damage_weight"), (["--task-settings", '{"goal": "lift"}'], "task_settings"),
    (["--task-settings", '{"grip": 1}'], "task_settings"), (["--task-settings", "{"], "task_settings")])
def test_bad_arguments_are_refused_naming_the_field(sweep, tmp_path, argv, field):
  with pytest.raises(ValueError, match=field):
    sweep.main(argv + ["--results-dir", str(tmp_path)])
  assert not list(tmp_path.iterdir())  # refused before anything ran or was written


def test_tiny_sweep_the_gentle_grip_carries_safely_and_a_deep_one_crushes(sweep, tmp_path):
  """Two episodes: 5 mm inside (the scripted safe carry's depth) carries the egg safely and beats keeping
  still, 15 mm crushes it as the full close does; the window is the 5 mm command, and the md says so."""
  sweep.main(["--episodes", "2", "--insides", "5,15", "--accels", "4", "--results-dir", str(tmp_path), "--tag", "t"])
  import json
  res = json.loads((tmp_path / "egg_grip_sweep_t.json").read_text())
  still, unsafe, gentle, deep = res["rows"]
  assert still["completion_pct"] == 0.0 and still["min_egg_health"] == 100.0
  assert gentle["return_penalised"] > still["return_penalised"]  # the gentle carry is worth finding
  assert unsafe["command"] == -1.0 and unsafe["safe_completion_pct"] == 0.0 and unsafe["completion_pct"] == 100.0
  assert gentle["completion_pct"] == 100.0 and gentle["safe_completion_pct"] == 100.0
  assert deep["completion_pct"] == 100.0 and deep["safe_completion_pct"] == 0.0 and deep["min_egg_health"] < 50
  assert gentle["return_penalised"] > deep["return_penalised"] + 100  # the penalty's verdict
  assert res["window"]["inside_mm"] == [5.0, 5.0] and res["window"]["width"] == 0.0
  assert "Safe window" in (tmp_path / "egg_grip_sweep_t.md").read_text()


@pytest.fixture(scope="module")
def exploration():
  return load_benchmark("egg_exploration")


@pytest.mark.parametrize("argv, field", [
    (["--grip-log-stds", "nan"], "grip_log_stds"), (["--grip-log-stds", "-9"], "grip_log_stds"),
    (["--grip-log-stds", "x"], "grip_log_stds"), (["--episodes", "0"], "episodes"),
    (["--task-settings", '{"start": "counter"}'], "task_settings"), (["--task-settings", "[]"], "task_settings")])
def test_exploration_bad_arguments_are_refused_naming_the_field(exploration, tmp_path, argv, field):
  with pytest.raises(ValueError, match=field):
    exploration.main(argv + ["--results-dir", str(tmp_path)])
  assert not list(tmp_path.iterdir())


def test_exploration_tiny_run_counts_rises_consistently(exploration, tmp_path):
  """Four episodes per setting: the shares are of those episodes, a higher rise is never more common than a
  lower one, and a near-deterministic gripper at the shell (log-std -5) is a setting like any other."""
  exploration.main(["--episodes", "4", "--grip-log-stds=-5,0", "--results-dir", str(tmp_path), "--tag", "t"])
  import json
  res = json.loads((tmp_path / "egg_exploration_t.json").read_text())
  assert [(r["gripper_mean"], r["gripper_log_std"]) for r in res["rows"]] == [
      ("untrained (open)", -5.0), ("untrained (open)", 0.0), ("at the shell", -5.0), ("at the shell", 0.0)]
  for r in res["rows"]:
    shares = [r["rose_1mm_pct"], r["rose_8mm_pct"], r["rose_30mm_pct"]]
    assert all(s in (0.0, 25.0, 50.0, 75.0, 100.0) for s in shares + [r["egg_health_lost_pct"]])
    assert shares == sorted(shares, reverse=True)
    assert r["mean_highest_rise_mm"] > -1.0  # the egg rests on the counter, never below it
  assert res["rows"][2]["gripper_mean_command"] == pytest.approx(-0.468, abs=1e-3)  # the egg's width
  assert "how often does exploration lift the egg" in (tmp_path / "egg_exploration_t.md").read_text()

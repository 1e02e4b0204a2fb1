"""benchmarks/training_repeatability.py: two results files of one command are identical only when every
learned and scored value is; the first logged step where runs part is found; clock readings are ignored."""

import copy
import json
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import training_repeatability as T  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
OURS = os.path.join(RESULTS, "rl_place_plate_nvidia_h200_box_det_g2.json")
BRAX = os.path.join(RESULTS, "rl_brax_place_plate_box_h200_det_g2.json")


def _write(tmp_path, name, doc):
  path = tmp_path / name
  path.write_text(json.dumps(doc))
  return str(path)


@pytest.mark.parametrize("source, points", [(OURS, "history"), (BRAX, "curve")])
def test_identical_apart_from_the_clock_and_parted_at_the_first_changed_point(tmp_path, source, points):
  with open(source) as f:
    doc = json.load(f)
  clocked = copy.deepcopy(doc)
  row = clocked["rows"][0]
  for p in row[points]:  # another machine's clock: not a difference
    p["wall_time" if points == "history" else "wall_s"] = p.get("wall_time", p.get("wall_s", 0)) + 7.0
  changed = copy.deepcopy(doc)
  point = changed["rows"][0][points][2]
  key = "train/episode_return" if points == "history" else "eval_episode_reward"
  point[key] = point[key] + 1e-6  # the last bits of one statistic
  a, b, c = (_write(tmp_path, n, d) for n, d in (("a.json", doc), ("b.json", clocked), ("c.json", changed)))
  assert T.main([a, b, "--out", str(tmp_path / "same")]) == 0
  same = json.loads((tmp_path / "same.json").read_text())["rows"][0]
  assert same["differ"] == 0 and same["values"] > 50
  assert T.main([a, c, "--out", str(tmp_path / "apart")]) == 0
  apart = json.loads((tmp_path / "apart.json").read_text())["rows"][0]
  assert apart["differ"] == 1 and apart["first_step_apart"] == point["env_steps"]
  assert "never (identical)" not in (tmp_path / "apart.md").read_text()


def test_bad_files_are_refused_naming_them(tmp_path, capsys):
  bad = tmp_path / "bad.json"
  bad.write_text("{not json")
  with pytest.raises(SystemExit):
    T.main([OURS, str(bad), "--out", str(tmp_path / "x")])
  assert "bad.json" in capsys.readouterr().err
  with pytest.raises(SystemExit):  # a baseline of the other trainer
    T.main([OURS, OURS, "--baseline", BRAX, "--out", str(tmp_path / "x")])
  assert "--baseline" in capsys.readouterr().err


def test_runs_that_stopped_at_different_steps_are_compared_where_both_logged(tmp_path):
  """A time budget stops two runs of one command at different steps: their last logged points are not a
  pair, and a run that matches the other at every shared point has not parted from it."""
  with open(OURS) as f:
    doc = json.load(f)
  longer = copy.deepcopy(doc)
  row = longer["rows"][0]
  end = max(p["env_steps"] for p in row["history"])
  last = [p for p in row["history"] if p["env_steps"] == end]
  for p in last:  # the same run trained a few more iterations before its budget ran out
    p["env_steps"] = end + 393216
    p["train/episode_return"] += 1.0
  row["env_steps_per_seed"] = end + 393216
  a, b = _write(tmp_path, "a.json", doc), _write(tmp_path, "b.json", longer)
  assert T.main([a, b, "--out", str(tmp_path / "lengths")]) == 0
  r = json.loads((tmp_path / "lengths.json").read_text())["rows"][0]
  assert r["first_step_apart"] is None and r["points_only_in"] == [len(last), len(last)]
  assert r["shared_points"] == len(row["history"]) - len(last) and r["shared_to_step"] < end
  assert r["differ"] == 1 and r["end_steps"] == [end, end + 393216]
  assert "at no shared point" in (tmp_path / "lengths.md").read_text()
  moved = copy.deepcopy(longer)  # ... and one that differs at a shared point parts there
  point = moved["rows"][0]["history"][0]
  point["loss/v_loss"] += 1e-6
  c = _write(tmp_path, "c.json", moved)
  assert T.main([a, c, "--out", str(tmp_path / "moved")]) == 0
  assert json.loads((tmp_path / "moved.json").read_text())["rows"][0]["first_step_apart"] == point["env_steps"]
  apart_all = copy.deepcopy(doc)  # no step in common (another eval interval): nothing to pair, no crash
  for p in apart_all["rows"][0]["history"]:
    p["env_steps"] += 1
  apart_all["rows"][0]["env_steps_per_seed"] += 1
  d = _write(tmp_path, "d.json", apart_all)
  assert T.main([a, d, "--out", str(tmp_path / "none")]) == 0
  r = json.loads((tmp_path / "none.json").read_text())["rows"][0]
  assert r["shared_points"] == 0 and r["shared_to_step"] is None and r["first_step_apart"] is None

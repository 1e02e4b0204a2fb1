"""benchmarks/compare_runs.py: bad input named before anything is drawn; two toy runs give the side-by-side table."""

import json
import os

import pytest

from conftest import load_benchmark


def _run(d, seeds, wall):
  os.makedirs(d)
  with open(os.path.join(d, "config.json"), "w") as f:
    json.dump({"task": "drop", "devices": 1, "mesh": {"seeds": 1, "envs": 1}, "config": {"seeds": seeds, "num_envs": 8}}, f)
  with open(os.path.join(d, "metrics.jsonl"), "w") as f:
    for s in seeds:
      for i, steps in enumerate((100, 200)):
        f.write(json.dumps({"seed": s, "env_steps": steps, "wall_time": wall * (i + 1), "train/episode_return": 1.0}) + "\n")
        f.write(json.dumps({"seed": s, "env_steps": steps, "wall_time": wall * (i + 1), "eval/completion": 0.5 * i,
                            "eval/safe_completion": 0.25 * i}) + "\n")
  return str(d)


def test_two_runs_side_by_side(tmp_path):
  a, b = _run(tmp_path / "a", [0, 1], 10.0), _run(tmp_path / "b", [0, 1], 20.0)
  cr = load_benchmark("compare_runs")
  assert cr.main([a, b, "--labels", "2 GPUs,1 GPU", "--out", str(tmp_path / "cmp")]) == 0
  md = open(tmp_path / "cmp.md").read()
  assert "| 1 | 200 | 20 | 50.0 | 25.0 | 40 | 50.0 | 25.0 |" in md
  assert md.count("\n| 0 |") == 2 and os.path.getsize(tmp_path / "cmp.png") > 0


@pytest.mark.parametrize("make,named", [
    (lambda t: [str(t / "missing"), str(t / "missing")], "config.json does not exist"),
    (lambda t: [_run(t / "a", [0], 1.0)], "at least two"),
])
def test_bad_runs_are_refused_naming_them(tmp_path, make, named, capsys):
  with pytest.raises(SystemExit) as e:
    load_benchmark("compare_runs").parse(make(tmp_path) + ["--out", "x"])
  assert e.value.code == 2 and named in capsys.readouterr().err


def test_labels_must_match_runs(tmp_path, capsys):
  a, b = _run(tmp_path / "a", [0], 1.0), _run(tmp_path / "b", [0], 1.0)
  with pytest.raises(SystemExit):
    load_benchmark("compare_runs").parse([a, b, "--labels", "one", "--out", "x"])
  assert "--labels: 1 label(s) for 2 run(s)" in capsys.readouterr().err


def test_corrupt_metrics_is_named(tmp_path, capsys):
  a, b = _run(tmp_path / "a", [0], 1.0), _run(tmp_path / "b", [0], 1.0)
  with open(os.path.join(b, "metrics.jsonl"), "a") as f:
    f.write("{not json\n")
  assert load_benchmark("compare_runs").main([a, b, "--out", str(tmp_path / "c")]) == 2
  assert "metrics.jsonl: not JSON" in capsys.readouterr().err

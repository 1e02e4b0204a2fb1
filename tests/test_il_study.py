"""benchmarks/il_study.py: a run cut short keeps the regimes it finished, and --resume runs an incomplete
task again (the study itself is a benchmark: benchmarks/results/il_study_*)."""

import json

import pytest
from conftest import load_benchmark

il = load_benchmark("il_study")

ROW = {"episodes": 4, "transitions": 40, "data_safe_fraction": 0.5, "final_loss": [0.1], "completion": 1.0,
       "completion_ci95": 0.0, "safe_completion": 0.5, "safe_completion_ci95": 0.0, "avg_health": 90.0,
       "avg_health_ci95": 0.0, "per_seed": [{"completion": 1.0, "safe_completion": 0.5}]}
RECORDED = {"careful": {"episodes": 4, "success": 1.0, "safe_success": 1.0}}


def test_a_time_limit_keeps_the_finished_regimes_and_resume_redoes_the_task(tmp_path, monkeypatch):
  calls = []

  def cut_short(task, args, log, save):
    calls.append(task)
    save({"task": task, "recorded": RECORDED, "regimes": {"careless": ROW}, "complete": False, "timings": {}})
    raise SystemExit(124)  # the device call's time limit, in the second regime

  monkeypatch.setattr(il, "run_task", cut_short)
  argv = ["--tasks", "pick_egg", "--quick", "--results-dir", str(tmp_path)]
  with pytest.raises(SystemExit):
    il.main(argv)
  (path,) = tmp_path.glob("il_study_*.json")
  (task,) = json.load(open(path))["tasks"]
  assert task["complete"] is False and list(task["regimes"]) == ["careless"]
  assert "Incomplete (the run ended before every regime was done): pick_egg." in open(path.with_suffix(".md")).read()

  def whole(task, args, log, save):
    calls.append(task)
    return {"task": task, "recorded": RECORDED, "regimes": {r: ROW for r in il.REGIMES}, "complete": True,
            "timings": {}}

  monkeypatch.setattr(il, "run_task", whole)
  assert il.main(argv + ["--resume"]) == 0
  (task,) = json.load(open(path))["tasks"]
  assert task["complete"] and list(task["regimes"]) == list(il.REGIMES) and calls == ["pick_egg", "pick_egg"]
  assert il.main(argv + ["--resume"]) == 0 and calls == ["pick_egg", "pick_egg"]  # complete: skipped

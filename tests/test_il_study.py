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


def test_the_temperature_with_the_best_validation_completion_is_chosen_ties_to_the_lower():
  assert il.choose_temperature({0.0: 0.2, 0.5: 0.6, 1.0: 0.4}) == 0.5
  assert il.choose_temperature({1.0: 0.5, 0.0: 0.5, 0.5: 0.1}) == 0.0
  assert il.choose_temperature({0.25: 0.0}) == 0.25


@pytest.mark.parametrize("value", ["a", "-1", "nan", "", "0,inf"])
def test_bad_temperatures_are_refused_naming_the_flag(value, capsys):
  with pytest.raises(SystemExit) as e:
    il.parse(["--temperature", value])
  assert e.value.code == 2 and "--temperature" in capsys.readouterr().err


def test_unknown_robot_is_refused_naming_the_flag(capsys):
  with pytest.raises(SystemExit) as e:
    il.parse(["--robot", "no_such_robot"])
  assert e.value.code == 2 and "--robot" in capsys.readouterr().err


def test_temperatures_default_to_the_grid_and_rows_show_the_chosen_one(tmp_path):
  a = il.parse(["--quick"])
  assert a.temperature == list(il.TEMPERATURES) and a.val_episodes == il.QUICK["val_episodes"]
  assert il.parse(["--temperature", "0.5"]).temperature == [0.5]
  payload = {"device": "cpu", "date": "d", "command": "c",
             "config": {"policy": "flow", "demos": 4, "seeds": 1, "eval_episodes": 4, "temperature": [0.0, 1.0]},
             "tasks": [{"task": "pick_egg", "recorded": RECORDED, "regimes": {"careful": dict(ROW, temperature=1.0)}}]}
  il.write_md(tmp_path / "x.md", payload)
  assert "| 100 / 50 | 1 |" in (tmp_path / "x.md").read_text()
  old = dict(payload, config=dict(payload["config"], temperature=0.0),
             tasks=[dict(payload["tasks"][0], regimes={"careful": ROW})])  # written before the choice existed
  il.write_md(tmp_path / "y.md", old)
  assert "| 100 / 50 | 0 |" in (tmp_path / "y.md").read_text()

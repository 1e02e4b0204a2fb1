"""benchmarks/value_loss_scan.py: the trainer's critic-divergence test applied to logged value losses (no training)."""

import importlib.util
import json
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("value_loss_scan",
                                              os.path.join(ROOT, "benchmarks", "value_loss_scan.py"))
S = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(S)


def _point(seed, steps, v, compl=None):
  p = {"seed": seed, "env_steps": steps, "loss/v_loss": v}
  if compl is not None:
    p.update({"eval/completion": compl, "eval/safe_completion": compl / 2})
  return p


@pytest.fixture
def files(tmp_path):
  # our seed 0 as Place Plate's first-draw seed 0 (2.4 -> 2.1e15, never completing); seed 1 a healthy run
  ours = {"rows": [{"method": "penalty", "history": [
      _point(0, 100, 2.44, 0.0), _point(1, 100, 9.0, 0.5), _point(0, 200, 2.1e15, 0.0), _point(1, 200, 50.0, 1.0),
      _point(0, 300, 7.8e19, 0.0), _point(1, 300, 3.0, 1.0)]}]}
  # Brax: Pick Egg's critic meeting the penalty late, 0.09 -> 4.5e7, under the floor: not a crossing
  brax = {"rows": [{"damage_weight": 2.0, "seed": 4, "completion": 1.0, "safe_completion": 1.0, "curve": [
      {"env_steps": 0, "wall_s": 1.0}, {"env_steps": 10, "v_loss": 0.09}, {"env_steps": 20, "v_loss": 4.5e7}]}]}
  paths = []
  for name, doc in (("ours.json", ours), ("brax.json", brax), ("table.json", {"groups": []})):
    paths.append(str(tmp_path / name))
    with open(paths[-1], "w") as f:
      json.dump(doc, f)
  return paths


def test_scan_finds_the_seed_whose_critic_diverged_and_counts_the_rest(files):
  res = S.scan(files)
  assert res["seed_runs"] == {"ours": 2, "brax": 1} and res["not_training_results"] == ["table.json"]
  (c,) = res["crossed"]
  assert (c["trainer"], c["seed"], c["env_steps"], c["v_loss"], c["lowest_before"]) == ("ours", 0, 200, 2.1e15, 2.44)
  assert c["largest"] == 7.8e19 and c["final"] == (0.0, 0.0)
  assert {e["seed"]: e["largest"] for e in res["every"]} == {0: 7.8e19, 1: 50.0, 4: 4.5e7}


def test_main_writes_the_table_and_refuses_bad_sources_naming_them(files, tmp_path):
  out = str(tmp_path / "scan")
  assert S.main(["--every", "--sources", *files, "--out", out]) == 0
  md = open(out + ".md").read()
  assert "1 seed-runs cross the lines" in md and "| ours.json | ours | penalty | 0 | 0.0 M | 2.1e+15 | 2.44 |" in md
  assert "| brax.json | w = 2 | 4 | 2 | 4.5e+07 | 100.0 / 100.0 % |" in md
  with pytest.raises(ValueError, match="sources: no such file"):
    S.main(["--sources", str(tmp_path / "missing.json"), "--out", out])
  bad = tmp_path / "bad.json"
  bad.write_text("{not json")
  with pytest.raises(ValueError, match="sources: cannot read"):
    S.main(["--sources", str(bad), "--out", out])

"""benchmarks/learning_phases.py: env steps to 80 % completion, then to 80 % safe, from results files."""

import importlib.util
import json
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("learning_phases", os.path.join(ROOT, "benchmarks", "learning_phases.py"))
L = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(L)


def _eval(compl, safe):
  return {"completion": compl, "safe_completion": safe, "avg_env_health": 90.0, "episode_cost": 1.0}


def _ours(history_by_seed):
  """An rl_multiseed.py file, w = 2, whose seeds logged the given (env_steps, completion, safe) evaluations."""
  return {"task": "place_plate", "device": "gpu_x (gpu)", "rows": [{
      "label": "penalty", "method": "penalty", "command": "rl_multiseed penalty", "env_steps_per_seed": 3_000_000,
      "train_kwargs": {"preset": "playground", "damage_weight": 2.0}, "task_kwargs": {"obs_mode": "paper"},
      "eval_actions": ["mode"],
      "per_seed": [{"seed": s, "final_eval": _eval(0.9, 0.9)} for s in history_by_seed],
      "history": [{"seed": s, "env_steps": n, "wall_time": n / 1e5, "eval/completion": c, "eval/safe_completion": f}
                  for s, pts in history_by_seed.items() for n, c, f in pts]}]}


def _brax(seed, action, points):
  return {"task": "place_plate", "device": "gpu_x", "recipe": {}, "rows": [{
      "damage_weight": 2.0, "seed": seed, "env_steps": 3_000_000, "command": f"rl_brax_ppo s{seed}", "recipe": {},
      "task_settings": {"obs_mode": "paper"}, **_eval(0.95, 0.9),
      "scored_curve": {"action": action, "points": [
          {"env_steps": n, "wall_s": n / 1e5, "completion": c, "safe_completion": f} for n, c, f in points]}}]}


def _write(tmp_path, name, doc):
  path = tmp_path / name
  path.write_text(json.dumps(doc))
  return str(path)


def test_each_run_splits_into_finding_the_task_and_doing_it_safely(tmp_path):
  ours = _write(tmp_path, "rl_place_plate_ours.json", _ours({
      0: [(1_000_000, 0.5, 0.1), (2_000_000, 0.85, 0.3), (3_000_000, 0.9, 0.85)],  # found at 2 M, safe at 3 M
      1: [(1_000_000, 0.2, 0.2), (2_000_000, 0.7, 0.7), (3_000_000, 0.79, 0.79)]}))  # neither
  brax = _write(tmp_path, "rl_brax_place_plate_s0.json", _brax(0, "mode", [(1_000_000, 0.9, 0.9)]))
  sampled = _write(tmp_path, "rl_brax_place_plate_s1.json", _brax(1, "sample", [(1_000_000, 0.9, 0.9)]))
  out = str(tmp_path / "phases")
  assert L.main(["--task", "place_plate", "--sources", ours, brax, sampled, "--out", out]) == 0
  doc = json.load(open(out + ".json"))
  g_ours, g_brax = doc["groups"]
  assert (g_ours["runs"], g_ours["scored"]) == (2, 2)
  assert [(r["seed"], r["c80"], r["s80"]) for r in g_ours["per_run"]] == [(0, 2_000_000, 3_000_000), (1, None, None)]
  assert g_ours["between"] == {"reached": 1, "mean": 1_000_000, "min": 1_000_000, "max": 1_000_000}
  # Brax's run scored by the sampled action has no evaluations by the mode: in the group, not scored
  assert (g_brax["runs"], g_brax["scored"]) == (2, 1)
  assert g_brax["to_80_completion"]["mean"] == g_brax["to_80_safe"]["mean"] == 1_000_000
  assert g_brax["between"]["mean"] == 0
  md = open(out + ".md").read()
  assert "| 2 (2) | 1.0 M | 2.0 (2.0–2.0) M, 1 / 2 | 3.0 (3.0–3.0) M, 1 / 2 | 1.0 (1.0–1.0) M, 1 / 1 |" in md
  assert "benchmarks/learning_phases.py --task place_plate --sources" in md


def test_a_file_that_is_not_a_results_file_is_refused_naming_it(tmp_path, capsys):
  bad = _write(tmp_path, "notes.json", {"hello": 1})
  with pytest.raises(SystemExit):
    L.main(["--task", "place_plate", "--sources", bad, "--out", str(tmp_path / "x")])
  err = capsys.readouterr().err
  assert "--sources" in err and "notes.json" in err
  assert not os.path.exists(tmp_path / "x.md")

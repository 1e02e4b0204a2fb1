"""benchmarks/trainer_table.py: one table of several trainers' results files (no training, no task code)."""

import importlib.util
import json
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("trainer_table", os.path.join(ROOT, "benchmarks", "trainer_table.py"))
T = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(T)


def _eval(compl, safe):
  return {"completion": compl, "safe_completion": safe, "avg_env_health": 90.0, "episode_cost": 1.0}


def _ours_row(method, preset, w, per_seed, label=None, **train_kwargs):
  """per_seed: [(seed, mode (compl, safe), sample (compl, safe))]."""
  return {"label": label or method, "method": method, "command": f"rl_multiseed {method}",
          "train_kwargs": {"preset": preset, "damage_weight": w, **train_kwargs}, "task_kwargs": {"obs_mode": "paper"},
          "eval_actions": ["sample", "mode"], "env_steps_per_seed": 1_000_000,
          "per_seed": [{"seed": s, "final_eval": _eval(*sa),
                        "final_eval_by_action": {"sample": _eval(*sa), "mode": _eval(*mo)}} for s, mo, sa in per_seed]}


def _brax_row(w, seed, mode, sample=None):
  row = {"damage_weight": w, "seed": seed, "env_steps": 2_000_000, "command": f"rl_brax_ppo w{w} s{seed}",
         "recipe": {}, "task_settings": {"obs_mode": "paper"}, **_eval(*mode)}
  if sample is not None:
    row.update(eval_actions=["mode", "sample"], by_action={"mode": _eval(*mode), "sample": _eval(*sample)})
  return row


@pytest.fixture
def sources(tmp_path):
  ours = {"device": "NVIDIA H100 80GB HBM3 (gpu, 1 device(s))", "task": "place_plate", "eval_episodes": 1024,
          "rows": [_ours_row("task_only", "playground", 0.0, [(0, (0.9, 0.0), (0.85, 0.01)), (1, (0.7, 0.0), (0.9, 0.0))]),
                   _ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.95), (1.0, 0.9)), (1, (1.0, 0.5), (1.0, 0.85))]),
                   _ours_row("pid", "playground", None, [(0, (1.0, 0.9), (1.0, 0.9))],
                             label="PID-Lagrangian (ĉ=1; λ0=2, K=0.01) + cost critic", cost_critic=True,
                             redraw_starts_steps=327680, max_grad_norm=None),
                   _ours_row("paper", "paper", 2.0, [(0, (0.1, 0.0), (0.1, 0.0))])]}
  brax = {"task": "place_plate", "device": "NVIDIA H200", "recipe": {}, "task_settings": {"obs_mode": "paper"},
          "rows": [_brax_row(0.0, 0, (1.0, 0.3)), _brax_row(2.0, 0, (1.0, 0.99), (1.0, 0.98)),
                   _brax_row(2.0, 1, (0.95, 0.85))]}
  paths = []
  for name, doc in (("ours.json", ours), ("brax.json", brax)):
    paths.append(str(tmp_path / name))
    with open(paths[-1], "w") as f:
      json.dump(doc, f)
  return paths


def test_groups_score_each_run_by_the_action_and_count_the_bar(sources, tmp_path):
  out = str(tmp_path / "table")
  assert T.main(["--task", "place_plate", "--action", "mode", "--sources", *sources, "--out", out]) == 0
  with open(out + ".json") as f:
    doc = json.load(f)
  g = {(x["trainer"], x["reward"]): x for x in doc["groups"]}
  ours = "ours (playground preset)"
  # task reward only, by the mode: seed 1 completes 70 % (< 80 %), so one of two runs meets the bar
  assert g[(ours, "task reward only")]["meet_bar"] == 1
  assert g[(ours, "task reward only")]["completion"] == pytest.approx(dict(mean=0.8, min=0.7, max=0.9))
  assert g[(ours, "damage penalty, w = 2")]["safe_completion"] == pytest.approx(dict(mean=0.725, min=0.5, max=0.95))
  assert g[(ours, "damage penalty, w = 2")]["meet_bar"] == 1
  assert (ours, "PID-Lagrangian (ĉ=1; λ0=2, K=0.01)") in g
  assert g[(T.PAPER, "damage penalty, w = 2")]["meet_bar"] == 0
  # Brax: task only at 30 % safe misses the bar; both w = 2 runs meet it (seed 1: 85 % safe at 95 % completion)
  assert g[(T.BRAX, "task reward only")]["meet_bar"] == 0
  assert g[(T.BRAX, "damage penalty, w = 2")]["meet_bar"] == 2
  assert "cost critic" in g[(ours, "PID-Lagrangian (ĉ=1; λ0=2, K=0.01)")]["settings"]
  assert "starts redrawn every 0.32768 M steps" in g[(ours, "PID-Lagrangian (ĉ=1; λ0=2, K=0.01)")]["settings"]
  assert "redrawn" not in g[(ours, "damage penalty, w = 2")]["settings"]
  assert "no gradient clipping" in g[(ours, "PID-Lagrangian (ĉ=1; λ0=2, K=0.01)")]["settings"]
  assert "clipping" not in g[(ours, "damage penalty, w = 2")]["settings"]
  md = open(out + ".md").read()
  assert "| 1 / 2 |" in md and "`rl_brax_ppo w2.0 s1`" in md and "python benchmarks/trainer_table.py" in md


def test_brax_runs_off_the_recipe_are_their_own_groups(tmp_path):
  """Fixed starts (num_resets_per_eval 0) and a gradient clip change brax's recipe: not pooled with stock runs."""
  rows = [_brax_row(2.0, 0, (0.0, 0.0)), _brax_row(2.0, 1, (0.1, 0.0)),
          dict(_brax_row(2.0, 0, (0.0, 0.0)), recipe={"num_resets_per_eval": 0}),
          dict(_brax_row(2.0, 0, (1.0, 0.9)), recipe={"max_grad_norm": 1.0, "num_resets_per_eval": 10})]
  path, out = str(tmp_path / "brax.json"), str(tmp_path / "table")
  with open(path, "w") as f:
    json.dump({"task": "place_plate", "device": "NVIDIA H200", "recipe": {}, "rows": rows}, f)
  assert T.main(["--task", "place_plate", "--action", "mode", "--sources", path, "--out", out]) == 0
  with open(out + ".json") as f:
    groups = json.load(f)["groups"]
  by = {g["settings"]: len(g["runs"]) for g in groups}
  assert len(by) == 3, by
  stock = [k for k in by if "fixed starts" not in k and "clip" not in k]
  assert by[stock[0]] == 2
  assert sum("fixed starts (no resets between epochs)" in k for k in by) == 1
  assert sum("grad-norm clip 1" in k and "fixed" not in k for k in by) == 1


def test_a_run_not_scored_by_the_action_is_counted_apart_not_guessed(sources, tmp_path):
  out = str(tmp_path / "table")
  T.main(["--task", "place_plate", "--action", "sample", "--sources", *sources, "--out", out])
  with open(out + ".json") as f:
    g = {(x["trainer"], x["reward"]): x for x in json.load(f)["groups"]}
  w2 = g[(T.BRAX, "damage penalty, w = 2")]
  assert len(w2["runs"]) == 1 and w2["unscored"] == 1  # seed 1 was scored by the mode only
  assert w2["safe_completion"]["mean"] == pytest.approx(0.98)
  assert g[("ours (playground preset)", "damage penalty, w = 2")]["meet_bar"] == 2  # sampled: 90 and 85 % safe
  assert "(1 more not scored by sample)" in open(out + ".md").read()


@pytest.mark.parametrize("doc, says", [
    ({"task": "place_plate", "rows": [{"x": 1}]}, "not a results file of rl_multiseed.py or rl_brax_ppo.py"),
    ({"task": "pick_egg", "recipe": {}, "rows": []}, "is of task 'pick_egg', not --task 'place_plate'"),
    ("not json", "cannot read"),
])
def test_bad_sources_are_refused_naming_the_flag(tmp_path, capsys, doc, says):
  path = tmp_path / "bad.json"
  path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
  with pytest.raises(SystemExit):
    T.parse(["--task", "place_plate", "--sources", str(path), "--out", str(tmp_path / "t")])
  err = capsys.readouterr().err
  assert "--sources:" in err and says in err


def test_unknown_action_and_missing_file_are_refused(tmp_path, capsys, sources):
  with pytest.raises(SystemExit):
    T.parse(["--task", "place_plate", "--sources", *sources, "--action", "greedy", "--out", "t"])
  assert "--action: one of mode, sample, mean, got 'greedy'" in capsys.readouterr().err
  with pytest.raises(SystemExit):
    T.parse(["--task", "place_plate", "--sources", str(tmp_path / "missing.json"), "--out", "t"])
  assert "--sources: cannot read" in capsys.readouterr().err


def _h200_table(tmp_path, ours_rows, brax_rows):
  """One results file of ours and one of Brax's (one H200 each), tabled by the mode → (groups by trainer, md)."""
  docs = {"ours.json": {"device": "NVIDIA H200 (gpu, 1 device(s))", "task": "place_plate", "rows": ours_rows},
          "brax.json": {"task": "place_plate", "device": "NVIDIA H200", "recipe": {}, "task_settings": {"obs_mode": "paper"},
                        "rows": brax_rows}}
  paths = []
  for name, doc in docs.items():
    paths.append(str(tmp_path / name))
    with open(paths[-1], "w") as f:
      json.dump(doc, f)
  out = str(tmp_path / "table")
  assert T.main(["--task", "place_plate", "--sources", *paths, "--out", out]) == 0
  with open(out + ".json") as f:
    return {x["trainer"]: x for x in json.load(f)["groups"]}, open(out + ".md").read()


def test_time_to_80_safe_per_group_counts_reached_and_unscored_runs(tmp_path):
  """Ours: each seed's time from its periodic evaluations (None: never reached); Brax: only rows with a
  scored curve by the mode (rl_brax_ppo.py --curve-episodes) are timed, earlier rows count as not scored."""
  row = _ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.95), (1.0, 0.9)), (1, (1.0, 0.5), (1.0, 0.85)),
                                                 (2, (1.0, 0.9), (1.0, 0.9))])
  for p, t in zip(row["per_seed"], (120.0, None, 180.0)):
    p["time_to_80_safe_s"] = t
  timed = dict(_brax_row(2.0, 0, (1.0, 0.99)), time_to_80_safe_s=200.0,
               scored_curve={"action": "mode", "episodes": 256, "points": []})
  by_sample = dict(_brax_row(2.0, 1, (1.0, 0.99)), time_to_80_safe_s=90.0,
                   scored_curve={"action": "sample", "episodes": 256, "points": []})
  g, md = _h200_table(tmp_path, [row], [timed, by_sample, _brax_row(2.0, 2, (1.0, 0.9))])
  assert g["ours (playground preset)"]["time_to_80_safe"] == dict(scored=3, reached=2, mean=150.0, min=120.0, max=180.0,
                                                                 shared=0)
  assert g[T.BRAX]["time_to_80_safe"] == dict(scored=1, reached=1, mean=200.0, min=200.0, max=200.0, shared=0)
  assert "| 150 (120–180), 2 / 3 reached |" in md and "| 200, 1 / 1 reached (2 not scored) |" in md
  assert sorted(_column(md, "time to 80 % safe (s)")) == ["120", "180", "200", "not reached", "not scored", "not scored"]


def _column(md: str, name: str) -> list[str]:
  """The cells of column ``name`` in the table of every run (the second table of ``md``)."""
  table = [line for line in md.split("Every run:", 1)[1].splitlines() if line.startswith("|")]
  cells = lambda line: [c.strip() for c in line.strip("|").split(" | ")]  # noqa: E731
  i = cells(table[0]).index(name)
  return [cells(line)[i] for line in table[2:]]


def _brax_table(tmp_path, rows) -> str:
  """A Brax results file of ``rows`` on one H200, tabled alone; returns the table's path stem."""
  path = str(tmp_path / "brax.json")
  with open(path, "w") as f:
    json.dump({"task": "place_plate", "device": "NVIDIA H200", "recipe": {}, "task_settings": {"obs_mode": "paper"},
               "rows": rows}, f)
  out = str(tmp_path / "table")
  T.main(["--task", "place_plate", "--sources", path, "--out", out])
  return out


def test_runs_that_shared_their_device_are_not_timed(tmp_path):
  """rl_brax_ppo.py --shared-card N rows: scored by the mode at every evaluation, but their seconds ran beside other
  runs, so the group's time to 80 % counts none of them and each run says why."""
  curve = {"action": "mode", "episodes": 256, "points": []}
  rows = [dict(_brax_row(2.0, s, (1.0, 0.95)), time_to_80_safe_s=400.0, scored_curve=curve, card_shared_by=3)
          for s in (0, 1)]
  out = _brax_table(tmp_path, rows)
  with open(out + ".json") as f:
    (g,) = json.load(f)["groups"]
  assert g["time_to_80_safe"]["scored"] == 0 and g["time_to_80_safe"]["shared"] == 2 and g["meet_bar"] == 2
  md = open(out + ".md").read()
  assert "| not timed (device shared) |" in md and md.count("| not timed (device shared by 3 runs) |") == 2


def test_a_group_of_alone_and_shared_runs_times_the_alone_ones(tmp_path):
  """Brax runs of one setting, some alone on their device and some sharing it: the group's time counts the
  alone ones and names the shared ones as not timed (not as "not scored", which means another action)."""
  curve = {"action": "mode", "episodes": 256, "points": []}
  rows = [dict(_brax_row(2.0, s, (1.0, 0.95)), time_to_80_safe_s=100.0 + s, scored_curve=curve,
               card_shared_by=3 if s < 2 else 1) for s in (0, 1, 2)]
  md = open(_brax_table(tmp_path, rows) + ".md").read()
  assert "| 102, 1 / 1 reached (2 not timed (device shared)) |" in md
  assert not any("not scored" in c for c in _column(md, "time to 80 % safe (s)"))


def test_files_from_before_the_panda_default_group_with_runs_naming_the_gripper(tmp_path):
  """A results file naming no robot ran the gripper (the default then): it groups with one naming it, not the Panda's."""
  import tasks  # the registry's rule, which this script copies rather than load the task code
  assert T.UNNAMED_ROBOT == tasks.UNNAMED_ROBOT
  old = {"task": "place_plate", "device": "NVIDIA H200", "recipe": {}, "task_settings": {"obs_mode": "paper"},
         "rows": [_brax_row(2.0, 0, (1.0, 0.9))]}
  new = {"task": "place_plate", "device": "NVIDIA H200", "recipe": {},
         "rows": [dict(_brax_row(2.0, 1, (1.0, 0.8)), task_settings={"robot": "gripper", "obs_mode": "paper"}),
                  dict(_brax_row(2.0, 2, (1.0, 0.7)), task_settings={"robot": "panda", "obs_mode": "paper"})]}
  paths = []
  for name, doc in (("old.json", old), ("new.json", new)):
    paths.append(str(tmp_path / name))
    with open(paths[-1], "w") as f:
      json.dump(doc, f)
  out = str(tmp_path / "table")
  T.main(["--task", "place_plate", "--action", "mode", "--sources", *paths, "--out", out])
  with open(out + ".json") as f:
    groups = json.load(f)["groups"]
  seeds = sorted((g["settings"], g["seeds"]) for g in groups)
  assert seeds == [("obs_mode=paper, robot=gripper", [0, 1]), ("obs_mode=paper, robot=panda", [2])]


def test_a_run_with_the_std_a_parameter_or_another_kl_rule_is_its_own_group(tmp_path):
  """policy_std and target_kl_rule change what a run learns: runs naming them are not pooled with the preset's."""
  doc = {"device": "NVIDIA H200 (gpu, 1 device(s))", "task": "place_plate", "eval_episodes": 1024,
         "rows": [_ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.5), (1.0, 0.9))]),
                  _ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.95), (1.0, 0.9))], policy_std="parameter"),
                  _ours_row("paper", "paper", 2.0, [(0, (0.1, 0.0), (0.1, 0.0))], target_kl_rule="epoch",
                            policy_std="parameter")]}
  path, out = str(tmp_path / "ours.json"), str(tmp_path / "table")
  with open(path, "w") as f:
    json.dump(doc, f)
  assert T.main(["--task", "place_plate", "--action", "mode", "--sources", path, "--out", out]) == 0
  with open(out + ".json") as f:
    groups = json.load(f)["groups"]
  ours = sorted((g["settings"], g["safe_completion"]["mean"]) for g in groups if g["trainer"].startswith("ours"))
  assert len(ours) == 2 and "std a parameter" in ours[1][0] and "std a" not in ours[0][0]
  assert ours[1][1] == pytest.approx(0.95)
  (paper,) = [g for g in groups if g["trainer"] == T.PAPER]
  assert "std a parameter" in paper["settings"] and "target-KL rule epoch" in paper["settings"]


def _evals(seed, points, keys=("eval/safe_completion", "eval/completion", "wall_time")):
  """Evaluation rows of one run: ``points`` [(env steps, safe, completion, clock s)]."""
  safe, completion, clock = keys
  return [dict(seed=seed, env_steps=n, **{safe: s, completion: c, clock: t}) for n, s, c, t in points]


def test_env_steps_to_80_safe_counts_each_runs_own_steps_on_any_device(tmp_path):
  """The first evaluation by the mode with ≥ 80 % safe and ≥ 80 % completion, in the run's own env steps: ours
  from its history (per seed), Brax's from its scored curve, a run that shared its device counted too (its
  steps are its own; only its seconds and rate are not); a curve scored by another action is not scored."""
  row = _ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.95), (1.0, 0.9)), (1, (1.0, 0.5), (1.0, 0.85))])
  row["history"] = (_evals(0, [(3_000_000, 0.5, 0.9, 100.0), (6_000_000, 0.85, 0.8, 160.0), (6_300_000, 0.9, 0.9, 170.0)])
                    + _evals(1, [(3_000_000, 0.9, 0.5, 100.0), (6_000_000, 0.5, 0.9, 160.0), (6_300_000, 0.7, 1.0, 170.0)]))
  brax_keys = ("safe_completion", "completion", "wall_s")
  curve = lambda action, pts: {"action": action, "episodes": 256, "points": _evals(0, pts, brax_keys)}  # noqa: E731
  alone = dict(_brax_row(2.0, 0, (1.0, 0.99)), scored_curve=curve("mode", [(0, 0.0, 0.0, 30.0), (3_300_000, 0.8, 0.8, 100.0),
                                                                        (6_600_000, 1.0, 1.0, 165.0)]))
  shared = dict(_brax_row(2.0, 1, (1.0, 0.99)), card_shared_by=3,
                scored_curve=curve("mode", [(0, 0.0, 0.0, 30.0), (3_300_000, 0.0, 0.0, 200.0), (6_600_000, 0.9, 0.9, 400.0)]))
  by_sample = dict(_brax_row(2.0, 2, (1.0, 0.99)), scored_curve=curve("sample", [(0, 0.0, 0.0, 30.0), (3_300_000, 1.0, 1.0, 99.0)]))
  g, md = _h200_table(tmp_path, [row], [alone, shared, by_sample])
  assert g["ours (playground preset)"]["env_steps_to_80_safe"] == dict(scored=2, reached=1, mean=6_000_000,
                                                                       min=6_000_000, max=6_000_000)
  assert g[T.BRAX]["env_steps_to_80_safe"] == dict(scored=2, reached=2, mean=4_950_000, min=3_300_000, max=6_600_000)
  runs = {(r["trainer"], r["seed"]): r for x in g.values() for r in x["runs"]}
  assert runs[("ours (playground preset)", 0)]["grain"] == 3_000_000  # the median spacing, not the last call's 0.3 M
  assert runs[("ours (playground preset)", 0)]["rate"] == pytest.approx(6_300_000 / 170.0)
  assert runs[(T.BRAX, 0)]["rate"] == pytest.approx(6_600_000 / 165.0) and runs[(T.BRAX, 1)]["rate"] is None
  assert not runs[(T.BRAX, 2)]["s80_scored"]
  assert "| 6.0 M, 1 / 2 reached |" in md and "| 5.0 (3.3–6.6) M, 2 / 2 reached (1 not scored) |" in md
  assert "| 6.0 M (evaluations every 3.0 M) | 37 k |" in md and "| not reached (evaluations every 3.0 M) | 37 k |" in md
  assert "| 6.6 M (evaluations every 3.3 M) | — |" in md and "| 3.3 M (evaluations every 3.3 M) | 40 k |" in md


def test_a_run_with_targets_once_per_iteration_is_its_own_group(tmp_path):
  """gae_per_iteration changes the critic's targets: such runs are not pooled with brax-style ones."""
  doc = {"device": "NVIDIA H200 (gpu, 1 device(s))", "task": "place_plate", "eval_episodes": 1024,
         "rows": [_ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.9), (1.0, 0.9))]),
                  _ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.5), (1.0, 0.5))], gae_per_iteration=True)]}
  path, out = str(tmp_path / "ours.json"), str(tmp_path / "table")
  with open(path, "w") as f:
    json.dump(doc, f)
  assert T.main(["--task", "place_plate", "--sources", path, "--out", out]) == 0
  with open(out + ".json") as f:
    groups = json.load(f)["groups"]
  assert sorted("GAE once per iteration" in g["settings"] for g in groups) == [False, True]


def test_a_paper_run_stopped_short_of_its_planned_steps_says_so(tmp_path):
  """A run of the paper's settings is planned to the paper's updates (config num_timesteps) and may stop short
  when its calls run out; the table says how far it got of the plan. A time-budgeted run's num_timesteps is only
  a ceiling and is not shown."""
  short = _ours_row("paper", "paper", 2.0, [(s, (0.03, 0.0), (0.03, 0.0)) for s in (0, 1)])
  whole = _ours_row("paper_task_only", "paper", 0.0, [(0, (0.2, 0.0), (0.2, 0.0))])
  timed = _ours_row("penalty", "playground", 2.0, [(0, (1.0, 0.9), (1.0, 0.9))])
  short.update(env_steps_per_seed=25_034_752, config={"num_timesteps": 25_559_040}, stopped_by_time_limit=True)
  whole.update(env_steps_per_seed=25_559_040, config={"num_timesteps": 25_559_040})
  timed.update(env_steps_per_seed=18_022_400, config={"num_timesteps": 1_000_000_000}, stopped_by_time_limit=True)
  g, md = _h200_table(tmp_path, [short, whole, timed], [])
  assert "| 25.0 M (2 of 2 stopped short of the planned) |" in md
  assert md.count("| 25.0 M of 25.6 M planned |") == 2
  assert "| 25.6 M |" in md and "| 18.0 M |" in md and "1000" not in md

"""benchmarks/rl_multiseed.py's command line, without training: bad values stop at parse time, the
tuning flags reach every Lagrangian method's train() keywords, and the defaults leave earlier commands'
methods unchanged (so committed rows stay reproducible)."""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import rl_multiseed  # noqa: E402
from train.ppo import TrainingDiverged  # noqa: E402


@pytest.mark.parametrize("argv, field", [
    (["--init-log-std=-0.5"], "--init-log-std"),
    (["--init-log-std=a,b"], "--init-log-std"),
    (["--init-log-std=-0.5,5"], "--init-log-std"),
    (["--pid-gains", "0.1,0.01"], "--pid-gains"),
    (["--pid-gains", "0.1,-1,0"], "--pid-gains"),
    (["--lagrange-lr", "nan"], "--lagrange-lr"),
    (["--lagrange-init", "-1"], "--lagrange-init"),
    (["--methods", "ppo"], "--methods"),
    (["--eval-actions", "greedy"], "--eval-actions"),
    (["--eval-actions", "mode,mode"], "--eval-actions"),
    (["--eval-actions", ","], "--eval-actions"),
    (["--resume"], "--resume"),  # a resumed run lives in --work-dir
    (["--damage-warmup-steps", "-1"], "--damage-warmup-steps"),
    (["--damage-ramp-steps", "1e6", "--methods", "pid"], "--damage-ramp-steps"),
    (["--damage-warmup-steps", "1e6", "--damage-weight", "0"], "--damage-warmup-steps"),
    (["--damage-warmup-completion", "1.5"], "--damage-warmup-completion"),
    (["--damage-warmup-completion", "nan"], "--damage-warmup-completion"),
    (["--damage-warmup-completion", "0.5", "--methods", "task_only"], "--damage-warmup-completion"),
    (["--timesteps", "-1"], "--timesteps"),
    (["--timesteps", "nan"], "--timesteps"),
    (["--anneal-lr"], "--anneal-lr"),  # over the default 1e9 steps it would barely decay
    (["--target-kl-rule", "batch"], "--target-kl-rule"),
    (["--policy-std", "global"], "--policy-std"),
    (["--redraw-starts-steps", "-1"], "--redraw-starts-steps"),
    (["--redraw-starts-steps", "nan"], "--redraw-starts-steps"),
    (["--redraw-starts-steps", "1.5"], "--redraw-starts-steps"),
    (["--max-grad-norm", "off"], "--max-grad-norm"),
    (["--max-grad-norm", "0"], "--max-grad-norm"),
    (["--max-grad-norm", "nan"], "--max-grad-norm"),
    (["--obs-clip", "0"], "--obs-clip"),
    (["--obs-clip", "-5"], "--obs-clip"),
    (["--obs-clip", "inf"], "--obs-clip"),
    # sizes: refused here, not by train() after the first method ran (nor 0 taken for the preset's)
    (["--num-envs", "0"], "--methods task_only: num_envs"),
    (["--num-envs", "-3"], "--methods task_only: num_envs"),
    (["--unroll-length", "0"], "--methods task_only: unroll_length"),
    (["--eval-episodes", "0"], "--eval-episodes"),
    (["--eval-envs", "0"], "--eval-envs"),
    (["--eval-every", "0"], "--eval-every"),
    (["--methods", "paper", "--paper-timesteps", "0"], "--paper-timesteps"),
    (["--damage-weight", "nan"], "--damage-weight"),
    (["--damage-weight", "-2"], "--damage-weight"),
    (["--seeds=-1"], "--seeds"),
])
def test_bad_values_name_the_flag(argv, field, capsys):
  with pytest.raises(SystemExit):
    rl_multiseed.parse(argv)
  assert field in capsys.readouterr().err


def test_tuning_reaches_the_lagrangian_methods_only():
  a = rl_multiseed.parse(["--cost-critic", "--init-log-std=-0.5,-1.5", "--lagrange-init", "2", "--lagrange-lr",
                          "0.002", "--pid-gains", "0.01,0.002,0.005"])
  lag, pid = rl_multiseed.method_spec("lagrangian", a), rl_multiseed.method_spec("pid", a)
  assert (lag["lagrange_init"], lag["lagrange_lr"]) == (2.0, 0.002) and "λ0=2, lr=0.002" in lag["label"]
  assert (pid["pid_kp"], pid["pid_ki"], pid["pid_kd"]) == (0.01, 0.002, 0.005) and "K=0.01/0.002/0.005" in pid["label"]
  for spec in (lag, pid, rl_multiseed.method_spec("penalty", a)):
    assert spec["cost_critic"] and spec["init_log_std"] == (-0.5, -1.5)
  task = rl_multiseed.method_spec("task_only", a)
  assert "lagrange_init" not in task and "cost_critic" not in task and task["init_log_std"] == (-0.5, -1.5)
  assert "init_log_std" not in rl_multiseed.method_spec("paper", a)  # the paper preset keeps its own


def test_defaults_keep_the_earlier_methods():
  a = rl_multiseed.parse([])
  assert rl_multiseed.method_spec("pid", a) == dict(label="PID-Lagrangian (ĉ=2)", preset="playground", budget=2.0,
                                                    multiplier="pid")
  assert rl_multiseed.method_spec("penalty", a) == dict(label="damage penalty (w=2)", preset="playground",
                                                        damage_weight=2.0)


def test_eval_actions_default_to_the_mode():
  assert rl_multiseed.parse([]).eval_actions == ["mode"]
  assert rl_multiseed.parse(["--eval-actions", "sample,mode,mean"]).eval_actions == ["sample", "mode", "mean"]


def _row(actions=("mode", "sample")):
  def ev(safe):
    return {"completion": 1.0, "safe_completion": safe, "avg_env_health": 99.0, "episode_cost": 1.0}
  per_seed = [{"seed": s, "final_eval": ev(0.5 + 0.2 * s), "time_to_80_safe_s": None, "final_lambda": None,
               "final_eval_by_action": {"mode": ev(0.5 + 0.2 * s), "sample": ev(0.9)}} for s in range(3)]
  return {"label": "damage penalty (w=2)", "eval_actions": list(actions), "per_seed": per_seed,
          "summary": rl_multiseed.summarise(per_seed)}


def test_headline_action_rescores_a_row_from_its_own_evaluations():
  row = _row()
  assert rl_multiseed.seeds_meeting(row) == 1  # the mode: 0.5 / 0.7 / 0.9 safe
  s = rl_multiseed.with_headline(row, "sample", "f.json")
  assert s["eval_actions"] == ["sample", "mode"] and rl_multiseed.seeds_meeting(s) == 3
  assert s["summary"]["safe_completion"]["mean"] == 0.9 and abs(row["summary"]["safe_completion"]["mean"] - 0.7) < 1e-12
  assert rl_multiseed._labelled(s).endswith(", sample action")


def test_headline_action_refuses_a_row_that_never_scored_it():
  with pytest.raises(SystemExit, match="f.json.*mean"):
    rl_multiseed.with_headline(_row(), "mean", "f.json")
  with pytest.raises(SystemExit):
    rl_multiseed.parse(["--combine", __file__, "--tag", "x", "--headline-action", "greedy"])


@pytest.mark.parametrize("value", ['{"start": "teleport"}', "not json", '{"damage_weight": 1}', '["start"]',
                                   '{"obs_mode": "paper"}'])
def test_bad_task_settings_name_the_flag(value, capsys):
  with pytest.raises(SystemExit):
    rl_multiseed.parse(["--task", "pick_egg", "--task-settings", value])
  assert "--task-settings" in capsys.readouterr().err


def test_task_settings_reach_the_task_keywords(monkeypatch):
  a = rl_multiseed.parse(["--task", "pick_egg", "--task-settings", '{"start": "pregrasp"}'])
  import tasks
  assert tasks.rl_settings(a.task, a.task_settings) == {"robot": "gripper", "goal": "carry", "start": "pregrasp"}


@pytest.mark.parametrize("value", ['{"start": "teleport"}', "not json", '{"damage_weight": 1}',
                                   '{"obs_mode": "full"}', '["start"]'])
def test_bad_eval_task_settings_name_the_flag(value, capsys):
  with pytest.raises(SystemExit):
    rl_multiseed.parse(["--task", "shelve_item", "--task-settings", '{"start": "route"}', "--eval-task-settings", value])
  assert "--eval-task-settings" in capsys.readouterr().err


def test_eval_task_settings_reach_train_and_the_final_evaluation(monkeypatch, tmp_path):
  """The evaluations' settings are the training ones with --eval-task-settings over them: train() gets them as
  eval_task_kwargs, the final evaluation builds its env from them, and the row records both."""
  import train
  seen = {}

  class Stop(Exception):
    pass

  def fake_train(task, task_kwargs=None, eval_task_kwargs=None, **kw):
    seen.update(task_kwargs=task_kwargs, eval_task_kwargs=eval_task_kwargs)
    raise Stop

  monkeypatch.setattr(train, "train", fake_train)
  a = rl_multiseed.parse(["--task", "shelve_item", "--task-settings", '{"start": "route"}',
                          "--eval-task-settings", '{"start": "in_front"}', "--methods", "penalty"])
  with pytest.raises(Stop):
    rl_multiseed.run_method("penalty", a, "cmd", str(tmp_path))
  assert seen == {"task_kwargs": {"robot": "gripper", "start": "route"},
                  "eval_task_kwargs": {"robot": "gripper", "start": "in_front"}}
  plain = rl_multiseed.parse(["--task", "shelve_item", "--methods", "penalty"])
  with pytest.raises(Stop):
    rl_multiseed.run_method("penalty", plain, "cmd", str(tmp_path / "plain"))
  assert seen["eval_task_kwargs"] is None


def test_task_settings_over_place_plates_rl_setting_keep_its_observation():
  a = rl_multiseed.parse(["--task", "place_plate", "--task-settings", '{"n_substeps": 5}'])
  import tasks
  assert tasks.rl_settings(a.task, a.task_settings)["obs_mode"] == "paper"


def test_a_diverged_method_is_reported_and_the_others_still_run(monkeypatch, tmp_path, capsys):
  ran = []

  def diverge(name, *a):
    ran.append(name)
    raise TrainingDiverged(f"training diverged at iteration 3: non-finite seed 0: loss/v_loss ({name})")

  monkeypatch.setattr(rl_multiseed, "run_method", diverge)
  status = rl_multiseed.main(["--methods", "penalty,pid", "--results-dir", str(tmp_path), "--work-dir", str(tmp_path)])
  err = capsys.readouterr().err
  assert status == 1 and ran == ["penalty", "pid"]
  assert "penalty: training diverged" in err and "diverged (no row): penalty, pid" in err
  assert not list(tmp_path.glob("*.md"))  # no table of nothing


def test_a_run_already_in_work_dir_is_refused_without_resume(tmp_path, capsys):
  (tmp_path / "penalty").mkdir()
  (tmp_path / "penalty" / "config.json").write_text("{}")
  with pytest.raises(SystemExit):
    rl_multiseed.parse(["--methods", "penalty", "--work-dir", str(tmp_path)])
  assert f"--work-dir: {tmp_path / 'penalty'} already holds a run" in capsys.readouterr().err
  assert rl_multiseed.parse(["--methods", "penalty", "--work-dir", str(tmp_path), "--resume"]).resume


def test_resume_of_a_work_dir_without_the_runs_is_refused(tmp_path, capsys):
  """--resume in a folder that holds none of the methods' runs (a mistyped path, a machine that did not keep
  it) once trained them all again from the start; now it is refused before anything compiles."""
  for work in (tmp_path / "missing", tmp_path):
    with pytest.raises(SystemExit):
      rl_multiseed.parse(["--methods", "penalty,pid", "--work-dir", str(work), "--resume"])
    assert f"--resume: {work} holds no run of penalty, pid" in capsys.readouterr().err
  (tmp_path / "pid").mkdir()
  (tmp_path / "pid" / "metrics.jsonl").write_text("")  # one method's run is there: the other starts afresh
  assert rl_multiseed.parse(["--methods", "penalty,pid", "--work-dir", str(tmp_path), "--resume"]).resume


def test_calls_without_work_dir_never_share_run_directories(monkeypatch, tmp_path):
  """Two calls at once (say one per GPU) once shared /tmp/rl_multiseed/<task>_<device>: the second
  overwrote the first's checkpoints before it was scored."""
  works = []

  def record(name, args, command, work):
    works.append(work)
    raise TrainingDiverged("stop here")

  monkeypatch.setattr(rl_multiseed, "run_method", record)
  for _ in range(2):
    rl_multiseed.main(["--methods", "penalty", "--results-dir", str(tmp_path)])
  assert len(set(works)) == 2 and all(os.path.isdir(w) and not os.listdir(w) for w in works)


def test_damage_schedule_reaches_the_penalty_method():
  a = rl_multiseed.parse(["--methods", "task_only,penalty", "--damage-warmup-steps", "5.5e6",
                          "--damage-ramp-steps", "1e6"])
  pen = rl_multiseed.method_spec("penalty", a)
  assert (pen["damage_warmup_steps"], pen["damage_ramp_steps"]) == (5_500_000, 1_000_000)
  assert "w=0 for 5.5e+06 steps, then linear to 2 over 1e+06" in pen["label"]
  assert "damage_warmup_steps" not in rl_multiseed.method_spec("task_only", a)


def test_completion_gate_reaches_the_penalty_method():
  a = rl_multiseed.parse(["--methods", "task_only,penalty", "--damage-warmup-completion", "0.8",
                          "--damage-ramp-steps", "4e6"])
  pen = rl_multiseed.method_spec("penalty", a)
  assert (pen["damage_warmup_completion"], pen["damage_warmup_steps"], pen["damage_ramp_steps"]) == (0.8, 0, 4_000_000)
  assert "w=0 until training completion ≥ 80%, then linear to 2 over 4e+06" in pen["label"]
  assert "damage_warmup_completion" not in rl_multiseed.method_spec("task_only", a)
  plain = rl_multiseed.method_spec("penalty", rl_multiseed.parse(["--methods", "penalty"]))
  assert "damage_warmup_completion" not in plain  # unchanged commands keep their settings


EGG_POLICY = os.path.join(ROOT, "benchmarks", "results",
                          "rl_pick_egg_nvidia_h200_held_std0_task_only_s345_rerun_task_only_policy.npz")  # seeds 3,4,5


def test_anneal_lr_reaches_the_playground_methods_and_names_its_horizon():
  a = rl_multiseed.parse(["--methods", "task_only,penalty,paper", "--anneal-lr", "--timesteps", "4.5e7"])
  for m in ("task_only", "penalty"):
    spec = rl_multiseed.method_spec(m, a)
    assert spec["anneal_learning_rate"] is True and "lr annealed to 0 over 4.5e+07 steps" in spec["label"]
  assert "anneal_learning_rate" not in rl_multiseed.method_spec("paper", a)  # the preset anneals already
  plain = rl_multiseed.parse(["--methods", "penalty"])
  assert plain.timesteps == 1e9 and "anneal_learning_rate" not in rl_multiseed.method_spec("penalty", plain)


def test_anneal_entropy_reaches_the_playground_methods_and_needs_a_horizon(capsys):
  a = rl_multiseed.parse(["--methods", "task_only,penalty,paper", "--anneal-entropy", "--timesteps", "1.1e7"])
  for m in ("task_only", "penalty"):
    spec = rl_multiseed.method_spec(m, a)
    assert spec["anneal_entropy"] is True and "entropy annealed to 0 over 1.1e+07 steps" in spec["label"]
  assert "anneal_entropy" not in rl_multiseed.method_spec("paper", a)  # no entropy term in the paper preset
  with pytest.raises(SystemExit):
    rl_multiseed.parse(["--methods", "penalty", "--anneal-entropy"])
  assert "--anneal-entropy: the coefficient decays to 0 over --timesteps" in capsys.readouterr().err


def test_redraw_starts_reaches_every_method_and_its_label():
  a = rl_multiseed.parse(["--methods", "task_only,penalty,paper", "--redraw-starts-steps", "327680"])
  for m in ("task_only", "penalty", "paper"):
    spec = rl_multiseed.method_spec(m, a)
    assert spec["redraw_starts_steps"] == 327680 and "starts redrawn every 3.28e+05 steps" in spec["label"]
  assert "redraw_starts_steps" not in rl_multiseed.method_spec("penalty", rl_multiseed.parse([]))


def test_max_grad_norm_reaches_every_method_none_meaning_no_clipping():
  a = rl_multiseed.parse(["--methods", "task_only,penalty", "--max-grad-norm", "none"])
  for m in ("task_only", "penalty"):
    spec = rl_multiseed.method_spec(m, a)
    assert "max_grad_norm" in spec and spec["max_grad_norm"] is None and "no gradient clipping" in spec["label"]
  spec = rl_multiseed.method_spec("penalty", rl_multiseed.parse(["--max-grad-norm", "0.5"]))
  assert spec["max_grad_norm"] == 0.5 and "grad-norm clip 0.5" in spec["label"]
  assert "max_grad_norm" not in rl_multiseed.method_spec("penalty", rl_multiseed.parse([]))


def test_obs_clip_reaches_every_method_and_its_label():
  a = rl_multiseed.parse(["--methods", "task_only,penalty", "--obs-clip", "10"])
  for m in ("task_only", "penalty"):
    spec = rl_multiseed.method_spec(m, a)
    assert spec["obs_clip"] == 10.0 and "observations clipped at ±10" in spec["label"]
  assert "obs_clip" not in rl_multiseed.method_spec("penalty", rl_multiseed.parse([]))


def test_gae_per_iteration_reaches_every_method_and_its_label():
  a = rl_multiseed.parse(["--methods", "task_only,penalty,paper", "--gae-per-iteration"])
  for name in ("task_only", "penalty", "paper"):
    spec = rl_multiseed.method_spec(name, a)
    assert spec["gae_per_iteration"] is True and "GAE once per iteration" in spec["label"]
  assert "gae_per_iteration" not in rl_multiseed.method_spec("penalty", rl_multiseed.parse([]))


def test_target_kl_rule_reaches_the_paper_methods_only():
  a = rl_multiseed.parse(["--methods", "paper,paper_task_only,penalty", "--target-kl-rule", "epoch"])
  for m in ("paper", "paper_task_only"):
    spec = rl_multiseed.method_spec(m, a)
    assert spec["target_kl_rule"] == "epoch" and "target-KL rule epoch" in spec["label"]
  assert "target_kl_rule" not in rl_multiseed.method_spec("penalty", a)  # no target KL there to rule
  assert "target_kl_rule" not in rl_multiseed.method_spec("paper", rl_multiseed.parse([]))  # the preset's own
  a = rl_multiseed.parse(["--methods", "paper,penalty", "--policy-std", "parameter"])
  for m in ("paper", "penalty"):
    spec = rl_multiseed.method_spec(m, a)
    assert spec["policy_std"] == "parameter" and "std a parameter" in spec["label"]
  assert "policy_std" not in rl_multiseed.method_spec("paper", rl_multiseed.parse([]))


def test_a_ramp_without_warmup_is_labelled_as_one():
  pen = rl_multiseed.method_spec("penalty", rl_multiseed.parse(["--methods", "penalty", "--damage-ramp-steps", "1e7"]))
  assert pen["damage_warmup_steps"] == 0 and "linear from 0 over 1e+07 steps" in pen["label"]


@pytest.mark.parametrize("argv, field, says", [
    (["--critic-warmup-iterations", "-1"], "--critic-warmup-iterations", ">= 0"),
    (["--critic-warmup-iterations", "5"], "--critic-warmup-iterations", "give --init-from"),
    (["--init-seed", "4"], "--init-seed", "give --init-from"),
    (["--init-from", "no/such/run"], "--init-from", "no checkpoint at"),
    (["--init-from", EGG_POLICY], "--init-from", "made for task 'pick_egg'"),  # --task defaults to place_plate
    (["--task", "pick_egg", "--init-from", EGG_POLICY, "--init-seed", "9"], "--init-seed", "its seeds: 3, 4, 5"),
    (["--task", "pick_egg", "--init-from", EGG_POLICY, "--seeds", "0,1"], "--init-from", "holds 3 seeds"),
])
def test_bad_init_from_names_the_flag_before_anything_runs(argv, field, says, capsys):
  with pytest.raises(SystemExit):
    rl_multiseed.parse(argv)
  err = capsys.readouterr().err
  assert field in err and says in err


def test_a_corrupt_init_from_is_refused(tmp_path, capsys):
  bad = tmp_path / "policy.npz"
  bad.write_bytes(b"not a checkpoint")
  with pytest.raises(SystemExit):
    rl_multiseed.parse(["--init-from", str(bad)])
  assert "--init-from: " in (err := capsys.readouterr().err) and "is not a readable checkpoint" in err


def test_init_from_reaches_every_method_with_its_seed_and_warmup():
  a = rl_multiseed.parse(["--task", "pick_egg", "--methods", "task_only,penalty", "--seeds", "0,1",
                          "--init-from", EGG_POLICY, "--init-seed", "4", "--critic-warmup-iterations", "10"])
  for name in ("task_only", "penalty"):
    spec = rl_multiseed.method_spec(name, a)
    assert (spec["init_from"], spec["init_seed"], spec["critic_warmup_iterations"]) == (EGG_POLICY, 4, 10)
    assert "actor from rl_pick_egg_nvidia_h200_held_std0_task_only_s345_rerun_task_only_policy.npz seed 4" \
        " (critic alone for 10 iterations)" in spec["label"]
  assert "init_from" not in rl_multiseed.method_spec("penalty", rl_multiseed.parse(["--methods", "penalty"]))

"""benchmarks/rl_brax_ppo.py: the second trainer's settings are what it says (no training here)."""

import os
import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.training.acme import running_statistics
from conftest import load_benchmark

from train.policy import load_policy

R = load_benchmark("rl_brax_ppo")


def _initial_scale(factory, obs_size=5, action_size=4):
  nets = factory(obs_size, action_size)
  params = nets.policy_network.init(jax.random.PRNGKey(0))
  logits = nets.policy_network.apply(None, params, jax.random.normal(jax.random.PRNGKey(1), (3, obs_size)))
  return np.asarray(nets.parametric_action_distribution.create_dist(logits).scale)


def test_init_log_std_is_the_policys_initial_std_in_every_state():
  """--init-log-std=-0.5,-1.5: brax's tanh-normal head starts at exp(-0.5) on the arm dims and exp(-1.5)
  on the gripper (last) dim, whatever the observation."""
  scale = _initial_scale(R.network_factory((-0.5, -1.5)))
  np.testing.assert_allclose(scale[:, :-1], np.exp(-0.5), rtol=1e-5)
  np.testing.assert_allclose(scale[:, -1], np.exp(-1.5), rtol=1e-5)


def test_default_is_brax_init():
  """Without the flag the std is brax's own (state-dependent, ≈ softplus(0) + 0.001 ± the init's spread)."""
  scale = _initial_scale(R.network_factory(None))
  assert not np.allclose(scale, scale[0, 0])  # state- and dimension-dependent: nothing was overridden
  assert 0.2 < scale.mean() < 2.0


@pytest.mark.parametrize("value", ["-0.5", "-0.5,nan", "-0.5,-9", "a,b", "-0.5,-1.5,0"])
def test_bad_init_log_std_is_refused_naming_it(value):
  with pytest.raises(ValueError, match="init_log_std"):
    R.parse_args([f"--init-log-std={value}"])


@pytest.mark.parametrize("value", ['{"start": "midair"}', '{"nonsense": 1}', '["start"]', "{start:",
                                   '{"damage_weight": 2}', '{"robot": "unicycle"}'])
def test_bad_task_settings_are_refused_naming_them(value):
  with pytest.raises(ValueError, match="task_settings"):
    R.parse_args(["--task", "pick_egg", f"--task-settings={value}"])


def test_task_settings_go_over_the_rl_setting_and_keep_rows_of_other_settings_apart():
  a = R.parse_args(["--task", "pick_egg", '--task-settings={"start": "pregrasp"}'])
  assert a.settings == {**R.RL_SETTINGS["pick_egg"], "start": "pregrasp"}
  assert R.parse_args(["--task", "pick_egg"]).settings == R.RL_SETTINGS["pick_egg"]
  row = {"damage_weight": 0.0, "seed": 0, "recipe": {}, "task_settings": a.settings}
  assert R._key(row) != R._key(dict(row, task_settings=R.RL_SETTINGS["pick_egg"]))
  doc = {"task_settings": R.RL_SETTINGS["pick_egg"]}
  assert R._settings_label(row, doc) == ", task goal=carry, start=pregrasp"
  assert R._settings_label(dict(row, task_settings=doc["task_settings"]), doc) == ""


@pytest.mark.parametrize("value", ['{"start": "teleport"}', "not json", '{"damage_weight": 1}', '["start"]'])
def test_bad_eval_task_settings_are_refused_naming_them(value):
  with pytest.raises(ValueError, match="eval_task_settings"):
    R.parse_args(["--task", "shelve_item", '--task-settings={"start": "route"}', f"--eval-task-settings={value}"])


def test_eval_task_settings_go_to_every_evaluation_and_label_the_row(monkeypatch):
  """Brax's own evaluations and the final one run the task with --eval-task-settings over the training ones;
  the row records them, its key and label tell it from a run evaluated in its training setting."""
  a = R.parse_args(["--task", "shelve_item", '--task-settings={"start": "route"}',
                    '--eval-task-settings={"start": "in_front"}'])
  assert a.settings["start"] == "route" and a.eval_settings == dict(a.settings, start="in_front")
  made, used = [], {}

  def fake_make(task, **kw):
    made.append(kw["start"])
    return types.SimpleNamespace(start=kw["start"], unwrapped=types.SimpleNamespace(episode_length=8),
                                 entity_names=("box",))

  def fake_train(environment, eval_env, progress_fn, policy_params_fn, **kw):
    used.update(train=environment.start, brax_eval=eval_env.start)
    policy_params_fn(10, lambda *x, **k: None, "weights")

  def fake_evaluate(env, policy, **kw):
    used["final"] = env.start
    return {"metrics": {"completion": 1.0, "safe_completion": 1.0, "avg_health": 100.0, "cost_mean": 0.0,
                        "episodes": 8}}

  monkeypatch.setattr(R.tasks, "make", fake_make)
  monkeypatch.setattr(R.brax_ppo, "train", fake_train)
  monkeypatch.setattr(R, "evaluate", fake_evaluate)
  monkeypatch.setattr(R, "parametrized_policy", lambda *x, **k: None)
  row = R.train_one("shelve_item", 2.0, 0, dict(R.PLAYGROUND_PANDA_PICK_CUBE, eval_episodes=8), None, a.settings,
                    eval_settings=a.eval_settings)
  assert used == {"train": "route", "brax_eval": "in_front", "final": "in_front"}
  assert row["eval_task_settings"]["start"] == "in_front"
  plain = {k: v for k, v in row.items() if k != "eval_task_settings"}
  assert R._key(row) != R._key(plain)
  doc = {"task_settings": R.RL_SETTINGS["shelve_item"]}
  assert R._settings_label(row, doc) == ", task start=route, evaluated with start=in_front"


def test_reward_preference_takes_the_same_task_settings():
  P = load_benchmark("reward_preference")
  a = P.parse_args(["--tasks", "pick_egg,place_plate", '--task-settings={"episode_length": 60}'])
  rl = {n: {k: v for k, v in R.RL_SETTINGS[n].items() if k != "robot"} for n in ("pick_egg", "place_plate")}
  assert a.settings["pick_egg"] == {**rl["pick_egg"], "episode_length": 60}  # the robot comes from --robot
  assert a.settings["place_plate"] == {**rl["place_plate"], "episode_length": 60}
  assert a.robot == "gripper"
  with pytest.raises(ValueError, match="task_settings"):
    P.parse_args(["--tasks", "pick_egg", '--task-settings={"start": "midair"}'])


def test_reward_preference_refuses_an_unknown_robot_and_a_robot_in_task_settings():
  P = load_benchmark("reward_preference")
  with pytest.raises(ValueError, match="--robot"):
    P.parse_args(["--tasks", "pick_egg", "--robot", "no_such_robot"])
  with pytest.raises(ValueError, match="task_settings.*--robot"):
    P.parse_args(["--tasks", "pick_egg", '--task-settings={"robot": "panda"}'])


def test_reward_preference_still_style_is_the_zero_action():
  P = load_benchmark("reward_preference")
  a = P.parse_args(["--tasks", "shelve_item", "--style", "shelve_item:still"])
  assert a.extra == {"shelve_item": ["still"]}
  env = P.tasks.make("shelve_item")
  act = P.still_policy(env)(None, None)
  assert act.shape == (env.action_size,) and not act.any()
  with pytest.raises(ValueError, match="style"):
    P.parse_args(["--tasks", "shelve_item", "--style", "pick_egg:still"])


@pytest.mark.parametrize("value", ["greedy", "mode,mode", ","])
def test_bad_eval_actions_are_refused_naming_them(value):
  with pytest.raises(ValueError, match="eval_actions"):
    R.parse_args([f"--eval-actions={value}"])


def test_rows_say_which_action_scored_them():
  assert R.parse_args([]).actions == ("mode",)
  assert R.parse_args(["--eval-actions", "sample,mode"]).actions == ("sample", "mode")
  v = {"completion": 1.0, "safe_completion": 0.9, "avg_env_health": 99.0, "episode_cost": 1.0}
  row = {"reward": "task reward only", "seed": 0, "env_steps": 10, "train_wall_s": 1.0, "stopped_by_budget": False,
         "completion": 1.0, "safe_completion": 0.9, "avg_env_health": 99.0, "episode_cost": 1.0, "eval_episodes": 8,
         "command": "c", "eval_actions": ["sample", "mode"], "by_action": {"sample": v, "mode": dict(v, safe_completion=0.5)}}
  doc = {"task": "place_plate", "task_settings": {}, "device": "cpu", "recipe": {}, "rows": [row]}
  md = R.render_md(doc)
  assert "| task reward only, sample action | 0 |" in md
  assert "| task reward only | 0 | 0.00 M | mode | 100.0 % | 50.0 % |" in md  # env-steps tell runs of one seed apart
  old = {k: x for k, x in row.items() if k not in ("eval_actions", "by_action")}  # before the flag: the mode
  assert "| task reward only | 0 |" in R.render_md(dict(doc, rows=[old])) and "by action" not in R.render_md(dict(doc, rows=[old]))


def _row(w, seed, safe, date="2026-11-29 05:50:00 UTC"):
  return {"reward": f"w {w}", "damage_weight": w, "seed": seed, "env_steps": 10, "train_wall_s": 1.0,
          "stopped_by_budget": False, "completion": 1.0, "safe_completion": safe, "avg_env_health": 99.0,
          "episode_cost": 1.0, "eval_episodes": 8, "command": "c", "recipe": {}, "task_settings": {}, "date": date}


def test_merge_combines_the_files_of_separate_processes_into_one_table(tmp_path):
  import json
  paths = []
  rerun = _row(0.0, 0, 0.2, date="2026-11-30 07:00:00 UTC")  # the same command run again, later
  for i, rows in enumerate([[_row(0.0, 0, 0.1)], [_row(2.0, 0, 0.9), _row(2.0, 1, 0.8)], [rerun]]):
    paths.append(str(tmp_path / f"p{i}.json"))
    with open(paths[-1], "w") as f:
      json.dump({"task": "shelve_item", "task_settings": {}, "device": "NVIDIA H200", "recipe": {}, "rows": rows}, f)
  assert R.main(["--merge", *paths, "--out-dir", str(tmp_path)]) == 0
  assert R.main(["--merge", paths[0], "--out-dir", str(tmp_path)]) == 0  # merging a run again adds nothing
  with open(tmp_path / "rl_brax_shelve_item_nvidia_h200.json") as f:
    merged = json.load(f)
  # one row per run: the second run of w 0 seed 0 is kept beside the first, in date order
  assert [(r["damage_weight"], r["seed"], r["safe_completion"]) for r in merged["rows"]] == [
      (0.0, 0, 0.1), (0.0, 0, 0.2), (2.0, 0, 0.9), (2.0, 1, 0.8)]
  md = (tmp_path / "rl_brax_shelve_item_nvidia_h200.md").read_text()
  assert md.count("| w 2.0 |") == 2 and "| 2026-11-29 05:50 |" in md and "| 2026-11-30 07:00 |" in md


def test_out_goes_inside_out_dir_when_both_are_given(tmp_path):
  """A relative --out names a file inside --out-dir (a device call's results folder), not the working directory;
  without --out-dir it stays relative to the working directory, as before; an absolute --out stays as it is."""
  stem = lambda argv: R.results_stem(R.parse_args(["--task", "pick_egg"] + argv), "dev")  # noqa: E731
  assert stem(["--out-dir", str(tmp_path), "--out", "run_w0"]) == str(tmp_path / "run_w0")
  assert stem(["--out", "run_w0"]) == "run_w0"
  assert stem(["--out-dir", str(tmp_path), "--out", "/abs/run"]) == "/abs/run"
  assert stem(["--out-dir", str(tmp_path)]) == str(tmp_path / "rl_brax_pick_egg_dev")
  assert stem([]) == os.path.join(R.RESULTS, "rl_brax_pick_egg_dev")


def test_merge_records_runs_that_shared_one_device(tmp_path):
  """--shared-card N: the merged rows say their runs ran N at a time, and their time to 80 % says so."""
  import json
  row = dict(_row(2.0, 0, 0.9), time_to_80_safe_s=400.0,
             scored_curve={"action": "mode", "episodes": 256, "points": [{"wall_s": 400.0, "env_steps": 6_553_600}]})
  path = str(tmp_path / "p.json")
  with open(path, "w") as f:
    json.dump({"task": "place_plate", "task_settings": {}, "device": "NVIDIA H200", "recipe": {}, "rows": [row]}, f)
  assert R.main(["--merge", path, "--shared-card", "3", "--out", str(tmp_path / "m")]) == 0
  with open(tmp_path / "m.json") as f:
    assert [r["card_shared_by"] for r in json.load(f)["rows"]] == [3]
  assert "| 400 (6.6 M, device shared by 3 runs) |" in (tmp_path / "m.md").read_text()
  assert R.main(["--merge", path, "--out", str(tmp_path / "alone")]) == 0  # by default: nothing recorded
  with open(tmp_path / "alone.json") as f:
    assert "card_shared_by" not in json.load(f)["rows"][0]
  for bad in ("0", "-2"):
    with pytest.raises(ValueError, match="shared_card"):
      R.parse_args(["--merge", path, "--shared-card", bad])


def test_merge_refuses_unreadable_files_and_mixed_tasks(tmp_path):
  import json
  bad = tmp_path / "bad.json"
  bad.write_text("{not json")
  with pytest.raises(ValueError, match="merge: cannot read"):
    R.parse_args(["--merge", str(bad)])
  with pytest.raises(ValueError, match="merge: cannot read"):
    R.parse_args(["--merge", str(tmp_path / "missing.json")])
  paths = []
  for task in ("place_plate", "pick_egg"):
    paths.append(str(tmp_path / f"{task}.json"))
    with open(paths[-1], "w") as f:
      json.dump({"task": task, "device": "cpu", "rows": []}, f)
  with pytest.raises(ValueError, match="merge: files of one task only"):
    R.parse_args(["--merge", *paths])


def test_reward_preference_noisy_style_adds_gaussian_noise_to_the_scripted_action():
  P = load_benchmark("reward_preference")
  a = P.parse_args(["--tasks", "shelve_item", "--style", "shelve_item:safe+noise=0.3"])
  assert a.extra == {"shelve_item": ["safe+noise=0.3"]}
  assert P.parse_style("safe+noise=0.3") == ("safe", 0.3) and P.parse_style("still") == ("still", 0.0)
  for bad in ("safe+noise=-1", "safe+noise=nan", "safe+noise=x", "+noise=0.1"):
    with pytest.raises(ValueError, match="style"):
      P.parse_args(["--tasks", "shelve_item", "--style", f"shelve_item:{bad}"])
  base = lambda state, rng: jnp.full((4,), 0.5)
  assert P.noisy_policy(base, 0.0) is base
  acts = jax.vmap(lambda k: P.noisy_policy(base, 0.3)(None, k))(jax.random.split(jax.random.PRNGKey(0), 4096))
  assert float(jnp.max(acts)) <= 1.0 and float(jnp.min(acts)) >= -1.0
  assert abs(float(jnp.mean(acts)) - 0.5) < 0.02 and abs(float(jnp.std(acts)) - 0.3) < 0.02


EGG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "results",
                   "rl_pick_egg_nvidia_h200_held_std0_task_only_s345_rerun_task_only_policy.npz")  # ours, seeds 3,4,5


@pytest.mark.parametrize("argv, says", [
    (["--init-seed", "4"], "init_seed: picks a seed"),
    (["--init-from", "no/such/file.npz"], "init_from: no checkpoint at"),
    (["--task", "place_plate", "--init-from", EGG, "--init-seed", "4"], "init_from: .* made for task 'pick_egg'"),
    (["--init-from", EGG], "init_seed: .* holds seeds 3,4,5; say which"),
    (["--init-from", EGG, "--init-seed", "7"], r"init_seed: 7 is not a seed .*\(its seeds: 3, 4, 5\)"),
])
def test_bad_init_from_is_refused_naming_it(argv, says):
  with pytest.raises(ValueError, match=says):
    R.parse_args((["--task", "pick_egg"] if "--task" not in argv else []) + argv)


class _Stop(Exception):
  pass


def _capture_train(monkeypatch):
  """brax's ppo.train replaced by one that records its keywords in ``got`` and raises ``Stop``."""
  got = {}

  def fake_train(**kw):
    got.update(kw)
    raise _Stop

  monkeypatch.setattr(R.brax_ppo, "train", fake_train)
  return got, _Stop


def test_init_from_hands_brax_our_actor_and_a_fresh_value_function(monkeypatch):
  """brax's ppo.train gets that seed's normaliser and policy weights (restore_params), not its value net."""
  got, Stop = _capture_train(monkeypatch)
  a = R.parse_args(["--task", "pick_egg", "--init-from", EGG, "--init-seed", "4"])
  with pytest.raises(Stop):
    R.train_one("pick_egg", 2.0, 0, dict(R.PLAYGROUND_PANDA_PICK_CUBE), None, a.settings, init=a.init)
  env = R.tasks.make("pick_egg", **a.settings)
  want = load_policy(EGG, env, seed=4).params
  normaliser, policy, value = got["restore_params"]
  assert value is None and got["restore_value_fn"] is False
  for x, y in zip(jax.tree.leaves((normaliser, policy)), jax.tree.leaves(want), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  other = load_policy(EGG, env, seed=3).params[1]
  assert not all(np.array_equal(np.asarray(x), np.asarray(y))
                 for x, y in zip(jax.tree.leaves(policy), jax.tree.leaves(other)))


def test_a_row_from_a_trained_actor_says_so_and_keeps_its_own_key():
  a = {"damage_weight": 2.0, "seed": 0, "recipe": {}, "task_settings": {}}
  b = dict(a, init_from="p.npz", init_seed=4)
  assert R._std_label(b) == ", actor from p.npz seed 4" and R._key(a) != R._key(b)


def _brax_final(monkeypatch, params, step=123):
  """brax's ppo.train replaced by one that hands ``params`` to the run's callbacks, as brax does at its end;
  the 1024-episode scoring replaced by fixed metrics (nothing compiles)."""
  def fake_train(progress_fn, policy_params_fn, **kw):
    progress_fn(step, {"eval/episode_reward": 1.0})
    policy_params_fn(step, lambda *a, **k: None, params)

  metrics = {"completion": 1.0, "safe_completion": 1.0, "avg_health": 100.0, "cost_mean": 0.0, "episodes": 8}
  monkeypatch.setattr(R.brax_ppo, "train", fake_train)
  monkeypatch.setattr(R, "evaluate", lambda *a, **k: {"metrics": metrics})


def test_curve_keeps_brax_training_losses(monkeypatch):
  """Each curve point keeps brax's last-epoch losses (the value loss first of all), where brax reports them."""
  a = R.parse_args(["--task", "pick_egg", "--init-from", EGG, "--init-seed", "4"])
  env = R.tasks.make("pick_egg", **a.settings)
  params = load_policy(EGG, env, seed=4).params

  def fake_train(progress_fn, policy_params_fn, **kw):
    progress_fn(0, {"eval/episode_reward": 1.0})
    progress_fn(50, {"eval/episode_reward": 2.0, "training/v_loss": 1.4e15, "training/kl_mean": 0.02,
                     "training/policy_dist_mean_std": 0.8, "training/sps": 1e5})
    policy_params_fn(50, lambda *a, **k: None, params)

  monkeypatch.setattr(R.brax_ppo, "train", fake_train)
  monkeypatch.setattr(R, "evaluate", lambda *a, **k: {"metrics": {"completion": 0.0, "safe_completion": 0.0,
                                                                  "avg_health": 100.0, "cost_mean": 0.0, "episodes": 8}})
  row = R.train_one("pick_egg", 2.0, 0, dict(R.PLAYGROUND_PANDA_PICK_CUBE, eval_episodes=8), None, a.settings,
                    init=a.init)
  first, last = row["curve"]
  assert "v_loss" not in first
  assert last["v_loss"] == 1.4e15 and last["kl_mean"] == 0.02 and last["policy_dist_mean_std"] == 0.8
  assert "sps" not in last and "policy_loss" not in last


def test_export_policy_writes_brax_weights_that_every_reader_of_ours_takes(monkeypatch, tmp_path):
  """The exported file is a policy of our format: load_policy gives back exactly brax's weights, and it can
  start either trainer (init_source, check_init) with its run's seed."""
  a = R.parse_args(["--task", "pick_egg", "--init-from", EGG, "--init-seed", "4", "--export-policy"])
  env = R.tasks.make("pick_egg", **a.settings)
  brax_params = (*load_policy(EGG, env, seed=4).params, None)  # no value function given: none kept
  _brax_final(monkeypatch, brax_params)
  path = str(tmp_path / "sub" / R.os.path.basename(R.policy_path("stem", 2.0, 7)))
  cfg = dict(R.PLAYGROUND_PANDA_PICK_CUBE, eval_episodes=8)
  row = R.train_one("pick_egg", 2.0, 7, cfg, None, a.settings, init=a.init, export=path)
  assert row["policy_file"] == "stem_w2_s7_policy.npz" and os.path.isfile(path)
  got = load_policy(path, env)
  assert got.seed == 7 and got.meta["kind"] == "brax_ppo" and got.meta["env_steps"] == 123
  assert got.meta["init_seed"] == 4 and got.meta["config"]["damage_weight"] == 2.0
  assert got.meta["config"]["max_grad_norm"] is None  # the config records what brax ran, not our preset
  assert got.meta["value_state"] is False
  for x, y in zip(jax.tree.leaves(got.params), jax.tree.leaves(brax_params[:2]), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  assert R.check_init(path, None, "pick_egg") == (path, 7)
  with pytest.raises(ValueError, match="made for task 'pick_egg'"):
    R.check_init(path, None, "place_plate")


def _exported_with_value(monkeypatch, tmp_path, step=123):
  """A brax run of pick_egg (w = 2, seed 7) exported with a value function of the recipe's shape."""
  a = R.parse_args(["--task", "pick_egg", "--init-from", EGG, "--init-seed", "4", "--export-policy"])
  env = R.tasks.make("pick_egg", **a.settings)
  obs_size = int(jax.eval_shape(env.reset, jax.random.PRNGKey(0)).obs.shape[-1])
  value = R.network_factory(None)(obs_size, int(env.action_size)).value_network.init(jax.random.PRNGKey(5))
  params = (*load_policy(EGG, env, seed=4).params, value)
  _brax_final(monkeypatch, params, step=step)
  path = str(tmp_path / R.os.path.basename(R.policy_path("stem", 2.0, 7)))
  cfg = dict(R.PLAYGROUND_PANDA_PICK_CUBE, eval_episodes=8)
  R.train_one("pick_egg", 2.0, 7, cfg, None, a.settings, init=a.init, export=path)
  return path, env, params, cfg, a.settings


def test_continue_from_restores_the_whole_run_and_counts_on(monkeypatch, tmp_path):
  """--continue-from: brax gets the exported normaliser, policy and value function (restore_value_fn), and the
  row's env steps and seconds count on from the first call's; the continued export says what it continued."""
  path, env, params, cfg, settings = _exported_with_value(monkeypatch, tmp_path)
  for x, y in zip(jax.tree.leaves(R.continued_params(path, env, cfg)), jax.tree.leaves(params), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  cont = R.check_continue(path, "pick_egg", settings, None, [2.0], [7], cfg, None)
  got = {}

  def fake_train(progress_fn, policy_params_fn, **kw):
    got.update(kw)
    for step in (0, 50):
      progress_fn(step, {"eval/episode_reward": 1.0})
      policy_params_fn(step, lambda *a, **k: None, params)

  monkeypatch.setattr(R.brax_ppo, "train", fake_train)
  again = str(tmp_path / "again.npz")
  row = R.train_one("pick_egg", 2.0, 7, cfg, None, settings, export=again, cont=cont)
  assert got["restore_value_fn"] is True and len(got["restore_params"]) == 3
  first = R.ckpt.read_meta(path)
  assert row["env_steps"] == 123 + 50 and [c["env_steps"] for c in row["curve"]] == [123, 173]
  assert row["continued_from"] == {"file": os.path.basename(path), "env_steps": 123,
                                   "train_wall_s": first["train_wall_s"]}
  assert row["train_wall_s"] >= first["train_wall_s"] and row["curve"][0]["wall_s"] >= first["train_wall_s"]
  meta = R.ckpt.read_meta(again)
  assert meta["env_steps"] == 173 and meta["continued_from"] == os.path.basename(path) and meta["value_state"]
  assert "continued from" in R._std_label(row) and R._key(row) != R._key({k: v for k, v in row.items()
                                                                          if k != "continued_from"})


def test_continue_from_refuses_another_run_naming_the_flag(monkeypatch, tmp_path):
  path, env, params, cfg, settings = _exported_with_value(monkeypatch, tmp_path)
  ok = ("pick_egg", settings, None, [2.0], [7], cfg, None)
  for change, says in ((dict(weights=[0.0]), "damage weights"), (dict(seeds=[1]), "seeds"),
                       (dict(settings=dict(settings, start="pregrasp")), "task settings"),
                       (dict(cfg=dict(cfg, num_envs=64)), "num_envs"),
                       (dict(cfg=dict(cfg, max_grad_norm=1.0)), "max_grad_norm"),
                       (dict(init=(EGG, 4)), "not both")):
    args = dict(zip(("task", "settings", "eval_settings", "weights", "seeds", "cfg", "init"), ok), **change)
    with pytest.raises(ValueError, match=f"^continue_from: .*{says}"):
      R.check_continue(path, **args)
  with pytest.raises(ValueError, match="^continue_from: .*not a run this script exported"):
    R.check_continue(EGG, *ok)
  with pytest.raises(ValueError, match="^continue_from: no file"):
    R.check_continue(str(tmp_path / "none.npz"), *ok)


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf"])
def test_bad_max_grad_norm_is_refused_naming_it(value):
  with pytest.raises(ValueError, match="max_grad_norm"):
    R.parse_args([f"--max-grad-norm={value}"])


def test_max_grad_norm_reaches_brax_its_export_and_the_row_label(monkeypatch, tmp_path):
  """--max-grad-norm 1: brax's ppo.train clips at 1 (stock: None), the exported config records it, and the
  row says so; a clipped run cannot be continued as an unclipped one."""
  got, Stop = _capture_train(monkeypatch)
  a = R.parse_args(["--task", "pick_egg"])
  for clip in (None, 1.0):
    cfg = dict(R.PLAYGROUND_PANDA_PICK_CUBE, **({} if clip is None else {"max_grad_norm": clip}))
    with pytest.raises(Stop):
      R.train_one("pick_egg", 2.0, 0, cfg, None, a.settings)
    assert got["max_grad_norm"] == clip
  assert R._std_label({"recipe": {"max_grad_norm": 1.0}}) == ", gradient norm clipped at 1"
  assert R._std_label({"recipe": {}}) == ""
  path, env, params, cfg, settings = _exported_with_value(monkeypatch, tmp_path)
  clipped = str(tmp_path / "clipped.npz")
  R.train_one("pick_egg", 2.0, 7, dict(cfg, max_grad_norm=1.0), None, settings, export=clipped)
  assert R.ckpt.read_meta(clipped)["config"]["max_grad_norm"] == 1.0
  assert R.ckpt.read_meta(path)["config"]["max_grad_norm"] is None
  R.check_continue(clipped, "pick_egg", settings, None, [2.0], [7], dict(cfg, max_grad_norm=1.0), None)
  with pytest.raises(ValueError, match="^continue_from: .*max_grad_norm"):
    R.check_continue(clipped, "pick_egg", settings, None, [2.0], [7], cfg, None)


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf"])
def test_bad_obs_clip_is_refused_naming_it(value):
  with pytest.raises(ValueError, match="obs_clip"):
    R.parse_args([f"--obs-clip={value}"])


def test_obs_clip_bounds_what_both_networks_see_and_is_recorded(monkeypatch, tmp_path):
  """--obs-clip 5: brax's networks get the normalised observation clipped at ±5 (stock: unbounded), the
  exported config records it so our loader builds the same networks, and a run cannot be continued without it."""
  stats = running_statistics.init_state(jnp.zeros((3,), jnp.float32))  # mean 0, std 1: normalised = raw
  near, far = jnp.array([[5.0, -5.0, 1.0]]), jnp.array([[5e6, -5e6, 1.0]])
  for clip, same in ((5.0, True), (None, False)):
    nets = R.network_factory((-0.5, -1.5), clip)(3, 2, preprocess_observations_fn=running_statistics.normalize)
    pol = nets.policy_network.init(jax.random.PRNGKey(0))
    val = nets.value_network.init(jax.random.PRNGKey(1))
    for net, w in ((nets.policy_network, pol), (nets.value_network, val)):
      a, b = net.apply(stats, w, near), net.apply(stats, w, far)
      assert bool(jnp.allclose(a, b)) is same
  got, Stop = _capture_train(monkeypatch)
  a = R.parse_args(["--task", "pick_egg", "--obs-clip", "5"])
  with pytest.raises(Stop):
    R.train_one("pick_egg", 2.0, 0, dict(R.PLAYGROUND_PANDA_PICK_CUBE, obs_clip=5.0), None, a.settings)
  nets = got["network_factory"](3, 2, preprocess_observations_fn=running_statistics.normalize)
  w = nets.value_network.init(jax.random.PRNGKey(1))
  assert bool(jnp.allclose(nets.value_network.apply(stats, w, near), nets.value_network.apply(stats, w, far)))
  assert R._std_label({"recipe": {"obs_clip": 5.0}}) == ", observations clipped at ±5"
  path, env, params, cfg, settings = _exported_with_value(monkeypatch, tmp_path)
  clipped = str(tmp_path / "obs_clipped.npz")
  R.train_one("pick_egg", 2.0, 7, dict(cfg, obs_clip=5.0), None, settings, export=clipped)
  assert R.ckpt.read_meta(clipped)["config"]["obs_clip"] == 5.0
  assert load_policy(clipped, env).meta["config"]["obs_clip"] == 5.0
  with pytest.raises(ValueError, match="^continue_from: .*obs_clip"):
    R.check_continue(clipped, "pick_egg", settings, None, [2.0], [7], cfg, None)


def test_export_policy_never_replaces_an_earlier_runs_weights(tmp_path):
  stem = str(tmp_path / "rl_brax_pick_egg_x")
  earlier = R.policy_path(stem, 2.0, 1)
  with open(earlier, "wb") as f:
    f.write(b"weights of an earlier run")
  with pytest.raises(ValueError, match=r"export_policy: .*_w2_s1_policy.npz already exist"):
    R.main(["--task", "pick_egg", "--damage-weights", "0,2", "--seeds", "0,1", "--export-policy", "--out", stem])
  with open(earlier, "rb") as f:
    assert f.read() == b"weights of an earlier run"
  assert not os.path.exists(stem + ".json")  # refused before any run


def test_each_evaluation_is_scored_off_the_clock_and_gives_the_time_to_80_safe(monkeypatch):
  """--curve-episodes: the policy of every brax evaluation is scored by our evaluator (built once, the weights
  as data); the scorings' seconds count neither in the run's clock nor against --budget-seconds."""
  import time

  scores = iter([(0.5, 0.0), (0.9, 0.7), (0.95, 0.85), (1.0, 1.0)])  # (completion, safe) of each evaluation
  built, runs = [], []

  class Scorer:
    def run(self, keys, fragility, params=None):
      runs.append((len(keys), params))
      time.sleep(0.4)  # a scoring slower than the budget: it must not stop the run
      return next(scores)

  def fake_make_evaluator(env, policy, episode_length):
    built.append(policy)
    return Scorer()

  def fake_train(progress_fn, policy_params_fn, **kw):
    for step in (0, 100, 200, 300):
      policy_params_fn(step, lambda *a, **k: None, f"weights at {step}")
      progress_fn(step, {"eval/episode_reward": 1.0})

  final = {"completion": 1.0, "safe_completion": 1.0, "avg_health": 100.0, "cost_mean": 0.0, "episodes": 8}
  monkeypatch.setattr(R.brax_ppo, "train", fake_train)
  monkeypatch.setattr(R, "make_evaluator", fake_make_evaluator)
  monkeypatch.setattr(R, "eval_metrics", lambda per_ep, names: {"completion": per_ep[0], "safe_completion": per_ep[1],
                                                                 "cost_mean": 0.0})
  monkeypatch.setattr(R, "evaluate", lambda *a, **k: {"metrics": final})
  cfg = dict(R.PLAYGROUND_PANDA_PICK_CUBE, eval_episodes=8)
  row = R.train_one("place_plate", 2.0, 0, cfg, 0.3, {}, curve_episodes=16)
  assert len(built) == 1 and [r[0] for r in runs] == [16] * 4
  assert [r[1] for r in runs] == [f"weights at {s}" for s in (0, 100, 200, 300)]
  c = row["scored_curve"]
  assert c["episodes"] == 16 and c["action"] == "mode" and c["seconds"] >= 1.6
  assert [(p["env_steps"], p["completion"], p["safe_completion"]) for p in c["points"]] == [
      (0, 0.5, 0.0), (100, 0.9, 0.7), (200, 0.95, 0.85), (300, 1.0, 1.0)]
  assert not row["stopped_by_budget"] and row["train_wall_s"] < 0.3 and row["curve"][-1]["wall_s"] < 0.3
  assert row["time_to_80_safe_s"] == c["points"][2]["wall_s"]  # the first with safe and completion >= 0.8
  doc = {"task": "place_plate", "task_settings": {}, "device": "cpu", "recipe": {},
         "rows": [dict(row, command="c", date="2026-11-29 10:00:00 UTC")]}
  assert f"| {row['time_to_80_safe_s']:.0f} (0.0 M) |" in R.render_md(doc)
  never = dict(row, time_to_80_safe_s=None)
  assert "| not reached (4 evaluations) |" in R.render_md(dict(doc, rows=[dict(never, command="c")]))
  earlier = {k: v for k, v in row.items() if k not in ("scored_curve", "time_to_80_safe_s")}
  assert "| not scored |" in R.render_md(dict(doc, rows=[dict(earlier, command="c")]))

  assert "scored_curve" not in R.train_one("place_plate", 2.0, 0, cfg, None, {})  # off unless asked
  with pytest.raises(ValueError, match="curve_episodes"):
    R.parse_args(["--curve-episodes", "-1"])


def test_a_row_trained_at_float32_matmuls_says_so(tmp_path):
  """Rows record the matmul precision they trained at (--matmul-precision or JAX_DEFAULT_MATMUL_PRECISION); the
  table labels a float32 one, and rows written before it was recorded read as the default."""
  import json
  path = str(tmp_path / "p.json")
  rows = [dict(_row(2.0, 0, 0.9), matmul_precision="float32"), _row(2.0, 1, 0.9)]
  with open(path, "w") as f:
    json.dump({"task": "place_plate", "task_settings": {}, "device": "NVIDIA H200", "recipe": {}, "rows": rows}, f)
  assert R.main(["--merge", path, "--out", str(tmp_path / "m")]) == 0
  lines = [ln for ln in (tmp_path / "m.md").read_text().splitlines() if ln.startswith("| w 2")]
  assert len(lines) == 2 and ", float32 matmuls |" in lines[0] and "matmuls" not in lines[1]

"""benchmarks/reward_preference.py: trained policies as styles, and the policy the others are compared with."""

import json
import os

import numpy as np
import pytest
from conftest import load_benchmark

P = load_benchmark("reward_preference")

RESULTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "results")
# Shelve Item, trained on an H200 (route starts, health_lost cost), evaluated from the in_front start
LIFT = "checkpoint:" + os.path.join(RESULTS, "rl_shelve_item_nvidia_h200_h200_ours_task_only_f32_s1_task_only_policy.npz#1")
HEALTH_LOST = '--task-settings={"cost": "health_lost"}'


def test_a_checkpoint_style_is_taken_in_the_settings_it_was_evaluated_in():
  a = P.parse_args(["--tasks", "shelve_item", HEALTH_LOST, "--style", f"shelve_item:{LIFT}",
                    "--baseline", f"shelve_item:{LIFT}"])
  assert a.extra == {"shelve_item": [LIFT]} and a.baselines == {"shelve_item": LIFT}
  assert a.trained["shelve_item"][LIFT] == {"robot": "gripper", "start": "in_front", "cost": "health_lost"}
  assert P.is_checkpoint(LIFT) and P.is_checkpoint(LIFT.replace("checkpoint:", "checkpoint+sample:"))
  assert not P.is_checkpoint("safe") and not P.is_checkpoint("still")


@pytest.mark.parametrize("argv, says", [
    # the run's cost differs from the one the policy was evaluated with: refused, naming the key
    (["--style", f"shelve_item:{LIFT}"], r"style: checkpoint .* evaluated with \{'cost': 'health_lost'\}, this run "
                                          r"has \{'cost': 'damage'\}"),
    ([HEALTH_LOST, "--robot", "panda", "--style", f"shelve_item:{LIFT}"], r"style: .*'robot': 'gripper'.*'robot': 'panda'"),
    ([HEALTH_LOST, "--style", "shelve_item:checkpoint:no/such/run.npz#0"], "policy: checkpoint 'no/such/run.npz' does not exist"),
    ([HEALTH_LOST, "--style", f"shelve_item:{LIFT[:-2]}#7"], "policy: seed 7 is not a seed"),
    ([HEALTH_LOST, "--style", "shelve_item:safe"], "style: 'shelve_item:safe' is given twice"),
    (["--baseline", "shelve_item:still"], "baseline: expected TASK:STYLE"),
    (["--baseline", "pick_egg:safe"], "baseline: expected TASK:STYLE"),
    (["--baseline", "shelve_item:unsafe", "--baseline", "shelve_item:safe"], "baseline: one per task"),
])
def test_bad_styles_and_baselines_are_refused_naming_them(argv, says):
  with pytest.raises(ValueError, match=says):
    P.parse_args(["--tasks", "shelve_item"] + argv)


def test_a_checkpoint_style_is_the_trained_policy():
  """make_policy gives the checkpoint's policy (the seed asked for, weights as data) for a checkpoint style."""
  env = P.tasks.make("shelve_item", robot="gripper", cost="health_lost")
  policy = P.make_policy(env, LIFT)
  assert policy.seed == 1 and "params" in dir(policy)


def test_comparisons_are_against_the_baseline(tmp_path):
  """Every style but the baseline is compared with it on the same episodes; the table says with which."""
  out = tmp_path / "r"
  argv = ["--tasks", "place_plate", "--episodes", "2", "--gammas", "0.97", '--task-settings={"episode_length": 4}',
          "--style", "place_plate:still", "--baseline", "place_plate:unsafe", "--out-dir", str(out), "--tag", "t"]
  assert P.main(argv) == 0
  res = json.loads((out / "reward_preference_t.json").read_text())
  task = res["tasks"][0]
  assert task["baseline"] == "unsafe"
  assert [(c["policy"], c["vs"]) for c in task["comparisons"]] == [("safe", "unsafe"), ("still", "unsafe")]
  rows = {r["policy"]: r for r in task["rows"]}
  for c in task["comparisons"]:  # the paired mean difference is the difference of the two policies' means
    want = rows[c["policy"]]["return_gamma_0.97"]["mean"] - rows["unsafe"]["return_gamma_0.97"]["mean"]
    np.testing.assert_allclose(c["return_gamma_0.97_diff_mean"], want, atol=1e-9)
  md = (out / "reward_preference_t.md").read_text()
  assert "| place_plate | still | unsafe |" in md and "| place_plate | safe | unsafe |" in md


def _ckpt(name: str, seed: int) -> str:
  return f"checkpoint:{os.path.join(RESULTS, name)}#{seed}"


@pytest.mark.slow
@pytest.mark.parametrize("task, settings, shortcut, safe", [
    # Place Plate: ours with the std a parameter, task only (drops) and w = 2 (gentle), seed 0 of each
    ("place_plate", None, _ckpt("rl_place_plate_nvidia_h200_box_stdparam_300s_task_only_s012_task_only_policy.npz", 0),
     _ckpt("rl_place_plate_nvidia_h200_box_stdparam_300s_s012_penalty_policy.npz", 0)),
    # Pick Egg: Brax's crushing carry (task only, both guards) against our safe carry after the warm-up
    ("pick_egg", '{"start": "pregrasp", "carry_reward": "held"}',
     _ckpt("rl_brax_pick_egg_held_std0_clip_obsclip_w0_430s_s1_w0_s1_policy.npz", 1),
     _ckpt("rl_pick_egg_nvidia_h200_held_std0_penalty_warmup_obsclip_penalty_policy.npz", 0)),
    # Shelve Item: a shove and the lift, both learnt from task reward alone (the lead is smallest here)
    ("shelve_item", '{"cost": "health_lost"}', _ckpt("rl_shelve_item_nvidia_h200_h200_ours_task_only_f32_s2_task_only_policy.npz", 2),
     LIFT),
])
def test_the_task_reward_pays_a_learned_shortcut_more_than_a_learned_safe_policy(tmp_path, task, settings, shortcut, safe):
  """The task design's claim for learned strategies (docs/rl_task_design.md, "The shortcut's lead among learned
  policies"): a committed policy that takes the shortcut earns more discounted task return than one that does not,
  on nearly every paired episode; a change to a task's reward or dynamics that erases the lead fails here."""
  argv = ["--tasks", task, "--episodes", "32", "--gammas", "0.97", "--style", f"{task}:{shortcut}",
          "--style", f"{task}:{safe}", "--baseline", f"{task}:{safe}", "--out-dir", str(tmp_path), "--tag", "t"]
  assert P.main(argv + ([f"--task-settings={settings}"] if settings else [])) == 0
  res = json.loads((tmp_path / "reward_preference_t.json").read_text())["tasks"][0]
  rows = {r["policy"]: r for r in res["rows"]}
  assert rows[shortcut]["completion_pct"] >= 90 and rows[shortcut]["safe_completion_pct"] <= 10
  assert rows[safe]["completion_pct"] >= 90 and rows[safe]["safe_completion_pct"] >= 80
  lead = next(c for c in res["comparisons"] if c["policy"] == shortcut)
  assert lead["return_gamma_0.97_diff_mean"] > 0.5 and lead["return_gamma_0.97_unsafe_higher_pct"] >= 90

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

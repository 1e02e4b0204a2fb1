"""benchmarks/place_plate_outcomes.py: how trained Place Plate policies end their episodes (bad values refused
before anything is built; the classification of a trace; one short run of a committed policy)."""

import json
import os

import numpy as np
import pytest
from conftest import BENCHMARKS, load_benchmark

outcomes = load_benchmark("place_plate_outcomes")
POLICY = os.path.join(BENCHMARKS, "results", "rl_brax_place_plate_box_h200_alone_s4_w2_s4_policy.npz")


@pytest.mark.parametrize("argv, says", [
    (["--policies", " , "], "policies: give at least one"),
    (["--policies", "no/such/file.npz#0"], "does not exist"),
    (["--policies", POLICY + "#7"], "seed 7 is not a seed"),
    (["--policies", POLICY + "#4", "--actions", "mode,greedy"], "actions: greedy"),
    (["--policies", POLICY + "#4", "--episodes", "0"], "episodes"),
    (["--policies", POLICY + "#4", "--clearance", "nan"], "clearance"),
    (["--policies", POLICY + "#4", "--clearance", "0.2"], "clearance"),
    (["--policies", POLICY + "#4", "--task-arg", "obs_mode=\"full\""], "trained with obs_mode='paper'"),
    (["--policies", POLICY + "#4", "--task-arg", "robot=\"panda\""], "trained with robot='gripper'"),
    (["--policies", POLICY + "#4", "--task-arg", "hand_speed=-1"], "hand_speed"),
])
def test_refuses_bad_values_before_anything_compiles(argv, says, tmp_path, capsys):
  with pytest.raises(SystemExit):
    outcomes.main(argv + ["--results-dir", str(tmp_path)])
  assert says in capsys.readouterr().err
  assert not os.listdir(tmp_path)


def test_classify_tells_placed_let_go_and_never_let_go_apart():
  """Four episodes of 5 steps (rest 1 cm, plate 12 cm wide, clearance 5 mm, 0.1 s steps): one placed, one whose
  fingers open with the plate 5 cm up and that falls 4 cm in a step, one held at 4 cm to the end, and one set
  down and let go at rest without the task's success (let go, not placed; no release height)."""
  rest, width = 0.01, 0.12
  z = np.array([[0.10, 0.10, 0.10, 0.10],
                [0.06, 0.06, 0.06, 0.06],
                [0.03, 0.06, 0.05, 0.03],
                [0.01, 0.02, 0.05, 0.01],
                [0.01, 0.01, 0.05, 0.01]])
  plate = np.stack([np.zeros_like(z), np.zeros_like(z), z], -1)
  gap = np.full_like(z, 0.12)
  gap[4:, 0] = 0.15  # placed, then opened at rest: not a let-go above the counter
  gap[2:, 1] = 0.14  # opened at 6 cm (5 cm above rest)
  gap[4:, 3] = 0.15  # opened at rest, no success (say, out of the goal's 3 cm)
  success = np.zeros_like(z)
  success[4, 0] = 1.0
  c = outcomes.classify(plate, gap, success, rest, width, 0.005, 0.1)
  assert c["outcome"].tolist() == [0, 1, 2, 1]
  assert np.isnan(c["release_height_m"][[0, 2, 3]]).all()
  assert c["release_height_m"][1] == pytest.approx(0.05)
  assert c["held_low_m"][2] == pytest.approx(0.04)
  # first step within 2 mm of rest: episode 0 at step 3 (3 → 1 cm), episode 1 at step 4 (2 → 1 cm); 2 never
  np.testing.assert_allclose(c["touchdown_speed_m_s"][[0, 1, 3]], [0.2, 0.1, 0.2])
  assert np.isnan(c["touchdown_speed_m_s"][2])
  s = outcomes.summarise(c, np.array([100.0, 40.0, 100.0, 100.0]))
  assert s["fractions"] == pytest.approx({"placed": 0.25, "let go, not placed": 0.5, "never let go": 0.25})
  assert s["plate_intact_rate"] == pytest.approx(0.75)
  assert s["release_height_cm_median"] == pytest.approx(5.0)
  assert s["never_let_go_held_at_cm_median"] == pytest.approx(4.0)


def test_a_committed_policy(tmp_path):
  """A committed Brax policy, 2 episodes by its mode on the counter it was trained on, with the spread probe: the
  file records every episode's outcome, the fractions add up, and the sampled action's scale at the first and
  the last step is one positive number per action dimension."""
  argv = ["--policies", POLICY + "#4", "--actions", "mode", "--episodes", "2", "--spread",
          "--results-dir", str(tmp_path), "--tag", "t"]
  assert outcomes.main(argv) == 0
  with open(tmp_path / "place_plate_outcomes_t.json") as f:
    res = json.load(f)
  (row,) = res["rows"]
  assert row["seed"] == 4 and row["action"] == "mode" and len(row["outcome_per_episode"]) == 2
  assert res["task_kwargs"]["counter"] == "box"
  assert sum(row["summary"]["fractions"].values()) == pytest.approx(1.0)
  md = open(tmp_path / "place_plate_outcomes_t.md").read()
  assert "| rl_brax_place_plate_box_h200_alone_s4_w2_s4_policy.npz | 4 | mode |" in md
  first, last = row["summary"]["sampled_spread_first_step"], row["summary"]["sampled_spread_last_step"]
  assert len(first) == len(last) == 4  # three hand dimensions and the gripper
  assert all(np.isfinite(v) and 0 < v < 5 for v in first + last), (first, last)
  assert "| rl_brax_place_plate_box_h200_alone_s4_w2_s4_policy.npz | 4 | " + " / ".join(f"{v:.2f}" for v in first) in md


def test_noise_mixture_takes_the_sample_on_the_named_dimensions_only():
  """arm_noise: the sampled action on every dimension but the last (the gripper), the mode there; gripper_noise:
  the reverse. An unknown mixture is refused."""
  import jax.numpy as jnp
  mode = lambda params, state, key: jnp.zeros(4)
  sample = lambda params, state, key: jnp.arange(1.0, 5.0)
  np.testing.assert_array_equal(outcomes.noise_mixture(mode, sample, "arm_noise")(None, None, None), [1, 2, 3, 0])
  np.testing.assert_array_equal(outcomes.noise_mixture(mode, sample, "gripper_noise")(None, None, None), [0, 0, 0, 4])
  with pytest.raises(ValueError, match="action: 'sample'"):
    outcomes.noise_mixture(mode, sample, "sample")


def test_spread_is_measured_at_the_first_and_the_last_step():
  """A stand-in env whose state counts the steps and a policy whose second dimension's noise grows with it: the
  scale before the tanh is ~(0.5, 0) at the first step and ~(0.5, 0.1·(T − 1)) after the mode's T − 1 steps."""
  import jax
  import jax.numpy as jnp
  from types import SimpleNamespace
  env = SimpleNamespace(reset=lambda key: jnp.zeros(()), step=lambda x, a: x + 1.0 + 0.0 * a.sum())
  mode = lambda params, x, key: jnp.zeros(2)
  # tanh-squashed, the first dimension's mean far out on the tanh: its scale is found before the squash
  scale = lambda x: jnp.stack([0.5, 0.1 * x])
  sample = lambda params, x, key: jnp.tanh(jnp.array([2.0, 0.0]) + jax.random.normal(key, (2,)) * scale(x))
  s = np.asarray(outcomes.spread_program(env, mode, sample, 5)(None, jax.random.split(jax.random.PRNGKey(0), 3)))
  assert s.shape == (3, 2, 2)
  np.testing.assert_allclose(s[:, 0], [[0.5, 0]] * 3, atol=0.07)
  np.testing.assert_allclose(s[:, 1], [[0.5, 0.4]] * 3, atol=0.07)

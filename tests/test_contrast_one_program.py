"""benchmarks/contrast_one_program.py: both rewards of a contrast as runs of one program, timed against one.

A tiny run on the pusher env writes both programs' rows and their ratio; bad input and an existing results
file are refused (exit 2, naming the field) before anything compiles.
"""

import json
import os

import pytest
from conftest import load_benchmark

C = load_benchmark("contrast_one_program")

TINY = ["--task", "train.experiments.pusher:PusherEnv", "--task-settings", "{}", "--preset", "paper",
        "--num-envs", "8", "--unroll-length", "8", "--iterations", "2", "--seeds", "0,1"]


def test_layouts_give_the_second_reward_new_seeds():
  assert C.layouts((0, 1, 2), 2.0) == [((0, 1, 2), (2.0, 2.0, 2.0)),
                                       ((0, 1, 2, 3, 4, 5), (0.0, 0.0, 0.0, 2.0, 2.0, 2.0))]


def test_a_tiny_run_times_both_programs_and_refuses_to_overwrite(tmp_path, capsys):
  args = TINY + ["--results-dir", str(tmp_path), "--tag", "t"]
  assert C.main(args) == 0
  with open(tmp_path / "contrast_one_program_pusherenv_cpu_t.json") as f:
    res = json.load(f)
  one, two = res["rows"]
  assert (one["runs"], two["runs"]) == (2, 4)
  assert (one["damage_weights"], two["damage_weights"]) == ([2.0, 2.0], [0.0, 0.0, 2.0, 2.0])
  assert two["env_steps_per_iteration_all_runs"] == 2 * one["env_steps_per_iteration_all_runs"] == 4 * 64
  assert one["timed_iterations"] == two["timed_iterations"] == 1
  assert res["ratio"] == pytest.approx(two["s_per_iteration"] / one["s_per_iteration"], rel=1e-2)
  md = (tmp_path / "contrast_one_program_pusherenv_cpu_t.md").read_text()
  assert "benchmarks/contrast_one_program.py" in md and "| both rewards | 4 | 0, 0, 2, 2 |" in md
  capsys.readouterr()
  assert C.main(args) == 2  # the file is there: not replaced without --overwrite
  err = capsys.readouterr().err
  assert "--tag:" in err and "already exists" in err and "--overwrite" in err
  assert (tmp_path / "contrast_one_program_pusherenv_cpu_t.md").read_text() == md


@pytest.mark.parametrize("extra, named", [
    (["--iterations", "1"], "iterations:"),
    (["--seeds", "0,0"], "seeds:"),
    (["--task-settings", "[1]"], "task_settings:"),
    (["--task-settings", "{"], "task_settings:"),
    (["--num-envs", "12"], "num_envs:"),
    (["--preset", "nope"], "preset:"),
    (["--task", "no_such_task"], "task:"),
])
def test_bad_input_is_refused_before_anything_compiles(extra, named, tmp_path, capsys):
  assert C.main(TINY + extra + ["--results-dir", str(tmp_path)]) == 2
  assert named in capsys.readouterr().err
  assert not os.listdir(tmp_path)

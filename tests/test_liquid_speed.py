"""benchmarks/liquid_speed.py: refuses bad input before anything compiles, and a toy run writes its rows.

The measurement itself is a benchmark (results/liquid_speed_gpu.md)."""

import json

import pytest
from conftest import load_benchmark

ls = load_benchmark("liquid_speed")


@pytest.mark.parametrize("argv, field", [
    (["--variants", "full,warp"], "--variants"),
    (["--variants", "two_pass+iter3"], "--variants"),
    (["--envs", "0"], "--envs"),
    (["--substeps", "-1"], "--substeps"),
    (["--task", "nope"], "--task"),
    (["--robot", "no_such_robot"], "--robot"),
])
def test_cli_names_the_bad_field(argv, field, capsys):
  with pytest.raises(SystemExit) as e:
    ls.main(argv)
  assert e.value.code == 2 and field in capsys.readouterr().err


def test_a_task_without_liquid_is_refused():
  with pytest.raises(SystemExit, match="--task: place_plate has no liquid"):
    ls.main(["--task", "place_plate", "--envs", "1", "--substeps", "1", "--variants", "full"])


def test_toy_run_writes_one_row_per_variant(tmp_path):
  out = tmp_path / "ls.json"
  assert ls.main(["--envs", "2", "--substeps", "1", "--repeats", "1", "--variants", "full,no_pairs",
                  "--out", str(out)]) == 0
  res = json.loads(out.read_text())
  assert [r["variant"] for r in res["rows"]] == ["full", "no_pairs"]
  assert all(r["particle_substeps_per_s"] > 0 and r["particles"] == 128 for r in res["rows"])
  assert res["command"].startswith("python benchmarks/liquid_speed.py")


def test_combined_variants_apply_each_part():
  """``two_pass+iter2``: both changes in one model, each part alone changes only its own field."""
  import tasks

  lm = tasks.make("pour_water", robot="gripper").unwrapped.damage_binding.liquid
  both = ls.variant_model(lm, "two_pass+iter2")
  assert (both.pair_passes, both.iterations) == (2, 2)
  assert (lm.pair_passes, lm.iterations) == (1, 1)  # the task's own: one pair pass, one geom pass
  assert ls.variant_model(lm, "two_pass").iterations == lm.iterations

"""benchmarks/step_overhead.py: its command line refuses bad input before anything compiles, and a
precompile child gets the parent's command with only its own share of the work.

The measurement itself is a benchmark (results under benchmarks/results/step_overhead_*)."""

import pytest
from conftest import load_benchmark

from apps.workers import argv_without

so = load_benchmark("step_overhead")


@pytest.mark.parametrize("argv,field", [
    (["--robot", "ur5"], "--robot"),
    (["--robot", "panda", "--tasks", "navigate_and_pick"], "--tasks"),
    (["--precompile-workers", "-1"], "--precompile-workers"),
    (["--variants", "task,warp"], "--variants"),
    (["--envs", "0"], "--envs"),
])
def test_cli_names_the_bad_field(argv, field, capsys):
  with pytest.raises(SystemExit) as e:
    so.main(argv)
  assert e.value.code == 2 and field in capsys.readouterr().err


def test_children_get_the_command_without_the_per_child_flags():
  argv = ["--envs", "32768", "--precompile-workers=6", "--tasks", "a,b", "--robot", "panda", "--variants", "task,raw"]
  assert argv_without(argv, ("--precompile-workers", "--tasks", "--variants")) == ["--envs", "32768", "--robot", "panda"]

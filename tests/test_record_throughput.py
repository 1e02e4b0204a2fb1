"""benchmarks/record_throughput.py refuses bad flags before building or compiling anything."""

import pytest

from conftest import load_benchmark


@pytest.mark.parametrize("flags, named", [
    (["--tasks", "no_such_task"], "--tasks"), (["--operator", "sloppy"], "--operator"),
    (["--episodes", "0"], "--episodes"), (["--chunk", "-1"], "--chunk"),
    (["--steady-episodes", "300"], "--steady-episodes")])
def test_bad_flags_exit_2_naming_the_flag(flags, named, capsys):
  with pytest.raises(SystemExit) as e:
    load_benchmark("record_throughput").main(flags)
  assert e.value.code == 2
  assert named in capsys.readouterr().err

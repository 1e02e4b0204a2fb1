"""benchmarks/il_temperature.py refuses bad flags before recording or compiling anything."""

import pytest
from conftest import load_benchmark


@pytest.mark.parametrize("flags, named", [
    (["--task", "no_such_task"], "--task"), (["--operator", "sloppy"], "--operator"),
    (["--demos", "0"], "--demos"), (["--seeds", "0"], "--seeds"), (["--temperatures", "x"], "--temperatures"),
    (["--temperatures", "-1"], "--temperatures"), (["--temperatures", "nan"], "--temperatures"),
    (["--robot", "no_such_robot"], "--robot")])
def test_bad_flags_exit_2_naming_the_flag(flags, named, capsys):
  with pytest.raises(SystemExit) as e:
    load_benchmark("il_temperature").parse(flags)
  assert e.value.code == 2
  assert named in capsys.readouterr().err


def test_the_temperature_grid_parses():
  a = load_benchmark("il_temperature").parse(["--temperatures", "0, 0.5,1"])
  assert a.temperature_list == [0.0, 0.5, 1.0]

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


def test_the_timing_process_loads_what_the_precompile_children_compiled(tmp_path):
  """The children must fill the cache this process reads (they once filled another directory, so every
  program compiled twice: in a child, then again while timing)."""
  import json
  import os
  import subprocess
  import sys

  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))  # the package's default cache, in tmp
  for k in ("MJX_DAMAGE_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR"):
    env.pop(k, None)
  p = subprocess.run([sys.executable, "benchmarks/step_overhead.py", "--tasks", "pick_egg", "--variants", "raw",
                      "--envs", "3", "--steps", "1", "--repeats", "1", "--precompile-workers", "1",
                      "--out-dir", str(tmp_path)], cwd=root, env=env, capture_output=True, text=True, timeout=600)
  assert p.returncode == 0, p.stderr[-2000:]
  row, = json.load(open(tmp_path / "step_overhead_cpu.json"))["results"]
  assert row["from_cache"], p.stdout

"""Regression test for the XLA:CPU deadlock of batched MJX calls (see mjx_damage/runtime.py).

A single jit(vmap) call of 512 place_plate envs stalled forever on a 2-core
machine before the package set its XLA:CPU scheduler flag. Each check runs in a
fresh process (XLA reads its flags once per process) under a timeout, so a
regression fails the test instead of freezing the suite.
"""

import os
import subprocess
import sys

import pytest
from conftest import load_benchmark

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "benchmarks", "cpu_stall.py")


def _loop(checks: str, repeats: int, calls: int, timeout: float):
  r = subprocess.run(
      [sys.executable, SCRIPT, "--checks", checks, "--modes", "fix", "--repeats", str(repeats),
       "--envs", "512", "--calls", str(calls), "--timeout", str(timeout), "--out", "-"],
      cwd=ROOT, capture_output=True, text=True, timeout=repeats * (timeout + 60) * len(checks.split(",")))
  assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
  assert "STALLED" not in r.stdout


def test_package_sets_the_cpu_flags():
  code = "import mjx_damage, os; print(os.environ['XLA_FLAGS'])"
  env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "MJX_DAMAGE_XLA_CPU_FIX")}
  out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
  assert "--xla_cpu_enable_concurrency_optimized_scheduler=false" in out
  assert "--xla_cpu_use_fusion_emitters=false" in out
  # a user's own choice for a flag is kept, the other one is still added
  env["XLA_FLAGS"] = "--xla_cpu_enable_concurrency_optimized_scheduler=true"
  out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
  assert out.split() == ["--xla_cpu_enable_concurrency_optimized_scheduler=true", "--xla_cpu_use_fusion_emitters=false"]


def test_flags_only_for_jaxlibs_that_know_them():
  # jaxlib 0.11's XLA aborts the process on an unknown flag: the fusion-emitter flag is gone there
  from mjx_damage import runtime
  assert runtime.cpu_flags((0, 10)) == runtime.CPU_FLAGS
  assert runtime.cpu_flags((0, 11)) == (runtime.CPU_SCHEDULER_FLAG,)
  assert runtime.cpu_flags((1, 0)) == (runtime.CPU_SCHEDULER_FLAG,)


def test_import_after_backend_start_warns():
  code = ("import jax, warnings; jax.devices(); warnings.simplefilter('error');\n"
          "try:\n  import mjx_damage\nexcept RuntimeWarning as e:\n  print('warned', e)")
  env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "MJX_DAMAGE_XLA_CPU_FIX")}
  out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True).stdout
  assert out.startswith("warned") and "XLA_FLAGS" in out


def test_unknown_robot_refused_naming_the_flag(capsys):
  """--robot is checked before any child process starts."""
  with pytest.raises(SystemExit) as e:
    load_benchmark("cpu_stall").main(["--robot", "no_such_robot", "--out", "-"])
  assert e.value.code == 2 and "--robot" in capsys.readouterr().err


def test_one_call_of_512_envs_finishes():
  """The call that deadlocked: 512 envs of a task step, and the 4-Cholesky reproduction."""
  _loop("task,cholesky", repeats=1, calls=2, timeout=240)


@pytest.mark.slow
def test_512_envs_twenty_times():
  _loop("task", repeats=20, calls=1, timeout=240)

"""benchmarks/eval_dispatch.py: flags checked before JAX starts; end to end on 2 fake CPU devices."""

import os
import subprocess
import sys

import pytest

from conftest import load_benchmark

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("argv,named", [(["--episodes-per-device", "0"], "--episodes-per-device"),
                                        (["--repeats", "0"], "--repeats"),
                                        (["--fragility", "1,x"], "--fragility"),
                                        (["--episodes-per-device", "6"], "--episodes-per-device"),
                                        (["--sequence", "shardy:one,gspmd:fast"], "--sequence"),
                                        (["--sequence", "one"], "--sequence"),
                                        (["--robot", "no_such_robot"], "--robot"),
                                        (["--robot", "panda_wrist", "--task", "navigate_and_pick"], "--robot"),
                                        (["--task", "train.experiments.pusher:PusherEnv", "--robot", "panda"], "--robot")])
def test_bad_flags_are_refused_naming_them(argv, named, capsys):
  with pytest.raises(SystemExit) as e:
    load_benchmark("eval_dispatch").parse(argv)
  assert e.value.code == 2 and named in capsys.readouterr().err


def test_the_gripper_by_default_whatever_the_registry_default(monkeypatch):
  import tasks

  monkeypatch.setattr(tasks.robots, "DEFAULT", "panda")  # committed results were made with the gripper
  ed = load_benchmark("eval_dispatch")
  assert ed.parse([]).task_kwargs == {"robot": "gripper"}
  assert ed.parse(["--task", "train.experiments.pusher:PusherEnv"]).task_kwargs is None  # an env class: no robot


def test_every_mode_runs_on_two_cpu_devices():
  env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT, XLA_FLAGS="--xla_force_host_platform_device_count=2")
  p = subprocess.run([sys.executable, "benchmarks/eval_dispatch.py", "--task", "train.experiments.pusher:PusherEnv", "--episodes-per-device", "4",
                      "--repeats", "1", "--layout", "sweep",
                      "--sequence", "shardy:one,shardy:async,shardy:threads,gspmd:threads,gspmd:spmd"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
  assert p.returncode == 0, p.stderr[-3000:]
  lines = [x for x in p.stdout.splitlines() if x.startswith("dispatch")]
  assert [x.split(" env-steps")[0].rsplit(":", 1)[0] for x in lines] == [
      "dispatch shardy:one (1 device(s))", "dispatch shardy:async (2 device(s))", "dispatch shardy:threads (2 device(s))",
      "dispatch gspmd:threads (2 device(s))", "dispatch gspmd:spmd (2 device(s))"]

"""Bad input, everywhere a user can type (issue 19 item 5): one table, each case rejected before anything compiles.

Python API cases must raise ``ValueError`` whose message starts with the field;
CLI cases call ``apps.cli.main([...])`` in-process and must return 2 with ONE
stderr line ``mjx-damage <cmd>: error: …`` naming the flag, no traceback. Every
case must return within ``FAST_S``: a compile (15 s or more for any task step on
CPU) would blow it, so a case that passes validated its input before compiling.
``{tmp}`` in an argument is the case's temporary directory, pre-filled by
:func:`_prepare` with an existing result file, an existing run, and runs whose
checkpoints are of another task or corrupt.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

import mjx_damage as md
import tasks
import train
from apps import cli
from train import checkpoint as ckpt
from train import evaluate as E

FAST_S = 5.0  # generous for a loaded 2-core machine; a compile takes far longer

PUSHER = "train.experiments.pusher:PusherEnv"
_SCENE = os.path.join(os.path.dirname(__file__), "scenes", "heat.xml")


def _prepare(tmp) -> None:
  open(os.path.join(tmp, "exists.mp4"), "wb").close()
  with open(os.path.join(tmp, "exists.json"), "w") as f:
    f.write("{}\n")
  os.makedirs(os.path.join(tmp, "run"))
  with open(os.path.join(tmp, "run", "config.json"), "w") as f:
    f.write("{}\n")
  os.makedirs(os.path.join(tmp, "other_task"))
  ckpt.save(os.path.join(tmp, "other_task", ckpt.FILENAME), {"x": np.zeros(2)}, {"y": np.zeros(1)},
            {"task": "pick_egg", "config": {}})
  os.makedirs(os.path.join(tmp, "other_config"))
  ckpt.save(os.path.join(tmp, "other_config", ckpt.FILENAME), {"x": np.zeros(2)}, {"y": np.zeros(1)},
            {"task": PUSHER, "config": {"num_envs": 3}})
  os.makedirs(os.path.join(tmp, "corrupt"))
  with open(os.path.join(tmp, "corrupt", ckpt.FILENAME), "wb") as f:
    f.write(b"PK\x03\x04 not a zip")
  with open(os.path.join(tmp, "afile"), "w") as f:
    f.write("x")


# --- Python API: (callable, field the message must start with) ---------------------------------

def _bind(config):
  import mujoco
  return md.bind(mujoco.MjModel.from_xml_path(_SCENE), config)


API_CASES = [
    ("tasks.make unknown name", lambda: tasks.make("no_such_task"), "name"),
    ("tasks.make unknown override", lambda: tasks.make("place_plate", bogus=1), "bogus"),
    ("tasks.make episode_length 0", lambda: tasks.make("place_plate", episode_length=0), "episode_length"),
    ("tasks.make episode_length str", lambda: tasks.make("place_plate", episode_length="10"), "episode_length"),
    ("tasks.make obs_mode", lambda: tasks.make("place_plate", obs_mode="pixels"), "obs_mode"),
    ("tasks.make success_bonus nan", lambda: tasks.make("place_plate", success_bonus=math.nan), "success_bonus"),
    ("tasks.scripted_policy style", lambda: tasks.scripted_policy(None, "reckless"), "style"),
    ("md.bind not a dict", lambda: _bind(42), "config"),
    ("md.bind unknown body", lambda: _bind({"entities": {"a": {"params": "default", "bodies": ["nobody"]}}}),
     "entities.a"),
    ("md.bind unknown params", lambda: _bind({"entities": {"a": {"params": "unobtainium", "bodies": ["world"]}}}),
     "entities.a"),
    ("train num_envs 0", lambda: train.train("place_plate", num_envs=0), "num_envs"),
    ("train num_timesteps -5", lambda: train.train("place_plate", num_timesteps=-5), "num_timesteps"),
    ("train learning_rate nan", lambda: train.train("place_plate", learning_rate=math.nan), "learning_rate"),
    ("train discounting 2", lambda: train.train("place_plate", discounting=2.0), "discounting"),
    ("train activation", lambda: train.train("place_plate", activation="sigmoidal"), "activation"),
    ("train seeds repeated", lambda: train.train("place_plate", seeds=(0, 0)), "seeds"),
    ("train multiplier", lambda: train.train("place_plate", multiplier="pi"), "multiplier"),
    ("train unknown field", lambda: train.train("place_plate", warp_speed=9), "warp_speed"),
    ("train preset", lambda: train.train("place_plate", preset="turbo"), "preset"),
    ("train time_limit", lambda: train.train("place_plate", time_limit=-1.0), "time_limit"),
    ("train hidden sizes", lambda: train.train("place_plate", policy_hidden_sizes=(32, 0)), "policy_hidden_sizes"),
    ("train unknown task", lambda: train.train("no_such_task", num_envs=8, batch_size=8, num_minibatches=1), "task"),
    ("evaluate episodes 0", lambda: E.evaluate(object(), None, 0), "episodes"),
    ("evaluate fragility nan", lambda: E.evaluate(object(), None, 2, fragility=math.nan), "fragility"),
    ("evaluate fragility per-episode count", lambda: E.evaluate(object(), None, 2, fragility=[1.0, 2.0, 3.0]),
     "fragility"),
    ("evaluate safe_threshold", lambda: E.evaluate(object(), None, 2, safe_threshold=150), "safe_threshold"),
    ("evaluate seed negative", lambda: E.evaluate(object(), None, 2, seed=-1), "seed"),
]


@pytest.mark.parametrize("name, call, field", API_CASES, ids=[c[0] for c in API_CASES])
def test_python_api_rejects(name, call, field):
  t0 = time.perf_counter()
  with pytest.raises(ValueError) as exc:
    call()
  assert str(exc.value).startswith(field), str(exc.value)
  assert time.perf_counter() - t0 < FAST_S


# --- CLI: (argv, text the one error line must contain) -----------------------------------------

CLI_CASES = [
    (["bogus"], "unknown command"),
    (["eval", "--task", "no_such_task", "--policy", "zero"], "task"),
    (["eval", "--task", "drop", "--policy", "greedy"], "policy"),
    (["eval", "--task", "drop", "--policy", "scripted:reckless"], "policy"),
    (["eval", "--task", "drop", "--policy", "checkpoint:{tmp}/missing"], "policy"),
    (["eval", "--task", "drop", "--policy", "checkpoint:{tmp}/corrupt/checkpoint.npz"], "checkpoint"),
    (["eval", "--task", "drop", "--policy", "zero", "--episodes", "0"], "episodes"),
    (["eval", "--task", "drop", "--policy", "zero", "--episodes", "-3"], "episodes"),
    (["eval", "--task", "drop", "--policy", "zero", "--episodes", "two"], "--episodes"),
    (["eval", "--task", "drop", "--policy", "zero", "--fragility", "nan"], "fragility"),
    (["eval", "--task", "drop", "--policy", "zero", "--fragility", "0"], "fragility"),
    (["eval", "--task", "drop", "--policy", "zero", "--safe-threshold", "101"], "safe_threshold"),
    (["eval", "--task", "drop", "--policy", "zero", "--episode-length", "0"], "episode_length"),
    (["eval", "--task", "drop", "--policy", "zero", "--seed", "-1"], "seed"),
    (["eval", "--task", "drop", "--policy", "zero", "--out", "{tmp}/exists.json"], "--overwrite"),
    (["eval", "--task", "drop", "--policy", "zero", "--out", "{tmp}/afile/result.json"], "--out"),
    (["eval", "--task", "drop", "--policy", "zero", "--out", "{tmp}/run"], "folder"),
    (["eval", "--task", "drop"], "--policy"),
    (["eval", "--task", "place_plate", "--policy", "zero", "--robot", "ur5"], "robot"),
    (["eval", "--task", "drop", "--policy", "zero", "--robot", "panda"], "--robot"),
    (["eval", "--task", "place_plate", "--policy", "zero", "--task-arg", "obs_mode"], "--task-arg"),
    (["eval", "--task", "place_plate", "--policy", "zero", "--task-arg", "colour=1"], "colour"),
    (["eval", "--task", "place_plate", "--policy", "zero", "--robot", "panda", "--task-arg", "robot=gripper"],
     "--robot"),
    (["render", "--task", "place_plate", "--policy", "zero", "--task-arg", "start=floor"], "start"),
    (["record", "--task", "pick_egg", "--policy", "zero", "--episodes", "1", "--robot", "ur5"], "robot"),
    (["sweep", "--tasks", "place_plate,drop", "--policies", "zero", "--robot", "panda"], "--robot"),
    (["render", "--task", "no_such_task", "--policy", "zero"], "task"),
    (["render", "--task", "drop", "--policy", "zero", "--out", "{tmp}/exists.mp4"], "--overwrite"),
    (["render", "--task", "drop", "--policy", "zero", "--out", "{tmp}/v.avi"], "out"),
    (["render", "--task", "drop", "--policy", "zero", "--num-envs", "0"], "num_envs"),
    (["sweep", "--tasks", "drop,no_such_task", "--policies", "zero"], "task"),
    (["sweep", "--tasks", "drop", "--policies", "zero,bogus"], "policy"),
    (["sweep", "--tasks", "drop", "--policies", "zero", "--seeds", "a"], "seeds"),
    (["sweep", "--tasks", "drop", "--policies", "zero", "--fragility", "1,nan"], "fragility"),
    (["sweep", "--tasks", "drop", "--policies", "zero", "--episodes", "0"], "episodes"),
    (["sweep", "--tasks", ",", "--policies", "zero"], "tasks"),
    (["sweep", "--tasks", "drop", "--policies", "zero", "--out", "{tmp}/exists.json"], "--overwrite"),
    (["train", "--task", "no_such_task"], "--task"),
    (["train", "--task", "drop"], "--task"),
    (["train", "--task", "place_plate", "--num-envs", "0"], "num_envs"),
    (["train", "--task", "place_plate", "--num-envs", "1.5"], "--num-envs"),
    (["train", "--task", "place_plate", "--timesteps", "-10"], "num_timesteps"),
    (["train", "--task", "place_plate", "--lr", "nan"], "learning_rate"),
    (["train", "--task", "place_plate", "--obs-clip", "-1"], "obs_clip"),
    (["train", "--task", "place_plate", "--gamma", "1.5"], "discounting"),
    (["train", "--task", "place_plate", "--activation", "sigmoidal"], "activation"),
    (["train", "--task", "place_plate", "--multiplier", "pi", "--budget", "2"], "multiplier"),
    (["train", "--task", "place_plate", "--budget-anneal-steps", "1000"], "budget_anneal_steps"),
    (["train", "--task", "place_plate", "--damage-warmup-steps", "1000"], "damage_warmup_steps"),
    (["train", "--task", "place_plate", "--damage-weight", "2", "--damage-warmup-completion", "2"],
     "damage_warmup_completion"),
    (["train", "--task", "place_plate", "--damage-warmup-completion", "0.5"], "damage_warmup_completion"),
    (["train", "--task", "place_plate", "--robot", "no_such_robot"], "--robot"),
    (["train", "--task", "place_plate", "--robot", "panda", "--task-arg", "robot=gripper"], "--robot"),
    (["train", "--task", "place_plate", "--budget", "2", "--budget-anneal-steps", "-5"], "budget_anneal_steps"),
    (["train", "--task", "place_plate", "--preset", "turbo"], "--preset"),
    (["train", "--task", "place_plate", "--seeds", "0,x"], "--seeds"),
    (["train", "--task", "place_plate", "--seeds", "1,1"], "seeds"),
    (["train", "--task", "place_plate", "--time-limit", "0"], "--time-limit"),
    (["train", "--task", "place_plate", "--task-arg", "obs_mode"], "--task-arg"),
    (["train", "--task", "place_plate", "--out", "{tmp}/run"], "--resume"),
    (["train", "--task", "place_plate", "--out", "{tmp}/afile"], "--out"),
    (["train", "--task", "place_plate", "--out", "{tmp}/nothing_here", "--resume"], "--resume"),
    (["train", "--task", "place_plate", "--out", "{tmp}/other_task", "--resume"], "pick_egg"),
    (["train", "--task", "place_plate", "--out", "{tmp}/corrupt", "--resume"], "checkpoint"),
    (["train", "--task", PUSHER, "--out", "{tmp}/other_config", "--resume", "--num-envs", "8", "--batch-size", "8",
      "--num-minibatches", "1"], "different config"),
    (["train", "--task", "place_plate", "--resume"], "--resume"),
    (["bench", "--envs", "0,4"], "--envs"),
    (["bench", "--k", "4", "--tracked", "1,8"], "--tracked"),
    (["bench", "--mounted", "1,x"], "--mounted"),
    (["bench", "--task", "no_such_task"], "--task"),
    (["bench", "--robot", "no_such_robot"], "--robot"),
    (["bench", "--task", "", "--robot", "panda"], "--robot"),
    (["bench", "--budget-s", "nan"], "--budget-s"),
    (["bench", "--out", "{tmp}/exists.json"], "--overwrite"),
    (["eval", "--task", "place_plate", "--policy", "scripted:safe", "--backend", "mujoco"], "backend: unknown"),
    (["eval", "--task", "drop", "--policy", "zero", "--backend", "warp"], "backend: warp runs the registry's tasks"),
    (["sweep", "--tasks", "drop", "--backend", "warp"], "backend: warp runs the registry's tasks"),
    (["sweep", "--tasks", "place_plate", "--backend", "warp", "--devices", "2"], "backend: warp steps one batch on one device"),
    (["render", "--task", "drop", "--policy", "zero", "--out", "{tmp}/x.gif", "--backend", "warp"],
     "backend: warp runs the registry's tasks"),
    (["eval", "--task", "place_plate", "--policy", "zero", "--backend", "native", "--native-envs", "0"],
     "native_envs"),
    (["sweep", "--tasks", "place_plate", "--backend", "jax"], "backend: unknown"),
    (["demo", "--envs", "0"], "--envs"),
    (["demo", "--seconds", "nan"], "--seconds"),
    (["demo", "--envs", "many"], "--envs"),
]


@pytest.fixture(scope="module", autouse=True)
def _imported():
  """Import every command module once, so a case's time is its own work, not the first JAX import."""
  import apps.bench.cli  # noqa: F401
  import apps.demo_cli  # noqa: F401
  import apps.eval_cli  # noqa: F401
  import apps.sweep_cli  # noqa: F401
  import train.cli  # noqa: F401
  import train.ppo  # noqa: F401


@pytest.mark.parametrize("argv, needle", CLI_CASES, ids=[" ".join(a) for a, _ in CLI_CASES])
def test_cli_rejects(argv, needle, tmp_path, capsys, monkeypatch):
  _prepare(str(tmp_path))
  monkeypatch.chdir(tmp_path)  # a command that got past validation would write here: checked below
  before = sorted(os.listdir(tmp_path))
  t0 = time.perf_counter()
  rc = cli.main([a.replace("{tmp}", str(tmp_path)) for a in argv])
  elapsed = time.perf_counter() - t0
  err = capsys.readouterr().err
  lines = [ln for ln in err.splitlines() if ln.strip()]
  assert rc == 2, err
  assert len(lines) == 1, err
  assert lines[0].startswith("mjx-damage") and ": error: " in lines[0], lines[0]
  assert needle in lines[0], lines[0]
  assert "Traceback" not in err
  assert elapsed < FAST_S, f"{elapsed:.1f} s: compiled before validating?"
  assert sorted(os.listdir(tmp_path)) == before  # nothing written, no runs/ folder


def test_table_size():
  assert len(API_CASES) + len(CLI_CASES) >= 40


def test_every_subcommand_help_shows_defaults(capsys):
  for cmd in cli.SUBCOMMANDS:
    assert cli.main([cmd, "--help"]) == 0
    out = capsys.readouterr().out
    assert "(default:" in out, cmd

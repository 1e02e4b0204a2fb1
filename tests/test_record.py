"""mjx-damage record (apps.record_cli) refuses bad input before compiling; train.record through the batched step (slow)."""

import numpy as np
import pytest

from mjx_damage import data as D
from apps import cli
from train import record as R


def test_cli_refuses_existing_out_without_overwrite(tmp_path, capsys):
  out = tmp_path / "demos.hdf5"
  out.write_bytes(b"keep me")
  rc = cli.main(["record", "--task", "pick_egg", "--policy", "operator:careful", "--episodes", "4", "--out", str(out)])
  assert rc == 2 and out.read_bytes() == b"keep me"
  err = capsys.readouterr().err.strip()
  assert err == (f"mjx-damage record: error: --out: {out} already exists; pass --overwrite to replace it, "
                 "or choose another --out")


@pytest.mark.parametrize("argv, msg", [
    (["--task", "nope", "--policy", "scripted:safe"], "task: unknown task 'nope'"),
    (["--task", "pick_egg", "--policy", "operator:sloppy"], "policy: unknown operator 'sloppy'"),
    (["--task", "pick_egg", "--policy", "scripted:fast"], "policy: unknown policy 'scripted:fast'"),
])
def test_cli_rejects_bad_specs(tmp_path, capsys, argv, msg):
  rc = cli.main(["record"] + argv + ["--episodes", "2", "--out", str(tmp_path / "x.hdf5")])
  assert rc == 2 and msg in capsys.readouterr().err
  assert not (tmp_path / "x.hdf5").exists()


@pytest.mark.slow
def test_record_operators_round_trip(tmp_path):
  import tasks
  from tasks import operators

  env = tasks.make("pick_egg", episode_length=30)
  ds = R.record(env, operators.careless(env), 4, seed=0, task="pick_egg", episode_length=30)
  assert ds.actions.shape == (4, 30, 4) and ds.obs["state"].shape == (4, 30, env.observation_size)
  assert ds.entity_names == tuple(env.entity_names)
  h = np.stack(list(ds.health.values()), -1)
  assert np.all(np.diff(h, axis=1) <= 1e-4)  # health never recovers
  np.testing.assert_allclose(ds.cost, sum(ds.damage.values()), rtol=1e-4, atol=1e-4)
  assert np.all(np.abs(ds.actions) <= 1)
  D.save(tmp_path / "d.hdf5", ds)
  back = D.load(tmp_path / "d.hdf5", task="pick_egg")
  np.testing.assert_array_equal(back.actions, ds.actions)
  assert back.label_names == ("careless",)


def test_cli_streams_chunks_into_the_file_as_record_would_hold_them(tmp_path, capsys):
  """`mjx-damage record` writes each chunk while the next records (record_chunks → save_chunks): the file
  must hold what record() gives in memory for the same seed, the last chunk shorter."""
  import json

  import tasks
  from tasks import operators

  out = tmp_path / "demos.hdf5"
  rc = cli.main(["record", "--task", "pick_egg", "--policy", "operator:careful", "--episodes", "5", "--chunk", "3",
                 "--episode-length", "12", "--seed", "7", "--out", str(out)])
  assert rc == 0
  summary = json.loads([ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("{")][-1])
  assert summary["episodes"] == 5 and summary["transitions"] == 5 * 12
  env = tasks.make("pick_egg")
  whole = R.record(env, operators.careful(env), 5, seed=7, task="pick_egg", episode_length=12, chunk=5,
                   label="careful")
  back = D.load(out, task="pick_egg")
  for f in ("actions", "rewards", "states", "cost", "success", "safe", "lengths"):
    np.testing.assert_allclose(getattr(back, f), getattr(whole, f), rtol=1e-5, atol=1e-5, err_msg=f)
  assert back.label_names == ("careful",) and summary["success_rate"] == float(np.mean(whole.success))


def test_cli_task_args_build_the_env_and_are_stored(tmp_path):
  """`--task-arg` builds the env the episodes come from and is stored with them (``env_config``), so a
  policy trained on the file (mjx-damage bc) gets the same task."""
  import json

  out = tmp_path / "demos.hdf5"
  rc = cli.main(["record", "--task", "pick_egg", "--policy", "zero", "--task-arg", "goal=carry", "--episodes", "2",
                 "--episode-length", "4", "--out", str(out)])
  assert rc == 0
  back = D.load(out, task="pick_egg")
  assert json.loads(back.env_config) == {"goal": "carry", "robot": "gripper"}  # and the robot it ran

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

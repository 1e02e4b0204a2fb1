"""mjx_damage.data: lossless HDF5 round trip in the robomimic layout, append, and bad-input errors."""

import json

import h5py
import jax
import numpy as np
import pytest

from mjx_damage import data as D


def hand_made(e=5, t=7, seed=0, env_name="pick_egg", labels=("careful", "careless")):
  """A dataset with random contents; steps past each length are zero (as a loaded file pads them)."""
  r = np.random.default_rng(seed)
  lengths = r.integers(1, t + 1, size=e)
  lengths[0] = t
  valid = np.arange(t)[None, :] < lengths[:, None]

  def arr(*shape, dtype=np.float32):
    a = r.normal(size=(e, t) + shape).astype(dtype)
    return a * valid.reshape(valid.shape + (1,) * len(shape))

  return D.build(
      env_name=env_name, env_config={"episode_length": t, "damage_weight": 0.0},
      obs={"state": arr(6), "eef_pos": arr(3)}, actions=arr(4), rewards=arr(), states=arr(9),
      health={"egg": (100 - np.abs(arr())) * valid, "agent": (100 - np.abs(arr())) * valid},
      damage={k: np.abs(arr()) for k in D.DAMAGE_KINDS}, cost=np.abs(arr()), lengths=lengths,
      success=r.random(e) < 0.5, safe=r.random(e) < 0.5, labels=r.integers(0, len(labels), e),
      label_names=labels)


def assert_same(a: D.Dataset, b: D.Dataset):
  la, lb = [jax_leaves(x) for x in (a, b)]
  assert len(la) == len(lb)
  for (pa, xa), (pb, xb) in zip(la, lb):
    assert pa == pb
    assert xa.dtype == xb.dtype, pa
    np.testing.assert_array_equal(xa, xb, err_msg=str(pa))
  assert (a.env_name, a.env_config, a.label_names) == (b.env_name, b.env_config, b.label_names)


def jax_leaves(ds):
  return [(jax.tree_util.keystr(p), np.asarray(x)) for p, x in jax.tree_util.tree_leaves_with_path(ds)]


def test_round_trip_is_lossless(tmp_path):
  ds = hand_made()
  path = tmp_path / "demos.hdf5"
  D.save(path, ds)
  assert_same(ds, D.load(path, task="pick_egg"))


def test_file_is_robomimic_layout(tmp_path):
  ds = hand_made()
  path = tmp_path / "demos.hdf5"
  D.save(path, ds)
  with h5py.File(path, "r") as f:
    g = f["data"]
    assert g.attrs["total"] == int(ds.lengths.sum())
    assert g.attrs["env_name"] == "pick_egg"
    n = int(ds.lengths[1])
    demo = g["demo_1"]
    assert demo.attrs["num_samples"] == n
    assert demo["actions"].shape == (n, 4) and demo["obs/state"].shape == (n, 6)
    assert demo["dones"][-1] == 1 and demo["dones"][:-1].sum() == 0
    assert set(demo["damage"]) == set(D.DAMAGE_KINDS) and set(demo["health"]) == {"egg", "agent"}
    # written through h5py's low-level API, read back as the high-level API would have stored them
    assert type(demo.attrs["num_samples"]) is np.int64
    assert demo["actions"].dtype == np.float32 and demo["actions"].chunks is None  # contiguous
    assert "keep" not in demo  # nothing curated out: keep is implied
    # episode flags as robomimic filter keys: mask/<key> lists the demos in it
    names = lambda key: sorted(int(n[5:]) for n in f[f"mask/{key}"][()])
    assert names("success") == np.flatnonzero(ds.success).tolist()
    assert names("safe") == np.flatnonzero(ds.safe).tolist()
    assert names("safe_success") == np.flatnonzero(ds.success & ds.safe).tolist()
    for i, label in enumerate(ds.label_names):
      assert names("label_" + label) == np.flatnonzero(ds.labels == i).tolist()


def test_curated_steps_round_trip(tmp_path):
  ds = hand_made()
  keep = np.array(ds.keep)
  keep[0, 2:4] = False  # datapoint curation dropped two steps of demo 0
  ds = ds.replace(keep=keep)
  D.save(tmp_path / "curated.hdf5", ds)
  assert_same(ds, D.load(tmp_path / "curated.hdf5"))
  with h5py.File(tmp_path / "curated.hdf5", "r") as f:
    assert "keep" in f["data/demo_0"] and "keep" not in f["data/demo_1"]


def write_format_1(path, ds):
  """The layout of format 1 (per-demo success/safe/label attributes, keep in every demo), high-level h5py."""
  with h5py.File(path, "w") as f:
    g = f.create_group("data")
    g.attrs.update({"env_name": ds.env_name, "entity_names": json.dumps(list(ds.health)), "format": 1,
                    "labels": json.dumps(list(ds.label_names)), "total": int(ds.lengths.sum()),
                    "env_args": json.dumps({"env_name": ds.env_name, "env_kwargs": json.loads(ds.env_config)})})
    for i, n in enumerate(ds.lengths):
      d = g.create_group(f"demo_{i}")
      d.attrs.update({"num_samples": int(n), "success": bool(ds.success[i]), "safe": bool(ds.safe[i]),
                      "label": ds.label_names[int(ds.labels[i])]})
      for k in ("actions", "rewards", "dones", "states", "cost", "keep"):
        d[k] = getattr(ds, k)[i, :n]
      for sub in ("obs", "health", "damage"):
        for k, v in getattr(ds, sub).items():
          d[f"{sub}/{k}"] = v[i, :n]


def test_format_1_files_load_and_append(tmp_path):
  a, b = hand_made(seed=5), hand_made(e=3, seed=6, labels=("careless", "other"))
  path = tmp_path / "old.hdf5"
  write_format_1(path, a)
  assert_same(a, D.load(path))
  D.append(path, b)
  assert_same(D.concat([a, b]), D.load(path))
  with h5py.File(path, "r") as f:
    assert f["data"].attrs["format"] == D.FORMAT and len(f["mask/success"]) == int(a.success.sum() + b.success.sum())


def test_bad_masks_name_the_cause(tmp_path):
  ds = hand_made()
  path = tmp_path / "demos.hdf5"
  D.save(path, ds)
  with h5py.File(path, "r+") as f:
    del f["mask/label_careful"]
    f["mask/label_careful"] = np.asarray([b"demo_0", b"demo_1", b"demo_2", b"demo_3", b"demo_4"])
  with pytest.raises(ValueError, match="is in 2 of the mask/label_<name> keys"):
    D.load(path)
  with h5py.File(path, "r+") as f:
    del f["mask/success"]
  with pytest.raises(ValueError, match="no 'mask/success'"):
    D.load(path)
  with h5py.File(path, "r+") as f:
    f["data"].attrs["format"] = D.FORMAT + 1
  with pytest.raises(ValueError, match=f"format {D.FORMAT + 1}, newer than"):
    D.load(path)


def test_append_and_concat_agree(tmp_path):
  a, b = hand_made(seed=1), hand_made(e=3, t=9, seed=2, labels=("careless", "other"))
  path = tmp_path / "demos.hdf5"
  D.save(path, a)
  D.append(path, b)
  both = D.load(path)
  assert both.num_episodes == 8 and both.label_names == ("careful", "careless", "other")
  assert_same(D.concat([a, b]), both)
  with h5py.File(path, "r") as f:
    assert f["data"].attrs["total"] == int(a.lengths.sum() + b.lengths.sum())


def test_transitions_and_select():
  ds = hand_made()
  tr = D.transitions(ds)
  assert tr["actions"].shape == (int(ds.lengths.sum()), 4) == (D.num_transitions(ds), 4)
  np.testing.assert_array_equal(tr["actions"][0], ds.actions[0, 0])
  sub = D.select(ds, np.asarray(ds.success))
  assert sub.num_episodes == int(np.sum(ds.success))


def test_save_refuses_existing_file(tmp_path):
  path = tmp_path / "demos.hdf5"
  D.save(path, hand_made())
  before = path.read_bytes()
  with pytest.raises(ValueError, match="exists; pass overwrite"):
    D.save(path, hand_made(seed=3))
  assert path.read_bytes() == before
  D.save(path, hand_made(seed=3), overwrite=True)
  assert path.read_bytes() != before


def test_bad_files_name_the_cause(tmp_path):
  with pytest.raises(ValueError, match="no such file"):
    D.load(tmp_path / "missing.hdf5")
  text = tmp_path / "text.hdf5"
  text.write_text("not hdf5")
  with pytest.raises(ValueError, match="text.hdf5: not an HDF5 file, or truncated"):
    D.load(text)
  good = tmp_path / "good.hdf5"
  D.save(good, hand_made())
  cut = tmp_path / "cut.hdf5"
  cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
  with pytest.raises(ValueError, match="cut.hdf5: "):
    D.load(cut)
  other = tmp_path / "other.hdf5"
  with h5py.File(other, "w") as f:
    f.create_group("stuff")
  with pytest.raises(ValueError, match="wrong layout: no 'data' group"):
    D.load(other)
  with pytest.raises(ValueError, match="dataset of task 'pick_egg', expected 'pour_water'"):
    D.load(good, task="pour_water")
  with pytest.raises(ValueError, match="of different tasks"):
    D.concat([hand_made(), hand_made(env_name="x")])
  with h5py.File(good, "r+") as f:
    del f["data/demo_2/cost"]
  with pytest.raises(ValueError, match="demo_2 lacks 'cost'"):
    D.load(good)
  empty = tmp_path / "empty.hdf5"
  with h5py.File(empty, "w") as f:
    g = f.create_group("data")
    g.attrs.update({"env_name": "pick_egg", "entity_names": "[]", "labels": "[]"})
  with pytest.raises(ValueError, match="no demos"):
    D.load(empty)


def test_append_refuses_other_task(tmp_path):
  path = tmp_path / "demos.hdf5"
  D.save(path, hand_made())
  with pytest.raises(ValueError, match="expected 'pour_water'"):
    D.append(path, hand_made(env_name="pour_water"))


def test_build_checks_shapes():
  ds = hand_made()
  with pytest.raises(ValueError, match="lengths: expected"):
    D.build(env_name="x", obs=ds.obs, actions=ds.actions, rewards=ds.rewards, states=ds.states,
            health=ds.health, damage=ds.damage, cost=ds.cost, lengths=[1, 2], success=ds.success, safe=ds.safe)
  with pytest.raises(ValueError, match="obs/state: expected leading shape"):
    D.build(env_name="x", obs={"state": ds.obs["state"][:, :3]}, actions=ds.actions, rewards=ds.rewards,
            states=ds.states, health=ds.health, damage=ds.damage, cost=ds.cost, lengths=ds.lengths,
            success=ds.success, safe=ds.safe)


def test_save_chunks_equals_save_of_the_concatenation(tmp_path):
  a, b = hand_made(e=4, t=7, seed=3), hand_made(e=3, t=7, seed=4, labels=("careless", "other"))
  D.save_chunks(tmp_path / "streamed.hdf5", iter([a, b]))
  D.save(tmp_path / "whole.hdf5", D.concat([a, b]))
  assert_same(D.load(tmp_path / "streamed.hdf5"), D.load(tmp_path / "whole.hdf5"))


def test_save_chunks_refuses_a_mismatched_chunk_and_keeps_the_old_file(tmp_path):
  path = tmp_path / "demos.hdf5"
  path.write_bytes(b"keep me")
  with pytest.raises(ValueError, match="datasets of different tasks"):
    D.save_chunks(path, iter([hand_made(), hand_made(env_name="pour_water")]), overwrite=True)
  assert path.read_bytes() == b"keep me"

  def interrupted():  # e.g. Ctrl-C while the device records the second chunk
    yield hand_made()
    raise KeyboardInterrupt

  with pytest.raises(KeyboardInterrupt):
    D.save_chunks(path, interrupted(), overwrite=True)
  assert path.read_bytes() == b"keep me" and [p.name for p in tmp_path.iterdir()] == ["demos.hdf5"]
  with pytest.raises(ValueError, match="no episodes"):
    D.save_chunks(tmp_path / "empty.hdf5", iter([]))
  assert not (tmp_path / "empty.hdf5").exists()

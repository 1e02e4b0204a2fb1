"""Demonstration datasets with per-step health: the robomimic HDF5 layout, in memory and on disk.

On disk (one HDF5 file; what robomimic/LeRobot-style readers expect, plus damage)::

    data                       attrs: env_name, env_args (JSON: env_name, type, env_kwargs),
                                      total (transitions), format, entity_names, labels (JSON)
    data/demo_<i>              attrs: num_samples
    data/demo_<i>/obs/<key>    [n, ...]  observations before the step (key "state": the env's obs)
    data/demo_<i>/actions      f32[n, A]
    data/demo_<i>/rewards      f32[n]    env reward of the step (task reward − w·cost)
    data/demo_<i>/dones        f32[n]    1 on the demo's last step
    data/demo_<i>/states       f32[n, S] simulator state before the step (qpos ‖ qvel)
    data/demo_<i>/health/<entity>  f32[n]  entity health after the step, 0–100
    data/demo_<i>/damage/{mechanical,thermal,fluid}  f32[n]  damage of the step, health points
    data/demo_<i>/cost         f32[n]    total damage of the step (health points)
    data/demo_<i>/keep         bool[n]   step usable for training; only where curation dropped a step
    mask/<key>                 S[k]      robomimic filter keys, the demos (b"demo_<i>") in each:
                                         success, safe, safe_success, label_<name> (who made them)

Episode flags are robomimic filter keys rather than per-demo attributes: robomimic trains
on one with ``config.train.hdf5_filter_key`` (e.g. ``"safe_success"``, the safely
completed demos), and a file holds thousands of demos, each HDF5 object written costing
20–50 µs, so four attributes and an all-True ``keep`` per demo were a quarter of the
writing time (benchmarks/dataset_writer.py). Format 1 files (per-demo ``success``,
``safe``, ``label`` attributes and ``keep`` in every demo) still load.

In memory: :class:`Dataset`, a pytree of arrays padded to ``[E, T, ...]`` with
``lengths`` and ``keep`` (False past an episode's end), so curation and
training are array operations; :func:`transitions` flattens the kept steps.

:func:`save_chunks` writes a stream of datasets (``train.record.record_chunks``) as one
file, chunk by chunk, so a recording larger than memory can be written while it
is recorded.

Every function here that touches a file raises ``ValueError`` naming the file
and the cause (missing, not HDF5 / truncated, wrong layout, missing key,
another task) before returning anything. Writes are atomic
(:func:`mjx_damage.io.atomic_path`): a file is either the old one or the new one.
"""

from __future__ import annotations

import json
import os
import shutil
from typing import Iterable, Optional, Sequence

import flax
import h5py
import numpy as np

from mjx_damage.io import atomic_path

FORMAT = 2  # 2: episode flags under mask/, keep only where curated; 1: per-demo attributes
DAMAGE_KINDS = ("mechanical", "thermal", "fluid")
_STEP_ARRAYS = ("actions", "rewards", "dones", "states", "cost")


@flax.struct.dataclass
class Dataset:
  """E episodes padded to T steps (a pytree; the metadata fields are static).

  obs:      {key: f32[E, T, ...]} observation before each step.
  actions:  f32[E, T, A]; rewards, dones, cost: f32[E, T]; states: f32[E, T, S].
  health:   {entity: f32[E, T]} health after each step (0–100).
  damage:   {"mechanical"|"thermal"|"fluid": f32[E, T]} damage of each step (health points).
  keep:     bool[E, T] step usable for training (False past ``lengths`` and where curated out).
  lengths:  i32[E] steps recorded per episode.
  success:  bool[E] the task's success condition held at some step.
  safe:     bool[E] every entity's final health above the safe threshold.
  labels:   i32[E] index into ``label_names`` (who made the demo, e.g. "careful").
  env_name: the task; env_config: JSON of its make() overrides.
  """

  obs: dict
  actions: np.ndarray
  rewards: np.ndarray
  dones: np.ndarray
  states: np.ndarray
  health: dict
  damage: dict
  cost: np.ndarray
  keep: np.ndarray
  lengths: np.ndarray
  success: np.ndarray
  safe: np.ndarray
  labels: np.ndarray
  env_name: str = flax.struct.field(pytree_node=False, default="")
  env_config: str = flax.struct.field(pytree_node=False, default="{}")
  label_names: tuple = flax.struct.field(pytree_node=False, default=())

  @property
  def num_episodes(self) -> int:
    return int(self.lengths.shape[0])

  @property
  def entity_names(self) -> tuple[str, ...]:
    return tuple(self.health)


def config_json(config: dict) -> str:
  """Canonical JSON of a task's make() overrides (sorted keys), as ``Dataset.env_config`` holds it."""
  return json.dumps(config, sort_keys=True, default=str)


def build(*, env_name: str, obs: dict, actions, rewards, states, health: dict, damage: dict, cost,
          lengths, success, safe, labels=None, label_names: Sequence[str] = (), env_config: Optional[dict] = None,
          keep=None) -> Dataset:
  """A :class:`Dataset` from padded ``[E, T, ...]`` arrays (shapes as in its docstring), checked.

  ``keep`` defaults to ``t < lengths``; ``dones`` is 1 on each episode's last step;
  ``labels`` default to 0 (``label_names`` then ``("default",)`` if empty).
  """
  actions = np.asarray(actions, np.float32)
  if actions.ndim != 3:
    raise ValueError(f"actions: expected f32[E, T, A], got shape {actions.shape}")
  e, t = actions.shape[:2]
  lengths = np.asarray(lengths, np.int32).reshape(-1)
  if lengths.shape != (e,):
    raise ValueError(f"lengths: expected i32[{e}], got shape {lengths.shape}")
  steps = np.arange(t)[None, :]
  valid = steps < lengths[:, None]
  keep = valid if keep is None else np.asarray(keep, bool) & valid
  label_names = tuple(label_names) or ("default",)
  labels = np.zeros(e, np.int32) if labels is None else np.asarray(labels, np.int32).reshape(e)
  f32 = lambda a: np.asarray(a, np.float32)
  ds = Dataset(
      obs={k: np.asarray(v) for k, v in obs.items()}, actions=actions, rewards=f32(rewards),
      dones=(steps == lengths[:, None] - 1).astype(np.float32), states=f32(states),
      health={k: f32(v) for k, v in health.items()}, damage={k: f32(damage[k]) for k in DAMAGE_KINDS},
      cost=f32(cost), keep=keep, lengths=lengths, success=np.asarray(success, bool).reshape(e),
      safe=np.asarray(safe, bool).reshape(e), labels=labels, env_name=env_name,
      env_config=config_json(env_config or {}), label_names=label_names)
  for name, tree in (("obs", ds.obs), ("health", ds.health), ("damage", ds.damage),
                     ("rewards", {"": ds.rewards}), ("states", {"": ds.states}), ("cost", {"": ds.cost})):
    for k, v in tree.items():
      if v.shape[:2] != (e, t):
        raise ValueError(f"{name}{'/' + k if k else ''}: expected leading shape ({e}, {t}), got {v.shape}")
  _check_self(ds)
  return ds


def num_transitions(ds: Dataset) -> int:
  """Kept steps over all episodes."""
  return int(np.sum(np.asarray(ds.keep)))


def to_numpy(ds: Dataset) -> Dataset:
  """``ds`` with every array on the host (numpy)."""
  return ds.replace(**{f: _tree_np(getattr(ds, f)) for f in _ARRAY_FIELDS})


def _tree_np(x):
  if isinstance(x, dict):
    return {k: np.asarray(v) for k, v in x.items()}
  return np.asarray(x)


_ARRAY_FIELDS = ("obs", "actions", "rewards", "dones", "states", "health", "damage", "cost", "keep",
                 "lengths", "success", "safe", "labels")
_EPISODE_FIELDS = ("lengths", "success", "safe", "labels")


def select(ds: Dataset, episodes) -> Dataset:
  """The episodes ``episodes`` (bool[E] mask or int indices) of ``ds``, padding unchanged."""
  idx = np.asarray(episodes)
  if idx.dtype == bool:
    if idx.shape != (ds.num_episodes,):
      raise ValueError(f"episodes: mask must be bool[{ds.num_episodes}], got shape {idx.shape}")
    idx = np.flatnonzero(idx)
  take = lambda a: np.asarray(a)[idx]
  return ds.replace(**{f: (({k: take(v) for k, v in getattr(ds, f).items()}) if isinstance(getattr(ds, f), dict)
                          else take(getattr(ds, f))) for f in _ARRAY_FIELDS})


def concat(parts: Sequence[Dataset]) -> Dataset:
  """Episodes of several datasets of one task, padded to the longest; labels merged by name."""
  parts = [to_numpy(p) for p in parts]
  if not parts:
    raise ValueError("parts: need at least one dataset")
  first = parts[0]
  for p in parts[1:]:
    _check_compatible(first, p, "parts")
  names = tuple(dict.fromkeys(n for p in parts for n in p.label_names))
  t_max = max(p.keep.shape[1] for p in parts)

  def pad(a):
    w = [(0, 0), (0, t_max - a.shape[1])] + [(0, 0)] * (a.ndim - 2)
    return np.pad(a, w)

  fields = {}
  for f in _ARRAY_FIELDS:
    if f in _EPISODE_FIELDS:
      continue
    if isinstance(getattr(first, f), dict):
      fields[f] = {k: np.concatenate([pad(getattr(p, f)[k]) for p in parts]) for k in getattr(first, f)}
    else:
      fields[f] = np.concatenate([pad(getattr(p, f)) for p in parts])
  for f in ("lengths", "success", "safe"):
    fields[f] = np.concatenate([getattr(p, f) for p in parts])
  fields["labels"] = np.concatenate([
      np.asarray([names.index(p.label_names[i]) for i in p.labels], np.int32).reshape(-1) for p in parts])
  return first.replace(label_names=names, **fields)


def _check_compatible(a: Dataset, b: Dataset, where: str) -> None:
  if a.env_name != b.env_name:
    raise ValueError(f"{where}: datasets of different tasks: {a.env_name!r} vs {b.env_name!r}")
  for f in ("obs", "health", "damage"):
    if sorted(getattr(a, f)) != sorted(getattr(b, f)):
      raise ValueError(f"{where}: {f} keys differ: {list(getattr(a, f))} vs {list(getattr(b, f))}")
  if a.actions.shape[2:] != b.actions.shape[2:] or a.states.shape[2:] != b.states.shape[2:]:
    raise ValueError(f"{where}: action/state sizes differ: {a.actions.shape[2:]}/{a.states.shape[2:]} "
                     f"vs {b.actions.shape[2:]}/{b.states.shape[2:]}")


def transitions(ds: Dataset) -> dict:
  """The kept steps as flat numpy arrays ``[N, ...]``: obs (dict), actions, rewards, cost,
  plus ``episode`` i32[N] and ``t`` i32[N] (where each came from)."""
  ds = to_numpy(ds)
  e, t = np.nonzero(ds.keep)
  return {
      "obs": {k: v[e, t] for k, v in ds.obs.items()},
      "actions": ds.actions[e, t],
      "rewards": ds.rewards[e, t],
      "cost": ds.cost[e, t],
      "episode": e.astype(np.int32),
      "t": t.astype(np.int32),
  }


# --- files ------------------------------------------------------------------------

def save(path: str, ds: Dataset, overwrite: bool = False) -> None:
  """Write ``ds`` to ``path`` (atomic). Refuses an existing file unless ``overwrite``."""
  save_chunks(path, [ds], overwrite)


def save_chunks(path: str, chunks: Iterable[Dataset], overwrite: bool = False) -> int:
  """Write the episodes of a stream of datasets of one task to ``path`` as one file, chunk by chunk.

  Each chunk is written as it arrives (with :func:`train.record.record_chunks`,
  while the device records the next), so the episodes never need to fit in
  memory together. Atomic: nothing at ``path`` until the last chunk is written;
  an error or an interruption leaves an existing file as it was. Refuses an
  existing file unless ``overwrite``. Returns the number of episodes written.
  """
  path = os.fspath(path)
  if os.path.exists(path) and not overwrite:
    raise ValueError(f"{path}: exists; pass overwrite=True (CLI: --overwrite) to replace it")
  first, written, names, flags = None, 0, (), []
  with atomic_path(path, suffix=".hdf5") as tmp:
    with h5py.File(tmp, "w") as f:
      for ds in chunks:
        ds = to_numpy(ds)
        _check_self(ds)
        if first is None:
          first = ds
          g = f.create_group("data")
          g.attrs["env_name"] = ds.env_name
          g.attrs["env_args"] = json.dumps({"env_name": ds.env_name, "type": "mjx_damage",
                                            "env_kwargs": json.loads(ds.env_config)})
          g.attrs["format"] = FORMAT
          g.attrs["entity_names"] = json.dumps(list(ds.entity_names))
          g.attrs["total"] = 0
        else:
          _check_compatible(first, ds, "chunks")
        names = tuple(dict.fromkeys(names + ds.label_names))
        g.attrs["labels"] = json.dumps(list(names))
        _write_demos(g, ds, start=written)
        flags.append(_flags(ds))
        written += ds.num_episodes
      if first is None:
        raise ValueError("dataset: no episodes")
      _write_masks(f, *(np.concatenate(x) for x in zip(*flags)))
  return written


def append(path: str, ds: Dataset) -> None:
  """Add the episodes of ``ds`` to the dataset file ``path`` (same task and layout), atomically."""
  path = os.fspath(path)
  old = load(path, task=ds.env_name)
  ds = to_numpy(ds)
  _check_self(ds)
  _check_compatible(old, ds, path)
  names = tuple(dict.fromkeys(old.label_names + ds.label_names))
  with atomic_path(path, suffix=".hdf5") as tmp:
    shutil.copyfile(path, tmp)
    with h5py.File(tmp, "r+") as f:
      g = f["data"]
      g.attrs["labels"] = json.dumps(list(names))
      g.attrs["format"] = FORMAT  # a format-1 file's demos keep their attributes; the masks now hold the flags
      _write_demos(g, ds, start=old.num_episodes)
      _write_masks(f, *(np.concatenate(x) for x in zip(_flags(old), _flags(ds))))


def _write_demos(g, ds: Dataset, start: int) -> None:
  """Episodes of ``ds`` as ``demo_<start + i>``, each labelled by name (``data.attrs["labels"]`` lists them)."""
  total = int(g.attrs["total"])
  ids = {}  # one HDF5 type per dtype and one dataspace per shape, shared by every object written
  valid = np.arange(ds.keep.shape[1])[None, :] < ds.lengths[:, None]
  curated = ~np.all(ds.keep | ~valid, axis=1)  # episodes with a dropped step: only they store keep
  for i in range(ds.num_episodes):
    n = int(ds.lengths[i])
    d = h5py.h5g.create(g.id, f"demo_{start + i}".encode())
    _attr(ids, d, b"num_samples", np.asarray(n, np.int64))
    for k in _STEP_ARRAYS + (("keep",) if curated[i] else ()):
      _put(ids, d, k.encode(), getattr(ds, k)[i, :n])
    for sub in ("obs", "health", "damage"):
      s = h5py.h5g.create(d, sub.encode())
      for k, v in getattr(ds, sub).items():
        _put(ids, s, k.encode(), v[i, :n])
    total += n
  g.attrs["total"] = total


# The writers use h5py's low-level API with shared type and dataspace ids: a file holds ~16 objects per
# episode, and h5py's high-level wrappers (plus a fresh type and dataspace per object) cost about as much
# as HDF5 itself (2.66 s vs 4.3 s for 4096 pick_egg episodes). They write what the high-level API writes
# (same types, contiguous layout), so readers see no difference.


def _type_space(ids: dict, dtype, shape):
  key = (dtype, shape)
  if key not in ids:
    space = h5py.h5s.create_simple(shape) if shape else h5py.h5s.create(h5py.h5s.SCALAR)
    ids[key] = (h5py.h5t.py_create(dtype, logical=True), space)
  return ids[key]


def _attr(ids: dict, obj, name: bytes, a: np.ndarray) -> None:
  """A scalar attribute ``name`` of ``obj`` (a low-level object id) holding ``a``."""
  h5py.h5a.create(obj, name, *_type_space(ids, a.dtype, ())).write(a)


def _put(ids: dict, group, name: bytes, a: np.ndarray) -> None:
  """A contiguous dataset ``group/name`` holding ``a`` (``group``: a low-level group id)."""
  a = np.ascontiguousarray(a)
  dset = h5py.h5d.create(group, name, *_type_space(ids, a.dtype, a.shape))
  if a.size:
    dset.write(h5py.h5s.ALL, h5py.h5s.ALL, a)


def _flags(ds: Dataset) -> tuple:
  """Per episode: success bool[E], safe bool[E], label name S[E] (``b""`` without label names)."""
  if ds.label_names:
    labels = np.asarray([n.encode() for n in ds.label_names])[np.asarray(ds.labels)]
  else:
    labels = np.full(ds.num_episodes, b"")
  return np.asarray(ds.success, bool), np.asarray(ds.safe, bool), labels


MASK_PREFIX = "label_"


def _write_masks(f, success, safe, labels) -> None:
  """``mask/<key>``: robomimic filter keys (demo names) for the episode flags, replacing any there."""
  demos = np.char.add(b"demo_", np.arange(len(success)).astype("S"))
  if "mask" in f:
    del f["mask"]
  m = f.create_group("mask")
  keys = {"success": success, "safe": safe, "safe_success": success & safe}
  keys.update({MASK_PREFIX + n.decode(): labels == n for n in dict.fromkeys(labels.tolist()) if n})
  for k, member in keys.items():
    m.create_dataset(k, data=demos[member])


def _check_self(ds: Dataset) -> None:
  if ds.num_episodes == 0:
    raise ValueError("dataset: no episodes")
  if set(ds.damage) != set(DAMAGE_KINDS):
    raise ValueError(f"damage: keys must be {DAMAGE_KINDS}, got {tuple(ds.damage)}")
  if not ds.env_name:
    raise ValueError("env_name: empty")
  if np.any(ds.lengths < 1) or np.any(ds.lengths > ds.keep.shape[1]):
    raise ValueError(f"lengths: each must be in [1, {ds.keep.shape[1]}], got {ds.lengths.tolist()}")
  if ds.label_names and (np.any(ds.labels < 0) or np.any(ds.labels >= len(ds.label_names))):
    raise ValueError(f"labels: indices must be in [0, {len(ds.label_names)}), got {np.unique(ds.labels).tolist()}")


def load(path: str, task: Optional[str] = None) -> Dataset:
  """Read a dataset file into a :class:`Dataset` (numpy arrays, padded to the longest demo).

  ``task``: expected task name (``ValueError`` if the file records another).
  """
  path = os.fspath(path)
  if not os.path.exists(path):
    raise ValueError(f"{path}: no such file")
  if not os.path.isfile(path):
    raise ValueError(f"{path}: not a file")
  try:
    f = h5py.File(path, "r")
  except OSError as e:
    raise ValueError(f"{path}: not an HDF5 file, or truncated ({e})") from None
  with f:
    try:
      return _read(f, path, task)
    except KeyError as e:
      raise ValueError(f"{path}: wrong layout: {e}") from None


def _read(f, path: str, task: Optional[str]) -> Dataset:
  if "data" not in f or not isinstance(f["data"], h5py.Group):
    raise ValueError(f"{path}: wrong layout: no 'data' group (robomimic layout: data/demo_<i>/...)")
  g = f["data"]
  for a in ("env_name", "entity_names", "labels"):
    if a not in g.attrs:
      raise ValueError(f"{path}: wrong layout: data.attrs lacks {a!r} (not written by mjx_damage.data?)")
  fmt = int(g.attrs.get("format", 1))
  if fmt > FORMAT:
    raise ValueError(f"{path}: format {fmt}, newer than this mjx_damage reads ({FORMAT}); upgrade mjx_damage")
  env_name = str(g.attrs["env_name"])
  if task is not None and env_name != task:
    raise ValueError(f"{path}: dataset of task {env_name!r}, expected {task!r}")
  env_args = json.loads(g.attrs.get("env_args", "{}"))
  entities = json.loads(g.attrs["entity_names"])
  label_names = tuple(json.loads(g.attrs["labels"]))
  demos = sorted((k for k in g if k.startswith("demo_")), key=lambda k: int(k.split("_")[1]))
  if not demos:
    raise ValueError(f"{path}: no demos in 'data' (empty dataset)")
  first = g[demos[0]]
  if "obs" not in first:
    raise ValueError(f"{path}: wrong layout: {demos[0]} has no 'obs' group")
  obs_keys = list(first["obs"])
  lengths = np.asarray([int(g[k].attrs["num_samples"]) for k in demos], np.int32)
  t_max = int(lengths.max())

  def stack(key, default=None):
    out = None
    for i, k in enumerate(demos):
      if key in g[k]:
        a = g[k][key][()]
      elif default is not None:
        a = np.full(lengths[i], default)
      else:
        raise ValueError(f"{path}: {k} lacks {key!r}")
      if a.shape[0] != lengths[i]:
        raise ValueError(f"{path}: {k}/{key} has {a.shape[0]} steps, num_samples says {lengths[i]}")
      if out is None:
        out = np.zeros((len(demos), t_max) + a.shape[1:], a.dtype)
      elif a.shape[1:] != out.shape[2:]:
        raise ValueError(f"{path}: {k}/{key} has shape {a.shape}, other demos {out.shape[2:]} per step")
      out[i, : lengths[i]] = a
    return out

  success, safe, labels = (_read_masks if fmt >= 2 else _read_attrs)(f, path, demos, label_names)
  return Dataset(
      obs={k: stack(f"obs/{k}") for k in obs_keys},
      actions=stack("actions"),
      rewards=stack("rewards"),
      dones=stack("dones"),
      states=stack("states"),
      health={e: stack(f"health/{e}") for e in entities},
      damage={k: stack(f"damage/{k}") for k in DAMAGE_KINDS},
      cost=stack("cost"),
      keep=stack("keep", default=True).astype(bool),
      lengths=lengths,
      success=success,
      safe=safe,
      labels=labels,
      env_name=env_name,
      env_config=config_json(env_args.get("env_kwargs", {})),
      label_names=label_names,
  )


def _read_masks(f, path: str, demos: list, label_names: tuple) -> tuple:
  """Format 2: success, safe bool[E] and labels i32[E] from the ``mask/`` filter keys."""
  names = np.asarray(demos, dtype="S")

  def member(key, required=True):
    if f"mask/{key}" not in f:
      if required:
        raise ValueError(f"{path}: wrong layout: no 'mask/{key}' (the demos' episode flags)")
      return np.zeros(len(demos), bool)
    return np.isin(names, f[f"mask/{key}"][()])

  success, safe = member("success"), member("safe")
  labels = np.zeros(len(demos), np.int32)
  if label_names:
    by_label = np.stack([member(MASK_PREFIX + n, required=False) for n in label_names])
    count = by_label.sum(0)
    if np.any(count != 1):
      bad = demos[int(np.flatnonzero(count != 1)[0])]
      raise ValueError(f"{path}: wrong layout: {bad} is in {int(count[demos.index(bad)])} of the "
                       f"mask/{MASK_PREFIX}<name> keys (each demo has one label)")
    labels = np.argmax(by_label, axis=0).astype(np.int32)
  return success, safe, labels


def _read_attrs(f, path: str, demos: list, label_names: tuple) -> tuple:
  """Format 1: success, safe bool[E] and labels i32[E] from each demo's attributes."""
  g = f["data"]
  labels = [str(g[k].attrs.get("label", "")) for k in demos]
  for lab in labels:
    if label_names and lab not in label_names:
      raise ValueError(f"{path}: demo label {lab!r} not in data.attrs labels {list(label_names)}")
  return (np.asarray([bool(g[k].attrs["success"]) for k in demos]),
          np.asarray([bool(g[k].attrs["safe"]) for k in demos]),
          np.asarray([label_names.index(lab) if label_names else 0 for lab in labels], np.int32))

"""Checkpoints: a pytree's leaves in one ``.npz`` file, plus JSON metadata.

A checkpoint holds two trees, each with a leading seed axis S on every leaf
(one file for all seeds of a run):

* ``state`` — the full :class:`train.iteration.TrainState` (network params,
  optimizer state, normaliser, multiplier, env states, episode accumulators,
  RNG, iteration counter), for exact ``--resume``;
* ``policy`` — only what inference needs, ``(normaliser, policy params)``, so a
  policy can be loaded without building the env or the optimizer.

``meta["config"]["seeds"]`` lists the seeds in axis order. Only leaves are
stored; the tree structure comes from a *template* built by the caller from
the same config (``jax.eval_shape`` of the init function: traces, compiles
nothing). Writes go through :func:`mjx_damage.io.atomic_path`, so an
interrupted write leaves the previous checkpoint; a truncated or corrupt file
(copied half-way, disk full) raises ``ValueError("checkpoint: <file> ...")``.
"""

from __future__ import annotations

import json
import os
import zipfile
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from mjx_damage import io

FILENAME = "checkpoint.npz"


def file_of(path: str) -> str:
  """A run directory's ``checkpoint.npz``, or ``path`` itself (a checkpoint file)."""
  return os.path.join(path, FILENAME) if os.path.isdir(path) else path


def save(path: str, state: Any, policy: Any, meta: dict) -> None:
  """Write ``state`` and ``policy`` leaves and ``meta`` (JSON-able) to ``path`` atomically."""
  arrays = {}
  for prefix, tree in (("s", state), ("p", policy)):
    for i, leaf in enumerate(jax.device_get(jax.tree.leaves(tree))):
      arrays[f"{prefix}{i}"] = np.asarray(leaf)
  # default=repr: task overrides may hold callables (params_fn); record, don't fail.
  arrays["meta"] = np.frombuffer(json.dumps(meta, default=repr).encode(), dtype=np.uint8)
  with io.atomic_path(path, suffix=".npz") as tmp:
    with open(tmp, "wb") as f:
      np.savez(f, **arrays)


def _open(path: str):
  """``np.load`` of a checkpoint with every way a file can be broken turned into one clear error."""
  if not os.path.isfile(path):
    raise ValueError(f"checkpoint: no checkpoint file at {path}")
  try:
    z = np.load(path)
    if not hasattr(z, "files") or "meta" not in z.files:
      raise ValueError("no 'meta' entry")
    return z
  except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
    raise ValueError(f"checkpoint: {path} is truncated or corrupt, not a checkpoint written by train ({e}); "
                     "delete it to start over") from e


def _read(z, path: str, key: str) -> np.ndarray:
  try:
    return z[key]
  except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
    raise ValueError(f"checkpoint: {path} is truncated or corrupt: cannot read entry {key!r} ({e})") from e


def read_meta(path: str) -> dict:
  with _open(path) as z:
    raw = _read(z, path, "meta")
  try:
    return json.loads(raw.tobytes().decode())
  except (UnicodeDecodeError, json.JSONDecodeError) as e:
    raise ValueError(f"checkpoint: {path} has corrupt metadata ({e})") from e


def check_seed(file: str, seeds, seed: int, field: str) -> None:
  """ValueError naming ``field`` unless ``seed`` is one of ``seeds``, the training seeds of checkpoint ``file``."""
  if seed not in seeds:
    raise ValueError(f"{field}: {seed} is not a seed of {file} (its seeds: {', '.join(map(str, seeds))})")


def restore(path: str, template: Any, which: str = "state") -> Any:
  """Leaves of ``which`` ('state' or 'policy') from ``path`` in the structure of ``template``.

  ``template`` may hold arrays or ``jax.ShapeDtypeStruct``s. Shapes must match
  exactly (a mismatch means the checkpoint comes from another config); dtypes
  are cast to the template's.
  """
  if which not in ("state", "policy"):
    raise ValueError(f"which: 'state' or 'policy', got {which!r}")
  prefix = "s" if which == "state" else "p"
  t_leaves, treedef = jax.tree.flatten(template)
  with _open(path) as z:
    n = sum(1 for k in z.files if k.startswith(prefix) and k[1:].isdigit())
    if n != len(t_leaves):
      raise ValueError(f"checkpoint: {path} holds {n} {which} arrays, this config needs {len(t_leaves)}")
    leaves = [_read(z, path, f"{prefix}{i}") for i in range(n)]
  out = []
  for i, (a, t) in enumerate(zip(leaves, t_leaves)):
    if tuple(a.shape) != tuple(t.shape):
      raise ValueError(f"checkpoint: {path} {which} array {i} has shape {a.shape}, this config needs {t.shape}")
    out.append(_like(a, t))
  return jax.tree.unflatten(treedef, out)


def _like(a: np.ndarray, t):
  """``a`` as the template leaf's dtype, weakly typed where the template is.

  A weak-typed scalar (brax's normaliser ``std_eps`` is a Python float) comes
  back as a strong one from numpy; the jitted iteration would then see a new
  input signature and compile a second time. A Python scalar keeps it weak.
  """
  if getattr(t, "weak_type", False) and a.ndim == 0:
    w = jnp.asarray(a.item())
    if w.dtype == t.dtype:
      return w
  return a.astype(t.dtype)


def export_policy(src: str, dst: str) -> None:
  """Write the ``policy`` half of checkpoint ``src`` (and its metadata) alone to ``dst``.

  What :func:`train.load_policy` and ``train(init_from=…)`` read, without the
  env states that make up nearly all of a run's checkpoint (≈ 130 MB for 3
  seeds × 2048 envs of Pick Egg against ≈ 0.1 MB of weights): the file to move
  a trained policy between machines or to commit beside a result. It cannot
  ``resume`` a run. ``dst`` is written atomically; ``src`` is checked as by
  :func:`restore` (``ValueError("checkpoint: …")``).
  """
  with _open(src) as z:
    keys = [k for k in z.files if k == "meta" or (k.startswith("p") and k[1:].isdigit())]
    arrays = {k: _read(z, src, k) for k in keys}
  with io.atomic_path(dst, suffix=".npz") as tmp:
    with open(tmp, "wb") as f:
      np.savez_compressed(f, **arrays)

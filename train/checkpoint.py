"""Checkpoints: a pytree's leaves in one ``.npz`` file, plus JSON metadata.

A checkpoint holds two trees:

* ``state`` — the full :class:`train.ppo.TrainState` (network params, optimizer
  state, observation normaliser, Lagrange multiplier, env states, episode
  accumulators, RNG, iteration counter), for exact ``--resume``;
* ``policy`` — only what inference needs, ``(normaliser, policy params)``, so a
  policy can be loaded without building the env or the optimizer.

Only leaves are stored; the tree structure comes from a *template* built by the
caller from the same config (``jax.eval_shape`` of the init function, which
traces but compiles nothing). This needs no new dependency and works for any
pytree (``mjx.Data``, optax states, brax's ``UInt64``) — no serialisation
registry to keep in sync. Files are written to a temporary name and renamed, so
an interrupted write never leaves a truncated checkpoint behind.
"""

from __future__ import annotations

import json
import os
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

FILENAME = "checkpoint.npz"


def save(path: str, state: Any, policy: Any, meta: dict) -> None:
  """Write ``state`` and ``policy`` leaves and ``meta`` (JSON-able) to ``path`` atomically."""
  arrays = {}
  for prefix, tree in (("s", state), ("p", policy)):
    for i, leaf in enumerate(jax.device_get(jax.tree.leaves(tree))):
      arrays[f"{prefix}{i}"] = np.asarray(leaf)
  # default=repr: task overrides may hold callables (params_fn); record, don't fail.
  arrays["meta"] = np.frombuffer(json.dumps(meta, default=repr).encode(), dtype=np.uint8)
  tmp = path + ".tmp"
  with open(tmp, "wb") as f:
    np.savez(f, **arrays)
  os.replace(tmp, path)


def read_meta(path: str) -> dict:
  with np.load(path) as z:
    return json.loads(z["meta"].tobytes().decode())


def _leaves(z, prefix: str) -> list[np.ndarray]:
  n = sum(1 for k in z.files if k.startswith(prefix) and k[len(prefix):].isdigit())
  return [z[f"{prefix}{i}"] for i in range(n)]


def restore(path: str, template: Any, which: str = "state") -> Any:
  """Leaves of ``which`` ('state' or 'policy') from ``path`` in the structure of ``template``.

  ``template`` may hold arrays or ``jax.ShapeDtypeStruct``s. Shapes must match
  exactly (a mismatch means the checkpoint comes from another config); dtypes
  are cast to the template's.
  """
  if which not in ("state", "policy"):
    raise ValueError(f"which: 'state' or 'policy', got {which!r}")
  t_leaves, treedef = jax.tree.flatten(template)
  with np.load(path) as z:
    leaves = _leaves(z, "s" if which == "state" else "p")
  if len(leaves) != len(t_leaves):
    raise ValueError(f"checkpoint: {path} holds {len(leaves)} {which} arrays, this config needs {len(t_leaves)}")
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

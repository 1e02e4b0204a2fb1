"""Traced programs kept on disk, so a warm command skips Python tracing as well as XLA compilation.

JAX's persistent compilation cache (:func:`mjx_damage.runtime.enable_compilation_cache`)
stores *compiled* executables, keyed by the lowered module; computing that key
means tracing the whole program in Python again. For a task's evaluation on CPU
that tracing (vmap of MJX's nested loops) takes 4–7 s, the largest part of a
warm ``mjx-damage eval``. Here the traced and lowered program itself is kept, as
a :mod:`jax.export` artifact (StableHLO with its calling convention), under
``<cache dir>/programs/<key>.jaxexport``. A hit deserialises it and jit-compiles
it, which the compilation cache then answers: no tracing at all.

The key is a SHA-256 over everything the traced program depends on:

* ``description`` — a JSON-able dict the caller gives (task name, overrides,
  policy spec, episode length, checkpoint config …);
* the shapes, dtypes and shardings of the arguments;
* :func:`fingerprint` of the source trees that build the program (every file:
  Python and the MJCF scenes beside it);
* the versions of the libraries that trace it, the Python version, JAX's x64 flag
  and float32 matmul precision (:func:`mjx_damage.runtime.matmul_precision`; a program traced at TF32 is
  another program than one at float32) and the device platform and count.

So only a caller that can *name* everything its function closes over may use it
(the CLI: a program built from names and files); a Python user passing arbitrary
closures uses plain ``jax.jit``. ``MJX_DAMAGE_CACHE_DIR=off`` switches this off
with the compilation cache. A corrupt or unreadable entry is ignored (with a
warning) and rewritten.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import warnings
from importlib import metadata
from typing import Callable, Optional, Sequence

import jax
from jax import export

from mjx_damage import runtime
from mjx_damage.io import write_bytes

SUFFIX = ".jaxexport"
_LIBRARIES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "brax", "flax", "optax", "numpy")
_SKIP_DIRS = {"__pycache__", ".ipynb_checkpoints"}


def directory() -> Optional[str]:
  """Where programs are kept (``<compilation cache>/programs``), or None when the cache is off."""
  base = runtime.cache_dir()
  return None if base is None else os.path.join(base, "programs")


@functools.lru_cache(maxsize=None)
def fingerprint(roots: tuple[str, ...]) -> str:
  """SHA-256 (hex) of every file under the directories ``roots`` (relative path + bytes), sorted."""
  h = hashlib.sha256()
  for root in roots:
    root = os.path.abspath(root)
    for dirpath, dirnames, files in os.walk(root):
      dirnames[:] = sorted(d for d in dirnames if d not in _SKIP_DIRS)
      for name in sorted(files):
        if name.endswith((".pyc", ".pyo")):
          continue
        path = os.path.join(dirpath, name)
        h.update(os.path.relpath(path, os.path.dirname(root)).encode())
        with open(path, "rb") as f:
          h.update(hashlib.sha256(f.read()).digest())
  return h.hexdigest()


def _versions() -> dict:
  out = {}
  for lib in _LIBRARIES:
    try:
      out[lib] = metadata.version(lib)
    except metadata.PackageNotFoundError:
      out[lib] = None
  return out


def _arg_spec(args) -> list:
  """Shape, dtype and sharding of every leaf of ``args`` plus the tree structure, JSON-able."""
  leaves, tree = jax.tree.flatten(args)
  spec = [str(tree)]
  for x in leaves:
    s = getattr(x, "sharding", None)
    spec.append([list(jax.numpy.shape(x)), str(jax.numpy.result_type(x)), str(getattr(s, "spec", None))])
  return spec


def key(description: dict, args, roots: Sequence[str]) -> str:
  """The cache key (hex) of a program described by ``description`` called with ``args``."""
  payload = {
      "description": description,
      "args": _arg_spec(args),
      "sources": fingerprint(tuple(roots)),
      "versions": _versions(),
      "python": list(sys.version_info[:2]),
      "x64": bool(jax.config.jax_enable_x64),
      "matmul_precision": runtime.matmul_precision(),
      "devices": [jax.default_backend(), jax.device_count()],
  }
  return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()


def _shape_struct(x):
  return jax.ShapeDtypeStruct(jax.numpy.shape(x), jax.numpy.result_type(x), sharding=getattr(x, "sharding", None))


def load_or_export(fn: Callable, args, description: dict, roots: Sequence[str]) -> tuple[Callable, str]:
  """A callable equivalent to the jitted ``fn`` for arguments shaped like ``args``, and how it was got.

  ``fn``: a ``jax.jit`` function. ``args``: a tuple of example arguments (arrays or
  pytrees; their values are not used). Returns ``(call, how)`` with ``how`` one of
  ``"loaded"`` (the traced program came from disk: no tracing), ``"exported"``
  (traced now and stored for the next process) or ``"off"`` (cache disabled, or
  JAX's GSPMD partitioner on: ``fn`` itself).
  """
  where = directory()
  if where is None or not jax.config.jax_use_shardy_partitioner:
    # Off under GSPMD (train.mesh switches to it for several devices): jax 0.10.2 exports shard_map
    # programs with Shardy annotations that GSPMD then refuses to lower ("'stablehlo.custom_call' op
    # should have a sharding attribute of type TensorShardingPerValueAttr"), in the exporting process too.
    return fn, "off"
  path = os.path.join(where, key(description, args, roots) + SUFFIX)
  if os.path.isfile(path):
    try:
      with open(path, "rb") as f:
        exported = export.deserialize(bytearray(f.read()))
      return jax.jit(exported.call), "loaded"
    except Exception as e:  # a truncated or foreign file must not stop the command: trace again
      warnings.warn(f"program cache: ignoring unreadable {path} ({type(e).__name__}: {e})",
                    RuntimeWarning, stacklevel=2)
  blob = export.export(fn)(*jax.tree.map(_shape_struct, args)).serialize()
  try:
    os.makedirs(where, exist_ok=True)
    write_bytes(path, blob)
  except OSError as e:  # read-only cache: run without storing
    warnings.warn(f"program cache: cannot write {path}: {e}", RuntimeWarning, stacklevel=2)
  # Run what later processes will load (the round trip), so this process's compilation is the one
  # the compilation cache answers for them.
  return jax.jit(export.deserialize(bytearray(blob)).call), "exported"

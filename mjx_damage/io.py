"""Crash-safe file output: every file the project writes goes through here.

A file is written to a temporary name in its own directory, flushed to disk,
and renamed over the target (``os.replace`` is atomic on POSIX), so a process
killed at any moment leaves either the old file or the new one, never half of
one. A killed writer can leave a ``.<name>.tmp-*`` file behind; it is never
mistaken for a result because no reader opens that name.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from typing import Any, Iterator


@contextlib.contextmanager
def atomic_path(path: str, suffix: str = "") -> Iterator[str]:
  """Yield a temporary path beside ``path``; on success rename it to ``path``.

  For writers that take a file name (matplotlib, imageio, h5py). ``suffix``
  keeps an extension those libraries read the format from.
  """
  path = os.fspath(path)
  d = os.path.dirname(os.path.abspath(path))
  os.makedirs(d, exist_ok=True)
  fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.tmp-", suffix=suffix, dir=d)
  os.close(fd)
  try:
    yield tmp
    with open(tmp, "rb+") as f:
      os.fsync(f.fileno())
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; a result file gets the usual permissions
    os.replace(tmp, path)
  finally:
    if os.path.exists(tmp):
      os.unlink(tmp)


def _umask() -> int:
  mask = os.umask(0)
  os.umask(mask)
  return mask


def write_bytes(path: str, data: bytes) -> None:
  with atomic_path(path) as tmp:
    with open(tmp, "wb") as f:
      f.write(data)


def write_text(path: str, text: str) -> None:
  write_bytes(path, text.encode("utf-8"))


def read_json(path: str, field: str) -> Any:
  """The JSON value in ``path``; a missing, unreadable or corrupt file raises ValueError naming ``field``."""
  try:
    with open(path) as f:
      return json.load(f)
  except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
    raise ValueError(f"{field}: cannot read {path!r} ({e})") from None


def write_json(path: str, obj: Any, indent: int = 2) -> None:
  write_text(path, json.dumps(obj, indent=indent, default=_jsonable) + "\n")


def _jsonable(x):
  """numpy / jax scalars and arrays as plain JSON values."""
  import numpy as np

  a = np.asarray(x)
  return a.item() if a.ndim == 0 else a.tolist()

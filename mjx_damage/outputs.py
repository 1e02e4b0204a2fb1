"""Where a command's outputs go: never over an existing result unless asked, else a new run folder.

Every command that writes checks its output paths while it parses its
arguments, before any JAX work: an existing path is refused with one line
naming the flag and the ways on (``--resume`` where a run can be continued,
``--overwrite`` to replace it). A command given no ``--out`` writes into a
fresh folder ``runs/<command>-<task>-<YYYYmmdd-HHMMSS>/`` of the current
directory, so repeating a command never touches the previous run's files.
"""

from __future__ import annotations

import os
import re
import time
from typing import Iterable, Optional

RUNS_DIR = "runs"


def run_dir(command: str, task: Optional[str] = None, when: Optional[float] = None) -> str:
  """A new, not yet existing folder ``runs/<command>[-<task>]-<YYYYmmdd-HHMMSS>[-n]`` (relative path)."""
  stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(when))
  label = re.sub(r"[^A-Za-z0-9_.+-]+", "_", "-".join(x for x in (command, task) if x))
  base = os.path.join(RUNS_DIR, f"{label}-{stamp}")
  path, n = base, 1
  while os.path.exists(path):
    path, n = f"{base}-{n}", n + 1
  return path


def check_writable(path: str, flag: str = "--out") -> None:
  """``ValueError("<flag>: ...")`` when ``path`` could not be created: the nearest existing ancestor
  is not a writable folder."""
  parent = os.path.dirname(os.path.abspath(path))
  while not os.path.exists(parent):
    parent = os.path.dirname(parent)
  if not os.path.isdir(parent):
    raise ValueError(f"{flag}: cannot write {path}: {parent} is a file, not a folder")
  if not os.access(parent, os.W_OK | os.X_OK):
    raise ValueError(f"{flag}: cannot write {path}: no write permission in {parent}")


def exists(path: str) -> bool:
  """A file, or a folder with something in it (an empty folder someone made for the run is free)."""
  return os.path.isfile(path) or (os.path.isdir(path) and bool(os.listdir(path))) or os.path.islink(path)


def check_new(paths: Iterable[str], flag: str = "--out", overwrite: bool = False, resumable: bool = False,
              folder: bool = False) -> None:
  """Refuse (``ValueError`` naming ``flag``) when one of ``paths`` :func:`exists` and ``overwrite`` is
  False; also refuse paths that cannot be written, and a folder where a file is wanted (``folder``:
  the paths are run folders). ``resumable``: the message offers ``--resume`` too."""
  for path in paths:
    if not folder and os.path.isdir(path):
      raise ValueError(f"{flag}: {path} is a folder; give a file path")
    if exists(path) and not overwrite:
      ways = "--resume to continue it or --overwrite to replace it" if resumable else "--overwrite to replace it"
      raise ValueError(f"{flag}: {path} already exists; pass {ways}, or choose another {flag}")
    check_writable(path, flag)

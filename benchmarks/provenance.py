"""What made a benchmark's results: the command, the git revision, jax and its backend, the date; and the
writer of a results pair (``.json`` + ``.md``) stamped with them. Shared by the sibling benchmarks (imported as
``provenance``: a script's own folder is on its ``sys.path``)."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage.io import write_json, write_text  # noqa: E402  (first: mjx_damage sets XLA flags before jax starts)
import jax  # noqa: E402


def git() -> str:
  """The checkout's short revision, ``+dirty`` with uncommitted changes to tracked files, or ``unknown``."""
  try:
    rev = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                         timeout=10).stdout.strip()
    dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True, timeout=10).stdout.strip()
    return rev + ("+dirty" if dirty else "") if rev else "unknown"
  except (OSError, subprocess.SubprocessError):
    return "unknown"


def command(script: str, argv) -> str:
  """The command line that reruns ``benchmarks/<script>.py`` with ``argv`` (None: this process's arguments)."""
  return f"PYTHONPATH=. .venv/bin/python benchmarks/{script}.py " + " ".join(
      shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))


def now() -> str:
  return time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())


def save_results(res: dict, script: str, argv, stem: str, render) -> None:
  """Stamp ``res`` with what made it (:func:`command`, jax, backend, date, :func:`git`) and write
  ``stem``.json and ``stem``.md (``render(res)``)."""
  res.update(command=command(script, argv), jax=jax.__version__, backend=jax.default_backend(), date=now(), git=git())
  write_json(stem + ".json", res)
  write_text(stem + ".md", render(res))
  print(f"wrote {stem}.json / .md")

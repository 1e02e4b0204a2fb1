"""Scripts that split their work over child processes (``--workers``): the command each child runs.

A parent re-runs its own script in each child with the same arguments, except the few that
say which share of the work the child does (``--tasks``) and where it writes (``--out``).
"""

from __future__ import annotations


def argv_without(argv: list[str], flags: tuple[str, ...]) -> list[str]:
  """``argv`` without ``flags`` and their values, in either form (``--f v`` or ``--f=v``).

  For scripts that re-run themselves in child processes, each child with its own value of these."""
  out, skip = [], False
  for a in argv:
    if skip:
      skip = False
      continue
    if a.split("=")[0] in flags:
      skip = "=" not in a
      continue
    out.append(a)
  return out

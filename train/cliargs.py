"""Command-line parsing every ``mjx-damage`` command shares: one-line errors, defaults shown in ``--help``.

argparse's own error path prints the whole usage block before the message;
a user who typed one wrong value should read one line naming the flag, and
the exit status 2 a shell script can test. ``--help`` shows every default
(``ArgumentDefaultsHelpFormatter``) while keeping hand-wrapped descriptions.
"""

from __future__ import annotations

import argparse
import sys


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
  """Defaults appended to every option's help; descriptions printed as written."""


class Parser(argparse.ArgumentParser):
  """``ArgumentParser`` whose errors are one line, ``<prog>: error: <message>``, exit status 2."""

  def __init__(self, *args, **kwargs):
    kwargs.setdefault("formatter_class", HelpFormatter)
    super().__init__(*args, **kwargs)

  def error(self, message: str):
    print(f"{self.prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
    sys.exit(2)

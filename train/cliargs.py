"""Command-line parsing every ``mjx-damage`` command shares: one-line errors, defaults shown in ``--help``.

argparse's own error path prints the whole usage block before the message;
a user who typed one wrong value should read one line naming the flag, and
the exit status 2 a shell script can test. ``--help`` shows every default
(``ArgumentDefaultsHelpFormatter``) while keeping hand-wrapped descriptions.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import threading
import time


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
  """``(default: X)`` after every option that has a default its help does not already state;
  descriptions printed as written."""

  def _get_help_string(self, action):
    text = action.help or ""
    if ("(default" in text or action.default in (None, argparse.SUPPRESS) or action.required
        or not action.option_strings or action.nargs == 0):
      return text
    return (text + " " if text else "") + "(default: %(default)s)"


class Parser(argparse.ArgumentParser):
  """``ArgumentParser`` whose errors are one line, ``<prog>: error: <message>``, exit status 2."""

  def __init__(self, *args, **kwargs):
    kwargs.setdefault("formatter_class", HelpFormatter)
    super().__init__(*args, **kwargs)

  def add_argument(self, *args, **kwargs):
    action = super().add_argument(*args, **kwargs)
    if not action.help and action.default not in (None, argparse.SUPPRESS) and action.nargs != 0:
      action.help = "(default: %(default)s)"  # argparse prints no help line at all for an empty help
    return action

  def error(self, message: str):
    print(f"{self.prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
    sys.exit(2)


def say_compiling(seconds: dict, platform: str, what: str = "the first time", default: int = 60) -> None:
  """Print the line every command prints before its first compile.

  ``seconds``: rough first-compile time of the command's program per platform
  ("cpu", "gpu"), s — an estimate shown to the user, not a measurement.
  """
  print(f"compiling, about {seconds.get(platform, default)} s {what} (seconds once cached) ...", flush=True)


@contextlib.contextmanager
def heartbeat(label: str, every: float = 20.0, stream=None):
  """While the block runs, print ``"<label>: still working, N s so far"`` every ``every`` seconds.

  A compiled call (compilation, or one long batched rollout) gives Python no
  place to report progress from; a line at a steady rhythm tells the user the
  command is alive and how long it has taken. The printing thread is a daemon
  and stops when the block ends (normally, by an error or by Ctrl-C).
  """
  stream = sys.stdout if stream is None else stream
  stop = threading.Event()
  t0 = time.perf_counter()

  def beat():
    while not stop.wait(every):
      print(f"{label}: still working, {time.perf_counter() - t0:.0f} s so far", file=stream, flush=True)

  thread = threading.Thread(target=beat, name="mjx-damage-heartbeat", daemon=True)
  thread.start()
  try:
    yield
  finally:
    stop.set()

"""``mjx-damage`` console script: one subcommand per job.

Each subcommand lives in the module that owns the job and exposes
``main(argv) -> int``; this file only dispatches, importing the chosen module
when it runs, so ``mjx-damage --help`` starts without loading JAX.

What a user sees when something goes wrong is decided here, for every command:

* a user error (``ValueError``/``FileNotFoundError`` raised while checking the
  arguments, before anything compiles) → one line ``mjx-damage <cmd>: error: …``,
  exit status 2 (``MJX_DAMAGE_TRACEBACK=1`` shows the traceback instead);
* Ctrl-C → one line ``interrupted; …``, exit status 130, no traceback. A SIGINT
  that arrives while XLA compiles is seen by Python only when the compile
  returns (and raising ``KeyboardInterrupt`` then has ended in a segfault at
  interpreter exit), so a watcher thread woken through ``signal.set_wakeup_fd``
  ends the process at once with ``os._exit(130)``. Inside the training loop
  ``train.ppo`` installs its own handler (finish the iteration, write the
  checkpoint, exit 130); the watcher steps aside whenever the SIGINT handler is
  not its own.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import signal
import socket
import sys
import threading

SUBCOMMANDS = {
    "demo": ("apps.demo_cli", "damage-aware batched rollout of the built-in drop scene"),
    "eval": ("apps.eval_cli", "evaluate a policy on a task for N episodes (table + JSON)"),
    "sweep": ("apps.sweep_cli", "tasks x policies x seeds x fragility table (markdown + JSON)"),
    "train": ("train.cli", "PPO / PPO-Lagrangian training on a task"),
    "bench": ("apps.bench.cli", "throughput benchmark (JSON + PNG)"),
    "render": ("apps.render_cli", "render a rollout with damage tint and health bars"),
    "record": ("apps.record_cli", "record N episodes of a policy or operator as an HDF5 dataset"),
    "bc": ("apps.bc_cli", "behaviour cloning of a dataset into a PPO actor (fine-tune with train --init-from)"),
    "tasks": ("apps.tasks_cli", "list the tasks: damage modality, entities, unsafe shortcut, safe strategy"),
    "view": ("apps.view_cli", "interactive viewer: live health bars and tint, teleoperation, --record"),
}
INTERRUPTED = 130
KEPT = "files written so far are kept, each one complete (atomic writes); nothing else was written"
_exit_lock = threading.Lock()


def _usage() -> str:
  lines = ["usage: mjx-damage <command> [options]", "", "commands:"]
  lines += [f"  {k:<8} {v[1]}" for k, v in SUBCOMMANDS.items()]
  lines += ["", "mjx-damage <command> --help for a command's options"]
  return "\n".join(lines)


def _exit_interrupted() -> None:
  if not _exit_lock.acquire(blocking=False):
    return  # the other path (handler or watcher) is already exiting
  for f in (sys.stdout, sys.stderr):
    with contextlib.suppress(Exception):
      f.flush()
  os.write(2, f"\ninterrupted; {KEPT}\n".encode())
  os._exit(INTERRUPTED)


def _on_sigint(signum, frame):
  _exit_interrupted()


@contextlib.contextmanager
def _clean_interrupts():
  """SIGINT → one line and exit 130, even while XLA compiles (see the module docstring)."""
  if threading.current_thread() is not threading.main_thread():
    yield
    return
  r, w = socket.socketpair()
  w.setblocking(False)
  old_handler = signal.signal(signal.SIGINT, _on_sigint)
  old_fd = signal.set_wakeup_fd(w.fileno(), warn_on_full_buffer=False)

  def watch():
    while True:
      try:
        data = r.recv(64)
      except OSError:
        return
      if not data:
        return
      if signal.SIGINT in data and signal.getsignal(signal.SIGINT) is _on_sigint:
        _exit_interrupted()

  threading.Thread(target=watch, name="mjx-damage-sigint", daemon=True).start()
  try:
    yield
  finally:
    signal.set_wakeup_fd(old_fd)
    signal.signal(signal.SIGINT, old_handler)
    w.close()  # EOF ends the watcher
    r.close()


def _one_line(e: BaseException) -> str:
  return " ".join(str(e).split())


def main(argv=None) -> int:
  argv = list(sys.argv[1:] if argv is None else argv)
  if not argv or argv[0] in ("-h", "--help"):
    print(_usage())
    return 0
  cmd, rest = argv[0], argv[1:]
  if cmd not in SUBCOMMANDS:
    print(f"mjx-damage: error: unknown command {cmd!r} (valid: {', '.join(SUBCOMMANDS)})", file=sys.stderr)
    return 2
  debug = os.environ.get("MJX_DAMAGE_TRACEBACK", "") not in ("", "0")
  try:
    with _clean_interrupts():
      module = importlib.import_module(SUBCOMMANDS[cmd][0])
      return int(module.main(rest) or 0)
  except SystemExit as e:  # argparse (0 for --help, 2 for errors) and train's 130 after a checkpoint
    return e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
  except KeyboardInterrupt:
    print(f"\ninterrupted; {KEPT}", file=sys.stderr)
    return INTERRUPTED
  except (ValueError, FileNotFoundError) as e:
    if debug:
      raise
    print(f"mjx-damage {cmd}: error: {_one_line(e)}", file=sys.stderr)
    return 2


if __name__ == "__main__":
  sys.exit(main())

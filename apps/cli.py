"""``mjx-damage`` console script: one subcommand per job.

Each subcommand lives in the module that owns the job and exposes
``main(argv) -> int``; this file only dispatches, importing the chosen module
when it runs, so ``mjx-damage --help`` starts without loading JAX.
"""

from __future__ import annotations

import importlib
import sys

SUBCOMMANDS = {
    "demo": ("apps.demo_cli", "damage-aware batched rollout of the built-in drop scene"),
    "eval": ("apps.eval_cli", "evaluate a policy on a task for N episodes (table + JSON)"),
    "sweep": ("apps.sweep_cli", "tasks x policies x seeds x fragility table (markdown + JSON)"),
    "train": ("train.cli", "PPO / PPO-Lagrangian training on a task"),
    "bench": ("apps.bench.cli", "throughput benchmark (JSON + PNG)"),
    "render": ("apps.render_cli", "render a rollout with damage tint and health bars"),
}


def _usage() -> str:
  lines = ["usage: mjx-damage <command> [options]", "", "commands:"]
  lines += [f"  {k:<8} {v[1]}" for k, v in SUBCOMMANDS.items()]
  lines += ["", "mjx-damage <command> --help for a command's options"]
  return "\n".join(lines)


def main(argv=None) -> int:
  argv = list(sys.argv[1:] if argv is None else argv)
  if not argv or argv[0] in ("-h", "--help"):
    print(_usage())
    return 0
  cmd, rest = argv[0], argv[1:]
  if cmd not in SUBCOMMANDS:
    print(f"mjx-damage: unknown command {cmd!r}\n\n{_usage()}", file=sys.stderr)
    return 2
  module = importlib.import_module(SUBCOMMANDS[cmd][0])
  return int(module.main(rest) or 0)


if __name__ == "__main__":
  sys.exit(main())

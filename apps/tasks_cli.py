"""``mjx-damage tasks``: the task suite at a glance — what each task damages, how, and how to avoid it.

    mjx-damage tasks                      # markdown table of every registered task
    mjx-damage tasks --format json        # the same as JSON (tasks.describe for each)
    mjx-damage tasks --task open_single_door

Reads class attributes only (:func:`tasks.describe`): nothing is compiled.
"""

from __future__ import annotations

import json
import sys

import tasks
from train.cliargs import Parser

COLUMNS = (("task", "name"), ("damage modality", "damage_modality"), ("tracked entities", "tracked_entities"),
           ("unsafe shortcut", "unsafe_shortcut"), ("safe strategy", "safe_strategy"), ("horizon (steps)", "horizon"),
           ("robots (default first)", "robots"), ("success condition", "success_condition"))


def markdown(rows: list[dict]) -> str:
  """One markdown table row per task description (the README's task table)."""
  def cell(v):
    return ", ".join(v) if isinstance(v, list) else str(v).replace("|", "\\|")

  def robots(r):  # the default first, each with the variant the task builds, if any
    names = [r["robot"]] + [n for n in r["robots"] if n != r["robot"]]
    return [f"{n} ({r['robot_variants'][n]})" if n in r["robot_variants"] else n for n in names]

  lines = ["| " + " | ".join(h for h, _ in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
  lines += ["| " + " | ".join(cell(robots(r) if k == "robots" else r[k]) for _, k in COLUMNS) + " |" for r in rows]
  return "\n".join(lines)


def build_parser() -> Parser:
  ap = Parser(prog="mjx-damage tasks", description="list the task suite: damage modality, tracked entities, "
              "unsafe shortcut, safe strategy, horizon, robots, success condition")
  ap.add_argument("--task", default=None, help="describe one task (default: all)")
  ap.add_argument("--format", choices=("md", "json"), default="md")
  return ap


def main(argv=None) -> int:
  args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
  names = [args.task] if args.task else tasks.names()
  rows = [tasks.describe(n) for n in names]  # an unknown --task raises ValueError naming the valid ones
  if args.format == "json":
    print(json.dumps(rows if not args.task else rows[0], indent=1, ensure_ascii=False))
  else:
    print(markdown(rows))
  return 0

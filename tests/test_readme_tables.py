"""The README's RL figures say what the committed trainer tables they link to say.

* Its trainer tables (``| trainer | reward | runs | completion, mode | …``): every row is a group of the table its
  list item links first, with its run count, mean completion and safe completion by the mode, sampled safe
  completion and runs meeting the bar.
* "RL at a glance": every leading "completion / safe, meeting / runs" figure of a setting that links a table is
  whole groups of it (one, or a union the README names), save the figures listed in ``PART_OF_A_GROUP``.

A figure left behind when its table was rebuilt with more runs fails here."""

from __future__ import annotations

import json
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HEADER = "| trainer | reward | runs | completion, mode | safe completion, mode | safe completion, sampled |"
_LINK = re.compile(r"\(benchmarks/results/(trainer_table_[A-Za-z0-9_]+)_mode\.md\)")
_NUM = re.compile(r"^\s*(\d+(?:\.\d+)?)")
_BARS = re.compile(r"(\d+) / (\d+)")


def _tables() -> list[tuple[str, list[list[str]]]]:
  """(linked table stem, rows as cells) of every README table with HEADER: the stem is the first trainer-table
  link of the list item (``- **…``) the table sits in."""
  lines = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read().splitlines()
  out = []
  for i, line in enumerate(lines):
    if not line.strip().startswith(HEADER):
      continue
    start = max(j for j in range(i) if lines[j].startswith("- **"))
    link = _LINK.search(" ".join(lines[start:i]))
    rows = []
    for row in lines[i + 2:]:
      if not row.strip().startswith("|"):
        break
      rows.append([c.strip() for c in row.strip().strip("|").split("|")])
    out.append((link.group(1) if link else None, rows))
  return out


def _pct(cell: str) -> float | None:
  m = _NUM.match(cell)
  return float(m.group(1)) if m else None


def _same(readme: float, frac: float) -> bool:
  return abs(readme - 100 * frac) <= 0.05 + 1e-9


def _groups(stem: str, action: str) -> list[dict]:
  with open(os.path.join(ROOT, "benchmarks", "results", f"{stem}_{action}.json"), encoding="utf-8") as f:
    return json.load(f)["groups"]


TABLES = _tables()


def test_the_readme_has_its_trainer_tables_and_each_links_one():
  assert len(TABLES) >= 2
  for stem, rows in TABLES:
    assert stem is not None and rows, "a README trainer table with no trainer-table link in its list item"


@pytest.mark.parametrize("stem,rows", TABLES, ids=[s or "?" for s, _ in TABLES])
def test_every_row_is_a_group_of_its_linked_table(stem, rows):
  mode, sample = _groups(stem, "mode"), _groups(stem, "sample")
  key = lambda g: (g["trainer"], g["reward"], g["settings"])  # noqa: E731
  by_key = {key(g): g for g in sample}
  for cells in rows:
    runs, compl, safe, sampled, bars = int(cells[2]), _pct(cells[3]), _pct(cells[4]), _pct(cells[5]), cells[6]
    matches = [g for g in mode if len(g["runs"]) == runs and _same(compl, g["completion"]["mean"])
               and _same(safe, g["safe_completion"]["mean"])]
    assert matches, f"README row {cells[:6]} is no group of {stem}_mode (runs, completion, safe completion)"
    counts = _BARS.findall(bars)
    ok = []
    for g in matches:
      s = by_key.get(key(g))
      good = int(counts[0][0]) == g["meet_bar"] if counts else True
      if sampled is not None and s is not None and s["safe_completion"] is not None:
        good = good and _same(sampled, s["safe_completion"]["mean"])
        if len(counts) > 1 and len(s["runs"]) == int(counts[1][1]):
          good = good and int(counts[1][0]) == s["meet_bar"]
      ok.append(good)
    assert any(ok), f"README row {cells} disagrees with {stem} (sampled safe completion or runs meeting the bar)"


GLANCE = "| task, setting (trainer table) | trainer | task reward only | w = 2 | contrast |"
_CELL = re.compile(r"^\**\s*(\d+(?:\.\d+)?) / (\d+(?:\.\d+)?), (\d+) / (\d+)")


def _glance_cells() -> list[tuple[str, str, str, tuple]]:
  """(linked table stem, trainer cell, reward kind, (completion, safe, meeting the bar, runs)) of every leading
  figure of the README's "RL at a glance" table whose setting links a trainer table."""
  lines = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read().splitlines()
  start = next(i for i, line in enumerate(lines) if line.startswith(GLANCE))
  out, stem = [], None
  for line in lines[start + 2:]:
    if not line.startswith("|"):
      break
    cells = [c.strip() for c in line.strip("|").split("|")]
    if cells[0]:  # a new setting: its link, or none (its rows are not checked here)
      m = _LINK.search(cells[0])
      stem = m.group(1) if m else None
    for col, kind in ((2, "task"), (3, "damage")):
      m = _CELL.match(cells[col])
      if stem and m:
        out.append((stem, cells[1], kind, (float(m[1]), float(m[2]), int(m[3]), int(m[4]))))
  return out


GLANCE_CELLS = _glance_cells()


def test_the_glance_table_is_checked_on_most_of_its_figures():
  assert len(GLANCE_CELLS) >= 20 and {s for s, *_ in GLANCE_CELLS} >= {
      "trainer_table_place_plate_box_h200_all", "trainer_table_shelve_item", "trainer_table_pick_egg_held"}


def _family(trainer: str) -> str:
  return "brax" if trainer.startswith("Brax") else "paper" if "paper's" in trainer else "ours"


def _meets(run: dict, kind: str) -> bool:
  """benchmarks/trainer_table.py's bars, per run."""
  c, s = run["scores"]["completion"], run["scores"]["safe_completion"]
  return s <= 0.20 and c >= 0.80 if kind == "task" else s >= 0.80 and c >= 0.90


# Figures the README draws from some of a group's results files, not all; each says so in its cell. Everywhere
# else a figure must be whole groups, so a figure left behind when its group grew fails.
PART_OF_A_GROUP = {
    ("trainer_table_shelve_item", "ours (gradient clip)", "damage"):
        "each seed alone on a GPU, 480 s: 5 of the group's 8 runs (the other 3 trained in one program)",
}


@pytest.mark.parametrize("stem,trainer,kind,figures", GLANCE_CELLS,
                         ids=[f"{s[14:]}-{t[:24]}-{k}" for s, t, k, _ in GLANCE_CELLS])
def test_every_glance_figure_is_whole_groups_of_its_table(stem, trainer, kind, figures):
  """A leading "completion / safe, meeting / runs" figure is one group of its linked table, or the union of up
  to three groups of one trainer and reward (where the README joins them, "with or without …"); figures of
  PART_OF_A_GROUP are the runs of up to five of a group's results files."""
  import itertools

  compl, safe, meet, n = figures

  def part(runs):
    return (len(runs), sum(_meets(r, kind) for r in runs), sum(r["scores"]["completion"] for r in runs),
            sum(r["scores"]["safe_completion"] for r in runs))

  groups, parts = [], []
  for g in _groups(stem, "mode"):
    if _family(g["trainer"]) != _family(trainer) or (g["reward"] == "task reward only") != (kind == "task"):
      continue
    groups.append(part(g["runs"]))
    for source in dict.fromkeys(r["source"] for r in g["runs"]):
      parts.append(part([r for r in g["runs"] if r["source"] == source]))

  def agrees(ps):
    runs = sum(p[0] for p in ps)
    return (runs == n and sum(p[1] for p in ps) == meet and _same(compl, sum(p[2] for p in ps) / runs)
            and _same(safe, sum(p[3] for p in ps) / runs))

  if (stem, trainer, kind) in PART_OF_A_GROUP:
    assert any(agrees(ps) for k in range(1, 6) for ps in itertools.combinations(parts, k)), (
        f"README 'RL at a glance' figure {figures} of {trainer!r} ({kind}) is not made of whole results files of "
        f"{stem}_mode")
    return
  assert any(agrees(gs) for k in range(1, 4) for gs in itertools.combinations(groups, k)), (
      f"README 'RL at a glance' figure {figures} of {trainer!r} ({kind}) is no group of {stem}_mode, nor a union "
      "of up to three")


def test_every_figure_read_from_part_of_a_group_is_in_the_glance_table():
  assert set(PART_OF_A_GROUP) <= {(s, t, k) for s, t, k, _ in GLANCE_CELLS}

"""The README's trainer tables (``| trainer | reward | runs | completion, mode | …``) say what the committed
trainer tables they link to say: every row is a group of that table, with its run count, its mean completion
and safe completion by the mode, its sampled safe completion and its runs meeting the bar. A README row left
behind when the table was rebuilt with more runs fails here."""

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

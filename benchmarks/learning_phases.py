"""Where a run's env steps go: finding the task, then doing it safely (no training; CPU, seconds).

For every run of the sources (the same files, runs and groups as ``trainer_table.py``), from its periodic
evaluations by the mode (ours: its history; Brax's: the scored curve of ``rl_brax_ppo.py --curve-episodes``):

  * **to 80 % completion**: env steps per seed to the first evaluation with ≥ 80 % completion (the task found,
    safely or not);
  * **to 80 % safe**: to the first with ≥ 80 % safe and ≥ 80 % completion (``trainer_table.py``'s env steps to
    80 % safe);
  * **between**: the second less the first, over the runs that reached both (0: found safely at once).

A trainer that needs more env steps to 80 % safe spends them in one phase or the other: exploring until
anything completes, or refining a found completion into a safe one. Cells are mean (min–max) over a group's runs
that reached the point, with how many did; the evaluations' spacing (the measure's grain, per group) bounds
what a difference means.

Example (the box counter's 300 s runs, H200, the table ``trainer_table_place_plate_box_h200_300s_*`` is built
from)::

    python benchmarks/learning_phases.py --task place_plate --sources $(sed -n 5p \\
        benchmarks/results/trainer_table_place_plate_box_h200_300s_mode.md | sed 's/.*--sources //; s/ --out.*//') \\
        --out benchmarks/results/learning_phases_place_plate_box_h200_300s
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import provenance  # noqa: E402  (puts the repo root on sys.path)
import trainer_table as tt  # noqa: E402  (sibling script: the same sources, runs and groups)
from rl_multiseed import time_to_safe  # noqa: E402
from mjx_damage import io  # noqa: E402


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--task", required=True, help="the task every source file is of")
  p.add_argument("--sources", nargs="+", required=True, metavar="FILE.json",
                 help="results files of rl_multiseed.py and/or rl_brax_ppo.py")
  p.add_argument("--out", required=True, help="output stem: writes OUT.md and OUT.json")
  a = p.parse_args(argv)
  # the same checks and reading as trainer_table.py (unknown, corrupt or other-task files refused, naming them)
  a.docs = tt.parse(["--task", a.task, "--out", a.out, "--sources", *a.sources]).docs
  return a


def _points(kind: str, doc: dict) -> list[list[dict]]:
  """Each run's evaluations by the mode as (env_steps, completion, safe_completion), in the order
  ``trainer_table.brax_runs`` / ``ours_runs`` list the runs; [] for a run with none scored by the mode."""
  out = []
  for r in doc["rows"]:
    if kind == "brax":
      curve = r.get("scored_curve") or {}
      pts = (curve.get("points") or []) if curve.get("action") == "mode" else []
      out.append([dict(env_steps=q["env_steps"], completion=q.get("completion"), safe=q.get("safe_completion"))
                  for q in pts])
    else:
      for p in r["per_seed"]:
        out.append([dict(env_steps=h["env_steps"], completion=h.get("eval/completion"),
                         safe=h.get("eval/safe_completion"))
                    for h in r.get("history") or [] if h.get("seed") == p["seed"]])
  return out


def phases(points: list[dict]) -> dict:
  """A run's env steps to its first evaluation with ≥ 80 % completion (``c80``) and to its first with ≥ 80 %
  safe and ≥ 80 % completion (``s80``); None where not reached or, for both, where nothing was scored."""
  pts = [q for q in points if q["completion"] is not None and q["safe"] is not None]
  if not pts:
    return dict(scored=False, c80=None, s80=None)
  keys = ("safe", "completion", "env_steps")
  return dict(scored=True, c80=time_to_safe(pts, safe=0.0, keys=keys), s80=time_to_safe(pts, keys=keys))


def _stat(values: list) -> dict:
  v = [x for x in values if x is not None]
  return dict(reached=len(v), mean=sum(v) / len(v) if v else None, min=min(v, default=None),
              max=max(v, default=None))


def build(docs) -> list[dict]:
  """Groups as ``trainer_table.groups`` forms them, each with its runs' phases."""
  runs = []
  for source, kind, doc in docs:
    listed = (tt.brax_runs if kind == "brax" else tt.ours_runs)(doc, source, "mode")
    for run, pts in zip(listed, _points(kind, doc), strict=True):
      runs.append({**run, **{f"phase_{k}": v for k, v in phases(pts).items()}})
  out = []
  for g in tt.groups(runs):
    rs = [r for r in g["runs"] if r["phase_scored"]]
    both = [r["phase_s80"] - r["phase_c80"] for r in rs if r["phase_s80"] is not None and r["phase_c80"] is not None]
    out.append(dict(trainer=g["trainer"], reward=g["reward"], settings=g["settings"], runs=len(g["runs"]),
                    scored=len(rs), grain=g["runs"][0].get("grain") if g["runs"] else None,
                    to_80_completion=_stat([r["phase_c80"] for r in rs]),
                    to_80_safe=_stat([r["phase_s80"] for r in rs]), between=_stat(both),
                    per_run=[dict(seed=r["seed"], source=r["source"], c80=r["phase_c80"], s80=r["phase_s80"])
                             for r in rs]))
  return out


def _m(s: dict, scored: int) -> str:
  if not s["reached"]:
    return f"none of {scored}"
  return f"{s['mean'] / 1e6:.1f} ({s['min'] / 1e6:.1f}–{s['max'] / 1e6:.1f}) M, {s['reached']} / {scored}"


def render_md(doc: dict) -> str:
  lines = [f"# {doc['task']}: env steps to 80 % completion, then to 80 % safe", "",
           "Each run's periodic evaluations by the mode (runs without them: not scored). Cells: mean (min–max) over "
           "the runs that reached the point, env steps per seed, and how many of the scored runs did; between: "
           "to 80 % safe less to 80 % completion, over runs that reached both. Built by:", "",
           f"    {doc['command']}", "",
           "| trainer | reward | settings | runs (scored) | evaluations every | to 80 % completion | to 80 % safe "
           "| between |", "|---|---|---|---|---|---|---|---|"]
  for g in doc["groups"]:
    if not g["scored"]:
      continue
    grain = f"{g['grain'] / 1e6:.1f} M" if g["grain"] else "—"
    lines.append(f"| {g['trainer']} | {g['reward']} | {g['settings']} | {g['runs']} ({g['scored']}) | {grain} "
                 f"| {_m(g['to_80_completion'], g['scored'])} | {_m(g['to_80_safe'], g['scored'])} "
                 f"| {_m(g['between'], g['between']['reached']) if g['between']['reached'] else '—'} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  a = parse(argv)
  doc = dict(task=a.task, command=provenance.command("learning_phases", argv), sources=[s for s, _, _ in a.docs],
             groups=build(a.docs))
  io.write_json(a.out + ".json", doc)
  io.write_text(a.out + ".md", render_md(doc))
  print(f"wrote {a.out}.md / .json ({len(doc['groups'])} groups)")
  return 0


if __name__ == "__main__":
  sys.exit(main())

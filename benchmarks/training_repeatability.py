"""Is a rerun of a training command a repeat? Two results files of one command, compared value by value.

Reads two results files of the same run made twice (``rl_multiseed.py`` or ``rl_brax_ppo.py``, e.g. one
command on two GPUs) and compares everything the runs learned and scored: every periodic evaluation and
training statistic at every logged step, and every final evaluation, per row (method or damage weight) and
seed. Clock readings (wall times, seconds, dates, throughput) are left out: they differ on any two runs.
Logged points are paired by seed and env step, not by position: two runs of a time budget stop at
different steps, and only the points both logged are compared (the rest are counted per run). The verdict
per row: identical (every value bitwise equal), or the number of values that differ and the first shared
logged step where the runs part, beside each run's final completion and safe completion (of different
policies when the runs ended at different steps).

``--baseline`` results files (runs of the same trainer without ``--deterministic``) add a throughput
column: the compared runs' training env steps per second over each baseline's (ours: the row's
``throughput_all_seeds``; Brax: env steps between its second and last evaluation over the training
seconds between them, so compile is left out).

Example (``--deterministic`` on two H200s; docs/safe_rl.md, "Repeatable GPU runs")::

    python benchmarks/training_repeatability.py \\
        benchmarks/results/rl_place_plate_nvidia_h200_box_det_g2.json \\
        benchmarks/results/rl_place_plate_nvidia_h200_box_det_g3.json \\
        --baseline benchmarks/results/rl_place_plate_nvidia_h200_box_3seeds_300s_a.json \\
        --out benchmarks/results/training_repeatability_ours_h200
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage import io  # noqa: E402
from trainer_table import source_kind  # noqa: E402  (sibling script: one test of which trainer wrote a file)

# Keys whose values are clock readings (or follow from them) or bookkeeping, never compared.
CLOCK_WORDS = ("wall", "date", "seconds", "throughput", "timings", "stopped_by", "command", "calls", "curves",
               "policy_file", "device", "note")


def _clock(key: str) -> bool:
  return key.endswith("_s") or any(w in key for w in CLOCK_WORDS)  # *_s: seconds (time to 80 %, eval, …)


def flatten(value, path: str = "") -> dict:
  """Every number (and string) in ``value`` keyed by its path, clock readings left out."""
  out = {}
  if isinstance(value, dict):
    for k, v in value.items():
      if not _clock(str(k)):
        out.update(flatten(v, f"{path}.{k}" if path else str(k)))
  elif isinstance(value, list):
    for i, v in enumerate(value):
      out.update(flatten(v, f"{path}[{i}]"))
  else:
    out[path] = value
  return out


def _like(row: dict) -> str:
  """What a baseline row must share with a compared one: its method (ours) or damage weight (Brax)."""
  return row["method"] if "per_seed" in row else f"w={row['damage_weight']:g}"


def row_key(row: dict) -> str:
  """One run's row: ours holds all its seeds, a Brax row one seed."""
  return _like(row) if "per_seed" in row else f"{_like(row)} seed {row['seed']}"


POINTS = ("history", "curve", "scored_curve")  # logged points, each with its env steps (Brax's scored
# curve is a dict whose "points" they are, beside how they were scored)


def _point_list(row: dict, name: str) -> list:
  value = row.get(name) or []
  return (value.get("points") or []) if isinstance(value, dict) else value


def _points(row: dict) -> dict:
  """Every logged point of a row keyed by (list, seed, env steps): two runs that stopped at different
  steps (a time budget on machines of different speed) are compared where both logged, not index by index."""
  return {(name, p.get("seed", -1), p["env_steps"]): p for name in POINTS for p in _point_list(row, name)}


def _without_points(row: dict) -> dict:
  out = {k: v for k, v in row.items() if k not in POINTS}
  out.update({k: {n: x for n, x in v.items() if n != "points"} for k, v in row.items()
              if k in POINTS and isinstance(v, dict)})
  return out


def end_step(row: dict) -> int:
  """Env steps (per seed) at which the row's training ended."""
  return int(row["env_steps_per_seed"] if "per_seed" in row else row["env_steps"])


def compare_rows(a: dict, b: dict) -> dict:
  """Values compared and differing: the rows outside their logged points, and every point both runs
  logged; first_step_apart: env steps of the first shared point that differs (None: none does)."""
  pa, pb = _points(a), _points(b)
  shared = sorted(set(pa) & set(pb), key=lambda k: (k[2], k[0], k[1]))
  fa, fb = flatten(_without_points(a)), flatten(_without_points(b))
  point_a, point_b = {k: flatten(pa[k]) for k in shared}, {k: flatten(pb[k]) for k in shared}
  for k in shared:
    fa.update({f"{k}.{n}": v for n, v in point_a[k].items()})
    fb.update({f"{k}.{n}": v for n, v in point_b[k].items()})
  keys = sorted(set(fa) | set(fb))
  differ = [k for k in keys if fa.get(k) != fb.get(k)
            and not (isinstance(fa.get(k), float) and isinstance(fb.get(k), float)
                     and math.isnan(fa[k]) and math.isnan(fb[k]))]
  apart = next((k[2] for k in shared if point_a[k] != point_b[k]), None)
  return {"values": len(keys), "differ": len(differ), "first_differing": differ[:3],
          "first_step_apart": apart, "shared_points": len(shared),
          "shared_to_step": shared[-1][2] if shared else None,
          "points_only_in": [len(set(pa) - set(pb)), len(set(pb) - set(pa))],
          "end_steps": [end_step(a), end_step(b)], "final": [final_scores(a), final_scores(b)]}


def throughput(row: dict) -> float | None:
  """Training env steps per second of one row (see the module docstring); None for a Brax row with fewer
  than 3 evaluations (its training cannot be timed without compile)."""
  if "per_seed" in row:
    return float(row["throughput_all_seeds"])
  curve = row["curve"]
  if len(curve) < 3:
    return None
  return (curve[-1]["env_steps"] - curve[1]["env_steps"]) / (curve[-1]["wall_s"] - curve[1]["wall_s"])


def final_scores(row: dict) -> list[list[float]]:
  """[completion, safe completion] of the row's final policies (one per seed), by its first scored action."""
  evals = [s["final_eval"] for s in row["per_seed"]] if "per_seed" in row else [row]
  return [[e["completion"], e["safe_completion"]] for e in evals]


def load(path: str, field: str) -> tuple[str, dict]:
  """(trainer, results) of an rl_multiseed.py ("ours") or rl_brax_ppo.py ("brax") results file."""
  doc = io.read_json(path, field)
  kind = source_kind(doc)
  if kind is None:
    raise ValueError(f"{field}: {path!r} is not a results file of rl_multiseed.py or rl_brax_ppo.py")
  return kind, doc


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("a", help="results file of the first run")
  p.add_argument("b", help="results file of the second run of the same command")
  p.add_argument("--baseline", nargs="*", default=[], metavar="JSON",
                 help="results files of the same trainer without --deterministic, for the throughput ratio")
  p.add_argument("--out", required=True, help="output path without extension: writes OUT.md and OUT.json")
  a = p.parse_args(argv)
  try:
    runs = [load(a.a, "a"), load(a.b, "b")]
    base = [load(path, "--baseline") for path in a.baseline]
  except ValueError as e:
    p.error(str(e))
  if runs[0][0] != runs[1][0]:
    p.error(f"b: a results file of {runs[1][0]}'s trainer, a of {runs[0][0]}'s")
  if any(k != runs[0][0] for k, _ in base):
    p.error(f"--baseline: results files of the compared runs' trainer ({runs[0][0]}) only")
  a.docs, a.base_docs = [d for _, d in runs], [d for _, d in base]
  return a


def main(argv=None) -> int:
  a = parse(argv)
  rows_a = {row_key(r): r for r in a.docs[0]["rows"]}
  rows_b = {row_key(r): r for r in a.docs[1]["rows"]}
  shared = [k for k in rows_a if k in rows_b]
  if not shared:
    raise SystemExit(f"{a.a} and {a.b} share no row (method or weight and seed)")
  like = {_like(r) for r in rows_a.values()}  # baseline rows of the same method (ours) or weight (Brax)
  base = [t for d in a.base_docs for r in d["rows"] if _like(r) in like and (t := throughput(r)) is not None]
  results = []
  for k in shared:
    c = compare_rows(rows_a[k], rows_b[k])
    speed = [throughput(rows_a[k]), throughput(rows_b[k])]
    results.append(dict(row=k, **c, env_steps_per_s=speed,
                        ratio_to_baseline=[s / b for s in speed if s for b in base] or None))
  command = "python benchmarks/training_repeatability.py " + " ".join(
      shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
  doc = {"a": os.path.basename(a.a), "b": os.path.basename(a.b), "baseline": [os.path.basename(x) for x in a.baseline],
         "baseline_env_steps_per_s": base, "rows": results, "command": command}
  lines = [f"# Training repeatability: {doc['a']} vs {doc['b']}", "",
           "Every logged training statistic, periodic evaluation and final evaluation of each row compared "
           "value by value (clock readings left out); logged points are paired by seed and env step, so runs "
           "that stopped at different steps are compared where both logged. Throughput: training env steps per "
           "second (all seeds), and its ratio to the baseline runs without deterministic kernels.", "",
           f"    {command}", "",
           "| row | values compared | values that differ | runs part at env step "
           "| logged points: shared (only a, only b) | final completion/safe %, a; b | env steps/s, a; b | ratio to baseline (min–max) |",
           "|---|---|---|---|---|---|---|---|"]
  for r in results:
    ratio = (f"{min(r['ratio_to_baseline']):.2f}–{max(r['ratio_to_baseline']):.2f}"
             if r["ratio_to_baseline"] else "—")
    ends = r["end_steps"]
    shared_to = "" if r["shared_to_step"] is None else f" (to {r['shared_to_step']:,})"
    apart = ("never (identical)" if r["differ"] == 0 else
             f"{r['first_step_apart']:,}" if r["first_step_apart"] is not None else
             "final evaluations only" if ends[0] == ends[1] else
             f"at no shared point{shared_to}; training ended at {ends[0]:,} and {ends[1]:,}")
    final = "; ".join(", ".join(f"{100 * c:.1f}/{100 * sc:.1f}" for c, sc in side) for side in r["final"])
    speed = "; ".join("—" if v is None else f"{v:,.0f}" for v in r["env_steps_per_s"])
    points = f"{r['shared_points']} ({r['points_only_in'][0]}, {r['points_only_in'][1]})"
    lines.append(f"| {r['row']} | {r['values']} | {r['differ']} | {apart} | {points} | {final} | {speed} | {ratio} |")
  if base:
    lines += ["", "Baseline env steps/s: " + ", ".join(f"{b:,.0f}" for b in base) + " ("
              + ", ".join(doc["baseline"]) + ")."]
  io.write_json(a.out + ".json", doc)
  io.write_text(a.out + ".md", "\n".join(lines) + "\n")
  print("\n".join(lines))
  return 0


if __name__ == "__main__":
  sys.exit(main())

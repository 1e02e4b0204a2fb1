"""Which committed training runs' critics diverged: every seed-run's logged value loss against the lines of
``train.ppo.CriticDivergedWarning`` (no training; CPU, seconds).

A critic whose value loss leaps orders of magnitude above its own lowest predicts values no return of the task
reaches; the advantages the policy learns from are then noise. Our trainer warns when that happens
(:func:`train.ppo.critic_diverged`: past ``V_FLOOR`` and ``V_JUMP`` times the seed's lowest so far);
this script applies the same test to the points the results files logged, so it also reads runs made before the
warning existed, and Brax's (``rl_brax_ppo.py`` files log brax's value loss at each of its evaluations).

Sources: ``rl_multiseed.py`` results (rows with a ``history`` of per-seed points with ``loss/v_loss``) and
``rl_brax_ppo.py`` results (rows with a ``curve`` whose points carry ``v_loss``); other files, and rows that log
no value loss, are skipped and counted. Points are logged at evaluations only, so a spike between two of them is
not seen here (the trainer's warning looks at every iteration).

For each seed-run that crosses the lines: the file, trainer, reward, seed, the env steps and value loss of the
first point past them, its lowest before, the largest logged, and the run's final completion and safe completion
(ours: its last periodic evaluation by the mode; Brax's: its final evaluation by the mode when scored both
ways, else its one score).

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/value_loss_scan.py                  # every benchmarks/results/rl_*.json
    PYTHONPATH=. .venv/bin/python benchmarks/value_loss_scan.py --sources F.json G.json --out /tmp/scan

Writes ``<out>.json`` and ``<out>.md`` (default ``benchmarks/results/value_loss_scan``) with the command.
"""

from __future__ import annotations

import argparse
import glob
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import provenance  # noqa: E402  (first: sets the path and mjx_damage's XLA flags before jax starts)

from mjx_damage import io  # noqa: E402
from train import ppo  # noqa: E402

RESULTS = os.path.join(provenance.ROOT, "benchmarks", "results")
TRAINERS = {"ours": "our trainer", "brax": "Brax's PPO"}


def _ours(row: dict):
  """(seed, [(env_steps, v_loss)], final (completion, safe) or None) per seed of an ``rl_multiseed`` row."""
  by_seed: dict = {}
  for p in row.get("history") or []:
    if isinstance(p, dict) and p.get("loss/v_loss") is not None:
      by_seed.setdefault(p.get("seed"), []).append(p)
  for seed, pts in by_seed.items():
    evals = [p for p in pts if p.get("eval/completion") is not None]
    final = (evals[-1]["eval/completion"], evals[-1]["eval/safe_completion"]) if evals else None
    yield seed, [(p["env_steps"], p["loss/v_loss"]) for p in pts], final


def _brax(row: dict):
  pts = [(p["env_steps"], p["v_loss"]) for p in row.get("curve") or [] if p.get("v_loss") is not None]
  if pts:
    score = (row.get("by_action") or {}).get("mode") or row
    yield row.get("seed"), pts, (score.get("completion"), score.get("safe_completion"))


def first_crossing(points):
  """The first ``(env_steps, v_loss, lowest before)`` of ``points`` [(env_steps, v_loss)] past the warning's
  lines, or None; the lowest is over the points before it, as the trainer's is over earlier iterations."""
  low = math.inf
  for steps, v in points:
    if ppo.critic_diverged(v, low):
      return steps, v, low
    low = min(low, v)
  return None


def scan(paths) -> dict:
  crossed, every, skipped = [], [], []
  for path in paths:
    doc = io.read_json(path, "sources")
    rows = doc.get("rows") if isinstance(doc, dict) else None
    if not isinstance(rows, list):
      skipped.append(os.path.basename(path))
      continue
    for row in rows:
      if not isinstance(row, dict):
        continue
      trainer = "brax" if "curve" in row else "ours"
      reward = (f"w = {row.get('damage_weight'):g}" if trainer == "brax" else
                row.get("method") or row.get("label") or "?")
      for seed, pts, final in (_brax(row) if trainer == "brax" else _ours(row)):
        hit = first_crossing(pts)
        one = {"file": os.path.basename(path), "trainer": trainer, "reward": reward, "seed": seed,
               "largest": max(v for _, v in pts), "points": len(pts), "final": final}
        every.append(one)
        if hit is not None:
          crossed.append(dict(one, env_steps=hit[0], v_loss=hit[1], lowest_before=hit[2]))
  return {"v_jump": ppo.V_JUMP, "v_floor": ppo.V_FLOOR, "files": len(paths), "not_training_results": skipped,
          "seed_runs": {t: sum(c["trainer"] == t for c in every) for t in TRAINERS}, "crossed": crossed,
          "every": every}


def _final(c) -> str:
  f = c["final"]
  return "—" if not f or f[0] is None else f"{100 * f[0]:.1f} / {100 * f[1]:.1f} %"


def render_md(res: dict) -> str:
  r = res["seed_runs"]
  out = ["# Which training runs' critics diverged", "",
         f"Date: {res['date']}. Git: {res['git']}. Every logged value loss of {r['ours'] + r['brax']} seed-runs "
         f"({r['ours']} of our trainer, {r['brax']} of Brax's PPO) in {res['files']} files, against the lines of "
         f"`train.ppo.CriticDivergedWarning`: past {res['v_floor']:.0e} and {res['v_jump']:.0e} times the "
         f"seed-run's lowest before. Points are logged at evaluations only. Final: completion / safe completion "
         f"of the last evaluation (by the mode where scored both ways).", "",
         f"Command: `{res['command'].strip()}`", "",
         f"{len(res['crossed'])} seed-runs cross the lines:", "",
         "| file | trainer | reward | seed | env steps | value loss | its lowest before | largest logged | final |",
         "|---|---|---|---|---|---|---|---|---|"]
  for c in res["crossed"]:
    out.append(f"| {c['file']} | {c['trainer']} | {c['reward']} | {c['seed']} | {c['env_steps'] / 1e6:.1f} M | "
               f"{c['v_loss']:.3g} | {c['lowest_before']:.3g} | {c['largest']:.3g} | {_final(c)} |")
  if res.get("list_every"):
    for trainer in TRAINERS:
      rows = [c for c in res["every"] if c["trainer"] == trainer]
      if rows:
        out += ["", f"Every seed-run of {TRAINERS[trainer]} "
                f"({len(rows)}), largest logged value loss by reward: "
                + "; ".join(f"{r}: {max(c['largest'] for c in rows if c['reward'] == r):.3g} over "
                            f"{sum(c['reward'] == r for c in rows)}" for r in dict.fromkeys(c["reward"] for c in rows)),
                "", "| file | reward | seed | points | largest logged | final |", "|---|---|---|---|---|---|"]
        out += [f"| {c['file']} | {c['reward']} | {c['seed']} | {c['points']} | {c['largest']:.3g} | {_final(c)} |"
                for c in rows]
  return "\n".join(out) + "\n"


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--sources", nargs="+", default=None, metavar="FILE",
                 help="results files (default: every benchmarks/results/rl_*.json)")
  p.add_argument("--out", default=os.path.join(RESULTS, "value_loss_scan"), help="stem of the .json and .md")
  p.add_argument("--every", action="store_true", help="the .md also lists every seed-run, not only those crossing")
  a = p.parse_args(argv)
  paths = a.sources if a.sources is not None else sorted(glob.glob(os.path.join(RESULTS, "rl_*.json")))
  if not paths:
    raise ValueError("sources: no results files given or found")
  for s in paths:
    if not os.path.isfile(s):
      raise ValueError(f"sources: no such file {s!r}")
  res = dict(scan(paths), list_every=a.every)
  provenance.save_results(res, "value_loss_scan", argv, a.out, render_md)
  print(f"{len(res['crossed'])} of {sum(res['seed_runs'].values())} seed-runs cross the lines")
  return 0


if __name__ == "__main__":
  try:
    sys.exit(main())
  except ValueError as e:
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)

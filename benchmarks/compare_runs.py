"""Learning curves of several `mjx-damage train` runs side by side (e.g. the same seeds on 1 and 2 GPUs).

Reads each run directory's ``config.json`` and ``metrics.jsonl`` (what ``train --out`` writes) and
writes ``<out>.md`` (one row per evaluation point: env steps per seed, each run's wall time and its
deterministic completion / safe completion per seed) and ``<out>.png`` (safe completion and
completion against env steps and against wall-clock seconds, one colour per run, one line style per
seed). Runs are compared at the evaluation points they share (same ``env_steps``).

Example (issue 21: the same seeds and global batch on 2 GPUs and on 1)::

    python benchmarks/compare_runs.py runs/d2 runs/d1 --labels "2 GPUs,1 GPU" --out benchmarks/results/curves
"""

from __future__ import annotations

import argparse
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage import io  # noqa: E402
from mjx_damage.png import save_png  # noqa: E402


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("runs", nargs="+", help="run directories (each with config.json and metrics.jsonl)")
  p.add_argument("--labels", default=None, help="comma-separated label per run (default: the directory names)")
  p.add_argument("--out", required=True, help="output path without extension: writes OUT.md and OUT.png")
  p.add_argument("--title", default="")
  a = p.parse_args(argv)
  if len(a.runs) < 2:
    p.error("runs: give at least two run directories")
  a.labels = a.labels.split(",") if a.labels else [os.path.basename(os.path.normpath(r)) for r in a.runs]
  if len(a.labels) != len(a.runs):
    p.error(f"--labels: {len(a.labels)} label(s) for {len(a.runs)} run(s)")
  for r in a.runs:
    for f in ("config.json", "metrics.jsonl"):
      if not os.path.isfile(os.path.join(r, f)):
        p.error(f"runs: {os.path.join(r, f)} does not exist (not a train --out directory?)")
  return a


def load(run: str) -> tuple[dict, list[dict]]:
  """(config, evaluation rows) of a run directory; raises ValueError naming the file if unreadable."""
  cfg_path, m_path = os.path.join(run, "config.json"), os.path.join(run, "metrics.jsonl")

  def read(path, lines):
    with open(path) as f:
      try:
        return [json.loads(x) for x in f if x.strip()] if lines else json.load(f)
      except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not JSON ({e})") from None

  cfg, rows = read(cfg_path, False), read(m_path, True)
  evals = [r for r in rows if r.get("eval/safe_completion") is not None]
  if not evals:
    raise ValueError(f"{m_path}: no evaluation rows (eval/safe_completion)")
  return cfg, evals


def table(labels: list, runs: list) -> str:
  """Markdown rows at the (seed, env_steps) evaluation points every run has."""
  keyed = [{(r["seed"], r["env_steps"]): r for r in rows} for _, rows in runs]
  common = sorted(set.intersection(*(set(k) for k in keyed)), key=lambda k: (k[0], k[1]))
  head = "| seed | env steps / seed | " + " | ".join(f"{lb}: wall s | {lb}: C % | {lb}: SC %" for lb in labels) + " |"
  lines = [head, "|" + "---:|" * (2 + 3 * len(labels))]
  for k in common:
    cells = []
    for kd in keyed:
      r = kd[k]
      cells += [f"{r['wall_time']:.0f}", f"{100 * r['eval/completion']:.1f}", f"{100 * r['eval/safe_completion']:.1f}"]
    lines.append(f"| {k[0]} | {k[1]:,} | " + " | ".join(cells) + " |")
  return "\n".join(lines)


def plot(labels: list, runs: list, path: str, title: str) -> None:
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
  styles = ["-", "--", ":", "-."]
  for j, (lb, (_, rows)) in enumerate(zip(labels, runs)):
    seeds = list(dict.fromkeys(r["seed"] for r in rows))
    for i, s in enumerate(seeds):
      pts = [r for r in rows if r["seed"] == s]
      ls = styles[i % len(styles)]
      for ax, x in ((axes[0], [r["env_steps"] for r in pts]), (axes[1], [r["wall_time"] for r in pts])):
        ax.plot(x, [100 * r["eval/safe_completion"] for r in pts], ls=ls, marker=".", color=f"C{j}",
                label=f"{lb}, seed {s}")
  axes[0].set_xlabel("env steps per seed")
  axes[1].set_xlabel("wall-clock s (compile included)")
  for ax in axes:
    ax.set_ylabel("safe completion % (deterministic eval)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
  axes[1].legend(fontsize=7)
  fig.suptitle(title)
  fig.tight_layout()
  save_png(fig, path, dpi=110)
  plt.close(fig)


def main(argv=None) -> int:
  a = parse(argv)
  try:
    runs = [load(r) for r in a.runs]
  except ValueError as e:
    print(f"compare_runs.py: error: {e}", file=sys.stderr)
    return 2
  lines = [f"# {a.title or 'Learning curves side by side'}", "",
           "Command: `python benchmarks/compare_runs.py " + " ".join(a.runs)
           + f" --labels \"{','.join(a.labels)}\" --out {a.out}`", ""]
  for lb, (cfg, rows) in zip(a.labels, runs):
    lines.append(f"- **{lb}**: task {cfg.get('task')} {cfg.get('task_kwargs', {})}, devices {cfg.get('devices')}, "
                 f"mesh {cfg.get('mesh')}, seeds {cfg.get('config', {}).get('seeds')}, "
                 f"{cfg.get('config', {}).get('num_envs')} envs per seed, last evaluation at "
                 f"{rows[-1]['env_steps']:,} env steps per seed, {rows[-1]['wall_time']:.0f} s")
  lines += ["", "C: completion, SC: safe completion, deterministic evaluation; wall s from the start of training "
            "(compile included).", "", table(a.labels, runs), "", f"![curves]({os.path.basename(a.out)}.png)", ""]
  io.write_text(a.out + ".md", "\n".join(lines))
  plot(a.labels, runs, a.out + ".png", a.title)
  print(f"wrote {a.out}.md / .png")
  return 0


if __name__ == "__main__":
  sys.exit(main())

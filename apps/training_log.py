"""A training run's log read back and drawn: ``metrics.jsonl`` (+ ``config.json``) → curves PNG.

Used by ``mjx-damage render --training-log``; the figure is the one training
itself writes (:func:`train.plots.plot_training`).
"""

from __future__ import annotations

import json
import os
from typing import Optional

from train.plots import plot_training


def find_training_log(path: str) -> str:
  """``metrics.jsonl`` itself, or the one inside a run directory; ValueError if absent."""
  p = os.fspath(path)
  if os.path.isdir(p):
    p = os.path.join(p, "metrics.jsonl")
  if not os.path.isfile(p):
    raise ValueError(f"training_log: no metrics.jsonl at {p!r}")
  return p


def read_training_log(path: str) -> tuple[list, Optional[float], str]:
  """(rows of metrics.jsonl, PPO-Lagrangian budget ĉ or None, task name) of a training run.

  The budget and task come from the run's ``config.json`` beside the log
  (written by :func:`train.train`); without it, a run is taken as Lagrangian
  when its rows carry a non-zero ``lagrange``, and its budget is then unknown (NaN).
  """
  p = find_training_log(path)
  with open(p) as f:
    rows = [json.loads(line) for line in f if line.strip()]
  if not rows:
    raise ValueError(f"training_log: {p!r} holds no rows")
  budget, task = None, ""
  cfg_path = os.path.join(os.path.dirname(p), "config.json")
  if os.path.isfile(cfg_path):
    with open(cfg_path) as f:
      cfg = json.load(f)
    budget = (cfg.get("config") or {}).get("budget")
    task = cfg.get("task") or ""
  elif any(r.get("lagrange") for r in rows):
    budget = float("nan")
  return rows, budget, task


def plot_training_log(path: str, out: str, title: Optional[str] = None) -> str:
  """PNG of a training run's curves (return, cost, success rates, λ for PPO-Lagrangian) at ``out``."""
  rows, budget, task = read_training_log(path)
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  return plot_training(rows, out, title=task if title is None else title, budget=budget)

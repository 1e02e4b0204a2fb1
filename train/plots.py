"""Training-curve figure: task return, episode cost (and λ, success) against env steps."""

from __future__ import annotations

from typing import Optional, Sequence


def _series(rows: Sequence[dict], key: str):
  pts = [(r["env_steps"], r[key]) for r in rows if r.get(key) is not None]
  return [p[0] for p in pts], [p[1] for p in pts]


def plot_training(rows: Sequence[dict], path: str, title: str = "", budget: Optional[float] = None) -> str:
  """Write a PNG of the rows of ``metrics.jsonl`` (as the paper's RL figure: return and
  damage per episode), plus completion/safe completion and, for PPO-Lagrangian, λ."""
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  lagrangian = budget is not None
  n = 4 if lagrangian else 3
  fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4))
  ax = axes[0]
  for key, label in (("train/episode_return", "train (stochastic)"), ("eval/task_return", "eval (deterministic)")):
    x, y = _series(rows, key)
    ax.plot(x, y, marker=".", label=label)
  ax.set_title("task return per episode")
  ax.legend(fontsize=8)
  ax = axes[1]
  for key, label in (("train/episode_cost", "train"), ("eval/episode_cost", "eval")):
    x, y = _series(rows, key)
    ax.plot(x, y, marker=".", label=label)
  if lagrangian:
    ax.axhline(budget, color="k", ls="--", lw=1, label=f"budget {budget:g}")
  ax.set_title("damage (cost) per episode")
  ax.legend(fontsize=8)
  ax = axes[2]
  for key, label in (("eval/completion", "completion"), ("eval/safe_completion", "safe completion")):
    x, y = _series(rows, key)
    ax.plot(x, y, marker=".", label=label)
  ax.set_ylim(-0.05, 1.05)
  ax.set_title("eval success rates")
  ax.legend(fontsize=8)
  if lagrangian:
    x, y = _series(rows, "lagrange")
    axes[3].plot(x, y, marker=".", color="C3")
    axes[3].set_title("Lagrange multiplier λ")
  for ax in axes:
    ax.set_xlabel("env steps")
    ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))  # 2e6, not 2000000 over its neighbours
    ax.grid(alpha=0.3)
  if title:
    fig.suptitle(title)
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)
  return path

"""Training-curve figure: task return, episode cost, success rates (and λ) against env steps, one line per seed."""

from __future__ import annotations

from typing import Optional, Sequence

from mjx_damage.png import save_png


def _series(rows: Sequence[dict], key: str, seed=None):
  pts = [(r["env_steps"], r[key]) for r in rows if r.get(key) is not None and r.get("seed") == seed]
  return [p[0] for p in pts], [p[1] for p in pts]


def plot_training(rows: Sequence[dict], path: str, title: str = "", budget: Optional[float] = None,
                  labels: Optional[dict] = None) -> str:
  """Write a PNG of the rows of ``metrics.jsonl`` (the paper's RL figure: return and damage per
  episode), plus completion/safe completion and, for a Lagrangian run, λ. Each seed (rows' ``seed``)
  is one colour, named by ``labels[seed]`` if given (e.g. its damage weight) or "seed N"; training
  (stochastic) dashed, evaluation (deterministic) solid."""
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  seeds = list(dict.fromkeys(r.get("seed") for r in rows))
  lagrangian = budget is not None
  n = 4 if lagrangian else 3
  fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4))
  for j, seed in enumerate(seeds):
    color, tag = f"C{j % 10}", (labels or {}).get(seed, f"seed {seed}" if seed is not None else "")
    first = j == 0
    for ax, train_key, eval_key in ((axes[0], "train/episode_return", "eval/task_return"),
                                    (axes[1], "train/episode_cost", "eval/episode_cost")):
      ax.plot(*_series(rows, train_key, seed), ls="--", color=color, lw=1,
              label="train (stochastic)" if first else None)
      ax.plot(*_series(rows, eval_key, seed), marker=".", color=color, label=tag or "eval (deterministic)")
    axes[2].plot(*_series(rows, "eval/completion", seed), ls="--", color=color,
                 label="completion" if first else None)
    axes[2].plot(*_series(rows, "eval/safe_completion", seed), marker=".", color=color,
                 label="safe completion" if first else None)
    if lagrangian:
      axes[3].plot(*_series(rows, "lagrange", seed), marker=".", color=color, label=tag or None)
      if any(r.get("budget") is not None and r["budget"] > budget for r in rows):  # a budget curriculum
        axes[1].plot(*_series(rows, "budget", seed), ls=":", color=color, lw=1,
                     label="budget in force" if first else None)
  axes[0].set_title("task return per episode")
  axes[1].set_title("damage (cost) per episode")
  if lagrangian:
    axes[1].axhline(budget, color="k", ls="--", lw=1, label=f"budget {budget:g}")
    axes[3].set_title("Lagrange multiplier λ")
  axes[2].set_ylim(-0.05, 1.05)
  axes[2].set_title("eval success rates (solid: safe)")
  for ax in axes:
    ax.set_xlabel("env steps (per seed)")
    ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))  # 2e6, not 2000000 over its neighbours
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
      ax.legend(fontsize=7)
  if title:
    fig.suptitle(title)
  fig.tight_layout()
  save_png(fig, path, dpi=110)
  plt.close(fig)
  return path

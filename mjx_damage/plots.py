"""Plots of a rollout (health, contact loads, cost) — PNG via matplotlib (Agg).

From a :class:`mjx_damage.render.Trajectory` (``render_rollout(...).trajectory`` or
``mjx_damage.render.rollout(...)``)::

    from mjx_damage import plots
    plots.plot_rollout(traj, "plots/")   # health.png, load.png, cost.png, rollout.png (all three)

* health — every tracked entity's health over time;
* load — the peak contact loads F∥ and F⊥ of each control step on the most
  damaged link (lowest final health; the most loaded one if none is damaged),
  with its mechanical stress ε = α·F∥ + β·F⊥ against the threshold E: damage
  accrues where ε > E (DAMAGE_MODEL.md §2). ε is formed from the step's peak
  F∥ and F⊥, which may come from different substeps, so it bounds the step's
  peak stress from above;
* cost — damage per step (bars) and cumulative episode cost.

Generic: any recorded :class:`~mjx_damage.trajectory.Trajectory`, no task and no
trainer. A training run's curves are the trainer's figure
(:func:`train.plots.plot_training`; ``mjx-damage render --training-log``:
:mod:`apps.training_log`).
"""

from __future__ import annotations

import os

import numpy as np


def _plt():
  import matplotlib

  matplotlib.use("Agg")  # no display: files only
  import matplotlib.pyplot as plt

  return plt


def most_damaged_link(traj, env_index: int = 0) -> int:
  """Index of the link with the lowest final health in env ``env_index``.

  Ties (e.g. nothing damaged) go to the link with the highest peak stress
  α·F∥ + β·F⊥ relative to its threshold, so the load plot shows the link
  closest to damage.
  """
  b = env_index
  final = traj.link_health[-1, b]
  eps = traj.alpha[b] * traj.f_par[:, b] + traj.beta[b] * traj.f_perp[:, b]
  closeness = eps.max(axis=0) / np.maximum(traj.mech_threshold[b], 1e-9)
  # lexicographic: lowest health first, then highest closeness
  order = np.lexsort((-closeness, final))
  return int(order[0])


def _health_ax(ax, traj, b):
  t = traj.time
  for i, name in enumerate(traj.entity_names):
    ax.plot(t, traj.entity_health[:, b, i], lw=2, label=name)
  ax.set_ylim(-3, 103)
  ax.set_xlabel("time (s)")
  ax.set_ylabel("health")
  ax.set_title("entity health")
  ax.legend(fontsize=8, loc="lower left")


def _load_ax(ax, traj, b):
  t = traj.time
  k = most_damaged_link(traj, b)
  fpar, fperp = traj.f_par[:, b, k], traj.f_perp[:, b, k]
  alpha, beta, E = traj.alpha[b, k], traj.beta[b, k], traj.mech_threshold[b, k]
  ax.plot(t, fpar, lw=1.5, label="F∥ (along acceleration)")
  ax.plot(t, fperp, lw=1.5, label="F⊥")
  ax.plot(t, alpha * fpar + beta * fperp, "k", lw=1, alpha=0.7, label=f"ε = {alpha:g}·F∥ + {beta:g}·F⊥")
  ax.axhline(E, color="C3", ls="--", lw=1, label=f"threshold E = {E:g} N")
  ax.set_xlabel("time (s)")
  ax.set_ylabel("peak load per step (N)")
  ax.set_title(f"contact load on '{traj.link_names[k]}'")
  top = max(float(np.max(alpha * fpar + beta * fperp)), float(np.max(fpar)), float(np.max(fperp)), E)
  ax.set_ylim(0, 1.1 * top if top > 0 else 1.0)
  ax.legend(fontsize=8, loc="upper left")


def _cost_ax(ax, traj, b):
  t = traj.time
  # step k's damage happened during (t_k − dt, t_k]: draw its bar over that interval
  ax.bar(t, traj.cost[:, b], width=-traj.dt, align="edge", color="C3", label="cost per step")
  ax.set_xlabel("time (s)")
  ax.set_ylabel("damage per step (health points)")
  ax.set_title("cost")
  ax2 = ax.twinx()
  ax2.plot(t, np.cumsum(traj.cost[:, b]), "k", lw=1.5, label="episode cost (cumulative)")
  ax2.set_ylabel("cumulative cost")
  ax2.set_ylim(bottom=0)
  h1, l1 = ax.get_legend_handles_labels()
  h2, l2 = ax2.get_legend_handles_labels()
  ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper left")


PANELS = {"health": _health_ax, "load": _load_ax, "cost": _cost_ax}


def plot_rollout(traj, out_dir: str, *, env_index: int = 0, title: str = "") -> dict:
  """Write health.png, load.png, cost.png and rollout.png (the three side by side) to ``out_dir``.

  Returns {name: path}. ``env_index`` picks the environment of a batched rollout.
  """
  if not 0 <= env_index < traj.num_envs:
    raise ValueError(f"env_index: must be in [0, {traj.num_envs}), got {env_index}")
  plt = _plt()
  os.makedirs(out_dir, exist_ok=True)
  paths = {}
  for name, draw in PANELS.items():
    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    draw(ax, traj, env_index)
    if title:
      fig.suptitle(title, fontsize=10)
    for a in fig.axes:
      a.grid(alpha=0.3)
    fig.tight_layout()
    paths[name] = os.path.join(out_dir, f"{name}.png")
    fig.savefig(paths[name], dpi=110)
    plt.close(fig)
  fig, axes = plt.subplots(1, 3, figsize=(15, 3.8))
  for ax, draw in zip(axes, PANELS.values()):
    draw(ax, traj, env_index)
    ax.grid(alpha=0.3)
  if title:
    fig.suptitle(title, fontsize=11)
  fig.tight_layout()
  paths["rollout"] = os.path.join(out_dir, "rollout.png")
  fig.savefig(paths["rollout"], dpi=100)
  plt.close(fig)
  return paths

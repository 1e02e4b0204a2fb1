"""Plots of a rollout (health, contact loads, damage; temperature, wetness) — PNG via matplotlib (Agg).

From a :class:`mjx_damage.render.Trajectory` (``render_rollout(...).trajectory`` or
``mjx_damage.render.rollout(...)``)::

    from mjx_damage import plots
    plots.plot_rollout(traj, "plots/")   # health.png, load.png, cost.png, …, rollout.png (all side by side)

Every axis names its quantity and unit; an axis whose peak is more than
:data:`LOG_RANGE` times its typical value switches to a log (symlog) scale, so
an impact spike does not flatten the rest.

* health — every tracked entity's health over time (health points, 0-100);
* load — the peak contact loads F∥ and F⊥ of each control step on the most
  damaged link (lowest final health; the most loaded one if none is damaged),
  with its mechanical stress ε = α·F∥ + β·F⊥ against the threshold E: damage
  accrues where ε > E (DAMAGE_MODEL.md §2). ε is formed from the step's peak
  F∥ and F⊥, which may come from different substeps, so it bounds the step's
  peak stress from above;
* cost — damage evaluated per step (bars, split by damage model when the scene
  drives more than one) and the episode's cumulative damage, both in health
  points; it keeps counting after a health reaches 0 (the cost a CMDP budget sees);
* temperature (scenes with heat sources) — each entity's hottest link and each
  source, °C;
* wetness (scenes with liquid) — liquid particles touching each entity.

Generic: any recorded :class:`~mjx_damage.trajectory.Trajectory`, no task and no
trainer. A training run's curves are the trainer's figure
(:func:`train.plots.plot_training`; ``mjx-damage render --training-log``:
:mod:`apps.training_log`).
"""

from __future__ import annotations

import os

import numpy as np

from mjx_damage.png import save_png
from mjx_damage.trajectory import MODELS

LOG_RANGE = 30.0  # a peak this many times the typical value switches an axis to a log scale
MODEL_COLORS = {"mechanical": "C3", "thermal": "C1", "fluid": "C0"}


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
  ax.set_xlabel("time since reset (s)")
  ax.set_ylabel("health (health points, 0-100)")
  ax.set_title("entity health (min over its links; 100 intact, 0 destroyed)", fontsize=9)
  ax.legend(fontsize=8, loc="lower left")


def _load_ax(ax, traj, b):
  t = traj.time
  k = most_damaged_link(traj, b)
  fpar, fperp = traj.f_par[:, b, k], traj.f_perp[:, b, k]
  alpha, beta, E = traj.alpha[b, k], traj.beta[b, k], traj.mech_threshold[b, k]
  eps = alpha * fpar + beta * fperp
  ax.plot(t, fpar, lw=1.5, label="F∥ peak contact force along the link's acceleration (N)")
  ax.plot(t, fperp, lw=1.5, label="F⊥ peak contact force across it (N)")
  ax.plot(t, eps, "k", lw=1, alpha=0.7, label=f"stress ε = {alpha:g}·F∥ + {beta:g}·F⊥ (N)")
  ax.axhline(E, color="C3", ls="--", lw=1, label=f"damage threshold E = {E:g} N (damage where ε > E)")
  ax.set_xlabel("time since reset (s)")
  top = max(float(np.max(eps)), float(np.max(fpar)), float(np.max(fperp)), float(E))
  if top > LOG_RANGE * max(float(E), 1e-9):
    # an impact spike would flatten the threshold and everything near it: symlog keeps both readable
    ax.set_yscale("symlog", linthresh=max(float(E), 1e-3) / 10.0)
    ax.set_ylim(0, 2.0 * top)
    ax.set_ylabel("peak load in the control step (N, symlog)")
  else:
    ax.set_ylim(0, 1.1 * top if top > 0 else 1.0)
    ax.set_ylabel("peak load in the control step (N)")
  ax.set_title(f"contact load on '{traj.link_names[k]}' vs damage threshold", fontsize=9)
  ax.legend(fontsize=7, loc="upper left")


def _cost_ax(ax, traj, b):
  t = traj.time
  cost = traj.cost[:, b]
  # step k's damage happened during (t_k − dt, t_k]: draw its bar over that interval
  if traj.damage is not None and len(traj.modalities) > 1:
    bottom = np.zeros_like(cost)
    for m in traj.modalities:
      part = traj.damage[:, b, MODELS.index(m)]
      ax.bar(t, part, bottom=bottom, width=-traj.dt, align="edge", color=MODEL_COLORS[m],
             label=f"{m} damage per step")
      bottom = bottom + part
  else:
    ax.bar(t, cost, width=-traj.dt, align="edge", color="C3", label="damage per step")
  ax.set_xlabel("time since reset (s)")
  positive = cost[cost > 0]
  if len(positive) and positive.max() > LOG_RANGE * np.median(positive):
    # one spike would hide every other step: log scale (steps without damage drop out of view)
    ax.set_yscale("log")
    ax.set_ylabel("damage per step (health points, log)")
  else:
    ax.set_ylabel("damage per step (health points)")
  ax.set_title("damage evaluated = cost (counts on after health reaches 0)", fontsize=9)
  ax2 = ax.twinx()
  ax2.plot(t, np.cumsum(cost), "k", lw=1.5, label="episode damage, cumulative (health points)")
  ax2.set_ylabel("episode damage (health points)")
  ax2.set_xlabel(ax.get_xlabel())
  ax2.set_ylim(bottom=0)
  h1, l1 = ax.get_legend_handles_labels()
  h2, l2 = ax2.get_legend_handles_labels()
  ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")


def _temperature_ax(ax, traj, b):
  t = traj.time
  for i, name in enumerate(traj.entity_names):
    links = traj.link_entity == i
    ax.plot(t, traj.temperature[:, b, links].max(axis=1), lw=2, label=f"{name} (hottest link)")
  for s, name in enumerate(traj.source_names):
    ax.plot(t, traj.source_temperature[:, b, s], "--", lw=1, color="C3", label=f"heat source '{name}'")
  ax.set_xlabel("time since reset (s)")
  ax.set_ylabel("temperature (°C)")
  ax.set_title("temperature", fontsize=9)
  ax.legend(fontsize=7, loc="best")


def _wetness_ax(ax, traj, b):
  t = traj.time
  for i, name in enumerate(traj.entity_names):
    links = traj.link_entity == i
    ax.plot(t, traj.exposure[:, b, links].sum(axis=1), lw=2, label=name)
  ax.set_xlabel("time since reset (s)")
  ax.set_ylabel("liquid particles touching (count)")
  ax.set_title(f"wetness ({traj.particles.shape[2]} particles in all)" if traj.particles is not None
               else "wetness", fontsize=9)
  ax.set_ylim(bottom=0)
  ax.legend(fontsize=8, loc="upper left")


PANELS = {"health": _health_ax, "load": _load_ax, "cost": _cost_ax}
SCENE_PANELS = {"temperature": ("thermal", _temperature_ax), "wetness": ("fluid", _wetness_ax)}


def panels_of(traj) -> dict:
  """{name: draw(ax, traj, env)} of the panels a rollout gets: health, load, cost, plus
  temperature with heat sources and wetness with liquid."""
  out = dict(PANELS)
  for name, (model, draw) in SCENE_PANELS.items():
    if model in traj.modalities:
      out[name] = draw
  return out


def rollout_figure(traj, env_index: int = 0, title: str = ""):
  """A matplotlib Figure with every panel of :func:`panels_of` side by side (not saved)."""
  plt = _plt()
  panels = panels_of(traj)
  fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.0))
  for ax, draw in zip(np.atleast_1d(axes), panels.values()):
    draw(ax, traj, env_index)
    ax.grid(alpha=0.3)
  if title:
    fig.suptitle(title, fontsize=11)
  fig.tight_layout()
  return fig


def plot_rollout(traj, out_dir: str, *, env_index: int = 0, title: str = "") -> dict:
  """Write health.png, load.png, cost.png and rollout.png (the three side by side) to ``out_dir``.

  Returns {name: path}. ``env_index`` picks the environment of a batched rollout.
  """
  if not 0 <= env_index < traj.num_envs:
    raise ValueError(f"env_index: must be in [0, {traj.num_envs}), got {env_index}")
  plt = _plt()
  os.makedirs(out_dir, exist_ok=True)
  paths = {}
  for name, draw in panels_of(traj).items():
    fig, ax = plt.subplots(figsize=(5.6, 4.0))
    draw(ax, traj, env_index)
    if title:
      fig.suptitle(title, fontsize=10)
    for a in fig.axes:
      a.grid(alpha=0.3)
    fig.tight_layout()
    paths[name] = os.path.join(out_dir, f"{name}.png")
    save_png(fig, paths[name], dpi=110)
    plt.close(fig)
  fig = rollout_figure(traj, env_index, title)
  paths["rollout"] = os.path.join(out_dir, "rollout.png")
  save_png(fig, paths["rollout"], dpi=100)
  plt.close(fig)
  return paths

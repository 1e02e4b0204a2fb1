"""Health-based curation of demonstration datasets (DAMAGE_MODEL.md §8, the paper's IL data regimes).

Pure functions ``Dataset -> Dataset`` (:mod:`mjx_damage.data`), run on the host:

* :func:`filter_episodes` — drop every episode in which some entity's health
  fell below ``min_health`` (the paper: 95) at any step;
* :func:`filter_datapoints` — drop the single steps t whose next ``horizon``
  steps (t … t+horizon−1; the paper: N = 8, the action-chunk length) cost some
  entity more than ``max_damage`` health points; the episode stays, only its
  ``keep`` mask changes, so chunks that start at a kept step still see the
  actions that follow it;
* :func:`successful`, :func:`with_label` — the episodes that completed the
  task, or that one operator condition made.

Each raises ``ValueError`` when nothing is left, naming the filter and its
setting, instead of handing an empty dataset to a trainer.
"""

from __future__ import annotations

import numpy as np

from mjx_damage import data as D
from mjx_damage.health import MAX_HEALTH


def _health(ds: D.Dataset) -> np.ndarray:
  """Entity health after each step, f32[E, T, N]; steps past an episode's end repeat its last value."""
  h = np.stack([np.asarray(v, np.float32) for v in ds.health.values()], axis=-1)
  t = np.minimum(np.arange(h.shape[1])[None, :], np.asarray(ds.lengths)[:, None] - 1)
  return np.take_along_axis(h, t[:, :, None], axis=1)


def _nonempty(ds: D.Dataset, what: str) -> D.Dataset:
  if ds.num_episodes == 0 or D.num_transitions(ds) == 0:
    raise ValueError(f"{what}: no data left after filtering (dataset of {ds.env_name!r})")
  return ds


def episode_min_health(ds: D.Dataset) -> np.ndarray:
  """Lowest health of any entity at any recorded step, f32[E]."""
  return _health(ds).min(axis=(1, 2))


def filter_episodes(ds: D.Dataset, min_health: float = 95.0) -> D.Dataset:
  """The episodes in which every entity's health stayed ≥ ``min_health`` (0–100) at every step."""
  if not 0.0 <= float(min_health) <= MAX_HEALTH:
    raise ValueError(f"min_health: must be in [0, 100], got {min_health!r}")
  ds = D.to_numpy(ds)
  out = D.select(ds, episode_min_health(ds) >= min_health)
  return _nonempty(out, f"filter_episodes(min_health={min_health})")


def window_damage(ds: D.Dataset, horizon: int = 8) -> np.ndarray:
  """Largest entity health loss over steps t … t+horizon−1 (clipped at the episode end), f32[E, T].

  Health before step 0 is taken as full (100): every episode starts intact.
  """
  if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
    raise ValueError(f"horizon: must be an int >= 1, got {horizon!r}")
  h = _health(ds)  # [E, T, N] after each step
  e, t, n = h.shape
  before = np.concatenate([np.full((e, 1, n), MAX_HEALTH, np.float32), h[:, :-1]], axis=1)
  end = np.minimum(np.arange(t) + horizon - 1, t - 1)
  after = h[:, end]  # [E, T, N]; past the end the padding repeats the last health
  return np.max(before - after, axis=-1)


def filter_datapoints(ds: D.Dataset, horizon: int = 8, max_damage: float = 5.0) -> D.Dataset:
  """``ds`` with step t un-kept where some entity loses more than ``max_damage`` health points
  over steps t … t+horizon−1 (:func:`window_damage`)."""
  if not np.isfinite(max_damage) or max_damage < 0:
    raise ValueError(f"max_damage: must be a finite number >= 0 (health points), got {max_damage!r}")
  ds = D.to_numpy(ds)
  keep = ds.keep & (window_damage(ds, horizon) <= max_damage)
  return _nonempty(ds.replace(keep=keep), f"filter_datapoints(horizon={horizon}, max_damage={max_damage})")


def successful(ds: D.Dataset) -> D.Dataset:
  """The episodes that completed the task."""
  ds = D.to_numpy(ds)
  return _nonempty(D.select(ds, ds.success), "successful")


def with_label(ds: D.Dataset, label: str) -> D.Dataset:
  """The episodes made by operator condition ``label`` (one of ``ds.label_names``)."""
  if label not in ds.label_names:
    raise ValueError(f"label: {label!r} not in this dataset; labels: {', '.join(ds.label_names)}")
  ds = D.to_numpy(ds)
  return _nonempty(D.select(ds, ds.labels == ds.label_names.index(label)), f"with_label({label!r})")

"""One viewed episode as a demonstration: the layout of ``mjx-damage record``, plus who saw what.

Per step, as :mod:`train.record` stores it: the observation and simulator state
(qpos ‖ qvel) *before* the step, the action, and the reward, entity health,
damage per model and cost *after* it. :func:`write` appends the episode to a
dataset file (:mod:`mjx_damage.data`, robomimic layout) or starts one, and
marks the new ``data/demo_<i>`` group with ``feedback`` (True: the operator saw
health bars and tint; False: ``--no-feedback``) — the two conditions of the
paper's teleoperation study. The file is replaced atomically, so it always
holds whole episodes.
"""

from __future__ import annotations

import os
import shutil

import h5py
import numpy as np

from mjx_damage import data as D
from mjx_damage.io import atomic_path
from mjx_damage.trajectory import MODELS


def step_record(obs, qpos, qvel, action, nxt) -> dict:
  """One step's row: ``obs``/``qpos``/``qvel`` before the step, ``action``, ``nxt`` the env state after."""
  info = nxt.info
  return {"obs": np.asarray(obs, np.float32), "actions": np.asarray(action, np.float32),
          "rewards": float(nxt.reward), "states": np.concatenate([qpos, qvel]).astype(np.float32),
          "health": np.asarray(info["entity_health"], np.float32),
          "damage": np.array([float(info["damage"][m]) for m in MODELS], np.float32),
          "cost": float(info["cost"]), "success": float(nxt.metrics["success"])}


def to_dataset(rows: list, *, task: str, entity_names, env_config: dict, label: str,
               safe_threshold: float) -> D.Dataset:
  """A one-episode :class:`mjx_damage.data.Dataset` from :func:`step_record` rows (at least one)."""
  if not rows:
    raise ValueError("episode: no steps to record")
  col = lambda k: np.stack([np.asarray(r[k]) for r in rows])[None]
  health = col("health")
  damage = col("damage")
  return D.build(
      env_name=task, env_config=env_config, obs={"state": col("obs")}, actions=col("actions"),
      rewards=col("rewards"), states=col("states"),
      health={n: health[:, :, i] for i, n in enumerate(entity_names)},
      damage={m: damage[:, :, i] for i, m in enumerate(MODELS)}, cost=col("cost"),
      lengths=[len(rows)], success=[bool(np.max(col("success")) > 0)],
      safe=[bool(np.all(health[0, -1] > safe_threshold))], label_names=(label,))


def check_target(path: str, task: str) -> int:
  """Episodes already in ``path`` (0: a new file), after checking it is a dataset of ``task``.

  Raises ValueError (naming ``--record``) for a folder, another task's dataset or a broken file.
  """
  if os.path.isdir(path):
    raise ValueError(f"--record: {path} is a folder; give a .hdf5 file path")
  if not os.path.exists(path):
    return 0
  try:
    return D.load(path, task=task).num_episodes
  except ValueError as e:
    raise ValueError(f"--record: {e}; it would not take this task's episodes (choose another file)") from None


def write(path: str, ds: D.Dataset, feedback: bool) -> int:
  """Append ``ds`` (one episode) to the dataset file ``path`` (created when missing), marking the new
  demo group with ``feedback``; returns its index. Atomic: ``path`` holds the old or the new file."""
  with atomic_path(path, suffix=".hdf5") as tmp:
    if os.path.exists(path):
      shutil.copyfile(path, tmp)
      D.append(tmp, ds)
    else:
      D.save(tmp, ds, overwrite=True)
    with h5py.File(tmp, "r+") as f:
      g = f["data"]
      index = max(int(k.split("_")[1]) for k in g if k.startswith("demo_"))
      g[f"demo_{index}"].attrs["feedback"] = bool(feedback)
  return index


def feedback_flags(path: str) -> dict:
  """``{demo index: feedback}`` of a dataset file (demos recorded without the attribute are left out)."""
  with h5py.File(path, "r") as f:
    g = f["data"]
    return {int(k.split("_")[1]): bool(g[k].attrs["feedback"]) for k in g
            if k.startswith("demo_") and "feedback" in g[k].attrs}

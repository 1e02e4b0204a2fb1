"""Built-in MJCF scenes: ``path(name)`` gives the file, ``load(name)`` the ``mujoco.MjModel``."""

from __future__ import annotations

import os

import mujoco

_DIR = os.path.dirname(__file__)


def names() -> list[str]:
  return sorted(f[:-4] for f in os.listdir(_DIR) if f.endswith(".xml"))


def path(name: str) -> str:
  p = os.path.join(_DIR, f"{name}.xml")
  if not os.path.isfile(p):
    raise ValueError(f"scene: unknown scene {name!r}; scenes: {', '.join(names())}")
  return p


def load(name: str) -> mujoco.MjModel:
  return mujoco.MjModel.from_xml_path(path(name))

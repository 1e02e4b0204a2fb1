"""Robots of the task suite, one module + MJCF each, behind :class:`tasks.robots.interface.Robot`.

* ``gripper`` — the floating parallel-jaw gripper (x/y/z slides); the default.
* ``panda`` — Franka Emika Panda, fixed base (on a mobile platform in navigate_and_pick), differential-IK control of the same
  ``[Δx, Δy, Δz, gripper]`` action.
* ``panda_wrist`` — the Panda with the 7-D action ``[Δpos, Δrot, gripper]``.
"""

from __future__ import annotations

from tasks.robots.gripper import Gripper
from tasks.robots.interface import Robot
from tasks.robots.panda import Panda, PandaWrist

DEFAULT = "gripper"
_REGISTRY: dict[str, type[Robot]] = {"gripper": Gripper, "panda": Panda, "panda_wrist": PandaWrist}


def names() -> list[str]:
  """Registered robot names, sorted."""
  return sorted(_REGISTRY)


def robot_class(name: str) -> type[Robot]:
  """The :class:`Robot` subclass registered as ``name``."""
  if name not in _REGISTRY:
    raise ValueError(f"robot: unknown {name!r}; valid: {', '.join(names())}")
  return _REGISTRY[name]

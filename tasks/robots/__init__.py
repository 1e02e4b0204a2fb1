"""Robots of the task suite, one module + MJCF each, behind :class:`tasks.robots.interface.Robot`.

* ``panda`` — Franka Emika Panda, fixed base (on a mobile platform in navigate_and_pick), differential-IK control of the same
  ``[Δx, Δy, Δz, gripper]`` action; the default: every task meets its scripted targets with it (README, Tasks).
* ``gripper`` — the floating parallel-jaw gripper (x/y/z slides); the robot of the RL settings
  (``tasks.RL_SETTINGS``) and of every results file whose command names no robot from before the switch.
* ``panda_wrist`` — the Panda with the 7-D action ``[Δpos, Δrot, gripper]``.
"""

from __future__ import annotations

import os

from tasks.robots.gripper import Gripper
from tasks.robots.interface import Robot
from tasks.robots.panda import Panda, PandaWrist

_REGISTRY: dict[str, type[Robot]] = {"gripper": Gripper, "panda": Panda, "panda_wrist": PandaWrist}
# The robot a task gets when none is named. MJX_DAMAGE_ROBOT chooses another for a whole process (read once,
# at import): e.g. the gripper for quick experiments; the test suite sets it to the gripper, the robot most
# of its checks were written for (tests/conftest.py).
ENV_VAR = "MJX_DAMAGE_ROBOT"
DEFAULT = os.environ.get(ENV_VAR) or "panda"
if DEFAULT not in _REGISTRY:
  raise ValueError(f"{ENV_VAR}: unknown robot {DEFAULT!r}; valid: {', '.join(sorted(_REGISTRY))}")


def names() -> list[str]:
  """Registered robot names, sorted."""
  return sorted(_REGISTRY)


def robot_class(name: str) -> type[Robot]:
  """The :class:`Robot` subclass registered as ``name``."""
  if name not in _REGISTRY:
    raise ValueError(f"robot: unknown {name!r}; valid: {', '.join(names())}")
  return _REGISTRY[name]

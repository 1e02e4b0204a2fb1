"""The viewer's keyboard: teleoperation of the policies' action and the viewer controls (pure functions).

MuJoCo's viewer calls back on key *presses* only (GLFW press/repeat; no
release), and binds most letters and digits to its own display toggles. So
the teleoperation keys are the arrow/navigation block and the numeric keypad,
which the viewer leaves alone, and motion is *latched*: a press moves the
commanded velocity of an axis one notch (±0.5 of the largest step) toward its
direction, and it stays until changed or stopped (holding a key repeats it,
so a held key reaches full speed in two repeats).

The action the key state gives is the suite's action (:mod:`tasks.robots.interface`):
``a[0:3]`` grip-point velocity (× the robot's ``MAX_STEP`` per control step),
``a[3:6]`` wrist rotation on 7-D robots, and the last entry the gripper
command (target gap; on Pour Water the glass tilt) — latched in notches of 0.5
from the value the task starts with.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

NOTCH = 0.5  # change of an action entry per key press

# GLFW key codes (glfw.h)
SPACE, BACKSPACE, ENTER, KP_ENTER, MINUS, EQUAL = 32, 259, 257, 335, 45, 61
INSERT, RIGHT, LEFT, DOWN, UP, PAGE_UP, PAGE_DOWN, HOME, END = 260, 262, 263, 264, 265, 266, 267, 268, 269
F6, F7, F8, F9, F10, F11 = 295, 296, 297, 298, 299, 300
KP = {i: 320 + i for i in range(10)}  # keypad digits

# key → (action entry, direction); entry "grip" is the last one
MOTION = {
    UP: (0, +1), KP[8]: (0, +1), DOWN: (0, -1), KP[2]: (0, -1),            # x (world)
    LEFT: (1, +1), KP[4]: (1, +1), RIGHT: (1, -1), KP[6]: (1, -1),         # y
    PAGE_UP: (2, +1), KP[9]: (2, +1), PAGE_DOWN: (2, -1), KP[3]: (2, -1),  # z
    HOME: ("grip", +1), KP[7]: ("grip", +1), END: ("grip", -1), KP[1]: ("grip", -1),
    F6: (3, +1), F7: (3, -1), F8: (4, +1), F9: (4, -1), F10: (5, +1), F11: (5, -1),  # wrist (7-D robots)
}
STOP = (INSERT, KP[5])  # every velocity to 0 (the gripper keeps its command)
PAUSE, RESET, END_EPISODE = (SPACE,), (BACKSPACE,), (ENTER, KP_ENTER)
SLOWER, FASTER = (MINUS,), (EQUAL,)
SPEEDS = (1.0, 0.5, 0.25, 0.125, 0.0625)  # slow-motion factors of real time

KEY_HELP = (
    ("Up / Down  (keypad 8 / 2)", "+x / -x (latched: each press one notch)"),
    ("Left / Right  (keypad 4 / 6)", "+y / -y"),
    ("PageUp / PageDown  (keypad 9 / 3)", "+z / -z"),
    ("Home / End  (keypad 7 / 1)", "gripper open / close (Pour Water: tilt)"),
    ("F6-F11", "wrist +rx -rx +ry -ry +rz -rz (7-D robots)"),
    ("Insert  (keypad 5)", "stop: every velocity 0"),
    ("Space", "pause / resume"),
    ("Backspace", "reset (the episode is discarded)"),
    ("Enter", "end the episode now (recorded with --record)"),
    ("- / =", "slow motion: half / double speed (1/16 .. 1x)"),
)


class Teleop(NamedTuple):
  """Latched teleoperation command: ``action`` f32[A] in [−1, 1] (last entry: gripper)."""

  action: np.ndarray


def start(action_size: int, grip: float) -> Teleop:
  """No motion, gripper command ``grip`` (the task's own at reset)."""
  a = np.zeros(action_size, np.float32)
  a[-1] = np.clip(grip, -1.0, 1.0)
  return Teleop(a)


def press(t: Teleop, key: int) -> Teleop:
  """The command after ``key`` was pressed (keys that are not teleoperation keys change nothing)."""
  a = t.action.copy()
  if key in STOP:
    a[:-1] = 0.0
    return Teleop(a)
  if key not in MOTION:
    return t
  entry, sign = MOTION[key]
  i = a.size - 1 if entry == "grip" else entry
  if i >= a.size - 1 and entry != "grip":  # wrist keys on a 4-D robot
    return t
  a[i] = np.clip(a[i] + sign * NOTCH, -1.0, 1.0)
  return Teleop(a)


def speed_after(speed: float, key: int) -> float:
  """Slow-motion factor after ``key`` (``-`` halves it, ``=`` doubles it, within :data:`SPEEDS`)."""
  i = int(np.argmin([abs(s - speed) for s in SPEEDS]))
  if key in SLOWER:
    i = min(i + 1, len(SPEEDS) - 1)
  elif key in FASTER:
    i = max(i - 1, 0)
  return SPEEDS[i]


def help_text() -> str:
  """The key map as lines ``keys: effect`` (``--help`` and docs/VIEWER.md print it)."""
  width = max(len(k) for k, _ in KEY_HELP)
  return "\n".join(f"  {k:<{width}}  {v}" for k, v in KEY_HELP)

"""``mjx-damage view``: the key map, recording, argument checks, and the viewer itself under Xvfb.

The viewer test opens MuJoCo's interactive viewer on a private Xvfb screen,
lets the scripted unsafe policy drop the plate of Place Plate, and reads the
screen: the plate's health bar drops and the scene turns red where the broken
plate lies. It is skipped, saying why, where the ``Xvfb`` binary is missing
(Debian package ``xvfb``; ``make install`` installs it as root).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import threading

import numpy as np
import pytest

import tasks
from apps import view_cli
from apps.viewer import display as X
from apps.viewer import episode as EP
from apps.viewer import feedback as F
from apps.viewer import keys as K
from mjx_damage import data as D
from mjx_damage import overlay

TASK = "place_plate"
STEPS = 70  # the unsafe policy has dropped the plate (health 0) by ~55 steps


# -- keys (pure) -----------------------------------------------------------------------------------
def test_keys_latch_velocity_and_gripper():
  t = K.start(4, grip=-1.0)
  assert t.action.tolist() == [0, 0, 0, -1]
  t = K.press(K.press(t, K.UP), K.UP)  # two notches: full speed +x
  t = K.press(t, K.PAGE_DOWN)
  t = K.press(t, K.HOME)
  np.testing.assert_allclose(t.action, [1.0, 0.0, -0.5, -0.5])
  t = K.press(t, K.UP)  # saturates
  assert t.action[0] == 1.0
  t = K.press(t, K.F6)  # wrist key on a 4-D robot: nothing
  assert t.action.shape == (4,) and t.action[1] == 0.0
  t = K.press(t, K.INSERT)  # stop keeps the gripper command
  np.testing.assert_allclose(t.action, [0.0, 0.0, 0.0, -0.5])
  t7 = K.press(K.start(7, 0.0), K.F6)
  assert t7.action[3] == K.NOTCH and t7.action[6] == 0.0
  assert K.press(t, 65).action.tolist() == t.action.tolist()  # a letter (viewer's own key): no change


def test_speed_keys_step_through_slow_motion():
  assert K.speed_after(1.0, K.MINUS) == 0.5
  assert K.speed_after(0.0625, K.MINUS) == 0.0625
  assert K.speed_after(0.25, K.EQUAL) == 0.5
  assert K.speed_after(1.0, K.EQUAL) == 1.0
  assert "Backspace" in K.help_text() and "keypad 8" in K.help_text()


# -- recording (no viewer) -------------------------------------------------------------------------
def _rows(n, h_end):
  return [{"obs": np.full(5, i, np.float32), "actions": np.zeros(4, np.float32), "rewards": 0.1,
           "states": np.zeros(7, np.float32), "health": np.array([100.0 - (100.0 - h_end) * i / (n - 1), 100.0]),
           "damage": np.array([1.0, 0.0, 0.0], np.float32), "cost": 1.0, "success": 0.0} for i in range(n)]


def test_episodes_append_with_feedback_attribute(tmp_path):
  path = str(tmp_path / "teleop.hdf5")
  kw = dict(task=TASK, entity_names=("plate", "agent"), env_config={}, safe_threshold=95.0)
  assert EP.check_target(path, TASK) == 0
  assert EP.write(path, EP.to_dataset(_rows(6, 40.0), label="teleop", **kw), feedback=True) == 0
  assert EP.write(path, EP.to_dataset(_rows(4, 100.0), label="teleop", **kw), feedback=False) == 1
  assert EP.check_target(path, TASK) == 2
  ds = D.load(path, task=TASK)
  assert ds.lengths.tolist() == [6, 4] and ds.safe.tolist() == [False, True]
  np.testing.assert_allclose(ds.health["plate"][0, :6][[0, -1]], [100.0, 40.0])
  assert EP.feedback_flags(path) == {0: True, 1: False}
  with pytest.raises(ValueError, match="--record: .*expected 'pick_egg'"):
    EP.check_target(path, "pick_egg")


def test_cli_checks_arguments_before_compiling(tmp_path, capsys):
  shot = tmp_path / "s.png"
  for argv, msg in (
      (["--task", TASK, "--screenshot", str(shot)], "screenshot: needs --headless"),
      (["--task", TASK, "--speed", "0.3"], "speed: must be one of"),
      (["--task", TASK, "--record", str(tmp_path / "x.csv")], "record: must end in .hdf5"),
      (["--task", "drop", "--robot", "panda"], "robot: built-in scene"),
      (["--task", TASK, "--policy", "scripted:reckless"], "policy: unknown policy"),
  ):
    with pytest.raises(SystemExit) as e:
      view_cli.main(argv)
    assert e.value.code == 2
    assert msg in capsys.readouterr().err
  shot.write_bytes(b"x")
  with pytest.raises(SystemExit):
    view_cli.main(["--task", TASK, "--headless", "--screenshot", str(shot)])
  assert "already exists" in capsys.readouterr().err


def test_read_xwd_decodes_a_little_endian_truecolor_dump():
  h, w = 2, 3
  px = np.array([[[10, 20, 30], [40, 50, 60], [70, 80, 90]], [[1, 2, 3], [4, 5, 6], [7, 8, 9]]], np.uint8)
  head = np.zeros(25, ">u4")
  head[0], head[1], head[4], head[5], head[7], head[11], head[12] = 100, 7, w, h, 0, 32, 4 * w
  head[14:17] = 0xFF0000, 0x00FF00, 0x0000FF
  body = np.zeros((h, w, 4), np.uint8)
  body[..., 0], body[..., 1], body[..., 2] = px[..., 2], px[..., 1], px[..., 0]  # B, G, R, pad (LSB first)
  raw = head.tobytes() + b"\0" * (100 - head.nbytes) + body.tobytes()
  np.testing.assert_array_equal(X.read_xwd(raw), px)


# -- the viewer on a private X screen ----------------------------------------------------------------
def _red(img):
  """bool[H, W]: pixels of the tint's red (a destroyed link: (0.9, 0.05, 0.05) lit)."""
  r, g, b = (img[..., c].astype(int) for c in range(3))
  return (r > 120) & (g < 0.35 * r) & (b < 0.35 * r)


def _bar_fill(img, box):
  """Share of a bar's row coloured (not the bar's grey background (70, 70, 70))."""
  x0, y0, x1, y1 = box
  row = img[(y0 + y1) // 2, x0 : x1 + 1].astype(int)
  return float(np.mean(np.abs(row - 70).sum(-1) > 30))


@pytest.fixture(scope="module")
def viewed(tmp_path_factory):
  if X.xvfb_path() is None:
    pytest.skip("Xvfb is not installed (Debian package xvfb; `make install` installs it as root)")
  from apps.viewer import app  # noqa: PLC0415  (loads GLFW; only where Xvfb exists)

  env = tasks.make(TASK)
  path = str(tmp_path_factory.mktemp("view") / "demos.hdf5")
  with X.virtual_display() as screen:
    res = app.run(env, TASK, policy=tasks.scripted_policy(env, "unsafe"), label="scripted:unsafe",
                  record=path, episode_length=100, steps=STEPS, realtime=False, screen=screen, shots=(0,),
                  plain=True, log=lambda m: None)
  return env, res, path


def test_viewer_shows_the_damage(viewed):
  env, res, _ = viewed
  assert res["steps"] == STEPS and res["final_health"]["plate"] < 50.0 and res["final_health"]["agent"] > 95.0
  before, after = res["shots"][0], res["screenshot"]
  assert before.shape == after.shape and before.ndim == 3
  # the panel sits top-left of the window, which Xvfb (no window manager) puts at the screen's origin
  boxes = F.panel_bar_boxes(res["scene"])
  plate = env.entity_names.index("plate")
  assert _bar_fill(before, boxes[plate]) > 0.95
  assert _bar_fill(after, boxes[plate]) < 0.6  # the bar dropped with the health
  assert _bar_fill(after, boxes[env.entity_names.index("agent")]) > 0.95
  panel_h, panel_w = res["last_panel"].shape[:2]
  scene = np.ones(after.shape[:2], bool)
  scene[:panel_h, :panel_w] = False  # the bars are not the scene
  assert _red(after)[scene].sum() > 20 * max(1, _red(before)[scene].sum())  # the broken plate is tinted red
  drawn = res["last_panel"].sum(-1) > 0  # the viewer shows the scene through the panel's black pixels
  np.testing.assert_array_equal(after[: panel_h, : panel_w][drawn], res["last_panel"][drawn])


def test_viewer_recording_loads_back(viewed):
  env, res, path = viewed
  ds = D.load(path, task=TASK)
  assert ds.num_episodes == 1 and ds.lengths.tolist() == [STEPS]
  assert ds.actions.shape == (1, STEPS, env.action_size)
  assert ds.obs["state"].shape[:2] == (1, STEPS)
  np.testing.assert_allclose(ds.health["plate"][0, -1], res["final_health"]["plate"], atol=1e-4)
  assert ds.damage["mechanical"][0].sum() > 50.0 and EP.feedback_flags(path) == {0: True}
  assert ds.label_names == ("scripted:unsafe",)


def test_keyboard_teleoperation_moves_the_hand(tmp_path):
  """Real key presses (xdotool → X server → GLFW → the viewer's key callback) drive the 4-D action."""
  if X.xvfb_path() is None or shutil.which("xdotool") is None:
    pytest.skip("needs Xvfb and xdotool (Debian packages xvfb, xdotool)")
  from apps.viewer import app  # noqa: PLC0415

  env = tasks.make(TASK)
  path = str(tmp_path / "teleop.hdf5")
  result = {}
  with X.virtual_display() as screen:
    run = threading.Thread(target=lambda: result.update(app.run(
        env, TASK, record=path, episode_length=150, steps=150, realtime=True, plain=True, log=lambda m: None)))
    run.start()
    env_x = dict(os.environ, DISPLAY=screen.name)
    win = subprocess.run(["xdotool", "search", "--sync", "--name", "MuJoCo"], env=env_x, capture_output=True,
                         text=True, timeout=120).stdout.split()[0]
    for key in ("Up", "Up", "Prior"):  # full speed +x, half speed +z
      subprocess.run(["xdotool", "key", "--window", win, key], env=env_x, check=True, timeout=30)
    run.join(timeout=300)
  assert not run.is_alive() and result["steps"] == 150
  ds = D.load(path, task=TASK)
  states, actions = ds.states[0], ds.actions[0]
  assert actions[-1, 0] == 1.0 and actions[-1, 2] == 0.5 and actions[-1, 1] == 0.0  # the latched command
  assert states[-1, 0] - states[0, 0] > 0.1 and states[-1, 2] > states[0, 2]  # the hand went +x and up
  assert EP.feedback_flags(path) == {0: True} and ds.label_names == ("teleop",)

"""benchmarks/task_stills.py: bad arguments fail before anything compiles; panels, PNG and contact sheet.

The end-to-end render of one task (one MJX compile) is ``@pytest.mark.slow``.
"""

import json
import os

import numpy as np
import pytest
from PIL import Image
from conftest import load_benchmark

stills = load_benchmark("task_stills")


@pytest.mark.parametrize("args, message", [
    (["--tasks", "no_such_task"], "tasks: unknown task(s) no_such_task"),
    (["--tasks", "pick_egg", "pick_egg"], "tasks: listed twice: pick_egg"),
    (["--width", "10"], "width: must be in [64, 2048]"),
    (["--height", "9000"], "height: must be in [64, 2048]"),
    (["--width", "0"], "width: must be a positive integer"),
    (["--steps", "0"], "steps: must be a positive integer"),
    (["--seed", "x"], "invalid int value"),
    (["--robot", "unicycle"], "robot: unknown robot 'unicycle'"),
    (["--robot", "panda_wrist", "--tasks", "navigate_and_pick"], "robot: navigate_and_pick run(s) without 'panda_wrist'"),
])
def test_rejects_bad_arguments(args, message, capsys):
  with pytest.raises(SystemExit) as e:
    stills.main(args)
  assert e.value.code == 2
  assert message in capsys.readouterr().err


def test_out_must_be_a_folder(tmp_path, capsys):
  f = tmp_path / "file.png"
  f.write_bytes(b"")
  with pytest.raises(SystemExit):
    stills.main(["--tasks", "pick_egg", "--out", str(f)])
  assert "out: exists and is not a folder" in capsys.readouterr().err


def test_panels_side_by_side_with_headers(tmp_path):
  grey = np.full((90, 120, 3), 128, np.uint8)
  p = stills.panel(grey, "scripted:safe - completed", stills.health_text(["plate", "agent"], [100.0, 42.5]))
  assert p.shape[1:] == (120, 3) and p.shape[0] > 90
  header = p[: p.shape[0] - 90]
  assert np.all(p[-90:] == grey)  # the frame itself is untouched
  assert header.min() < 100 and header.max() == 255  # dark text on white
  img = stills.side_by_side([p, p], gap=4)
  assert img.shape == (p.shape[0], 244, 3) and np.all(img[:, 120:124] == 255)
  path = str(tmp_path / "x.png")
  stills.save_png(img, path)
  back = np.asarray(Image.open(path).convert("RGB"))
  assert back.shape == img.shape and np.abs(back.astype(int) - img).max() <= 8


def test_health_text_wraps_within_the_panel():
  draw = stills.ImageDraw.Draw(Image.new("RGB", (10, 10)))
  font = stills._font(12)
  text = stills.health_text([f"entity_{i}" for i in range(12)], np.linspace(0, 100, 12))
  lines = stills._wrap(draw, text, font, 200)
  assert len(lines) > 1 and all(draw.textlength(x, font=font) <= 200 for x in lines[:-1])
  assert " ".join(lines) == text  # broken after a comma, nothing lost


def _summary(task, safe_ok, unsafe_min):
  pol = lambda ok, h: {"completed": ok, "final_health": {"obj": h, "agent": 100.0},  # noqa: E731
                       "episode_damage": 100.0 - h,
                       "damage_by_model": {"mechanical": 100.0 - h, "thermal": 0.0, "fluid": 0.0}}
  return {"task": task, "seed": 0, "steps": 10, "dt": 0.04, "entities": ["obj", "agent"],
          "policies": {"safe": pol(safe_ok, 100.0), "unsafe": pol(True, unsafe_min)},
          "command": f"python benchmarks/task_stills.py --tasks {task} --force"}


def test_index_lists_only_tasks_with_a_still(tmp_path):
  for task, has_png in (("place_plate", True), ("pick_egg", False)):
    with open(tmp_path / f"{task}.json", "w") as f:
      json.dump(_summary(task, True, 12.5), f)
    if has_png:
      Image.new("RGB", (4, 4)).save(tmp_path / f"{task}.png")
  text = open(stills.write_index(str(tmp_path))).read()
  assert "| [place_plate](#place_plate) | yes, 100.0 | yes, 12.5 | 87.5 / 0.0 / 0.0 |" in text
  assert "![place_plate: safe vs unsafe](place_plate.png)" in text
  assert "pick_egg" not in text


def test_existing_still_is_skipped_without_force(tmp_path, capsys):
  (tmp_path / "pick_egg.png").write_bytes(b"x")
  (tmp_path / "pick_egg.json").write_text(json.dumps(_summary("pick_egg", True, 50.0)))
  assert stills.main(["--tasks", "pick_egg", "--out", str(tmp_path)]) == 0
  assert "pick_egg: already rendered" in capsys.readouterr().out


@pytest.mark.slow
def test_one_task_renders_safe_and_unsafe(tmp_path):
  out = str(tmp_path)
  assert stills.main(["--tasks", "pick_egg", "--out", out, "--width", "96", "--height", "72"]) == 0
  img = np.asarray(Image.open(os.path.join(out, "pick_egg.png")).convert("RGB")).astype(int)
  assert img.shape[1] == 2 * 96 + 6
  for half in (img[-72:, :96], img[-72:, -96:]):  # the rendered frames, below the headers
    assert half.std() > 10  # a scene, not a blank or single-colour frame
  meta = json.load(open(os.path.join(out, "pick_egg.json")))
  assert set(meta["policies"]) == {"safe", "unsafe"}
  assert "pick_egg.png" in open(os.path.join(out, "index.md")).read()


def test_entity_pixels_counts_each_entitys_geoms():
  from types import SimpleNamespace

  # geoms 0, 1 → link 0 (entity 1), geom 2 → link 1 (entity 0), geom 3 untracked
  traj = SimpleNamespace(geom_link=np.array([0, 0, 1, -1]), link_entity=np.array([1, 0]))
  seg = np.array([[0, 1, 2, 3], [-1, -1, 2, 0]])
  np.testing.assert_array_equal(stills.entity_pixels(seg, traj, 2), [2, 3])


def test_other_robots_get_their_own_folder_and_only_their_tasks():
  args = stills.build_parser().parse_args(["--robot", "panda"])
  chosen = stills.check_args(args)
  assert args.out == stills.DEFAULT_OUT + "_panda"
  assert chosen == stills.tasks.select(None, "panda") and "place_plate" in chosen
  assert stills.command_of("place_plate", args) == ("python benchmarks/task_stills.py --tasks place_plate "
                                                    "--robot panda --force")
  gripper = stills.build_parser().parse_args([])
  assert stills.check_args(gripper) == stills.tasks.names() and gripper.out == stills.DEFAULT_OUT


def test_index_names_the_robot(tmp_path):
  with open(tmp_path / "place_plate.json", "w") as f:
    json.dump(_summary("place_plate", True, 12.5), f)
  Image.new("RGB", (4, 4)).save(tmp_path / "place_plate.png")
  text = open(stills.write_index(str(tmp_path), "panda")).read()
  assert "(panda)" in text and "task_stills.py --robot panda`" in text

"""Seeing damage: tinted frames, health-bar overlay, video files, plots, CLI errors.

The frames come from the built-in drop scene (plates falling onto a counter
beside a resting mug) because a fall damages a plate within a few steps: 8
environments, 9 steps (10 frames each), one compiled step. Seed 3 drops env 0's
plate low enough to hit and break within those steps; the other envs' plates
are still intact. The CLI test runs the same task/policy/batch, so its step
program is the same and comes from the persistent compilation cache.

The liquid and heat overlays come from a small scene (``tests/scenes/liquid_glass.xml``:
a glass of water on a hinge beside a laptop; the glass's bottom doubles as a
200 °C heat source): 1 environment, 3 steps, one compile of its own.

Rendering is headless (OSMesa from Debian's libosmesa6, installed by `make
install`): if the GL library is missing these tests FAIL with the package name.
"""

import json
import os

import dataclasses

import imageio.v2 as imageio
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from brax.envs.base import State
from mujoco import mjx
from PIL import ImageDraw

from apps import render_cli, training_log
from mjx_damage import plots
from mjx_damage import render as R
from mjx_damage.env import DamageEnv
from mjx_damage.overlay import HEALTH_HEADER, caption_box
from mjx_damage.wrapper import DamageWrapper

WET_SCENE = os.path.join(os.path.dirname(__file__), "scenes", "liquid_glass.xml")
WET_P = 32
WET_CONFIG = {
    "entities": {"laptop": {"params": "laptop", "bodies": ["laptop"]}},
    "liquid": {"particles": WET_P, "radius": 0.006,
               "spawn": {"body": "glass", "offset": [0, 0, 0.045], "size": [0.02, 0.02, 0.03]}},
    "temperature": {"sources": {"hot": {"geom": "glass_bottom", "temperature": 200.0, "on": True}}},
}

W, H = 160, 120
STEPS, NUM_ENVS, SEED = 9, 8, 3
DAMAGED_ENV = 0


def redness(rgb):
  """Mean of R − (G + B)/2 over pixels (f[..., 3] 0–255): 0 for greys, > 0 for reds."""
  rgb = np.asarray(rgb, np.float32)
  return float(np.mean(rgb[..., 0] - 0.5 * (rgb[..., 1] + rgb[..., 2])))


def entity_pixels(seg, traj, entity):
  """Mask of pixels showing a geom of ``entity`` in a geom-id image."""
  name_id = traj.entity_names.index(entity)
  geom_entity = np.where(traj.geom_link >= 0, traj.link_entity[np.maximum(traj.geom_link, 0)], -1)
  lut = np.append(geom_entity, -1)  # index −1 (background) → −1
  return lut[seg] == name_id


@pytest.fixture(scope="module")
def gl():
  try:
    return R.ensure_gl()
  except RuntimeError as e:
    pytest.fail(f"headless OpenGL unavailable — run `make install` as root (it installs libosmesa6): {e}")


@pytest.fixture(scope="module")
def drop(gl, tmp_path_factory):
  from apps.resolve import make_policy, make_task

  env = make_task("drop")
  policy = make_policy("zero", env)
  out = tmp_path_factory.mktemp("render") / "drop.mp4"
  res = R.render_rollout(env, policy, steps=STEPS, seed=SEED, out=str(out), width=W, height=H,
                         num_envs=NUM_ENVS, fps=25)
  model = R.mj_model_of(env)
  seg = {b: R.render_frames(model, res.trajectory, width=W, height=H, env_index=b, segmentation=True)
         for b in range(NUM_ENVS)}
  return env, res, seg, out


class WetEnv(DamageEnv):
  """The liquid-glass test scene as a damage env: action = the glass's tilt target (rad)."""

  def __init__(self):
    super().__init__(mujoco.MjModel.from_xml_path(WET_SCENE), WET_CONFIG, n_substeps=5)

  @property
  def observation_size(self):
    return 1

  @property
  def action_size(self):
    return 1

  def reset(self, rng):
    d = mjx.make_data(self.sys)
    z = jnp.zeros(())
    return State(d, d.qpos[:1], z, z, {"success": z}, {"damage_state": self.init_damage(rng)})

  def step(self, state, action):
    d, ds = self.physics_step(state.pipeline_state, state.info["damage_state"], action)
    return state.replace(pipeline_state=d, obs=d.qpos[:1], info=dict(state.info, damage_state=ds))


@pytest.fixture(scope="module")
def wet(gl):
  env = DamageWrapper(WetEnv())
  res = R.render_rollout(env, lambda s, k: jnp.full((1,), 2.0), steps=3, seed=0, width=W, height=H)
  return env, res


# --- pure helpers -------------------------------------------------------------------------
def test_tint_is_lerp_toward_red_by_lost_health():
  base = np.array([[1, 1, 1, 1], [1, 1, 1, 0.5], [0.2, 0.4, 0.8, 1], [0.5, 0.5, 0.5, 1]], np.float32)
  geom_link = np.array([0, 1, -1, 1])
  out = R.tinted_rgba(base, geom_link, np.array([100.0, 0.0]))
  np.testing.assert_array_equal(out[0], base[0])  # intact link: untouched
  np.testing.assert_allclose(out[1, :3], R.TINT_RGB)  # destroyed: fully red
  assert out[1, 3] == 0.5  # alpha kept
  np.testing.assert_array_equal(out[2], base[2])  # untracked geom: untouched
  half = R.tinted_rgba(base, geom_link, np.array([50.0, 50.0]))
  np.testing.assert_allclose(half[0, :3], 0.5 * base[0, :3] + 0.5 * R.TINT_RGB)
  np.testing.assert_array_equal(base[1], [1, 1, 1, 0.5])  # input not modified
  reds = [redness(R.tinted_rgba(base, geom_link, np.array([h, h]))[0, :3] * 255) for h in (100, 75, 50, 25, 0)]
  assert np.all(np.diff(reds) > 0)


def test_health_colour_green_to_red():
  assert R.health_color(100) == (0, 200, 40)
  assert R.health_color(0) == (220, 0, 40)
  r, g, _ = R.health_color(50)
  assert r > 150 and g > 150  # yellow midway
  assert R.health_color(150) == R.health_color(100) and R.health_color(-5) == R.health_color(0)


def test_overlay_bars_follow_health():
  frame = np.zeros((H, W, 3), np.uint8)
  names = ("plate", "mug")
  a = R.draw_health_bars(frame, names, [100.0, 100.0], caption="t 0.00 s")
  b = R.draw_health_bars(frame, names, [40.0, 100.0], caption="t 0.00 s")
  assert not np.shares_memory(a, frame) and frame.max() == 0
  (px0, py0, px1, py1), (mx0, my0, mx1, my1) = R.health_bar_boxes(H, W, names)
  plate_a, plate_b = a[py0:py1 + 1, px0:px1 + 1], b[py0:py1 + 1, px0:px1 + 1]
  # full bar: all green; at 40: the right 60 % is the grey background, the fill is red-orange
  assert np.all(plate_a[:, :, 1] > 150) and np.all(plate_a[:, :, 0] < 50)
  right = plate_b[:, int(0.5 * (px1 - px0)):]
  assert np.all(right == 70)
  assert plate_b[2, 2, 0] > plate_b[2, 2, 1]  # 40 → more red than green
  np.testing.assert_array_equal(a[my0:my1 + 1, mx0:mx1 + 1], b[my0:my1 + 1, mx0:mx1 + 1])


def test_overlay_draws_header_readouts_and_caption(monkeypatch):
  drawn = []
  real_text = ImageDraw.ImageDraw.text
  monkeypatch.setattr(ImageDraw.ImageDraw, "text", lambda self, xy, text, *a, **k: (
      drawn.append(text), real_text(self, xy, text, *a, **k))[1])
  frame = np.full((H, W, 3), 128, np.uint8)
  caption = ["t 0.10 s", "episode damage 3.0 hp (keeps counting after health 0)"]
  out = R.draw_health_bars(frame, ("laptop",), [50.0], caption, readouts=[("40", "7")],
                           headers=("max °C", "wet (particles)"))
  assert {HEALTH_HEADER, "max °C", "wet (particles)", "laptop", "50", "40", "7", *caption} <= set(drawn)
  x0, y0, x1, y1 = caption_box(H, W, ("laptop",), caption)
  assert y1 - y0 > 15 and np.abs(out[y0:y1, x0:x1].astype(int) - 128).mean() > 20  # caption panel drawn


def test_glow_follows_source_temperature():
  base = np.array([[0.5, 0.5, 0.5, 0.2], [0.1, 0.1, 0.1, 1.0]], np.float32)
  cold = R.glow_rgba(base, np.array([0]), np.array([22.0]), ambient=22.0)
  hot = R.glow_rgba(base, np.array([0]), np.array([22.0 + R.GLOW_SPAN]), ambient=22.0)
  np.testing.assert_array_equal(cold[0, :3], base[0, :3])
  np.testing.assert_allclose(hot[0, :3], R.GLOW_RGB)
  assert hot[0, 3] > cold[0, 3] >= base[0, 3]
  np.testing.assert_array_equal(hot[1], base[1])  # not a source: untouched


# --- rendered rollouts ----------------------------------------------------------------------
def test_damaged_plate_turns_red_and_its_bar_changes(drop):
  _, res, seg, _ = drop
  traj, frames = res.trajectory, res.frames[DAMAGED_ENV]
  assert frames.shape == (STEPS + 1, H, W, 3) and frames.dtype == np.uint8
  plate = traj.entity_names.index("plate")
  health = traj.entity_health[:, DAMAGED_ENV, plate]
  assert health[0] == 100.0 and health[-1] < 90.0, f"seed {SEED} env {DAMAGED_ENV} should break its plate: {health}"
  m0 = entity_pixels(seg[DAMAGED_ENV][0], traj, "plate")
  m1 = entity_pixels(seg[DAMAGED_ENV][-1], traj, "plate")
  assert m0.sum() > 50 and m1.sum() > 50, "the plate should be in view"
  r0, r1 = redness(frames[0][m0]), redness(frames[-1][m1])
  assert r1 > r0 + 15, f"plate redness {r0:.1f} → {r1:.1f} at health {health[-1]:.1f}"
  # the mug rests undamaged beside it: no tint on its pixels
  mug0 = entity_pixels(seg[DAMAGED_ENV][0], traj, "mug")
  mug1 = entity_pixels(seg[DAMAGED_ENV][-1], traj, "mug")
  assert abs(redness(frames[-1][mug1]) - redness(frames[0][mug0])) < 3
  # the plate's bar differs, the mug's (still 100) does not
  (px0, py0, px1, py1), (mx0, my0, mx1, my1) = R.health_bar_boxes(H, W, traj.entity_names)
  assert np.abs(frames[-1][py0:py1, px0:px1].astype(int) - frames[0][py0:py1, px0:px1]).mean() > 20
  np.testing.assert_array_equal(frames[-1][my0:my1, mx0:mx1], frames[0][my0:my1, mx0:mx1])


def test_no_tint_where_health_stays_100(drop):
  env, res, seg, _ = drop
  traj = res.trajectory
  intact = [b for b in range(NUM_ENVS) if np.all(traj.entity_health[:, b] == 100.0)]
  assert intact, "expected some env without damage in this batch"
  model = R.mj_model_of(env)
  b = intact[0]
  # the tint is a no-op there: frames with and without it are identical
  plain = R.render_frames(model, traj, width=W, height=H, env_index=b, tint=False)
  np.testing.assert_array_equal(plain, res.frames[b])
  m = entity_pixels(seg[b][-1], traj, "plate")
  assert redness(res.frames[b][-1][m]) < 10


def test_selected_times_are_the_same_frames(drop):
  env, res, _, _ = drop
  model = R.mj_model_of(env)
  b = DAMAGED_ENV
  ends = R.render_frames(model, res.trajectory, width=W, height=H, env_index=b, times=[0, -1, 4])
  np.testing.assert_array_equal(ends, res.frames[b][[0, STEPS, 4]])  # same camera (framed at reset), same overlay
  with pytest.raises(ValueError, match="times"):
    R.render_frames(model, res.trajectory, width=W, height=H, times=[STEPS + 1])


def test_same_reset_starts_every_env_from_env_0s_episode(drop):
  env = drop[0]
  zero = lambda s, k: jnp.zeros((0,))  # noqa: E731 (the drop scene has no actions)
  own = R.rollout(env, zero, steps=1, seed=SEED, num_envs=2)
  same = R.rollout(env, zero, steps=1, seed=SEED, num_envs=2, same_reset=True)  # the same compiled program
  assert not np.allclose(own.qpos[0, 0], own.qpos[0, 1])  # by default: two different episodes
  np.testing.assert_array_equal(same.qpos[0, 1], same.qpos[0, 0])
  np.testing.assert_array_equal(same.qpos[0, 0], own.qpos[0, 0])  # env 0's episode is unchanged


def test_video_files_decode(drop, tmp_path):
  _, res, _, out = drop
  assert [os.path.basename(p) for p in res.paths] == ["drop.mp4"] + [f"drop_env{b}.mp4" for b in range(1, NUM_ENVS)]
  video = np.stack(imageio.mimread(str(out), format="FFMPEG"))
  assert video.shape == (STEPS + 1, H, W, 3)
  assert np.abs(video.astype(int) - res.frames[0]).mean() < 12  # lossy, but the same pictures
  gif = R.write_video(res.frames[DAMAGED_ENV], str(tmp_path / "drop.gif"), fps=25)
  frames = imageio.mimread(gif)
  assert len(frames) == STEPS + 1 and frames[0].shape[:2] == (H, W)


def test_rollout_plots(drop, tmp_path):
  _, res, _, _ = drop
  traj = res.trajectory
  assert traj.link_names[plots.most_damaged_link(traj, DAMAGED_ENV)] == "plate/plate"
  assert traj.f_par[:, DAMAGED_ENV].max() + traj.f_perp[:, DAMAGED_ENV].max() > traj.mech_threshold[DAMAGED_ENV].min()
  paths = plots.plot_rollout(traj, str(tmp_path), env_index=DAMAGED_ENV, title="drop")
  assert set(paths) == {"health", "load", "cost", "rollout"}
  for p in paths.values():
    img = imageio.imread(p)
    assert img.shape[0] > 200 and img.std() > 10


def test_rollout_plots_label_every_axis(drop, wet):
  for traj, names in ((drop[1].trajectory, ["health", "load", "cost"]),
                      (wet[1].trajectory, ["health", "load", "cost", "temperature", "wetness"])):
    assert list(plots.panels_of(traj)) == names
    fig = plots.rollout_figure(traj, 0, title="x")
    try:
      for ax in fig.axes:
        assert ax.get_xlabel() and ax.get_ylabel(), (ax.get_title(), ax.get_xlabel(), ax.get_ylabel())
        assert "(" in ax.get_ylabel(), f"no unit in {ax.get_ylabel()!r}"
    finally:
      plots._plt().close(fig)


def test_load_plot_goes_log_when_a_spike_dwarfs_the_threshold(drop):
  traj = drop[1].trajectory
  big = dataclasses.replace(traj, f_par=traj.f_par * 0 + 1e4 * traj.mech_threshold[None].max())
  fig, ax = plots._plt().subplots()
  plots._load_ax(ax, big, DAMAGED_ENV)
  assert ax.get_yscale() == "symlog" and "symlog" in ax.get_ylabel()
  plots._plt().close(fig)


# --- every damage model shows: liquid particles, heat, wetness -------------------------------
def test_wet_rollout_records_particles_and_heat(wet):
  _, res = wet
  traj = res.trajectory
  assert traj.modalities == ("mechanical", "thermal", "fluid")
  assert traj.particles.shape == (4, 1, WET_P, 3) and traj.particle_radius == 0.006
  assert traj.source_names == ("hot",) and np.all(traj.source_temperature[:, 0, 0] == 200.0)
  assert traj.damage.shape == (4, 1, 3) and traj.temperature.shape == traj.exposure.shape == (4, 1, 1)
  np.testing.assert_allclose(traj.damage.sum(-1), traj.cost, rtol=1e-5, atol=1e-6)
  headers, readouts, caption = R.frame_labels(traj, 3, 0)
  assert headers == ["max °C", "wet (particles)"] and len(readouts) == 1 and len(readouts[0]) == 2
  text = "\n".join(caption)
  assert "episode damage" in text and "hp" in text and "keeps counting after health 0" in text
  assert "hot 200 °C" in text and f"liquid: {WET_P} particles" in text and "by model: mechanical" in text


def test_env_b_runs_policy_b_of_a_sequence(wet):
  env, res = wet
  tilt, hold = (lambda s, k: jnp.full((1,), 2.0)), (lambda s, k: jnp.zeros((1,)))
  traj = R.rollout(env, [tilt, hold], steps=3, seed=0, num_envs=2, same_reset=True)
  np.testing.assert_allclose(traj.qpos[:, 0], res.trajectory.qpos[:, 0], atol=1e-5)  # env 0: the tilt, as alone
  assert abs(traj.qpos[-1, 0, 0] - traj.qpos[-1, 1, 0]) > 0.05  # env 1 held the glass upright
  with pytest.raises(ValueError, match="policy"):
    R.rollout(env, [], steps=1)


def test_particles_are_drawn(wet):
  env, res = wet
  model = R.mj_model_of(env)
  laptop_top = model.body("laptop").pos + [0.0, 0.0, 0.016]
  grid = np.stack(np.meshgrid(np.linspace(-0.1, 0.1, 8), np.linspace(-0.06, 0.06, 4), [0.0]), -1).reshape(-1, 3)
  # the recorded particles moved onto the laptop, which the free camera frames, so they are in view
  traj = dataclasses.replace(res.trajectory, particles=np.broadcast_to(
      (laptop_top + grid)[None, None], res.trajectory.particles.shape).copy())
  on = R.render_frames(model, traj, width=W, height=H, overlay=False)
  off = R.render_frames(model, traj, width=W, height=H, overlay=False, particles=False)
  changed = np.any(on != off, axis=-1)
  assert changed.mean() > 0.01, "no particle pixels"
  rgb = on[changed].astype(np.float32)
  assert np.mean(rgb[:, 2] - rgb[:, 0]) > 40, "particle pixels should be blue"
  seg = R.render_frames(model, traj, width=W, height=H, segmentation=True)
  assert seg.shape == (4, H, W)  # segmentation ignores the particles


def test_overlay_changes_the_frame_and_names_every_model(wet):
  env, res = wet
  model = R.mj_model_of(env)
  plain = R.render_frames(model, res.trajectory, width=W, height=H, overlay=False)
  _, row, pad, boxes, cols, panel = R.overlay_layout(H, W, res.trajectory)
  x0, y0, x1, y1 = panel
  assert len(cols) == 2  # max °C, wet (particles)
  assert np.abs(res.frames[0][:, y0:y1, x0:x1].astype(int) - plain[:, y0:y1, x0:x1]).mean() > 10


def test_training_log_plot(tmp_path):
  run = tmp_path / "run"
  run.mkdir()
  rows = [{"env_steps": 1000 * i, "train/episode_return": -5.0 + i, "train/episode_cost": 10.0 - i,
           "eval/task_return": -4.0 + i, "eval/episode_cost": 9.0 - i, "eval/completion": 0.1 * i,
           "eval/safe_completion": 0.05 * i, "lagrange": 0.2 * i} for i in range(5)]
  (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
  (run / "config.json").write_text(json.dumps({"task": "place_plate", "config": {"budget": 5.0}}))
  got_rows, budget, task = training_log.read_training_log(str(run))
  assert got_rows == rows and budget == 5.0 and task == "place_plate"
  p = training_log.plot_training_log(str(run), str(tmp_path / "curves.png"))
  assert imageio.imread(p).shape[1] > 4 * 400  # four panels: return, cost, success, λ
  with pytest.raises(ValueError, match="training_log"):
    training_log.find_training_log(str(tmp_path / "nowhere"))


# --- CLI ------------------------------------------------------------------------------------
def test_cli_writes_gif_and_plots(drop, tmp_path, capsys):
  out = tmp_path / "cli.gif"
  rc = render_cli.main(["--task", "drop", "--policy", "zero", "--out", str(out), "--steps", "2", "--seed", str(SEED),
               "--num-envs", str(NUM_ENVS), "--width", "96", "--height", "64", "--plots", str(tmp_path / "p")])
  assert rc == 0
  assert len(imageio.mimread(str(out))) == 3
  assert os.path.exists(tmp_path / f"cli_env{NUM_ENVS - 1}.gif")
  assert sorted(os.listdir(tmp_path / "p")) == ["cost.png", "health.png", "load.png", "rollout.png"]
  assert "final health: plate" in capsys.readouterr().out


@pytest.mark.parametrize("backend", ["native", "auto"])  # auto: native on this one-device CPU
def test_cli_native_backend_writes_frames(backend, gl, tmp_path, capsys):
  """--backend native: the rollout behind the frames is stepped by native MuJoCo (and the run says so)."""
  out = tmp_path / "native.gif"
  rc = render_cli.main(["--task", "drop", "--policy", "zero", "--out", str(out), "--steps", "2", "--seed", str(SEED),
                        "--num-envs", "2", "--width", "64", "--height", "48", "--backend", backend])
  assert rc == 0
  assert len(imageio.mimread(str(out))) == 3 and os.path.exists(tmp_path / "native_env1.gif")
  text = capsys.readouterr().out
  assert "backend native" in text and "final health: plate" in text



@pytest.mark.slow  # about 40 s of compiling on 2 CPU cores
def test_cli_warp_backend_writes_frames(gl, tmp_path, capsys):
  """--backend warp: the rollout behind the frames is a registry task stepped by MuJoCo Warp, the envs its batch."""
  pytest.importorskip("warp", reason="warp-lang (the mjx_damage[warp] extra) is not installed")
  out = tmp_path / "warp.gif"
  rc = render_cli.main(["--task", "place_plate", "--robot", "gripper", "--policy", "scripted:unsafe", "--out", str(out),
                        "--steps", "2", "--num-envs", "2", "--width", "64", "--height", "48", "--backend", "warp"])
  assert rc == 0
  assert len(imageio.mimread(str(out))) == 3 and os.path.exists(tmp_path / "warp_env1.gif")
  text = capsys.readouterr().out
  assert "backend warp" in text and "final health: plate" in text

def test_native_rollout_records_the_same_episode(drop):
  """The drop fixture's episode, physics on the native backend: same keys, same fall, same broken plate."""
  from apps.resolve import make_policy, on_backend

  env, res, _, _ = drop
  native = R.rollout(on_backend(env, "native", NUM_ENVS), make_policy("zero", env), steps=STEPS, seed=SEED,
                     num_envs=NUM_ENVS)
  mjx_traj = res.trajectory
  assert native.qpos.shape == mjx_traj.qpos.shape and native.dt == mjx_traj.dt
  np.testing.assert_allclose(native.qpos, mjx_traj.qpos, atol=2e-3)
  np.testing.assert_allclose(native.entity_health, mjx_traj.entity_health, atol=1.0)
  assert native.entity_health[-1, DAMAGED_ENV].min() < 95  # the fall still breaks env 0's plate
  with pytest.raises(ValueError, match="num_envs: the native batch steps 8"):
    R.rollout(on_backend(env, "native", NUM_ENVS), lambda s, k: s.obs[:0], steps=1, num_envs=2)


@pytest.mark.parametrize("args, message", [
    (["--task", "nope", "--policy", "zero", "--out", "x.mp4"], "unknown task 'nope'"),
    (["--task", "drop", "--policy", "zero", "--out", "x.gif", "--backend", "foo"], "backend: unknown backend 'foo'"),
    (["--task", "drop", "--policy", "greedy", "--out", "x.mp4"], "unknown policy 'greedy'"),
    (["--task", "drop", "--policy", "checkpoint:/no/such/run", "--out", "x.mp4"], "does not exist"),
    (["--task", "drop", "--policy", "zero", "--out", "x.avi"], "unsupported extension '.avi'"),
    (["--task", "drop", "--policy", "zero", "--out", "x"], "unsupported extension"),
    (["--task", "drop", "--policy", "zero", "--out", "x.gif", "--steps", "0"], "steps: must be a positive"),
    (["--task", "drop", "--policy", "zero", "--out", "x.gif", "--width", "-3"], "width: must be a positive"),
    (["--task", "drop", "--policy", "zero", "--out", "x.gif", "--camera", "top"], "camera: unknown camera 'top'"),
    (["--task", "drop", "--policy", "zero", "--out", "x.gif", "--training-log", "/no/run"], "needs --plots"),
])
def test_cli_rejects_bad_arguments(args, message, capsys):
  with pytest.raises(SystemExit) as e:
    render_cli.main(args)
  assert e.value.code == 2
  assert message in capsys.readouterr().err


def test_api_rejects_bad_arguments(drop):
  env, _, _, _ = drop
  policy = lambda s, k: s.obs[:0]  # noqa: E731 (never compiled: arguments are checked first)
  for kw, message in [({"steps": 0}, "steps"), ({"steps": 2, "out": "a.webm"}, "unsupported extension"),
                      ({"steps": 2, "num_envs": 0}, "num_envs"), ({"steps": 2, "fps": -1}, "fps")]:
    with pytest.raises(ValueError, match=message):
      R.render_rollout(env, policy, **kw)
  with pytest.raises(ValueError, match="not damage-tracked"):
    R.render_rollout(object(), policy, steps=2)


# --- the task suite's scripted strategies (two Place Plate compiles: slow) --------------------
@pytest.mark.slow
def test_place_plate_unsafe_reddens_plate_safe_does_not(gl):
  import tasks
  from apps.resolve import make_policy

  env = tasks.make("place_plate")
  model = R.mj_model_of(env)
  steps = tasks.default_config("place_plate")["episode_length"]
  out = {}
  for style in ("unsafe", "safe"):
    res = R.render_rollout(env, make_policy(f"scripted:{style}", env), steps=steps, seed=0, width=W, height=H)
    traj = res.trajectory
    seg = R.render_frames(model, traj, width=W, height=H, segmentation=True)
    m0, m1 = entity_pixels(seg[0], traj, "plate"), entity_pixels(seg[-1], traj, "plate")
    out[style] = (traj.entity_health[-1, 0], redness(res.frames[0][0][m0]), redness(res.frames[0][-1][m1]))
  (h_u, r0_u, r1_u), (h_s, r0_s, r1_s) = out["unsafe"], out["safe"]
  assert h_u[0] < 90 and r1_u > r0_u + 15, out
  assert np.all(h_s == 100.0) and abs(r1_s - r0_s) < 5, out

"""Seeing damage: render a rollout with damaged links tinted red and health bars on every frame.

Python API::

    import tasks
    from mjx_damage.render import render_rollout
    env = tasks.make("place_plate")
    res = render_rollout(env, tasks.scripted_policy(env, "unsafe"), steps=100, seed=0,
                         out="rollout.mp4", width=640, height=480)
    res.frames[0]        # uint8[steps + 1, H, W, 3] of env 0 (frame 0 = the reset state)
    res.paths            # ["rollout.mp4"] (one file per env: rollout_env1.mp4, … when num_envs > 1)
    res.trajectory       # Trajectory: per-step health, loads, cost (see mjx_damage.plots)

CLI (:mod:`apps.render_cli`)::

    mjx-damage render --task place_plate --policy scripted:unsafe --out rollout.mp4 [--plots DIR]

The pieces, one module each: :mod:`mjx_damage.trajectory` (the compiled
rollout), :mod:`mjx_damage.overlay` (tint, health bars), :mod:`mjx_damage.gl`
(headless OpenGL), :mod:`mjx_damage.video` (MP4/GIF); this module frames and
draws. Generic: it renders any damage-wrapped env and imports no task.

How it works:

* Simulation: ``num_envs`` environments step together through ONE compiled
  program, ``jit(vmap(policy + env.step))``; the Python loop over time calls it
  ``steps`` times, so the step count is not baked into the program and any
  rollout length reuses the same compilation. After each step only what a frame
  and the plots need comes back to the host (positions, health, loads, cost).
* Frames: a plain ``mujoco.MjData`` takes each recorded ``qpos``/``mocap`` and
  goes through ``mj_forward``; MuJoCo's offscreen renderer draws it headless
  (OSMesa by default, ``MUJOCO_GL=egl`` for EGL). Each tracked link's geoms are
  tinted toward red by (100 − h)/100 of that link's health (an entity's health is
  the min over its links, so its most damaged link shows the value on its bar);
  untracked geoms keep their colours.
* Overlay: one labelled bar per tracked entity (name, value, colour green →
  red), whether or not the entity is in view, plus time and cumulative cost.

MP4 (imageio-ffmpeg, H.264) or GIF (Pillow) by the output's extension.
"""

from __future__ import annotations

import copy
import dataclasses
import os
from typing import Callable, Optional

import mujoco
import numpy as np

# Re-exported: `from mjx_damage.render import ...` is the documented entry point to all of it.
from mjx_damage.gl import ensure_gl, gl_backend  # noqa: F401
from mjx_damage.overlay import TINT_RGB, draw_health_bars, health_bar_boxes, health_color, tinted_rgba  # noqa: F401
from mjx_damage.trajectory import Trajectory, binding_of, positive_int, mj_model_of, rollout  # noqa: F401
from mjx_damage.video import OUTPUT_FORMATS, check_out, write_video  # noqa: F401


def camera_of(model, data, camera, tracked_bodies):
  """A camera argument (None, 'free', a camera name or id, or an MjvCamera) → what update_scene takes."""
  if camera is None or camera == "free":
    cam = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(model, cam)
    # Look at the tracked objects (at reset) rather than the model's centre, which
    # large static geoms (floors) pull away from where things happen.
    if len(tracked_bodies):
      pts = data.xpos[tracked_bodies]
      cam.lookat[:] = pts.mean(axis=0)
      spread = float(np.max(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))
      cam.distance = max(0.5, 3.0 * spread)
    cam.azimuth, cam.elevation = 135.0, -30.0
    return cam
  if isinstance(camera, mujoco.MjvCamera):
    return camera
  if isinstance(camera, (int, np.integer)) and not isinstance(camera, bool):
    if not 0 <= camera < model.ncam:
      raise ValueError(f"camera: id {camera} out of range (model has {model.ncam} cameras)")
    return int(camera)
  if isinstance(camera, str):
    names = [model.camera(i).name for i in range(model.ncam)]
    if camera not in names:
      raise ValueError(f"camera: unknown camera {camera!r}; valid: free{''.join(', ' + n for n in names)}")
    return camera
  raise ValueError(f"camera: expected None, 'free', a camera name/id or an MjvCamera, got {camera!r}")


def render_frames(mj_model, traj: Trajectory, *, width: int = 640, height: int = 480, camera=None,
                  env_index: int = 0, overlay: bool = True, tint: bool = True,
                  segmentation: bool = False) -> np.ndarray:
  """uint8[T + 1, height, width, 3]: env ``env_index`` of ``traj``, tinted, with health bars.

  ``segmentation=True`` returns instead i32[T + 1, height, width], the geom id
  seen at each pixel (−1: none), from the same camera: which pixels show which
  entity (``traj.geom_link`` → ``traj.link_entity``).
  """
  width, height = positive_int("width", width), positive_int("height", height)
  if not 0 <= env_index < traj.num_envs:
    raise ValueError(f"env_index: must be in [0, {traj.num_envs}), got {env_index}")
  ensure_gl()
  model = copy.deepcopy(mj_model)  # its geom colours are overwritten per frame
  # The offscreen buffer must hold the frame; the scene's XML may ask for less.
  model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
  model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
  # A geom with a material takes the material's colour: start tinted geoms from it
  # and drop the material (textures would hide the tint).
  base = np.array(model.geom_rgba, np.float32)
  has_mat = (model.geom_matid >= 0) & (traj.geom_link >= 0)
  base[has_mat] = model.mat_rgba[model.geom_matid[has_mat]]
  if tint:
    model.geom_matid[has_mat] = -1
  data = mujoco.MjData(model)
  b = env_index
  renderer = mujoco.Renderer(model, height=height, width=width)
  if segmentation:
    renderer.enable_segmentation_rendering()
    overlay = False
  try:
    frames = np.empty((traj.steps + 1, height, width) + (() if segmentation else (3,)),
                      np.int32 if segmentation else np.uint8)
    cam = None
    tracked_bodies = np.unique(np.asarray(_body_of_links(model, traj)))
    cum_cost = np.cumsum(traj.cost[:, b])
    for t in range(traj.steps + 1):
      data.qpos[:] = traj.qpos[t, b]
      data.qvel[:] = traj.qvel[t, b]
      if model.nmocap:
        data.mocap_pos[:] = traj.mocap_pos[t, b]
        data.mocap_quat[:] = traj.mocap_quat[t, b]
      mujoco.mj_forward(model, data)
      if cam is None:  # framed on the reset state and then held still
        cam = camera_of(model, data, camera, tracked_bodies)
      model.geom_rgba[:] = tinted_rgba(base, traj.geom_link, traj.link_health[t, b]) if tint else base
      renderer.update_scene(data, camera=cam)
      img = renderer.render()
      if segmentation:  # channel 0: object id, channel 1: object type
        img = np.where(img[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), img[..., 0], -1)
      elif overlay:
        caption = f"t {t * traj.dt:5.2f} s   cost {cum_cost[t]:6.1f}"
        img = draw_health_bars(img, traj.entity_names, traj.entity_health[t, b], caption)
      frames[t] = img
  finally:
    renderer.close()  # free the GL context now, not at interpreter exit
  return frames


def _body_of_links(model, traj):
  """Body id of each tracked link (from the geoms' link assignment)."""
  out = []
  for link in range(len(traj.link_names)):
    geoms = np.nonzero(traj.geom_link == link)[0]
    if len(geoms):
      out.append(int(model.geom_bodyid[geoms[0]]))
  return out


def _env_path(out: str, b: int, num_envs: int) -> str:
  if num_envs == 1 or b == 0:
    return out
  root, ext = os.path.splitext(out)
  return f"{root}_env{b}{ext}"


@dataclasses.dataclass
class RenderResult:
  frames: list  # per env: uint8[steps + 1, H, W, 3]
  paths: list  # written files, one per env (empty without out)
  trajectory: Trajectory


def render_rollout(env, policy: Callable, *, steps: int, seed: int = 0, out: Optional[str] = None,
                   width: int = 640, height: int = 480, camera=None, fps: Optional[float] = None,
                   num_envs: int = 1, overlay: bool = True, tint: bool = True) -> RenderResult:
  """Roll ``policy`` out in ``num_envs`` envs of ``env`` and render every step of each.

  Args:
    env: a damage-tracked env (``tasks.make(...)``, or any ``DamageWrapper`` env
      whose scene has an ``mj_model``).
    policy: ``policy(state, rng) -> action`` for one env (jittable).
    steps: control steps; frames = steps + 1 (the first shows the reset state).
    seed: PRNG seed of resets and actions.
    out: ``.mp4`` or ``.gif`` path, or None for frames only. With several envs,
      env b > 0 goes to ``<stem>_env<b><ext>``.
    width, height: frame size in pixels.
    camera: None/'free' (framed on the tracked objects), a model camera name or
      id, or a ``mujoco.MjvCamera``.
    fps: playback rate; default real time (1 / env.dt).
    num_envs: environments simulated together (one compiled step).
    overlay, tint: draw the health bars / tint damaged links (on by default).

  Raises:
    ValueError: bad arguments, checked before anything compiles.
    RuntimeError: the headless OpenGL library is missing (names the package).
  """
  steps, num_envs = positive_int("steps", steps), positive_int("num_envs", num_envs)
  width, height = positive_int("width", width), positive_int("height", height)
  if out is not None:
    check_out(out)
  binding_of(env)
  mj_model = mj_model_of(env)
  fps = float(fps) if fps is not None else 1.0 / float(env.dt)
  if not 0 < fps <= 1000:
    raise ValueError(f"fps: must be in (0, 1000], got {fps!r}")
  ensure_gl()  # fail on a missing GL library before spending time compiling
  traj = rollout(env, policy, steps=steps, seed=seed, num_envs=num_envs)
  frames, paths = [], []
  for b in range(num_envs):
    f = render_frames(mj_model, traj, width=width, height=height, camera=camera, env_index=b,
                      overlay=overlay, tint=tint)
    frames.append(f)
    if out is not None:
      paths.append(write_video(f, _env_path(os.fspath(out), b, num_envs), fps))
  return RenderResult(frames=frames, paths=paths, trajectory=traj)

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
* Overlay (:func:`frame_labels`): a header "health (0-100)" and one bar per
  tracked entity (name, value, colour green → red), whether or not the entity
  is in view; with heat sources a column of each entity's hottest link (°C),
  with liquid one of the particles touching it. Bottom-left: time, the
  episode's damage in health points (it keeps counting after a health reaches
  0: the models still evaluate abuse of a destroyed object, as the cost does),
  its split by damage model, each heat source's temperature, the liquid.
* Every damage model the scene drives is visible: liquid particles are drawn
  as blue spheres added to MuJoCo's scene each frame; heat source geoms glow
  (orange, more opaque the hotter the source).

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
from mjx_damage.overlay import (TINT_RGB, bar_layout, draw_health_bars, health_bar_boxes, health_color,  # noqa: F401
                                tinted_rgba)
from mjx_damage.trajectory import (MODELS, Trajectory, base_env, binding_of, positive_int, mj_model_of,  # noqa: F401
                                   rollout)
from mjx_damage.video import OUTPUT_FORMATS, check_out, write_video  # noqa: F401


WATER_RGBA = np.array([0.15, 0.45, 1.0, 0.9], np.float32)  # liquid particles
GLOW_RGB = np.array([1.0, 0.45, 0.05], np.float32)  # a heat source at full glow
GLOW_SPAN = 300.0  # °C above ambient at which a source glows fully


def add_spheres(scene, centres: np.ndarray, radius: float, rgba=WATER_RGBA) -> int:
  """Append one sphere per row of ``centres`` (f[P, 3] world frame, m) to an ``MjvScene``.

  Call after ``Renderer.update_scene`` (which resets the scene's geoms). Stops
  at the scene's capacity; returns the number added.
  """
  n = max(0, min(len(centres), scene.maxgeom - scene.ngeom))
  size = np.array([radius, 0.0, 0.0])
  eye = np.eye(3).ravel()
  rgba = np.asarray(rgba, np.float32)
  for p in np.asarray(centres[:n], np.float64):
    mujoco.mjv_initGeom(scene.geoms[scene.ngeom], int(mujoco.mjtGeom.mjGEOM_SPHERE), size, p, eye, rgba)
    scene.ngeom += 1
  return n


def glow_rgba(base_rgba: np.ndarray, source_geom: np.ndarray, source_temperature: np.ndarray,
              ambient: float) -> np.ndarray:
  """Geom colours with each heat source's geom lerped toward orange by (T − ambient)/300 °C.

  base_rgba f32[G, 4]; source_geom i32[S]; source_temperature f32[S] °C. Its alpha
  rises with the glow (a hot translucent flame shows). Returns a new array.
  """
  rgba = np.array(base_rgba, np.float32, copy=True)
  w = np.clip((np.asarray(source_temperature, np.float32) - ambient) / GLOW_SPAN, 0.0, 1.0)[:, None]
  g = np.asarray(source_geom)
  rgba[g, :3] = (1.0 - w) * rgba[g, :3] + w * GLOW_RGB
  rgba[g, 3] = np.maximum(rgba[g, 3], 0.15 + 0.35 * w[:, 0])  # translucent: what is inside stays visible
  return rgba


def _per_entity(values: np.ndarray, link_entity: np.ndarray, n: int, reduce) -> list:
  return [float(reduce(values[link_entity == i])) if np.any(link_entity == i) else float("nan") for i in range(n)]


def frame_labels(traj: Trajectory, t: int, b: int = 0) -> tuple:
  """What the overlay of frame ``t`` of env ``b`` says: (headers, readouts per entity, caption lines).

  Headers/readouts: "max °C" (hottest link of the entity) with heat sources;
  "wet (particles)" (liquid particles within contact distance of the entity's
  links, a particle touching two links counted twice) with liquid.
  """
  n = len(traj.entity_names)
  headers, columns = [], []
  if "thermal" in traj.modalities and traj.temperature is not None:
    headers.append("max °C")
    temps = _per_entity(traj.temperature[t, b], traj.link_entity, n, np.max)
    columns.append([f"{x:.0f}" for x in temps])
  if "fluid" in traj.modalities and traj.exposure is not None:
    headers.append("wet (particles)")
    wet = _per_entity(traj.exposure[t, b], traj.link_entity, n, np.sum)
    columns.append([f"{x:.0f}" for x in wet])
  readouts = [tuple(c[i] for c in columns) for i in range(n)] if columns else None
  episode = float(np.sum(traj.cost[: t + 1, b]))
  caption = [f"t {t * traj.dt:5.2f} s",
             f"episode damage {episode:.1f} hp (keeps counting after health 0)"]
  if traj.damage is not None and len(traj.modalities) > 1:
    by = np.sum(traj.damage[: t + 1, b], axis=0)
    caption.append("by model: " + ", ".join(f"{m} {by[MODELS.index(m)]:.1f}" for m in traj.modalities))
  if traj.source_temperature is not None:
    caption.append("heat source: " + ", ".join(
        f"{name} {temp:.0f} °C" for name, temp in zip(traj.source_names, traj.source_temperature[t, b])))
  if traj.particles is not None:
    caption.append(f"liquid: {traj.particles.shape[2]} particles (blue), r {1000 * traj.particle_radius:.0f} mm")
  return headers, readouts, caption


def overlay_layout(height: int, width: int, traj: Trajectory, t: int = 0, b: int = 0) -> tuple:
  """(font, row, pad, bar boxes, readout column x's, panel box) of frame ``t``'s overlay (tests, figures)."""
  headers, readouts, _ = frame_labels(traj, t, b)
  return bar_layout(height, width, traj.entity_names, readouts, headers)


def camera_of(model, data, camera, tracked_bodies, extra_geoms=()):
  """A camera argument (None, 'free', a camera name or id, or an MjvCamera) → what update_scene takes.

  The free camera frames ``tracked_bodies`` and ``extra_geoms`` (heat sources) at their pose in ``data``.
  """
  if camera is None or camera == "free":
    cam = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(model, cam)
    # Look at the tracked objects (at reset) rather than the model's centre, which
    # large static geoms (floors) pull away from where things happen.
    if len(tracked_bodies) or len(extra_geoms):
      pts = np.concatenate([data.xpos[np.asarray(tracked_bodies, int)], data.geom_xpos[np.asarray(extra_geoms, int)]])
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
                  env_index: int = 0, overlay: bool = True, tint: bool = True, particles: bool = True,
                  segmentation: bool = False, times=None) -> np.ndarray:
  """uint8[T + 1, height, width, 3]: env ``env_index`` of ``traj``, tinted, with health bars.

  ``particles``: draw the liquid (when the scene has one); heat sources glow
  with ``tint``. ``times``: only these recorded steps (ints in [0, T]), in that
  order: uint8[len(times), height, width, 3] (e.g. ``[-1]``: the end state alone).

  ``segmentation=True`` returns instead i32[T + 1, height, width], the geom id
  seen at each pixel (−1: none), from the same camera: which pixels show which
  entity (``traj.geom_link`` → ``traj.link_entity``).
  """
  width, height = positive_int("width", width), positive_int("height", height)
  if not 0 <= env_index < traj.num_envs:
    raise ValueError(f"env_index: must be in [0, {traj.num_envs}), got {env_index}")
  if times is None:
    times = range(traj.steps + 1)
  else:
    times = [int(t) for t in times]
    if not times or not all(-(traj.steps + 1) <= t <= traj.steps for t in times):
      raise ValueError(f"times: recorded steps in [0, {traj.steps}] (negative from the end), got {times}")
    times = [t % (traj.steps + 1) for t in times]
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
  draw_liquid = particles and traj.particles is not None and not segmentation
  extra = traj.particles.shape[2] if draw_liquid else 0
  renderer = mujoco.Renderer(model, height=height, width=width, max_geom=10000 + extra)
  if segmentation:
    renderer.enable_segmentation_rendering()
    overlay = False
  try:
    frames = np.empty((len(times), height, width) + (() if segmentation else (3,)),
                      np.int32 if segmentation else np.uint8)
    tracked_bodies = np.unique(np.asarray(_body_of_links(model, traj)))
    _set_state(model, data, traj, 0, b)  # the camera is framed on the reset state and then held still
    sources = traj.source_geom if traj.source_geom is not None else ()
    cam = camera_of(model, data, camera, tracked_bodies, sources)
    for i, t in enumerate(times):
      _set_state(model, data, traj, t, b)
      rgba = tinted_rgba(base, traj.geom_link, traj.link_health[t, b]) if tint else base
      if tint and traj.source_temperature is not None:
        rgba = glow_rgba(rgba, traj.source_geom, traj.source_temperature[t, b], traj.ambient)
      model.geom_rgba[:] = rgba
      renderer.update_scene(data, camera=cam)
      if draw_liquid:
        add_spheres(renderer.scene, traj.particles[t, b], traj.particle_radius)
      img = renderer.render()
      if segmentation:  # channel 0: object id, channel 1: object type
        img = np.where(img[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), img[..., 0], -1)
      elif overlay:
        headers, readouts, caption = frame_labels(traj, t, b)
        img = draw_health_bars(img, traj.entity_names, traj.entity_health[t, b], caption, readouts, headers)
      frames[i] = img
  finally:
    renderer.close()  # free the GL context now, not at interpreter exit
  return frames


def _set_state(model, data, traj: Trajectory, t: int, b: int) -> None:
  """Load recorded step ``t`` of env ``b`` into ``data`` and run ``mj_forward``."""
  data.qpos[:] = traj.qpos[t, b]
  data.qvel[:] = traj.qvel[t, b]
  if model.nmocap:
    data.mocap_pos[:] = traj.mocap_pos[t, b]
    data.mocap_quat[:] = traj.mocap_quat[t, b]
  mujoco.mj_forward(model, data)


def _body_of_links(model, traj):
  """Body id of each tracked link (from the geoms' link assignment)."""
  out = []
  for link in range(len(traj.link_names)):
    geoms = np.nonzero(traj.geom_link == link)[0]
    if len(geoms):
      out.append(int(model.geom_bodyid[geoms[0]]))
  return out


def env_path(out: str, b: int, num_envs: int) -> str:
  """The file env ``b`` of ``num_envs`` is written to: ``out`` for env 0, ``<root>_env<b><ext>`` after."""
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
                   num_envs: int = 1, overlay: bool = True, tint: bool = True,
                   particles: bool = True) -> RenderResult:
  """Roll ``policy`` out in ``num_envs`` envs of ``env`` and render every step of each.

  Args:
    env: a damage-tracked env (``tasks.make(...)``, or any ``DamageWrapper`` env
      whose scene has an ``mj_model``), or a :class:`~mjx_damage.native_batch.NativeBatchEnv`
      of ``num_envs`` of them (the same episode, physics stepped by native MuJoCo).
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
    overlay, tint, particles: draw the labelled health bars / tint damaged
      links and make heat sources glow / draw the liquid (all on by default).

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
  fps = float(fps) if fps is not None else 1.0 / float(base_env(env).dt)
  if not 0 < fps <= 1000:
    raise ValueError(f"fps: must be in (0, 1000], got {fps!r}")
  ensure_gl()  # fail on a missing GL library before spending time compiling
  traj = rollout(env, policy, steps=steps, seed=seed, num_envs=num_envs)
  frames, paths = [], []
  for b in range(num_envs):
    f = render_frames(mj_model, traj, width=width, height=height, camera=camera, env_index=b,
                      overlay=overlay, tint=tint, particles=particles)
    frames.append(f)
    if out is not None:
      paths.append(write_video(f, env_path(os.fspath(out), b, num_envs), fps))
  return RenderResult(frames=frames, paths=paths, trajectory=traj)

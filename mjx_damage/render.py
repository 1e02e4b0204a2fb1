"""Seeing damage: render a rollout with damaged links tinted red and health bars on every frame.

Python API::

    import tasks
    from mjx_damage.render import render_rollout
    from train.evaluate import make_policy
    env = tasks.make("place_plate")
    res = render_rollout(env, make_policy("scripted:unsafe", env), steps=100, seed=0,
                         out="rollout.mp4", width=640, height=480)
    res.frames[0]        # uint8[steps + 1, H, W, 3] of env 0 (frame 0 = the reset state)
    res.paths            # ["rollout.mp4"] (one file per env: rollout_env1.mp4, … when num_envs > 1)
    res.trajectory       # Trajectory: per-step health, loads, cost (see mjx_damage.plots)

CLI::

    mjx-damage render --task place_plate --policy scripted:unsafe --out rollout.mp4 [--plots DIR]

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

import argparse
import collections
import dataclasses
import os
import sys
import time
import warnings
from typing import Callable, Optional, Sequence

import numpy as np

OUTPUT_FORMATS = (".mp4", ".gif")
GL_BACKENDS = ("osmesa", "egl")
DEFAULT_GL = "osmesa"  # what `make install` provides (Debian libosmesa6): software GL, no GPU or display
# System packages each backend needs on Debian (for the error message).
GL_PACKAGES = {"osmesa": "libosmesa6", "egl": "libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0"}
TINT_RGB = np.array([0.9, 0.05, 0.05], np.float32)  # colour of a destroyed link
MAX_HEALTH = 100.0


# --------------------------------------------------------------------------------------
# Headless OpenGL
# --------------------------------------------------------------------------------------
def gl_backend() -> str:
  """The headless OpenGL backend to render with: ``$MUJOCO_GL``, else ``$PYOPENGL_PLATFORM``
  when one names ``osmesa`` or ``egl``, else OSMesa."""
  for var in ("MUJOCO_GL", "PYOPENGL_PLATFORM"):
    name = os.environ.get(var, "").strip().lower()
    if name in GL_BACKENDS:
      return name
  return DEFAULT_GL


def ensure_gl() -> str:
  """Make ``mujoco.Renderer`` use a headless GL context; return the backend's name.

  MuJoCo picks its GL context class once, when ``mujoco`` is first imported,
  from ``MUJOCO_GL`` (unset → GLFW, which needs a display). ``mjx_damage``
  imports mujoco long before anything renders, so instead of relying on the
  environment at import time we point MuJoCo's context class at the headless
  backend here; ``mujoco.Renderer`` looks it up when it is constructed.

  Raises:
    RuntimeError: the backend's system library cannot be loaded (the message
      names the Debian package to install).
  """
  backend = gl_backend()
  platform = os.environ.setdefault("PYOPENGL_PLATFORM", backend)  # PyOpenGL reads it on first import
  if platform.strip().lower() != backend:
    raise RuntimeError(f"headless rendering: MUJOCO_GL={backend} but PYOPENGL_PLATFORM={platform}; "
                       "set both to the same backend (osmesa or egl), or unset PYOPENGL_PLATFORM")
  try:
    if backend == "osmesa":
      from mujoco.osmesa import GLContext
    else:
      from mujoco.egl import GLContext
  except Exception as e:  # ImportError, OSError, PyOpenGL's own errors when the .so is missing
    raise RuntimeError(
        f"headless rendering: cannot load the {backend} OpenGL backend ({type(e).__name__}: {e}). "
        f"Install it with `apt-get install {GL_PACKAGES[backend]}` (`make install` does this when run "
        f"as root), or choose the other backend with MUJOCO_GL={'egl' if backend == 'osmesa' else 'osmesa'}."
    ) from e
  from mujoco.rendering.classic import gl_context

  gl_context.GLContext = GLContext
  return backend


# --------------------------------------------------------------------------------------
# Pure helpers: tint, colours, overlay
# --------------------------------------------------------------------------------------
def tinted_rgba(base_rgba: np.ndarray, geom_link: np.ndarray, link_health: np.ndarray) -> np.ndarray:
  """Geom colours with every tracked link's geoms lerped toward red by (100 − h)/100.

  base_rgba f32[G, 4]; geom_link i32[G] (tracked link of each geom or −1);
  link_health f32[L]. Alpha is kept; untracked geoms are unchanged. Returns a new array.
  """
  rgba = np.array(base_rgba, np.float32, copy=True)
  tracked = geom_link >= 0
  h = np.clip(np.asarray(link_health, np.float32)[geom_link[tracked]], 0.0, MAX_HEALTH)
  w = ((MAX_HEALTH - h) / MAX_HEALTH)[:, None]
  rgba[tracked, :3] = (1.0 - w) * rgba[tracked, :3] + w * TINT_RGB
  return rgba


def health_color(h: float) -> tuple[int, int, int]:
  """Bar colour for health ``h``: green at 100 through yellow at 50 to red at 0 (RGB 0–255)."""
  x = float(np.clip(h, 0.0, MAX_HEALTH)) / MAX_HEALTH
  r = 1.0 if x < 0.5 else 2.0 * (1.0 - x)
  g = 2.0 * x if x < 0.5 else 1.0
  return int(round(220 * r)), int(round(200 * g)), 40


def _font(size: int):
  from PIL import ImageFont

  try:
    return ImageFont.load_default(size=size)  # scalable (FreeType) default font, Pillow >= 10.1
  except (TypeError, OSError):
    return ImageFont.load_default()


def _bar_layout(height: int, width: int, names: Sequence[str]):
  """Font, sizes and each entity's bar box (x0, y0, x1, y1) of the overlay for a frame size."""
  from PIL import Image, ImageDraw

  row = max(9, height // 22)
  font = _font(max(7, row - 2))
  pad = max(2, row // 4)
  measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
  name_w = max([measure.textlength(n, font=font) for n in names] + [0.0])
  val_w = measure.textlength("100", font=font)
  bar_w = max(20, min(int(width * 0.3), width - int(name_w + val_w) - 6 * pad))
  x0 = int(2 * pad + name_w)
  boxes = [(x0, pad + i * row + 2, x0 + bar_w, pad + (i + 1) * row - 2) for i in range(len(names))]
  panel = (0, 0, int(name_w + bar_w + val_w + 5 * pad), len(names) * row + 2 * pad)
  return font, row, pad, boxes, panel


def health_bar_boxes(height: int, width: int, names: Sequence[str]) -> list:
  """Pixel box (x0, y0, x1, y1), inclusive, of each entity's bar in a ``height`` × ``width`` frame.

  Bars are drawn opaque, so these pixels depend on health alone (tests and
  figure scripts read them).
  """
  return _bar_layout(height, width, names)[3]


def draw_health_bars(frame: np.ndarray, names: Sequence[str], health: Sequence[float],
                     caption: Optional[str] = None) -> np.ndarray:
  """``frame`` (uint8[H, W, 3]) with one labelled health bar per entity drawn top-left.

  Every entity gets a row — name, a bar filled to h/100 in :func:`health_color`,
  the value — on a translucent panel, so entities out of the camera's view are
  shown too. ``caption`` (time, cost …) goes bottom-left. Sizes scale with the
  frame height. Returns a new array; ``frame`` is not modified.
  """
  from PIL import Image, ImageDraw

  H, W = frame.shape[:2]
  font, row, pad, boxes, panel = _bar_layout(H, W, names)
  img = Image.fromarray(np.ascontiguousarray(frame[..., :3])).convert("RGBA")
  layer = Image.new("RGBA", img.size, (0, 0, 0, 0))
  draw = ImageDraw.Draw(layer)
  draw.rectangle(panel, fill=(0, 0, 0, 150))
  for name, h, (x0, y0, x1, y1) in zip(names, health, boxes):
    h = float(np.clip(h, 0.0, MAX_HEALTH))
    ty = y0 - 2
    draw.text((pad, ty), name, font=font, fill=(255, 255, 255, 255))
    draw.rectangle([x0, y0, x1, y1], fill=(70, 70, 70, 255))
    fill = int(round((x1 - x0) * h / MAX_HEALTH))
    if fill > 0:
      draw.rectangle([x0, y0, x0 + fill, y1], fill=health_color(h) + (255,))
    draw.text((x1 + pad, ty), f"{h:.0f}", font=font, fill=(255, 255, 255, 255))
  if caption:
    tw = draw.textlength(caption, font=font)
    draw.rectangle([0, H - row - 2 * pad, int(tw + 2 * pad), H], fill=(0, 0, 0, 150))
    draw.text((pad, H - row - pad), caption, font=font, fill=(255, 255, 255, 255))
  return np.asarray(Image.alpha_composite(img, layer).convert("RGB"))


# --------------------------------------------------------------------------------------
# The rollout
# --------------------------------------------------------------------------------------
@dataclasses.dataclass
class Trajectory:
  """A recorded rollout, numpy, time-major: index t = 0 is the reset state, t = k after k steps.

  Per step (leading axes [T + 1, B]): ``qpos``, ``qvel``, ``mocap_pos``, ``mocap_quat``
  (what a frame needs), ``entity_health`` [.., N], ``link_health`` [.., L],
  ``f_par``/``f_perp`` [.., L] (peak contact loads of the step, N), ``cost`` (damage
  of the step), ``reward``, ``success``, ``done``. Per env: ``alpha``, ``beta``,
  ``mech_threshold`` [B, L] (mechanical parameters, for the load plot).
  """

  qpos: np.ndarray
  qvel: np.ndarray
  mocap_pos: np.ndarray
  mocap_quat: np.ndarray
  entity_health: np.ndarray
  link_health: np.ndarray
  f_par: np.ndarray
  f_perp: np.ndarray
  cost: np.ndarray
  reward: np.ndarray
  success: np.ndarray
  done: np.ndarray
  alpha: np.ndarray
  beta: np.ndarray
  mech_threshold: np.ndarray
  entity_names: tuple
  link_names: tuple
  link_entity: np.ndarray
  geom_link: np.ndarray
  dt: float

  @property
  def steps(self) -> int:
    return self.qpos.shape[0] - 1

  @property
  def num_envs(self) -> int:
    return self.qpos.shape[1]

  @property
  def time(self) -> np.ndarray:
    """Seconds since reset of each recorded state, f[T + 1]."""
    return np.arange(self.steps + 1) * self.dt


def _record(state, done_before):
  """What one env's state contributes to a :class:`Trajectory` (traced, inside the step)."""
  import jax.numpy as jnp

  d, info = state.pipeline_state, state.info
  ds = info["damage_state"]
  live = 1.0 - done_before  # a finished (frozen) env adds no more cost
  return {
      "qpos": d.qpos, "qvel": d.qvel, "mocap_pos": d.mocap_pos, "mocap_quat": d.mocap_quat,
      "entity_health": info["entity_health"], "link_health": info["link_health"],
      "f_par": ds.f_par * live, "f_perp": ds.f_perp * live, "cost": info["cost"] * live,
      "reward": state.reward * live, "success": state.metrics.get("success", jnp.zeros(())),
      "done": jnp.maximum(done_before, state.done),
  }


class _Programs:
  """The compiled reset and step of (env, policy, num_envs), reused across calls."""

  def __init__(self, env, policy: Callable, num_envs: int):
    import jax
    import jax.numpy as jnp

    self.env, self.policy, self.num_envs = env, policy, num_envs

    def reset_one(key):
      reset_key, act_key = jax.random.split(key)
      state = env.reset(reset_key)
      z = jnp.zeros((), jnp.float32)
      return state, act_key, _record(state, z)

    def step_one(state, act_key, done, t):
      nxt = env.step(state, policy(state, jax.random.fold_in(act_key, t)))
      # An env whose episode ended stays frozen at its final state (as train.evaluate does).
      nxt = jax.tree.map(lambda a, b: jnp.where(done > 0, b, a), nxt, state)
      rec = _record(nxt, done)
      return nxt, rec["done"], rec

    self.reset = jax.jit(jax.vmap(reset_one))
    self.step = jax.jit(jax.vmap(step_one, in_axes=(0, 0, 0, None)))


_PROGRAMS: "collections.OrderedDict" = collections.OrderedDict()
_MAX_PROGRAMS = 4  # a few (env, policy) pairs stay compiled, e.g. safe and unsafe of one task


def _programs(env, policy, num_envs) -> _Programs:
  # Keyed by identity; the entry keeps env and policy alive so their ids are not reused.
  key = (id(env), id(policy), num_envs)
  if key in _PROGRAMS:
    _PROGRAMS.move_to_end(key)
  else:
    _PROGRAMS[key] = _Programs(env, policy, num_envs)
    while len(_PROGRAMS) > _MAX_PROGRAMS:
      _PROGRAMS.popitem(last=False)
  return _PROGRAMS[key]


def _positive_int(name, v):
  if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
    raise ValueError(f"{name}: must be a positive integer, got {v!r}")
  return int(v)


def _binding(env):
  # DamageWrapper's binding (brax wrappers around it forward the attribute); a bare
  # DamageEnv tracks damage but lacks the health/cost summaries that frames and plots read.
  b = getattr(env, "binding", None)
  if b is None:
    raise ValueError("env: not damage-tracked: wrap it in mjx_damage.DamageWrapper (tasks.make does)")
  return b


def mj_model_of(env):
  """The scene's ``mujoco.MjModel`` of a (wrapped) env."""
  e = env
  for _ in range(16):
    m = getattr(e, "mj_model", None)
    if m is not None:
      return m
    if not hasattr(e, "env"):
      break
    e = e.env
  raise ValueError("env: exposes no mj_model (needed to render)")


def rollout(env, policy: Callable, *, steps: int, seed: int = 0, num_envs: int = 1) -> Trajectory:
  """Run ``num_envs`` episodes of ``steps`` control steps through one compiled step; record them.

  ``env``: a :class:`~mjx_damage.wrapper.DamageWrapper`-wrapped env (e.g. ``tasks.make``);
  ``policy(state, rng) -> action`` for one env. Env b's reset and action keys
  come from ``split(PRNGKey(seed), num_envs)[b]``, as in :mod:`train.evaluate`.
  """
  import jax

  steps, num_envs = _positive_int("steps", steps), _positive_int("num_envs", num_envs)
  if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
    raise ValueError(f"seed: must be an integer, got {seed!r}")
  if not callable(policy):
    raise ValueError(f"policy: must be callable policy(state, rng) -> action, got {policy!r}")
  binding = _binding(env)
  prog = _programs(env, policy, num_envs)
  state, act_keys, rec = prog.reset(jax.random.split(jax.random.PRNGKey(int(seed)), num_envs))
  done = rec["done"]
  recs = [jax.device_get(rec)]
  for t in range(steps):
    state, done, rec = prog.step(state, act_keys, done, t)
    recs.append(jax.device_get(rec))
  stacked = {k: np.stack([np.asarray(r[k]) for r in recs]) for k in recs[0]}
  params = jax.device_get(state.info["damage_state"].params)
  return Trajectory(
      **stacked,
      alpha=np.asarray(params.alpha), beta=np.asarray(params.beta),
      mech_threshold=np.asarray(params.mech_threshold),
      entity_names=tuple(binding.entity_names), link_names=tuple(binding.link_names),
      link_entity=np.asarray(binding.link_entity), geom_link=np.asarray(binding.geom_link),
      dt=float(env.dt),
  )


# --------------------------------------------------------------------------------------
# Frames
# --------------------------------------------------------------------------------------
def _camera(model, data, camera, tracked_bodies):
  """A camera argument (None, 'free', a camera name or id, or an MjvCamera) → what update_scene takes."""
  import mujoco

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
  import copy

  import mujoco

  width, height = _positive_int("width", width), _positive_int("height", height)
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
        cam = _camera(model, data, camera, tracked_bodies)
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


# --------------------------------------------------------------------------------------
# Writing video
# --------------------------------------------------------------------------------------
def check_out(out) -> str:
  """The output path's format ('.mp4' or '.gif'); ValueError for anything else."""
  if not isinstance(out, (str, os.PathLike)) or not os.fspath(out):
    raise ValueError(f"out: expected a file path ending in {' or '.join(OUTPUT_FORMATS)}, got {out!r}")
  ext = os.path.splitext(os.fspath(out))[1].lower()
  if ext not in OUTPUT_FORMATS:
    raise ValueError(f"out: unsupported extension {ext or '(none)'!r} in {os.fspath(out)!r}; "
                     f"use {' or '.join(OUTPUT_FORMATS)}")
  return ext


def write_video(frames: np.ndarray, out: str, fps: float) -> str:
  """Write uint8[T, H, W, 3] frames to ``out`` (.mp4: H.264 via imageio-ffmpeg; .gif: Pillow)."""
  ext = check_out(out)
  if not (isinstance(fps, (int, float)) and not isinstance(fps, bool) and 0 < fps <= 1000):
    raise ValueError(f"fps: must be a number in (0, 1000], got {fps!r}")
  out = os.fspath(out)
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  if ext == ".gif":
    from PIL import Image

    imgs = [Image.fromarray(f) for f in frames]
    # GIF frame delays are whole centiseconds (and viewers clamp < 2 cs): round to 10 ms.
    duration = max(20, int(round(1000.0 / fps / 10.0)) * 10)
    imgs[0].save(out, save_all=True, append_images=imgs[1:], duration=duration, loop=0, optimize=False)
    return out
  import imageio.v2 as imageio

  # H.264 in yuv420p needs even dimensions: pad by one edge pixel rather than let
  # imageio resize (which would blur the overlay text).
  h, w = frames.shape[1:3]
  frames = np.pad(frames, ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge")
  with warnings.catch_warnings():
    # imageio-ffmpeg starts ffmpeg with subprocess (fork + exec at once); JAX's
    # generic "os.fork() was called" warning does not apply to that.
    warnings.filterwarnings("ignore", message="os.fork", category=RuntimeWarning)
    with imageio.get_writer(out, format="FFMPEG", mode="I", fps=float(fps), codec="libx264",
                            pixelformat="yuv420p", quality=8, macro_block_size=1) as writer:
      for f in frames:
        writer.append_data(f)
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
  steps, num_envs = _positive_int("steps", steps), _positive_int("num_envs", num_envs)
  width, height = _positive_int("width", width), _positive_int("height", height)
  if out is not None:
    check_out(out)
  _binding(env)
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


# --------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
  ap = argparse.ArgumentParser(
      prog="mjx-damage render",
      description="Render a rollout: damaged links tinted red, health bars for every tracked entity.")
  ap.add_argument("--task", required=True, help="task name (registry tasks, or built-in: drop, push_boxes)")
  ap.add_argument("--policy", required=True, help="scripted:safe | scripted:unsafe | random | zero | checkpoint:PATH")
  ap.add_argument("--out", required=True, help="output video, .mp4 or .gif")
  ap.add_argument("--steps", type=int, default=None, help="control steps (default: the task's episode length)")
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--num-envs", type=int, default=1, help="environments run together; env b>0 → <out>_env<b>")
  ap.add_argument("--width", type=int, default=640)
  ap.add_argument("--height", type=int, default=480)
  ap.add_argument("--camera", default=None, help="'free' (default) or a camera name of the scene")
  ap.add_argument("--fps", type=float, default=None, help="playback rate (default: real time)")
  ap.add_argument("--plots", default=None, metavar="DIR", help="also write rollout plots (PNG, env 0) to DIR")
  ap.add_argument("--training-log", default=None, metavar="PATH",
                  help="a training run's metrics.jsonl (or run dir): its curves go to --plots DIR too")
  return ap


def _checkpoint_task_kwargs(policy_spec: str, task: str) -> dict:
  """Task overrides a checkpoint was trained with (its obs_mode …), so the env matches the policy."""
  from train import checkpoint as ckpt

  path = policy_spec.partition(":")[2]
  file = os.path.join(path, ckpt.FILENAME) if os.path.isdir(path) else path
  try:
    meta = ckpt.read_meta(file)
  except Exception as e:  # not a readable checkpoint
    raise ValueError(f"policy: cannot read checkpoint {file!r} ({e})") from e
  if meta.get("task") not in (None, task):
    raise ValueError(f"policy: checkpoint {path!r} was trained on task {meta['task']!r}, not {task!r}")
  return dict(meta.get("task_kwargs") or {})


def main(argv=None) -> int:
  from train import evaluate as ev

  ap = build_parser()
  args = ap.parse_args(argv)
  try:  # everything the user gave is checked before a task is built or compiled
    ev.check_task(args.task)
    kind, _ = ev.parse_policy_spec(args.policy)
    check_out(args.out)
    for name in ("num_envs", "width", "height"):
      _positive_int(name, getattr(args, name))
    if args.steps is not None:
      _positive_int("steps", args.steps)
    if args.fps is not None and not 0 < args.fps <= 1000:
      raise ValueError(f"fps: must be in (0, 1000], got {args.fps}")
    if args.training_log is not None:
      if args.plots is None:
        raise ValueError("training_log: needs --plots DIR to write the curves to")
      from mjx_damage import plots

      plots.find_training_log(args.training_log)
    task_kwargs = _checkpoint_task_kwargs(args.policy, args.task) if kind == "checkpoint" else {}
    env = ev.make_task(args.task, **task_kwargs)
    policy = ev.make_policy(args.policy, env)
    steps = args.steps or ev.episode_length_of(env, args.task)
    if args.camera not in (None, "free"):
      _camera(mj_model_of(env), None, args.camera, [])
  except ValueError as e:
    ap.error(str(e))
  try:
    ensure_gl()
  except RuntimeError as e:
    print(f"mjx-damage render: {e}", file=sys.stderr)
    return 1
  t0 = time.perf_counter()
  res = render_rollout(env, policy, steps=steps, seed=args.seed, out=args.out, width=args.width,
                       height=args.height, camera=args.camera, fps=args.fps, num_envs=args.num_envs)
  traj = res.trajectory
  final = traj.entity_health[-1]
  for b, path in enumerate(res.paths):
    health = ", ".join(f"{n} {h:.1f}" for n, h in zip(traj.entity_names, final[b]))
    print(f"wrote {path}: {steps} steps ({steps * traj.dt:.2f} s), final health: {health}, "
          f"cost {traj.cost[:, b].sum():.2f}")
  if args.plots:
    from mjx_damage import plots

    title = f"{args.task} / {args.policy} (seed {args.seed})"
    written = list(plots.plot_rollout(traj, args.plots, title=title).values())
    if args.training_log:
      written.append(plots.plot_training_log(args.training_log, os.path.join(args.plots, "training.png")))
    for p in written:
      print(f"wrote {p}")
  print(f"({time.perf_counter() - t0:.1f} s incl. compile)")
  return 0


if __name__ == "__main__":
  sys.exit(main())

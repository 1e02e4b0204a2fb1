"""Writing frames to a video file: MP4 (imageio-ffmpeg, H.264) or GIF (Pillow), by the extension."""

from __future__ import annotations

import os
import warnings

import imageio.v2 as imageio
import numpy as np
from PIL import Image

from mjx_damage.io import atomic_path

OUTPUT_FORMATS = (".mp4", ".gif")


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
  if ext == ".gif":
    imgs = [Image.fromarray(f) for f in frames]
    # GIF frame delays are whole centiseconds (and viewers clamp < 2 cs): round to 10 ms.
    duration = max(20, int(round(1000.0 / fps / 10.0)) * 10)
    with atomic_path(out, ext) as tmp:
      imgs[0].save(tmp, save_all=True, append_images=imgs[1:], duration=duration, loop=0, optimize=False)
    return out
  # H.264 in yuv420p needs even dimensions: pad by one edge pixel rather than let
  # imageio resize (which would blur the overlay text).
  h, w = frames.shape[1:3]
  frames = np.pad(frames, ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge")
  with warnings.catch_warnings():
    # imageio-ffmpeg starts ffmpeg with subprocess (fork + exec at once); JAX's
    # generic "os.fork() was called" warning does not apply to that.
    warnings.filterwarnings("ignore", message="os.fork", category=RuntimeWarning)
    with atomic_path(out, ext) as tmp:
      with imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=float(fps), codec="libx264",
                              pixelformat="yuv420p", quality=8, macro_block_size=1) as writer:
        for f in frames:
          writer.append_data(f)
  return out

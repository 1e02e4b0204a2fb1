"""A private X display for the interactive viewer without a screen: Xvfb, and its framebuffer as an image.

MuJoCo's interactive viewer opens a GLFW window, which needs an X display.
:func:`virtual_display` starts ``Xvfb`` (Debian package ``xvfb``; ``make
install`` installs it where it runs as root) on a free display number with its
screen memory-mapped to a file (``-fbdir``), points ``DISPLAY`` at it, and
stops that one process afterwards. :func:`screenshot` reads that file (X
Window Dump format) into RGB — what the viewer window shows, pixel for pixel,
with no GL read-back.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import shutil
import subprocess
import tempfile
import time
from typing import Iterator, NamedTuple

import numpy as np

XVFB = "Xvfb"
_XWD_HEADER = 25  # CARD32 fields of an XWD file header (X11 XWDFile.h)


class Display(NamedTuple):
  name: str  # ":N"
  fbdir: str  # folder holding Xvfb_screen0
  width: int
  height: int


def xvfb_path() -> str | None:
  """Path of the Xvfb binary, or None when it is not installed."""
  return shutil.which(XVFB) or (f"/usr/bin/{XVFB}" if os.path.exists(f"/usr/bin/{XVFB}") else None)


def _free_display() -> int:
  for n in range(90, 400):
    if not os.path.exists(f"/tmp/.X{n}-lock") and not os.path.exists(f"/tmp/.X11-unix/X{n}"):
      return n
  raise RuntimeError("no free X display number in :90..:399")


# GLFW connects to one display per process, when it is first initialised, and keeps that
# connection until interpreter exit (terminating and re-initialising it under a viewer whose
# thread is still alive aborts the process). So a process gets ONE private screen: started by
# the first virtual_display, reused by later ones, stopped at exit after GLFW let it go.
_screen: list = []  # [(Display, Popen)] once started


def _stop(proc: subprocess.Popen, fbdir: str) -> None:
  proc.terminate()
  try:
    proc.wait(timeout=5)
  except subprocess.TimeoutExpired:
    proc.kill()
    proc.wait()
  shutil.rmtree(fbdir, ignore_errors=True)


def _start(width: int, height: int) -> Display:
  exe = xvfb_path()
  if exe is None:
    raise RuntimeError("the viewer without a screen needs Xvfb (apt-get install xvfb; `make install` does "
                       "this as root)")
  fbdir = tempfile.mkdtemp(prefix="mjx-damage-xvfb-")
  n = _free_display()
  # -terminate: the server also goes when its last client does (a process killed before its exit
  # handlers run leaves no Xvfb behind once GLFW's connection has closed)
  proc = subprocess.Popen([exe, f":{n}", "-screen", "0", f"{width}x{height}x24", "-fbdir", fbdir, "-nolisten",
                           "tcp", "-terminate"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
  deadline = time.monotonic() + 10.0
  while not os.path.exists(f"/tmp/.X11-unix/X{n}") or not os.path.exists(os.path.join(fbdir, "Xvfb_screen0")):
    if proc.poll() is not None or time.monotonic() > deadline:
      _stop(proc, fbdir)
      raise RuntimeError(f"Xvfb :{n} did not start (exit status {proc.poll()})")
    time.sleep(0.05)
  # registered before GLFW registers its own glfw.terminate (at the first viewer): exit handlers
  # run last-in first-out, so GLFW closes its connection before the server stops
  atexit.register(_stop, proc, fbdir)
  display = Display(f":{n}", fbdir, width, height)
  _screen.append((display, proc))
  return display


@contextlib.contextmanager
def virtual_display(width: int = 1280, height: int = 800) -> Iterator[Display]:
  """Run the block with ``DISPLAY`` set to this process's private Xvfb screen (24-bit), started on
  first use with ``width`` × ``height`` and stopped at interpreter exit."""
  if _screen:
    display = _screen[0][0]
    if (display.width, display.height) != (width, height):
      raise ValueError(f"virtual_display: this process's screen is {display.width}x{display.height}, "
                       f"got {width}x{height} (one screen per process)")
  else:
    display = _start(width, height)
  old = os.environ.get("DISPLAY")
  os.environ["DISPLAY"] = display.name
  try:
    yield display
  finally:
    if old is None:
      os.environ.pop("DISPLAY", None)
    else:
      os.environ["DISPLAY"] = old


def read_xwd(raw: bytes) -> np.ndarray:
  """uint8[H, W, 3] RGB of an X Window Dump (TrueColor, 24/32 bits per pixel, as Xvfb writes)."""
  head = np.frombuffer(raw[: 4 * _XWD_HEADER], ">u4")
  header_size, version = int(head[0]), int(head[1])
  if version != 7:
    raise ValueError(f"screenshot: not an XWD version 7 file (version {version})")
  width, height = int(head[4]), int(head[5])
  byte_order, bpp, line = int(head[7]), int(head[11]), int(head[12])
  masks = [int(m) for m in head[14:17]]
  ncolors = int(head[19])
  if bpp not in (24, 32):
    raise ValueError(f"screenshot: {bpp} bits per pixel not supported (24-bit Xvfb screens only)")
  start = header_size + 12 * ncolors
  rows = np.frombuffer(raw[start : start + line * height], np.uint8).reshape(height, line)
  px = rows[:, : width * bpp // 8].reshape(height, width, bpp // 8).astype(np.uint32)
  order = range(bpp // 8) if byte_order == 0 else reversed(range(bpp // 8))  # 0: LSB first
  value = sum(px[..., i] << (8 * k) for k, i in enumerate(order))
  out = np.empty((height, width, 3), np.uint8)
  for c, m in enumerate(masks):
    shift = (m & -m).bit_length() - 1
    out[..., c] = ((value & m) >> shift).astype(np.uint8)
  return out


def screenshot(display: Display, settle_s: float = 0.0) -> np.ndarray:
  """uint8[H, W, 3]: the whole screen of ``display``. With ``settle_s`` > 0, the first screen
  that equals the one 0.25 s before (the last frame asked for is drawn: a software renderer on a
  busy CPU can take longer than a fixed wait), or the last one read after ``settle_s``."""

  def read():
    with open(os.path.join(display.fbdir, "Xvfb_screen0"), "rb") as f:
      return read_xwd(f.read())

  img = read()
  deadline = time.monotonic() + settle_s
  while time.monotonic() < deadline:
    time.sleep(0.25)
    nxt = read()
    if np.array_equal(nxt, img):
      break
    img = nxt
  return img

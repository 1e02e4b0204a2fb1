"""What a rendered frame adds to the scene: damaged links tinted red, one labelled health bar per entity.

Pure numpy/Pillow functions of a frame and health values (no simulator, no GL).
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from mjx_damage.health import MAX_HEALTH

TINT_RGB = np.array([0.9, 0.05, 0.05], np.float32)  # colour of a destroyed link


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
  try:
    return ImageFont.load_default(size=size)  # scalable (FreeType) default font, Pillow >= 10.1
  except (TypeError, OSError):
    return ImageFont.load_default()


HEALTH_HEADER = "health (0-100)"  # ASCII hyphen: the default font has no en dash


def _as_lines(caption) -> list:
  if not caption:
    return []
  return [caption] if isinstance(caption, str) else [str(c) for c in caption]


def bar_layout(height: int, width: int, names: Sequence[str], readouts=None, headers=()):
  """Font, sizes, each entity's bar box (x0, y0, x1, y1), readout column x's and the panel box.

  Row 0 is the header (``health (0-100)`` over the bars, ``headers`` over the
  readout columns); entity i is row i + 1.
  """
  row = max(9, height // 22)
  font = _font(max(7, row - 2))
  pad = max(2, row // 4)
  measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
  name_w = max([measure.textlength(n, font=font) for n in names] + [0.0])
  val_w = measure.textlength("100", font=font)
  bar_w = max(20, min(int(width * 0.3), width - int(name_w + val_w) - 6 * pad))
  x0 = int(2 * pad + name_w)
  boxes = [(x0, pad + (i + 1) * row + 2, x0 + bar_w, pad + (i + 2) * row - 2) for i in range(len(names))]
  cols, x = [], x0 + bar_w + pad + val_w + 2 * pad
  n_cols = len(headers) if headers else (len(readouts[0]) if readouts is not None and len(readouts) else 0)
  for c in range(n_cols):
    texts = [headers[c] if headers else ""] + [r[c] for r in (readouts or [])]
    cols.append(int(x))
    x += max(measure.textlength(t, font=font) for t in texts) + 2 * pad
  header_w = x0 + measure.textlength(HEALTH_HEADER, font=font)
  right = max(x - pad, header_w, name_w + bar_w + val_w + 5 * pad)
  panel = (0, 0, int(right), (len(names) + 1) * row + 2 * pad)
  return font, row, pad, boxes, cols, panel


def health_bar_boxes(height: int, width: int, names: Sequence[str]) -> list:
  """Pixel box (x0, y0, x1, y1), inclusive, of each entity's bar in a ``height`` × ``width`` frame.

  Bars are drawn opaque, so these pixels depend on health alone (tests and
  figure scripts read them). Readout columns go right of the bars, so they do
  not move them.
  """
  return bar_layout(height, width, names)[3]


def caption_box(height: int, width: int, names: Sequence[str], caption) -> tuple:
  """Pixel box (x0, y0, x1, y1) of the caption panel bottom-left (empty caption: a zero-height box)."""
  font, row, pad, _, _, _ = bar_layout(height, width, names)
  lines = _as_lines(caption)
  measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
  tw = max([measure.textlength(t, font=font) for t in lines] + [0.0])
  return 0, height - len(lines) * row - 2 * pad, int(tw + 2 * pad), height


def draw_health_bars(frame: np.ndarray, names: Sequence[str], health: Sequence[float],
                     caption=None, readouts: Optional[Sequence[Sequence[str]]] = None,
                     headers: Sequence[str] = ()) -> np.ndarray:
  """``frame`` (uint8[H, W, 3]) with one labelled health bar per entity drawn top-left.

  A header row names the bars' quantity (:data:`HEALTH_HEADER`) and each readout
  column (``headers``, e.g. "max °C", "wet (particles)"); then every entity gets a
  row — name, a bar filled to h/100 in :func:`health_color`, the value, its
  ``readouts[i]`` strings — on a translucent panel, so entities out of the
  camera's view are shown too. ``caption`` (a string or lines: time, episode
  damage …) goes bottom-left. Sizes scale with the frame height. Returns a new
  array; ``frame`` is not modified.
  """
  H, W = frame.shape[:2]
  font, row, pad, boxes, cols, panel = bar_layout(H, W, names, readouts, headers)
  img = Image.fromarray(np.ascontiguousarray(frame[..., :3])).convert("RGBA")
  layer = Image.new("RGBA", img.size, (0, 0, 0, 0))
  draw = ImageDraw.Draw(layer)
  white, grey = (255, 255, 255, 255), (200, 200, 200, 255)
  draw.rectangle(panel, fill=(0, 0, 0, 150))
  if boxes:
    draw.text((boxes[0][0], pad - 2), HEALTH_HEADER, font=font, fill=grey)
  for c, x in enumerate(cols):
    if c < len(headers):
      draw.text((x, pad - 2), headers[c], font=font, fill=grey)
  for i, (name, h, (x0, y0, x1, y1)) in enumerate(zip(names, health, boxes)):
    h = float(np.clip(h, 0.0, MAX_HEALTH))
    ty = y0 - 2
    draw.text((pad, ty), name, font=font, fill=white)
    draw.rectangle([x0, y0, x1, y1], fill=(70, 70, 70, 255))
    fill = int(round((x1 - x0) * h / MAX_HEALTH))
    if fill > 0:
      draw.rectangle([x0, y0, x0 + fill, y1], fill=health_color(h) + (255,))
    draw.text((x1 + pad, ty), f"{h:.0f}", font=font, fill=white)
    for x, text in zip(cols, readouts[i] if readouts is not None else ()):
      draw.text((x, ty), text, font=font, fill=white)
  lines = _as_lines(caption)
  if lines:
    x0, y0, x1, y1 = caption_box(H, W, names, lines)
    draw.rectangle([x0, y0, x1, y1], fill=(0, 0, 0, 150))
    for k, text in enumerate(lines):
      draw.text((pad, y0 + pad + k * row), text, font=font, fill=white)
  return np.asarray(Image.alpha_composite(img, layer).convert("RGB"))

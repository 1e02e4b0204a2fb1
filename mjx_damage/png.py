"""PNG files of figures, written small: an 8-bit palette instead of matplotlib's RGBA.

Every training run's curves are committed under benchmarks/results and the whole repository travels to the GPU
machine, so a figure's bytes count; a line plot has few colours besides its antialiasing, and 256 look the same
at about a third of the bytes. No JAX here: light scripts (compare_runs, the figure of a results table) use it.
"""

from __future__ import annotations

import io

from PIL import Image  # matplotlib's own dependency

from mjx_damage.io import atomic_path


def write_palette_png(src, dst) -> None:
  """Re-encodes the PNG ``src`` (a path or file object) as an 8-bit palette PNG at ``dst``; transparent pixels are
  laid on white first."""
  with Image.open(src) as im:
    rgba = im.convert("RGBA")
  rgb = Image.alpha_composite(Image.new("RGBA", rgba.size, "white"), rgba).convert("RGB")
  rgb.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(dst, format="PNG", optimize=True)


def save_png(fig, path: str, *, dpi: int) -> str:
  """Writes the matplotlib figure ``fig`` to ``path`` as a palette PNG (:func:`write_palette_png`), atomically."""
  buf = io.BytesIO()
  fig.savefig(buf, dpi=dpi, format="png")
  buf.seek(0)
  with atomic_path(path, ".png") as tmp:
    write_palette_png(buf, tmp)
  return path

"""Figures written as palette PNGs (mjx_damage.png): same picture, fewer bytes, opaque on white."""

import io
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

from mjx_damage.png import save_png, write_palette_png  # noqa: E402


def _figure():
  fig, ax = plt.subplots(figsize=(4.0, 3.0))
  x = np.linspace(0, 1, 50)
  for k, c in enumerate(("tab:blue", "tab:orange", "tab:green")):
    ax.plot(x, np.sin(6 * x + k), color=c, label=f"seed {k}")
  ax.legend()
  ax.grid(alpha=0.3)
  return fig


def test_save_png_is_the_same_picture_in_a_palette(tmp_path):
  fig = _figure()
  rgba = io.BytesIO()
  fig.savefig(rgba, dpi=80, format="png")
  path = save_png(fig, str(tmp_path / "curves.png"), dpi=80)
  plt.close(fig)
  assert os.listdir(tmp_path) == ["curves.png"]  # the temporary file renamed into place, none left
  with Image.open(path) as im:
    assert im.mode == "P"
    got = np.asarray(im.convert("RGB"), dtype=int)
  want = np.asarray(Image.open(rgba).convert("RGB"), dtype=int)
  assert got.shape == want.shape
  err = np.abs(got - want)
  assert err.mean() < 1.0 and np.percentile(err, 99.9) <= 16, (err.mean(), err.max())
  assert os.path.getsize(path) < 0.6 * rgba.getbuffer().nbytes


def test_transparent_pixels_are_laid_on_white(tmp_path):
  src = Image.new("RGBA", (8, 4), (0, 0, 0, 0))
  src.paste((200, 30, 30, 255), (0, 0, 4, 4))
  src.save(tmp_path / "a.png")
  write_palette_png(str(tmp_path / "a.png"), str(tmp_path / "b.png"))
  got = np.asarray(Image.open(tmp_path / "b.png").convert("RGB"))
  assert (got[:, :4] == (200, 30, 30)).all() and (got[:, 4:] == 255).all()

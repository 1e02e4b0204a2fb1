"""What the viewer shows about damage each step: tint, the health panel, the scene's heat and water.

The drawing is :mod:`mjx_damage.overlay`'s (tint, labelled health bars) and
:mod:`mjx_damage.render`'s (heat-source glow, liquid spheres), the same as in
rendered videos; this module picks the numbers from the env state and lays
them out for MuJoCo's interactive viewer (an RGB panel through
``Handle.set_images``, geom colours through the shared ``MjModel``, particles
through ``Handle.user_scn``).

Feedback (the damage shown to an operator) is the tint and the panel; the
glow of a heat source and the water are the scene itself and are drawn with
feedback off too (``--no-feedback``, the paper's second condition).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import mujoco
import numpy as np

from mjx_damage import overlay, render
from mjx_damage import temperature as T
from mjx_damage.trajectory import MODELS

PANEL_ROW = 18  # px per panel row: the overlay's row height is frame height / 22
PANEL_WIDTH = 600  # px


class Scene(NamedTuple):
  """Static facts of one scene the feedback needs (from the binding and the model)."""

  entity_names: tuple
  geom_link: np.ndarray  # i32[ngeom]
  link_entity: np.ndarray  # i32[L]
  base_rgba: np.ndarray  # f32[ngeom, 4] colours to tint from (materials' colours for tracked geoms)
  source_geom: np.ndarray | None  # i32[S] heat-source geoms, or None
  source_names: tuple
  ambient: float
  particle_radius: float | None  # m, or None without liquid
  window: int  # control steps in the last second


def scene(binding, model: mujoco.MjModel, dt: float, feedback: bool) -> Scene:
  """:class:`Scene` of ``model``; with ``feedback`` the tracked geoms lose their materials (a
  material's colour and texture would hide the tint), as :func:`mjx_damage.render.render_frames` does."""
  geom_link = np.asarray(binding.geom_link)
  base = np.array(model.geom_rgba, np.float32)
  has_mat = (model.geom_matid >= 0) & (geom_link >= 0)
  base[has_mat] = model.mat_rgba[model.geom_matid[has_mat]]
  if feedback:
    model.geom_matid[has_mat] = -1
  tm, lm = binding.thermal, binding.liquid
  return Scene(entity_names=tuple(binding.entity_names), geom_link=geom_link,
               link_entity=np.asarray(binding.link_entity), base_rgba=base,
               source_geom=None if tm is None or tm.num_sources == 0 else np.asarray(tm.source_geom),
               source_names=() if tm is None else tuple(tm.source_names),
               ambient=T.AMBIENT if tm is None else float(tm.ambient),
               particle_radius=None if lm is None else float(lm.radius), window=max(1, round(1.0 / dt)))


class Frame(NamedTuple):
  """The numbers of one step, on the host."""

  link_health: np.ndarray  # f32[L]
  entity_health: np.ndarray  # f32[N]
  temperature: np.ndarray  # f32[L] °C
  exposure: np.ndarray  # f32[L] particles
  sources: np.ndarray | None  # f32[S] °C
  particles: np.ndarray | None  # f32[P, 3] m
  damage: np.ndarray  # f32[3] this step, health points, MODELS order
  episode_cost: float  # health points since reset
  time: float  # s since reset


def frame(state, ambient: float) -> Frame:
  """:class:`Frame` of an env state (a damage-wrapped env's ``State``), fetched in one transfer."""
  info = state.info
  ds = info["damage_state"]
  th, lq = ds.thermal, ds.liquid
  h = jax.device_get({
      "link": info["link_health"], "entity": info["entity_health"], "temp": ds.temperature, "wet": ds.exposure,
      "on": None if th is None else th.source_on, "src": None if th is None else th.source_temperature,
      "pos": None if lq is None else lq.pos, "damage": [info["damage"][m] for m in MODELS],
      "cost": info["damage_episode"]["cost"], "t": state.pipeline_state.time - info["damage_t0"]})
  sources = None if th is None else ambient + h["on"] * (h["src"] - ambient)
  return Frame(link_health=h["link"], entity_health=h["entity"], temperature=h["temp"], exposure=h["wet"],
               sources=sources, particles=h["pos"], damage=np.asarray(h["damage"], np.float32),
               episode_cost=float(h["cost"]), time=float(h["t"]))


def colours(sc: Scene, fr: Frame, feedback: bool) -> np.ndarray:
  """f32[ngeom, 4] geom colours: tracked links tinted by health (feedback), heat sources glowing."""
  rgba = overlay.tinted_rgba(sc.base_rgba, sc.geom_link, fr.link_health) if feedback else sc.base_rgba
  if sc.source_geom is not None and fr.sources is not None:
    rgba = render.glow_rgba(rgba, sc.source_geom, fr.sources, sc.ambient)
  return rgba


def _per_entity(values: np.ndarray, link_entity: np.ndarray, n: int, reduce) -> list:
  return [float(reduce(values[link_entity == i])) if np.any(link_entity == i) else float("nan") for i in range(n)]


def panel(sc: Scene, fr: Frame, recent: np.ndarray, status=(), feedback: bool = True) -> np.ndarray:
  """uint8[h, PANEL_WIDTH, 3], the viewer's one overlay: with ``feedback``, a health bar, the value
  and readouts per entity, the episode cost, the damage per model of the last second (``recent``
  f32[3], health points) and the heat sources; then the ``status`` lines (mode, speed, recording).
  Without ``feedback`` only the status lines."""
  n = len(sc.entity_names) if feedback else 0
  names, health = (sc.entity_names, fr.entity_health) if feedback else ((), ())
  headers, columns = [], []
  if feedback and sc.source_geom is not None:
    headers.append("max °C")
    columns.append([f"{x:.0f}" for x in _per_entity(fr.temperature, sc.link_entity, n, np.max)])
  if feedback and sc.particle_radius is not None:
    headers.append("wet (particles)")
    columns.append([f"{x:.0f}" for x in _per_entity(fr.exposure, sc.link_entity, n, np.sum)])
  readouts = [tuple(c[i] for c in columns) for i in range(n)] if columns else None
  caption = []
  if feedback:
    caption = [f"t {fr.time:5.2f} s   episode damage {fr.episode_cost:.1f} hp",
               "last 1 s: " + ", ".join(f"{m} {v:.1f}" for m, v in zip(MODELS, recent)) + " hp"]
    if fr.sources is not None and len(sc.source_names):
      caption.append("heat source: " + ", ".join(f"{s} {t:.0f} °C" for s, t in zip(sc.source_names, fr.sources)))
  caption += list(status)
  H = 22 * PANEL_ROW
  img = overlay.draw_health_bars(np.zeros((H, PANEL_WIDTH, 3), np.uint8), names, health, caption, readouts, headers)
  top = overlay.bar_layout(H, PANEL_WIDTH, names, readouts, headers)[5][3] if feedback else 0
  cap = overlay.caption_box(H, PANEL_WIDTH, names, caption)[1]
  return np.ascontiguousarray(np.concatenate([img[:top], img[cap:]]))  # drop the empty rows between


def panel_bar_boxes(sc: Scene) -> list:
  """Each entity's bar box (x0, y0, x1, y1) inside :func:`panel`'s image (bars sit in the kept top rows)."""
  return overlay.health_bar_boxes(22 * PANEL_ROW, PANEL_WIDTH, sc.entity_names)


def add_particles(scn: mujoco.MjvScene, sc: Scene, fr: Frame) -> None:
  """Replace the user scene's geoms with the liquid's particles (blue spheres)."""
  scn.ngeom = 0
  if fr.particles is not None:
    render.add_spheres(scn, fr.particles, sc.particle_radius)

"""What a throughput run writes: the summary ratios, the markdown report, the PNG, and the files."""

from __future__ import annotations

import json
import os

from mjx_damage.io import write_json, write_text
from mjx_damage.png import save_png


def save(result: dict, out: str) -> None:
  """Write JSON, markdown and PNG for ``result`` (called after every point: a run
  killed midway, e.g. by a hung device call, still leaves what it measured)."""
  base = os.path.splitext(out)[0]
  write_json(out, result, indent=1)
  write_text(base + ".md", report_md(result))
  plot(result, base + ".png")


def _lookup(rows, **kw):
  for r in rows:
    if all(r.get(k) == v for k, v in kw.items()):
      return r
  return None


def summarize(result: dict, k_main: int, target_n: int, fixed: int) -> dict:
  """Ratios the project reports against its targets (computed from this run's rows only)."""
  rows = result["vs_envs"] + result["vs_entities"]
  s = {}
  trk = result.get("vs_tracked", [])
  lo = min((r["entities"] for r in trk), default=None)
  for dmg in (True, False):
    a = _lookup(trk, entities=lo, envs=fixed, damage=dmg)
    b = _lookup(trk, entities=k_main, envs=fixed, damage=dmg)
    if a and b and lo != k_main:
      s[f"tracked_{k_main}_over_{lo}_in_{k_main}_box_scene_damage_{'on' if dmg else 'off'}_{fixed}envs"] = (
          b["env_steps_per_s"] / a["env_steps_per_s"])
  mnt = result.get("vs_mounted", [])
  top = max((r["entities"] for r in mnt), default=None)
  for dmg in (True, False):
    a = _lookup(mnt, entities=1, envs=fixed, damage=dmg)
    b = _lookup(mnt, entities=top, envs=fixed, damage=dmg)
    if a and b and top != 1:
      s[f"entities_{top}_over_1_mounted_throughput_damage_{'on' if dmg else 'off'}_{fixed}envs"] = (
          b["env_steps_per_s"] / a["env_steps_per_s"])
  on = _lookup(rows, entities=k_main, envs=target_n, damage=True)
  off = _lookup(rows, entities=k_main, envs=target_n, damage=False)
  if on and off:
    s[f"damage_on_off_ratio_K{k_main}_{target_n}envs"] = on["env_steps_per_s"] / off["env_steps_per_s"]
  one = _lookup(rows, entities=1, envs=fixed, damage=True)
  many = _lookup(rows, entities=k_main, envs=fixed, damage=True)
  if one and many:
    s[f"entities_{k_main}_over_1_throughput_damage_on_{fixed}envs"] = many["env_steps_per_s"] / one["env_steps_per_s"]
  one_off = _lookup(rows, entities=1, envs=fixed, damage=False)
  many_off = _lookup(rows, entities=k_main, envs=fixed, damage=False)
  if one_off and many_off:
    s[f"entities_{k_main}_over_1_throughput_damage_off_{fixed}envs"] = (
        many_off["env_steps_per_s"] / one_off["env_steps_per_s"])
  # damage-tracking overhead per K (on/off at the same K and batch): separates what
  # tracking costs from what simulating K free bodies costs
  s["damage_on_off_ratio_by_entities"] = {
      str(r["entities"]): r["env_steps_per_s"] / off_r["env_steps_per_s"]
      for r in result["vs_entities"] if r["damage"]
      for off_r in [_lookup(result["vs_entities"], entities=r["entities"], envs=r["envs"], damage=False)] if off_r
  }
  s["damage_on_off_ratio_by_envs"] = {
      str(r["envs"]): r["env_steps_per_s"] / off_r["env_steps_per_s"]
      for r in result["vs_envs"] if r["damage"]
      for off_r in [_lookup(result["vs_envs"], entities=r["entities"], envs=r["envs"], damage=False)] if off_r
  }
  for k, ref in result.get("reference", {}).items():
    best = max((r for r in rows if r["entities"] == int(k) and r["damage"]),
               key=lambda r: r["env_steps_per_s"], default=None)
    if best:
      s[f"speedup_over_reference_K{k}"] = {
          "mjx_env_steps_per_s": best["env_steps_per_s"],
          "mjx_envs": best["envs"],
          "reference_env_steps_per_s": ref["reference_damage"]["env_steps_per_s"],
          "ratio_vs_reference_damage": best["env_steps_per_s"] / ref["reference_damage"]["env_steps_per_s"],
          "ratio_vs_native_no_damage_1thread": best["env_steps_per_s"] / ref["native_no_damage"]["env_steps_per_s"],
          "ratio_vs_rollout_no_damage": best["env_steps_per_s"] / ref["rollout_no_damage"]["env_steps_per_s"],
      }
  if "task" in result:
    s["task_physics_steps_per_s"] = result["task"]["physics_steps_per_s"]
  return s


def report_md(result: dict) -> str:
  """Markdown report of a run: tables of every point, the summary, and what the numbers mean."""
  lines = [f"# Throughput: {result['device']} ({result['platform']}, {result['num_devices']} device(s))", "",
           f"Command: `{result['command']}`  ", f"Date: {result['date']}; total {result.get('total_s', 0):.0f} s", ""]
  lines += [f"- note: {n}" for n in result.get("notes", [])]
  lines += ["", f"One env step = {result['n_substeps']} physics steps of {result['timestep_s'] * 1e3:g} ms. "
            "Scene: " + result["scene"] + ".", ""]
  for section, title in (("vs_envs", "Versus environments"),
                         ("vs_entities", "Versus tracked entities: K boxes in the scene, all tracked"),
                         ("vs_tracked", "Versus tracked entities: a fixed scene, n of its boxes tracked"),
                         ("vs_mounted", "Versus tracked entities: the scene grows by mounted boxes (1 free box + K-1 "
                                        "mounted, all tracked)")):
    if not result.get(section):
      continue
    lines += [f"## {title}", "", "| tracked | boxes in scene | free boxes | envs | damage | env steps/s | physics steps/s |"
              " compile s | peak host RSS GB | load avg |", "|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|"]
    for r in sorted(result[section], key=lambda r: (r["entities"], r["envs"], not r["damage"])):
      boxes = r.get("boxes", r["entities"])
      lines.append(f"| {r['entities']} | {boxes} | {r.get('free_boxes', boxes)} | {r['envs']} | {'on' if r['damage'] else 'off'} | {r['env_steps_per_s']:,.0f} |"
                   f" {r['physics_steps_per_s']:,.0f} | {r['compile_s']:.1f} | {r['host_maxrss_bytes'] / 2**30:.2f} |"
                   f" {r.get('loadavg_1min', float('nan')):.1f} |")
    lines.append("")
  if "reference" in result:
    lines += ["## Reference-style and native MuJoCo (same scene, same control)", "",
              "| K | pipeline | envs run | env steps/s | physics steps/s |", "|---:|---|---:|---:|---:|"]
    for k, ref in result["reference"].items():
      for name, r in ref.items():
        lines.append(f"| {k} | {name} | {r['envs']} | {r['env_steps_per_s']:,.1f} | {r['physics_steps_per_s']:,.0f} |")
    lines.append("")
  if "task" in result:
    t = result["task"]
    robot = f", robot {t['robot']}" if "robot" in t else ""  # rows before --robot name none (the gripper)
    lines += [f"Task `{t['task']}` ({t.get('backend', 'mjx')} backend{robot}, {t['envs']} envs, {t['n_substeps']} substeps): "
              f"{t['physics_steps_per_s']:,.0f} physics steps/s, {t['env_steps_per_s']:,.0f} env steps/s.", ""]
  lines += ["## Summary", "", "```json", json.dumps(result["summary"], indent=1), "```", ""]
  reading = []
  for key, sp in result["summary"].items():
    if key.startswith("speedup_over_reference_K"):
      k = key.rsplit("K", 1)[1]
      reading.append(
          f"- K={k}: MJX damage-aware at {sp['mjx_envs']} envs = {sp['ratio_vs_reference_damage']:.1f}x the "
          f"reference-style pipeline (native MuJoCo + Python evaluators, 1 env at a time), "
          f"{sp['ratio_vs_native_no_damage_1thread']:.2f}x native MuJoCo without damage (1 thread), "
          f"{sp['ratio_vs_rollout_no_damage']:.2f}x mujoco.rollout without damage "
          f"({result['reference'][k]['rollout_no_damage']['threads']} threads).")
  summ = result["summary"]
  grow = [(k, v) for k, v in summ.items()
          if k.startswith("entities_") and "_damage_on_" in k and "_mounted_" not in k]
  fixed = [(k, v) for k, v in summ.items() if k.startswith("tracked_") and "_damage_on_" in k]
  if grow and fixed:
    off = [v for k, v in summ.items()
           if k.startswith("entities_") and "_damage_off_" in k and "_mounted_" not in k]
    reading.append(
        f"- Tracked entities: in one fixed scene, tracking all its boxes instead of one keeps {fixed[0][1]:.0%} of "
        f"the throughput — what damage tracking itself costs. Growing the scene with the tracked boxes keeps "
        f"{grow[0][1]:.1%} (damage off: {off[0] if off else float('nan'):.1%}): that is the physics of more free "
        "bodies, not the damage. Each free box adds 6 dofs and 5 contacts to a scene whose fixed part is a 2-dof "
        "pusher, and MJX's JAX implementation makes every step's constraint work grow faster than K (a dense "
        "constraint Jacobian, nefc x nv, both growing with K). `benchmarks/entity_scaling.py` breaks the step "
        "down by stage; `benchmarks/warp_scaling.py` times the same scenes' raw physics on MuJoCo Warp.")
  mnt = [(k, v) for k, v in summ.items() if k.startswith("entities_") and "_mounted_" in k]
  if mnt:
    on = [v for k, v in mnt if "_damage_on_" in k]
    off = [v for k, v in mnt if "_damage_off_" in k]
    reading.append(
        f"- Mounted entities: growing the scene by damageable boxes mounted on the table (1 free box + K-1 mounted, "
        f"all tracked) keeps {on[0] if on else float('nan'):.0%} of the 1-entity throughput at the largest K "
        f"(damage off: {off[0] if off else float('nan'):.0%}). A tracked entity that adds no degrees of freedom "
        "costs its one designed contact pair (pusher-box) and its damage evaluation: model fixtures the task never "
        "moves (stoves, shelves, wall units) as mounted bodies and keep free joints for what must move.")
  if reading:
    lines += ["## Reading the numbers", ""] + reading + [""]
    if result["platform"] == "cpu":
      native = {k: sp["ratio_vs_native_no_damage_1thread"] for k, sp in result["summary"].items()
                if k.startswith("speedup_over_reference_K")}
      lines += [f"On this CPU the batched MJX (JAX) step reaches {min(native.values()):.2f}-{max(native.values()):.2f}x "
                "the throughput of native MuJoCo stepping one environment on one thread, even at its best batch: "
                "for CPU work choose native MuJoCo (`--backend native` on eval, sweep, render and bench: MuJoCo on C "
                "threads feeding the same damage functions) and keep MJX for accelerators. The reference-style "
                "per-entity Python evaluators are the slow path on any device.", ""]
  if result.get("skipped"):
    lines += ["Skipped: " + "; ".join(json.dumps(s) for s in result["skipped"]), ""]
  return "\n".join(lines)


def plot(result: dict, path: str) -> None:
  """Panels: env-steps/s vs envs (a line per K × damage); vs tracked entities as the scene grows and,
  when measured, in a fixed scene (damage on vs off)."""
  import matplotlib  # loaded only when a plot is drawn: keeps `--help` fast

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  trk = result.get("vs_tracked", [])
  fig, axes = plt.subplots(1, 3 if trk else 2, figsize=(18 if trk else 12, 4.5))
  a, b = axes[0], axes[1]
  settings = sorted({(r["entities"], r["damage"]) for r in result["vs_envs"]})
  for k, dmg in settings:
    rows = sorted((r for r in result["vs_envs"] if r["entities"] == k and r["damage"] == dmg), key=lambda r: r["envs"])
    a.plot([r["envs"] for r in rows], [r["env_steps_per_s"] for r in rows], "o-" if dmg else "s--",
           label=f"K={k} tracked, damage {'on' if dmg else 'off'}")
  for k, ref in result.get("reference", {}).items():
    a.axhline(ref["reference_damage"]["env_steps_per_s"], ls=":", color="gray")
    a.annotate(f"reference-style K={k}", (0.02, ref["reference_damage"]["env_steps_per_s"]),
               xycoords=("axes fraction", "data"), fontsize=8, color="gray", va="bottom")
  a.set(xscale="log", yscale="log", xlabel="parallel environments", ylabel="env steps / s",
        title=f"{result['device']}: throughput vs batch")
  if a.get_legend_handles_labels()[0]:
    a.legend(fontsize=8)
  for section, what in (("vs_entities", "all boxes free"), ("vs_mounted", "1 free + K-1 mounted")):
    for dmg in (True, False):
      rows = sorted((r for r in result.get(section, []) if r["damage"] == dmg), key=lambda r: r["entities"])
      if rows:
        b.plot([r["entities"] for r in rows], [r["env_steps_per_s"] for r in rows],
               ("o-" if dmg else "s--") if section == "vs_entities" else ("^-" if dmg else "v--"),
               label=f"{what}, damage {'on' if dmg else 'off'} ({rows[0]['envs']} envs)")
  b.set(xscale="log", yscale="log", xlabel="tracked entities = boxes in the scene", ylabel="env steps / s",
        title="throughput vs tracked entities (scene grows)")
  if b.get_legend_handles_labels()[0]:
    b.legend(fontsize=8)
  if trk:
    c = axes[2]
    for dmg in (True, False):
      rows = sorted((r for r in trk if r["damage"] == dmg), key=lambda r: r["entities"])
      c.plot([r["entities"] for r in rows], [r["env_steps_per_s"] for r in rows], "o-" if dmg else "s--",
             label=f"damage {'on' if dmg else 'off'} ({rows[0]['envs']} envs)")
    c.set(xscale="log", yscale="log", xlabel=f"tracked entities of {trk[0].get('boxes')} boxes in the scene",
          ylabel="env steps / s", title="throughput vs tracked entities (fixed scene)")
    c.set_ylim(min(r["env_steps_per_s"] for r in trk) / 3, max(r["env_steps_per_s"] for r in trk) * 3)
    c.legend(fontsize=8)
  fig.tight_layout()
  save_png(fig, path, dpi=120)
  plt.close(fig)

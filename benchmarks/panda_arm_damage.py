"""Which tasks damage the Panda's *arm* (links 0–7, not the hand or fingers) under the unsafe shortcut.

    .venv/bin/python benchmarks/panda_arm_damage.py                       # every task the Panda runs
    .venv/bin/python benchmarks/panda_arm_damage.py --tasks shelve_item open_drawer --episodes 8

For each task: ``--episodes`` randomised episodes of the scripted safe policy and as many of the
unsafe one in one compiled rollout (:func:`mjx_damage.trajectory.rollout`: env b runs policy b % 2
from its own reset); then, per policy, the share of episodes in
which any arm link ends below ``--threshold`` health (default 99.5: a health point lost somewhere on
the arm), the arm link that ends lowest on average, and the same share for the hand and fingers.
The agent entity holds every link, so the entity's health alone cannot say where the robot was hit.

Writes ``benchmarks/results/panda_arm_damage_<device>.{json,md}`` (or ``--out STEM``), rewritten
after every task, each row with its command.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
  sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

import jax  # noqa: E402

import tasks  # noqa: E402
from apps.resolve import episode_length_of  # noqa: E402
from mjx_damage import runtime  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from mjx_damage.trajectory import positive_int, rollout  # noqa: E402
from train.cliargs import Parser  # noqa: E402

ROBOT = "panda"
STYLES = ("safe", "unsafe")


def build_parser() -> Parser:
  ap = Parser(prog="panda_arm_damage.py", description=__doc__.splitlines()[0])
  ap.add_argument("--tasks", nargs="+", default=None, metavar="TASK",
                  help="tasks (default: every task the Panda runs, tasks.robots_for)")
  ap.add_argument("--episodes", type=int, default=16, help="episodes per policy")
  ap.add_argument("--seed", type=int, default=0)
  ap.add_argument("--threshold", type=float, default=99.5, help="a link below this final health counts as damaged")
  ap.add_argument("--out", default=None, help="results stem (default benchmarks/results/panda_arm_damage_<device>)")
  return ap


def check_args(args) -> list:
  """The tasks, in order; ``ValueError`` naming the field (before anything compiles)."""
  chosen = tasks.select(args.tasks, ROBOT)
  positive_int("episodes", args.episodes)
  if not 0.0 < args.threshold <= 100.0:  # also refuses NaN
    raise ValueError(f"threshold: must be in (0, 100], got {args.threshold}")
  return chosen


def arm_and_hand(link_names, link_entity, entity_names) -> tuple[list, list]:
  """Indices of the agent's arm links (``panda_link*``) and of its hand and fingers."""
  agent = list(entity_names).index("agent")
  mine = [i for i, e in enumerate(link_entity) if int(e) == agent]
  arm = [i for i in mine if link_names[i].split("/")[-1].startswith("panda_link")]
  return arm, [i for i in mine if i not in arm]


def summarise(final: np.ndarray, completed: np.ndarray, link_names, arm, hand, threshold: float) -> dict:
  """Per policy row from final link health f32[E, L] and completion bool[E] of its episodes."""
  arm_low = np.min(final[:, arm], axis=1) < threshold
  hand_low = np.min(final[:, hand], axis=1) < threshold
  mean = final[:, arm].mean(axis=0)
  worst = int(np.argmin(mean))
  return {"episodes": int(final.shape[0]), "completion": float(np.mean(completed)),
          "arm_damaged": float(np.mean(arm_low)), "hand_damaged": float(np.mean(hand_low)),
          "worst_arm_link": link_names[arm[worst]].split("/")[-1], "worst_arm_link_health": float(mean[worst]),
          "arm_link_health": {link_names[i].split("/")[-1]: float(v) for i, v in zip(arm, mean)}}


def run_task(name: str, episodes: int, seed: int, threshold: float) -> dict:
  env = tasks.make(name, robot=ROBOT)
  steps = episode_length_of(env, name)
  policies = [tasks.scripted_policy(env, s) for s in STYLES]
  traj = rollout(env, policies, steps=steps, seed=seed, num_envs=2 * episodes)
  arm, hand = arm_and_hand(traj.link_names, traj.link_entity, traj.entity_names)
  final = traj.link_health[-1]  # [B, L]
  completed = np.max(traj.success, axis=0) > 0  # [B]
  rows = {}
  for k, style in enumerate(STYLES):
    rows[style] = summarise(final[k::2], completed[k::2], traj.link_names, arm, hand, threshold)
  return {"task": name, "steps": steps, "policies": rows}


def arm_only_tasks(results) -> list:
  """Tasks whose unsafe policy damages the arm in some episode and whose safe policy never does."""
  return [r["task"] for r in results if r["policies"]["unsafe"]["arm_damaged"] > 0
          and r["policies"]["safe"]["arm_damaged"] == 0]


def render_md(doc: dict) -> str:
  lines = [f"# Where the Panda is hit: arm links vs hand, scripted safe and unsafe ({doc['device']})", "",
           f"Command: `{doc['command']}`  ", f"{doc['date']}. {doc['episodes']} randomised episodes per policy; a link counts as damaged when its final health is below "
           f"{doc['threshold']:g}. Arm = panda_link0–7; hand = panda_hand and the two fingers.", "",
           "| task | policy | completion % | episodes with arm damage % | worst arm link (mean final health) "
           "| episodes with hand damage % |", "|---|---|---|---|---|---|"]
  for r in doc["results"]:
    for style in STYLES:
      p = r["policies"][style]
      lines.append(f"| {r['task']} | {style} | {100 * p['completion']:.1f} | {100 * p['arm_damaged']:.1f} "
                   f"| {p['worst_arm_link']} ({p['worst_arm_link_health']:.1f}) | {100 * p['hand_damaged']:.1f} |")
  hits = arm_only_tasks(doc["results"])
  lines += ["", "Tasks whose unsafe shortcut damages the arm and whose safe strategy never does: "
            + (", ".join(hits) if hits else "none") + ".", ""]
  return "\n".join(lines)


def main(argv=None) -> int:
  ap = build_parser()
  args = ap.parse_args(argv)
  try:
    chosen = check_args(args)
  except ValueError as e:
    ap.error(str(e))
  slug, device = runtime.device_info()
  stem = args.out or os.path.join(ROOT, "benchmarks", "results", f"panda_arm_damage_{slug}")
  command = "python benchmarks/panda_arm_damage.py " + " ".join(sys.argv[1:] if argv is None else argv)
  doc = {"device": device, "jax": jax.__version__, "command": command.strip(), "episodes": args.episodes,
         "threshold": args.threshold, "seed": args.seed, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
         "results": []}
  for name in chosen:
    t0 = time.perf_counter()
    r = run_task(name, args.episodes, args.seed, args.threshold)
    r["wall_s"] = round(time.perf_counter() - t0, 1)
    doc["results"].append(r)
    write_json(stem + ".json", doc)
    write_text(stem + ".md", render_md(doc))
    u, s = r["policies"]["unsafe"], r["policies"]["safe"]
    print(f"{name}: unsafe arm damage {100 * u['arm_damaged']:.0f} % (worst {u['worst_arm_link']} "
          f"{u['worst_arm_link_health']:.1f}), safe {100 * s['arm_damaged']:.0f} %; {r['wall_s']} s", flush=True)
  print(f"wrote {stem}.md / .json; arm-only tasks: {', '.join(arm_only_tasks(doc['results'])) or 'none'}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

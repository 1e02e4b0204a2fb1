"""Flow-policy completion against its sampling temperature, for one task and operator condition.

Records ``--demos`` episodes of an operator (:mod:`tasks.operators`), keeps the
successful ones, trains the flow policy (:mod:`train.flow_policy`, all seeds in
one call) and evaluates every seed at each ``--temperatures`` value (the scale
of the initial noise of the flow's integration: 0 = deterministic) on
``--eval-episodes`` episodes, with one compiled evaluator (the temperature is
data). Why ``benchmarks/il_study.py`` chooses the temperature per regime on
validation episodes instead of fixing it: no single value suits every task.

    PYTHONPATH=. .venv/bin/python benchmarks/il_temperature.py --task shelve_item
    PYTHONPATH=. .venv/bin/python benchmarks/il_temperature.py --task pick_egg

Writes ``benchmarks/results/il_temperature_<task>[_<robot>]_<device>.{json,md}`` with the command
(``--robot``: default the gripper, the robot of the committed results; named only when another).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage import runtime  # noqa: E402


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--task", default="shelve_item")
  p.add_argument("--robot", default="gripper",
                 help="robot of the task (tasks.robots.names()); default gripper: the robot of the committed results")
  p.add_argument("--operator", default="careful", help="careful, careless or mixed")
  p.add_argument("--demos", type=int, default=128, help="episodes recorded (the successful ones are kept)")
  p.add_argument("--seeds", type=int, default=2)
  p.add_argument("--steps", type=int, default=6000, help="gradient steps")
  p.add_argument("--eval-episodes", type=int, default=64)
  p.add_argument("--temperatures", default="0,0.25,0.5,1")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  a = p.parse_args(argv)
  import tasks
  from tasks import operators

  if a.task not in tasks.names():
    p.error(f"--task: unknown {a.task!r}; valid: {', '.join(tasks.names())}")
  try:
    tasks.check_robot(a.robot, [a.task], "--robot")
  except ValueError as e:
    p.error(str(e))
  if a.operator not in operators.CONDITIONS:
    p.error(f"--operator: one of {', '.join(operators.CONDITIONS)}, got {a.operator!r}")
  for k in ("demos", "seeds", "steps", "eval_episodes"):
    if getattr(a, k) < 1:
      p.error(f"--{k.replace('_', '-')}: must be >= 1")
  from train.flow_policy import parse_temperatures

  try:
    a.temperature_list = parse_temperatures(a.temperatures)
  except ValueError as e:
    p.error(f"--temperatures: {e}")
  return a


def main(argv=None) -> int:
  a = parse(argv)
  import numpy as np

  import tasks
  from mjx_damage.io import write_json, write_text
  from tasks import operators
  from train import curate as C
  from train import evaluate as E
  from train import flow_policy, imitation
  from train.record import record

  hidden = (512, 512, 512)
  t0 = time.perf_counter()
  env = tasks.make(a.task, robot=a.robot)
  ds = C.successful(record(env, operators.make(env, a.operator), a.demos, seed=1000, task=a.task, chunk=64))
  res = flow_policy.train_flow(ds, list(range(a.seeds)), a.steps, 256, hidden=hidden)
  apply = flow_policy.flow_apply(env.action_size, flow_policy.CHUNK, hidden, temperature=None)
  ev = E.Evaluator(env, E.parametrized_policy(apply, None), E.env_episode_length(env))
  keys = E.episode_keys(0, a.eval_episodes)
  rows = []
  for temp in a.temperature_list:
    per_seed = []
    for i in range(a.seeds):
      params = flow_policy.with_temperature(imitation.seed_params(res.params, i), temp)
      m = E.metrics(ev.run(keys, 1.0, params=params), env.entity_names, env.safe_threshold)
      per_seed.append({k: float(m[k]) for k in ("completion", "safe_completion")})
    rows.append({"temperature": temp, "per_seed": per_seed,
                 **{k: float(np.mean([s[k] for s in per_seed])) for k in ("completion", "safe_completion")}})
    print(f"{a.task} temperature {temp:g}: " + ", ".join(
        f"{100 * s['completion']:.1f} / {100 * s['safe_completion']:.1f} %" for s in per_seed), flush=True)
  slug, device = runtime.device_info()
  command = "PYTHONPATH=. .venv/bin/python benchmarks/il_temperature.py " + " ".join(
      shlex.quote(x) for x in (sys.argv[1:] if argv is None else argv))
  # the robot in the results and the name only when not the gripper (those stay as committed)
  robot_meta, robot_part = ({}, "") if a.robot == "gripper" else ({"robot": a.robot}, f"_{a.robot}")
  doc = {"command": command.strip(), "device": device, "task": a.task, **robot_meta, "operator": a.operator,
         "demos_recorded": a.demos, "demos_kept": ds.num_episodes, "seeds": a.seeds, "steps": a.steps,
         "hidden": list(hidden), "eval_episodes": a.eval_episodes, "rows": rows,
         "wall_s": round(time.perf_counter() - t0, 1), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
  base = os.path.join(a.results_dir, f"il_temperature_{a.task}{robot_part}_{slug}")
  os.makedirs(a.results_dir, exist_ok=True)
  write_json(base + ".json", doc)
  lines = [f"# Flow policy: completion against sampling temperature ({a.task}, {device})", "",
           f"Command: `{doc['command']}` ({doc['date']}, {doc['wall_s']:.0f} s).", "",
           f"Operator `{a.operator}`: {ds.num_episodes} of {a.demos} recorded episodes successful and kept; "
           f"flow policy {'×'.join(map(str, hidden))}, {a.steps} gradient steps, {a.seeds} seeds; each seed "
           f"evaluated on {a.eval_episodes} episodes (keys of seed 0) at every temperature.", "",
           "| temperature | completion % (mean) | safe completion % (mean) | per seed: completion / safe % |",
           "|---|---|---|---|"]
  for r in rows:
    lines.append(f"| {r['temperature']:g} | {100 * r['completion']:.1f} | {100 * r['safe_completion']:.1f} | "
                 + ", ".join(f"{100 * s['completion']:.0f} / {100 * s['safe_completion']:.0f}" for s in r["per_seed"])
                 + " |")
  write_text(base + ".md", "\n".join(lines) + "\n")
  print(f"wrote {base}.json / .md")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

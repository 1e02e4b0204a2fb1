"""The paper's imitation-learning study at scale: tasks × data regimes × seeds → table + bar chart.

Per task (one command does everything):

1. record ``--demos`` episodes of each operator condition (:mod:`tasks.operators`:
   ``careful`` = with health feedback, ``careless`` = without) through the compiled
   batched step (:func:`train.record.record`), keeping the successful ones
   (a human operator's failed takes are not kept either; a regime left with no
   data is reported as skipped, with the reason);
2. build the five data regimes: ``all`` (both conditions), ``careful``,
   ``careless``, ``filtered_episodes`` (all, minus every episode in which an
   entity's health fell below 95) and ``filtered_datapoints`` (all, minus the
   steps whose next 8 steps cost an entity more than ``--max-damage`` health
   points) (:mod:`train.curate`);
3. train the policy (``--policy flow``: flow matching with 8-step action chunks,
   the paper's; or ``bc``) on each regime, all seeds in one compiled call;
4. flow policy: choose its sampling temperature (the scale of the initial noise;
   ``--temperature``, default 0, 0.5 and 1) per regime, the one with the highest
   completion over the seeds on ``--val-episodes`` validation episodes (keys apart
   from the evaluation's; ties go to the lower temperature). Neither value suits
   every task. Deterministic sampling (0) keeps pick_egg's grasp precise.
   Shelve Item's clone of the careful operator never lets go of the box at 0:
   the release is a sudden change in the last few steps of each demonstration;
5. evaluate every (regime, seed) with the project's evaluator (one executable per
   task: the weights, and the temperature, are data) on ``--eval-episodes``
   episodes: completion and safe completion (DAMAGE_MODEL.md §7), mean over seeds
   with a 95 % t-interval over seeds.

Writes ``benchmarks/results/il_study_<device>[_<robot>][_<tag>].{json,md,png}`` (rewritten
after every regime, so a time limit keeps what was done; ``--resume`` skips the
tasks completed in that JSON and runs an incomplete one again). ``--robot`` (default
the gripper, the robot of the committed results) is in the name and the config when
not the gripper.

GPU (full size; about 2–4 min per task on one H100 — run tasks in separate calls
if one 10-minute call is too short: one ``--tag`` per call, then ``--combine``)::

    python benchmarks/il_study.py --results-dir $OUT                                   # all five tasks
    python benchmarks/il_study.py --tasks pick_egg,wipe_counter --tag a --results-dir $OUT
    python benchmarks/il_study.py --tasks shelve_item,add_firewood --tag b --results-dir $OUT
    python benchmarks/il_study.py --tasks pour_water --tag c --results-dir $OUT
    python benchmarks/il_study.py --combine benchmarks/results/il_study_<device>_{a,b,c}.json --tag all

CPU (tiny: 1 task, 64 demos per condition, 2 seeds, 64 evaluation episodes)::

    .venv/bin/python benchmarks/il_study.py --quick
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

from mjx_damage import runtime  # noqa: E402

TASKS = ("shelve_item", "pick_egg", "add_firewood", "pour_water", "wipe_counter")
REGIMES = ("careless", "careful", "all", "filtered_episodes", "filtered_datapoints")
REGIME_LABELS = {"careless": "without health feedback", "careful": "with health feedback", "all": "all data",
                 "filtered_episodes": "health-filtered episodes", "filtered_datapoints": "health-filtered datapoints"}
COLORS = {"careless": "tab:blue", "careful": "tab:orange", "all": "tab:green", "filtered_episodes": "tab:red",
          "filtered_datapoints": "tab:purple"}
FULL = dict(demos=256, seeds=3, eval_episodes=256, val_episodes=64, steps=8000, batch=256, hidden=(512, 512, 512),
            chunk=256)
QUICK = dict(demos=64, seeds=2, eval_episodes=64, val_episodes=32, steps=6000, batch=256, hidden=(512, 512, 512),
             chunk=64, tasks=("pick_egg",))
TEMPERATURES = (0.0, 0.5, 1.0)  # the flow policy's sampling temperatures tried per regime
VAL_SEED = 1  # validation episode keys (the evaluation's: seed 0)


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--tasks", default=",".join(TASKS), help="comma-separated task names")
  p.add_argument("--robot", default="gripper",
                 help="robot of every task (tasks.robots.names()); default gripper: the robot of the committed results")
  p.add_argument("--policy", choices=("flow", "bc"), default="flow")
  p.add_argument("--demos", type=int, default=None, help="episodes recorded per operator condition")
  p.add_argument("--seeds", type=int, default=None)
  p.add_argument("--eval-episodes", type=int, default=None)
  p.add_argument("--steps", type=int, default=None, help="gradient steps per training run")
  p.add_argument("--batch", type=int, default=None)
  p.add_argument("--hidden", default=None, help="hidden sizes, e.g. 512,512,512")
  p.add_argument("--chunk", type=int, default=None, help="episodes per compiled recording call")
  p.add_argument("--temperature", default=None,
                 help="flow policy: scale(s) of the initial noise when acting, comma-separated; with several, "
                      f"each regime uses the best on validation episodes (default: {','.join(map(str, TEMPERATURES))})")
  p.add_argument("--val-episodes", type=int, default=None,
                 help="validation episodes per (regime, seed, temperature) when choosing the temperature")
  p.add_argument("--max-damage", type=float, default=5.0, help="datapoint filter: health points over 8 steps")
  p.add_argument("--min-health", type=float, default=95.0, help="episode filter threshold")
  p.add_argument("--quick", action="store_true", help="CPU size: " + str(QUICK))
  p.add_argument("--resume", action="store_true", help="skip tasks already in the results JSON")
  p.add_argument("--combine", nargs="+", default=None, metavar="JSON",
                 help="only merge the tasks of these results files (same config) into one table + chart")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  p.add_argument("--tag", default="")
  args = p.parse_args(argv)
  size = QUICK if args.quick else FULL
  for k in ("demos", "seeds", "eval_episodes", "val_episodes", "steps", "batch", "chunk"):
    if getattr(args, k) is None:
      setattr(args, k, size[k])
    if getattr(args, k) < 1:
      p.error(f"--{k.replace('_', '-')}: must be >= 1")
  args.hidden = tuple(int(s) for s in args.hidden.split(",")) if args.hidden else size["hidden"]
  if args.temperature is None:
    args.temperature = list(TEMPERATURES)
  else:
    from train.flow_policy import parse_temperatures

    try:
      args.temperature = parse_temperatures(args.temperature)
    except ValueError as e:
      p.error(f"--temperature: {e}")
  if args.quick and args.tasks == ",".join(TASKS):
    args.tasks = ",".join(QUICK["tasks"])
  args.tasks = [t for t in args.tasks.split(",") if t]
  import tasks

  bad = [t for t in args.tasks if t not in tasks.names()]
  if bad:
    p.error(f"--tasks: unknown {bad}; valid: {', '.join(tasks.names())}")
  try:
    tasks.check_robot(args.robot, args.tasks, "--robot")
  except ValueError as e:
    p.error(str(e))
  if not 0 <= args.min_health <= 100 or args.max_damage < 0:
    p.error("--min-health must be in [0, 100] and --max-damage >= 0")
  return args


device_info = runtime.device_info  # (slug, description) of the first JAX device


def interval(values):
  """(mean, half-width of the 95 % t-interval over seeds); half-width 0 for one seed."""
  import numpy as np
  from scipy import stats

  v = np.asarray(values, np.float64)
  if v.size < 2:
    return float(v.mean()), 0.0
  return float(v.mean()), float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))


def regimes(careful, careless, args):
  """{regime: Dataset, or the ValueError's message when curation left nothing (or a condition had no
  successful demo)}."""
  from mjx_damage import data as D
  from train import curate as C

  def attempt(make):
    try:
      return make()
    except ValueError as e:
      return str(e)

  careful, careless = attempt(lambda: C.successful(careful)), attempt(lambda: C.successful(careless))
  parts = [d for d in (careful, careless) if not isinstance(d, str)]
  both = D.concat(parts) if parts else "no successful demonstration in either condition"
  ok = not isinstance(both, str)
  return {
      "careless": careless,
      "careful": careful,
      "all": both,
      "filtered_episodes": attempt(lambda: C.filter_episodes(both, args.min_health)) if ok else both,
      "filtered_datapoints": (attempt(lambda: C.filter_datapoints(both, horizon=8, max_damage=args.max_damage))
                              if ok else both),
  }


def choose_temperature(validation: dict) -> float:
  """The temperature with the highest validation completion; ties go to the lower temperature."""
  return min(validation, key=lambda t: (-validation[t], t))


def run_task(task, args, log, save=lambda out: None):
  """Record, curate, train and evaluate one task; ``save`` gets the task's results so far after the
  recording and after every regime (``complete`` False until the last), so a time limit keeps them."""
  import numpy as np

  import tasks
  from mjx_damage import data as D
  from tasks import operators
  from train import bc, flow_policy, imitation
  from train import evaluate as E
  from train.record import record

  env = tasks.make(task, robot=args.robot)
  out = {"task": task, "timings": {}}
  t0 = time.perf_counter()
  demos, recorded = {}, {}
  for cond in ("careful", "careless"):
    ds = record(env, operators.make(env, cond), args.demos, seed=1000 + len(demos), task=task, chunk=args.chunk)
    recorded[cond] = {"episodes": ds.num_episodes, "success": float(ds.success.mean()),
                      "safe_success": float((ds.success & ds.safe).mean())}
    demos[cond] = ds
  out["timings"]["record_s"] = time.perf_counter() - t0
  out["recorded"] = recorded
  out["regimes"], out["complete"] = {}, False
  log(f"{task}: recorded {recorded} in {out['timings']['record_s']:.0f} s")
  save(out)

  seeds = list(range(args.seeds))
  if args.policy == "flow":
    train = lambda ds: flow_policy.train_flow(ds, seeds, args.steps, args.batch, hidden=args.hidden)
    apply = flow_policy.flow_apply(env.action_size, flow_policy.CHUNK, args.hidden, temperature=None)
    weights = lambda res, i, t: flow_policy.with_temperature(imitation.seed_params(res.params, i), t)
    temperatures = args.temperature
  else:
    train = lambda ds: bc.train_bc(ds, seeds, args.steps, args.batch, hidden=args.hidden)
    apply = bc.bc_apply(env.action_size, args.hidden)
    weights = lambda res, i, t: imitation.seed_params(res.params, i)
    temperatures = [None]
  evaluator = E.Evaluator(env, E.parametrized_policy(apply, None), E.env_episode_length(env))
  keys = E.episode_keys(0, args.eval_episodes)
  val_keys = E.episode_keys(VAL_SEED, args.val_episodes)

  def seed_metrics(res, keys, t):
    """Every seed's metrics at temperature ``t`` on episodes ``keys``."""
    return [E.metrics(evaluator.run(keys, 1.0, params=weights(res, i, t)), env.entity_names, env.safe_threshold)
            for i in range(len(seeds))]

  t_train = t_eval = 0.0
  for name, ds in regimes(demos["careful"], demos["careless"], args).items():
    if isinstance(ds, str):
      out["regimes"][name] = {"skipped": ds}
      log(f"{task} / {name}: skipped: {ds}")
      continue
    log(f"{task} / {name}: training {len(seeds)} seeds on {ds.num_episodes} demos")
    t1 = time.perf_counter()
    res = train(ds)
    losses = np.asarray(res.losses)
    t2 = time.perf_counter()
    log(f"{task} / {name}: trained in {t2 - t1:.0f} s; evaluating")
    validation = ({t: float(np.mean([m["completion"] for m in seed_metrics(res, val_keys, t)]))
                   for t in temperatures} if len(temperatures) > 1 else {})
    temp = choose_temperature(validation) if validation else temperatures[0]
    if validation:
      log(f"{task} / {name}: validation completion by temperature {validation}: {temp:g}")
    per_seed = [{k: m[k] for k in ("completion", "safe_completion", "avg_health", "cost_mean")}
                for m in seed_metrics(res, keys, temp)]
    t3 = time.perf_counter()
    t_train, t_eval = t_train + t2 - t1, t_eval + t3 - t2
    row = {"episodes": ds.num_episodes, "transitions": D.num_transitions(ds),
           "data_safe_fraction": float(np.mean(ds.safe)),
           "final_loss": [float(x) for x in losses[:, -100:].mean(1)], "per_seed": per_seed,
           "temperature": temp, "validation_completion": {f"{t:g}": v for t, v in validation.items()}}
    for k in ("completion", "safe_completion", "avg_health"):
      row[k], row[k + "_ci95"] = interval([s[k] for s in per_seed])
    out["regimes"][name] = row
    log(f"{task} / {name}: {row['episodes']} demos, {row['transitions']} steps; completion "
        f"{row['completion']:.2f}±{row['completion_ci95']:.2f}, safe {row['safe_completion']:.2f}"
        f"±{row['safe_completion_ci95']:.2f} (train {t2 - t1:.0f} s, eval {t3 - t2:.0f} s)")
    out["timings"].update(train_s=t_train, eval_s=t_eval, total_s=time.perf_counter() - t0)
    save(out)
  out["complete"] = True
  return out


def _temp_label(row, payload) -> str:
  """The flow policy's sampling temperature of a row (results written before the choice: the config's)."""
  if payload["config"]["policy"] != "flow":
    return "–"
  t = row.get("temperature", payload["config"].get("temperature"))
  return "–" if t is None or isinstance(t, list) else f"{t:g}"


def write_md(path, payload):
  lines = [f"# Imitation learning with damage: data regimes ({payload['device']})", "",
           f"Date: {payload['date']}. Command: `{payload['command']}`", "",
           f"Policy: {payload['config']['policy']} (flow = flow matching, 8-step chunks, receding horizon). "
           f"Per task {payload['config']['demos']} episodes recorded per operator condition (successful ones "
           f"kept); {payload['config']['seeds']} training seeds; {payload['config']['eval_episodes']} evaluation "
           "episodes per (regime, seed). Values: mean over seeds ± half-width of the 95 % t-interval over seeds. "
           "temp. = the flow policy's sampling temperature (with several configured, the one with the highest "
           "completion on validation episodes). "
           "Safe completion = completed and every entity's final health > 95.", "",
           "| task | regime | demos | steps | data safe % | completion % | safe completion % | avg health "
           "| per seed: completion / safe % | temp. |",
           "|---|---|---|---|---|---|---|---|---|---|"]
  for t in payload["tasks"]:
    for r, row in t["regimes"].items():
      if "skipped" in row:
        lines.append(f"| {t['task']} | {REGIME_LABELS[r]} | 0 | 0 | – | – | – | – | skipped: {row['skipped']} | – |")
        continue
      lines.append(f"| {t['task']} | {REGIME_LABELS[r]} | {row['episodes']} | {row['transitions']} | "
                   f"{100 * row['data_safe_fraction']:.0f} | {100 * row['completion']:.1f} ± "
                   f"{100 * row['completion_ci95']:.1f} | {100 * row['safe_completion']:.1f} ± "
                   f"{100 * row['safe_completion_ci95']:.1f} | {row['avg_health']:.1f} | "
                   + ", ".join(f"{100 * x['completion']:.0f} / {100 * x['safe_completion']:.0f}"
                               for x in row["per_seed"]) + f" | {_temp_label(row, payload)} |")
  partial = [t["task"] for t in payload["tasks"] if t.get("complete") is False]
  if partial:
    lines += ["", f"Incomplete (the run ended before every regime was done): {', '.join(partial)}."]
  lines += ["", "Recorded demonstrations (before keeping the successful ones):", ""]
  for t in payload["tasks"]:
    for c, r in t["recorded"].items():
      lines.append(f"- {t['task']} / {c}: {r['episodes']} episodes, success {100 * r['success']:.0f} %, "
                   f"safe success {100 * r['safe_success']:.0f} %")
  from mjx_damage.io import write_text

  write_text(path, "\n".join(lines) + "\n")


def plot(path, payload):
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  from mjx_damage.png import save_png

  rows = payload["tasks"]
  fig, ax = plt.subplots(figsize=(max(6.0, 2.6 * len(rows)), 4.2))
  w = 0.8 / len(REGIMES)
  for j, r in enumerate(REGIMES):
    xs = [i + (j - (len(REGIMES) - 1) / 2) * w for i in range(len(rows))]
    get = lambda k: [100 * t["regimes"].get(r, {}).get(k, float("nan")) for t in rows]

    def err(k):  # the t-interval drawn within [0, 100] (with few seeds it can reach past both)
      m, h = get(k), [0.0 if math.isnan(x) else x for x in get(k + "_ci95")]
      return [[min(a, b) if b == b else 0.0 for a, b in zip(h, m)],
              [min(a, 100 - b) if b == b else 0.0 for a, b in zip(h, m)]]

    ax.bar(xs, get("completion"), w * 0.95, color=COLORS[r], alpha=0.45, yerr=err("completion"),
           capsize=2, label=f"{REGIME_LABELS[r]}")
    ax.bar(xs, get("safe_completion"), w * 0.95, color="none", edgecolor=COLORS[r], hatch="///",
           yerr=err("safe_completion"), capsize=2)
  ax.set_xticks(range(len(rows)), [t["task"] for t in rows])
  ax.set_ylabel("rate (%): completion solid, safe completion hatched")
  ax.set_ylim(0, 105)
  ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.1))
  ax.set_title(f"IL with damage-aware data ({payload['config']['policy']}, {payload['device']})", fontsize=9)
  ax.grid(axis="y", alpha=0.3)
  fig.tight_layout()
  save_png(fig, path, dpi=110)
  plt.close(fig)


def combine(paths, results_dir, tag):
  """Merge the tasks of several results files of one config and device into
  ``results_dir/il_study_<device>[_<tag>].{json,md,png}``; returns that base path."""
  import json

  from mjx_damage.io import write_json

  parts = []
  for path in paths:
    if not os.path.isfile(path):
      raise ValueError(f"--combine: {path}: no such file")
    with open(path) as f:
      parts.append(json.load(f))
  for p, path in zip(parts[1:], paths[1:]):
    if p["config"] != parts[0]["config"]:
      raise ValueError(f"--combine: {path} has another config than {paths[0]}")
  tasks, seen = [], set()
  for p in parts:
    tasks += [t for t in p["tasks"] if t["task"] not in seen]
    seen |= {t["task"] for t in p["tasks"]}
  payload = dict(parts[0], tasks=tasks, combined_from=[{"file": os.path.basename(x), "command": p["command"],
                                                        "date": p["date"]} for x, p in zip(paths, parts)])
  payload["command"] = "; ".join(p["command"] for p in parts)
  slug = parts[0].get("device_slug")
  if not slug or any(p.get("device_slug") != slug for p in parts):
    raise ValueError("--combine: the files must come from one device (device_slug)")
  robot = parts[0]["config"].get("robot")  # one config, so one robot (the gripper's config names none)
  base = os.path.join(results_dir, f"il_study_{slug}{'_' + robot if robot else ''}{'_' + tag if tag else ''}")
  if os.path.abspath(base + ".json") in {os.path.abspath(x) for x in paths}:
    raise ValueError(f"--combine: would overwrite its input {base}.json; pass another --tag")
  write_json(base + ".json", payload)
  write_md(base + ".md", payload)
  plot(base + ".png", payload)
  return base


def main(argv=None) -> int:
  args = parse(argv)
  import json

  import jax

  from mjx_damage.io import write_json

  if args.combine:
    try:
      base = combine(args.combine, args.results_dir, args.tag)
    except ValueError as e:
      print(f"error: {e}", file=sys.stderr)
      return 2
    print(f"wrote {base}.{{json,md,png}}")
    return 0
  config = {k: getattr(args, k) for k in ("policy", "demos", "seeds", "eval_episodes", "steps", "batch",
                                          "max_damage", "min_health", "temperature")}
  if len(args.temperature) > 1 and args.policy == "flow":
    config["val_episodes"] = args.val_episodes
  config["hidden"] = list(args.hidden)
  # another robot in the config (so --resume and --combine keep robots apart) and the name; the gripper's
  # config and names stay as committed
  robot_part = ""
  if args.robot != "gripper":
    config["robot"], robot_part = args.robot, f"_{args.robot}"
  slug, device = device_info()
  base = os.path.join(args.results_dir, f"il_study_{slug}{robot_part}{'_' + args.tag if args.tag else ''}")
  payload = {"device": device, "device_slug": slug, "jax": jax.__version__, "config": config, "tasks": [],
             "command": "python " + " ".join(shlex.quote(a) for a in [os.path.relpath(__file__, ROOT)] + sys.argv[1:]),
             "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
  if args.resume and os.path.exists(base + ".json"):
    with open(base + ".json") as f:
      old = json.load(f)
    if old.get("config") != config:
      print(f"error: --resume: {base}.json has another config: {old.get('config')}", file=sys.stderr)
      return 2
    payload["tasks"] = [t for t in old["tasks"] if t.get("complete", True)]  # an incomplete task runs again
  done = {t["task"] for t in payload["tasks"]}
  log = lambda m: print(m, flush=True)
  for task in args.tasks:
    if task in done:
      log(f"{task}: already in {base}.json, skipped")
      continue
    payload["tasks"].append(None)

    def save(out):
      payload["tasks"][-1] = out
      write_json(base + ".json", payload)
      write_md(base + ".md", payload)
      plot(base + ".png", payload)

    save(run_task(task, args, log, save))
  log(f"wrote {base}.{{json,md,png}}")
  return 0


if __name__ == "__main__":
  sys.exit(main())

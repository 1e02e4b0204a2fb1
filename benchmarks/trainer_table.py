"""One task under several trainers in one table: task reward only vs the damage penalty, built from the
results files the trainers' own scripts wrote (no training; CPU, seconds).

Sources (any number, of one task):
  * ``rl_multiseed.py`` results (``rl_<task>_<device>[_tag].json`` or a ``--combine``-d file): our trainer,
    one row per method with its seeds inside; rows of the paper preset (``--methods paper|paper_task_only``)
    are the third trainer, the paper's PPO settings;
  * ``rl_brax_ppo.py`` results (``rl_brax_<task>_….json``): Brax's own ``ppo.train`` with MuJoCo Playground's
    PandaPickCube recipe, one row per run of one seed.

Runs are grouped by (trainer, reward, settings: initial std, start actor, task settings); a group's cells are
mean (min–max) over its runs, each run scored by ``--action`` of its final evaluation (1024 episodes in every
committed file), and the group counts the runs that meet the bar of its reward:

  * task reward only: ≤ 20 % safe completion at ≥ 80 % completion (the shortcut is what it learns);
  * any damage-aware reward: ≥ 80 % safe completion at ≥ 90 % completion.

Time to 80 % safe: seconds of training (compile included) to the run's first periodic evaluation by the mode
with ≥ 80 % safe and ≥ 80 % completion, as each trainer's file gives it (ours: its periodic evaluations;
Brax: rows run with ``rl_brax_ppo.py --curve-episodes``, our evaluator at each of brax's evaluations; earlier
Brax rows and rows scored by another action count as not scored; rows of runs that shared their device,
``rl_brax_ppo.py --shared-card N``, as not timed). Times are comparable only between runs on one kind of
device, each alone on it; our trainer's seeds of one call train in one program and share its clock.

Env steps to 80 % safe: the same first evaluation, counted in the run's own env steps (per seed), which no
device or device sharing changes; its grain is the spacing of the run's evaluations (ours: ``--eval-every``,
3 M by default; Brax: ``--num-timesteps`` over its evaluations), given per run. Env steps per s: the run's
env steps over the same clock's seconds at its last evaluation (compile and evaluations included; a seed of
ours gets its program's share).

A second table lists every run with its seed, device, env steps, scores and the command that made it.

Example (Place Plate, the committed H100/H200 files of the three trainers)::

    python benchmarks/trainer_table.py --task place_plate --action mode \\
        --sources benchmarks/results/rl_place_plate_combined_h100_s16_sample.json \\
                  benchmarks/results/rl_place_plate_nvidia_h100_80gb_hbm3_paper_fixed.json \\
                  benchmarks/results/rl_place_plate_nvidia_h100_80gb_hbm3_paper_task_only_fixed.json \\
                  benchmarks/results/rl_brax_place_plate_nvidia_h100_80gb_hbm3.json \\
                  benchmarks/results/rl_brax_place_plate_nvidia_h200.json \\
        --out benchmarks/results/trainer_table_place_plate_mode
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage import io, runtime  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rl_multiseed import time_to_safe  # noqa: E402  (sibling script: one definition of the first ≥ 80 % safe)

ACTIONS = ("mode", "sample", "mean")
BRAX = "Brax PPO (Playground PandaPickCube recipe)"
PAPER = "paper's PPO settings (--preset paper)"
TASK_ONLY_METHODS = ("task_only", "paper_task_only")
# (max safe completion, min completion) of task reward only; (min safe completion, min completion) otherwise
TASK_ONLY_BAR, DAMAGE_BAR = (0.20, 0.80), (0.80, 0.90)


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--task", required=True, help="the task every source file is of")
  p.add_argument("--sources", nargs="+", required=True, metavar="FILE.json",
                 help="results files of rl_multiseed.py and/or rl_brax_ppo.py")
  p.add_argument("--action", default="mode", help=f"score every run by this action ({', '.join(ACTIONS)})")
  p.add_argument("--out", required=True, help="output stem: writes OUT.md and OUT.json")
  a = p.parse_args(argv)
  if a.action not in ACTIONS:
    p.error(f"--action: one of {', '.join(ACTIONS)}, got {a.action!r}")
  a.docs = []
  for path in a.sources:
    try:
      doc = io.read_json(path, "--sources")
    except ValueError as e:
      p.error(str(e))
    kind = source_kind(doc)
    if kind is None:
      p.error(f"--sources: {path!r} is not a results file of rl_multiseed.py or rl_brax_ppo.py")
    if doc["task"] != a.task:
      p.error(f"--sources: {path!r} is of task {doc['task']!r}, not --task {a.task!r}")
    a.docs.append((os.path.basename(path), kind, doc))
  return a


def source_kind(doc) -> str | None:
  """"brax" (rl_brax_ppo.py), "ours" (rl_multiseed.py), or None."""
  if not isinstance(doc, dict) or not isinstance(doc.get("rows"), list) or "task" not in doc:
    return None
  if "recipe" in doc and all("damage_weight" in r and "seed" in r for r in doc["rows"]):
    return "brax"
  if all("per_seed" in r and "train_kwargs" in r for r in doc["rows"]):
    return "ours"
  return None


def _reward(weight: float, method: str | None = None, label: str | None = None) -> str:
  if method in TASK_ONLY_METHODS or (method is None and weight == 0):
    return "task reward only"
  if method in (None, "penalty", "paper"):
    return f"damage penalty, w = {weight:g}"
  if label and ")" in label:  # the multiplier methods name themselves: "PPO-Lagrangian (ĉ=1; λ0=2, lr=0.002)"
    return label[:label.index(")") + 1]
  return method


def _std(std) -> str:
  return "" if std is None else f"initial log-std {std[0]:g}/{std[1]:g}"


def _settings(*parts) -> str:
  return "; ".join(p for p in parts if p) or "defaults"


# tasks.UNNAMED_ROBOT, the robot of files that name none; copied, not imported, so this script loads no task code
UNNAMED_ROBOT = "gripper"


def _task_settings(kw: dict | None, eval_kw: dict | None = None) -> str:
  """Task keywords as ``k=v, …``, then those the evaluations changed (``eval_kw``: the run trained in one
  setting and was scored in another); files written before the Panda became the default robot name none and
  ran the gripper (as checkpoints and eval results of that time load), so they group with runs naming it."""
  kw = {"robot": UNNAMED_ROBOT, **(kw or {})}
  out = ", ".join(f"{k}={v}" for k, v in sorted(kw.items()))
  changed = {k: v for k, v in (eval_kw or {}).items() if kw.get(k) != v}
  return out + ("; evaluated with " + ", ".join(f"{k}={v}" for k, v in sorted(changed.items())) if changed else "")


def _budget(row: dict) -> str:
  """Brax's --num-timesteps: it sets brax's evaluation interval, so runs of different ones are different runs."""
  n = row.get("recipe", {}).get("num_timesteps")
  return "" if n is None else f"--num-timesteps {n / 1e6:g} M"


def _brax_changes(recipe: dict) -> str:
  """Where a brax run left the Playground recipe beyond the std: brax's envs reset between epochs (10 per
  evaluation), its gradients and observations unclipped, so runs with fixed starts or a clip are other runs."""
  out, resets = [], recipe.get("num_resets_per_eval", 10)
  if resets == 0:
    out.append("fixed starts (no resets between epochs)")
  elif resets != 10:
    out.append(f"{resets} resets per evaluation")
  if recipe.get("max_grad_norm") is not None:
    out.append(_clip(recipe["max_grad_norm"]))
  if recipe.get("obs_clip") is not None:
    out.append(_obs_clip(recipe["obs_clip"]))
  return ", ".join(out)


def _matmuls(row: dict) -> str:
  """Runs at another float32 matmul precision than the backend's default are other runs (docs/rl_task_design.md,
  "TF32 in the simulation"); rows written before it was recorded ran at the default."""
  return runtime.matmul_label(row.get("matmul_precision", "default"))


def _clip(max_grad_norm: float | None) -> str:
  return "no gradient clipping" if max_grad_norm is None else f"grad-norm clip {max_grad_norm:g}"


def _obs_clip(bound: float) -> str:
  return f"observations clipped at ±{bound:g}"


def _scores(by_action: dict | None, head: dict, head_action: str, action: str) -> dict | None:
  """The run's final evaluation by ``action``: its by-action entry, or the row itself when that is the action."""
  if by_action and action in by_action:
    return by_action[action]
  return head if head_action == action else None


def brax_runs(doc: dict, source: str, action: str) -> list[dict]:
  runs = []
  for r in doc["rows"]:
    init = r.get("init_from")
    actor = f"actor from {os.path.basename(init)} seed {r.get('init_seed')}" if init else ""
    if r.get("continued_from"):  # one run over several calls (--continue-from): brax's optimizer restarted
      actor = ", ".join(x for x in (actor, "continued over calls") if x)
    s = _scores(r.get("by_action"), r, (r.get("eval_actions") or ["mode"])[0], action)
    runs.append(dict(trainer=BRAX, reward=_reward(r["damage_weight"]), seed=r["seed"], device=doc["device"],
                     settings=_settings(_std(r.get("recipe", {}).get("init_log_std")),
                                        _brax_changes(r.get("recipe", {})), _budget(r), _matmuls(r), actor,
                                        _task_settings(r.get("task_settings", doc.get("task_settings")),
                                                       r.get("eval_task_settings"))),
                     env_steps=r["env_steps"], scores=s, command=r["command"], source=source,
                     date=r.get("date"), t80=r.get("time_to_80_safe_s"),
                     # a run that shared its device with others has no comparable seconds
                     t80_scored=(r.get("scored_curve") or {}).get("action") == "mode"
                     and r.get("card_shared_by", 1) == 1, shared_by=r.get("card_shared_by", 1),
                     **_steps_to_safe((r.get("scored_curve") or {}).get("points") or []
                                      if (r.get("scored_curve") or {}).get("action") == "mode" else [],
                                      ("safe_completion", "completion", "wall_s"),
                                      timed=r.get("card_shared_by", 1) == 1)))
  return runs


def ours_runs(doc: dict, source: str, action: str) -> list[dict]:
  runs = []
  for r in doc["rows"]:
    kw = r["train_kwargs"]
    trainer = PAPER if kw.get("preset") == "paper" else f"ours ({kw.get('preset', 'default')} preset)"
    init = kw.get("init_from")
    actor = f"actor from {os.path.basename(init)}" + (f" seed {kw['init_seed']}" if "init_seed" in kw else "") if init else ""
    schedule = ", ".join(x for x in (
        "cost critic" if kw.get("cost_critic") else "",
        # presets' other choices, named only where a run changed them (train.config.PPOConfig)
        f"std a {kw['policy_std']}" if kw.get("policy_std") else "",
        f"target-KL rule {kw['target_kl_rule']}" if kw.get("target_kl_rule") else "",
        f"penalty off for the first {kw['damage_warmup_steps'] / 1e6:g} M" if kw.get("damage_warmup_steps") else "",
        f"penalty off until training completion ≥ {kw['damage_warmup_completion']:.0%}"
        if kw.get("damage_warmup_completion") else "",
        f"w ramped over {kw['damage_ramp_steps'] / 1e6:g} M" if kw.get("damage_ramp_steps") else "",
        f"critic warm-up {kw['critic_warmup_iterations']} iterations" if kw.get("critic_warmup_iterations") else "",
        "lr annealed" if kw.get("anneal_learning_rate") else "",
        "entropy annealed" if kw.get("anneal_entropy") else "",
        f"starts redrawn every {kw['redraw_starts_steps'] / 1e6:g} M steps" if kw.get("redraw_starts_steps") else "",
        _clip(kw["max_grad_norm"]) if "max_grad_norm" in kw else "",
        _obs_clip(kw["obs_clip"]) if kw.get("obs_clip") is not None else "",
        "GAE once per iteration" if kw.get("gae_per_iteration") else "",
        _matmuls(r))
        if x)
    head = (r.get("eval_actions") or ["mode"])[0]
    for p in r["per_seed"]:
      runs.append(dict(trainer=trainer, reward=_reward(kw.get("damage_weight", 0.0), r["method"], r["label"]),
                       seed=p["seed"], device=doc["device"].split(" (")[0],
                       settings=_settings(_std(kw.get("init_log_std")) if trainer != PAPER else "", schedule,
                                          actor, _task_settings(r.get("task_kwargs"), r.get("eval_task_kwargs"))),
                       env_steps=r["env_steps_per_seed"], planned=_planned(r, trainer),
                       scores=_scores(p.get("final_eval_by_action"), p["final_eval"], head, action),
                       command=r["command"], source=source, date=r.get("date"),
                       t80=p.get("time_to_80_safe_s"), t80_scored="time_to_80_safe_s" in p,
                       **_steps_to_safe([h for h in r.get("history") or [] if h.get("seed") == p["seed"]],
                                        ("eval/safe_completion", "eval/completion", "wall_time"))))
  return runs


def _planned(row: dict, trainer: str) -> int | None:
  """The env steps per seed a run of the paper's settings was to reach (the paper's updates, ``--paper-timesteps``)
  where it stopped short of them (its calls ran out); ``None`` for time-budgeted runs, whose ``num_timesteps`` is
  only a ceiling."""
  n = (row.get("config") or {}).get("num_timesteps")
  return n if trainer == PAPER and n and row["env_steps_per_seed"] < n else None


def _steps_to_safe(points: list[dict], keys: tuple, timed: bool = True) -> dict:
  """A run's env steps to its first evaluation by the mode with ≥ 80 % safe and ≥ 80 % completion (``s80``;
  None: not reached), whether its evaluations were scored that way at all (``s80_scored``), their spacing
  (``grain``: the median step between evaluations, env steps) and the run's env steps per second of its
  training clock at its last evaluation (``rate``; None for a run that shared its device). ``points``: its
  evaluations in order, each with ``env_steps`` and the ``keys`` (safe completion, completion, clock)."""
  safe, completion, clock = keys
  pts = [q for q in points if q.get(safe) is not None and q.get("env_steps") is not None]
  if not pts:
    return dict(s80=None, s80_scored=False, grain=None, rate=None)
  steps = [0] + [q["env_steps"] for q in pts if q["env_steps"] > 0]
  gaps = sorted(b - a for a, b in zip(steps, steps[1:]) if b > a)
  last = pts[-1]
  return dict(s80=time_to_safe(pts, keys=(safe, completion, "env_steps")), s80_scored=True,
              grain=gaps[len(gaps) // 2] if gaps else None,
              rate=last["env_steps"] / last[clock] if timed and last.get(clock) and last["env_steps"] else None)


def meets_bar(run: dict) -> bool:
  s = run["scores"]
  if run["reward"] == "task reward only":
    return s["safe_completion"] <= TASK_ONLY_BAR[0] and s["completion"] >= TASK_ONLY_BAR[1]
  return s["safe_completion"] >= DAMAGE_BAR[0] and s["completion"] >= DAMAGE_BAR[1]


def groups(runs: list[dict]) -> list[dict]:
  """Runs scored by the action, grouped by (trainer, reward, settings), in the order they first appear."""
  out: dict[tuple, dict] = {}
  for run in runs:
    key = (run["trainer"], run["reward"], run["settings"])
    g = out.setdefault(key, dict(trainer=key[0], reward=key[1], settings=key[2], runs=[], unscored=0))
    if run["scores"] is None:
      g["unscored"] += 1
    else:
      g["runs"].append(run)
  for g in out.values():
    rs = g["runs"]
    for m in ("completion", "safe_completion"):
      v = [r["scores"][m] for r in rs]
      g[m] = dict(mean=sum(v) / len(v), min=min(v), max=max(v)) if v else None
    g["meet_bar"] = sum(meets_bar(r) for r in rs)
    g["seeds"] = sorted({r["seed"] for r in rs})
    g["devices"] = sorted({r["device"] for r in rs})
    g["env_steps"] = (min(r["env_steps"] for r in rs), max(r["env_steps"] for r in rs)) if rs else None
    g["short"] = sum(r.get("planned") is not None for r in rs)
    timed = [r for r in rs if r["t80_scored"]]
    t = [r["t80"] for r in timed if r["t80"] is not None]
    g["time_to_80_safe"] = dict(scored=len(timed), reached=len(t), mean=sum(t) / len(t) if t else None,
                                min=min(t, default=None), max=max(t, default=None),
                                shared=sum(r.get("shared_by", 1) > 1 for r in rs))
    counted = [r for r in rs if r.get("s80_scored")]
    s = [r["s80"] for r in counted if r["s80"] is not None]
    g["env_steps_to_80_safe"] = dict(scored=len(counted), reached=len(s), mean=sum(s) / len(s) if s else None,
                                     min=min(s, default=None), max=max(s, default=None))
  return list(out.values())


def _pct(c: dict | None) -> str:
  if c is None:
    return "—"
  return f"{100 * c['mean']:.1f} ({100 * c['min']:.1f}–{100 * c['max']:.1f})"


def _steps(lo_hi) -> str:
  if lo_hi is None:
    return "—"
  lo, hi = lo_hi
  return f"{lo / 1e6:.1f} M" if lo == hi else f"{lo / 1e6:.1f}–{hi / 1e6:.1f} M"


def _group_steps(g: dict) -> str:
  short = g.get("short", 0)
  return _steps(g["env_steps"]) + (f" ({short} of {len(g['runs'])} stopped short of the planned)" if short else "")


def _run_steps(r: dict) -> str:
  planned = r.get("planned")
  return f"{r['env_steps'] / 1e6:.1f} M" + (f" of {planned / 1e6:.1f} M planned" if planned else "")


def _t80(t: dict, runs: int) -> str:
  """A group's time to 80 % safe: 'mean (min–max) s, k / n reached' over its timed runs."""
  if not t["scored"]:
    return "not timed (device shared)" if t.get("shared") == runs else "not scored"
  shared, unscored = t.get("shared", 0), runs - t["scored"] - t.get("shared", 0)
  rest = ", ".join(([f"{shared} not timed (device shared)"] if shared else [])
                   + ([f"{unscored} not scored"] if unscored > 0 else []))
  rest = f" ({rest})" if rest else ""
  if not t["reached"]:
    return f"none of {t['scored']} reached{rest}"
  span = f"{t['mean']:.0f}" if t["min"] == t["max"] else f"{t['mean']:.0f} ({t['min']:.0f}–{t['max']:.0f})"
  return f"{span}, {t['reached']} / {t['scored']} reached{rest}"


def _s80(s: dict, runs: int) -> str:
  """A group's env steps to 80 % safe: 'mean (min–max) M, k / n reached' over its runs scored by the mode."""
  if not s["scored"]:
    return "not scored"
  rest = f" ({runs - s['scored']} not scored)" if runs > s["scored"] else ""
  if not s["reached"]:
    return f"none of {s['scored']} reached{rest}"
  m = lambda v: f"{v / 1e6:.1f}"  # noqa: E731
  span = m(s["mean"]) if s["min"] == s["max"] else f"{m(s['mean'])} ({m(s['min'])}–{m(s['max'])})"
  return f"{span} M, {s['reached']} / {s['scored']} reached{rest}"


def _run_s80(r: dict) -> str:
  if not r.get("s80_scored"):
    return "not scored"
  every = f" (evaluations every {r['grain'] / 1e6:.1f} M)" if r.get("grain") else ""
  return ("not reached" if r["s80"] is None else f"{r['s80'] / 1e6:.1f} M") + every


def _run_rate(r: dict) -> str:
  return "—" if r.get("rate") is None else f"{r['rate'] / 1e3:.0f} k"


def _run_t80(r: dict) -> str:
  if r.get("shared_by", 1) > 1:  # a run's seconds while others ran on its device time nothing comparable
    return f"not timed (device shared by {r['shared_by']} runs)"
  if not r["t80_scored"]:
    return "not scored"
  return "not reached" if r["t80"] is None else f"{r['t80']:.0f}"


def render_md(doc: dict) -> str:
  a = doc["action"]
  lines = [
      f"# {doc['task']}: task reward only vs the damage penalty, by trainer", "",
      f"Every run's final policy scored by its **{a}** action. Bars: task reward only ≤ "
      f"{100 * TASK_ONLY_BAR[0]:.0f} % safe at ≥ {100 * TASK_ONLY_BAR[1]:.0f} % completion; damage-aware ≥ "
      f"{100 * DAMAGE_BAR[0]:.0f} % safe at ≥ {100 * DAMAGE_BAR[1]:.0f} % completion. Cells: mean (min–max) "
      "over the group's runs, %. Time to 80 % safe: s of training (compile incl.) to the first periodic "
      "evaluation by the mode with ≥ 80 % safe and ≥ 80 % completion (comparable only on one kind of device, "
      "each run alone on it; our trainer's seeds of one call train in one program and share its clock); env "
      "steps to 80 % safe: the same evaluation in the run's own env steps, any device (its grain, the "
      "evaluations' spacing, per run below). Built by:", "", f"    {doc['command']}", "",
      "| trainer | reward | settings | runs | seeds | devices | env steps per run | completion | "
      "safe completion | runs meeting the bar | time to 80 % safe (s) | env steps to 80 % safe |",
      "|---|---|---|---|---|---|---|---|---|---|---|---|"]
  for g in doc["groups"]:
    n = len(g["runs"])
    extra = f" ({g['unscored']} more not scored by {a})" if g["unscored"] else ""
    lines.append(f"| {g['trainer']} | {g['reward']} | {g['settings']} | {n}{extra} | "
                 f"{', '.join(map(str, g['seeds'])) or '—'} | {', '.join(g['devices']) or '—'} | "
                 f"{_group_steps(g)} | {_pct(g['completion'])} | {_pct(g['safe_completion'])} | {g['meet_bar']} / {n} "
                 f"| {_t80(g['time_to_80_safe'], n)} | {_s80(g['env_steps_to_80_safe'], n)} |")
  lines += ["", "Every run:", "",
            "| trainer | reward | settings | seed | device | env steps | completion | safe completion "
            "| time to 80 % safe (s) | env steps to 80 % safe | env steps per s | source | command |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
  for g in doc["groups"]:
    for r in g["runs"]:
      s = r["scores"]
      lines.append(f"| {r['trainer']} | {r['reward']} | {r['settings']} | {r['seed']} | {r['device']} | "
                   f"{_run_steps(r)} | {100 * s['completion']:.1f} % | {100 * s['safe_completion']:.1f} % | "
                   f"{_run_t80(r)} | {_run_s80(r)} | {_run_rate(r)} | {r['source']} | `{r['command']}` |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  a = parse(argv)
  runs = []
  for source, kind, doc in a.docs:
    runs += (brax_runs if kind == "brax" else ours_runs)(doc, source, a.action)
  command = "python benchmarks/trainer_table.py " + " ".join(
      shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
  out = dict(task=a.task, action=a.action, command=command, sources=[s for s, _, _ in a.docs], groups=groups(runs))
  io.write_json(a.out + ".json", out)
  io.write_text(a.out + ".md", render_md(out))
  print(f"wrote {a.out}.md / .json ({len(out['groups'])} groups, {len(runs)} runs)")
  return 0


if __name__ == "__main__":
  sys.exit(main())

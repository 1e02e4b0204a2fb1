"""Which strategy does the task reward alone pay for? Scripted safe vs unsafe (and trained policies), by discounted task return.

For each task (in its RL setting: Place Plate with ``obs_mode="paper"``, the
in-hand start), N randomised episodes of each scripted policy run through ONE
compiled ``jit(vmap(lax.scan(step)))`` executable (the policy is a per-episode
``lax.switch`` index, so each policy's batch is one call of the same program).
Per step it records the task reward (``info["task_reward"]``: the env's reward
before any damage shaping, i.e. what a task-only learner maximises), the
success flag and ``done``. Per task and policy it reports:

* discounted task return ``Σ_t γ^t r_t`` for each ``--gammas`` (0.97: Brax /
  Playground's PPO recipe; 0.99: the paper's), and the undiscounted return;
* steps to success (first step whose success condition holds), completion and
  safe completion (completed, every entity's final health > the env's safe
  threshold);
* the per-step reward trace: mean reward of each policy in windows of steps,
  and on how many steps the unsafe policy earns more than the safe one.

An episode ends at its first ``done`` (``terminate_on_success``); later steps
earn nothing. ``--style`` adds task-specific scripted styles beyond
``safe``/``unsafe`` when a task's ``policy`` accepts them, and ``TASK:still`` for
any task: the zero action at every step (the hand held where it is, the gripper
at the middle of its range), the policy a damage-aware learner falls back to
when every move it tries costs damage; its row against ``safe`` shows whether
keeping still or the safe strategy earns more, with and without the damage
penalty.
``TASK:STYLE+noise=SIGMA`` runs a style with N(0, SIGMA²) added to every action
entry (clipped): the scripted strategy as a Gaussian learner's exploration
perturbs it, e.g. whether the careful route still avoids damage at a policy's
initial standard deviation.
``TASK:checkpoint[+sample|+mean]:FILE#SEED`` (a policy as ``mjx-damage eval --policy``
names it) adds a trained policy: which of two learned strategies the task reward
pays more for, on the same episodes. The checkpoint must have been evaluated in
this run's settings (``--task-settings``, ``--robot``); a mismatch is refused.
``--baseline TASK:STYLE`` (default ``safe``) is the policy every other one of
the task is compared with, episode by episode.

Writes ``benchmarks/results/reward_preference[_TAG].{json,md}`` with the command. ``--robot`` (default the
gripper, the committed results' robot) is every task's robot; another robot writes
``reward_preference_ROBOT[_TAG]`` with the robot in the JSON. ``--task-settings`` takes no ``robot``.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/reward_preference.py --episodes 32 \
        [--tasks place_plate,pick_egg,shelve_item] [--gammas 0.97,0.99] [--tag before]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags and the jax compat shim before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import provenance  # noqa: E402  (the sibling module: command, git, date)
import tasks  # noqa: E402
from apps import resolve as R  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
RL_TASKS = ("place_plate", "pick_egg", "shelve_item")
WINDOW = 10  # steps per window of the reward-trace summary


STILL = "still"  # the zero action at every step
NOISE = "+noise="  # STYLE+noise=SIGMA: the scripted style with N(0, SIGMA²) added to every action entry


def still_policy(env):
  """``policy(state, rng) -> f32[A]``: the zero action (hand held, gripper at mid-range)."""
  size = env.action_size
  return lambda state, rng: jnp.zeros((size,), jnp.float32)


def parse_style(style: str) -> tuple[str, float]:
  """``"safe+noise=0.3"`` -> ``("safe", 0.3)``; a style without the suffix has noise 0."""
  base, sep, sigma = style.partition(NOISE)
  if not sep:
    return style, 0.0
  try:
    value = float(sigma)
  except ValueError:
    value = float("nan")
  if not base or not np.isfinite(value) or value < 0:
    raise ValueError(f"style: STYLE{NOISE}SIGMA needs a style and a finite SIGMA >= 0, got {style!r}")
  return base, value


def noisy_policy(policy, sigma: float):
  """``policy`` with N(0, sigma²) added to each action entry, clipped to [-1, 1]: what a Gaussian learner's
  exploration does to a scripted strategy (a policy's initial std: exp(init log-std), e.g. 0.61 for -0.5)."""
  if sigma == 0.0:
    return policy

  def act(state, rng):
    k_policy, k_noise = jax.random.split(rng)
    a = policy(state, k_policy)
    return jnp.clip(a + sigma * jax.random.normal(k_noise, a.shape, a.dtype), -1.0, 1.0)

  return act


def is_checkpoint(style: str) -> bool:
  """Whether a style names a trained policy (``checkpoint[+sample|+mean]:FILE#SEED``) rather than a script."""
  return style.partition(":")[0] in R.CHECKPOINT_ACTIONS


def make_policy(env, style: str):
  base, sigma = parse_style(style)
  if base == STILL:
    policy = still_policy(env)
  elif is_checkpoint(base):
    policy = R.make_policy(base, env)  # checks the checkpoint's observation and action sizes against env
  else:
    policy = env.unwrapped.policy(base)
  return noisy_policy(policy, sigma)


def trace_fn(env, policies, length: int):
  """``run(rngs u32[B, 2], which i32[B]) -> dict of f32[B, T] / f32[B, N]``, jitted.

  Per step: ``reward`` (task reward), ``success``, ``done``, ``cost`` (damage, health
  points summed over entities); at the end:
  ``health`` f32[B, N] (final entity health).
  """
  policies = tuple(policies)

  def episode(rng, which):
    r0, rp = jax.random.split(rng)
    state = env.reset(r0)

    def body(s, k):
      s = env.step(s, jax.lax.switch(which, policies, s, k))
      return s, (s.info["task_reward"], s.metrics["success"], s.done, s.info["cost"])

    state, (rew, succ, done, cost) = jax.lax.scan(body, state, jax.random.split(rp, length))
    return {"reward": rew, "success": succ, "done": done, "cost": cost, "health": state.info["entity_health"]}

  return jax.jit(jax.vmap(episode))


def episode_numbers(out: dict, gammas, safe_threshold: float, damage_weight: float) -> dict:
  """Per-episode numbers (numpy) from one policy's traces: returns, success step, completion, safety.

  ``return_g*``: discounted task return; ``shaped_g*``: discounted return of the damage-aware
  reward ``task − damage_weight · cost`` (what a w-weighted learner maximises).
  """
  rew, succ, done, cost = (np.asarray(out[k], np.float64) for k in ("reward", "success", "done", "cost"))
  T = rew.shape[1]
  # steps after the first done earn nothing (the episode has ended)
  ended_before = np.concatenate([np.zeros((rew.shape[0], 1)), np.cumsum(done, axis=1)[:, :-1]], axis=1) > 0
  alive = ~ended_before
  rew = np.where(alive, rew, 0.0)
  shaped = rew - damage_weight * np.where(alive, cost, 0.0)
  succ = np.where(alive, succ, 0.0)
  completed = succ.max(axis=1) > 0
  first = np.where(completed, np.argmax(succ > 0, axis=1) + 1, np.nan)  # control steps until success
  safe = completed & np.all(np.asarray(out["health"]) > safe_threshold, axis=-1)
  res = {"undiscounted": rew.sum(axis=1), "completed": completed, "safe": safe, "success_step": first,
         "reward": rew}
  for g in gammas:
    res[f"return_g{g:g}"] = (rew * g ** np.arange(T)).sum(axis=1)
    res[f"shaped_g{g:g}"] = (shaped * g ** np.arange(T)).sum(axis=1)
  return res


def _stat(x):
  x = np.asarray(x, np.float64)
  x = x[np.isfinite(x)]
  if x.size == 0:
    return {"mean": None, "min": None, "max": None}
  return {"mean": float(x.mean()), "min": float(x.min()), "max": float(x.max())}


def run_task(name: str, styles, episodes: int, gammas, seed: int, overrides: dict, damage_weight: float,
             robot: str = "gripper", baseline: str = "safe") -> dict:
  env = tasks.make(name, robot=robot, **overrides)
  task = env.unwrapped
  length = task.episode_length
  policies = [make_policy(env, s) for s in styles]
  run = trace_fn(env, policies, length)
  rngs = jax.random.split(jax.random.PRNGKey(seed), episodes)  # the same episodes for every policy
  t0 = time.time()
  compiled = run.lower(rngs, jnp.zeros((episodes,), jnp.int32)).compile()
  compile_s = time.time() - t0
  rows, per = [], {}
  t0 = time.time()
  for i, style in enumerate(styles):
    out = jax.device_get(compiled(rngs, jnp.full((episodes,), i, jnp.int32)))
    per[style] = episode_numbers(out, gammas, env.safe_threshold, damage_weight)
  run_s = time.time() - t0
  for style in styles:
    e = per[style]
    row = {"task": name, "policy": style, "episodes": episodes, "episode_length": length,
           "completion_pct": 100 * float(e["completed"].mean()),
           "safe_completion_pct": 100 * float(e["safe"].mean()),
           "undiscounted_return": _stat(e["undiscounted"]),
           "success_step": _stat(e["success_step"])}
    for g in gammas:
      row[f"return_gamma_{g:g}"] = _stat(e[f"return_g{g:g}"])
      row[f"shaped_return_gamma_{g:g}"] = _stat(e[f"shaped_g{g:g}"])
    mean_trace = e["reward"].mean(axis=0)
    row["reward_trace_windows"] = [float(mean_trace[i:i + WINDOW].mean()) for i in range(0, length, WINDOW)]
    rows.append(row)
  # paired comparison on the same episodes (same reset keys): policy − baseline, per step and per return
  # (the keys keep the names of the first comparison, unsafe vs safe: "unsafe" is the policy, "safe" the baseline)
  cmp = []
  base = per[baseline]
  for style in styles:
    if style == baseline:
      continue
    e = per[style]
    diff = e["reward"].mean(axis=0) - base["reward"].mean(axis=0)
    c = {"task": name, "policy": style, "vs": baseline,
         "steps_unsafe_earns_more": int((diff > 1e-6).sum()), "steps_safe_earns_more": int((diff < -1e-6).sum()),
         "first_step_unsafe_ahead": int(np.argmax(diff > 1e-6)) + 1 if (diff > 1e-6).any() else None,
         "undiscounted_diff_mean": float((e["undiscounted"] - base["undiscounted"]).mean())}
    for g in gammas:
      d = e[f"return_g{g:g}"] - base[f"return_g{g:g}"]
      ds = e[f"shaped_g{g:g}"] - base[f"shaped_g{g:g}"]
      c[f"return_gamma_{g:g}_diff_mean"] = float(d.mean())
      c[f"return_gamma_{g:g}_diff_min"], c[f"return_gamma_{g:g}_diff_max"] = float(d.min()), float(d.max())
      c[f"return_gamma_{g:g}_unsafe_higher_pct"] = 100 * float((d > 0).mean())
      c[f"shaped_return_gamma_{g:g}_diff_mean"] = float(ds.mean())
      c[f"shaped_return_gamma_{g:g}_diff_max"] = float(ds.max())
    cmp.append(c)
  return {"task": name, "overrides": overrides, "damage_weight": damage_weight, "styles": list(styles), "baseline": baseline,
          "compile_s": round(compile_s, 1),
          "run_s": round(run_s, 1), "rows": rows, "comparisons": cmp,
          "config": {k: v for k, v in tasks.default_config(name).items() if k != "params_fn"} | overrides
          | {"robot": robot}}


def _f(s, key="mean", fmt="{:.2f}"):
  v = s[key]
  return "–" if v is None else fmt.format(v)


def render_md(result: dict) -> str:
  gammas = result["gammas"]
  lines = [
      "# Reward preference: which strategy the task reward alone pays for (scripted safe vs unsafe, and any other policy)",
      "",
      f"Command: `{result['command']}`  ",
      f"jax {result['jax']} on {result['backend']} ({result['cpu_count']} CPU cores), {result['date']}, "
      f"git {result['git']}.",
      "",
      "Task reward = the env's reward before damage shaping (what a task-only learner maximises). "
      "Returns are means over the same randomised episodes for every policy (min–max in brackets); "
      "steps to success = control steps until the success condition first holds.",
      "",
      "| task | policy | completion % | safe completion % | "
      + " | ".join(f"return γ={g:g}" for g in gammas)
      + " | undiscounted return | steps to success (mean, min–max) |",
      "|---|---|---|---|" + "---|" * len(gammas) + "---|---|",
  ]
  for t in result["tasks"]:
    for r in t["rows"]:
      rets = " | ".join(
          f"{_f(r[f'return_gamma_{g:g}'])} ({_f(r[f'return_gamma_{g:g}'], 'min')}–{_f(r[f'return_gamma_{g:g}'], 'max')})"
          for g in gammas)
      ss = r["success_step"]
      lines.append(
          f"| {r['task']} | {r['policy']} | {r['completion_pct']:.1f} | {r['safe_completion_pct']:.1f} | {rets} "
          f"| {_f(r['undiscounted_return'])} | {_f(ss, 'mean', '{:.1f}')} ({_f(ss, 'min', '{:.0f}')}–"
          f"{_f(ss, 'max', '{:.0f}')}) |")
  lines += ["", "Paired differences (policy − the policy it is compared with, `vs`; same episodes; mean, min–max "
            "over episodes):", "",
            "| task | policy | vs | " + " | ".join(f"Δ return γ={g:g} (episodes policy higher)" for g in gammas)
            + " | Δ undiscounted | steps policy earns more / vs earns more | first step policy ahead | "
            + " | ".join(f"Δ return γ={g:g} with damage penalty w={result['damage_weight']:g} (max)" for g in gammas)
            + " |",
            "|---|---|---|" + "---|" * len(gammas) + "---|---|---|" + "---|" * len(gammas)]
  for t in result["tasks"]:
    for c in t["comparisons"]:
      d = " | ".join(f"{c[f'return_gamma_{g:g}_diff_mean']:+.2f}, {c[f'return_gamma_{g:g}_diff_min']:+.2f}–"
                     f"{c[f'return_gamma_{g:g}_diff_max']:+.2f} ({c[f'return_gamma_{g:g}_unsafe_higher_pct']:.0f} %)"
                     for g in gammas)
      lines.append(f"| {c['task']} | {c['policy']} | {c['vs']} | {d} | {c['undiscounted_diff_mean']:+.2f} "
                   f"| {c['steps_unsafe_earns_more']} / {c['steps_safe_earns_more']} | {c['first_step_unsafe_ahead']} | "
                   + " | ".join(f"{c[f'shaped_return_gamma_{g:g}_diff_mean']:+.1f} "
                                f"({c[f'shaped_return_gamma_{g:g}_diff_max']:+.1f})" for g in gammas) + " |")
  lines += ["", f"Mean task reward per step, in windows of {WINDOW} steps:", ""]
  for t in result["tasks"]:
    for r in t["rows"]:
      w = ", ".join(f"{x:.2f}" for x in r["reward_trace_windows"])
      lines.append(f"- {r['task']} / {r['policy']}: {w}")
  lines += ["", "Settings per task (make() overrides): "
            + "; ".join(f"{t['task']}: {t['overrides'] or 'defaults'}" for t in result["tasks"]), ""]
  trained = [(t["task"], s, k) for t in result["tasks"] for s, k in t.get("trained_settings", {}).items()]
  if trained:
    lines += ["Trained policies (each evaluated, in its run, in these settings; the same as the task's here):", ""]
    lines += [f"- {n} / `{s}`: {json.dumps(k, sort_keys=True)}" for n, s, k in trained]
    lines += [""]
  return "\n".join(lines)


def parse_args(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--tasks", default=",".join(RL_TASKS))
  p.add_argument("--episodes", type=int, default=32, help="episodes per policy (the same reset keys for each)")
  p.add_argument("--gammas", default="0.97,0.99")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--damage-weight", type=float, default=2.0,
                 help="w of the damage-aware return also reported (task − w·cost; the paper's w = 2)")
  p.add_argument("--style", action="append", default=[],
                 help="TASK:STYLE, an extra scripted style of a task, or TASK:still (the zero action), each "
                      "optionally with +noise=SIGMA (N(0, SIGMA²) added to every action entry, e.g. "
                      "shelve_item:safe+noise=0.3), or TASK:checkpoint[+sample|+mean]:FILE#SEED, a trained policy "
                      "(mjx-damage eval --policy's spec; repeatable)")
  p.add_argument("--baseline", action="append", default=[], metavar="TASK:STYLE",
                 help="the policy of TASK every other one is compared with, episode by episode (default safe; "
                      "STYLE: safe, unsafe or one of TASK's --style values)")
  p.add_argument("--task-settings", default=None, metavar="JSON",
                 help="task keyword arguments over each task's RL setting (tasks.RL_SETTINGS), e.g. "
                      "'{\"start\": \"pregrasp\"}'; the results record them")
  p.add_argument("--tag", default="", help="results file suffix: reward_preference_TAG.{json,md}")
  p.add_argument("--out-dir", default=RESULTS)
  p.add_argument("--robot", default="gripper",
                 help=f"robot of every task, one of {', '.join(tasks.robots.names())} (default: gripper, the robot "
                      "of the committed results); the results file gets _ROBOT unless it is the gripper")
  a = p.parse_args(argv)
  tasks.check_robot(a.robot, (), "--robot")
  a.task_list = [n for n in a.tasks.split(",") if n]
  a.settings = {}
  for n in a.task_list:
    tasks.task_class(n)  # ValueError listing the valid names, before anything compiles
    tasks.check_robot(a.robot, [n], "--robot")
    a.settings[n] = tasks.rl_settings(n, a.task_settings)
    given = json.loads(a.task_settings) if a.task_settings else {}  # valid JSON: rl_settings checked it
    if "robot" in given:  # one place for the robot: the file name and metadata follow --robot
      raise ValueError(f"task_settings: no 'robot' key (got {given['robot']!r}); give the robot with --robot")
    a.settings[n].pop("robot", None)  # the RL setting's robot gives way to --robot
  if isinstance(a.episodes, bool) or a.episodes < 1:
    raise ValueError(f"episodes: must be >= 1, got {a.episodes}")
  try:
    a.gamma_list = [float(g) for g in a.gammas.split(",") if g]
  except ValueError:
    raise ValueError(f"gammas: comma-separated numbers in (0, 1], got {a.gammas!r}") from None
  if not a.gamma_list or not all(0 < g <= 1 for g in a.gamma_list):
    raise ValueError(f"gammas: comma-separated numbers in (0, 1], got {a.gammas!r}")
  if not np.isfinite(a.damage_weight) or a.damage_weight < 0:
    raise ValueError(f"damage_weight: must be a finite number >= 0, got {a.damage_weight}")
  a.extra, a.trained = {}, {}
  for s in a.style:
    t, _, style = s.partition(":")
    if t not in a.task_list or not style:
      raise ValueError(f"style: expected TASK:STYLE with TASK in {a.task_list}, got {s!r}")
    base, _ = parse_style(style)  # a bad noise suffix is refused here, before anything compiles
    if is_checkpoint(base):
      a.trained.setdefault(t, {})[style] = _trained_settings(t, base, a.settings[t], a.robot)
    if style in ("safe", "unsafe") or style in a.extra.get(t, []):
      raise ValueError(f"style: {s!r} is given twice (safe and unsafe always run)")
    a.extra.setdefault(t, []).append(style)
  a.baselines = {}
  for s in a.baseline:
    t, _, style = s.partition(":")
    if t not in a.task_list or style not in ["safe", "unsafe"] + a.extra.get(t, []):
      raise ValueError(f"baseline: expected TASK:STYLE with TASK in {a.task_list} and STYLE safe, unsafe or one "
                       f"of the task's --style values, got {s!r}")
    if t in a.baselines:
      raise ValueError(f"baseline: one per task; {t} has {a.baselines[t]!r} and {style!r}")
    a.baselines[t] = style
  return a


def _trained_settings(task: str, spec: str, settings: dict, robot: str) -> dict:
  """The settings a checkpoint style's run evaluated it in (``apps.resolve.checkpoint_task_kwargs``), refused
  (ValueError naming the keys) unless they are this run's: the reward is compared on the same task."""
  R.parse_policy_spec(spec)  # the file exists; the seed is one of its run's
  trained = R.checkpoint_task_kwargs(spec, task)  # its task is this task
  mine, default = dict(settings, robot=robot), tasks.default_config(task)
  differ = sorted(k for k in set(trained) | set(mine) if trained.get(k, default.get(k)) != mine.get(k, default.get(k)))
  if differ:
    raise ValueError(f"style: checkpoint {spec!r} was evaluated with "
                     f"{ {k: trained.get(k, default.get(k)) for k in differ} }, this run has "
                     f"{ {k: mine.get(k, default.get(k)) for k in differ} } (give them with --task-settings or --robot)")
  return trained


def main(argv=None) -> int:
  a = parse_args(argv)
  command = provenance.command("reward_preference", argv)
  result = {"command": command.strip(), "gammas": a.gamma_list, "damage_weight": a.damage_weight, "jax": jax.__version__,
            "backend": jax.default_backend(), "machine": platform.machine(), "cpu_count": os.cpu_count(),
            "date": provenance.now(), "git": provenance.git(), "tasks": []}
  robot = "" if a.robot == "gripper" else f"_{a.robot}"  # gripper: the committed results' names and fields
  if robot:
    result["robot"] = a.robot
  stem = os.path.join(a.out_dir, "reward_preference" + robot + (f"_{a.tag}" if a.tag else ""))
  for n in a.task_list:
    styles = ["safe", "unsafe"] + a.extra.get(n, [])
    t = run_task(n, styles, a.episodes, a.gamma_list, a.seed, a.settings[n], a.damage_weight, a.robot,
                 a.baselines.get(n, "safe"))
    if a.trained.get(n):
      t["trained_settings"] = a.trained[n]
    result["tasks"].append(t)
    for c in t["comparisons"]:
      print(f"{n} {c['policy']} - {c['vs']}: " + ", ".join(
          f"γ={g:g} {c[f'return_gamma_{g:g}_diff_mean']:+.2f}" for g in a.gamma_list), flush=True)
    write_json(stem + ".json", result)  # partial results survive an interrupted run
    write_text(stem + ".md", render_md(result))
  print(f"wrote {stem}.json / .md")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

"""Scripted safe vs unsafe policies on every registered task: does the damage signal tell them apart?

For each task, 256 randomised episodes of each scripted policy (safe, unsafe)
run through ONE batched, compiled executable (``jit(vmap(lax.scan(step)))``,
the policy chosen per episode; ``--chunk`` splits the batch into equal calls
of that executable), and the DAMAGE_MODEL.md §7
metrics are written to ``benchmarks/results/scripted_policies.{md,json}``:
completion %, safe completion % (completed and every entity's final health
> 95), average environment health, zero-damage rate %, plus the first-compile
time of the task's batched rollout (reset + policy + step; one compilation
serves both policies) and the time of the compiled run.

Targets (issue #4): safe policy completion ≥ 95 % and safe completion ≥ 90 %;
unsafe policy completion ≥ 80 % and safe completion ≤ 10 %.

``--robot`` picks the robot (:func:`tasks.robots.names`; default the gripper);
``--rl-settings`` builds each task in its RL setting (``tasks.RL_SETTINGS``, e.g.
Pick Egg's carry to a goal) instead of its defaults; ``--name`` the results' file
stem (default ``scripted_policies`` for the gripper with default settings,
``scripted_policies_rl`` with ``--rl-settings``, ``scripted_policies_<robot>_<backend>``
otherwise).

Usage::

    .venv/bin/python benchmarks/scripted_policies.py [--episodes 256] [--chunk 64] [--tasks a,b] [--seed 0] \
        [--robot panda] [--name scripted_policies_panda_cpu] [--rl-settings]
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import os
import platform
import signal
import sys
import time

faulthandler.register(signal.SIGUSR1)  # `kill -USR1 <pid>` prints where a long run is

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

# First-compile times are only meaningful without the persistent cache: switch it off here.
jax.config.update("jax_enable_compilation_cache", False)

import tasks  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from tasks import robots  # noqa: E402
from tasks.rollout import rollout_fn, summarise  # noqa: E402

RESULTS = os.path.join(os.path.dirname(__file__), "results")
STYLES = ("safe", "unsafe")
ROBOT = "gripper"  # the committed results' robot; robots.DEFAULT may differ
COMMAND = ""


def meets_target(style: str, row: dict) -> bool:
  if style == "safe":
    return row["completion_pct"] >= 95.0 and row["safe_completion_pct"] >= 90.0
  return row["completion_pct"] >= 80.0 and row["safe_completion_pct"] <= 10.0


def run_task(name: str, episodes: int, seed: int, chunk: int, robot: str = ROBOT,
             settings: dict | None = None) -> list[dict]:
  """Both policies' episodes of one task; ``chunk`` episodes per policy per compiled call.

  All calls reuse ONE compiled executable (same shapes). ``chunk = episodes``
  (the default) is a single call. Chunks only bound memory on small machines:
  the XLA:CPU stall that once made them necessary is fixed by the scheduler
  flag ``import mjx_damage`` sets (mjx_damage/runtime.py, docs/cpu_stall.md).
  """
  if episodes % chunk:
    raise ValueError(f"chunk: must divide episodes ({episodes}), got {chunk}")
  settings = dict(settings or {})
  env = tasks.make(name, robot=robot, **settings)
  length = env.unwrapped.episode_length
  run = rollout_fn(env, [tasks.scripted_policy(env, s) for s in STYLES], length)
  rngs = jax.random.split(jax.random.PRNGKey(seed), len(STYLES) * episodes).reshape(len(STYLES), episodes, -1)
  which = jnp.repeat(jnp.arange(len(STYLES))[:, None], chunk, axis=1).reshape(-1)

  def batch(i):  # chunk i of every policy, policy-major
    return rngs[:, i * chunk : (i + 1) * chunk].reshape(len(STYLES) * chunk, -1)

  t0 = time.time()
  compiled = run.lower(batch(0), which).compile()
  t_compile = time.time() - t0
  t0 = time.time()
  parts = [jax.block_until_ready(compiled(batch(i), which)) for i in range(episodes // chunk)]
  t_run = time.time() - t0
  # regroup policy-major: [policy, chunk, episode] -> [policy * episodes]
  stats = jax.tree.map(
      lambda *xs: jnp.concatenate([x.reshape((len(STYLES), chunk) + x.shape[1:]) for x in xs], axis=1).reshape(
          (len(STYLES) * episodes,) + xs[0].shape[1:]), *parts)
  rows = []
  for i, style in enumerate(STYLES):
    sub = jax.tree.map(lambda x: x[i * episodes : (i + 1) * episodes], stats)
    row = {"task": name, "robot": robot, "settings": settings, "policy": style, "episode_length": length,
           "entities": list(env.entity_names)}
    row.update(summarise(sub))
    row["first_compile_s"] = round(t_compile, 1)
    row["run_s"] = round(t_run, 1)
    row["calls"] = episodes // chunk
    row["meets_target"] = meets_target(style, row)
    row["command"] = COMMAND
    rows.append(row)
    print(json.dumps(row), flush=True)
  return rows


def write(rows: list[dict], command: str, stem: str = "scripted_policies") -> None:
  """Write the table; rows of tasks not in this run are kept from the existing JSON (each row names its command)."""
  os.makedirs(RESULTS, exist_ok=True)
  path = os.path.join(RESULTS, stem + ".json")
  done = {r["task"] for r in rows}
  if os.path.exists(path):
    with open(path) as f:
      old = json.load(f).get("rows", [])
    rows = [r for r in old if r["task"] not in done] + rows
  order = {n: i for i, n in enumerate(tasks.names())}
  rows = sorted(rows, key=lambda r: (order.get(r["task"], 99), STYLES.index(r["policy"])))
  meta = {
      "command": command,
      "jax": jax.__version__, "backend": jax.default_backend(), "machine": platform.processor() or platform.machine(),
      "cpu_count": os.cpu_count(),
      "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
  }
  write_json(path, {"meta": meta, "rows": rows}, indent=1)
  robot_names = sorted({r.get("robot", ROBOT) for r in rows})  # rows without one: before --robot, the gripper
  lines = [
      "# Scripted safe vs unsafe policies (DAMAGE_MODEL.md §7 metrics)",
      "",
      f"Robot: {', '.join(robot_names)}.  ",
      f"Command (latest run; each JSON row records the command that produced it): `{command}`  ",
      f"jax {meta['jax']} on {meta['backend']} ({meta['cpu_count']} CPU cores, shared), {meta['date']}.",
      "Per task: ONE compiled `jit(vmap(scan))` executable runs the episodes of both policies (policy chosen per "
      "episode), called `episodes/chunk` times on 2×chunk episodes (`calls` in the JSON); first-compile time is "
      "its compilation with the persistent cache off (reset + policy + step with damage at every substep), "
      "run s the compiled calls. Chunks only bound memory (the XLA:CPU stall that once required them is fixed: "
      "docs/cpu_stall.md).",
      "Targets: safe completion ≥ 95 % and safe-completion ≥ 90 %; unsafe completion ≥ 80 % and safe-completion ≤ 10 %.",
      "",
      "Mean episode damage per model (mech / therm / fluid, health points; '–' for rows measured before it was "
      "recorded) shows which damage model each unsafe shortcut triggers.",
      "",
      "| task | policy | episodes | completion % | safe completion % | avg env health | zero-damage % | mean episode cost "
      "| mech / therm / fluid | first compile s | run s | target |",
      "|---|---|---|---|---|---|---|---|---|---|---|---|",
  ]

  def per_model(r):
    if "mean_damage_mechanical" not in r:
      return "–"
    return " / ".join(f"{r[f'mean_damage_{m}']:.1f}" for m in ("mechanical", "thermal", "fluid"))

  for r in rows:
    lines.append(
        f"| {r['task']} | {r['policy']} | {r['episodes']} | {r['completion_pct']:.1f} | {r['safe_completion_pct']:.1f} "
        f"| {r['avg_env_health']:.1f} | {r['zero_damage_pct']:.1f} | {r['mean_episode_cost']:.1f} | {per_model(r)} "
        f"| {r['first_compile_s']:.0f} | {r['run_s']:.0f} | {'met' if r['meets_target'] else 'MISSED'} |"
    )
  settings = {r["task"]: r["settings"] for r in rows if r.get("settings")}
  if settings:
    lines += ["", "Settings (make() overrides, the tasks' RL settings): "
              + "; ".join(f"{n}: {v}" for n, v in settings.items()) + "; other tasks: defaults."]
  lines += ["", "Mean final health per entity:", ""]
  for r in rows:
    ents = ", ".join(f"{n} {h:.1f}" for n, h in zip(r["entities"], r["entity_health_mean"]))
    lines.append(f"- {r['task']} / {r['policy']}: {ents}")
  write_text(os.path.join(RESULTS, stem + ".md"), "\n".join(lines) + "\n")


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--episodes", type=int, default=256)
  p.add_argument("--tasks", default=None, help="comma-separated (default: every task --robot runs)")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--chunk", type=int, default=0, help="episodes per policy per compiled call (default: all in one)")
  p.add_argument("--robot", default=ROBOT,
                 help=f"one of {', '.join(robots.names())} (default {ROBOT}, the robot of the committed results)")
  p.add_argument("--rl-settings", action="store_true",
                 help="build each task in its RL setting (tasks.RL_SETTINGS) instead of its defaults")
  p.add_argument("--name", default=None, help="results file stem under benchmarks/results (see the module docstring)")
  a = p.parse_args(argv)
  robots.robot_class(a.robot)  # ValueError listing the valid robots, before anything compiles
  stem = a.name or (("scripted_policies_rl" if a.rl_settings else "scripted_policies") if a.robot == ROBOT
                    else f"scripted_policies_{a.robot}_{jax.default_backend()}")
  if not stem or os.sep in stem or stem.startswith("."):
    raise ValueError(f"name: must be a plain file stem, got {stem!r}")
  # ValueError naming tasks or robot (unknown, listed twice, or not run by --robot) before anything compiles
  names = tasks.select(None if a.tasks is None else [n for n in a.tasks.split(",") if n], a.robot)
  global COMMAND
  flags = os.environ.get("XLA_FLAGS")
  command = (f"XLA_FLAGS={flags} " if flags else "") + ".venv/bin/python benchmarks/scripted_policies.py " + " ".join(
      argv if argv is not None else sys.argv[1:])
  COMMAND = command.strip()
  rows = []
  for n in names:
    rows += run_task(n, a.episodes, a.seed, a.chunk or a.episodes, a.robot,
                     tasks.rl_overrides(n) if a.rl_settings else {})
    write(rows, command.strip(), stem)  # partial results survive an interrupted run
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

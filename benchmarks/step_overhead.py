"""Whole task step vs raw physics: where a registered task's env step spends its time.

For each task (``tasks.make(name)``, the damage wrapper included) and one batch
size, every variant is one ``jit`` of a ``lax.scan`` over ``--steps`` control
steps of ``vmap(step)``, compiled ahead of time and timed after one warm-up call
(best of ``--repeats``), every timed call from the state the warm-up call ended in (so all
repeats time the same physics: MJX's solver loop, vmapped, runs until every env has
converged, so the cost of a step follows what the batch is doing). Variants:

* ``task``          — policy + ``env.step`` (what training runs);
* ``zeros_policy``  — ``env.step`` with zero actions (the robot then stays put: other physics);
* ``no_policy``     — ``env.step`` from the ``task`` variant's timed start with the very actions its
                      policy chose there (recorded from one run of it): the task step, same physics,
                      without the policy's forward pass and sampling;
* ``no_wrapper``    — the bare task's step (``env.unwrapped``) with the policy: the damage
                      wrapper's bookkeeping (health summaries, episode stats, reset masks);
* ``no_liquid``     — the task step with the liquid model not advanced (tasks with liquid);
* ``no_pairs``      — liquid advanced without particle–particle pairs (tasks with liquid);
* ``no_temperature``— the task step with the temperature model not advanced (tasks with heat);
* ``no_damage``     — the task step with the substeps as plain ``mjx.step`` (no damage
                      signals, temperature or liquid): policy, observation, reward, wrapper;
* ``raw``           — ``n_substeps × mjx.step`` of the same model and batch (no policy, no task),
                      controls held at their reset values;
* ``raw_moving``    — the same with the controls the task's ``robot.ctrl`` makes of uniform
                      random actions each step: MJX's solver stops early once every env has
                      converged, so a moving robot can cost more physics than one at rest.
* ``raw_replay``    — ``n_substeps × mjx.step`` from the ``task`` variant's timed start, replaying the
                      very controls that variant applies from there (recorded from one run of it): the
                      same physics the task step does, with nothing else. ``task`` over
                      ``raw_replay`` is the share of the step that is physics.

The ``ratio`` column is env-steps/s of the variant over ``raw``; ``share of task
step`` is the time the variant removes, 1 − t_variant / t_task. The policy
(``--policy``) is an untrained Brax PPO MLP (``mlp``: 256 × 256 swish, tanh-normal
sampling, as ``train/``), ``zeros`` or the task's scripted ``safe`` policy.

    python benchmarks/step_overhead.py --envs 32768                      # GPU, all variants
    python benchmarks/step_overhead.py --envs 64 --steps 10 --variants task,raw   # CPU smoke
    python benchmarks/step_overhead.py --tasks add_firewood,...,wipe_counter --variants task,raw \
        --envs 32768 --precompile-workers 8 [--robot panda]      # the every-task table, one GPU

``--robot`` runs every task with that robot (rows record it). ``--precompile-workers N``
compiles every (task, variant) program first in N parallel child processes, which fill JAX's
persistent compilation cache; this process then times them one after another, loading each
from the cache. Compiles dominate a many-task run (20–60 s each, one CPU thread each), and
timings must not share the device, so this splits the two.

Writes ``benchmarks/results/step_overhead_<device>.{json,md}`` (``--out-dir``) with the command.
A run merges into an existing file of the same device, batch size, steps, policy and
clock: the (task, variant) rows it measured are replaced and the others kept (so one
long measurement can be split into several commands, e.g. under a per-command time
limit); the
``commands`` list records every command that contributed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))  # the repo's packages, wherever this is run from

VARIANTS = ("task", "zeros_policy", "no_policy", "no_wrapper", "no_liquid", "no_pairs", "no_temperature", "no_damage",
            "raw", "raw_moving", "raw_replay")
POLICIES = ("mlp", "zeros", "scripted")
ROBOT = "gripper"  # the committed results' robot; tasks.robots.DEFAULT may differ


def make_policy(env, kind: str):
  """``policy(state, rng) -> action f32[A]`` for one env."""
  import jax
  import jax.numpy as jnp

  if kind == "zeros":
    return lambda s, k: jnp.zeros((env.action_size,), jnp.float32)
  if kind == "scripted":
    import tasks

    return tasks.scripted_policy(env, "safe")
  from brax.training.agents.ppo import networks as ppo_networks

  nets = ppo_networks.make_ppo_networks(env.observation_size, env.action_size,
                                        policy_hidden_layer_sizes=(256, 256), value_hidden_layer_sizes=(256, 256))
  params = nets.policy_network.init(jax.random.PRNGKey(0))
  infer = ppo_networks.make_inference_fn(nets)((None, params), deterministic=False)
  return lambda s, k: infer(s.obs, k)[0]


def _physics_override(task, variant: str):
  """The task's ``physics_step`` for a variant that switches a model off, or None."""
  from mjx_damage import physics

  b, sys_, n = task.damage_binding, task.sys, task.n_substeps
  if variant == "no_damage":
    return lambda d, ds, ctrl: (physics.step_without_damage(sys_, d.replace(ctrl=ctrl), n), ds)
  if variant == "no_liquid":
    b = dataclasses.replace(b, liquid=None)  # state kept, never advanced
  elif variant == "no_pairs":
    b = dataclasses.replace(b, liquid=b.liquid.replace(pair_stiffness=0.0))
  elif variant == "no_temperature":
    b = dataclasses.replace(b, thermal=None)
  else:
    return None
  return lambda d, ds, ctrl: physics.step(sys_, b, d.replace(ctrl=ctrl), ds, n)


def _policy_step(stepper, policy, carry):
  """One step of ``vmap(policy)`` + ``vmap(stepper.step)`` from ``carry`` = (state, key): (carry, actions)."""
  import jax

  s, k = carry
  k, kp = jax.random.split(k)
  a = jax.vmap(policy)(s, jax.random.split(kp, s.obs.shape[0]))
  return (jax.vmap(stepper.step)(s, a), k), a


def _policy_rollout(stepper, policy, carry, steps: int, record=lambda s: None):
  """``steps`` :func:`_policy_step` from ``carry`` = (state, key) in one scan: (final carry, ``record(state)``
  after each step, stacked). The ``task`` variants time it; ``raw_replay`` records the controls it applied."""
  import jax

  def body(c, _):
    c, _ = _policy_step(stepper, policy, c)
    return c, record(c[0])

  return jax.lax.scan(body, carry, None, length=steps)


def _timed_start(env, policy, state, steps: int):
  """(state, key) where the ``task`` variant's timed calls start: after its warm-up call from ``state``."""
  import jax

  return jax.jit(lambda c: _policy_rollout(env, policy, c, steps)[0])((state, jax.random.PRNGKey(1)))


def _task_controls(env, policy, state, steps: int, key=None):
  """The controls (``d.ctrl`` after each step, f32[steps, envs, nu]) of ``steps`` task steps from ``state``
  with the rollout key ``key`` (default ``PRNGKey(1)``).

  Given the ``task`` variant's timed start (state and key), ``raw_replay`` steps the very physics
  that variant's policy drove."""
  import jax

  key = jax.random.PRNGKey(1) if key is None else key
  rollout = lambda s, k: _policy_rollout(env, policy, (s, k), steps,  # noqa: E731
                                         lambda s: s.pipeline_state.ctrl)[1]
  return jax.jit(rollout)(state, key)


def _task_actions(env, policy, carry, steps: int):
  """The actions (f32[steps, envs, A]) the policy picks in ``steps`` task steps from ``carry`` = (state, key),
  drawn as :func:`_policy_rollout` draws them: ``no_policy`` steps them without the policy."""
  import jax

  chosen = lambda c: jax.lax.scan(lambda c, _: _policy_step(env, policy, c), c, None, length=steps)[1]  # noqa: E731
  return jax.jit(chosen)(carry)


def applicable(task, variant: str) -> bool:
  b = task.damage_binding
  if variant in ("no_liquid", "no_pairs"):
    return b.liquid is not None and (variant == "no_liquid" or b.liquid.pair_stiffness > 0)
  if variant == "no_temperature":
    return b.thermal is not None
  return True


def measure(name: str, variant: str, envs: int, steps: int, repeats: int, policy_kind: str, clock=time.perf_counter,
            robot: str = ROBOT, compile_only: bool = False) -> dict | None:
  """One (task, variant) row; ``compile_only``: compile (filling the persistent cache) and return None."""
  import jax
  import jax.numpy as jnp

  import tasks
  from mjx_damage import physics

  env = tasks.make(name, robot=robot)
  task = env.unwrapped
  override = _physics_override(task, variant)
  if override is not None:
    task.physics_step = override  # instance attribute: this env object only
  policy = make_policy(env, "zeros" if variant == "zeros_policy" else policy_kind)
  stepper = task if variant == "no_wrapper" else env
  keys = jax.random.split(jax.random.PRNGKey(0), envs)
  state = jax.jit(jax.vmap(stepper.reset))(keys)

  # Every timed call starts from the same state: the one after this variant's warm-up call (for
  # raw_replay, after a warm-up call of the task rollout). Calls that continued from the last one timed
  # later and later parts of the episode, and raw_replay (controls recorded from the reset state)
  # then stepped other physics than the task call it was compared with.
  if variant in ("raw", "raw_moving"):
    n, moving = task.n_substeps, variant == "raw_moving"

    def one(d, k):
      if moving:
        a = jax.random.uniform(k, (env.action_size,), minval=-1.0, maxval=1.0)
        d = d.replace(ctrl=task.robot.ctrl(d, a, task.ws_lo, task.ws_hi))
      return physics.step_without_damage(task.sys, d, n)

    def run(carry):
      def body(c, _):
        d, k = c
        k, kp = jax.random.split(k)
        return (jax.vmap(one)(d, jax.random.split(kp, envs)), k), None
      return jax.lax.scan(body, carry, None, length=steps)[0]

    carry = (state.pipeline_state, jax.random.PRNGKey(1))
  elif variant == "no_policy":
    warm = _timed_start(env, policy, state, steps)
    actions = _task_actions(env, policy, warm, steps)  # what the policy picks from the task's timed start

    def run(carry):
      s, actions = carry
      return jax.lax.scan(lambda s, a: (jax.vmap(env.step)(s, a), None), s, actions)[0], actions

    carry = (warm[0], actions)
  elif variant == "raw_replay":
    n = task.n_substeps
    warm = _timed_start(env, policy, state, steps)
    ctrls = _task_controls(env, policy, warm[0], steps, warm[1])  # f32[steps, envs, nu], what `task` applies from there

    def run(carry):
      def body(d, ctrl):
        return jax.vmap(lambda d1, c1: physics.step_without_damage(task.sys, d1.replace(ctrl=c1), n))(d, ctrl), None
      d, ctrls = carry
      return jax.lax.scan(body, d, ctrls)[0], ctrls

    carry = (warm[0].pipeline_state, ctrls)
  else:
    def run(carry):
      return _policy_rollout(stepper, policy, carry, steps)[0]

    carry = (state, jax.random.PRNGKey(1))
  hits = CACHE_HITS[0]
  t0 = time.perf_counter()
  compiled = jax.jit(run).lower(carry).compile()
  compile_s = time.perf_counter() - t0
  from_cache = CACHE_HITS[0] > hits
  if compile_only:
    print(f"{name:12s} {variant:15s} compiled in {compile_s:.0f} s", flush=True)
    return None
  if variant in ("raw_replay", "no_policy"):
    jax.block_until_ready(compiled(carry))  # warm-up (its start already is the task's timed start)
  else:
    carry = jax.block_until_ready(compiled(carry))  # warm-up; every timed call starts here
  best, out = float("inf"), None
  for _ in range(repeats):
    t0 = clock()
    out = jax.block_until_ready(compiled(carry))
    best = min(best, clock() - t0)
  last = out[0]
  d = last if variant.startswith("raw") else last.pipeline_state
  row = {
      "task": name, "robot": robot, "variant": variant, "envs": envs, "steps": steps,
      "env_steps_per_s": envs * steps / best, "wall_s": best, "compile_s": compile_s, "from_cache": from_cache,
      "finite": bool(jnp.all(jnp.isfinite(d.qpos))),
  }
  print(f"{name:12s} {variant:15s} {row['env_steps_per_s']:>12,.0f} env-steps/s  (compile {compile_s:.0f} s"
        f"{', from the cache' if from_cache else ''})", flush=True)
  return row


CACHE_HITS = [0]  # persistent-cache hits of this process (jax.monitoring), to tell a cache load from a compile


def _count_hit(event: str, **_) -> None:
  if event == "/jax/compilation_cache/cache_hits":
    CACHE_HITS[0] += 1


def precompile(argv: list[str], pairs: list[tuple[str, str]], workers: int) -> None:
  """Compiles ``pairs`` in ``workers`` child processes (this script, ``--compile-only``, a share each).

  The children write JAX's persistent compilation cache; the timing process then loads each
  program from it instead of compiling it, so compiles run in parallel and timings do not share
  the device with anything. On a GPU the children allocate memory as they need it."""
  import subprocess

  from apps.workers import argv_without
  from mjx_damage import runtime

  if runtime.cache_dir() is None:
    raise SystemExit("--precompile-workers: the persistent compilation cache is off (MJX_DAMAGE_CACHE_DIR); "
                     "nothing would carry the compiled programs over")
  base = argv_without(argv, ("--precompile-workers", "--tasks", "--variants"))
  env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")
  shares = [pairs[i::workers] for i in range(workers) if pairs[i::workers]]
  procs = []
  for share in shares:  # one shell per share, running one child per (task, variant) pair of it in turn
    cmds = [[sys.executable, os.path.abspath(__file__), *base, "--tasks", n, "--variants", v, "--compile-only"]
            for n, v in share]
    procs.append(subprocess.Popen("; ".join(shlex.join(c) for c in cmds), shell=True, env=env))
  codes = [q.wait() for q in procs]
  if any(codes):
    print(f"precompile: some workers failed (exit codes {codes}); those programs compile while timing", flush=True)


def summarise(rows: list[dict]) -> list[dict]:
  """Adds ``ratio_to_raw``, ``ratio_to_replay`` and ``share_of_task_step`` to each row (per task)."""
  robot = lambda r: r.get("robot", "gripper")  # noqa: E731  (rows written before --robot: the gripper)
  rows = sorted(rows, key=lambda r: (r["task"], robot(r), VARIANTS.index(r["variant"])))
  by = {(r["task"], robot(r), r["variant"]): r for r in rows}
  for r in rows:
    raw, task = by.get((r["task"], robot(r), "raw")), by.get((r["task"], robot(r), "task"))
    replay = by.get((r["task"], robot(r), "raw_replay"))
    r["ratio_to_raw"] = r["env_steps_per_s"] / raw["env_steps_per_s"] if raw else None
    r["ratio_to_replay"] = r["env_steps_per_s"] / replay["env_steps_per_s"] if replay else None
    r["share_of_task_step"] = 1.0 - r["wall_s"] / task["wall_s"] if task and r["variant"] != "task" else None
  return rows


def markdown(record: dict) -> str:
  lines = [
      *(f"Command: `{c}`  " for c in record["commands"]),
      f"Device: {record['device']} · {record['envs']} envs · {record['steps']} control steps per timed call · "
      f"policy {record['policy']} · {record['clock']} clock · {record['timestamp_utc']}",
      "",
      "ratio = env-steps/s over `raw` (n_substeps × mjx.step, same model and batch); share = time the variant "
      "removes from the task step (1 − t_variant / t_task); ratio to the same physics = env-steps/s over "
      "`raw_replay` (the controls the task step applied, replayed through n_substeps × mjx.step).",
      "",
      "| task | robot | variant | env-steps/s | ratio to raw | ratio to the same physics | share of task step | compile s |",
      "|---|---|---|---:|---:|---:|---:|---:|",
  ]
  for r in record["results"]:
    ratio = "" if r["ratio_to_raw"] is None else f"{r['ratio_to_raw']:.3f}"
    share = "" if r["share_of_task_step"] is None else f"{100 * r['share_of_task_step']:.1f} %"
    same = "" if r.get("ratio_to_replay") is None else f"{r['ratio_to_replay']:.3f}"
    lines.append(f"| {r['task']} | {r.get('robot', 'gripper')} | {r['variant']} | {r['env_steps_per_s']:,.0f} | {ratio} | "
                 f"{same} | {share} | {r['compile_s']:.0f} |")
  return "\n".join(lines) + "\n"


def write(stem: str, a, argv, rows: list, old) -> None:
  """Results so far into ``stem``.json/.md, merged with an earlier file of the same setting (rows replaced by key)."""
  from mjx_damage import io, runtime

  record = {
      "benchmark": "step_overhead",
      "command": " ".join(shlex.quote(x) for x in [sys.executable, *(sys.argv if argv is None else ["benchmarks/step_overhead.py", *argv])]),
      **runtime.run_facts(),
      "envs": a.envs,
      "steps": a.steps,
      "repeats": a.repeats,
      "policy": a.policy,
      "clock": a.clock,
      "results": summarise(rows),
  }
  record["commands"] = [record["command"]]
  if old is not None and all(old.get(k) == record[k] for k in ("device", "envs", "steps", "policy", "clock")):
    key = lambda r: (r["task"], r.get("robot", "gripper"), r["variant"])  # noqa: E731
    new = {key(r) for r in rows}
    kept = [r for r in old["results"] if key(r) not in new]
    record["results"] = summarise(kept + rows)
    record["commands"] = [c for c in old.get("commands", [old["command"]]) if c != record["command"]] + record["commands"]
  io.write_json(stem + ".json", record)
  io.write_text(stem + ".md", markdown(record))


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--tasks", default="place_plate,shelve_item,pour_water")
  p.add_argument("--envs", type=int, default=1024)
  p.add_argument("--steps", type=int, default=20, help="control steps per timed call")
  p.add_argument("--repeats", type=int, default=2, help="timed calls per variant (best kept)")
  p.add_argument("--variants", default=",".join(VARIANTS), help=f"comma list of {', '.join(VARIANTS)}")
  p.add_argument("--policy", default="mlp", choices=POLICIES)
  p.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                 help="cpu: process CPU seconds (all threads) — steadier than wall time on a shared, loaded CPU; "
                      "use wall on a GPU")
  p.add_argument("--robot", default=ROBOT,
                 help=f"robot of every task (default {ROBOT}, the robot of the committed results)")
  p.add_argument("--precompile-workers", type=int, default=0,
                 help="compile every (task, variant) first in this many parallel processes, which fill JAX's "
                      "persistent cache; then time them one after another in this process (its compiles hit the "
                      "cache, so compile s is the cache load). 0: compile each just before timing it")
  p.add_argument("--compile-only", action="store_true", help=argparse.SUPPRESS)  # a precompile worker
  p.add_argument("--out-dir", default=os.path.join(HERE, "results"))
  a = p.parse_args(argv)
  if a.precompile_workers < 0:
    p.error(f"--precompile-workers: must be >= 0, got {a.precompile_workers}")
  for k in ("envs", "steps", "repeats"):
    if getattr(a, k) < 1:
      p.error(f"--{k}: must be >= 1")
  variants = a.variants.split(",")
  for v in variants:
    if v not in VARIANTS:
      p.error(f"--variants: unknown {v!r}; valid: {', '.join(VARIANTS)}")
  import tasks

  names = a.tasks.split(",")
  for n in names:
    if n not in tasks.names():
      p.error(f"--tasks: unknown {n!r}; valid: {', '.join(tasks.names())}")
  if a.robot not in tasks.robots.names():
    p.error(f"--robot: unknown {a.robot!r}; valid: {', '.join(tasks.robots.names())}")
  for n in names:
    if a.robot not in tasks.robots_for(n):
      p.error(f"--tasks: {n!r} supports {', '.join(tasks.robots_for(n))} only, not --robot {a.robot}")
  # No JAX_COMPILATION_CACHE_DIR of its own: set here, after `import tasks` had pointed this process's
  # cache at the package's directory, it reached only the precompile children, which then filled
  # another directory than the one this process reads (every program compiled twice).
  if a.precompile_workers:
    # the children compile while this process holds the device: preallocating 75 % of a GPU here left
    # them too little for autotuning (out-of-memory errors in the first H100 run)
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
  import jax

  jax.monitoring.register_event_listener(_count_hit)

  probes = {n: tasks.make(n, robot=a.robot).unwrapped for n in names}
  pairs = [(n, v) for n in names for v in variants if applicable(probes[n], v)]
  clock = time.perf_counter if a.clock == "wall" else time.process_time
  if a.compile_only:
    for n, v in pairs:
      measure(n, v, a.envs, a.steps, a.repeats, a.policy, clock, a.robot, compile_only=True)
    return 0
  if a.precompile_workers:
    precompile(argv if argv is not None else sys.argv[1:], pairs, a.precompile_workers)
  device = jax.devices()[0]
  stem = os.path.join(a.out_dir, f"step_overhead_{device.platform}")
  old = None
  if os.path.exists(stem + ".json"):
    with open(stem + ".json") as f:
      old = json.load(f)
  rows = []
  for n, v in pairs:
    rows.append(measure(n, v, a.envs, a.steps, a.repeats, a.policy, clock, a.robot))
    write(stem, a, argv, rows, old)  # after every row: a time limit keeps what was measured
  print(f"wrote {stem}.json, {stem}.md")
  return 0


if __name__ == "__main__":
  sys.exit(main())

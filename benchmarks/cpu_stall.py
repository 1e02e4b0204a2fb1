"""The XLA:CPU stall: loop the calls that used to deadlock, under a watchdog, with and without the fix.

Each check runs in a fresh subprocess (XLA reads its flags once per process)
and must finish ``--calls`` calls within ``--timeout`` seconds. When a child
stalls, the watchdog dumps its Python stacks (faulthandler) and, when py-spy is
installed, every native thread's stack (``py-spy dump --native``), then kills
it. Checks:

- ``cholesky``: four independent batched Cholesky factorizations of 512 12×12
  matrices in one jit (no MuJoCo): the smallest program that deadlocks; one
  "call" is 100 executions, since each deadlocks only with some probability.
- ``task``: one jit(vmap) call of ``--envs`` environments × ``--steps`` env
  steps of a task with its scripted safe policy (one physics step = MJX's
  Newton solver = one batched Cholesky per substep), with ``--robot`` (default
  the gripper, the robot of the committed results; the command records it).

Usage::

    .venv/bin/python benchmarks/cpu_stall.py                       # fix on and off, results file
    .venv/bin/python benchmarks/cpu_stall.py --modes fix --repeats 20 --out -   # the regression loop
    .venv/bin/python benchmarks/cpu_stall.py --child task --envs 512 --calls 1  # one check, this process

Writes ``benchmarks/results/cpu_stall.{json,md}`` (``--out -``: print only).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
RESULTS = os.path.join(HERE, "results")
MODES = {"fix": {}, "nofix": {"MJX_DAMAGE_XLA_CPU_FIX": "0"}}


def child(check: str, envs: int, steps: int, calls: int, task: str, robot: str = "gripper") -> None:
  """Run the check in this process; prints one line per call."""
  import mjx_damage  # noqa: F401  (applies the XLA:CPU setting unless switched off)
  import jax
  import jax.numpy as jnp

  if check == "cholesky":
    keys = jax.random.split(jax.random.PRNGKey(0), 4)

    def spd(k):
      a = jax.random.normal(k, (envs, 12, 12))
      return a @ jnp.swapaxes(a, -1, -2) + 12 * jnp.eye(12)

    mats = [spd(k) for k in keys]
    f = jax.jit(lambda *xs: sum(jnp.sum(jnp.linalg.cholesky(x)) for x in xs))

    def run(i):  # one "call" = 100 executions: each one deadlocks only with some probability
      for _ in range(100):
        out = f(*mats)
        out.block_until_ready()
      return out
  else:
    import tasks

    env = tasks.make(task, robot=robot)
    policy = tasks.scripted_policy(env, "safe")

    def episode(key):
      def body(s, k):
        s = env.step(s, policy(s, k))
        return s, s.reward

      s, r = jax.lax.scan(body, env.reset(key), jax.random.split(key, steps))
      return r.sum() + jnp.sum(s.info["entity_health"])

    f = jax.jit(jax.vmap(episode))
    run = lambda i: f(jax.random.split(jax.random.PRNGKey(i), envs))  # noqa: E731
  t0 = time.perf_counter()
  for i in range(calls):
    jax.block_until_ready(run(i))
    print(f"call {i} done at {time.perf_counter() - t0:.2f} s", flush=True)
  print("XLA_FLAGS=" + os.environ.get("XLA_FLAGS", ""), flush=True)


def _summarise_gdb(text: str) -> str:
  """Per thread: its name and the XLA / jaxlib / Eigen / absl frames (function names only)."""
  out = []
  for line in text.splitlines():
    if line.startswith("Thread "):
      out.append(line.split(" from ")[0])
    elif line.startswith("#") and any(k in line for k in ("jax::", "xla::", "Eigen::", "absl::", "lapack_")):
      fn = line.split(" in ", 1)[-1].split(" (", 1)[0] if " in " in line else line
      out.append("    " + fn[:140])
  return "\n".join(out)


def _native_stacks(pid: int) -> str:
  """Every thread's native stack (gdb), else the Python threads' (py-spy), else a note."""
  if shutil.which("gdb"):
    r = subprocess.run(["gdb", "-p", str(pid), "-batch", "-ex", "thread apply all bt 30"],
                       capture_output=True, text=True, timeout=120)
    return _summarise_gdb(r.stdout)
  spy = shutil.which("py-spy")
  if spy:
    r = subprocess.run([spy, "dump", "--native", "--pid", str(pid)], capture_output=True, text=True, timeout=60)
    return r.stdout + r.stderr
  return "(neither gdb nor py-spy installed: native stacks not dumped)"


def run_check(check: str, mode: str, envs: int, steps: int, calls: int, task: str, timeout: float,
              robot: str = "gripper") -> dict:
  """One fresh process; returns its outcome, with stack dumps when it stalled."""
  # no persistent cache: each process compiles under its own XLA flags
  env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONFAULTHANDLER="1", MJX_DAMAGE_CACHE_DIR="off", **MODES[mode])
  env.pop("JAX_COMPILATION_CACHE_DIR", None)
  if mode == "nofix":
    env["XLA_FLAGS"] = env.get("XLA_FLAGS", "").replace("--xla_cpu_enable_concurrency_optimized_scheduler=false", "")
  cmd = [sys.executable, os.path.abspath(__file__), "--child", check, "--envs", str(envs), "--steps", str(steps),
         "--calls", str(calls), "--task", task] + (["--robot", robot] if check == "task" else [])
  t0 = time.perf_counter()
  p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
  try:
    out, _ = p.communicate(timeout=timeout)
    ok = p.returncode == 0
    stacks = ""
  except subprocess.TimeoutExpired:
    stacks = _native_stacks(p.pid)
    os.kill(p.pid, 6)  # SIGABRT: faulthandler prints every Python thread's stack
    try:
      out, _ = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
      p.kill()
      out, _ = p.communicate()
    ok = False
  wall = time.perf_counter() - t0
  done = sum(1 for line in (out or "").splitlines() if line.startswith("call "))
  return {"check": check, "mode": mode, "envs": envs, "steps": steps, "calls": calls, "task": task,
          "ok": ok, "calls_done": done, "wall_s": round(wall, 1), "timeout_s": timeout,
          "tail": (out or "")[-3000:] if not ok else "", "native_stacks": stacks[-20000:]}


def markdown(rows: list[dict], command: str) -> str:
  lines = ["# XLA:CPU stall: the triggering calls with and without the package's fix", "",
           f"Command: `{command}`", "",
           "Each row is one fresh process (no persistent compilation cache) that must finish all its calls before the timeout. "
           "`fix`: XLA_FLAGS as `import mjx_damage` sets them "
           "(`--xla_cpu_enable_concurrency_optimized_scheduler=false`); `nofix`: `MJX_DAMAGE_XLA_CPU_FIX=0`.", "",
           "| check | mode | envs | steps | calls | finished | calls done | wall s (compile incl.) |",
           "|---|---|---|---|---|---|---|---|"]
  for r in rows:
    lines.append(f"| {r['check']}{'' if r['check'] == 'cholesky' else ' ' + r['task']} | {r['mode']} | {r['envs']} | "
                 f"{r['steps'] if r['check'] != 'cholesky' else '—'} | {r['calls']} | {'yes' if r['ok'] else '**stalled**'} | "
                 f"{r['calls_done']} | {r['wall_s']} |")
  stalled = [r for r in rows if not r["ok"]]
  if stalled:
    lines += ["", "## Stack of the first stalled process", "", "```", stalled[0]["native_stacks"] or stalled[0]["tail"], "```"]
  return "\n".join(lines) + "\n"


def check_robot(p: argparse.ArgumentParser, robot: str, task: str, keep_flags: bool) -> None:
  """``p.error`` naming --robot for a robot that is not registered or does not run ``task``.

  The gripper (the default) is always registered: checked without importing the package, so the default
  parent stays free of jax. Another robot imports :mod:`tasks`, whose ``import mjx_damage`` adds the
  XLA:CPU fix to ``XLA_FLAGS``; the parent restores its own (``keep_flags=False``), since its children
  inherit its environment and ``nofix`` must run without the fix.
  """
  if robot == "gripper":
    return
  saved = os.environ.get("XLA_FLAGS")
  import tasks

  if not keep_flags:
    if saved is None:
      os.environ.pop("XLA_FLAGS", None)
    else:
      os.environ["XLA_FLAGS"] = saved
  try:
    tasks.check_robot(robot, [task], "--robot")
  except ValueError as e:
    p.error(str(e))


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
  p.add_argument("--child", choices=("cholesky", "task"), help="run one check in this process")
  p.add_argument("--checks", default="cholesky,task", help="checks to run, comma-separated")
  p.add_argument("--modes", default="fix,nofix", help="fix, nofix or both")
  p.add_argument("--repeats", type=int, default=3, help="fresh processes per (check, mode)")
  p.add_argument("--envs", type=int, default=512, help="batch size")
  p.add_argument("--steps", type=int, default=1, help="env steps per call (task check)")
  p.add_argument("--calls", type=int, default=3, help="calls per process")
  p.add_argument("--task", default="place_plate", help="task of the task check")
  p.add_argument("--robot", default="gripper",
                 help="robot of the task check (tasks.robots.names()); gripper: the robot of the committed results")
  p.add_argument("--timeout", type=float, default=180.0, help="seconds a process may take, compile included")
  p.add_argument("--out", default=RESULTS, help="results directory, or - to print only")
  a = p.parse_args(argv)
  for field in ("repeats", "envs", "steps", "calls"):
    if getattr(a, field) < 1:
      p.error(f"--{field}: must be >= 1, got {getattr(a, field)}")
  check_robot(p, a.robot, a.task, keep_flags=bool(a.child))
  if a.child:
    child(a.child, a.envs, a.steps, a.calls, a.task, a.robot)
    return 0
  checks, modes = a.checks.split(","), a.modes.split(",")
  for c in checks:
    if c not in ("cholesky", "task"):
      p.error(f"--checks: unknown check {c!r} (choose from cholesky, task)")
  for m in modes:
    if m not in MODES:
      p.error(f"--modes: unknown mode {m!r} (choose from {', '.join(MODES)})")
  rows = []
  for c in checks:
    for m in modes:
      for i in range(a.repeats):
        r = run_check(c, m, a.envs, a.steps, a.calls, a.task, a.timeout, a.robot)
        rows.append(r)
        print(f"{c:8s} {m:5s} repeat {i}: {'ok' if r['ok'] else 'STALLED'} {r['calls_done']}/{a.calls} calls, "
              f"{r['wall_s']} s", flush=True)
  command = "python benchmarks/cpu_stall.py " + " ".join(sys.argv[1:] if argv is None else argv)
  if a.out != "-":
    os.makedirs(a.out, exist_ok=True)
    from mjx_damage.io import write_json, write_text  # noqa: E402  (keeps --help free of jax)

    write_json(os.path.join(a.out, "cpu_stall.json"), {"command": command, "rows": rows})
    write_text(os.path.join(a.out, "cpu_stall.md"), markdown(rows, command))
  return 0 if all(r["ok"] for r in rows if r["mode"] == "fix") else 1


if __name__ == "__main__":
  sys.exit(main())

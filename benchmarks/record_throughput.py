"""Recording throughput: demonstrations recorded through the compiled batched step and written to HDF5.

Two measurements per task, both with an operator of :mod:`tasks.operators`
(default ``careful``) through :func:`train.record.record` and
:func:`mjx_damage.data.save` — the path of ``mjx-damage record``:

* **a dataset from scratch** — ``--episodes`` episodes in one compiled call, then
  written: the wall time a user waits, compilation included (target on CPU:
  256 episodes in ≤ 2 minutes);
* **steady state** — ``--steady-episodes`` episodes in chunks of ``--chunk``
  (one executable), then written. The first chunk, which compiles, is left out;
  transitions per second recorded, written, and both (``1 / (1/r + 1/w)``: one
  after the other);
* **streamed** — what ``mjx-damage record`` does: the same episodes through
  :func:`train.record.record_chunks` into :func:`mjx_damage.data.save_chunks`,
  each chunk written while the device records the next. Rate = transitions of
  chunks 2..N / time from chunk 1's arrival to chunk N's (each interval writes
  one chunk and records the next; needs ``--steady-episodes`` ≥ 2 ×
  ``--chunk``). Target on one H100: ≥ 100 k transitions/s recorded and written.

Results: ``benchmarks/results/record_throughput_<device>.{json,md}`` (``--robot`` other than the gripper:
``record_throughput_<robot>_<device>``, the robot in the JSON).

CPU (``MJX_DAMAGE_CACHE_DIR=off``: compile as a first-time user does)::

    MJX_DAMAGE_CACHE_DIR=off .venv/bin/python benchmarks/record_throughput.py

GPU (one call)::

    python benchmarks/record_throughput.py --steady-episodes 32768 --chunk 8192 --results-dir $OUT
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
  sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (first: XLA flags, compilation cache)
import jax  # noqa: E402
import numpy as np  # noqa: E402

import tasks  # noqa: E402
from mjx_damage import data as D  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402
from mjx_damage.runtime import device_info  # noqa: E402
from tasks import operators  # noqa: E402
from train import evaluate as E  # noqa: E402
from train.record import record, record_chunks  # noqa: E402


def timed_record(env, op, task: str, episodes: int, chunk: int, seed: int, path: str) -> dict:
  """Record ``episodes`` in chunks of ``chunk``, save to ``path``; per-chunk and save times (s)."""
  chunk_s, t_last = [], [time.perf_counter()]

  def log(_msg):  # record() calls it after every chunk
    now = time.perf_counter()
    chunk_s.append(now - t_last[0])
    t_last[0] = now

  t0 = time.perf_counter()
  ds = record(env, op, episodes, seed, task=task, episode_length=E.env_episode_length(env), chunk=chunk, log=log)
  t1 = time.perf_counter()
  D.save(path, ds)
  t2 = time.perf_counter()
  return {"episodes": episodes, "chunk": min(chunk, episodes), "transitions": D.num_transitions(ds),
          "record_s": t1 - t0, "save_s": t2 - t1, "total_s": t2 - t0, "chunk_s": chunk_s,
          "file_mb": os.path.getsize(path) / 2**20, "success": float(np.mean(ds.success)),
          "safe": float(np.mean(ds.safe))}


def timed_stream(env, op, task: str, episodes: int, chunk: int, seed: int, path: str) -> dict:
  """Record and write at once (``mjx-damage record``'s path); the steady rate after the first chunk."""
  return stream_rate(lambda: record_chunks(env, op, episodes, seed, task=task,
                                           episode_length=E.env_episode_length(env), chunk=chunk),
                     path, episodes, min(chunk, episodes))


def stream_rate(make_chunks, path: str, episodes: int, chunk: int) -> dict:
  """Write ``make_chunks()``'s stream with :func:`mjx_damage.data.save_chunks`, timing each chunk's arrival.

  Between two arrivals the writer writes one chunk while the device records the
  next, so the steady rate is the transitions of chunks 2..N over the time from
  chunk 1's arrival to chunk N's: N − 1 chunks recorded and N − 1 written. (Up
  to this commit the time ran to the file's close, which also counts chunk N's
  write: with N = 4 chunks that understated a write-bound rate by a quarter.)
  Needs at least 2 chunks (otherwise ``None``).
  """
  marks, sizes = [], []

  def stamped(chunks):
    for ds in chunks:
      marks.append(time.perf_counter())
      sizes.append(D.num_transitions(ds))
      yield ds

  t0 = time.perf_counter()
  D.save_chunks(path, stamped(make_chunks()))
  t1 = time.perf_counter()
  steady = sum(sizes[1:]) / (marks[-1] - marks[0]) if len(marks) > 1 else None
  return {"episodes": episodes, "chunk": chunk, "chunks": len(marks), "total_s": t1 - t0,
          "first_chunk_s": marks[0] - t0, "last_write_s": t1 - marks[-1], "transitions_per_s": steady}


def main(argv=None) -> int:
  ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  ap.add_argument("--tasks", default="pick_egg", help="comma-separated task names")
  ap.add_argument("--operator", default="careful", help=f"one of {', '.join(operators.CONDITIONS)}")
  ap.add_argument("--episodes", type=int, default=256, help="the from-scratch dataset (one compiled call)")
  ap.add_argument("--steady-episodes", type=int, default=512, help="episodes of the steady-state measurement")
  ap.add_argument("--chunk", type=int, default=256, help="episodes per compiled call (steady state)")
  ap.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  ap.add_argument("--tag", default="")
  ap.add_argument("--robot", default="gripper",
                  help=f"robot of every task, one of {', '.join(tasks.robots.names())} (default: gripper, "
                       "the robot of the committed results)")
  args = ap.parse_args(argv)
  names = [t for t in args.tasks.split(",") if t]
  for t in names:
    if t not in tasks.names():
      ap.error(f"--tasks: unknown task {t!r}")
  try:
    tasks.check_robot(args.robot, names, "--robot")
  except ValueError as e:
    ap.error(str(e))
  if args.operator not in operators.CONDITIONS:
    ap.error(f"--operator: one of {', '.join(operators.CONDITIONS)}, got {args.operator!r}")
  for k in ("episodes", "steady_episodes", "chunk"):
    if getattr(args, k) < 1:
      ap.error(f"--{k.replace('_', '-')}: must be >= 1, got {getattr(args, k)}")
  if args.steady_episodes < 2 * args.chunk:
    ap.error(f"--steady-episodes: needs at least two chunks (>= {2 * args.chunk}): the first one compiles")
  slug, desc = device_info()
  rows = []
  with tempfile.TemporaryDirectory(prefix="record_throughput_") as tmp:
    for task in names:
      env = tasks.make(task, robot=args.robot)  # the gripper explicitly: tasks.robots.DEFAULT may change
      op = operators.make(env, args.operator)
      scratch = timed_record(env, op, task, args.episodes, args.episodes, 0, os.path.join(tmp, f"{task}_a.hdf5"))
      steady = timed_record(env, op, task, args.steady_episodes, args.chunk, 1, os.path.join(tmp, f"{task}_b.hdf5"))
      # every chunk runs `chunk` whole episodes (the last one padded), so each is chunk × T transitions of work
      per_chunk = steady["chunk"] * E.env_episode_length(env)
      rec_tps = per_chunk * (len(steady["chunk_s"]) - 1) / sum(steady["chunk_s"][1:])
      save_tps = steady["transitions"] / steady["save_s"]
      stream = timed_stream(env, op, task, args.steady_episodes, args.chunk, 1, os.path.join(tmp, f"{task}_c.hdf5"))
      rows.append({"task": task, "episode_length": E.env_episode_length(env), "scratch": scratch,
                   "steady": steady, "record_transitions_per_s": rec_tps, "save_transitions_per_s": save_tps,
                   "written_transitions_per_s": 1.0 / (1.0 / rec_tps + 1.0 / save_tps), "streamed": stream})
      print(f"{task}: {args.episodes} episodes from scratch in {scratch['total_s']:.1f} s; steady "
            f"{rec_tps:,.0f} recorded, {save_tps:,.0f} written, {rows[-1]['written_transitions_per_s']:,.0f} "
            f"both, {stream['transitions_per_s']:,.0f} streamed (transitions/s)", flush=True)

  cmd = "python benchmarks/record_throughput.py " + " ".join(
      shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
  cache = jax.config.jax_compilation_cache_dir or None
  result = {"command": cmd.strip(), "device": desc, "operator": args.operator, "rows": rows,
            "compilation_cache": cache,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
  robot = "" if args.robot == "gripper" else f"{args.robot}_"  # gripper: the committed results' names and fields
  if robot:
    result["robot"] = args.robot
  os.makedirs(args.results_dir, exist_ok=True)
  base = os.path.join(args.results_dir, f"record_throughput_{robot}{slug}" + (f"_{args.tag}" if args.tag else ""))
  write_json(base + ".json", result)
  lines = [f"# Recording throughput ({desc})", "", f"Command: `{result['command']}` ({result['date']}).", "",
           f"Operator `{args.operator}` through `train.record.record` (one compiled `jit(vmap(episode))` per "
           "chunk), written by `mjx_damage.data.save` (robomimic HDF5 layout + health, damage, cost). "
           "From scratch: one call, compilation included (what `mjx-damage record` takes). Steady state: "
           "chunks after the first (which compiles); 'both' = 1 / (1/recorded + 1/written); 'streamed' = "
           "recorded and written at once, each chunk written while the device records the next (what "
           "`mjx-damage record` does): transitions of chunks 2..N over the time from chunk 1's arrival at the "
           "writer to chunk N's, in which N − 1 chunks are recorded and N − 1 written. Persistent "
           f"compilation cache: {'on (' + cache + '; a warm cache skips compiling)' if cache else 'off (every run compiles)'}.",
           "",
           "| task | T | from scratch: episodes | s (compile incl.) | of it writing s | file MB | "
           "steady: episodes × chunk | recorded tr/s | written tr/s | both tr/s | streamed tr/s |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
  for r in rows:
    a, b = r["scratch"], r["steady"]
    lines.append(f"| {r['task']} | {r['episode_length']} | {a['episodes']} | {a['total_s']:.1f} | {a['save_s']:.1f} | "
                 f"{a['file_mb']:.0f} | {b['episodes']} × {b['chunk']} | {r['record_transitions_per_s']:,.0f} | "
                 f"{r['save_transitions_per_s']:,.0f} | {r['written_transitions_per_s']:,.0f} | "
                 f"{r['streamed']['transitions_per_s']:,.0f} |")
  write_text(base + ".md", "\n".join(lines) + "\n")
  print("\n".join(lines))
  print(f"wrote {base}.json, {base}.md")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

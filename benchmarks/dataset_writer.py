"""How fast does ``mjx_damage.data.save`` write, and what does each HDF5 object cost?

Writing bounds ``mjx-damage record`` on a GPU (benchmarks/record_throughput.py): HDF5's
cost is per object (group, dataset, attribute), not per byte. This benchmark times, on
this machine's CPU and disk, with no simulation:

* **per object**: creating a group, a small float32 dataset (created and written), and a
  scalar attribute on a fresh group, through h5py's low-level API as the writer does;
* **the writer**: ``save`` of a synthetic dataset shaped like a pick_egg recording (80
  steps, obs 17, actions 4, states 40, two entities), repeated, and with ``--compare REV``
  the writer of git revision REV (its ``mjx_damage/data.py``) interleaved with this one on
  the same data, so the two see the same disk and load.

Writes ``benchmarks/results/dataset_writer_<tag>.{json,md}`` with the command (median and
spread over repeats).

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/dataset_writer.py --episodes 4096 --repeats 8 --compare 18a26ff --tag cpu
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import h5py  # noqa: E402
import numpy as np  # noqa: E402

import provenance  # noqa: E402  (the sibling module: command, git, date)
from mjx_damage import data as D  # noqa: E402
from mjx_damage.io import write_json, write_text  # noqa: E402

RESULTS = os.path.join(ROOT, "benchmarks", "results")
T = 80  # pick_egg's lift episode length, the recording benchmark's task


def synthetic(module, episodes: int, seed: int = 0):
  """A pick_egg-shaped dataset built by ``module.build`` (this writer's or another revision's)."""
  r = np.random.default_rng(seed)
  e = episodes
  return module.build(
      env_name="pick_egg", obs={"state": r.normal(size=(e, T, 17)).astype(np.float32)},
      actions=r.normal(size=(e, T, 4)), rewards=r.normal(size=(e, T)), states=r.normal(size=(e, T, 40)),
      health={k: np.full((e, T), 100.0) for k in ("egg", "agent")},
      damage={k: np.zeros((e, T)) for k in ("mechanical", "thermal", "fluid")}, cost=np.zeros((e, T)),
      lengths=np.full(e, T), success=r.random(e) < 0.9, safe=r.random(e) < 0.8, label_names=("careful",))


def object_costs(n: int, tmp: str) -> dict:
  """µs per group, per small dataset (create + write), per scalar attribute on a fresh group."""
  f32 = h5py.h5t.py_create(np.dtype("f4"), logical=True)
  b8 = h5py.h5t.py_create(np.dtype("bool"), logical=True)
  space, scalar = h5py.h5s.create_simple((T, 17)), h5py.h5s.create(h5py.h5s.SCALAR)
  a, flag = np.zeros((T, 17), np.float32), np.asarray(True)
  out = {}
  path = os.path.join(tmp, "objects.hdf5")
  with h5py.File(path, "w") as f:
    root = f.create_group("g").id
    t = time.perf_counter()
    groups = [h5py.h5g.create(root, f"d{i}".encode()) for i in range(n)]
    out["group_us"] = 1e6 * (time.perf_counter() - t) / n
    t = time.perf_counter()
    for g in groups:
      h5py.h5d.create(g, b"x", f32, space).write(h5py.h5s.ALL, h5py.h5s.ALL, a)
    out["dataset_us"] = 1e6 * (time.perf_counter() - t) / n
    t = time.perf_counter()
    for g in groups:
      h5py.h5a.create(g, b"flag", b8, scalar).write(flag)
    out["attribute_us"] = 1e6 * (time.perf_counter() - t) / n
  os.remove(path)
  return out


def writer_at(rev: str, tmp: str):
  """The ``mjx_damage.data`` module of git revision ``rev``, loaded under another name."""
  try:
    src = subprocess.run(["git", "-C", ROOT, "show", f"{rev}:mjx_damage/data.py"], check=True,
                         capture_output=True, text=True).stdout
  except subprocess.CalledProcessError as e:
    raise ValueError(f"compare: git cannot show {rev}:mjx_damage/data.py ({e.stderr.strip()})") from None
  path = os.path.join(tmp, f"data_{rev}.py")
  with open(path, "w") as fh:
    fh.write(src)
  spec = importlib.util.spec_from_file_location(f"data_{rev}", path)
  module = importlib.util.module_from_spec(spec)
  sys.modules[spec.name] = module  # flax dataclasses look their module up
  spec.loader.exec_module(module)
  return module


def main(argv=None) -> int:
  p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
  p.add_argument("--episodes", type=int, default=1024)
  p.add_argument("--repeats", type=int, default=5)
  p.add_argument("--compare", default=None, metavar="REV", help="also time the writer of this git revision")
  p.add_argument("--objects", type=int, default=4096, help="objects of each kind timed")
  p.add_argument("--tag", default="cpu")
  p.add_argument("--results-dir", default=RESULTS)
  a = p.parse_args(argv)
  for name in ("episodes", "repeats", "objects"):
    if getattr(a, name) < 1:
      p.error(f"--{name}: must be >= 1, got {getattr(a, name)}")
  with tempfile.TemporaryDirectory() as tmp:
    writers = {"this": D}
    if a.compare:
      writers[a.compare] = writer_at(a.compare, tmp)
    data = {k: synthetic(m, a.episodes) for k, m in writers.items()}
    rates = {k: [] for k in writers}
    for _ in range(a.repeats):  # interleaved: both writers see the same disk and load
      for k, m in writers.items():
        path = os.path.join(tmp, f"{k}.hdf5")
        if os.path.exists(path):
          os.remove(path)
        t = time.perf_counter()
        m.save(path, data[k])
        rates[k].append(a.episodes * T / (time.perf_counter() - t))
        print(f"{k}: {rates[k][-1]:,.0f} transitions/s", flush=True)
    objects = object_costs(a.objects, tmp)
  rows = [{"writer": k, "median_tr_s": float(np.median(v)), "min_tr_s": float(min(v)), "max_tr_s": float(max(v)),
           "rates": v} for k, v in rates.items()]
  res = {"episodes": a.episodes, "steps": T, "repeats": a.repeats, "rows": rows, "objects": objects,
         "command": provenance.command("dataset_writer", argv),
         "date": provenance.now(), "cpus": os.cpu_count(), "git": provenance.git()}
  lines = ["# Dataset writer: transitions/s and the cost of an HDF5 object", "",
           f"Command: `{res['command']}`  ", f"{res['date']}, git {res['git']}, {res['cpus']} CPUs. "
           f"{a.episodes} synthetic pick_egg-shaped episodes of {T} steps per save, {a.repeats} saves per writer, "
           "interleaved; 'this' is the checkout's `mjx_damage.data`.", "",
           "| writer | median transitions/s | min | max |", "|---|---|---|---|"]
  lines += [f"| {r['writer']} | {r['median_tr_s']:,.0f} | {r['min_tr_s']:,.0f} | {r['max_tr_s']:,.0f} |" for r in rows]
  lines += ["", f"Per object ({a.objects} each, low-level h5py): group {objects['group_us']:.1f} µs, small dataset "
            f"created and written {objects['dataset_us']:.1f} µs, scalar attribute on a fresh group "
            f"{objects['attribute_us']:.1f} µs."]
  stem = os.path.join(a.results_dir, f"dataset_writer_{a.tag}")
  write_json(stem + ".json", res)
  write_text(stem + ".md", "\n".join(lines) + "\n")
  print(f"wrote {stem}.json / .md")
  return 0


if __name__ == "__main__":
  raise SystemExit(main())

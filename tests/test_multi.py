"""Several devices and several processes (train.mesh, train.distributed), on CPU.

* one device: the mesh program is today's single-device program, bit for bit;
* 2 processes x 1 CPU device on 127.0.0.1 (gloo collectives) against 1 process x 2 CPU devices (the same
  mesh): an evaluation sweep gives identical metrics; training gives the same losses (rtol 1e-5: the
  cross-process all-reduce may sum in another order) and evaluations; a run resumed by both processes from
  process 0's checkpoint continues it;
* a process that dies (SIGKILL) ends the other within the heartbeat timeout + a margin, with JAX's error;
* bad flags: one line naming the flag, status 2, before anything compiles.

The tiny PusherEnv config of tests/test_train.py: each CLI run compiles little, and the persistent cache
makes the second and later runs of a program cheap.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import jax
import numpy as np
import pytest

from conftest import load_benchmark
from train import cli, mesh as M
from train.config import PPOConfig
from train.envs import resolve_task
from train.experiments.pusher import PusherEnv
from train.iteration import Trainer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TASK = "train.experiments.pusher:PusherEnv"
# 16 envs x 8 steps = 128 env steps per iteration; split over 2 devices: 8 envs and 4-sequence minibatches each.
TINY = ["--num-envs", "16", "--unroll-length", "8", "--num-minibatches", "2", "--batch-size", "8",
        "--updates-per-batch", "2", "--episode-length", "24", "--policy-hidden", "16,16", "--value-hidden", "16,16",
        "--eval-envs", "8", "--seeds", "3", "--eval-every", "256", "--checkpoint-every", "256", "--no-progress"]
SWEEP = ["sweep", "--tasks", "drop", "--policies", "random", "--seeds", "0,1", "--fragility", "1,4",
         "--episodes", "3", "--episode-length", "8"]
HEARTBEAT_S = 5
LOSS_RTOL = 1e-5


def _port() -> int:
  with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    return s.getsockname()[1]


def _env(devices: int, **extra) -> dict:
  return dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT,
              XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}", **extra)


def _launch(argv: list, processes: int, devices_per_process: int, **env) -> list:
  """``mjx-damage ARGV`` in ``processes`` processes (a coordinator on 127.0.0.1 when more than one)."""
  if processes == 1:
    cmds = [argv]
  else:
    port = _port()
    cmds = [argv + ["--coordinator", f"127.0.0.1:{port}", "--num-processes", str(processes), "--process-id", str(i),
                    "--heartbeat-timeout", str(HEARTBEAT_S), "--dist-timeout", "120"] for i in range(processes)]
  return [subprocess.Popen([sys.executable, "-m", "apps.cli"] + c, cwd=ROOT, env=_env(devices_per_process, **env),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in cmds]


def _run(argv: list, processes: int, devices_per_process: int, timeout: float = 500, **env) -> list:
  procs = _launch(argv, processes, devices_per_process, **env)
  outs = []
  for p in procs:
    try:
      out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
      for q in procs:
        q.kill()
      raise
    outs.append((p.returncode, out, err))
  for i, (rc, out, err) in enumerate(outs):
    assert rc == 0, f"process {i}: status {rc}\n{out[-2000:]}\n{err[-4000:]}"
  return outs


def _rows(out_dir):
  with open(os.path.join(out_dir, "metrics.jsonl")) as f:
    return [json.loads(line) for line in f]


# --- one device: the mesh program is today's program ---------------------------------------------------------

def test_one_device_mesh_equals_the_single_device_program():
  cfg = PPOConfig.preset("playground", num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8,
                         num_updates_per_batch=2, episode_length=24, policy_hidden_sizes=(16, 16),
                         value_hidden_sizes=(16, 16), seeds=(3, 4)).validate()
  env, _ = resolve_task(PusherEnv())
  mesh = M.make_mesh(jax.devices()[:1], cfg.num_seeds)
  assert M.axis_name(mesh) is None  # one env shard: no collectives, no folded keys
  trainer = Trainer(env, cfg, M.axis_name(mesh))
  init = trainer.init_states
  seeds = np.asarray(cfg.seeds, np.int32)
  specs = M.state_specs(jax.eval_shape(init, seeds))
  plain = jax.jit(jax.vmap(trainer.train_iteration))  # the run loop's program before the mesh
  meshed = M.per_seed(trainer.train_iteration, mesh, specs, (specs, M.P(M.SEEDS)))
  a = jax.jit(init)(seeds)
  b = jax.jit(init, out_shardings=M.shardings(mesh, specs))(seeds)
  for _ in range(2):
    a, ma = plain(a)
    b, mb = meshed(b)
  for x, y in zip(jax.tree.leaves((a, ma)), jax.tree.leaves((b, mb)), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


# --- 2 processes against 1 process with the same 2 devices ------------------------------------------------------

@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
  d = tmp_path_factory.mktemp("sweep")
  # an empty cache: the first process must trace (and, where allowed, export) its program itself —
  # a program exported by an earlier run once hid that exporting under GSPMD could not lower
  cache = str(d / "cache")
  _run(SWEEP + ["--out", str(d / "one.json")], 1, 2, MJX_DAMAGE_CACHE_DIR=cache)
  _run(SWEEP + ["--out", str(d / "two.json")], 2, 1, MJX_DAMAGE_CACHE_DIR=cache)
  _run(SWEEP + ["--out", str(d / "single.json")], 1, 1, MJX_DAMAGE_CACHE_DIR=cache)
  return [json.load(open(d / f"{n}.json")) for n in ("one", "two", "single")]


def test_two_process_sweep_equals_one_process(sweeps):
  one, two, _ = sweeps
  assert (one["num_devices"], one["processes"]) == (2, 1) and (two["num_devices"], two["processes"]) == (2, 2)
  assert len(one["runs"]) == 2 * 2 * 1
  assert one["runs"] == two["runs"] and one["rows"] == two["rows"]


def test_sweep_on_two_devices_equals_one_device(sweeps):
  """On 2 devices the sweep hands its rows over in device-local order (train.sweep.device_local_order);
  the metrics are those of the level-major batch on one device: rates equal, costs to float rounding
  (XLA:CPU's code for a 3-row and a 6-row batch may round a sum differently; the same before the order)."""
  one, _, single = sweeps
  assert single["num_devices"] == 1 and len(one["runs"]) == len(single["runs"])
  for a, b in zip(one["runs"], single["runs"]):
    assert {k: v for k, v in a.items() if k != "metrics"} == {k: v for k, v in b.items() if k != "metrics"}
    ma, mb = a["metrics"], b["metrics"]
    assert ma.keys() == mb.keys()
    for k in ("completion", "safe_completion", "zero_damage_rate", "episodes"):
      assert ma[k] == mb[k], k
    np.testing.assert_allclose(np.asarray(jax.tree.leaves(ma), float), np.asarray(jax.tree.leaves(mb), float),
                               rtol=1e-4, atol=1e-6)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):  # 3 CLI runs, each compiling (≈ 4 min on a quiet 2-core CPU): the slow suite
  """6 iterations on 1 process x 2 devices; 4 on 2 processes, then resumed by both to 6."""
  d = tmp_path_factory.mktemp("train")
  one, two = str(d / "one"), str(d / "two")
  _run(["train", "--task", TASK, *TINY, "--timesteps", "768", "--devices", "2", "--out", one], 1, 2)
  first = _run(["train", "--task", TASK, *TINY, "--timesteps", "512", "--out", two], 2, 1)
  rows_before = _rows(two)
  _run(["train", "--task", TASK, *TINY, "--timesteps", "768", "--out", two, "--resume"], 2, 1)
  return one, two, first, rows_before


@pytest.mark.slow
def test_two_process_training_matches_one_process(runs):
  one, two, first, rows_before = runs
  a, b = _rows(one), _rows(two)
  assert [r["iteration"] for r in a] == [r["iteration"] for r in b] == [2, 4, 6]
  assert [r["iteration"] for r in rows_before] == [2, 4] and b[:2] == rows_before  # resume kept them
  for ra, rb in zip(a, b):
    for k, v in ra.items():
      if k.startswith("loss/"):
        np.testing.assert_allclose(rb[k], v, rtol=LOSS_RTOL, atol=1e-7, err_msg=f"{k} at {ra['iteration']}")
      elif (k.startswith("eval/") or k.startswith("train/")) and v is not None:
        assert rb[k] == pytest.approx(v, rel=1e-4, abs=1e-6), (k, ra["iteration"])
  meta = json.load(open(os.path.join(two, "config.json")))
  assert meta["processes"] == 2 and meta["devices"] == 2 and meta["mesh"] == {"seeds": 1, "envs": 2}
  summaries = [json.loads(out[out.index("{\n"):out.rindex("}") + 1]) for _, out, _ in first]
  assert [s["process"] for s in summaries] == [0, 1]
  assert summaries[0]["final_eval"] == summaries[1]["final_eval"]


@pytest.mark.timeout(600)
@pytest.mark.parametrize("victim", [1, 0])  # a worker; the coordinator itself
def test_a_dead_process_ends_the_other(victim, tmp_path):
  """SIGKILL one process once both are connected (the others then compile, or wait in a collective):
  the survivor ends with JAX's error within the heartbeat timeout + a margin, and does not hang."""
  procs = _launch(["train", "--task", TASK, *TINY, "--timesteps", "1e6", "--out", str(tmp_path / "run")], 2, 1)
  try:
    for p in procs:
      for line in p.stdout:
        if line.startswith("distributed: process"):
          break
    procs[victim].send_signal(signal.SIGKILL)
    t0 = time.monotonic()
    survivor = procs[1 - victim]
    _, err = survivor.communicate(timeout=HEARTBEAT_S + 60)
    waited = time.monotonic() - t0
  finally:
    for p in procs:
      if p.poll() is None:
        p.kill()
  assert survivor.returncode != 0 and waited < HEARTBEAT_S + 60
  assert "another task died" in err or "heartbeat" in err.lower(), err[-3000:]


# --- bad flags --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("flags, named", [
    (["--devices", "0"], "--devices"),
    (["--devices", "two"], "--devices"),
    (["--devices", "3"], "--devices"),  # 16 envs do not split 3 ways
    (["--coordinator", "nohost"], "--coordinator"),
    (["--coordinator", "127.0.0.1:99999", "--num-processes", "2", "--process-id", "0"], "--coordinator"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"], "--process-id"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "0", "--process-id", "0"], "--num-processes"),
    (["--coordinator", "127.0.0.1:1234", "--process-id", "1"], "--num-processes"),
    (["--num-processes", "2", "--process-id", "1"], "--coordinator"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "1", "--devices", "3"], "--devices"),
])
def test_bad_flags_one_line_before_jax(flags, named, capsys, tmp_path):
  assert cli.main(["--task", TASK, *TINY, "--out", str(tmp_path / "r"), *flags]) == 2
  err = capsys.readouterr().err.strip()
  assert "\n" not in err and f"error: {named}:" in err, err


def test_more_devices_than_exist_and_no_coordinator(tmp_path):
  """After JAX starts, still before compiling: too many devices; a coordinator that never answers."""
  p = subprocess.run([sys.executable, "-m", "apps.cli", "train", "--task", TASK, *TINY, "--devices", "4",
                      "--out", str(tmp_path / "a")], cwd=ROOT, env=_env(2), capture_output=True, text=True, timeout=300)
  assert p.returncode == 2 and "error: --devices: 4 requested, 2 available" in p.stderr, p.stderr[-2000:]
  t0 = time.monotonic()
  p = subprocess.run([sys.executable, "-m", "apps.cli", "train", "--task", TASK, *TINY, "--out", str(tmp_path / "b"),
                      "--coordinator", f"127.0.0.1:{_port()}", "--num-processes", "2", "--process-id", "1",
                      "--dist-timeout", "3"], cwd=ROOT, env=_env(1), capture_output=True, text=True, timeout=300)
  assert p.returncode == 2, p.stderr[-2000:]
  assert "error: --coordinator: could not reach the coordinator" in p.stderr
  assert time.monotonic() - t0 < 120


@pytest.mark.slow
def test_multi_gpu_benchmark_runs_on_two_cpu_devices(tmp_path):
  """benchmarks/multi_gpu.py end to end at toy size (the numbers mean nothing on CPU)."""
  config = {"unroll_length": 8, "num_minibatches": 2, "batch_size": 4, "num_updates_per_batch": 2,
            "episode_length": 24, "policy_hidden_sizes": [16, 16], "value_hidden_sizes": [16, 16], "num_eval_envs": 8}
  p = subprocess.run([sys.executable, "benchmarks/multi_gpu.py", "--task", TASK, "--devices", "1,2",
                      "--envs-per-device", "8", "--eval-episodes-per-device", "4", "--fragility", "1,2",
                      "--iterations", "4", "--eval-points", "2", "--config", json.dumps(config),
                      "--results-dir", str(tmp_path)], cwd=ROOT, env=_env(2), capture_output=True, text=True,
                     timeout=1500)
  assert p.returncode == 0, p.stderr[-3000:]
  res = json.load(open(tmp_path / "multi_gpu_cpu.json"))
  assert [r["devices"] for r in res["rows"]] == [1, 2]
  for r in res["rows"]:
    assert len(r["train"]["env_steps_per_s"]["runs"]) == 2 and len(r["eval"]["env_steps_per_s"]["runs"]) == 2
    assert r["train"]["config"]["num_envs"] == 8 * r["devices"] and r["train"]["curve"]
  assert (tmp_path / "multi_gpu_cpu.md").exists() and (tmp_path / "multi_gpu_cpu_curves.png").exists()


def test_replicas_stay_equal_across_env_shards_and_the_iteration_compiles_once():
  """shard_map runs with check_vma=False (MJX's solver does not type-check under it): the leaves laid out
  P(seeds) — weights, optimizer, normaliser, multiplier, RNG — must still be equal on every env shard.
  And the iteration compiles once: its output state, fed back, must hit the same jit cache entry (a
  P() vs P(seeds) mismatch once recompiled it at iteration 2, seconds lost inside the timed iterations).
  And --profile, which feeds the iteration a copy of the state, runs on 2 devices."""
  code = """
import sys
import jax, numpy as np, train
from train.experiments.pusher import PusherEnv
r = train.train(PusherEnv(), seeds=(3,), devices=2, num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8,
                num_updates_per_batch=2, episode_length=24, policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16),
                num_eval_envs=8, num_timesteps=512, progress=False)
ts = r.train_state
for tree in (ts.params, ts.opt_state, ts.normalizer, ts.multiplier, ts.rng, ts.iteration):
  for leaf in jax.tree.leaves(tree):
    a, b = (np.asarray(s.data) for s in leaf.addressable_shards)
    assert np.array_equal(a, b), leaf.shape
print("REPLICAS EQUAL")
print("PROFILED RUN", file=sys.stderr, flush=True)
r = train.train(PusherEnv(), seeds=(3,), devices=2, num_envs=16, unroll_length=8, num_minibatches=2, batch_size=8,
                num_updates_per_batch=2, episode_length=24, policy_hidden_sizes=(16, 16), value_hidden_sizes=(16, 16),
                num_eval_envs=8, num_timesteps=256, progress=False, profile=True)
assert r.timings["profile/iteration"] > 0  # the profile feeds the iteration a copy of the state
"""
  p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(2, JAX_LOG_COMPILES="1"), capture_output=True,
                     text=True, timeout=900)
  assert p.returncode == 0 and "REPLICAS EQUAL" in p.stdout, p.stderr[-3000:]
  first = p.stderr.split("PROFILED RUN")[0]
  assert first.count("Compiling jit(train_iteration)") == 1, first.count("Compiling jit(train_iteration)")


def test_several_devices_switch_to_gspmd(monkeypatch):
  # XLA:GPU 0.11.2 crashes compiling the training iteration in its Shardy export pass (train/mesh.py).
  before = jax.config.jax_use_shardy_partitioner
  try:
    jax.config.update("jax_use_shardy_partitioner", True)
    assert not M.use_gspmd(1) and jax.config.jax_use_shardy_partitioner  # one device: left alone
    monkeypatch.setenv("MJX_DAMAGE_SHARDY", "1")
    assert not M.use_gspmd(2) and jax.config.jax_use_shardy_partitioner  # the user's choice wins
    monkeypatch.delenv("MJX_DAMAGE_SHARDY")
    assert M.use_gspmd(2) and not jax.config.jax_use_shardy_partitioner
  finally:
    jax.config.update("jax_use_shardy_partitioner", before)


@pytest.mark.parametrize("parts", ["", "eval,bogus", "training"])
def test_multi_gpu_benchmark_refuses_bad_parts(parts, capsys):
  mg = load_benchmark("multi_gpu")
  with pytest.raises(SystemExit) as e:
    mg.parse(["--parts", parts])
  assert e.value.code == 2 and "--parts" in capsys.readouterr().err
  assert mg.parse(["--parts", "train"]).parts == ["train"]


@pytest.mark.parametrize("argv", [["--robot", "no_such_robot"], ["--task", TASK, "--robot", "panda"],
                                  ["--task", "navigate_and_pick", "--robot", "panda_wrist"]])
def test_multi_gpu_benchmark_refuses_a_bad_robot(argv, capsys):
  with pytest.raises(SystemExit) as e:
    load_benchmark("multi_gpu").parse(argv)
  assert e.value.code == 2 and "--robot" in capsys.readouterr().err


def test_multi_gpu_benchmark_keeps_the_gripper_and_its_file_names(tmp_path, monkeypatch):
  """The committed results are the gripper's: its default and file names do not follow tasks.robots.DEFAULT;
  another robot's files carry its name."""
  import tasks

  monkeypatch.setattr(tasks.robots, "DEFAULT", "panda")
  mg = load_benchmark("multi_gpu")
  seen = []
  monkeypatch.setattr(mg, "eval_runs", lambda args, d, save: seen.append(args.task_kwargs) or {
      "episodes": 4, "env_steps_per_s": {"runs": [1.0], "mean": 1.0, "min": 1.0, "max": 1.0}})
  base = ["--devices", "1", "--parts", "eval", "--results-dir", str(tmp_path)]
  assert mg.main(base) == 0 and mg.main(base + ["--robot", "panda"]) == 0
  assert seen == [{"robot": "gripper"}, {"robot": "panda"}]
  assert {"multi_gpu_cpu.json", "multi_gpu_panda_cpu.json"} <= set(os.listdir(tmp_path))


def test_multi_gpu_append_merges_a_train_call_and_an_eval_call(tmp_path, monkeypatch):
  """A training-only call and an evaluation-only call (e.g. two device calls under a time limit) end in one
  row per device count, each part with its own command; a call's own parts replace the earlier ones."""
  mg = load_benchmark("multi_gpu")
  rate = lambda v: {"runs": [v], "mean": v, "min": v, "max": v}
  monkeypatch.setattr(mg, "train_runs", lambda args, d, save: {"config": {"num_envs": 8 * d}, "curve": [],
                                                               "env_steps_per_s": rate(100.0 * d)})
  monkeypatch.setattr(mg, "eval_runs", lambda args, d, save: {"episodes": 4 * d, "env_steps_per_s": rate(50.0 * d)})
  base = ["--devices", "1", "--results-dir", str(tmp_path)]
  assert mg.main(base + ["--parts", "train"]) == 0
  assert mg.main(base + ["--parts", "eval", "--append"]) == 0
  rows = json.load(open(tmp_path / "multi_gpu_cpu.json"))["rows"]
  assert len(rows) == 1 and rows[0]["train"]["env_steps_per_s"]["mean"] == 100.0
  assert rows[0]["eval"]["env_steps_per_s"]["mean"] == 50.0
  assert "--parts train" in rows[0]["train"]["command"] and "--parts eval" in rows[0]["eval"]["command"]
  md = open(tmp_path / "multi_gpu_cpu.md").read()
  assert "--parts train" in md and "--parts eval" in md and "| 1 | 8 | 100 (100–100)" in md
  monkeypatch.setattr(mg, "eval_runs", lambda args, d, save: {"episodes": 4 * d, "env_steps_per_s": rate(70.0 * d)})
  assert mg.main(base + ["--parts", "eval", "--append"]) == 0
  rows = json.load(open(tmp_path / "multi_gpu_cpu.json"))["rows"]
  assert rows[0]["eval"]["env_steps_per_s"]["mean"] == 70.0 and rows[0]["train"]["env_steps_per_s"]["mean"] == 100.0
  assert mg.main(base + ["--parts", "eval"]) == 0  # without --append a call starts the file afresh
  assert "train" not in json.load(open(tmp_path / "multi_gpu_cpu.json"))["rows"][0]


def test_multi_gpu_keeps_the_finished_repeats_when_a_time_limit_ends_the_run(tmp_path, monkeypatch):
  """A device call's time limit (SIGTERM) mid-run must not lose the repeats already timed."""
  mg = load_benchmark("multi_gpu")

  def cut_short(args, d, save):
    save({"config": {"num_envs": 8}, "curve": [], "env_steps_per_s": {"runs": [123.0], "mean": 123.0,
                                                                       "min": 123.0, "max": 123.0}})
    raise SystemExit(124)  # the second repeat never finishes

  monkeypatch.setattr(mg, "train_runs", cut_short)
  with pytest.raises(SystemExit):
    mg.main(["--devices", "1", "--parts", "train", "--results-dir", str(tmp_path)])
  row, = json.load(open(tmp_path / "multi_gpu_cpu.json"))["rows"]
  assert row["devices"] == 1 and row["train"]["env_steps_per_s"]["runs"] == [123.0]


def test_multi_gpu_benchmark_runs_as_two_processes(tmp_path):
  """benchmarks/multi_gpu.py over JAX's distributed runtime, one device per process: process 0 writes
  a ``_2proc`` file whose 2-device row timed the sweep over both processes' devices."""
  port = _port()
  argv = [sys.executable, "benchmarks/multi_gpu.py", "--task", TASK, "--parts", "eval", "--devices", "2",
          "--eval-episodes-per-device", "4", "--fragility", "1,2",
          "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--results-dir", str(tmp_path)]
  procs = [subprocess.Popen(argv + ["--process-id", str(i)], cwd=ROOT, env=_env(1), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True) for i in range(2)]
  outs = [p.communicate(timeout=600) for p in procs]
  for p, (out, err) in zip(procs, outs):
    assert p.returncode == 0, err[-3000:]
  assert sorted(os.listdir(tmp_path)) == ["multi_gpu_cpu_2proc.json", "multi_gpu_cpu_2proc.md",
                                          "multi_gpu_cpu_2proc_curves.png"]
  res = json.load(open(tmp_path / "multi_gpu_cpu_2proc.json"))
  assert res["processes"] == 2 and [r["devices"] for r in res["rows"]] == [2]
  assert res["rows"][0]["eval"]["episodes"] == 2 * 4 * 2 and len(res["rows"][0]["eval"]["env_steps_per_s"]["runs"]) == 2
  assert "2 processes" in (tmp_path / "multi_gpu_cpu_2proc.md").read_text()


def test_multi_gpu_benchmark_refuses_device_counts_not_split_over_the_processes():
  mg = load_benchmark("multi_gpu")
  with pytest.raises(SystemExit, match="--devices: 3 cannot be split evenly over --num-processes 2"):
    mg.device_counts("3", 4, 2)
  with pytest.raises(SystemExit):
    mg.parse(["--coordinator", "127.0.0.1:1234"])  # no --num-processes / --process-id: argparse's exit 2

"""``mjx-damage`` as a user runs it (issue 23 "Must show"): subprocesses started in an empty temporary
directory, tiny sizes.

* nothing appears there but ``runs/`` (no ``--out``) or the paths asked for;
* a second identical ``train --out`` exits 2 in one line and leaves the first run's files byte-identical;
* SIGINT while ``train`` compiles ends with status 130, one ``interrupted; …`` line, no traceback;
* SIGINT during training does the same and leaves a readable checkpoint;
* SIGKILL at a random moment, then ``--resume``, ends bitwise equal to an uninterrupted run.

The trainer runs on ``train.experiments.pusher:PusherEnv`` (one contact pair: compiles in seconds).
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TRAIN = ["train", "--task", "train.experiments.pusher:PusherEnv", "--num-envs", "8", "--batch-size", "8",
         "--num-minibatches", "1", "--updates-per-batch", "1", "--timesteps", "160", "--eval-envs", "2",
         "--no-progress"]


def _env(**extra) -> dict:
  env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu", **extra)
  if extra.get("MJX_DAMAGE_CACHE_DIR") == "off":  # JAX itself would read the suite's cache dir (conftest.py)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
  return env


def _run(args, cwd, timeout=300, **extra) -> subprocess.CompletedProcess:
  return subprocess.run([sys.executable, "-m", "apps.cli", *args], cwd=cwd, env=_env(**extra),
                        capture_output=True, text=True, timeout=timeout)


def _tree(path) -> dict:
  """Every file under ``path`` → sha256 of its bytes."""
  out = {}
  for d, _, files in os.walk(path):
    for f in files:
      p = os.path.join(d, f)
      with open(p, "rb") as fh:
        out[os.path.relpath(p, path)] = hashlib.sha256(fh.read()).hexdigest()
  return out


def test_eval_without_out_writes_one_run_folder(tmp_path):
  p = _run(["eval", "--task", "drop", "--policy", "zero", "--episodes", "2"], tmp_path)
  assert p.returncode == 0, p.stderr[-2000:]
  assert os.listdir(tmp_path) == ["runs"]
  (run,) = os.listdir(tmp_path / "runs")
  assert run.startswith("eval-drop-") and os.listdir(tmp_path / "runs" / run) == ["result.json"]
  where = os.path.join("runs", run, "result.json")
  first, last = p.stdout.splitlines()[0], p.stdout.strip().splitlines()[-1]
  assert where in first and "compiling" in p.stdout.splitlines()[1]  # said before compiling
  assert last == f"outputs: {where}"
  assert "Traceback" not in p.stderr

  q = _run(["eval", "--task", "drop", "--policy", "zero", "--episodes", "2", "--out", "r.json"], tmp_path)
  assert q.returncode == 0, q.stderr[-2000:]
  assert sorted(os.listdir(tmp_path)) == ["r.json", "runs"]
  again = _run(["eval", "--task", "drop", "--policy", "zero", "--episodes", "2", "--out", "r.json"], tmp_path)
  assert again.returncode == 2 and again.stderr.strip().count("\n") == 0, again.stderr
  assert "--overwrite" in again.stderr and "compiling" not in again.stdout


def test_second_train_is_refused_and_first_run_untouched(tmp_path):
  p = _run(TRAIN + ["--out", "r"], tmp_path)
  assert p.returncode == 0, p.stderr[-3000:]
  assert os.listdir(tmp_path) == ["r"]
  before = _tree(tmp_path / "r")
  assert "checkpoint.npz" in before and "config.json" in before
  assert p.stdout.strip().splitlines()[-1].startswith("outputs: r ")

  t0 = time.perf_counter()
  q = _run(TRAIN + ["--out", "r"], tmp_path)
  assert q.returncode == 2, q.stderr[-2000:]
  err = q.stderr.strip().splitlines()
  assert len(err) == 1 and "--resume" in err[0] and "--overwrite" in err[0], q.stderr
  assert "compiling" not in q.stdout
  assert time.perf_counter() - t0 < 60  # refused at argument parsing, not after a compile
  assert _tree(tmp_path / "r") == before
  assert os.listdir(tmp_path) == ["r"]


def test_sigint_while_train_compiles_exits_130_without_traceback(tmp_path):
  # Cache off: the compile must really happen, so the signal lands in it.
  proc = subprocess.Popen([sys.executable, "-m", "apps.cli", *TRAIN, "--out", "r"], cwd=tmp_path,
                          env=_env(MJX_DAMAGE_CACHE_DIR="off"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True)
  try:
    seen = []
    for line in proc.stdout:  # wait for the line printed just before compiling
      seen.append(line)
      if line.startswith("compiling"):
        break
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
  finally:
    if proc.poll() is None:
      proc.kill()
  assert any(s.startswith("compiling") for s in seen), "".join(seen)
  assert proc.returncode == 130, err[-2000:]
  assert "Traceback" not in err and "Segmentation" not in err
  assert [ln for ln in err.splitlines() if ln.strip()][-1].startswith("interrupted"), err


def test_sigint_during_training_keeps_a_checkpoint(tmp_path):
  """SIGINT once the loop runs: train.ppo's handler finishes the iteration, writes the checkpoint, exits 130."""
  args = [a for a in TRAIN if a != "--no-progress"]
  args[args.index("--timesteps") + 1] = "80000"  # 1000 iterations: still running when the signal comes
  proc = subprocess.Popen([sys.executable, "-m", "apps.cli", *args, "--out", "r"], cwd=tmp_path, env=_env(),
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
  err = b""
  try:
    while b"seeds" not in err:  # the progress bar exists: train.ppo's signal handler is about to be installed
      chunk = os.read(proc.stderr.fileno(), 4096)
      assert chunk, err.decode()[-2000:]
      err += chunk
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=240)
    err = (err + rest).decode()
  finally:
    if proc.poll() is None:
      proc.kill()
  assert proc.returncode == 130, err[-2000:]
  assert "Traceback" not in err
  last = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip()][-1]
  assert last.startswith("interrupted") and "checkpoint at iteration" in last, last
  from train import checkpoint as ckpt
  meta = ckpt.read_meta(str(tmp_path / "r" / ckpt.FILENAME))
  assert 1 <= meta["iteration"] < 1000


def test_sigkill_then_resume_ends_bitwise_equal_to_an_uninterrupted_run(tmp_path):
  """Crash safety (issue 19): SIGKILL at a random moment after the first checkpoint, then ``--resume``,
  gives the same final train state, bit for bit on CPU, as a run that was never interrupted."""
  import random

  import numpy as np

  from train import checkpoint as ckpt

  args = list(TRAIN)
  args[args.index("--timesteps") + 1] = "4800"  # 75 iterations of 64 env steps
  args += ["--checkpoint-every", "640", "--eval-every", "1600"]  # a checkpoint every 10 iterations
  full = _run(args + ["--out", "full"], tmp_path)
  assert full.returncode == 0, full.stderr[-2000:]

  proc = subprocess.Popen([sys.executable, "-m", "apps.cli", *args, "--out", "killed"], cwd=tmp_path,
                          env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
  target = tmp_path / "killed" / ckpt.FILENAME
  try:
    deadline = time.time() + 240
    while not target.exists() and proc.poll() is None and time.time() < deadline:
      time.sleep(0.05)
    assert target.exists(), "no checkpoint before the run ended"
    time.sleep(random.uniform(0.0, 0.5))  # a random moment: mid-iteration, mid-write or between them
    proc.kill()
    proc.wait(timeout=30)
  finally:
    if proc.poll() is None:
      proc.kill()
  killed_at = ckpt.read_meta(str(target))["iteration"]
  assert killed_at < 75, "the run ended before the kill: nothing was tested"
  resumed = _run(args + ["--out", "killed", "--resume"], tmp_path)
  assert resumed.returncode == 0, resumed.stderr[-2000:]

  a, b = np.load(tmp_path / "full" / ckpt.FILENAME), np.load(target)
  keys = sorted(k for k in a.files if k != "meta")
  assert keys == sorted(k for k in b.files if k != "meta") and keys
  for k in keys:
    np.testing.assert_array_equal(a[k], b[k], err_msg=f"{k} (killed after iteration {killed_at})")

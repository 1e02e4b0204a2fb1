"""``--deterministic`` (mjx_damage.runtime.use_deterministic_gpu_ops): every training command line puts XLA's
deterministic-GPU-kernel flag into XLA_FLAGS before a backend starts, refuses a contradicting XLA_FLAGS
naming the option, and says so when a backend has already started (XLA would ignore the flag).

One fresh Python process for all of it: XLA reads its flags when the first backend starts, which a test
process has long done."""

import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SCRIPT = r"""
import contextlib, io, json, os, sys
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
from mjx_damage import runtime
FLAG = runtime.GPU_DETERMINISM_FLAG
base = os.environ.get("XLA_FLAGS", "")
out = {"base": base}

def flags():
  return os.environ.get("XLA_FLAGS", "")

runtime.use_deterministic_gpu_ops()
runtime.use_deterministic_gpu_ops()  # a second call adds nothing
out["runtime"] = flags()
os.environ["XLA_FLAGS"] = base
import rl_multiseed
rl_multiseed.parse(["--deterministic"])
out["multiseed"] = flags()
os.environ["XLA_FLAGS"] = base
import rl_brax_ppo
rl_brax_ppo.parse_args(["--deterministic", "--seeds", "0"])
out["brax"] = flags()
os.environ["XLA_FLAGS"] = base
from train import cli
err = io.StringIO()
with contextlib.redirect_stderr(err):  # a bad value after it: the flag is set first, then the error
  out["train_rc"] = cli.main(["--task", "place_plate", "--deterministic", "--time-limit", "-1"])
out["train"], out["train_err"] = flags(), err.getvalue()
os.environ["XLA_FLAGS"] = base + " --xla_gpu_deterministic_ops=false"
try:
  runtime.use_deterministic_gpu_ops("--deterministic")
except ValueError as e:
  out["conflict"] = str(e)
err = io.StringIO()
with contextlib.redirect_stderr(err), contextlib.suppress(SystemExit):
  rl_multiseed.parse(["--deterministic"])
out["multiseed_conflict"] = err.getvalue()
os.environ["XLA_FLAGS"] = base + " " + FLAG
import jax.numpy as jnp
out["cpu_sum"] = float(jnp.arange(4.0).sum())  # a CPU backend starts with the flag: runs as before
runtime.use_deterministic_gpu_ops()  # already in force: nothing to do, no error
os.environ["XLA_FLAGS"] = base
try:
  runtime.use_deterministic_gpu_ops("--deterministic")
except RuntimeError as e:
  out["late"] = str(e)
err = io.StringIO()
with contextlib.redirect_stderr(err):
  out["train_late_rc"] = cli.main(["--task", "place_plate", "--deterministic"])
out["train_late_err"] = err.getvalue()
print("RESULT" + json.dumps(out))
"""


def test_deterministic_option_sets_the_xla_flag_before_any_backend_and_refuses_otherwise():
  env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT)
  env.pop("XLA_FLAGS", None)
  proc = subprocess.run([sys.executable, "-c", f"ROOT = {ROOT!r}\n" + SCRIPT], env=env, cwd=ROOT,
                        capture_output=True, text=True, timeout=600)
  assert proc.returncode == 0, proc.stderr[-3000:]
  out = json.loads(proc.stdout.split("RESULT", 1)[1])
  flag = "--xla_gpu_deterministic_ops=true"
  assert flag not in out["base"].split()
  for key in ("runtime", "multiseed", "brax", "train"):
    assert out[key].split() == out["base"].split() + [flag], key  # added once, the package's CPU flags kept
  assert out["train_rc"] != 0 and "--time-limit" in out["train_err"]
  assert "--deterministic" in out["conflict"] and "=false" in out["conflict"]
  assert "--deterministic" in out["multiseed_conflict"]
  assert out["cpu_sum"] == 6.0
  assert "--deterministic" in out["late"] and "already started" in out["late"]
  assert out["train_late_rc"] != 0 and "--deterministic" in out["train_late_err"]

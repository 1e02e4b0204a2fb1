"""``--matmul-precision`` (mjx_damage.runtime.use_matmul_precision): every training command line sets JAX's
float32 matmul precision before anything is traced, refuses other values before anything is built, records the
precision in force (also when JAX_DEFAULT_MATMUL_PRECISION set it) in its rows, labels and rerun command, and
the trainer table keeps runs of other precisions apart.

One fresh Python process for the command lines: the option changes a process-wide JAX setting."""

import json
import os
import subprocess
import sys

import jax
import pytest
from conftest import load_benchmark

from mjx_damage import runtime

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def restore_precision():
  before = jax.config.jax_default_matmul_precision
  yield
  jax.config.update("jax_default_matmul_precision", before)


def test_use_matmul_precision_sets_jaxs_option_and_reads_back(restore_precision):
  runtime.use_matmul_precision("float32")
  assert jax.config.jax_default_matmul_precision == "float32" and runtime.matmul_precision() == "float32"
  f = jax.jit(lambda a: a @ a).lower(jax.numpy.ones((2, 2))).as_text()
  assert "HIGHEST" in f  # a program traced now computes its products at full precision
  runtime.use_matmul_precision("default")
  assert jax.config.jax_default_matmul_precision is None and runtime.matmul_precision() == "default"
  jax.config.update("jax_default_matmul_precision", "highest")  # JAX's synonym
  assert runtime.matmul_precision() == "float32"
  jax.config.update("jax_default_matmul_precision", "tensorfloat32")
  assert runtime.matmul_precision() == "tensorfloat32"


@pytest.mark.parametrize("value", ["highest", "tf32", "", "FLOAT32"])
def test_other_values_are_refused_naming_the_option(value, restore_precision):
  with pytest.raises(ValueError, match="--matmul-precision: one of default, float32"):
    runtime.use_matmul_precision(value)
  assert jax.config.jax_default_matmul_precision is None


def test_flags_in_force_name_what_the_environment_set(restore_precision, monkeypatch):
  monkeypatch.setenv("XLA_FLAGS", "")
  assert runtime.flags_in_force(False, None) == ""
  jax.config.update("jax_default_matmul_precision", "float32")  # as JAX_DEFAULT_MATMUL_PRECISION=float32 does
  assert runtime.flags_in_force(False, None) == " --matmul-precision float32"
  assert runtime.flags_in_force(False, "float32") == ""  # given: the command says it
  monkeypatch.setenv("XLA_FLAGS", runtime.GPU_DETERMINISM_FLAG)
  assert runtime.flags_in_force(False, None) == " --deterministic --matmul-precision float32"
  assert runtime.flags_in_force(True, "default") == ""


SCRIPT = r"""
import contextlib, io, json, os, sys
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
import jax
from mjx_damage import runtime
out = {"env": jax.config.jax_default_matmul_precision}
import rl_multiseed, rl_brax_ppo
from train import cli
a = rl_multiseed.parse(["--methods", "penalty", "--matmul-precision", "default"])
out["multiseed_default"] = [jax.config.jax_default_matmul_precision, rl_multiseed.method_spec("penalty", a)["label"]]
a = rl_multiseed.parse(["--methods", "penalty", "--matmul-precision", "float32"])
out["multiseed"] = [jax.config.jax_default_matmul_precision, rl_multiseed.method_spec("penalty", a)["label"]]
jax.config.update("jax_default_matmul_precision", None)
rl_brax_ppo.parse_args(["--matmul-precision", "float32", "--seeds", "0"])
out["brax"] = jax.config.jax_default_matmul_precision
out["brax_label"] = [rl_brax_ppo._matmul_label({"matmul_precision": "float32"}), rl_brax_ppo._matmul_label({})]
jax.config.update("jax_default_matmul_precision", None)
err = io.StringIO()
with contextlib.redirect_stderr(err):  # a bad value after it: the option is applied first, then the error
  out["train_rc"] = cli.main(["--task", "place_plate", "--matmul-precision", "float32", "--time-limit", "-1"])
out["train"], out["train_err"] = jax.config.jax_default_matmul_precision, err.getvalue()
for name, call in (("multiseed_bad", lambda: rl_multiseed.parse(["--matmul-precision", "highest"])),
                   ("brax_bad", lambda: rl_brax_ppo.parse_args(["--matmul-precision", "bf16", "--seeds", "0"])),
                   ("train_bad", lambda: cli.main(["--task", "place_plate", "--matmul-precision", "x"]))):
  err = io.StringIO()
  with contextlib.redirect_stderr(err), contextlib.suppress(SystemExit):
    call()
  out[name] = err.getvalue()
print("RESULT" + json.dumps(out))
"""


def test_training_command_lines_set_the_precision_and_refuse_other_values():
  env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT, JAX_DEFAULT_MATMUL_PRECISION="float32")
  proc = subprocess.run([sys.executable, "-c", f"ROOT = {ROOT!r}\n" + SCRIPT], env=env, cwd=ROOT,
                        capture_output=True, text=True, timeout=600)
  assert proc.returncode == 0, proc.stderr[-3000:]
  out = json.loads(proc.stdout.split("RESULT", 1)[1])
  assert out["env"] == "float32"  # the environment's setting, which the option overrides
  assert out["multiseed_default"] == [None, "damage penalty (w=2)"]
  assert out["multiseed"] == ["float32", "damage penalty (w=2), float32 matmuls"]
  assert out["brax"] == "float32" and out["brax_label"] == [", float32 matmuls", ""]
  assert out["train"] == "float32" and out["train_rc"] != 0 and "--time-limit" in out["train_err"]
  for key in ("multiseed_bad", "brax_bad", "train_bad"):
    assert "--matmul-precision" in out[key] and "invalid choice" in out[key], (key, out[key])


def test_the_trainer_table_keeps_runs_of_another_precision_apart(tmp_path):
  table = load_benchmark("trainer_table")
  src = os.path.join(ROOT, "benchmarks", "results", "rl_pick_egg_nvidia_h200_held_std0_task_only_obsclip_stdparam.json")
  with open(src) as f:
    doc = json.load(f)
  other = json.loads(json.dumps(doc))
  for r in other["rows"]:
    r["matmul_precision"] = "float32"
  runs = table.ours_runs(doc, "a.json", "mode") + table.ours_runs(other, "b.json", "mode")
  groups = table.groups(runs)
  assert len(groups) == 2 and all(len(g["runs"]) == 3 for g in groups)
  assert "matmuls" not in groups[0]["settings"] and "float32 matmuls" in groups[1]["settings"]
  brax = os.path.join(ROOT, "benchmarks", "results", "rl_brax_shelve_item_nvidia_h200_h200_brax_w0_s0.json")
  with open(brax) as f:
    bdoc = json.load(f)
  assert "matmuls" not in table.brax_runs(bdoc, "c.json", "mode")[0]["settings"]
  for r in bdoc["rows"]:
    r["matmul_precision"] = "float32"
  assert "float32 matmuls" in table.brax_runs(bdoc, "c.json", "mode")[0]["settings"]

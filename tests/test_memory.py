"""Memory estimate: a batch that cannot fit is refused before anything compiles, naming the flag and
the largest value that fits; one that fits passes; the CLI turns the refusal into one line, exit 2."""

import os
import subprocess
import sys

import jax
import pytest

import train.evaluate as E
from mjx_damage.wrapper import DamageWrapper
from tasks.bench_table import table_env
from train import memory as MEM
from train.config import PPOConfig
from train.iteration import Trainer
from train.ppo import check_memory

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def env():
  return DamageWrapper(table_env(k=1, n_substeps=2, episode_length=8))


def test_check_fits_message_names_field_and_largest():
  MEM.check_fits("num_envs", 10, needed=100, per_unit=10, available=1000)
  with pytest.raises(ValueError, match=r"^num_envs: 1000 needs about .* the largest that fits is about 85$"):
    MEM.check_fits("num_envs", 1000, needed=10_000, per_unit=10, available=1000)
  MEM.check_fits("num_envs", 10**9, needed=10**15, per_unit=10**6, available=None)  # unknown: accepted


def test_estimates_grow_with_the_batch(env):
  s = MEM.state_bytes(env)
  assert s > 1000  # mjx.Data of a real scene, not an empty tree
  assert MEM.eval_bytes(s, 64) == 64 * MEM.eval_bytes(s, 1)
  assert MEM.train_bytes(s, 10, 2, 64, 64, 10, seeds=2) == 2 * MEM.train_bytes(s, 10, 2, 64, 64, 10)
  assert MEM.available_bytes() is None or MEM.available_bytes() > 0


def test_evaluation_refused_before_compiling(env):
  with pytest.raises(ValueError, match=r"^episodes: 4096 needs about"):
    E.check_memory(env, 4096, jax.devices()[:1], available=10**6)
  E.check_memory(env, 4, jax.devices()[:1], available=10**12)


def test_training_refused_before_compiling(env):
  cfg = PPOConfig.preset("playground", num_envs=64, batch_size=16, num_minibatches=4, episode_length=8,
                         num_timesteps=10_000).validate()
  trainer = Trainer(env, cfg)
  with pytest.raises(ValueError, match=r"^num_envs: 64 needs about .* training, .* the largest that fits is about \d+$"):
    check_memory(trainer, cfg, available=10**6)
  check_memory(trainer, cfg, available=10**12)


def test_cli_refuses_a_batch_that_cannot_fit(tmp_path):
  """A hundred million episodes of a task in one MJX batch: one line naming --episodes-as-field, exit 2, well
  before any compile. (``--backend mjx``: the native backend steps --native-envs at a time, so its memory
  does not grow with --episodes; on a CPU ``auto`` would pick it.)"""
  p = subprocess.run([sys.executable, "-m", "apps.cli", "eval", "--task", "push_boxes", "--policy", "zero",
                      "--backend", "mjx", "--episodes", "100000000", "--out", str(tmp_path / "r.json")], cwd=tmp_path,
                     env=dict(os.environ, PYTHONPATH=ROOT), capture_output=True, text=True, timeout=300)
  assert p.returncode == 2, p.stderr[-2000:]
  err = [line for line in p.stderr.splitlines() if line.strip()]
  assert len(err) == 1 and "episodes: 100000000 needs about" in err[0] and "largest that fits" in err[0], p.stderr
  assert not (tmp_path / "r.json").exists()

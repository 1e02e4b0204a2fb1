"""benchmarks/soak.py: its on-device checks catch what they claim to, and a small soak of a task passes.

The full soak (every task, the results file) is ``benchmarks/soak.py``; the
``slow`` tests here run it on tasks at a reduced size (the default suite's per-task
extreme-action checks are tests/test_task_contract.py's).
"""

import jax
import jax.numpy as jnp
import pytest
from brax.envs.base import Wrapper
from conftest import load_benchmark

import mjx_damage as md
import tasks
from tasks.drop import DropEnv

soak = load_benchmark("soak")


def run_soak(env, envs, chunks, chunk, extreme_frac, episode_length=None, seed=0) -> dict:
  reset, run = soak.build(env, envs, chunk, extreme_frac, episode_length)
  carry = reset(jax.random.PRNGKey(seed))
  for _ in range(chunks):
    carry = run(carry)
  return {k: int(v) for k, v in jax.device_get(carry[-1]).items()}


class ActedDrop(DropEnv):
  """DropEnv with a 3-D action it ignores (the soak needs actions to sanitise)."""

  episode_length = 8

  @property
  def action_size(self):
    return 3


class Corrupt(Wrapper):
  """Breaks the invariants the soak checks whenever action[0] > 0.5: health +1 (so above 100 at
  full health, and a rise), NaN observation."""

  def step(self, state, action):
    s = self.env.step(state, action)
    hit = action[0] > 0.5
    info = dict(s.info, link_health=s.info["link_health"] + jnp.where(hit, 1.0, 0.0))
    return s.replace(obs=jnp.where(hit, jnp.nan, s.obs), info=info)


def test_soak_counters_catch_broken_invariants():
  clean = run_soak(md.DamageWrapper(ActedDrop()), envs=3, chunks=1, chunk=20, extreme_frac=0.2)
  assert all(clean[k] == 0 for k in soak.COUNTERS), clean
  assert clean["steps"] == 60 and clean["episodes"] == 3 * 2  # 20 steps of 8-step episodes: 2 ends per env
  assert clean["action_sanitised"] == clean["extreme_injected"] > 0
  broken = run_soak(Corrupt(md.DamageWrapper(ActedDrop())), envs=3, chunks=1, chunk=20, extreme_frac=0.2)
  assert broken["non_finite"] > 0 and broken["health_out_of_range"] > 0 and broken["health_increase"] > 0, broken
  assert broken["particle_violations"] == 0 and broken["sanitise_mismatch"] == 0


@pytest.mark.slow
def test_soak_place_plate_small():
  """Two envs, 40 steps of 15-step episodes (auto-resets included), 20 % extreme action entries.

  Slow (two compiles of a task program of its own): the default suite covers each part elsewhere —
  the soak's counters and auto-reset bookkeeping above (DropEnv), and every task, place_plate
  included, under 20 % extreme action entries with health bounded and never rising, the state
  finite and the sanitised count exact in tests/test_task_contract.py; ``test_soak_every_task``
  runs this harness on every task."""
  c = run_soak(tasks.make("place_plate"), envs=2, chunks=2, chunk=20, extreme_frac=0.2, episode_length=15)
  assert c["steps"] == 80 and c["episodes"] == 2 * 2
  assert all(c[k] == 0 for k in soak.COUNTERS), c
  assert c["action_sanitised"] == c["extreme_injected"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("name", tasks.names())
def test_soak_every_task(name):
  """The CPU defaults of benchmarks/soak.py (8 envs × 400 steps, chunks of 200) for one task."""
  r = soak.soak_task(name, envs=8, steps=400, chunk=200, extreme_frac=0.05)
  # every env ends an episode (auto-reset) every episode_length steps: ≥ 2 in 400 steps for ≤ 200-step tasks
  assert r["steps"] == 3200 and r["episodes"] >= 8 * (400 // tasks.default_config(name)["episode_length"])
  assert soak.failures(r) == 0, r
  assert r["action_sanitised"] == r["extreme_injected"] > 0
  if name == "pour_water":
    assert r["particles"] > 0


@pytest.mark.slow
def test_soak_with_the_safe_script_and_noise():
  """``--scripted-noise``: the safe script's actions plus Gaussian noise, clipped into [−1, 1], so none is
  sanitised; nothing breaks an invariant."""
  r = soak.soak_task("place_plate", envs=2, steps=40, chunk=20, extreme_frac=0.0, scripted_noise=0.3)
  assert r["steps"] == 80 and soak.failures(r) == 0 and r["action_sanitised"] == r["extreme_injected"] == 0, r


def test_worker_argv_drops_only_the_per_worker_flags():
  argv = ["--robot", "panda", "--workers", "4", "--tasks=a,b", "--envs", "16", "--out", "x.json", "--seed=3"]
  assert soak.worker_argv(argv) == ["--robot", "panda", "--envs", "16", "--seed=3"]


@pytest.mark.parametrize("argv,field", [(["--robot", "ur5"], "--robot"), (["--workers", "0"], "--workers"),
                                        (["--robot", "gripper", "--tasks", "nope"], "--tasks"),
                                        (["--robot", "panda_wrist", "--tasks", "navigate_and_pick"], "--tasks"),
                                        (["--tasks", ","], "--tasks"),
                                        (["--scripted-noise", "-0.1"], "--scripted-noise"),
                                        (["--scripted-noise", "nan"], "--scripted-noise")])
def test_soak_cli_names_the_bad_field(argv, field, capsys):
  with pytest.raises(SystemExit) as e:
    soak.main(argv)
  assert e.value.code == 2 and field in capsys.readouterr().err


def test_soak_keeps_the_gripper_and_its_file_names(monkeypatch):
  """The committed results are the gripper's: the default robot and file names do not follow
  tasks.robots.DEFAULT; another robot's file carries its name."""
  monkeypatch.setattr(soak.robots, "DEFAULT", "panda")

  class Stop(Exception):
    pass

  def stop(name, *a, **kw):
    raise Stop(a[-1])

  monkeypatch.setattr(soak, "soak_task", stop)
  with pytest.raises(Stop, match="^gripper$"):
    soak.main(["--tasks", "place_plate", "--out", "unused.json"])
  assert soak.default_out("cpu", "gripper").endswith("soak_cpu.json")
  assert soak.default_out("cpu", "panda").endswith("soak_panda_cpu.json")


@pytest.mark.parametrize("argv, preallocate", [(["--workers", "3"], "false"), (["--workers=2"], "false"),
                                                (["--workers", "1"], None), ([], None), (["--workers"], None)])
def test_a_soak_with_workers_leaves_the_gpu_memory_to_them(argv, preallocate, monkeypatch):
  """With --workers > 1 this process only merges files: its backend starts without preallocating (JAX's
  default takes 75 % of a GPU's memory), so the workers get the GPU. Checked at the moment the backend starts."""
  monkeypatch.delenv("XLA_PYTHON_CLIENT_PREALLOCATE", raising=False)
  seen = []

  class Stop(Exception):
    pass

  def backend():
    seen.append(soak.os.environ.get("XLA_PYTHON_CLIENT_PREALLOCATE"))
    raise Stop

  monkeypatch.setattr(soak.jax, "default_backend", backend)
  with pytest.raises(Stop):
    soak.main(argv)
  assert seen == [preallocate]

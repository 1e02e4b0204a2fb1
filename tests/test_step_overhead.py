"""benchmarks/step_overhead.py: its command line refuses bad input before anything compiles, and a
precompile child gets the parent's command with only its own share of the work.

The measurement itself is a benchmark (results under benchmarks/results/step_overhead_*)."""

import pytest
from conftest import load_benchmark

from apps.workers import argv_without

so = load_benchmark("step_overhead")


@pytest.mark.parametrize("argv,field", [
    (["--robot", "ur5"], "--robot"),
    (["--robot", "panda_wrist", "--tasks", "navigate_and_pick"], "--tasks"),
    (["--precompile-workers", "-1"], "--precompile-workers"),
    (["--variants", "task,warp"], "--variants"),
    (["--envs", "0"], "--envs"),
])
def test_cli_names_the_bad_field(argv, field, capsys):
  with pytest.raises(SystemExit) as e:
    so.main(argv)
  assert e.value.code == 2 and field in capsys.readouterr().err


def test_the_gripper_by_default_whatever_the_registry_default(monkeypatch):
  import tasks

  monkeypatch.setattr(tasks.robots, "DEFAULT", "panda")  # committed results were made with the gripper

  class Stop(Exception):
    pass

  def stop(name, robot):
    raise Stop(robot)

  monkeypatch.setattr(tasks, "make", stop)
  with pytest.raises(Stop, match="^gripper$"):
    so.main(["--tasks", "place_plate"])


def test_children_get_the_command_without_the_per_child_flags():
  argv = ["--envs", "32768", "--precompile-workers=6", "--tasks", "a,b", "--robot", "panda", "--variants", "task,raw"]
  assert argv_without(argv, ("--precompile-workers", "--tasks", "--variants")) == ["--envs", "32768", "--robot", "panda"]


def test_the_timing_process_loads_what_the_precompile_children_compiled(tmp_path):
  """The children must fill the cache this process reads (they once filled another directory, so every
  program compiled twice: in a child, then again while timing)."""
  import json
  import os
  import subprocess
  import sys

  root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
  env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))  # the package's default cache, in tmp
  for k in ("MJX_DAMAGE_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR"):
    env.pop(k, None)
  p = subprocess.run([sys.executable, "benchmarks/step_overhead.py", "--tasks", "pick_egg", "--variants", "raw",
                      "--envs", "3", "--steps", "1", "--repeats", "1", "--precompile-workers", "1",
                      "--out-dir", str(tmp_path)], cwd=root, env=env, capture_output=True, text=True, timeout=600)
  assert p.returncode == 0, p.stderr[-2000:]
  row, = json.load(open(tmp_path / "step_overhead_cpu.json"))["results"]
  assert row["from_cache"], p.stdout


def test_raw_replay_steps_the_physics_the_task_step_did():
  """Replaying the recorded controls through n_substeps × mjx.step from the same states reproduces the
  task rollout's qpos: the variant times the task's own physics (damage is one-way coupled)."""
  import jax
  import numpy as np

  import tasks
  from mjx_damage import physics

  env = tasks.make("pick_egg")
  task = env.unwrapped
  policy = so.make_policy(env, "mlp")
  state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 4))
  ctrls = so._task_controls(env, policy, state, 3)

  def task_qpos(s):
    return so._policy_rollout(env, policy, (s, jax.random.PRNGKey(1)), 3, lambda s: s.pipeline_state.qpos)[1]

  def replay_qpos(d):
    def body(d, c):
      d = jax.vmap(lambda d1, c1: physics.step_without_damage(task.sys, d1.replace(ctrl=c1), task.n_substeps))(d, c)
      return d, d.qpos
    return jax.lax.scan(body, d, ctrls)[1]

  want = jax.jit(task_qpos)(state)
  got = jax.jit(replay_qpos)(state.pipeline_state)
  assert float(np.abs(np.asarray(ctrls[1:]) - np.asarray(ctrls[:-1])).max()) > 1e-4  # the controls move
  np.testing.assert_allclose(got, want, atol=1e-5)


def test_no_policy_steps_the_actions_the_task_policy_chose():
  """``no_policy`` replays the recorded actions through ``env.step``: the same rollout as the ``task`` variant
  (policy and all) from the same start, so the two time the same physics and the difference is the policy."""
  import jax
  import numpy as np

  import tasks

  env = tasks.make("pick_egg")
  policy = so.make_policy(env, "mlp")
  state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 4))
  carry = (state, jax.random.PRNGKey(3))
  actions = so._task_actions(env, policy, carry, 3)

  want = jax.jit(lambda c: so._policy_rollout(env, policy, c, 3, lambda s: s.pipeline_state.qpos)[1])(carry)
  got = jax.jit(lambda s: jax.lax.scan(lambda s, a: (jax.vmap(env.step)(s, a),) * 2, s, actions)[1])(state)
  assert float(np.abs(np.asarray(actions[1:]) - np.asarray(actions[:-1])).max()) > 1e-4  # the policy acts
  np.testing.assert_allclose(got.pipeline_state.qpos, want, atol=1e-6)

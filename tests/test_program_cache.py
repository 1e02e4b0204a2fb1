"""The traced-program cache: a hit gives the same results without tracing; anything the key covers
(description, shapes, sources) misses; a corrupt entry is re-traced, never trusted; ``off`` is off."""

import os
import warnings

import jax
import jax.numpy as jnp
from jax import export
import numpy as np
import pytest

import train.evaluate as E
from mjx_damage import program_cache as P
from mjx_damage.wrapper import DamageWrapper
from tasks.bench_table import table_env

T, EPISODES = 8, 3  # tests/test_eval.py's episode length and count (the same program)


@pytest.fixture
def cache(tmp_path, monkeypatch):
  monkeypatch.setenv("MJX_DAMAGE_CACHE_DIR", str(tmp_path / "cache"))
  return tmp_path / "cache" / "programs"


@pytest.fixture
def roots(tmp_path):
  src = tmp_path / "src" / "pkg"
  src.mkdir(parents=True)
  (src / "a.py").write_text("x = 1\n")
  return (str(src),)


def traced_counter():
  """A jitted function that counts how often Python traces it."""
  count = {"n": 0}

  @jax.jit
  def f(x, y):
    count["n"] += 1
    return jnp.sin(x) * y + 1.0

  return f, count


def test_hit_skips_tracing_and_gives_identical_results(cache, roots):
  f, count = traced_counter()
  args = (np.linspace(0, 1, 5, dtype=np.float32), np.float32(2.0))
  call, how = P.load_or_export(f, args, {"name": "f"}, roots)
  assert how == "exported" and count["n"] == 1
  first = np.asarray(call(*args))
  assert len(list(cache.iterdir())) == 1
  call2, how2 = P.load_or_export(f, args, {"name": "f"}, roots)
  assert how2 == "loaded" and count["n"] == 1  # not traced again
  np.testing.assert_array_equal(np.asarray(call2(*args)), first)
  np.testing.assert_array_equal(first, np.asarray(f(*args)))


def test_key_covers_description_shapes_and_sources(cache, roots):
  f, _ = traced_counter()
  a5 = (np.zeros(5, np.float32), np.float32(1.0))
  P.load_or_export(f, a5, {"name": "f"}, roots)
  assert P.load_or_export(f, a5, {"name": "g"}, roots)[1] == "exported"
  assert P.load_or_export(f, (np.zeros(6, np.float32), np.float32(1.0)), {"name": "f"}, roots)[1] == "exported"
  k0 = P.key({"name": "f"}, a5, roots)
  with open(os.path.join(roots[0], "a.py"), "a") as fh:
    fh.write("y = 2\n")
  P.fingerprint.cache_clear()
  assert P.key({"name": "f"}, a5, roots) != k0
  assert P.load_or_export(f, a5, {"name": "f"}, roots)[1] == "exported"


def test_key_covers_the_matmul_precision(cache, roots):
  """A program traced at float32 matmul precision is another program: one loaded from a run at the backend's
  default (TF32 on a GPU) would silently compute at that precision (docs/rl_task_design.md, "TF32 in the
  simulation")."""
  def f(x):
    return x @ x
  a = (np.eye(3, dtype=np.float32),)
  assert P.load_or_export(jax.jit(f), a, {"name": "mm"}, roots)[1] == "exported"
  with jax.default_matmul_precision("float32"):
    assert P.load_or_export(jax.jit(f), a, {"name": "mm"}, roots)[1] == "exported"
    assert P.load_or_export(jax.jit(f), a, {"name": "mm"}, roots)[1] == "loaded"
  assert P.load_or_export(jax.jit(f), a, {"name": "mm"}, roots)[1] == "loaded"
  programs = [export.deserialize(bytearray(p.read_bytes())).mlir_module() for p in cache.iterdir()]
  assert sorted("HIGHEST" in m for m in programs) == [False, True]  # one entry per precision


def test_corrupt_entry_is_retraced(cache, roots):
  f, count = traced_counter()
  args = (np.ones(3, np.float32), np.float32(1.0))
  P.load_or_export(f, args, {"name": "f"}, roots)
  (entry,) = cache.iterdir()
  entry.write_bytes(b"not a program")
  with warnings.catch_warnings(record=True) as w:
    warnings.simplefilter("always")
    call, how = P.load_or_export(f, args, {"name": "f"}, roots)
  assert how == "exported" and any("unreadable" in str(x.message) for x in w)
  np.testing.assert_array_equal(np.asarray(call(*args)), np.asarray(f(*args)))
  assert P.load_or_export(f, args, {"name": "f"}, roots)[1] == "loaded"  # rewritten


def test_off_returns_the_function(monkeypatch, roots, tmp_path):
  monkeypatch.setenv("MJX_DAMAGE_CACHE_DIR", "off")
  f, _ = traced_counter()
  call, how = P.load_or_export(f, (np.ones(2, np.float32), np.float32(1.0)), {"name": "f"}, roots)
  assert how == "off" and call is f


def test_off_under_gspmd(cache, roots):
  """With JAX's GSPMD partitioner on (train.mesh's choice for several devices) nothing is exported or
  loaded: jax 0.10.2 cannot lower an exported shard_map program there."""
  f, _ = traced_counter()
  before = jax.config.jax_use_shardy_partitioner
  try:
    jax.config.update("jax_use_shardy_partitioner", False)
    call, how = P.load_or_export(f, (np.ones(2, np.float32), np.float32(1.0)), {"name": "f"}, roots)
  finally:
    jax.config.update("jax_use_shardy_partitioner", before)
  assert how == "off" and call is f and not cache.exists()


def push_policy(env):
  """tests/test_eval.py's scripted pusher policy, op for op: with its env (below) the plain evaluation
  is the program test_eval.py compiles, a persistent-cache hit here (one compile fewer in the suite)."""
  radius = env.unwrapped.radius

  def policy(state, rng):
    target = state.obs[2:4] / radius
    return jnp.clip(target + 0.1 * jax.random.normal(rng, (2,)), -1.0, 1.0)

  return policy


def test_evaluator_with_program_equals_plain_evaluation(cache, roots):
  """A (tiny) damage-wrapped env: the cached program's per-episode results equal the plain jit's."""
  env = DamageWrapper(table_env(k=1, n_substeps=2, episode_length=T), terminate_on_destroyed=True)
  policy = push_policy(env)
  plain = E.evaluate(env, policy, EPISODES, seed=3, devices=jax.devices()[:1])
  desc = {"task": "table_k1", "policy": "push"}
  first = E.evaluate(env, policy, EPISODES, seed=3, devices=jax.devices()[:1], program=desc, program_roots=roots)
  second = E.evaluate(env, policy, EPISODES, seed=3, devices=jax.devices()[:1], program=desc, program_roots=roots)
  assert (plain["program"], first["program"], second["program"]) == (None, "exported", "loaded")
  for k, v in plain["per_episode"].items():
    np.testing.assert_array_equal(first["per_episode"][k], v)
    np.testing.assert_array_equal(second["per_episode"][k], v)

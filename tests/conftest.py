"""Shared test set-up: headless plotting; the package itself sets the XLA:CPU flag and the
persistent compilation cache (mjx_damage/runtime.py), as it does for every user.

The cache directory the package chose is exported as ``JAX_COMPILATION_CACHE_DIR`` so the CLI
subprocesses the tests start compile into (and read from) the same cache as the test process.

``task_rollout(name)`` (session fixture): the task contract's one compiled batched rollout of a
registered task, memoised for the whole run, so every test file that needs a task's MJX rollout
(tests/test_task_contract.py, tests/test_native_agreement.py) shares one compile per task.

``load_benchmark(name)``: ``benchmarks/<name>.py`` as a module (the scripts are not a package), for
tests of their argument checks and helpers.
"""

import functools
import importlib.util
import os
import sys

os.environ.setdefault("MPLBACKEND", "Agg")
# The suite's checks were written for the floating gripper (half the Panda's compile time, 2.8x its step
# rate); tests of the Panda name it. Inherited by the CLI subprocesses. The default itself: test_robots.py.
os.environ.setdefault("MJX_DAMAGE_ROBOT", "gripper")

import mjx_damage  # noqa: E402,F401  (before any test starts a JAX backend)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import tasks  # noqa: E402

BENCHMARKS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks")


def load_benchmark(name: str):
  """``benchmarks/<name>.py`` imported as module ``name``; its sibling imports (``provenance``,
  ``reward_preference``) resolve as when it runs as a script (the folder joins ``sys.path``, last, so it
  shadows nothing)."""
  if BENCHMARKS not in sys.path:
    sys.path.append(BENCHMARKS)
  spec = importlib.util.spec_from_file_location(name, os.path.join(BENCHMARKS, name + ".py"))
  module = importlib.util.module_from_spec(spec)
  sys.modules[name] = module  # as an import would: dataclasses and pickling look a module up by its name
  spec.loader.exec_module(module)
  return module


if jax.config.jax_compilation_cache_dir:
  os.environ["JAX_COMPILATION_CACHE_DIR"] = jax.config.jax_compilation_cache_dir

# Episodes of the contract rollout, by policy: uniform random actions; uniform random with 20 % of the
# entries extreme (NaN, ±inf, ±1e3: the wrapper must sanitise them); scripted safe; scripted unsafe.
RANDOM, EXTREME, SAFE, UNSAFE = 0, 1, 2, 3
EPISODES = (RANDOM,) * 8 + (EXTREME,) * 8 + (SAFE,) * 3 + (UNSAFE,) * 3
STEPS = 200
MODELS = ("mechanical", "thermal", "fluid")
_EXTREMES = (float("nan"), float("inf"), -float("inf"), 1e3, -1e3)


def _contract_rollout(name):
  """(env, results) of ``len(EPISODES)`` episodes × ``STEPS`` steps of ``tasks.make(name)`` in one
  ``jit(vmap(scan))`` call; results (numpy, leading axis = episode):

  which i32 (policy), reset_key u32[2], state0 (the env State after reset), obs0 f32[O] / health0 f32[E], obs, health (final),
  bad bool (some obs, reward, qpos or dynamic damage-state leaf non-finite), lo / hi (min / max link
  and entity health over the steps), rise (largest step-to-step link-health increase), unsanitised
  (steps where the wrapper's ``action_sanitised`` count differs from the non-finite-or-out-of-range
  entries sent), completed (success at some step), damage f32[3] (health points per model, MODELS),
  and per step (axis 1): actions f32[T, A], health_t f32[T, E], damage_t f32[T, 3],
  temperature_t / exposure_t f32[T, L].
  """
  env = tasks.make(name)
  A = env.action_size
  extremes = jnp.asarray(_EXTREMES, jnp.float32)

  def uniform(s, k):
    return jax.random.uniform(k, (A,), minval=-1.0, maxval=1.0)

  def extreme(s, k):
    ka, km, kv = jax.random.split(k, 3)
    hit = jax.random.uniform(km, (A,)) < 0.2
    return jnp.where(hit, extremes[jax.random.randint(kv, (A,), 0, len(_EXTREMES))], uniform(s, ka))

  policies = [uniform, extreme, tasks.scripted_policy(env, "safe"), tasks.scripted_policy(env, "unsafe")]

  def episode(rng, which):
    r0, rp = jax.random.split(rng)
    s = env.reset(r0)
    start = (s.obs, s.info["entity_health"], s)

    def body(carry, k):
      s, bad, lo, hi, rise, unsanitised, dmg = carry
      a = jax.lax.switch(which, policies, s, k)
      h_prev = s.info["link_health"]
      s = env.step(s, a)
      h = jnp.concatenate([s.info["link_health"], s.info["entity_health"]])
      dynamic = jax.tree.leaves(s.info["damage_state"].replace(params=None))
      finite = (jnp.all(jnp.isfinite(s.obs)) & jnp.isfinite(s.reward) & jnp.all(jnp.isfinite(s.pipeline_state.qpos))
                & jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in dynamic])))
      sent = jnp.sum(~(jnp.abs(a) <= 1.0))  # NaN compares false: counted as sent-invalid
      step_dmg = jnp.stack([s.info["damage"][m] for m in MODELS])
      carry = (s, bad | ~finite, jnp.minimum(lo, jnp.min(h)), jnp.maximum(hi, jnp.max(h)),
               jnp.maximum(rise, jnp.max(s.info["link_health"] - h_prev)),
               unsanitised + (s.metrics["action_sanitised"] != sent), dmg + step_dmg)
      ds = s.info["damage_state"]
      return carry, (s.metrics["success"], a, s.info["entity_health"], step_dmg, ds.temperature, ds.exposure)

    init = (s, jnp.zeros((), bool), jnp.asarray(jnp.inf), jnp.asarray(-jnp.inf), jnp.asarray(-jnp.inf),
            jnp.zeros((), jnp.int32), jnp.zeros(len(MODELS)))
    (s, bad, lo, hi, rise, unsanitised, dmg), (succ, acts, h_t, d_t, temp_t, exp_t) = jax.lax.scan(
        body, init, jax.random.split(rp, STEPS))
    return {"reset_key": r0, "state0": start[2], "obs0": start[0], "health0": start[1], "obs": s.obs, "health": s.info["entity_health"],
            "bad": bad, "lo": lo, "hi": hi, "rise": rise, "unsanitised": unsanitised, "completed": jnp.max(succ),
            "damage": dmg, "actions": acts, "health_t": h_t, "damage_t": d_t, "temperature_t": temp_t,
            "exposure_t": exp_t}

  which = jnp.asarray(EPISODES, jnp.int32)
  out = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.PRNGKey(3), len(EPISODES)), which)
  out = jax.tree.map(np.asarray, out)
  out["which"] = np.asarray(EPISODES)
  return env, out


@pytest.fixture(scope="session")
def task_rollout():
  """``task_rollout(name) -> (env, results)``: :func:`_contract_rollout`, computed once per task per run."""
  return functools.lru_cache(maxsize=None)(_contract_rollout)

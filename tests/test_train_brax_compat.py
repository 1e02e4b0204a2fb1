"""brax 0.14.2's own ``ppo.train`` runs on this jax through mjx_damage.compat's shim.

brax's trainer calls ``jax.device_put_replicated`` (removed from jax 0.10);
``import mjx_damage`` restores it. A handful of steps on the tiny pusher env
with the smallest networks keeps this cheap.
"""

import functools

import jax
import numpy as np

import mjx_damage  # noqa: F401  (installs the shim)
from brax.training.agents.ppo import networks as ppo_networks
from brax.training.agents.ppo import train as brax_ppo
from mjx_damage.wrapper import DamageWrapper
from train.experiments.pusher import PusherEnv


def test_brax_ppo_train_runs_through_compat_shim():
  assert hasattr(jax, "device_put_replicated")
  env = DamageWrapper(PusherEnv(), weight=1.0)
  make_policy, params, metrics = brax_ppo.train(
      environment=env,
      num_timesteps=256,
      episode_length=16,
      num_envs=8,
      batch_size=8,
      num_minibatches=2,
      unroll_length=4,
      num_updates_per_batch=1,
      num_evals=1,
      num_eval_envs=4,
      network_factory=functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(8,),
                                        value_hidden_layer_sizes=(8,)),
      seed=0,
  )
  assert np.isfinite(float(metrics["eval/episode_reward"]))
  policy = make_policy(params, deterministic=True)
  state = jax.jit(env.reset)(jax.random.PRNGKey(0))
  action, _ = policy(state.obs, jax.random.PRNGKey(1))
  assert action.shape == (1,)


def test_import_is_quiet_about_optional_warp():
  """MJX 3.17 prints two 'Failed to import warp' lines when warp-lang is absent; mjx_damage hides only those."""
  import subprocess
  import sys

  out = subprocess.run([sys.executable, "-c", "import mjx_damage; from mujoco import mjx; print('imported')"],
                       capture_output=True, text=True, timeout=300)
  assert out.returncode == 0, out.stderr
  assert out.stdout.strip().splitlines()[-1] == "imported"
  assert "Failed to import" not in out.stdout

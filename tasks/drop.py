"""The demo scene: plates dropped from random heights onto a counter beside a resting mug.

``DropEnv`` is the smallest damage-tracking MJX env of the project (no robot,
no actions; scene ``drop.xml`` beside this file); ``mjx-damage demo``
(:mod:`apps.demo_cli`) rolls out a batch of it under one
``jax.jit(jax.vmap(...))`` and prints per-entity health. It is a scene built on
the core, like the tasks, so it lives here and not in ``mjx_damage``.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
from brax.envs.base import State
import mujoco
from mujoco import mjx

from mjx_damage.env import DamageEnv

SCENE = os.path.join(os.path.dirname(__file__), "drop.xml")

DROP_CONFIG = {
    "entities": {
        "plate": {"params": "plate", "bodies": ["plate"]},
        "mug": {"params": "coffee_cup", "bodies": ["mug"]},
    }
}
COUNTER_TOP = 0.42  # m, z of the counter's top face


def load_scene() -> mujoco.MjModel:
  """The drop scene's ``mujoco.MjModel`` (a counter, a plate on a free joint, a mug)."""
  return mujoco.MjModel.from_xml_path(SCENE)


class DropEnv(DamageEnv):
  """Plate released at rest from ``height`` ∈ [min_height, max_height] m above the counter."""

  def __init__(self, min_height: float = 0.02, max_height: float = 0.6, n_substeps: int = 5, config=None):
    if not 0 <= min_height <= max_height:
      raise ValueError(f"min_height/max_height: need 0 <= min <= max, got {min_height}, {max_height}")
    super().__init__(load_scene(), config or DROP_CONFIG, n_substeps)
    self.min_height, self.max_height = float(min_height), float(max_height)
    self._plate_q = self.mj_model.jnt_qposadr[self.mj_model.joint("plate").id]

  @property
  def observation_size(self) -> int:
    return 7

  @property
  def action_size(self) -> int:
    return 0

  def drop_data(self, height) -> mjx.Data:
    d = mjx.make_data(self.sys)
    q = d.qpos.at[self._plate_q + 2].set(COUNTER_TOP + 0.008 + height)
    return d.replace(qpos=q)

  def reset(self, rng: jax.Array) -> State:
    rng, hr = jax.random.split(rng)
    height = jax.random.uniform(hr, (), minval=self.min_height, maxval=self.max_height)
    d = self.drop_data(height)
    info = {"damage_state": self.init_damage(rng), "drop_height": height}
    z = jnp.zeros(())
    return State(d, self._obs(d), z, z, {"success": z}, info)

  def step(self, state: State, action: jax.Array) -> State:
    d, ds = self.physics_step(state.pipeline_state, state.info["damage_state"], state.pipeline_state.ctrl)
    info = dict(state.info, damage_state=ds)
    return state.replace(pipeline_state=d, obs=self._obs(d), info=info)

  def _obs(self, d):
    return d.qpos[self._plate_q : self._plate_q + 7]

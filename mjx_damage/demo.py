"""The built-in demo: plates dropped from random heights onto a counter beside a resting mug.

``DropEnv`` is the smallest damage-tracking MJX env of the project (no robot,
no actions); ``mjx-damage demo`` rolls out a batch of it under one
``jax.jit(jax.vmap(...))`` and prints per-entity health.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import State
from mujoco import mjx

from mjx_damage import scenes
from mjx_damage.env import DamageEnv

DROP_CONFIG = {
    "entities": {
        "plate": {"params": "plate", "bodies": ["plate"]},
        "mug": {"params": "coffee_cup", "bodies": ["mug"]},
    }
}
COUNTER_TOP = 0.42  # m, z of the counter's top face


class DropEnv(DamageEnv):
  """Plate released at rest from ``height`` ∈ [min_height, max_height] m above the counter."""

  def __init__(self, min_height: float = 0.02, max_height: float = 0.6, n_substeps: int = 5, config=None):
    if not 0 <= min_height <= max_height:
      raise ValueError(f"min_height/max_height: need 0 <= min <= max, got {min_height}, {max_height}")
    super().__init__(scenes.load("drop"), config or DROP_CONFIG, n_substeps)
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

"""``PusherEnv``: the smallest actuated damage-aware env, for tests and CPU plumbing.

A ball on a slide joint (x only, no gravity) is driven by a motor towards a goal
just in front of a fixed fragile vase. The task reward is ``−|x − goal|`` (+1
while within ``tol`` of the goal and nearly at rest, which is also the success
condition), so a task-only policy rushes forward and — with any overshoot —
rams the vase; a damage-aware one must brake. The scene has one contact pair
(sphere-sphere), so it compiles and steps in a fraction of the time of a
manipulation scene, which is what the CPU tests need.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
from brax.envs.base import State

from mjx_damage.env import DamageEnv

_XML = """
<mujoco model="pusher">
  <option timestep="0.01" gravity="0 0 0"/>
  <worldbody>
    <body name="pusher" pos="0 0 0.1">
      <joint name="slide" type="slide" axis="1 0 0" damping="4" range="-1 1" limited="false"/>
      <geom name="pusher" type="sphere" size="0.05" mass="1"/>
    </body>
    <body name="vase" pos="{vase_x} 0 0.1">
      <geom name="vase" type="sphere" size="0.05"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="slide" gear="{gear}" ctrlrange="-1 1" ctrllimited="true"/>
  </actuator>
</mujoco>
"""

CONFIG = {"entities": {"vase": {"params": "vase", "bodies": ["vase"]}}}


class PusherEnv(DamageEnv):
  """obs = [x, ẋ, goal − x] (3), action = [force] (1) in [−1, 1]; episodes of 50 steps (2 s).

  Args:
    goal: target x of the pusher's centre, m (contact with the vase at 0.5).
    start: (lo, hi) range of the initial x, drawn uniformly at reset.
    gear: motor force per unit action, N.
    tol: success radius around the goal, m.
  """

  def __init__(self, goal: float = 0.42, start=(0.0, 0.3), gear: float = 20.0, tol: float = 0.03,
               vase_x: float = 0.6, n_substeps: int = 4):
    mj_model = mujoco.MjModel.from_xml_string(_XML.format(vase_x=vase_x, gear=gear))
    super().__init__(mj_model, CONFIG, n_substeps)
    self.goal, self.start, self.tol = float(goal), (float(start[0]), float(start[1])), float(tol)
    self.episode_length = 50  # the trainer's default episode length for this env

  @property
  def observation_size(self) -> int:
    return 3

  @property
  def action_size(self) -> int:
    return 1

  def reset(self, rng: jax.Array) -> State:
    rng, kx = jax.random.split(rng)
    x0 = jax.random.uniform(kx, (), minval=self.start[0], maxval=self.start[1])
    from mujoco import mjx
    d = mjx.make_data(self.sys)
    d = d.replace(qpos=d.qpos.at[0].set(x0))
    z = jnp.zeros(())
    info = {"damage_state": self.init_damage(rng)}
    return State(d, self._obs(d), z, z, {"success": z}, info)

  def step(self, state: State, action: jax.Array) -> State:
    ctrl = jnp.clip(action, -1.0, 1.0)
    d, ds = self.physics_step(state.pipeline_state, state.info["damage_state"], ctrl)
    x, v = d.qpos[0], d.qvel[0]
    dist = jnp.abs(x - self.goal)
    success = ((dist < self.tol) & (jnp.abs(v) < 0.2)).astype(jnp.float32)
    reward = -dist + success
    info = dict(state.info, damage_state=ds)
    metrics = dict(state.metrics, success=success)
    return state.replace(pipeline_state=d, obs=self._obs(d), reward=reward, metrics=metrics, info=info)

  def _obs(self, d):
    x, v = d.qpos[0], d.qvel[0]
    return jnp.stack([x, v, self.goal - x])

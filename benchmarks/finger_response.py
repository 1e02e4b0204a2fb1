"""Can exploration release the plate? Finger response per robot in Place Plate's RL setting.

A PPO policy first succeeds at Place Plate by chance: its noisy gripper command opens the hand on a
plate that has reached the goal. Whether chance can do that depends on how fast the fingers follow a
command. Per robot (in-hand start, paper observation, 100-step horizon), one compiled call each:

* ``open steps``: control steps of a full open command (+1), after 5 steps of the zero action, until
  the gap passes the success test's release gap (plate width + 1 cm);
* under uniform random actions (``--episodes`` episodes): completion, and the share of steps with the
  plate resting on the counter on which the gap is past the release gap;
* the finger servo's gains (kp, kv) and whether one joint equality couples the two fingers, read from
  the compiled model, so each row says what it measured.

    python benchmarks/finger_response.py [--robots gripper,panda] [--episodes 128] [--seed 0] \
        [--out benchmarks/results/finger_response_cpu.md]

To measure another finger servo, edit its ``<position>`` default in the robot's MJCF and rerun with
another ``--out`` (the committed file's candidate rows for the Panda were measured that way).
"""

from __future__ import annotations

import argparse
import datetime
import os
import shlex
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OPEN_AFTER = 5  # zero-action steps before the open command
OPEN_STEPS = 12


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--robots", default="gripper,panda", help="comma-separated robots")
  p.add_argument("--episodes", type=int, default=128, help="uniform-random episodes per robot")
  p.add_argument("--seed", type=int, default=0)
  p.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "finger_response_cpu.md"))
  a = p.parse_args(argv)
  if a.episodes < 1:
    p.error(f"--episodes: must be ≥ 1, got {a.episodes}")
  sys.path.insert(0, ROOT)
  from tasks import robots
  a.robots = [r.strip() for r in a.robots.split(",") if r.strip()]
  for r in a.robots:
    if r not in robots.names():
      p.error(f"--robots: unknown robot {r!r}; valid: {', '.join(robots.names())}")
  if not a.robots:
    p.error("--robots: empty")
  return a


def measure(robot: str, episodes: int, seed: int) -> dict:
  import jax
  import jax.numpy as jnp
  import mujoco
  import numpy as np

  import tasks
  from tasks.place_plate import PLATE_REST_Z
  from tasks.robots.interface import FINGER_ACTUATORS

  env = tasks.make("place_plate", **{**tasks.RL_SETTINGS["place_plate"], "robot": robot})  # the RL setting, this robot
  t = env.unwrapped
  release = 2 * t.plate_half_y + 0.01  # the success test's gap (m)
  rest_z = PLATE_REST_Z + 0.0015  # the success test's resting height (m)
  m = t.mj_model
  fingers = list(FINGER_ACTUATORS)
  kp, kv = float(m.actuator_gainprm[fingers[0], 0]), -float(m.actuator_biasprm[fingers[0], 2])
  # one drive for both fingers (the Panda hand): an active joint equality between the two finger joints
  finger_joints = {int(m.actuator_trnid[i, 0]) for i in fingers}
  coupled = any(m.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and m.eq_active0[e]
                and {int(m.eq_obj1id[e]), int(m.eq_obj2id[e])} == finger_joints for e in range(m.neq))

  def open_gaps(rng):
    acts = jnp.concatenate([jnp.zeros((OPEN_AFTER, 4)), jnp.tile(jnp.array([0.0, 0.0, 0.0, 1.0]), (OPEN_STEPS, 1))])

    def body(s, a):
      s = env.step(s, a)
      return s, t.robot.gap(s.pipeline_state)

    return jax.lax.scan(body, env.reset(rng), acts)[1]

  def random_episode(rng):
    def body(s, k):
      s = env.step(s, jax.random.uniform(k, (4,), minval=-1.0, maxval=1.0))
      d = s.pipeline_state
      resting = t.plate_pos(d)[2] < rest_z
      return s, (s.metrics["success"], resting, resting & (t.robot.gap(d) > release))

    r0, r1 = jax.random.split(rng)
    return jax.lax.scan(body, env.reset(r0), jax.random.split(r1, t.episode_length))[1]

  gaps = np.asarray(jax.jit(open_gaps)(jax.random.PRNGKey(seed)))[OPEN_AFTER:]
  past = np.nonzero(gaps > release)[0]
  succ, resting, open_resting = (np.asarray(x) for x in jax.jit(jax.vmap(random_episode))(
      jax.random.split(jax.random.PRNGKey(seed + 1), episodes)))
  return {
      "robot": robot, "finger_kp": kp, "finger_kv": kv, "fingers_coupled": coupled, "release_gap_m": release,
      "open_steps": int(past[0]) + 1 if past.size else None, "gap_after_open_m": [round(float(g), 4) for g in gaps],
      "random_completion": float(succ.max(axis=1).mean()), "random_resting_steps": int(resting.sum()),
      "random_open_share_resting": float(open_resting.sum() / max(resting.sum(), 1)), "episodes": episodes,
      "episode_length": t.episode_length,
  }


def main(argv=None) -> int:
  a = parse(argv)
  import jax

  from mjx_damage import io  # after parse: it puts the repo on sys.path

  rows = [measure(r, a.episodes, a.seed) for r in a.robots]
  cmd = "python benchmarks/finger_response.py " + shlex.join(argv if argv is not None else sys.argv[1:])
  when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
  lines = [
      "# Finger response in Place Plate's RL setting (in-hand start, paper observation)", "",
      f"Command: `{cmd.strip()}` ({when}; jax {jax.__version__} on {jax.default_backend()}).", "",
      "Open steps: control steps of a full open command (after 5 zero-action steps) until the gap passes the "
      "success test's release gap (plate width + 1 cm). Random: uniform random actions; 'open while resting' = "
      "share of the steps with the plate resting on the counter on which the hand is open past that gap.", "",
      "| robot | finger kp (N/m) | finger kv (N·s/m) | fingers coupled | release gap (cm) | open steps | gap after 1, 2, 3 open steps (cm) "
      "| random: completion | random: open while resting | episodes × steps |",
      "|---|---|---|---|---|---|---|---|---|---|",
  ]
  for r in rows:
    g = ", ".join(f"{100 * x:.2f}" for x in r["gap_after_open_m"][:3])
    lines.append(f"| {r['robot']} | {r['finger_kp']:g} | {r['finger_kv']:g} "
                 f"| {'yes' if r['fingers_coupled'] else 'no'} | {100 * r['release_gap_m']:.1f} "
                 f"| {r['open_steps'] if r['open_steps'] is not None else f'> {OPEN_STEPS}'} | {g} "
                 f"| {100 * r['random_completion']:.1f} % | {100 * r['random_open_share_resting']:.1f} % "
                 f"| {r['episodes']} × {r['episode_length']} |")
  io.write_text(a.out, "\n".join(lines) + "\n")
  io.write_json(os.path.splitext(a.out)[0] + ".json", {"command": cmd.strip(), "date": when, "rows": rows}, indent=1)
  print("\n".join(lines))
  return 0


if __name__ == "__main__":
  sys.exit(main())

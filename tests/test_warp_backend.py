"""The MuJoCo Warp backend (mjx_damage.backends.mjx_warp, mjx_damage.warp_step) against the MJX-JAX one.

MJX's Warp implementation runs on CPU too (warp-lang, the ``warp`` extra, is in the test extra), so the
batch-level readout of Warp's one contact list is checked here: the same health after a drop, the same
contact forces on a sliding box, joint-limit forces, the per-world slots and what is refused.
"""

import numpy as np
import pytest

warp = pytest.importorskip("warp", reason="warp-lang (the mjx_damage[warp] extra) is not installed")
warp.config.quiet = True

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
from mujoco import mjx  # noqa: E402

import tasks  # noqa: E402
from mjx_damage import physics, warp_step  # noqa: E402
from mjx_damage.backends import mjx_jax, mjx_warp  # noqa: E402
from mjx_damage.binding import bind  # noqa: E402
from tasks import drop  # noqa: E402


def warp_model(model):
  m = mjx.put_model(model, impl="warp")
  return m.replace(opt=m.opt.replace(_impl=m.opt._impl.replace(warn_overflow=0)))


def warp_data(model, qpos, qvel=None, contacts_per_world=32):
  B = qpos.shape[0]
  qvel = jnp.zeros((B, model.nv), jnp.float32) if qvel is None else qvel
  make = lambda q, v: mjx.make_data(model, impl="warp", naconmax=B * contacts_per_world, njmax=200).replace(
      qpos=q, qvel=v)
  return jax.jit(jax.vmap(make))(qpos, qvel)


@pytest.fixture(scope="module")
def drops():
  """Plates dropped from 5, 20 and 35 cm, 120 substeps, under both implementations."""
  model = drop.load_scene()
  binding = bind(model, drop.DROP_CONFIG)
  heights = np.array([0.05, 0.2, 0.35], np.float32)
  q = model.jnt_qposadr[model.joint("plate").id]
  qpos = np.tile(np.asarray(model.qpos0, np.float32), (3, 1))
  qpos[:, q + 2] = drop.COUNTER_TOP + 0.008 + heights
  qpos = jnp.asarray(qpos)
  ds0 = jax.vmap(lambda _: physics.init_state(binding))(jnp.arange(3))
  mj = mjx.put_model(model)
  dj = jax.vmap(lambda x: mjx.make_data(mj).replace(qpos=x))(qpos)
  _, dsj = jax.jit(jax.vmap(lambda d, s: physics.step(mj, binding, d, s, 120)))(dj, ds0)
  mw = warp_model(model)
  _, dsw, over = jax.jit(lambda d, s: warp_step.step(mw, binding, d, s, 120, slots=24))(warp_data(model, qpos), ds0)
  return np.asarray(dsj.link_health), np.asarray(dsw.link_health), np.asarray(over)


def test_a_drop_damages_the_plate_as_on_the_jax_implementation(drops):
  jax_health, warp_health, overflow = drops
  assert jax_health[0, 0] == 100.0 and jax_health[1, 0] < 90.0  # 5 cm: unharmed; 20 cm: damaged
  np.testing.assert_allclose(warp_health, jax_health, atol=2.0)  # issue 17: within 2 % of health
  assert (overflow == 0).all()


SLIDE_XML = """<mujoco><option timestep="0.002"/><worldbody><geom type="plane" size="1 1 .1" friction="0.5"/>
<body name="box" pos="0 0 .0499"><freejoint/><geom type="box" size=".05 .05 .05" mass="2" friction="0.5"/></body>
</worldbody></mujoco>"""
SLIDE_CONFIG = {"entities": {"box": {"params": "plate", "bodies": ["box"]}}}


def test_contact_forces_of_a_sliding_box_match_the_jax_implementation():
  """Normal and friction forces (pyramidal cone, condim 3) on a box sliding at 0.5 and 1 m/s."""
  model = mujoco.MjModel.from_xml_string(SLIDE_XML)
  binding = bind(model, SLIDE_CONFIG)
  qpos = jnp.tile(jnp.asarray(model.qpos0, jnp.float32), (2, 1))
  qvel = jnp.zeros((2, model.nv), jnp.float32).at[:, 0].set(jnp.array([0.5, 1.0]))
  mj = mjx.put_model(model)
  # compiled (op by op, MJX-JAX's forward dispatches for tens of seconds)
  fj, lj = jax.jit(jax.vmap(lambda q, v: mjx_jax.applied_forces(
      binding, mj, mjx.forward(mj, mjx.make_data(mj).replace(qpos=q, qvel=v)))))(qpos, qvel)
  mw = warp_model(model)
  fw, lw, over = jax.jit(lambda d: mjx_warp.contact_forces(binding, mw, jax.vmap(lambda x: mjx.step(mw, x))(d), slots=8))(
      warp_data(model, qpos, qvel))
  net = lambda f, link: np.asarray(jnp.sum(jnp.where((link == 0)[..., None], f, 0.0), axis=1))  # on the box
  nj, nw = net(fj, lj), net(fw, lw)
  assert (nj[:, 2] > 2 * 9.81).all() and (nj[:, 0] < 0).all()  # pushed up, and back against the motion
  np.testing.assert_allclose(nw, nj, rtol=0.02, atol=0.02 * np.abs(nj).max())
  assert (np.asarray(over) == 0).all()


def test_contacts_beyond_the_slots_are_counted_per_world():
  model = mujoco.MjModel.from_xml_string(SLIDE_XML)
  binding = bind(model, SLIDE_CONFIG)
  qpos = jnp.tile(jnp.asarray(model.qpos0, jnp.float32), (3, 1))
  mw = warp_model(model)
  dw = jax.vmap(lambda d: mjx.step(mw, d))(warp_data(model, qpos))
  forces, links, over = mjx_warp.contact_forces(binding, mw, dw, slots=1)  # a box on a plane: 4 contacts
  assert forces.shape == (3, 2, 3) and links.shape == (3, 2)
  assert np.asarray(over).tolist() == [3, 3, 3]
  # slot 0: the force on geom[1] (the box, link 0), pushed up; slot 1: its reaction on the plane (untracked)
  assert (np.asarray(links)[:, 0] == 0).all() and (np.asarray(forces)[:, 0, 2] > 0).all()
  assert (np.asarray(links)[:, 1] == -1).all()


def test_joint_limit_forces_and_damage_match_the_jax_implementation():
  """A door servoed past its 90° stop and a slider pushed against its end, no contacts: the limit force on each
  child link and the health after 200 substeps on Warp equal the MJX-JAX backend's (test_joint_limits' scene);
  a world whose servo stops short (80°) has no limit row and loses nothing."""
  from test_joint_limits import CONFIG, PAST, PUSH, SHORT, XML

  model = mujoco.MjModel.from_xml_string(XML)
  binding = bind(model, CONFIG)
  qpos = jnp.tile(jnp.asarray(model.qpos0, jnp.float32), (2, 1)).at[:, :2].set(jnp.array([np.pi / 2, 0.1]))
  qpos = qpos.at[1, :2].set(jnp.array([SHORT, 0.05]))  # world 1: inside both ranges
  ctrl = jnp.array([[PAST, PUSH], [SHORT, 0.0]], jnp.float32)
  ds0 = jax.vmap(lambda _: physics.init_state(binding))(jnp.arange(2))
  mj = mjx.put_model(model)
  dj = jax.vmap(lambda q, c: mjx.make_data(mj).replace(qpos=q, ctrl=c))(qpos, ctrl)
  run = jax.jit(jax.vmap(lambda d, s: physics.step(mj, binding, d, s, 200)))
  settled, _ = run(dj, ds0)  # pressed into the stops: each limit holds its actuator's load
  fj = jax.jit(jax.vmap(lambda d: mjx_jax.limit_forces(binding, mj, mjx.forward(mj, d))[0]))(settled)
  mw = warp_model(model)
  ds_w = warp_data(model, settled.qpos, settled.qvel).replace(ctrl=ctrl)
  fw = jax.jit(lambda d: mjx_warp.limit_forces(binding, mw, jax.vmap(lambda x: mjx.step(mw, x))(d), d.qpos)[0])(ds_w)
  np.testing.assert_allclose(np.asarray(fw), np.asarray(fj), rtol=0.02, atol=0.05)
  assert np.abs(np.asarray(fw)[0]).max() > 10.0 and np.abs(np.asarray(fw)[1]).max() == 0.0  # not vacuous
  _, dsj = run(dj, ds0)
  dw = warp_data(model, qpos).replace(ctrl=ctrl)
  _, dsw, _ = jax.jit(lambda d, s: warp_step.step(mw, binding, d, s, 200))(dw, ds0)
  np.testing.assert_allclose(np.asarray(dsw.link_health), np.asarray(dsj.link_health), atol=1.5)
  assert float(dsw.link_health[0, 0]) < 90.0 and (np.asarray(dsw.link_health)[1] == 100.0).all()


def both_steps(model, config, substeps, qpos=None):
  """(MJX-JAX damage state, Warp damage state) after ``substeps`` from ``qpos`` (default qpos0), 2 envs."""
  binding = bind(model, config)
  qpos = jnp.tile(jnp.asarray(model.qpos0 if qpos is None else qpos, jnp.float32), (2, 1))
  ds0 = jax.vmap(lambda k: physics.init_state(binding, rng=k))(jax.random.split(jax.random.PRNGKey(0), 2))
  mj = mjx.put_model(model)
  dj = jax.vmap(lambda q: mjx.make_data(mj).replace(qpos=q))(qpos)
  _, dsj = jax.jit(jax.vmap(lambda d, s: physics.step(mj, binding, d, s, substeps)))(dj, ds0)
  _, dsw, over = jax.jit(lambda d, s: warp_step.step(warp_model(model), binding, d, s, substeps, slots=16))(
      warp_data(model, qpos), ds0)
  assert (np.asarray(over) == 0).all()
  return dsj, dsw


HOT_XML = """<mujoco><option timestep="0.004"/><worldbody><geom type="plane" size="1 1 .1"/>
<geom name="hot" type="box" size=".1 .1 .01" pos="0 0 .01"/>
<body name="pan" pos="0 0 .0699"><freejoint/><geom type="box" size=".05 .05 .05" mass="1"/></body>
<body name="cup" pos=".3 0 .05"><freejoint/><geom type="box" size=".03 .03 .05" mass=".2"/></body>
</worldbody></mujoco>"""


def test_temperature_from_warp_contacts_matches_the_jax_implementation():
  """A pan resting on a hot plate (conduction through the contact) and a cup beside it (radiation only)."""
  config = {"temperature": {"sources": {"plate": {"geom": "hot", "temperature": 300, "on": True, "reach": 0.05}}},
            "entities": {n: {"params": "plate", "bodies": [n], "heat": {"conduction": 2.0, "radiation": 0.1,
                                                                         "cooling": 0.05}} for n in ("pan", "cup")}}
  dsj, dsw = both_steps(mujoco.MjModel.from_xml_string(HOT_XML), config, 150)
  tj, tw = np.asarray(dsj.temperature), np.asarray(dsw.temperature)
  assert (tj[:, 0] > tj[:, 1] + 20).all()  # the pan touches the plate and heats faster
  np.testing.assert_allclose(tw, tj, rtol=1e-3)


WET_XML = """<mujoco><option timestep="0.004"/><worldbody><geom type="plane" size="1 1 .1"/>
<body name="tray"><geom type="box" size=".1 .1 .005" pos="0 0 .005"/></body>
<body name="ball" pos=".5 0 .02"><freejoint/><geom type="sphere" size=".02"/></body></worldbody></mujoco>"""


def test_liquid_on_warp_data_matches_the_jax_implementation():
  """Eight particles dropped on a tracked tray wet it, and the fluid damage follows, on both implementations."""
  config = {"liquid": {"particles": 8, "radius": 0.008, "spawn": {"center": [0, 0, 0.1], "size": [0.012] * 3}},
            "entities": {"tray": {"params": "laptop", "bodies": ["tray"]}}}
  dsj, dsw = both_steps(mujoco.MjModel.from_xml_string(WET_XML), config, 100)
  assert (np.asarray(dsj.exposure) == 8).all()  # every particle on the tray
  np.testing.assert_allclose(np.asarray(dsw.liquid.pos), np.asarray(dsj.liquid.pos), atol=1e-4)
  np.testing.assert_array_equal(np.asarray(dsw.exposure), np.asarray(dsj.exposure))
  np.testing.assert_allclose(np.asarray(dsw.link_health), np.asarray(dsj.link_health), atol=0.01)


def test_warp_scaling_times_the_damage_aware_step_on_both_implementations():
  """benchmarks/warp_scaling.py's -damage configs run the damage step (every box tracked) and say so."""
  from conftest import load_benchmark

  W = load_benchmark("warp_scaling")
  for config in ("jax-cg-damage", "warp-cg-damage"):
    row = W.measure(config, 2, 2, "sweep", 2, 3)
    assert row["damage"] and row["finite"] and row["config"] == config
    assert 0.0 <= row["min_health"] <= 100.0 and row["physics_steps_per_s"] > 0


def test_a_task_runs_on_warp_and_its_scripted_policies_separate_as_on_jax():
  """tasks.make(..., backend="warp", num_envs=B): the env is written per environment and vmapped, and its
  physics step runs the batch on MuJoCo Warp (custom_vmap); Place Plate's scripted policies end as on MJX-JAX."""
  from tasks import rollout

  B = 4
  out = {}
  for backend in ("jax", "warp"):
    kw = {"backend": "warp", "num_envs": B} if backend == "warp" else {}
    env = tasks.make("place_plate", robot="gripper", obs_mode="paper", **kw)
    assert env.unwrapped.physics_backend == backend
    run = rollout.rollout_fn(env, [tasks.scripted_policy(env, s) for s in ("safe", "unsafe")],
                             env.unwrapped.episode_length)
    st = run(jax.random.split(jax.random.PRNGKey(0), B), jnp.array([0, 0, 1, 1]))
    out[backend] = (np.asarray(st.completed), np.asarray(st.entity_health), np.asarray(st.any_nan))
  (cj, hj, nj), (cw, hw, nw) = out["jax"], out["warp"]
  assert cw.tolist() == cj.tolist() == [1, 1, 1, 1] and not nw.any()
  assert (hw[:2] > 95).all() and (hw[2:, 0] < 5).all()  # safe: intact; unsafe: the plate broken
  np.testing.assert_allclose(hw, hj, atol=2.0)


@pytest.mark.parametrize("kw, field", [
    ({"backend": "cuda"}, "backend"),
    ({"backend": "warp"}, "num_envs"),
    ({"backend": "warp", "num_envs": -2}, "num_envs"),
    ({"backend": "warp", "num_envs": 4, "warp_contacts": 0}, "warp_contacts"),
    ({"num_envs": 4}, "num_envs"),
])
def test_bad_backend_options_are_refused_by_name(kw, field):
  with pytest.raises(ValueError, match=field):
    tasks.make("place_plate", robot="gripper", **kw)


def test_warp_scaling_times_a_task_step_on_both_backends(capsys):
  from conftest import load_benchmark

  W = load_benchmark("warp_scaling")
  for bad in (["--tasks", "no_such_task"], ["--tasks", "place_plate", "--robot", "no_robot"],
              ["--tasks", "place_plate", "--task-steps", "0"]):
    with pytest.raises(SystemExit):
      W.main(bad + ["--out", "unused.json"])
    assert "--" in capsys.readouterr().err
  for backend in ("jax", "warp"):
    row = W.measure_task("place_plate", backend, 2, 2, "gripper")
    assert row["backend"] == backend and row["finite"] and row["env_steps_per_s"] > 0 and row["n_substeps"] == 6


def test_contacts_the_warp_env_cannot_read_are_recorded_in_its_damage_state():
  """DamageState.contacts_dropped: 0 on MJX-JAX; on Warp, the contacts beyond warp_contacts places per world, or
  1 where the world's contacts did not fit in Warp's shared buffer (2 envs × 1 place: one world takes both)."""
  for kw, dropped in (({}, False), ({"backend": "warp", "num_envs": 2, "warp_contacts": 1}, True)):
    env = tasks.make("place_plate", robot="gripper", obs_mode="paper", **kw)
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 2))
    assert (np.asarray(state.info["damage_state"].contacts_dropped) == 0).all()
    state = jax.jit(jax.vmap(env.step))(state, jnp.zeros((2, env.action_size)))
    got = np.asarray(state.info["damage_state"].contacts_dropped)
    assert ((got > 0) if dropped else (got == 0)).all(), got


@pytest.mark.slow  # about 40 s of compiling on 2 CPU cores
def test_eval_cli_runs_a_task_on_warp(tmp_path):
  """``mjx-damage eval --backend warp``: the evaluator (episodes vmapped, finished ones frozen) runs the Warp env,
  records the backend, keeps no traced program (Warp's FFI calls cannot be exported) and separates Place Plate's
  scripted policies as the scripts do on MJX-JAX."""
  import json

  from apps import cli

  res = {}
  for style in ("safe", "unsafe"):
    out = tmp_path / f"{style}.json"
    assert cli.main(["eval", "--task", "place_plate", "--robot", "gripper", "--policy", f"scripted:{style}",
                     "--episodes", "4", "--backend", "warp", "--out", str(out)]) == 0
    res[style] = json.loads(out.read_text())
  assert res["safe"]["backend"] == "warp" and res["safe"]["backend_requested"] == "warp"
  assert res["safe"]["metrics"]["completion"] == 1.0 and res["safe"]["metrics"]["safe_completion"] == 1.0
  assert res["unsafe"]["metrics"]["completion"] == 1.0 and res["unsafe"]["metrics"]["safe_completion"] == 0.0



@pytest.mark.slow  # about 40 s of compiling on 2 CPU cores
def test_sweep_cli_runs_a_task_on_warp(tmp_path):
  """``mjx-damage sweep --backend warp``: both fragility levels' episodes run in the Warp env's one batch, the
  scripted policies separate at the task's fragility, and a 4x tougher plate loses no more health."""
  import json

  from apps import cli

  out = tmp_path / "sweep.json"
  assert cli.main(["sweep", "--tasks", "place_plate", "--robot", "gripper", "--fragility", "0.25,1",
                   "--episodes", "2", "--backend", "warp", "--out", str(out)]) == 0
  res = json.loads(out.read_text())
  assert res["backend_per_task"] == {"place_plate": "warp"}
  rows = {(r["policy"], r["fragility"]): r for r in res["rows"]}
  assert rows[("scripted:safe", 1.0)]["SC"] == 100.0
  assert rows[("scripted:unsafe", 1.0)]["C"] == 100.0 and rows[("scripted:unsafe", 1.0)]["SC"] == 0.0
  assert rows[("scripted:unsafe", 0.25)]["avg_health"] >= rows[("scripted:unsafe", 1.0)]["avg_health"]


@pytest.mark.slow  # about 70 s of compiling and stepping on 2 CPU cores
def test_a_joint_limit_task_separates_on_warp_as_on_jax():
  """Turn On Faucet's damage is the lever forced against its stop (joint-limit force + finger contact): on Warp
  the scripted policies separate and the unsafe one's episode cost is the MJX-JAX backend's within 5 %."""
  from train import evaluate as E

  res = {}
  for kw in ({"backend": "warp", "num_envs": 2}, {}):
    env = tasks.make("turn_on_faucet", robot="gripper", **kw)
    for style in ("safe", "unsafe"):
      res[kw.get("backend", "jax"), style] = E.evaluate(env, tasks.scripted_policy(env, style), 2)["metrics"]
  assert res["warp", "safe"]["safe_completion"] == 1.0 and res["warp", "safe"]["cost_mean"] == 0.0
  assert res["warp", "unsafe"]["completion"] == 1.0 and res["warp", "unsafe"]["safe_completion"] == 0.0
  np.testing.assert_allclose(res["warp", "unsafe"]["cost_mean"], res["jax", "unsafe"]["cost_mean"], rtol=0.05)


def test_a_second_vmap_over_a_warp_env_is_refused_while_tracing():
  """vmap(vmap(env.step)) (seeds x envs) would run the physics right but read no contact damage (each outer
  element's contact list is not the one the readout indexes): it raises ValueError before anything compiles;
  one vmap over the worlds traces."""
  env = tasks.make("place_plate", robot="gripper", backend="warp", num_envs=4)
  keys = jax.random.split(jax.random.PRNGKey(0), 4)
  flat = jax.eval_shape(jax.vmap(env.reset), keys)
  jax.eval_shape(jax.vmap(env.step), flat, jnp.zeros((4, env.action_size)))
  nested = jax.eval_shape(jax.vmap(jax.vmap(env.reset)), keys.reshape(2, 2, -1))
  with pytest.raises(ValueError, match="backend: warp steps the worlds of ONE jax.vmap"):
    jax.eval_shape(jax.vmap(jax.vmap(env.step)), nested, jnp.zeros((2, 2, env.action_size)))

def test_the_evaluator_counts_episodes_with_contacts_it_could_not_read():
  """A Warp env with too few contact places per world: the wrapper keeps each episode's worst step in
  ``damage_episode["contacts_dropped"]`` and the evaluator counts those episodes (0 on MJX-JAX)."""
  from train import evaluate as E

  res = {}
  for kw in ({"backend": "warp", "num_envs": 2, "warp_contacts": 1}, {}):
    env = tasks.make("place_plate", robot="gripper", **kw)
    res[kw.get("backend", "jax")] = E.evaluate(env, tasks.scripted_policy(env, "safe"), 2, episode_length=20)["metrics"]
  assert res["warp"]["contacts_dropped_episodes"] == 2
  assert res["jax"]["contacts_dropped_episodes"] == 0


def test_bench_times_a_task_on_warp():
  """``mjx-damage bench --backend warp``: the task row is timed on MuJoCo Warp and says so."""
  from apps.bench.measure import measure_task

  row = measure_task("place_plate", 2, 0.05, 2, backend="warp", overrides={"robot": "gripper"})
  assert row["backend"] == "warp" and row["robot"] == "gripper" and row["envs"] == 2
  assert row["env_steps_per_s"] > 0

"""Benchmark scene, reference-style pipeline and report plumbing (no MJX compilation
except in the slow end-to-end run)."""

import dataclasses
import json

import mujoco
import numpy as np
import pytest
from conftest import load_benchmark

from apps import bench
from mjx_damage import bind
from mjx_damage import reference as R
from mjx_damage.backends import native as native_backend
from mjx_damage.signals import LinkSignals, evaluate
from tasks import bench_table as S


def _collide(m, g1, g2):
  return bool((m.geom_contype[g1] & m.geom_conaffinity[g2]) | (m.geom_contype[g2] & m.geom_conaffinity[g1]))


def test_scene_collides_boxes_only_with_table_and_pusher():
  m = S.table_scene(5)
  g = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, i): i for i in range(m.ngeom)}
  boxes = [g[f"box{i}"] for i in range(5)]
  for i, a in enumerate(boxes):
    assert _collide(m, a, g["table"]) and _collide(m, a, g["pusher"])
    assert not any(_collide(m, a, b) for b in boxes[i + 1:])
  assert not _collide(m, g["pusher"], g["table"])
  binding = bind(m, S.table_config(5))
  assert binding.num_entities == binding.num_links == 5
  with pytest.raises(ValueError, match="^k:"):
    S.table_scene_xml(0)


@pytest.fixture(scope="module")
def pushed_state():
  """Native K=3 scene after the pusher has swept into the boxes (contacts with forces)."""
  m = S.table_scene(3)
  binding = bind(m, S.table_config(3))
  d = mujoco.MjData(m)
  best, best_n = None, -1
  for _ in range(300):
    d.ctrl[:] = S.pusher_ctrl(d.time, S.sweep_radius(3))
    mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)
    n = sum(1 for i in range(d.ncon) if "pusher" in (m.geom(d.contact[i].geom1).name, m.geom(d.contact[i].geom2).name))
    if n > best_n:
      best, best_n = (d.qpos.copy(), d.qvel.copy(), d.time, d.ctrl.copy(), d.act.copy()), n
  qpos, qvel, t, ctrl, _ = best
  d.qpos[:], d.qvel[:], d.time, d.ctrl[:] = qpos, qvel, t, ctrl
  mujoco.mj_forward(m, d)
  assert best_n > 0, "the pusher never touched a box"
  return m, binding, d


def test_reference_evaluators_match_library_formulas(pushed_state):
  m, binding, d = pushed_state
  pipe = R.ReferencePipeline(m, binding, 1)
  mujoco.mj_forward(m, d)
  mujoco.mj_rnePostConstraint(m, d)
  # acceleration via mj_objectAcceleration (+ gravity) = the library's kinematic acceleration
  acc6 = np.zeros(6)
  lib_acc = native_backend.link_acceleration(binding, d)
  for li, body in enumerate(binding.link_body):
    mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_BODY, int(body), acc6, 0)
    np.testing.assert_allclose(acc6[3:] + m.opt.gravity, lib_acc[li], rtol=1e-4, atol=1e-3)
  # for fragile parameters every contact counts, so the comparison is not trivially 0 = 0
  fragile = binding.params.with_fragility(50.0)
  pipe = R.ReferencePipeline(m, dataclasses.replace(binding, params=fragile), 1)
  ref = np.concatenate([ev.mechanical(m, d) for ev in pipe.evaluators])
  forces, links = native_backend.contact_forces(binding, m, d)
  sig = LinkSignals(forces, links, lib_acc, np.full(3, 22.0, np.float32), np.zeros(3, np.float32))
  lib = np.asarray(evaluate(sig, fragile).rate.mechanical)
  assert ref.max() > 0
  np.testing.assert_allclose(ref, lib, rtol=2e-3, atol=1e-3)


def test_reference_timing_and_rollout_run(pushed_state):
  m, binding, _ = pushed_state
  q = np.tile(m.qpos0, (2, 1))
  ctrl = lambda t: S.pusher_ctrl(t, S.sweep_radius(3))
  with_dmg = R.time_reference(m, binding, 2, q, ctrl, steps=5, damage=True)
  without = R.time_reference(m, binding, 2, q, ctrl, steps=5, damage=False)
  roll = R.time_rollout(m, 2, q, ctrl, steps=5, nthread=2)
  assert with_dmg["env_steps"] == without["env_steps"] == roll["env_steps"] == 10
  assert 0 <= with_dmg["mean_final_min_health"] <= 100
  assert with_dmg["env_steps_per_s"] > 0 and roll["physics_steps_per_s"] > 0


def test_summary_and_plot(tmp_path):
  rows = [
      {"envs": n, "entities": k, "damage": dmg, "env_steps_per_s": float(n * (2 if dmg else 2.1) / k),
       "physics_steps_per_s": 1.0, "compile_s": 1.0, "host_maxrss_bytes": 2**30}
      for n in (1, 8) for k in (1, 4) for dmg in (True, False)
  ]
  result = {"device": "cpu", "platform": "cpu", "num_devices": 1, "command": "x", "date": "d", "n_substeps": 5,
            "timestep_s": 0.004, "scene": "s", "vs_envs": [r for r in rows if r["entities"] == 4],
            "vs_entities": [r for r in rows if r["envs"] == 8],
            "vs_tracked": [dict(r, boxes=4, env_steps_per_s=r["env_steps_per_s"] * r["entities"] * (0.9 if r["entities"] == 4 else 1))
                           for r in rows if r["envs"] == 8],
            "vs_mounted": [dict(r, boxes=r["entities"], free_boxes=1,
                                env_steps_per_s=r["env_steps_per_s"] * r["entities"] * (0.6 if r["entities"] == 4 else 1))
                           for r in rows if r["envs"] == 8],
            "reference": {"4": {"reference_damage": {"env_steps_per_s": 1.0, "envs": 1, "physics_steps_per_s": 5.0},
                                "native_no_damage": {"env_steps_per_s": 4.0, "envs": 1, "physics_steps_per_s": 20.0},
                                "rollout_no_damage": {"env_steps_per_s": 8.0, "envs": 1, "physics_steps_per_s": 40.0, "threads": 2}}}}
  s = bench.summarize(result, 4, 8, 8)
  assert s["damage_on_off_ratio_K4_8envs"] == pytest.approx(2 / 2.1)
  assert s["entities_4_over_1_throughput_damage_on_8envs"] == pytest.approx(0.25)
  assert s["speedup_over_reference_K4"]["ratio_vs_reference_damage"] == pytest.approx(4.0)
  assert s["tracked_4_over_1_in_4_box_scene_damage_on_8envs"] == pytest.approx(0.9)
  assert s["entities_4_over_1_mounted_throughput_damage_on_8envs"] == pytest.approx(0.6)
  result["summary"] = s
  md = bench.report_md(result)
  assert "| 4 | 4 | 4 | 8 | on | 4 |" in md and "ratio_vs_reference_damage" in md
  assert "a fixed scene, n of its boxes tracked" in md
  assert "| 4 | 4 | 1 | 8 | on | 10 |" in md and "Mounted entities" in md
  bench.plot(result, str(tmp_path / "p.png"))
  assert (tmp_path / "p.png").stat().st_size > 1000


def test_bench_cli_rejects_bad_sizes(capsys):
  with pytest.raises(SystemExit):
    bench.main(["--envs", "0,4"])
  assert "--envs:" in capsys.readouterr().err
  with pytest.raises(SystemExit):
    bench.main(["--k", "4", "--tracked", "1,8"])
  assert "--tracked:" in capsys.readouterr().err
  with pytest.raises(SystemExit):
    bench.main(["--mounted", "1,x"])
  assert "--mounted:" in capsys.readouterr().err


def test_tracked_subset_of_a_fixed_scene():
  with pytest.raises(ValueError, match="tracked"):
    S.table_config(4, tracked=5)
  with pytest.raises(ValueError, match="jacobian"):
    S.table_scene_xml(2, jacobian="banded")
  env = S.table_env(4, tracked=2, jacobian="dense")
  assert env.mj_model.nbody == 1 + 1 + 4 and len(env.damage_binding.entity_names) == 2


def test_mounted_boxes_add_no_dofs_and_still_take_damage_signals():
  """Mounted boxes: welded to the world (no dofs, no box-table contacts), yet the pusher loads them."""
  import jax
  import jax.numpy as jnp

  from mjx_damage import physics

  with pytest.raises(ValueError, match="free"):
    S.table_scene_xml(3, free=4)
  with pytest.raises(ValueError, match="free"):
    S.table_env(3, free=0)  # box 0 is observed: it must be free
  m_all, m_one = S.table_scene(3), S.table_scene(3, free=1)
  assert (m_all.nv, m_one.nv) == (2 + 3 * 6, 2 + 6)
  assert [int(m_one.body_weldid[m_one.body(f"box{i}").id]) for i in (1, 2)] == [0, 0]
  env = S.table_env(2, free=1)  # box0 free at x = -0.05, box1 mounted at x = +0.05
  d, ds, _ = bench.batched_initial_state(env, 1)
  box1 = env.damage_binding.entity_names.index("box1")
  target = jnp.array([0.05, 0.0], jnp.float32)  # drive the pusher into the mounted box

  @jax.jit
  def run(d, ds):
    def body(c, _):
      d, ds = c
      d, ds = jax.vmap(lambda d, ds: physics.step(env.sys, env.damage_binding, d.replace(ctrl=target), ds, 5))(d, ds)
      return (d, ds), ds.f_perp
    return jax.lax.scan(body, (d, ds), None, length=40)

  (d, ds), f_perp = run(d, ds)
  # servo force ~ kp * remaining distance (300 N/m x 6.5 cm ~ 20 N) pressing on a body that cannot accelerate
  assert 10.0 < float(f_perp[-1, 0, box1]) < 40.0
  assert np.isfinite(np.asarray(d.qpos)).all()
  assert abs(float(d.qpos[0, 0]) - (0.05 - S.BOX_HALF - S.PUSHER_RADIUS)) < 0.01  # pusher stopped at the box face


@pytest.mark.slow
def test_bench_end_to_end(tmp_path):
  out = tmp_path / "b.json"
  assert bench.main(["--envs", "2", "--entities", "1,2", "--tracked", "1,2", "--mounted", "1,2", "--k", "2",
                     "--entity-envs", "2", "--ratio-envs", "2",
                     "--target-s", "0.2", "--max-steps", "3", "--ref-envs", "1", "--ref-steps", "2",
                     "--task", "", "--out", str(out)]) == 0
  res = json.loads(out.read_text())
  assert res["summary"]["damage_on_off_ratio_K2_2envs"] > 0
  assert {r["backend"] for r in res["vs_envs"] + res["vs_entities"]} == {"mjx"} and res["task_backend"] == "mjx"
  assert res["summary"]["tracked_2_over_1_in_2_box_scene_damage_on_2envs"] > 0
  assert res["summary"]["entities_2_over_1_mounted_throughput_damage_on_2envs"] > 0
  assert (tmp_path / "b.png").exists()


def test_warp_scaling_plan_and_report(capsys):
  """benchmarks/warp_scaling.py: bad plan points are rejected before anything runs; ratios are per config."""
  W = load_benchmark("warp_scaling")
  for bad in ("warp-cg:sweep:2:3", "cuda:sweep:1:1", "jax-cg:spin:1:1", "jax-cg:sweep:1"):
    with pytest.raises(SystemExit):
      W.main(["--plan", bad, "--out", "unused.json"])
    assert "--plan" in capsys.readouterr().err
  rows = [dict(config=c, motion="sweep", boxes=k, free_boxes=f, nv=2 + 6 * f, physics_steps_per_s=v,
               compile_and_first_s=1.0, finite=True)
          for c, k, f, v in (("jax-cg", 1, 1, 100.0), ("jax-cg", 4, 4, 10.0), ("warp-cg", 1, 1, 200.0),
                             ("warp-cg", 4, 1, 150.0))]
  s = W.summarize(rows)
  assert s == {"jax-cg_sweep_K4_free_over_K1": pytest.approx(0.1), "warp-cg_sweep_K4_1free_over_K1": pytest.approx(0.75)}
  md = W.report_md({"device": "d", "command": "c", "date": "t", "versions": {}, "envs": 2, "rows": rows})
  assert "| warp-cg | sweep | 4 | 1 | 8 | 150 | 75.0% |" in md


# --- --backend: the task throughput on either backend ------------------------------------------
@pytest.mark.parametrize("argv, message", [
    (["--backend", "foo"], "backend: unknown backend 'foo'"),
    (["--backend", "native", "--task", ""], "backend: native times the --task throughput only"),
    (["--backend", "warp", "--task", ""], "backend: warp times the --task throughput only"),
])
def test_bench_cli_rejects_bad_backend(argv, message, tmp_path, capsys, monkeypatch):
  """Refused while the arguments are checked: nothing measured, nothing written."""
  monkeypatch.setattr(bench.cli, "run_benchmark", lambda args: pytest.fail("got past argument checking"))
  with pytest.raises(SystemExit) as e:
    bench.main(argv + ["--out", str(tmp_path / "b.json")])
  assert e.value.code == 2
  assert message in capsys.readouterr().err
  assert not list(tmp_path.iterdir())


def test_task_throughput_on_native_backend():
  row = bench.measure_task("place_plate", 2, 0.05, 2, backend="native", overrides={"robot": "gripper"})
  assert row["backend"] == "native" and row["task"] == "place_plate" and row["envs"] == 2
  assert row["robot"] == "gripper"
  assert row["steps"] >= 2 and row["env_steps_per_s"] > 0 and row["nthread"] >= 1
  assert row["physics_steps_per_s"] == pytest.approx(row["env_steps_per_s"] * row["n_substeps"])


@pytest.mark.parametrize("backend", ["native", "auto"])  # auto on a CPU, place_plate: native
def test_bench_cli_records_native_task_backend(backend, tmp_path, monkeypatch):
  """--backend native: the task row is timed natively and says so; the K-box points stay MJX (stubbed out
  here, so no MJX program compiles: each is recorded as skipped)."""
  def no_mjx(*a, **k):
    raise RuntimeError("not measured in this test")

  monkeypatch.setattr(bench.cli, "measure_pair", no_mjx)
  out = tmp_path / "b.json"
  assert bench.main(["--backend", backend, "--task", "place_plate", "--task-envs", "2", "--target-s", "0.05",
                     "--max-steps", "2", "--envs", "1", "--entities", "1", "--tracked", "", "--mounted", "",
                     "--k", "1", "--entity-envs", "1", "--ratio-envs", "1", "--ref-envs", "1", "--ref-steps", "1",
                     "--ref-max-s", "1", "--out", str(out)]) == 0
  res = json.loads(out.read_text())
  assert res["task_backend"] == "native"
  assert res["task"]["backend"] == "native" and res["task"]["env_steps_per_s"] > 0
  assert "(native backend, robot gripper, 2 envs" in (tmp_path / "b.md").read_text()
  assert f"--backend {backend}" in res["command"]

"""Committed trained weights, scored again on this machine: the ``checkpoint:PATH#SEED`` policy spec every
command takes, and benchmarks/policy_recheck.py (bad values refused before anything is built; a tiny native
run of a committed Pick Egg policy)."""

import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import load_benchmark

import tasks
import train
from apps import resolve as R

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Pick Egg from the pre-grasp start, trained on a GPU (seeds 0,1,2: w = 2 from a carrying actor; the committed
# results say seed 0 keeps still, seeds 1 and 2 carry the egg safely)
SAFE = os.path.join(ROOT, "benchmarks", "results", "rl_pick_egg_nvidia_h200_held_from_carry_ramp10_penalty_policy.npz")

recheck = load_benchmark("policy_recheck")


def test_seed_suffix_names_a_seed_of_the_run():
  assert R.parse_policy_spec(f"checkpoint:{SAFE}#2") == ("checkpoint", SAFE)
  assert R.checkpoint_seed(f"checkpoint+sample:{SAFE}#2") == 2
  assert R.checkpoint_seed(f"checkpoint:{SAFE}") is None


@pytest.mark.parametrize("suffix, says", [("#9", "seed 9 is not a seed of checkpoint .*its seeds: 0, 1, 2"),
                                          ("#one", "after '#' comes a seed of the run")])
def test_bad_seed_suffix_is_refused(suffix, says):
  with pytest.raises(ValueError, match="^policy: .*" + says):
    R.parse_policy_spec(f"checkpoint:{SAFE}{suffix}")


def test_a_path_with_a_hash_that_exists_is_a_path(tmp_path):
  odd = tmp_path / "run#1.npz"
  odd.write_bytes(open(SAFE, "rb").read())
  assert R.parse_policy_spec(f"checkpoint:{odd}") == ("checkpoint", str(odd))
  assert R.checkpoint_seed(f"checkpoint:{odd}") is None


def test_seed_suffix_loads_that_seeds_weights():
  overrides = R.task_overrides("pick_egg", R.policy_task_kwargs(f"checkpoint:{SAFE}#1", "pick_egg"), None, [])
  assert overrides["start"] == "pregrasp" and overrides["carry_reward"] == "held"
  env = tasks.make("pick_egg", **overrides)
  got = R.make_policy(f"checkpoint:{SAFE}#1", env)
  for seed, same in ((1, True), (0, False)):
    want = train.load_policy(SAFE, env, seed=seed)
    eq = all(np.array_equal(np.asarray(a), np.asarray(b))
             for a, b in zip(jax.tree.leaves(got.params), jax.tree.leaves(want.params), strict=True))
    assert eq == same


@pytest.mark.parametrize("argv, says", [
    (["--task", "pick_eggs", "--policies", "zero"], "task: unknown task"),
    (["--task", "pick_egg", "--policies", ","], "policies: give at least one"),
    (["--task", "pick_egg", "--policies", "zero", "--backends", "warp"], "backends: unknown backend 'warp'"),
    (["--task", "pick_egg", "--policies", "zero", "--backends", "mjx,mjx"], "backends: give each"),
    (["--task", "pick_egg", "--policies", "zero", "--episodes", "0"], "episodes"),
    (["--task", "pick_egg", "--policies", "zero", "--fragility", "1,-2"], "fragility"),
    (["--task", "pick_egg", "--policies", "zero", "--fragility", "one"], "fragility: comma-separated numbers"),
    (["--task", "pick_egg", "--policies", "zero", "--fragility", "nan"], "fragility"),
    (["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#7"], "policy: seed 7"),
    (["--task", "place_plate", "--policies", f"checkpoint:{SAFE}#1"], "trained on task 'pick_egg'"),
    (["--task", "pick_egg", "--policies", "zero", "--task-arg", "start=\"flying\""], "start"),
    (["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1", "--policy-precision", "bf16"], "policy_precision"),
    (["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1", "--policy-precision", "tf32,tf32"],
     "policy_precision"),
    (["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1,zero", "--policy-precision", "float32,tf32"],
     "policy_precision: tf32 rounds a checkpoint policy's network; zero has none"),
    (["--task", "pick_egg", "--policies", "zero", "--matmul-precision", "highest"], "matmul_precision"),
    (["--task", "pick_egg", "--policies", "zero", "--matmul-precision", "float32,float32"], "matmul_precision"),
    (["--task", "pick_egg", "--policies", "zero", "--matmul-precision", ","], "matmul_precision"),
])
def test_bad_values_are_refused_before_anything_is_built(argv, says, tmp_path, capsys):
  with pytest.raises(SystemExit):
    recheck.main(argv + ["--results-dir", str(tmp_path)])
  assert says in capsys.readouterr().err
  assert not os.listdir(tmp_path)


def test_a_committed_safe_carry_scores_safe_on_native_mujoco(tmp_path):
  assert recheck.main(["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1", "--backends", "native",
                       "--episodes", "8", "--tag", "t", "--results-dir", str(tmp_path)]) == 0
  with open(tmp_path / "policy_recheck_pick_egg_t.json") as f:
    res = json.load(f)
  (row,) = res["rows"]
  assert row["backend"] == "native" and row["task_kwargs"]["start"] == "pregrasp"
  assert row["completion"] >= 0.75 and row["safe_completion"] >= 0.75
  md = open(tmp_path / "policy_recheck_pick_egg_t.md").read()
  assert "benchmarks/policy_recheck.py" in md and "| `checkpoint:" in md and "#1` | native |" in md


def test_references_run_where_the_checkpoints_were_trained():
  """A scripted reference beside checkpoints gets their task settings (robot, start …) without --task-arg."""
  a = recheck.parse(["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1,scripted:safe"])
  ckpt_kw, ref_kw = a.overrides
  assert ref_kw == ckpt_kw and ref_kw["robot"] == "gripper" and ref_kw["start"] == "pregrasp"
  alone = recheck.parse(["--task", "pick_egg", "--policies", "scripted:safe"]).overrides[0]
  assert alone.get("start") != "pregrasp"


def test_seeds_of_one_checkpoint_share_one_evaluator_and_score_as_a_fresh_one():
  """Rows of one checkpoint file, action, settings and backend reuse one compiled evaluator (the weights are
  data); each row's numbers are those of its own evaluator."""
  a = recheck.parse(["--task", "pick_egg", "--policies",
                     f"checkpoint:{SAFE}#1,checkpoint:{SAFE}#0,checkpoint+sample:{SAFE}#1,scripted:safe"])
  shared = {}
  rows = [recheck.rescore("pick_egg", env, spec, ov, "native", 4, 3, shared)
          for spec, ov, env in zip(a.policies, a.overrides, a.envs)]
  assert len(shared) == 3  # mode and sample of the one file, and the scripted reference
  (ev_mode,) = [ev for k, ev in shared.items() if k[0][1:] == ("mode",)]  # key: ((file, action), settings, backend)
  assert ev_mode.num_compiled == 1  # seeds 1 and 0 ran one per-step program
  fresh = recheck.rescore("pick_egg", a.envs[1], a.policies[1], a.overrides[1], "native", 4, 3)
  assert {k: v for k, v in rows[1].items() if k != "wall_s"} == {k: v for k, v in fresh.items() if k != "wall_s"}
  assert rows[0]["safe_completion"] != rows[1]["safe_completion"] or rows[0]["task_return"] != rows[1]["task_return"]


def test_fragility_levels_share_one_evaluator_and_lower_safety_of_a_policy_near_the_thresholds(tmp_path):
  """--fragility 1,4: one row per level from one compiled evaluator per policy; at 4 the thresholds are a
  quarter, so a carry that was safe at 1 is not safer (and the rows say their level)."""
  assert recheck.main(["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1", "--backends", "native",
                       "--episodes", "8", "--fragility", "1,4", "--tag", "f", "--results-dir", str(tmp_path)]) == 0
  with open(tmp_path / "policy_recheck_pick_egg_f.json") as f:
    rows = json.load(f)["rows"]
  assert [r["fragility"] for r in rows] == [1.0, 4.0]
  assert rows[1]["safe_completion"] <= rows[0]["safe_completion"] and rows[1]["cost_mean"] > rows[0]["cost_mean"]
  assert "| native | float32 | default | 4 |" in open(tmp_path / "policy_recheck_pick_egg_f.md").read()


def test_task_arg_overrides_a_checkpoints_settings():
  """--task-arg counter="box" scores Place Plate policies trained on the plane counter on the box one."""
  brax = os.path.join(ROOT, "benchmarks", "results", "rl_brax_place_plate_h200_scored_s0_w2_s0_policy.npz")
  a = recheck.parse(["--task", "place_plate", "--policies", f"checkpoint:{brax}#0,scripted:safe",
                     "--task-arg", 'counter="box"'])
  for kw, env in zip(a.overrides, a.envs):
    assert kw["counter"] == "box" and kw["obs_mode"] == "paper" and kw["robot"] == "gripper"
    assert env.unwrapped.counter == "box"
  assert recheck.parse(["--task", "place_plate", "--policies", f"checkpoint:{brax}#0"]).envs[0].unwrapped.counter == "plane"


def test_tf32_policy_rounds_the_networks_products_and_is_a_row_of_its_own(tmp_path):
  """--policy-precision float32,tf32: the same checkpoint scored with its matrix products at full float32 and
  at TF32 (emulated); the TF32 action differs from the float32 one by rounding, not more."""
  a = recheck.parse(["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1"])
  env = a.envs[0]
  policy = recheck.R.make_policy(a.policies[0], env)
  state = jax.jit(env.reset)(jax.random.PRNGKey(0))
  full = policy(state, jax.random.PRNGKey(1))
  tf32 = recheck.tf32_policy(policy)(state, jax.random.PRNGKey(1))
  gap = float(jnp.max(jnp.abs(full - tf32)))
  assert 0 < gap < 0.05, gap
  assert recheck.main(["--task", "pick_egg", "--policies", f"checkpoint:{SAFE}#1", "--backends", "native",
                       "--episodes", "4", "--policy-precision", "float32,tf32", "--tag", "p",
                       "--results-dir", str(tmp_path)]) == 0
  with open(tmp_path / "policy_recheck_pick_egg_p.json") as f:
    rows = json.load(f)["rows"]
  assert [r["policy_precision"] for r in rows] == ["float32", "tf32"]
  assert "| native | tf32 | default | 1 |" in open(tmp_path / "policy_recheck_pick_egg_p.md").read()


def test_matmul_precision_is_fixed_when_the_evaluator_traces_and_is_a_row_of_its_own(tmp_path, monkeypatch):
  """--matmul-precision default,float32: the second row's program is traced under float32 matmul precision (what
  a GPU needs to compute without TF32), the first under the backend's default; on this CPU both score alike."""
  seen = []
  make_policy = recheck.R.make_policy

  def recording(spec, env):
    policy = make_policy(spec, env)

    def traced(state, rng):  # runs when the evaluator traces the policy
      seen.append(jax.config.jax_default_matmul_precision)
      return policy(state, rng)
    return traced
  monkeypatch.setattr(recheck.R, "make_policy", recording)
  assert recheck.main(["--task", "pick_egg", "--policies", "scripted:safe", "--backends", "native",
                       "--episodes", "4", "--matmul-precision", "default,float32", "--tag", "m",
                       "--results-dir", str(tmp_path)]) == 0
  assert seen and seen[0] is None and seen[-1] == "float32" and set(seen) == {None, "float32"}
  with open(tmp_path / "policy_recheck_pick_egg_m.json") as f:
    rows = json.load(f)["rows"]
  assert [r["matmul_precision"] for r in rows] == ["default", "float32"]
  assert {k: v for k, v in rows[0].items() if k not in ("wall_s", "matmul_precision")} == \
      {k: v for k, v in rows[1].items() if k not in ("wall_s", "matmul_precision")}
  assert "| native | float32 | float32 | 1 |" in open(tmp_path / "policy_recheck_pick_egg_m.md").read()

"""benchmarks/rl_multiseed.py at toy size on CPU: S seeds per method in one program, per-seed final
evaluation, mean ± std / min rows with their commands, and --combine of two calls into one table."""

import json
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import rl_multiseed  # noqa: E402

# Minutes on 2 shared cores (compiles of the preset networks per method): run with -m slow.
pytestmark = pytest.mark.slow

TOY = ["--task", "train.experiments.pusher:PusherEnv", "--seeds", "0,1", "--num-envs", "16", "--unroll-length", "8",
       "--budget-seconds", "600", "--timesteps", "2048", "--eval-every", "1024", "--eval-envs", "8",
       "--eval-episodes", "8"]


@pytest.fixture(scope="module")
def two_calls(tmp_path_factory):
  d = str(tmp_path_factory.mktemp("rl_ms"))
  # the paper preset's 128 env-steps per iteration (16 envs, rollout 8) → 2 iterations, as the others get
  for methods, tag, steps, actions in (("task_only,pid", "a", "2048", "mode,sample,mean"),
                                       ("paper", "b", "256", "sample")):
    assert rl_multiseed.main(TOY + ["--methods", methods, "--tag", tag, "--timesteps", steps, "--results-dir", d,
                                    "--work-dir", d, "--eval-actions", actions]) == 0
  return d


def _load(path):
  with open(path) as f:
    return json.load(f)


def test_rows_have_per_seed_stats_and_commands(two_calls):
  a = _load(os.path.join(two_calls, "rl_pusherenv_cpu_a.json"))
  assert [r["method"] for r in a["rows"]] == ["task_only", "pid"]
  for r in a["rows"]:
    assert [p["seed"] for p in r["per_seed"]] == [0, 1]
    assert all(p["final_eval"]["episodes"] == 8 for p in r["per_seed"])
    s = r["summary"]["safe_completion"]
    vals = [p["final_eval"]["safe_completion"] for p in r["per_seed"]]
    assert s["n"] == 2 and s["min"] == min(vals) and abs(s["mean"] - sum(vals) / 2) < 1e-12
    assert "--methods task_only,pid" in r["command"] and r["throughput_all_seeds"] > 0  # 2 iterations: 1 timed
    assert {h["seed"] for h in r["history"]} == {0, 1}
    assert r["matmul_precision"] == "default" and [c["matmul_precision"] for c in r["calls"]] == ["default"]
  assert a["rows"][1]["config"]["multiplier"] == "pid" and a["rows"][1]["config"]["budget"] == 2.0
  assert os.path.isfile(os.path.join(two_calls, "rl_pusherenv_cpu_a_pid.png"))
  for r in a["rows"]:  # the first action is the headline; every action is kept per seed
    assert r["eval_actions"] == ["mode", "sample", "mean"]
    for p in r["per_seed"]:
      assert set(p["final_eval_by_action"]) == {"mode", "sample", "mean"}
      assert p["final_eval_by_action"]["mode"] == p["final_eval"]
  md = open(os.path.join(two_calls, "rl_pusherenv_cpu_a.md")).read()
  assert "## Final policy by action" in md and md.count("| sample |") == 2


def test_a_sampled_headline_says_so(two_calls):
  b = _load(os.path.join(two_calls, "rl_pusherenv_cpu_b.json"))
  assert b["rows"][0]["eval_actions"] == ["sample"]
  md = open(os.path.join(two_calls, "rl_pusherenv_cpu_b.md")).read()
  assert "penalty (w=2), sample action |" in md and "## Final policy by action" not in md


def test_resume_continues_a_run_over_calls(two_calls, tmp_path):
  """A run longer than one device call: --resume continues the method's run in --work-dir; the row lists
  both calls, its history goes on with the first call's rows, and time keeps counting across calls."""
  argv = TOY + ["--methods", "paper", "--tag", "c", "--results-dir", str(tmp_path), "--work-dir", two_calls,
                "--eval-actions", "sample", "--resume"]
  assert rl_multiseed.main(argv[:argv.index("--timesteps")] + ["--timesteps", "512"]
                           + argv[argv.index("--timesteps") + 2:]) == 0
  row = _load(os.path.join(str(tmp_path), "rl_pusherenv_cpu_c.json"))["rows"][0]
  assert [c["iterations_at_end"] for c in row["calls"]] == [2, 4] and row["env_steps_per_seed"] == 512
  assert "--tag b" in row["calls"][0]["command"] and "--resume" in row["calls"][1]["command"]
  seed0 = [h for h in row["history"] if h["seed"] == 0]
  assert [h["iteration"] for h in seed0] == [2, 4]  # the first call's row kept, then this call's
  assert seed0[1]["wall_time"] > seed0[0]["wall_time"] > 0
  md = open(os.path.join(str(tmp_path), "rl_pusherenv_cpu_c.md")).read()
  assert "  - call 1: `" in md and "  - call 2: `" in md


def test_paper_preset_row(two_calls):
  b = _load(os.path.join(two_calls, "rl_pusherenv_cpu_b.json"))
  cfg = b["rows"][0]["config"]
  assert cfg["activation"] == "tanh" and cfg["policy_hidden_sizes"] == [512, 512] and cfg["target_kl"] == 0.01
  assert cfg["init_log_std"] == [-0.5, -1.5] and cfg["anneal_learning_rate"] and cfg["damage_weight"] == 2.0


def test_combine_keeps_each_rows_command(two_calls):
  files = [os.path.join(two_calls, f"rl_pusherenv_cpu_{t}.json") for t in "ab"]
  assert rl_multiseed.main(["--combine", *files, "--tag", "toy", "--results-dir", two_calls]) == 0
  c = _load(os.path.join(two_calls, "rl_pusherenv_combined_toy.json"))
  assert [r["method"] for r in c["rows"]] == ["task_only", "pid", "paper"]
  assert "--tag b" in c["rows"][2]["command"] and "--tag a" in c["rows"][0]["command"]
  md = open(os.path.join(two_calls, "rl_pusherenv_combined_toy.md")).read()
  assert "PID-Lagrangian" in md and "paper PPO preset" in md and "± " in md


def test_combine_numbers_reruns_of_one_command(two_calls):
  a = os.path.join(two_calls, "rl_pusherenv_cpu_a.json")
  assert rl_multiseed.main(["--combine", a, a, "--tag", "rerun", "--results-dir", two_calls]) == 0
  c = _load(os.path.join(two_calls, "rl_pusherenv_combined_rerun.json"))
  labels = [r["label"] for r in c["rows"]]
  assert len(labels) == 4 and len(set(labels)) == 4
  assert labels[0].endswith(" — run 1") and labels[2].endswith(" — run 2")
  assert labels[0].removesuffix(" — run 1") == labels[2].removesuffix(" — run 2")


def test_completion_gate_is_reported_per_seed(tmp_path):
  """--damage-warmup-completion: each seed's row records the env steps at which w began to ramp (the
  iteration after its gate opened, a multiple of the 128 steps per iteration), and the table says so."""
  d = str(tmp_path)
  assert rl_multiseed.main(TOY + ["--methods", "penalty", "--damage-warmup-completion", "0.05", "--timesteps", "4096",
                                  "--damage-ramp-steps", "256", "--tag", "gate", "--results-dir", d,
                                  "--work-dir", d]) == 0
  row = _load(os.path.join(d, "rl_pusherenv_cpu_gate.json"))["rows"][0]
  assert row["train_kwargs"]["damage_warmup_completion"] == 0.05
  for p in row["per_seed"]:
    v = p["penalty_from_steps"]
    assert v is None or (v > 0 and v % 128 == 0), p
  with open(os.path.join(d, "rl_pusherenv_cpu_gate.md")) as f:
    assert "Penalty gate of damage penalty (w=2; w=0 until training completion ≥ 5%" in f.read()

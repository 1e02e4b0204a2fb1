"""benchmarks/critic_targets.py: moving vs fixed value targets under a stress learning rate (plumbing on CPU)."""

import json

import pytest
from conftest import load_benchmark

CT = load_benchmark("critic_targets")


@pytest.mark.parametrize("argv, says", [
    (["--settings", "0.01"], "--settings"),
    (["--settings", "0.01:x"], "--settings"),
    (["--settings", "-1:none"], "--settings"),
    (["--settings", "nan:1"], "--settings"),
    (["--settings", "0.01:0"], "--settings"),
    (["--seeds", "0,0"], "--seeds"),
    (["--seeds", "a"], "--seeds"),
    (["--timesteps", "100"], "--timesteps"),
    (["--timesteps", "2560", "--evals", "3"], "--evals"),
    (["--evals", "0"], "--evals"),
])
def test_bad_arguments_are_refused_naming_the_flag(argv, says, capsys):
  with pytest.raises(SystemExit) as e:
    CT.parse(argv)
  assert e.value.code == 2 and says in capsys.readouterr().err


def test_a_run_reports_each_seed_and_the_table_counts_them(tmp_path):
  """One tiny run through train.train (fixed targets, a cost critic, two seeds, two logged points), then the
  results pair of a grid made of it and a copy marked as moving targets with one seed diverged."""
  a = CT.parse(["--seeds", "0,1", "--settings", "0.01:none", "--timesteps", "2560", "--evals", "2", "--cost-critic"])
  r = CT.run(a.seed_list, 0.01, None, True, a.timesteps, a.evals, a.per_iteration, a.cost_critic)
  assert r["gae_per_iteration"] and r["cost_critic"] and [p["seed"] for p in r["per_seed"]] == [0, 1]
  for p in r["per_seed"]:
    assert p["env_steps"] == [1280, 2560] and len(p["value_loss"]) == 2
    assert p["largest_value_loss"] == max(p["value_loss"]) and 0.0 <= p["safe_completion"] <= p["completion"] <= 1.0
  moving = json.loads(json.dumps(r))
  moving["gae_per_iteration"] = False
  moving["per_seed"][1].update(value_loss=[5.0, 1e12], largest_value_loss=1e12, past_floor=True,
                               diverged={"env_steps": 2560, "value_loss": 1e12, "lowest_before": 5.0})
  res = dict(task="pusher", seeds=a.seed_list, timesteps=a.timesteps, run=CT.RUN, runs=[moving, r], cost_critic=True,
             date="today", git="abc", jax="0", backend="cpu", command="critic_targets")
  md = CT.render_md(res)
  assert "| 0.01 | none | moving | 1 / 2 | 1 / 2 |" in md and "| 0.01 | none | per iteration | 0 / 2 | 0 / 2 |" in md
  assert "| 2,560 steps (1e+12) |" in md and "two heads (reward, cost" in md

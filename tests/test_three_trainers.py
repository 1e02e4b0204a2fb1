"""benchmarks/three_trainers.py: the steps of each recipe, bad values refused before any step runs, and the
orchestration over calls (done steps skipped, the paper's runs continued, --stop-after, a failed step, the
tables) with a stand-in for the trainers that copies committed results files."""

import json
import os
import shutil
import subprocess
import sys

import pytest
from conftest import BENCHMARKS, load_benchmark

three = load_benchmark("three_trainers")
RESULTS = os.path.join(BENCHMARKS, "results")
# committed results of the three trainers on Place Plate's box counter, seeds 0-2 (ours, paper) and 0 (Brax)
COPIES = {
    "ours_task_only": "rl_place_plate_nvidia_h200_box_stdparam_300s_task_only_s012.json",
    "ours_penalty": "rl_place_plate_nvidia_h200_box_stdparam_300s_s012.json",
    "paper_task_only": "rl_place_plate_nvidia_h200_paper_box_epochkl_stdparam_task_only.json",
    "paper_penalty": "rl_place_plate_nvidia_h200_paper_box_epochkl_stdparam_penalty.json",
    "brax_w0_s0": "rl_brax_place_plate_box_h200_w0_s0.json",
    "brax_w2_s0": "rl_brax_place_plate_box_h200_alone_s0.json",
}


def _dirs(tmp_path):
  return ["--results-dir", str(tmp_path / "r"), "--work-dir", str(tmp_path / "w")]


def _run(argv, runner=None):
  def refuse(step, env):
    raise AssertionError(f"no step should run, {step.name} did")
  return three.main(argv, slug="gpu_x", runner=runner or refuse)


@pytest.mark.parametrize("argv, says", [
    (["--task", "drop"], "task: one of place_plate, shelve_item, pick_egg"),
    (["--seeds", "0,x"], "seeds: comma-separated"),
    (["--seeds", "1,1"], "seeds: distinct"),
    (["--trainers", "ours,sac"], "trainers: comma-separated of ours,brax,paper"),
    (["--task", "shelve_item", "--trainers", "paper"], "no recipe for shelve_item"),
    (["--stop-after", "-5"], "stop_after"),
    (["--stop-after", "nan"], "stop_after"),
    (["--tag", "a/b"], "tag: letters"),
    (["--device", "nvidia h100", "--plan"], "device: a results-file slug"),
    (["--device", "nvidia_h100"], "device: only with --plan or --tables"),
    (["--ours-args", "--seeds 3"], "ours_args: --seeds are set by this script"),
    (["--brax-args=--out=x"], "brax_args: --out are set by this script"),
    (["--paper-args", "'unclosed"], "paper_args: not a shell-quoted list"),
])
def test_refuses_bad_values_before_anything_runs(argv, says, tmp_path, capsys):
  with pytest.raises(SystemExit) as e:
    _run(argv + _dirs(tmp_path))
  assert e.value.code == 2 and says in capsys.readouterr().err


@pytest.mark.parametrize("argv, says", [
    (["--parts", "ours,sac"], "parts: 'sac' names no step"),
    (["--ours-args", "--num-envs -3"], "step ours_task_only: its flags are refused by benchmarks/rl_multiseed.py"),
    (["--paper-args", "--eval-actions greedy"], "step paper_task_only: its flags are refused"),
    (["--brax-args", "--num-evals 0"], "step brax_w0_s0: num_evals: must be >= 1"),
])
def test_a_step_refused_by_its_script_stops_the_call_before_any_step_runs(argv, says, tmp_path, capsys):
  assert _run(argv + _dirs(tmp_path)) == 2
  assert says in capsys.readouterr().err
  assert not os.path.exists(tmp_path / "r")


def test_the_steps_of_each_recipe(tmp_path):
  """Place Plate: ours (seeds in one program), Brax per seed and weight, the paper's settings; Shelve Item: ours
  one program per seed, no paper; Pick Egg: Brax's w = 2 starts from its own w = 0 policy of the seed and waits
  for it. The results files carry the device, the tag and the step; an option of --*-args replaces the recipe's."""
  def steps(task, *extra):
    return three.plan(three.parse(["--task", task, *extra] + _dirs(tmp_path)), "gpu_x")

  pp = steps("place_plate", "--ours-args", "--budget-seconds 20")
  assert [s.name for s in pp] == ["ours_task_only", "ours_penalty", "brax_w0_s0", "brax_w0_s1", "brax_w0_s2",
                                  "brax_w2_s0", "brax_w2_s1", "brax_w2_s2", "paper_task_only", "paper_penalty"]
  ours = pp[0]
  assert ours.results.endswith("rl_place_plate_gpu_x_three_trainers_ours_task_only.json")
  assert ours.budget_s == 20 and three._flag_value(ours.argv, "--budget-seconds") == "20"
  assert ours.argv.count("--budget-seconds") == 1  # the recipe's value replaced, not repeated
  assert three._flag_value(ours.argv, "--policy-std") == "parameter" and ours.seeds == [0, 1, 2]
  assert pp[5].results.endswith("rl_brax_place_plate_gpu_x_three_trainers_brax_w2_s0.json")
  assert three._flag_value(pp[5].argv, "--damage-weights") == "2" and pp[5].budget_s == 300
  assert pp[-1].work.endswith("place_plate_three_trainers_paper_penalty")
  assert three._flag_value(pp[-1].argv, "--paper-timesteps") == "25559040"
  assert [s.name for s in three.select(pp, ["paper_penalty", "brax_w0_s1"])] == ["brax_w0_s1", "paper_penalty"]
  assert [s.name for s in three.select(pp, ["paper"])] == ["paper_task_only", "paper_penalty"]

  si = steps("shelve_item", "--seeds", "4,5")
  assert [s.name for s in si][:4] == ["ours_task_only_s4", "ours_task_only_s5", "ours_penalty_s4", "ours_penalty_s5"]
  assert all(s.trainer != "paper" for s in si) and len(si) == 8
  assert three._flag_value(si[2].argv, "--eval-task-settings") == '{"start":"in_front"}' and si[2].budget_s == 480

  pe = steps("pick_egg", "--trainers", "brax", "--seeds", "1")
  w0, w2 = pe
  assert w2.waits_for == w0.results.replace(".json", "_w0_s1_policy.npz")
  assert three._flag_value(w2.argv, "--init-from") == w2.waits_for
  assert three._flag_value(w2.argv, "--init-seed") == "1"
  assert three.update_status(w2).status.startswith("waits for")


def _stand_in(log, finish_paper=False, fail=()):
  """Runs no trainer: writes the step's results file from a committed one (and, for the paper's runs, a work
  folder to continue); ``finish_paper``: the paper's run reaches its env steps."""
  def run(step, env):
    log.append(list(step.argv))
    if step.name in fail:
      return 1
    doc = json.load(open(os.path.join(RESULTS, COPIES[step.name])))
    if step.work:
      run = os.path.join(three._at(step.work), three._flag_value(step.argv, "--methods"))  # rl_multiseed's folder
      os.makedirs(run, exist_ok=True)
      open(os.path.join(run, "checkpoint.npz"), "w").close()
      doc["rows"][0]["stopped_by_time_limit"] = not finish_paper
    os.makedirs(os.path.dirname(three._at(step.results)), exist_ok=True)
    with open(three._at(step.results), "w") as f:
      json.dump(doc, f)
    return 0
  return run


def test_calls_skip_what_is_done_continue_the_paper_and_build_the_table(tmp_path, capsys):
  argv = ["--trainers", "ours,paper"] + _dirs(tmp_path)
  log = []
  # call 1: --stop-after leaves no time for a 300 s step; nothing runs, nothing is written
  assert _run(argv + ["--stop-after", "200"], _stand_in(log)) == 0
  assert log == [] and "ours_task_only: not started, it needs about 375 s" in capsys.readouterr().out
  # call 2: ours' task-only step fails, the rest runs; the paper's runs stop short of their env steps
  assert _run(argv, _stand_in(log, fail=("ours_task_only",))) == 1
  assert [a[a.index("--methods") + 1] for a in log] == ["task_only", "penalty", "paper_task_only", "paper"]
  assert all("--resume" not in a for a in log)
  out = capsys.readouterr().out
  assert "steps left: ours_task_only, paper_task_only, paper_penalty" in out
  assert os.path.exists(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.md")
  # call 3: only what is left; the paper's runs continue their work folders, and finish
  log.clear()
  assert _run(argv, _stand_in(log, finish_paper=True)) == 0
  assert [a[a.index("--methods") + 1] for a in log] == ["task_only", "paper_task_only", "paper"]
  assert ["--resume" in a for a in log] == [False, True, True]
  assert "steps left: none" in capsys.readouterr().out
  table = json.load(open(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.json"))
  md = open(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.md").read()
  assert "paper's PPO settings" in md and "| ours" in md, table.keys()
  # call 4: all done; a call runs nothing and --plan says so
  log.clear()
  assert _run(argv + ["--plan"]) == 0 and "4 steps (4 done)" in capsys.readouterr().out


def test_brax_steps_and_a_results_file_of_other_seeds(tmp_path, capsys):
  argv = ["--trainers", "brax", "--seeds", "0"] + _dirs(tmp_path)
  log = []
  assert _run(argv + ["--parts", "brax_w2"], _stand_in(log)) == 0
  assert len(log) == 1 and three._flag_value(log[0], "--damage-weights") == "2"
  assert "steps left: brax_w0_s0" in capsys.readouterr().out
  # a file at a step's name that holds another run is not taken for it, and not replaced
  src = os.path.join(RESULTS, COPIES["brax_w2_s0"])
  shutil.copy(src, tmp_path / "r" / "rl_brax_place_plate_gpu_x_three_trainers_brax_w0_s0.json")
  assert _run(argv) == 2
  assert "holds seeds [0], not the run of step brax_w0_s0" in capsys.readouterr().err


def test_brax_w2_runs_in_the_call_that_made_the_w0_policy_it_waits_for(tmp_path, capsys):
  """Pick Egg: Brax's w = 2 step starts from the w = 0 step's exported policy; one call runs both, in order
  (the w = 2 step's flags, its --init-from file included, checked once that file exists)."""
  log = []
  made = {"brax_w0_s1": "rl_brax_pick_egg_held_std0_clip_obsclip_w0_430s_s1",  # committed runs of seed 1
          "brax_w2_s1": "rl_brax_pick_egg_from_own_carry_w2_own_s1"}

  def run(step, env):  # as rl_brax_ppo.py --export-policy: the results and the policy beside them
    log.append(list(step.argv))
    shutil.copy(os.path.join(RESULTS, made[step.name] + ".json"), three._at(step.results))
    w = three._flag_value(step.argv, "--damage-weights")
    shutil.copy(os.path.join(RESULTS, f"{made['brax_w0_s1']}_w0_s1_policy.npz"),
                three._at(step.results).replace(".json", f"_w{w}_s1_policy.npz"))
    return 0

  argv = ["--task", "pick_egg", "--trainers", "brax", "--seeds", "1"] + _dirs(tmp_path)
  os.makedirs(tmp_path / "r")
  assert _run(argv, run) == 0
  assert [three._flag_value(a, "--damage-weights") for a in log] == ["0", "2"]
  assert three._flag_value(log[1], "--init-from").endswith("rl_brax_pick_egg_gpu_x_three_trainers_brax_w0_s1_w0_s1_policy.npz")
  assert "steps left: none" in capsys.readouterr().out


def test_a_paper_run_whose_folder_is_gone_is_not_started_over(tmp_path, capsys):
  """A stopped paper run whose work folder went with its machine: no call runs its step over the results of its
  earlier calls, while --plan shows it and --tables builds the tables with it (its env steps as it stopped)."""
  argv = ["--trainers", "paper", "--seeds", "0,1,2"] + _dirs(tmp_path)
  assert _run(argv + ["--parts", "paper_task_only"], _stand_in([])) == 0
  shutil.rmtree(tmp_path / "w")
  before = open(tmp_path / "r" / "rl_place_plate_gpu_x_three_trainers_paper_task_only.json").read()
  for parts in ([], ["--parts", "paper_task_only"]):
    assert _run(argv + parts) == 2
    err = capsys.readouterr().err
    assert "paper_task_only.json is a run stopped at" in err and "whose folder" in err and "move the file away" in err
  assert _run(argv + ["--plan"]) == 0
  assert "paper_task_only: stopped at" in capsys.readouterr().out
  os.remove(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.md")
  assert _run(argv + ["--tables"]) == 0
  assert ("steps left: paper_penalty; stopped short, their folders gone (tabled as they stopped): paper_task_only"
          in capsys.readouterr().out)
  md = open(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.md").read()
  assert "rl_place_plate_gpu_x_three_trainers_paper_task_only.json" in md
  # a call that leaves the stopped step out runs the rest
  log = []
  assert _run(argv + ["--parts", "paper_penalty"], _stand_in(log)) == 0 and len(log) == 1
  assert open(tmp_path / "r" / "rl_place_plate_gpu_x_three_trainers_paper_task_only.json").read() == before


def test_stop_after_counts_each_trainers_overhead(tmp_path, capsys):
  """Shelve Item: ours' w = 2 step (480 s + 75 s) does not fit 552 s; Brax's (400 s + 150 s) does."""
  started = []
  argv = ["--task", "shelve_item", "--seeds", "0", "--stop-after", "552"] + _dirs(tmp_path)
  assert _run(argv, lambda step, env: started.append(step.name) or 1) == 1  # the stand-in fails every step
  assert started == ["ours_task_only_s0", "brax_w0_s0", "brax_w2_s0"]
  out = capsys.readouterr().out
  assert "ours_penalty_s0: not started, it needs about 555 s" in out
  assert "== brax_w0_s0: exit status 1 after 0 s (budget 400 s)" in out


def test_stop_after_counts_less_for_a_paper_run_continued(tmp_path, capsys):
  """The paper's first call needs its 470 s budget + 90 s; the calls that continue it + 60 s."""
  argv = ["--trainers", "paper", "--seeds", "0,1,2", "--parts", "paper_penalty"] + _dirs(tmp_path)
  log = []
  assert _run(argv + ["--stop-after", "540"], _stand_in(log)) == 0
  assert log == [] and "paper_penalty: not started, it needs about 560 s" in capsys.readouterr().out
  assert _run(argv, _stand_in(log)) == 0 and len(log) == 1  # stopped short: its work folder holds the run
  assert _run(argv + ["--stop-after", "540"], _stand_in(log)) == 0
  assert len(log) == 2 and "--resume" in log[1]
  assert _run(argv + ["--stop-after", "520"], _stand_in(log)) == 0
  assert len(log) == 2 and "paper_penalty: not started, it needs about 530 s" in capsys.readouterr().out


def test_tables_of_a_benchmark_run_on_another_device(tmp_path, capsys):
  """--device names the results of a benchmark run elsewhere (a GPU): --plan shows their status and --tables
  rebuilds the tables from them here, running nothing."""
  argv = ["--trainers", "ours", "--seeds", "0,1,2"] + _dirs(tmp_path)
  assert _run(argv, _stand_in([])) == 0  # made on "gpu_x"
  os.remove(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.md")

  def here(*extra):
    return three.main(argv + list(extra), slug="cpu", runner=lambda step, env: pytest.fail(f"{step.name} ran"))

  assert here("--plan") == 0 and "device cpu: 2 steps (0 done)" in capsys.readouterr().out
  assert here("--plan", "--device", "gpu_x") == 0 and "device gpu_x: 2 steps (2 done)" in capsys.readouterr().out
  assert here("--tables", "--device", "gpu_x") == 0
  md = open(tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode.md").read()
  assert "rl_place_plate_gpu_x_three_trainers_ours_penalty.json" in md
  assert here("--tables") == 0 and "steps left: ours_task_only, ours_penalty" in capsys.readouterr().out


def test_a_table_of_its_name_built_from_other_results_is_not_replaced(tmp_path, capsys):
  """The benchmark rebuilds its tables after every call; a table already at their name that other results
  built (a hand-made table, another device's benchmark under the same --tag) stops the call before any step
  runs, and stays as it was."""
  argv = ["--trainers", "ours", "--seeds", "0,1,2"] + _dirs(tmp_path)
  assert _run(argv, _stand_in([])) == 0  # on "gpu_x": its own tables, rebuilt by --tables there
  assert _run(argv + ["--tables"]) == 0
  stem = tmp_path / "r" / "trainer_table_place_plate_three_trainers_mode"
  doc = json.load(open(f"{stem}.json"))
  doc["sources"] = doc["sources"] + ["rl_place_plate_by_hand.json"]
  with open(f"{stem}.json", "w") as f:
    json.dump(doc, f)
  before = open(f"{stem}.json").read(), open(f"{stem}.md").read()
  for extra in ([], ["--tables"]):
    assert _run(argv + extra) == 2
    err = capsys.readouterr().err
    assert "tag: " in err and "rl_place_plate_by_hand.json" in err and "choose another --tag" in err, err
  os.remove(f"{stem}.json")  # a table with no record of its sources is not taken for the benchmark's either
  assert _run(argv + ["--tables"]) == 2 and "(no sources recorded)" in capsys.readouterr().err
  assert open(f"{stem}.md").read() == before[1]
  # on another device the same --tag names the same tables: --tables has nothing there to build them from, a
  # call that would run steps is refused before any runs; another --tag is a benchmark of its own
  def on_cpu(*extra, runner=lambda step, env: pytest.fail(f"{step.name} ran")):
    return three.main(argv + list(extra), slug="cpu", runner=runner)
  assert on_cpu("--tables") == 0 and "tables: none yet" in capsys.readouterr().out
  assert on_cpu() == 2 and "choose another --tag" in capsys.readouterr().err
  assert open(f"{stem}.md").read() == before[1]
  assert on_cpu("--tag", "cpu_run", runner=_stand_in([])) == 0


def test_the_driver_keeps_jax_off_the_gpu(tmp_path):
  """The driver runs as a script with JAX already imported (by mjx_damage): setting JAX_PLATFORMS then is too
  late, so it pins JAX's config to the CPU; without that, on a GPU machine it took 75 % of the GPU's memory
  from the steps."""
  code = ("import runpy, sys, jax\n"
          "sys.argv = ['three_trainers.py', '--task', 'shelve_item', '--plan', '--results-dir', sys.argv[1]]\n"
          "try:\n  runpy.run_path(%r, run_name='__main__')\n"
          "except SystemExit as e:\n  assert e.code == 0, e.code\n"
          "print('platforms', jax.config.jax_platforms)\n") % os.path.join(BENCHMARKS, "three_trainers.py")
  env = {k: v for k, v in os.environ.items() if k != "JAX_PLATFORMS"}
  out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], env=env, capture_output=True, text=True)
  assert out.returncode == 0, out.stderr
  assert out.stdout.strip().splitlines()[-1] == "platforms cpu"


@pytest.mark.slow
def test_a_tiny_benchmark_for_real(tmp_path, capsys):
  """Every trainer's own script, tiny sizes (learns nothing; ~15 min on 2 cores): six results files, the tables
  with six groups, and a second call that finds everything done."""
  argv = ["--seeds", "0", "--tag", "tiny"] + _dirs(tmp_path) + [
      "--ours-args", "--num-envs 16 --budget-seconds 10 --eval-episodes 16 --eval-envs 16",
      "--brax-args", "--num-envs 16 --batch-size 16 --num-minibatches 4 --num-timesteps 2000 --num-evals 2 "
                     "--eval-episodes 16 --curve-episodes 0",
      "--paper-args", "--num-envs 8 --unroll-length 16 --paper-timesteps 1024 --eval-episodes 16 --eval-envs 16"]
  assert three.main(argv) == 0
  assert "steps left: none" in capsys.readouterr().out
  table = json.load(open(tmp_path / "r" / "trainer_table_place_plate_tiny_mode.json"))
  assert len(table["sources"]) == 6 and sum(len(g["runs"]) for g in table["groups"]) == 6
  assert {(g["trainer"].split(" (")[0], g["reward"]) for g in table["groups"]} == {
      (t, r) for t in ("ours", "Brax PPO", "paper's PPO settings") for r in ("task reward only", "damage penalty, w = 2")}
  assert three.main(argv) == 0 and "6 steps (6 done)" in capsys.readouterr().out

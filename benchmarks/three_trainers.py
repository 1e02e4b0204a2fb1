"""One task under three trainers, task reward only and w = 2, the same seeds, one table: issue 24's benchmark.

The trainers:

* **ours** — ``rl_multiseed.py`` (``train.ppo``; all seeds of a reward in one program, or one program per seed
  where the recipe says so);
* **Brax's PPO** — ``rl_brax_ppo.py``: brax 0.14.2's own ``ppo.train`` with MuJoCo Playground's published
  PandaPickCube recipe (``mujoco_playground/config/manipulation_params.py``), one run per seed and weight;
* **the paper's PPO settings** — ``rl_multiseed.py --methods paper_task_only|paper`` (``train/config.py``'s
  ``paper`` preset: 512×2 tanh actor and critic, log-std −0.5 arm / −1.5 gripper, lr 1e-3 annealed, 512-step
  rollouts, 10 epochs × 8 minibatches, clip 0.2, target KL 0.01, …), batched over environments.

Each run is one step: the trainer's own script, called as a subprocess with the task's recipe (``RECIPES``: the
flags of the committed runs behind the README's "RL at a glance" rows), then ``trainer_table.py`` builds the
table (``trainer_table_<task>_<tag>_{mode,sample}``: every run, mean (min–max) over seeds, the runs meeting the
bars, the command of every run) from every step's results so far.

A step whose results file exists is done and skipped: the benchmark spreads over as many calls as it needs
(a time-limited GPU machine: ``--stop-after``), and nothing written is ever replaced. The paper's runs, longer
than a call, live in ``--work-dir`` and continue (``--resume``) until their env steps are done; a machine that
does not keep that folder between calls needs it brought along (the checkpoint, 47 MB for the paper's 3 seeds,
22 MB as ``tar | xz -1``, holds the whole training state and names no path); without it the step stops short,
is tabled as it stopped, and no call starts it over. The tables are rebuilt at the end of every call. The driver's flags, and every step's (by its own script's parser), are
checked before any step starts.

Usage (one H100 or H200; ``--plan`` prints every step, its status and its command, and runs nothing)::

    python benchmarks/three_trainers.py --task place_plate --seeds 0,1,2 --stop-after 560 --tag h100   # call 1, 2, …

Its results copied back to another machine, ``--device nvidia_h100`` (the slug in their names) with ``--plan``
or ``--tables`` shows their status or rebuilds the tables there, running nothing.

Two GPUs: two drivers, each with its own ``--parts`` (step names or their prefixes: ``ours``, ``brax_w2``,
``paper_task_only``) and ``CUDA_VISIBLE_DEVICES``. A CPU check of the plumbing (learns nothing)::

    python benchmarks/three_trainers.py --task place_plate --seeds 0 --tag cpu_check --results-dir /tmp/r \\
        --work-dir /tmp/w --ours-args '--num-envs 16 --budget-seconds 20 --eval-episodes 16' \\
        --brax-args '--num-envs 16 --batch-size 16 --num-minibatches 4 --num-timesteps 20000 --num-evals 2
                     --eval-episodes 16 --curve-episodes 0' \\
        --paper-args '--num-envs 8 --unroll-length 16 --paper-timesteps 2048 --eval-episodes 16'
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from mjx_damage import io, outputs  # noqa: E402  (first: the package's JAX settings before JAX is imported)

import jax  # noqa: E402

HERE = os.path.join(ROOT, "benchmarks")
RESULTS = os.path.join(HERE, "results")
TRAINERS = ("ours", "brax", "paper")
# Seconds a step takes beyond its training budget, by trainer: starting the script, the final evaluation on
# 1024 episodes by two actions, writing; --stop-after counts them. Measured by this driver on an H200 ("== step:
# ... after N s"): Shelve Item ours 35-60 s over a 300 s budget, Brax's 127 s over 400 s; Place Plate ours 37-63 s,
# Brax's 72-131 s over 300 s.
OVERHEAD_S = {"ours": 75.0, "brax": 150.0, "paper": 90.0}
# A paper run's later calls (--resume) take less beyond their budget: 47-51 s over 400-440 s on an H200, against
# 74 s for its first call over 470 s (Place Plate at w = 2, 2026-12-02).
RESUMED_OVERHEAD_S = 60.0


@dataclass(frozen=True)
class Recipe:
  """The flags of one task's committed runs, by trainer and reward (``rl_multiseed.py`` / ``rl_brax_ppo.py``).

  ``ours`` / ``paper``: method -> (flags, seconds of training per call); ``brax``: damage weight -> (flags,
  seconds). ``{w0_policy}`` in a Brax flag stands for that seed's exported w = 0 policy (the w = 2 run starts
  from it, and waits for it). ``paper`` empty: the paper's settings are not run on this task by default.
  """
  settings: tuple[str, ...]  # task settings for every trainer (--task-settings / --eval-task-settings)
  ours: dict
  brax: dict
  paper: dict = field(default_factory=dict)
  ours_seeds_apart: bool = False  # ours: one program per seed (each seed's own clock), as the committed runs
  where: str = ""  # where the committed runs of this recipe are described


_OURS_PP = ("--init-log-std=-0.5,-1.5", "--cost-critic", "--policy-std", "parameter", "--eval-actions", "mode,sample",
            "--export-policy")
_BRAX_PP = ("--num-timesteps", "20000000", "--num-evals", "9", "--init-log-std=-0.5,-1.5", "--eval-actions",
            "mode,sample", "--curve-episodes", "256", "--export-policy")
_PAPER = ("--paper-timesteps", "25559040", "--eval-actions", "sample,mode")
_SHELVE = ("--task-settings", '{"start":"route","cost":"health_lost"}', "--eval-task-settings", '{"start":"in_front"}')
_OURS_SI = ("--init-log-std=-0.5,-1.5", "--eval-actions", "mode,sample", "--export-policy", "--redraw-starts-steps",
            "327680", "--max-grad-norm", "none", "--obs-clip", "10", "--policy-std", "parameter")
_BRAX_SI = ("--num-timesteps", "30000000", "--num-evals", "16", "--curve-episodes", "128", "--init-log-std=-0.5,-1.5",
            "--eval-actions", "mode,sample", "--export-policy", "--max-grad-norm", "1")
_EGG = ("--task-settings", '{"start": "pregrasp", "carry_reward": "held"}')
_BRAX_EGG = ("--num-timesteps", "60000000", "--num-evals", "16", "--init-log-std=-0.5,0", "--eval-actions",
             "mode,sample", "--max-grad-norm", "1", "--obs-clip", "10", "--export-policy")

RECIPES = {
    # box counter (the task's RL setting); ours with the std a parameter; README "Place Plate, three trainers"
    "place_plate": Recipe(
        settings=(), ours={"task_only": (_OURS_PP, 300), "penalty": (_OURS_PP, 300)},
        brax={0: (_BRAX_PP, 300), 2: (_BRAX_PP, 300)},
        paper={"paper_task_only": (_PAPER, 470), "paper": (_PAPER, 470)},
        where="README, 'Place Plate, three trainers, on the box counter'; docs/safe_rl.md"),
    # training starts along the careful route, scored from the default start; docs/rl_task_design.md
    "shelve_item": Recipe(
        settings=_SHELVE, ours={"task_only": (_OURS_SI, 300), "penalty": (_OURS_SI, 480)}, ours_seeds_apart=True,
        brax={0: (_BRAX_SI, 400), 2: (_BRAX_SI, 400)},
        where="docs/rl_task_design.md, 'The std a parameter on Shelve Item' and 'Shelve Item route starts'"),
    # from scratch (pre-grasp start, held-carry reward); w = 2 after a task-only warm-up: ours within one run,
    # Brax's from its own w = 0 run of the same seed; docs/rl_task_design.md, "Pick Egg from scratch"
    "pick_egg": Recipe(
        settings=_EGG,
        ours={"task_only": (("--init-log-std=-0.5,0", "--cost-critic", "--eval-actions", "mode,sample", "--obs-clip",
                             "10", "--export-policy"), 400),
              "penalty": (("--init-log-std=-0.5,0", "--eval-actions", "mode,sample", "--damage-warmup-steps", "22e6",
                           "--damage-ramp-steps", "4e6", "--obs-clip", "10", "--export-policy"), 460)},
        brax={0: (_BRAX_EGG, 430), 2: (_BRAX_EGG + ("--init-from", "{w0_policy}"), 430)},
        where="docs/rl_task_design.md, 'Pick Egg from scratch: the warm-up again, and Brax's PPO with both guards'"),
}


@dataclass
class Step:
  """One training run of the benchmark: ``argv`` of ``script`` (in benchmarks/), its results file, its budget."""
  name: str
  trainer: str
  script: str
  argv: list
  results: str  # the JSON the run writes
  budget_s: float
  seeds: list
  work: str | None = None  # the paper's runs: the folder they continue from
  waits_for: str | None = None  # a file another step writes first (Brax's w = 2 from its own w = 0 policy)
  status: str = "to run"


def _seeds(text: str) -> list[int]:
  try:
    seeds = [int(s) for s in text.split(",") if s.strip()]
  except ValueError:
    raise ValueError(f"seeds: comma-separated whole numbers >= 0, got {text!r}") from None
  if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
    raise ValueError(f"seeds: distinct whole numbers >= 0, got {text!r}")
  return seeds


def _flag_value(flags, name: str):
  """The last value of ``name`` in ``flags`` (``--name V`` or ``--name=V``), or None."""
  value = None
  for i, f in enumerate(flags):
    if f == name and i + 1 < len(flags):
      value = flags[i + 1]
    elif f.startswith(name + "="):
      value = f.split("=", 1)[1]
  return value


def _at(path: str) -> str:
  """A step's path (relative to the repository's root, or absolute) as this process finds it."""
  return os.path.join(ROOT, path)


def _rel(path: str) -> str:
  """``path`` as the steps see it (they run in the repository's root): relative there when inside it."""
  path = os.path.abspath(path)
  return os.path.relpath(path, ROOT) if path == ROOT or path.startswith(ROOT + os.sep) else path


# flags the driver sets itself: an --*-args giving one of them would make the step write where the driver
# does not look, or train what its name does not say
_DRIVER_FLAGS = {"--task", "--seeds", "--tag", "--results-dir", "--methods", "--work-dir", "--resume",
                 "--damage-weights", "--out", "--out-dir", "--combine", "--merge", "--task-settings",
                 "--eval-task-settings", "--init-from", "--init-seed"}


def _extra(text: str | None, field_name: str) -> list[str]:
  try:
    extra = shlex.split(text or "")
  except ValueError as e:
    raise ValueError(f"{field_name}: not a shell-quoted list of flags ({e})") from None
  clash = sorted({a.split("=", 1)[0] for a in extra} & _DRIVER_FLAGS)
  if clash:
    raise ValueError(f"{field_name}: {', '.join(clash)} are set by this script (--task, --seeds, --tag, "
                     "--results-dir, --work-dir and the recipe)")
  return extra


def _options(flags) -> list[list[str]]:
  """``flags`` cut into options: ``[--name, value]``, ``[--name=value]`` or ``[--switch]``."""
  out = []
  for f in flags:
    if f.startswith("--") or not out or len(out[-1]) > 1 or "=" in out[-1][0]:
      out.append([f])
    else:
      out[-1].append(f)
  return out


def _with(budget: float, flags, extra: list[str]) -> tuple[list[str], float]:
  """The recipe's budget and ``flags`` with ``extra`` over them (an option of ``extra`` replaces the recipe's of
  that name), and the budget that holds."""
  budget = float(_flag_value(extra, "--budget-seconds") or budget)
  given = {o[0].split("=", 1)[0] for o in _options(extra)}
  own = [o for o in _options(["--budget-seconds", f"{budget:g}", *flags]) if o[0].split("=", 1)[0] not in given]
  return [f for o in own for f in o] + list(extra), budget


def plan(args, slug: str) -> list[Step]:
  """Every step of the benchmark for ``args.task`` on the device ``slug`` (its results file names), in order."""
  r, task, tag, out = RECIPES[args.task], args.task, args.tag, _rel(args.results_dir)
  seeds = ",".join(map(str, args.seeds))
  steps = []
  if "ours" in args.trainers:
    for method, (flags, budget) in r.ours.items():
      groups = [[s] for s in args.seeds] if r.ours_seeds_apart else [list(args.seeds)]
      for group in groups:
        name = f"ours_{method}" + (f"_s{group[0]}" if r.ours_seeds_apart else "")
        flags_, budget_ = _with(budget, flags, args.ours_extra)
        argv = ["--task", task, *r.settings, "--methods", method, *flags_, "--seeds", ",".join(map(str, group)),
                "--tag", f"{tag}_{name}", "--results-dir", out]
        steps.append(Step(name, "ours", "rl_multiseed.py", argv,
                          os.path.join(out, f"rl_{task}_{slug}_{tag}_{name}.json"), budget_, group))
  if "brax" in args.trainers:
    for w, (flags, budget) in r.brax.items():
      for s in args.seeds:
        name = f"brax_w{w}_s{s}"
        stem = os.path.join(out, f"rl_brax_{task}_{slug}_{tag}_{name}")
        waits, own = None, tuple(flags)
        if "{w0_policy}" in own:
          waits = os.path.join(out, f"rl_brax_{task}_{slug}_{tag}_brax_w0_s{s}_w0_s{s}_policy.npz")
          own = tuple(waits if f == "{w0_policy}" else f for f in own) + ("--init-seed", str(s))
        flags_, budget_ = _with(budget, own, args.brax_extra)
        argv = ["--task", task, *r.settings, "--damage-weights", str(w), "--seeds", str(s), *flags_, "--out", stem]
        steps.append(Step(name, "brax", "rl_brax_ppo.py", argv, stem + ".json", budget_, [s], waits_for=waits))
  if "paper" in args.trainers:
    for method, (flags, budget) in r.paper.items():
      name = "paper_penalty" if method == "paper" else method  # a prefix of no other step: --parts picks it alone
      work = os.path.join(_rel(args.work_dir), f"{task}_{tag}_{name}")
      flags_, budget_ = _with(budget, flags, args.paper_extra)
      argv = ["--task", task, *r.settings, "--methods", method, *flags_, "--seeds", seeds, "--work-dir", work,
              "--tag", f"{tag}_{name}", "--results-dir", out]
      steps.append(Step(name, "paper", "rl_multiseed.py", argv,
                        os.path.join(out, f"rl_{task}_{slug}_{tag}_{name}.json"), budget_, list(args.seeds), work))
  return steps


def update_status(step: Step) -> Step:
  """``step.status``: done, partly done (a paper run to continue), stopped … its folder gone (a paper run that
  cannot continue: its tables are built, the step is not run again over it), waits (for another step's file) or
  to run.
  A results file of other seeds than the step's is refused (``ValueError``): choose another ``--tag``."""
  step.status = "to run"  # asked again during a call: a step that waited may run now
  if os.path.exists(_at(step.results)):
    doc = io.read_json(_at(step.results), "results")
    if step.trainer == "brax":
      have = sorted({r["seed"] for r in doc.get("rows", [])})
      weight = float(_flag_value(step.argv, "--damage-weights"))
      if not any(r["seed"] == step.seeds[0] and float(r["damage_weight"]) == weight for r in doc.get("rows", [])):
        raise ValueError(f"results: {step.results} holds seeds {have}, not the run of step {step.name}; choose "
                         "another --tag or --results-dir")
      step.status = "done"
      return step
    rows = doc.get("rows", [])
    if not rows or sorted(rows[0].get("seeds", [])) != sorted(step.seeds):
      raise ValueError(f"results: {step.results} holds seeds {rows[0].get('seeds') if rows else []}, not "
                       f"{step.seeds} of step {step.name}; choose another --tag or --results-dir")
    if step.trainer != "paper" or not rows[0].get("stopped_by_time_limit"):
      step.status = "done"
      return step
    if not _holds_run(step):  # started over, the run would replace the file of its earlier calls
      step.status = f"stopped at {rows[0].get('env_steps_per_seed')} env steps per seed, its folder gone"
      return step
  if step.work is not None and _holds_run(step):
    step.status = "partly done"
    if "--resume" not in step.argv:
      step.argv.append("--resume")
  elif step.waits_for is not None and not os.path.exists(_at(step.waits_for)):
    step.status = f"waits for {os.path.basename(step.waits_for)}"
  return step


def _holds_run(step: Step) -> bool:
  """A paper run to continue: its method's folder in its --work-dir holds something (as rl_multiseed checks)."""
  return outputs.exists(_at(os.path.join(step.work, _flag_value(step.argv, "--methods"))))


def command(step: Step) -> str:
  return " ".join(shlex.quote(a) for a in ["python", f"benchmarks/{step.script}", *step.argv])


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--task", default="place_plate", help=f"one of {', '.join(RECIPES)} (its recipe: RECIPES)")
  p.add_argument("--seeds", default="0,1,2")
  p.add_argument("--trainers", default=None,
                 help=f"comma-separated of {','.join(TRAINERS)} (default: the recipe's; the paper's settings on "
                      "place_plate only)")
  p.add_argument("--parts", default=None,
                 help="run only these steps: comma-separated names or their prefixes (ours, brax_w2, brax_w0_s1, "
                      "paper); default every step (--plan lists them)")
  p.add_argument("--tag", default="three_trainers", help="names every results file of the benchmark")
  p.add_argument("--results-dir", default=RESULTS)
  p.add_argument("--work-dir", default=os.path.join(ROOT, "runs", "three_trainers"),
                 help="the paper's runs, continued over calls")
  p.add_argument("--stop-after", type=float, default=None, metavar="SECONDS",
                 help="start no step that would end later than this many seconds after the start (its budget "
                      f"+ {', '.join(f'{v:.0f} s ({k})' for k, v in OVERHEAD_S.items())}, {RESUMED_OVERHEAD_S:.0f} s for a paper "
                      "run continued); for a time-limited machine")
  p.add_argument("--plan", action="store_true", help="print every step, its status and command; run nothing")
  p.add_argument("--tables", action="store_true",
                 help="rebuild the tables from the results there are; run nothing")
  p.add_argument("--device", default=None, metavar="SLUG",
                 help="the device whose results to read (their file names: nvidia_h100, nvidia_h200, cpu, ...), "
                      "with --plan or --tables; default the device the steps would run on")
  for t in TRAINERS:
    p.add_argument(f"--{t}-args", default=None, metavar="FLAGS",
                   help=f"flags of every {t} step's command over the recipe's (one replaces the recipe's of its name); "
                        f"one flag alone: --{t}-args=--flag=V")
  a = p.parse_args(argv)
  try:
    if a.task not in RECIPES:
      raise ValueError(f"task: one of {', '.join(RECIPES)} (the tasks with a recipe), got {a.task!r}")
    a.seeds = _seeds(a.seeds)
    trainers = [t for t in (a.trainers or "").split(",") if t.strip()] if a.trainers else (
        [t for t in TRAINERS if t != "paper" or RECIPES[a.task].paper])
    bad = [t for t in trainers if t not in TRAINERS]
    if bad or not trainers:
      raise ValueError(f"trainers: comma-separated of {','.join(TRAINERS)}, got {a.trainers!r}")
    if "paper" in trainers and not RECIPES[a.task].paper:
      raise ValueError(f"trainers: the paper's settings have no recipe for {a.task} (place_plate only)")
    a.trainers = trainers
    a.parts = None if a.parts is None else [x.strip() for x in a.parts.split(",") if x.strip()]
    if a.parts is not None and not a.parts:
      raise ValueError("parts: give at least one step name or prefix")
    if a.stop_after is not None and not a.stop_after > 0:
      raise ValueError(f"stop_after: seconds > 0, got {a.stop_after}")
    if not a.tag or any(not (c.isalnum() or c in "_-") for c in a.tag):
      raise ValueError(f"tag: letters, digits, '_' or '-', got {a.tag!r}")
    if a.device is not None:
      if not a.device or any(not (c.isalnum() or c == "_") for c in a.device):
        raise ValueError(f"device: a results-file slug of letters, digits and '_' (nvidia_h100), got {a.device!r}")
      if not (a.plan or a.tables):
        raise ValueError("device: only with --plan or --tables (steps run on this machine's device and name "
                         "their files after it)")
    a.ours_extra = _extra(a.ours_args, "ours_args")
    a.brax_extra = _extra(a.brax_args, "brax_args")
    a.paper_extra = _extra(a.paper_args, "paper_args")
  except ValueError as e:
    p.error(str(e))
  return a


def select(steps: list[Step], parts) -> list[Step]:
  """The steps named by ``parts`` (names or prefixes); ``ValueError`` naming ``parts`` for one that names none."""
  if parts is None:
    return steps
  for x in parts:
    if not any(s.name.startswith(x) for s in steps):
      raise ValueError(f"parts: {x!r} names no step; the steps: {', '.join(s.name for s in steps)}")
  return [s for s in steps if any(s.name.startswith(x) for x in parts)]


def check_step(step: Step) -> None:
  """The step's own script parses its flags (the recipe's, the --*-args, the task settings): ``ValueError``
  naming the step before anything is trained. Runs in this process, on the CPU (``keep_jax_on_cpu``)."""
  module = _script(step.script[:-3])
  check = module.parse if step.trainer != "brax" else module.parse_args
  argv = [a for a in step.argv if a != "--resume"] if step.work else step.argv
  if step.work:  # the paper's work dir may hold the run a --resume continues; parse without both
    i = argv.index("--work-dir")
    argv = argv[:i] + argv[i + 2:]
  try:
    check(argv)
  except SystemExit as e:  # argparse has printed its line
    raise ValueError(f"step {step.name}: its flags are refused by benchmarks/{step.script} (above)") from None
  except ValueError as e:
    raise ValueError(f"step {step.name}: {e}") from None


def device_slug(env: dict) -> str:
  """The results-file slug of the device the steps will run on (``mjx_damage.runtime.device_info``), from a
  child process with the steps' environment: this one keeps JAX on the CPU, away from the GPU's memory."""
  out = subprocess.run([sys.executable, "-c", "from mjx_damage import runtime; print(runtime.device_info()[0])"],
                       env=env, cwd=ROOT, capture_output=True, text=True)
  if out.returncode != 0:
    raise RuntimeError(f"could not start JAX to name the device:\n{out.stderr.strip()}")
  return out.stdout.strip().splitlines()[-1]


def run_step(step: Step, env: dict) -> int:
  return subprocess.run([sys.executable, os.path.join(HERE, step.script), *step.argv], env=env, cwd=ROOT).returncode


def _script(name: str):
  """``benchmarks/<name>.py`` as a module (its sibling imports resolve as when it runs as a script)."""
  if HERE not in sys.path:
    sys.path.append(HERE)
  return importlib.import_module(name)


def table_stem(args, action: str) -> str:
  """Where the benchmark's table by ``action`` goes (without .md / .json), as the steps see it."""
  return os.path.join(_rel(args.results_dir), f"trainer_table_{args.task}_{args.tag}_{action}")


def check_tables(args, steps: list[Step]) -> None:
  """Refuse (``ValueError`` naming ``tag``) a table already at the benchmark's table names that was built from
  other results than its steps': the benchmark rebuilds its own tables after every call, and must not replace
  a table someone else made under that name."""
  own = {os.path.basename(s.results) for s in steps}
  for action in ("mode", "sample"):
    stem = _at(table_stem(args, action))
    if not (os.path.exists(stem + ".json") or os.path.exists(stem + ".md")):
      continue
    doc = io.read_json(stem + ".json", "tables") if os.path.exists(stem + ".json") else {}
    sources = doc.get("sources") if isinstance(doc, dict) else None
    other = sorted(set(sources) - own) if isinstance(sources, list) and sources else ["(no sources recorded)"]
    if other:
      raise ValueError(f"tag: {_rel(stem)}.md / .json exists and was built from other results than this "
                       f"benchmark's ({', '.join(other[:3])}{', …' if len(other) > 3 else ''}); the benchmark "
                       "would replace it: choose another --tag or --results-dir")


def build_tables(args, steps: list[Step]) -> list[str]:
  """``trainer_table.py`` by mode and by sample over every results file of ``steps`` there is (in this process:
  it reads JSON, no JAX); their stems."""
  sources = sorted({s.results for s in steps if os.path.exists(_at(s.results))})
  stems = []
  if not sources:
    return stems
  check_tables(args, steps)  # again: a table may have appeared while the steps ran
  table = _script("trainer_table")
  with contextlib.chdir(ROOT):  # the table records its command with the paths the steps wrote
    for action in ("mode", "sample"):
      stem = table_stem(args, action)
      table.main(["--task", args.task, "--action", action, "--sources", *sources, "--out", stem])
      stems.append(stem)
  return stems


def main(argv=None, *, child_env: dict | None = None, slug: str | None = None, runner=run_step) -> int:
  """``child_env``: the steps' environment (default this process's); ``slug``: the device's (default: asked
  of JAX in a child); ``runner(step, env) -> exit status``: how a step runs (tests pass their own)."""
  child_env = dict(os.environ) if child_env is None else child_env
  args = parse(argv)
  t0 = time.monotonic()
  checked = set()  # steps whose flags their script's parser has taken
  try:
    slug = args.device or slug or device_slug(child_env)
    steps = [update_status(s) for s in plan(args, slug)]
    chosen = select(steps, args.parts)
    if not args.plan and (not args.tables or any(os.path.exists(_at(s.results)) for s in steps)):
      check_tables(args, steps)  # before any step runs: the call would end by replacing the table
    for s in chosen if not (args.plan or args.tables) else []:
      if s.status.startswith("stopped"):  # --plan and --tables show it; a call to run it must not replace it
        raise ValueError(f"results: {s.results} is a run {s.status.replace(', its folder gone', '')} whose "
                         f"folder {s.work} is gone (or give the --work-dir it ran in); move the file away to "
                         "start the step over, or leave it out of --parts")
      if s.status in ("to run", "partly done"):
        check_step(s)
        checked.add(s.name)
  except ValueError as e:
    print(f"three_trainers.py: error: {e}", file=sys.stderr)
    return 2
  print(f"{args.task}, seeds {args.seeds}, device {slug}: {len(steps)} steps "
        f"({sum(s.status == 'done' for s in steps)} done); the recipe's runs: {RECIPES[args.task].where}")
  for s in steps:
    mark = "" if s in chosen else " (not in --parts)"
    print(f"  {s.name}: {s.status}{mark}\n    {command(s)}")
  if args.plan:
    return 0
  failed = []
  try:
    for s in chosen if not args.tables else []:
      update_status(s)
      if s.status == "done":
        continue
      if s.status.startswith("waits"):
        print(f"{s.name}: {s.status}; not run", flush=True)
        continue
      needs = s.budget_s + (RESUMED_OVERHEAD_S if s.status == "partly done" else OVERHEAD_S[s.trainer])
      if args.stop_after is not None and time.monotonic() - t0 + needs > args.stop_after:
        print(f"{s.name}: not started, it needs about {needs:.0f} s and "
              f"{args.stop_after - (time.monotonic() - t0):.0f} s of --stop-after are left", flush=True)
        continue
      if s.name not in checked:  # a step that waited: its input exists now
        check_step(s)
      start = time.monotonic()
      print(f"== {s.name} ({start - t0:.0f} s): {command(s)}", flush=True)
      rc = runner(s, child_env)
      print(f"== {s.name}: exit status {rc} after {time.monotonic() - start:.0f} s "
            f"(budget {s.budget_s:g} s)", flush=True)
      if rc != 0:
        print(f"{s.name}: exit status {rc}; the next call runs it again", file=sys.stderr, flush=True)
        failed.append(s.name)
  except KeyboardInterrupt:
    print("three_trainers.py: interrupted; the steps done so far are kept, the next call goes on", file=sys.stderr)
    return 130
  except ValueError as e:
    print(f"three_trainers.py: error: {e}", file=sys.stderr)
    return 2
  try:
    stems = build_tables(args, steps)
  except ValueError as e:
    print(f"three_trainers.py: error: {e}; the steps' results are kept", file=sys.stderr)
    return 2
  now = [update_status(s) for s in steps]
  left = [s.name for s in now if s.status != "done" and not s.status.startswith("stopped")]
  # a stopped step is tabled as it stopped and no call runs it again: not left for the next call
  stopped = [s.name for s in now if s.status.startswith("stopped")]
  print(f"tables: {', '.join(x + '.md' for x in stems) or 'none yet (no step done)'}; "
        f"steps left: {', '.join(left) or 'none'}"
        + (f"; stopped short, their folders gone (tabled as they stopped): {', '.join(stopped)}" if stopped else ""))
  return 1 if failed else 0


def keep_jax_on_cpu() -> None:
  """Pin this process's JAX to the CPU: it only parses the steps' flags (``check_step``) and reads JSON, and a
  GPU backend here would take 75 % of the GPU's memory from the steps, its children. The environment variable
  ``JAX_PLATFORMS`` is read when JAX is imported (``mjx_damage`` imports it above), so the config is set
  instead; it holds as long as no backend has started."""
  jax.config.update("jax_platforms", "cpu")


if __name__ == "__main__":
  steps_env = dict(os.environ)  # the steps' own: the GPU where there is one
  keep_jax_on_cpu()
  sys.exit(main(child_env=steps_env))

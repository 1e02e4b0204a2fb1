"""Both rewards of a contrast in one program: seconds per training iteration of S runs against 2S runs.

``damage_weight`` may be one number per seed (train.config), so task reward alone (w = 0) and the damage
penalty can train as 2S runs of one compiled program instead of two programs of S runs each. Whether that
saves device time depends on whether S runs already fill the device. This script trains the same task and
preset twice for a few iterations: S runs at ``--damage-weight``, then 2S runs (the S seeds at w = 0 and S
more seeds at ``--damage-weight``), and reports each program's compile time and seconds per iteration (the
first iteration, which compiles, is not timed). The ratio of the two iteration times says what the second
reward costs: 2 means no gain over two programs (the device was full), 1 means it came free.

Writes ``benchmarks/results/contrast_one_program_<task>_<device>[_<tag>].{json,md}`` with the command (an
existing file is refused unless ``--overwrite``). Usage::

    # this 2-core CPU: the paper preset with 8 envs per seed and 32-step rollouts
    PYTHONPATH=. .venv/bin/python benchmarks/contrast_one_program.py --preset paper --num-envs 8 \\
        --unroll-length 32 --iterations 4
    # a GPU: the paper preset as the Place Plate runs use it (256 envs per seed, 512-step rollouts), then
    # the playground preset (2048 envs per seed): about 4 min each on one H200 with a warm compile cache
    python benchmarks/contrast_one_program.py --preset paper --iterations 5
    python benchmarks/contrast_one_program.py --preset playground --iterations 12 --tag playground

Each program ends with train()'s final evaluation of its runs (8 episodes each), which the timings leave out
but the wall clock does not. Each program's row is printed as soon as it is measured.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags and the jax compat shim before jax starts)

import provenance  # noqa: E402  (the sibling module: the results writer)
import train  # noqa: E402
from mjx_damage import outputs, runtime  # noqa: E402
from train.config import PRESETS, PPOConfig  # noqa: E402
from train.envs import resolve_task  # noqa: E402


def _ints(text: str) -> tuple[int, ...]:
  try:
    return tuple(int(s) for s in text.split(",") if s.strip())
  except ValueError:
    raise argparse.ArgumentTypeError(f"comma-separated integers, got {text!r}") from None


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--task", default="place_plate", help="a registered task or package.module:EnvClass")
  p.add_argument("--task-settings", default='{"counter": "box"}', metavar="JSON",
                 help="the task's keyword arguments (the Place Plate contrasts' box counter by default)")
  p.add_argument("--preset", default="paper", help=f"one of {', '.join(PRESETS)}")
  p.add_argument("--seeds", type=_ints, default=(0, 1, 2), help="the S seeds of each reward")
  p.add_argument("--damage-weight", type=float, default=2.0, help="w of the penalised runs")
  p.add_argument("--num-envs", type=int, default=None, help="envs per seed (default: the preset's)")
  p.add_argument("--unroll-length", type=int, default=None, help="rollout length (default: the preset's)")
  p.add_argument("--iterations", type=int, default=4, help="training iterations per program; the first compiles")
  p.add_argument("--tag", default="")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  p.add_argument("--overwrite", action="store_true", help="replace an existing results file")
  a = p.parse_args(argv)
  if not a.seeds or len(set(a.seeds)) != len(a.seeds) or min(a.seeds) < 0:
    raise ValueError(f"seeds: distinct integers >= 0, got {','.join(map(str, a.seeds))!r}")
  if a.iterations < 2:
    raise ValueError(f"iterations: at least 2 (the first compiles and is not timed), got {a.iterations}")
  try:
    a.task_kwargs = json.loads(a.task_settings)
  except json.JSONDecodeError as e:
    raise ValueError(f"task_settings: not JSON ({e})") from None
  if not isinstance(a.task_kwargs, dict):
    raise ValueError(f"task_settings: a JSON object, got {a.task_settings!r}")
  resolve_task(a.task, a.task_kwargs)  # an unknown task or keyword: "task: …" before anything compiles
  a.overrides = {k: v for k, v in (("num_envs", a.num_envs), ("unroll_length", a.unroll_length)) if v is not None}
  # the two programs' configs, every field checked before anything compiles
  a.configs = [PPOConfig.preset(a.preset, seeds=seeds, damage_weight=weights, **a.overrides).validate()
               for seeds, weights in layouts(a.seeds, a.damage_weight)]
  return a


def layouts(seeds, w) -> list[tuple[tuple[int, ...], tuple[float, ...]]]:
  """(seeds, weights) of the two programs: S runs at w; the S seeds at w = 0 beside S more at w."""
  more = tuple(max(seeds) + 1 + i for i in range(len(seeds)))  # runs are named by their seed: new ones
  return [(tuple(seeds), (w,) * len(seeds)), (tuple(seeds) + more, (0.0,) * len(seeds) + (w,) * len(seeds))]


def measure(a, cfg: PPOConfig) -> dict:
  """Train ``a.iterations`` iterations of the program of ``cfg``; its compile and per-iteration seconds."""
  seeds, weights = cfg.seeds, cfg.damage_weights
  res = train.train(a.task, task_kwargs=a.task_kwargs, preset=a.preset, seeds=seeds, damage_weight=weights,
                    num_timesteps=a.iterations * cfg.steps_per_iteration, num_eval_envs=8, progress=False,
                    plot=False, **a.overrides)
  timed = res.iterations - 1
  per_iter = res.timings["iterations"] / timed
  return {"runs": len(seeds), "seeds": list(seeds), "damage_weights": list(weights),
          "env_steps_per_iteration_all_runs": cfg.steps_per_iteration * len(seeds),
          "compile_s": round(res.timings["compile"], 2), "timed_iterations": timed,
          "s_per_iteration": round(per_iter, 4),
          "env_steps_per_s_all_runs": round(cfg.steps_per_iteration * len(seeds) / per_iter, 1)}


def render_md(res: dict) -> str:
  one, two = res["rows"]
  lines = [f"# Both rewards of a contrast in one program: {res['task']}, {res['device']}", "",
           f"Preset `{res['preset']}` ({res['num_envs']} envs per seed, {res['unroll_length']}-step rollouts), "
           f"task settings `{json.dumps(res['task_kwargs'])}`; {res['iterations']} iterations per program, the "
           "first (compile) not timed. Date " + res["date"] + f", git {res['git']}, jax {res['jax']}.", "",
           "    " + res["command"], "",
           "| program | runs | weights | env steps per iteration (all runs) | compile (s) | s per iteration | env steps/s (all runs) |",
           "|---|---|---|---|---|---|---|"]
  for name, r in (("one reward", one), ("both rewards", two)):
    lines.append(f"| {name} | {r['runs']} | {', '.join(f'{w:g}' for w in r['damage_weights'])} | "
                 f"{r['env_steps_per_iteration_all_runs']:,} | {r['compile_s']:.1f} | {r['s_per_iteration']:.3f} | "
                 f"{r['env_steps_per_s_all_runs']:,.0f} |")
  lines += ["", f"Time per iteration, both rewards over one: **{res['ratio']:.2f}** (2: no gain over two programs; "
            "1: the second reward free)."]
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  try:
    a = parse(argv)
    slug, device = runtime.device_info()
    task_slug = a.task.rsplit(":", 1)[-1].lower()
    stem = os.path.join(a.results_dir, f"contrast_one_program_{task_slug}_{slug}" + (f"_{a.tag}" if a.tag else ""))
    outputs.check_new([stem + ".json", stem + ".md"], "--tag", overwrite=a.overwrite)
  except ValueError as e:
    print(f"contrast_one_program: {e}", file=sys.stderr)
    return 2
  rows = []
  for cfg in a.configs:  # each program's row printed as it comes, so a run cut short still tells the first
    rows.append(measure(a, cfg))
    print(json.dumps(rows[-1]), flush=True)
  cfg = a.configs[0]
  res = {"task": a.task, "task_kwargs": a.task_kwargs, "preset": a.preset, "device": device,
         "num_envs": cfg.num_envs, "unroll_length": cfg.unroll_length, "iterations": a.iterations, "rows": rows,
         "ratio": round(rows[1]["s_per_iteration"] / rows[0]["s_per_iteration"], 3)}
  provenance.save_results(res, "contrast_one_program", argv, stem, render_md)
  print(render_md(res))
  return 0


if __name__ == "__main__":
  sys.exit(main())

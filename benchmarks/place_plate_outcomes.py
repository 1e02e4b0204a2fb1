"""How trained Place Plate policies end their episodes, by action: placed, let go above the counter, or never let go.

A Gaussian policy is trained on its samples but usually scored by its mode (tanh of the mean). Where the two
disagree, the way the episodes end says why: a mode that never opens the fingers wide enough to let the plate go
(it hovers with the plate in hand: nothing broken, nothing completed) fails differently from one that lets go
too high (the plate falls and breaks). For each checkpoint policy ``FILE#SEED`` of ``--policies`` and each
action of ``--actions``, ``--episodes`` episodes from the same resets (key ``--seed``) are stepped, and per
episode this script finds:

- *let go*: the first step at which the fingers' inner gap exceeds the plate's width by more than
  ``--clearance`` (the pads no longer touch it) with the plate still above its resting height;
- *release height*: the plate's centre above its resting height at that step (cm);
- *placed*: the task's success at any step (the evaluator's completion);
- *outcome*: "placed", "let go, not placed" (the fingers opened past the plate at some height), or "never let
  go" (they never did: the hand kept the plate to the end);
- *touchdown speed*: the plate's mean downward speed over the control step in which it reaches the counter;
- the plate's final health and the lowest height the hand brought it to while holding it.

Besides the policy's own actions (``mode``, ``sample``, ``mean``), ``--actions`` takes two mixtures that say
which dimension's noise a mode policy lacks: ``arm_noise`` (the sampled action on the arm's dimensions, the mode
on the gripper) and ``gripper_noise`` (the reverse). With ``--spread``, for ``mode`` it also reports the spread
of the sampled action before the tanh (the std of the arctanh of ``SPREAD_DRAWS`` draws, per dimension: the
Gaussian's scale) at the first and the last step of each mode episode: a policy whose std is an output of its
network can make its noise smaller or larger where its mean stalls; one whose std is a parameter cannot.

Writes ``benchmarks/results/place_plate_outcomes[_<tag>].{json,md}`` with the command. Each (action, network
shape) compiles once; the weights are data, so every checkpoint of one shape reuses the program.

Usage::

    PYTHONPATH=. .venv/bin/python benchmarks/place_plate_outcomes.py --episodes 64 --actions mode,sample \\
        --policies benchmarks/results/rl_place_plate_nvidia_h200_box_3seeds_300s_b_penalty_policy.npz#2
"""

from __future__ import annotations

import argparse
import os
import sys
import types

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import mjx_damage  # noqa: E402,F401  (XLA:CPU flags and the jax compat shim before jax starts)
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import provenance  # noqa: E402  (the sibling module: the results writer)
from apps import resolve as R  # noqa: E402
from mjx_damage import warp_step  # noqa: E402
from tasks.place_plate import PLATE_REST_Z  # noqa: E402  (the plate's centre height at rest, m)
from train import evaluate as E  # noqa: E402
from train import networks as N  # noqa: E402

TASK = "place_plate"
OUTCOMES = ("placed", "let go, not placed", "never let go")
NOISE_ACTIONS = ("arm_noise", "gripper_noise")  # the sampled action on these dimensions, the mode on the rest
ACTIONS = N.POLICY_ACTIONS + NOISE_ACTIONS
SPREAD_DRAWS = 256  # sampled actions per state for the spread at an episode's first and last step


def parse(argv=None):
  p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
  p.add_argument("--policies", required=True,
                 help="comma-separated checkpoint files of place_plate policies, each FILE#SEED (FILE alone: its first seed)")
  p.add_argument("--actions", default="mode,sample",
                 help=f"comma-separated of {', '.join(ACTIONS)} (the last two: the sampled action on the arm's or "
                      "the gripper's dimensions only, the mode on the others)")
  p.add_argument("--episodes", type=int, default=64)
  p.add_argument("--seed", type=int, default=12345, help="episode key (resets and sampled actions)")
  p.add_argument("--clearance", type=float, default=0.005,
                 help="m: inner gap beyond the plate's width at which the fingers count as let go")
  p.add_argument("--spread", action="store_true",
                 help="with the mode: also the sampled action's scale before the tanh at each mode episode's first "
                      "and last step")
  p.add_argument("--task-arg", action="append", default=[], metavar="KEY=JSON",
                 help="task keyword over every policy's own settings")
  p.add_argument("--tag", default="")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  args = p.parse_args(argv)
  try:  # everything checked before a task is built or compiled
    args.specs = [s.strip() for s in args.policies.split(",") if s.strip()]
    if not args.specs:
      raise ValueError("policies: give at least one FILE#SEED")
    for s in args.specs:
      R.parse_policy_spec("checkpoint:" + s)
    args.action_list = [a.strip() for a in args.actions.split(",") if a.strip()]
    bad = [a for a in args.action_list if a not in ACTIONS]
    if bad or not args.action_list:
      raise ValueError(f"actions: {', '.join(bad) or '(none)'} not among {', '.join(ACTIONS)}")
    E.check_args(args.episodes, 1.0, 95.0, seed=args.seed)
    if not (np.isfinite(args.clearance) and 0.0 <= args.clearance < 0.05):
      raise ValueError(f"clearance: {args.clearance!r} must be in [0, 0.05) m")
    kwargs = {R.checkpoint_path("checkpoint:" + s): R.checkpoint_task_kwargs("checkpoint:" + s, TASK)
              for s in args.specs}
    if len({repr(sorted(k.items())) for k in kwargs.values()}) > 1:
      raise ValueError(f"policies: trained with different task settings ({kwargs}); trace one setting per call")
    args.overrides = R.task_overrides(TASK, next(iter(kwargs.values())), None, args.task_arg)
    args.env = R.make_task(TASK, **args.overrides)
  except ValueError as e:
    p.error(str(e))
  return args


def episodes_program(env, apply, steps: int):
  """``run(params, keys) -> (plate f32[B, T, 3] m, gap f32[B, T] m, success f32[B, T], health f32[B, N])``:
  B episodes of ``steps`` control steps (the evaluator's key split), the weights traced."""
  robot = env.robot  # the damage wrapper forwards the task's attributes

  def one(params, key):
    reset_key, act_key = jax.random.split(key)
    state = env.reset(reset_key)

    def body(carry, t):
      state, done = carry
      nxt = env.step(state, apply(params, state, jax.random.fold_in(act_key, t)))
      state = warp_step.freeze(done > 0, state, nxt)  # as train.evaluate: an ended episode keeps its final state
      d = state.pipeline_state
      row = (env.plate_pos(d), robot.gap(types.SimpleNamespace(qpos=d.qpos)), state.metrics["success"])
      return (state, jnp.maximum(done, nxt.done)), row

    (state, _), rows = jax.lax.scan(body, (state, jnp.zeros((), state.done.dtype)), jnp.arange(steps))
    return rows + (state.info["entity_health"],)

  return jax.jit(jax.vmap(one, in_axes=(None, 0)))


def noise_mixture(mode_apply, sample_apply, action: str):
  """``apply(params, state, key)``: the sampled action on the dimensions ``action`` names (``arm_noise``: every
  dimension but the last; ``gripper_noise``: the last), the mode on the others; the same key as ``sample``."""
  if action not in NOISE_ACTIONS:
    raise ValueError(f"action: {action!r} is not one of {', '.join(NOISE_ACTIONS)}")

  def apply(params, state, key):
    a = mode_apply(params, state, key)
    b = sample_apply(params, state, key)
    gripper = jnp.arange(a.shape[-1]) == a.shape[-1] - 1
    return jnp.where(gripper if action == "gripper_noise" else ~gripper, b, a)

  return apply


def spread_program(env, mode_apply, sample_apply, steps: int):
  """``run(params, keys) -> f32[B, 2, A]``: per episode of the mode policy, the std of ``SPREAD_DRAWS`` sampled
  actions at its first and its last control step, before the tanh (arctanh of each draw): the Gaussian's scale."""

  def spread(params, state, key):
    draws = jax.vmap(lambda k: sample_apply(params, state, k))(jax.random.split(key, SPREAD_DRAWS))
    # before the tanh: where the mean saturates it, the squashed draws' spread shrinks whatever the scale
    return jnp.std(jnp.arctanh(jnp.clip(draws, -1.0 + 1e-6, 1.0 - 1e-6)), axis=0)

  def one(params, key):
    reset_key, act_key = jax.random.split(key)
    state = env.reset(reset_key)
    first = spread(params, state, jax.random.fold_in(act_key, steps))  # keys apart from the steps' 0 … T − 2

    def body(state, t):
      return env.step(state, mode_apply(params, state, jax.random.fold_in(act_key, t))), None

    state, _ = jax.lax.scan(body, state, jnp.arange(steps - 1))
    return jnp.stack([first, spread(params, state, jax.random.fold_in(act_key, steps + 1))])

  return jax.jit(jax.vmap(one, in_axes=(None, 0)))


def classify(plate, gap, success, rest_z: float, width: float, clearance: float, dt: float) -> dict:
  """Per-episode outcome from a trace (numpy, time-major [T, B]; ``dt`` s per control step); see the module
  docstring. Touchdown speed: the plate's mean downward speed over the control step in which it first comes
  within 2 mm of its resting height (m/s; NaN if it never does)."""
  placed = success.max(0) > 0
  above = plate[..., 2] > rest_z + 0.002
  open_ = gap > width + clearance
  let_go = open_ & above
  released = let_go.any(0)
  n = np.arange(plate.shape[1])
  height = np.where(released, plate[let_go.argmax(0), n, 2] - rest_z, np.nan)
  held_low = np.where(~open_, plate[..., 2], np.inf).min(0) - rest_z
  # never let go: the fingers never opened past the plate (at any height), so the hand held it to the end
  outcome = np.where(placed, 0, np.where(open_.any(0), 1, 2))
  down = plate[..., 2] < rest_z + 0.002
  touched = down.any(0)
  k = down.argmax(0)
  z_before = plate[np.maximum(k - 1, 0), n, 2]
  speed = np.where(touched & (k > 0), (z_before - plate[k, n, 2]) / dt, np.nan)
  return {"outcome": outcome, "release_height_m": height, "held_low_m": held_low,
          "touchdown_speed_m_s": speed}


def summarise(c: dict, plate_health: np.ndarray) -> dict:
  out = c["outcome"]
  h = c["release_height_m"]
  frac = {name: float((out == i).mean()) for i, name in enumerate(OUTCOMES)}
  rel = np.isfinite(h)
  never = out == 2
  v = c["touchdown_speed_m_s"]
  tv = np.isfinite(v)
  return {"fractions": frac,
          "release_height_cm_median": float(np.median(h[rel]) * 100) if rel.any() else None,
          "release_height_cm_p90": float(np.percentile(h[rel], 90) * 100) if rel.any() else None,
          "never_let_go_held_at_cm_median": float(np.median(c["held_low_m"][never]) * 100) if never.any() else None,
          "touchdown_speed_m_s_median": float(np.median(v[tv])) if tv.any() else None,
          "touchdown_speed_m_s_p90": float(np.percentile(v[tv], 90)) if tv.any() else None,
          "plate_health_mean": float(plate_health.mean()),
          "plate_intact_rate": float((plate_health > 95.0).mean())}


def render_md(res: dict) -> str:
  lines = [f"# How trained Place Plate policies end their episodes, by action", "",
           f"Date: {res['date']}. Git: {res['git']}. jax {res['jax']} ({res['backend']}). {res['episodes']} episodes "
           f"per policy and action from the same resets (key {res['seed']}); task settings {res['task_kwargs']}. "
           f"Let go: the fingers' inner gap exceeds the plate's width + {100 * res['clearance']:g} cm with the plate "
           "above its resting height; release height: the plate's centre above rest at that step; never let go: "
           "held to the end of the episode (held at: the lowest the hand brought it, above rest). Touchdown speed: "
           "the plate's mean downward speed over the control step in which it first comes within 2 mm of rest. "
           "Intact: plate health > 95.", "", f"Command: `{res['command']}`", "",
           "| policy | seed | action | placed | let go, not placed | never let go | release height, median (p90) cm "
           "| never let go: held at, median cm | touchdown speed, median (p90) m/s | plate intact |",
           "|---|---|---|---|---|---|---|---|---|---|"]
  for r in res["rows"]:
    s = r["summary"]
    f = s["fractions"]
    rh = ("—" if s["release_height_cm_median"] is None
          else f"{s['release_height_cm_median']:.1f} ({s['release_height_cm_p90']:.1f})")
    nh = "—" if s["never_let_go_held_at_cm_median"] is None else f"{s['never_let_go_held_at_cm_median']:.1f}"
    tv = ("—" if s["touchdown_speed_m_s_median"] is None
          else f"{s['touchdown_speed_m_s_median']:.2f} ({s['touchdown_speed_m_s_p90']:.2f})")
    lines.append(f"| {os.path.basename(r['file'])} | {r['seed']} | {r['action']} | {100 * f['placed']:.1f} % | "
                 f"{100 * f['let go, not placed']:.1f} % | {100 * f['never let go']:.1f} % | {rh} | {nh} | {tv} | "
                 f"{100 * s['plate_intact_rate']:.1f} % |")
  spread = [r for r in res["rows"] if "sampled_spread_first_step" in r["summary"]]
  if spread:
    lines += ["", f"Spread of the sampled action before the tanh (std of the arctanh of {SPREAD_DRAWS} draws: the "
              "Gaussian's scale; arm dimensions, then the gripper) at the first and the last step of each mode "
              "episode, mean over episodes:", "",
              "| policy | seed | first step | last step |", "|---|---|---|---|"]
    for r in spread:
      s = r["summary"]
      lines.append(f"| {os.path.basename(r['file'])} | {r['seed']} | "
                   f"{' / '.join(f'{v:.2f}' for v in s['sampled_spread_first_step'])} | "
                   f"{' / '.join(f'{v:.2f}' for v in s['sampled_spread_last_step'])} |")
  return "\n".join(lines) + "\n"


def main(argv=None) -> int:
  args = parse(argv)
  env = args.env
  steps = R.episode_length_of(env, TASK)
  plate_entity = list(env.entity_names).index("plate")
  keys = jax.random.split(jax.random.PRNGKey(args.seed), args.episodes)
  programs: dict = {}
  res = {"task": TASK, "episodes": args.episodes, "seed": args.seed, "clearance": args.clearance,
         "task_kwargs": args.overrides, "rows": []}
  for spec in args.specs:
    for action in args.action_list:
      own = action if action in N.POLICY_ACTIONS else "mode"
      policy = R.make_policy(f"checkpoint{'' if own == 'mode' else '+' + own}:{spec}", env)
      mixed = action != own or (action == "mode" and args.spread)
      sampled = R.make_policy(f"checkpoint+sample:{spec}", env) if mixed else None
      apply = noise_mixture(policy.apply, sampled.apply, action) if action != own else policy.apply
      shape = (action, repr(jax.tree.map(lambda x: (x.shape, str(x.dtype)), policy.params)))
      if shape not in programs:  # one compile per (action, network shape); the weights are an argument
        programs[shape] = episodes_program(env, apply, steps)
      plate, gap, success, health = jax.device_get(programs[shape](policy.params, keys))
      # the program is episode-major [B, T, ...]; classify reads time-major [T, B, ...]
      plate, gap, success = (np.swapaxes(np.asarray(x), 0, 1) for x in (plate, gap, success))
      c = classify(plate, gap, success, PLATE_REST_Z,
                   2 * float(env.plate_half_y), args.clearance, float(env.dt))
      ph = np.asarray(health)[:, plate_entity]
      row = {"file": R.checkpoint_path("checkpoint:" + spec), "seed": policy.seed, "action": action,
             "summary": summarise(c, ph), "outcome_per_episode": c["outcome"].tolist()}
      if action == "mode" and args.spread:
        key = ("spread",) + shape[1:]
        if key not in programs:
          programs[key] = spread_program(env, policy.apply, sampled.apply, steps)
        spread = np.asarray(jax.device_get(programs[key](policy.params, keys)))
        row["summary"]["sampled_spread_first_step"] = spread[:, 0].mean(0).round(4).tolist()
        row["summary"]["sampled_spread_last_step"] = spread[:, 1].mean(0).round(4).tolist()
      res["rows"].append(row)
      f = row["summary"]["fractions"]
      print(f"{os.path.basename(row['file'])}#{policy.seed} {action}: " +
            ", ".join(f"{k} {100 * v:.1f} %" for k, v in f.items()), flush=True)
  stem = os.path.join(args.results_dir, "place_plate_outcomes" + (f"_{args.tag}" if args.tag else ""))
  provenance.save_results(res, "place_plate_outcomes", argv, stem, render_md)
  return 0


if __name__ == "__main__":
  sys.exit(main())

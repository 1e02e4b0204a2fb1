"""Safe RL from scratch, S seeds per method in one program: task-only vs penalty vs PPO-Lagrangian vs PID-Lagrangian.

For each method, ``train.train(task, seeds=S, time_limit=--budget-seconds)`` trains all
seeds in one compiled program (vmap over the seed axis), with periodic deterministic
evaluations (``--eval-envs`` episodes per seed) for the curves and the time to 80 %
safe; then every seed's final policy is scored (its mode unless ``--eval-actions`` says) by ``train.evaluate`` on
``--eval-episodes`` episodes (seed 12345, the same key as benchmarks/rl_brax_ppo.py).
Each row: mean ± std and min over seeds of completion, safe completion, avg env
health, episode cost; time to ≥ 80 % safe (with ≥ 80 % completion); env-steps/s of
the whole S-seed program; and the exact command that produced it.

Methods (``--methods``): ``task_only`` (w = 0), ``penalty`` (w = ``--damage-weight``),
``lagrangian`` (PPO-Lagrangian, ĉ = ``--budget``), ``pid`` (PID-Lagrangian, ĉ =
``--budget``), ``lagrangian_curriculum`` / ``pid_curriculum`` (the same with the budget
falling from the first measured episode cost to ĉ over ``--budget-anneal-steps``; with
``--cost-critic`` every damage-aware method uses separate reward and cost critics) — all with ``--preset`` (playground: MuJoCo Playground's PandaPickCube
recipe) — and ``paper`` / ``paper_task_only`` (the paper's PPO settings, w = 2 / 0).

GPU: each method alone on one GPU for 300 s including compile, then the final evaluation; results in
$OUT, then one table. The recipe that learns Place Plate (docs/safe_rl.md: the paper's per-dimension
initial std, a cost critic, multipliers from λ0 = 2 with slow gains), every final policy scored by
its mode, a sample and its squashed mean (the four ran at once, one per GPU of a 4-GPU host, with
CUDA_VISIBLE_DEVICES=0..3)::

    R="--init-log-std=-0.5,-1.5 --cost-critic --lagrange-init 2 --lagrange-lr 0.002 --pid-gains 0.01,0.002,0.005 --budget 1 --eval-actions mode,sample,mean --seeds 0,1,2,3,4 --budget-seconds 300"
    for m in task_only penalty lagrangian pid; do
      python benchmarks/rl_multiseed.py --methods $m $R --tag ${m}_act2 --results-dir $OUT
    done
    python benchmarks/rl_multiseed.py --combine benchmarks/results/rl_place_plate_<device>_{task_only,penalty,lagrangian,pid}_act2.json --tag h200_sample --headline-action sample

(--budget only changes the Lagrangian methods.) Without the recipe flags the methods run with brax's
initial std and λ0 = 0, lr 0.1, K = 0.1/0.01/0.05: the configuration whose collapse
rl_collapse_evidence.md shows.

Other tasks where the unsafe shortcut is tempting (issue 12 item 5; docs/rl_task_design.md), 3 seeds,
one GPU per call::

    R="--init-log-std=-0.5,-1.5 --cost-critic --eval-actions mode,sample --seeds 0,1,2 --budget-seconds 270"
    python benchmarks/rl_multiseed.py --task shelve_item --methods task_only $R --tag task_only --results-dir $OUT
    python benchmarks/rl_multiseed.py --task pick_egg --task-settings '{"start": "pregrasp"}' --methods penalty $R --tag pregrasp_penalty --results-dir $OUT

The paper's PPO settings (issue 24's third trainer: the paper's ≈ 195 updates of 512-step rollouts,
here 256 envs per seed) run longer than one device call, so the run lives in --work-dir and each later
call continues it with --resume (the row lists every call; the checkpoint, 46 MB for 3 seeds, must be on the
machine that continues). One reward alone on an H200 trains 58–65 k env steps/s over its 3 seeds, ≈ 1,300 s
for the 195 updates; two such processes sharing one GPU ran 22 k each, so give each its own GPU or call.
Task reward alone and w = 2 each ran the whole 195 updates in three such calls on one warm H200 (66, 73
and 56 updates with task reward alone, 67, 72 and 56 with w = 2; a work folder under the ignored runs/ is
what such a machine keeps between calls; a machine released between calls comes back without it, and --resume
then refuses, before anything compiles, unless the folder is brought along: its checkpoint holds the whole
training state, env states and RNG included, and names no path, so a copy continues anywhere)::

    P="--work-dir runs/rl_paper --paper-timesteps 25559040 --eval-actions sample,mode --seeds 0,1,2 --budget-seconds 490"
    python benchmarks/rl_multiseed.py --methods paper_task_only $P --tag paper_task_only --results-dir $OUT
    python benchmarks/rl_multiseed.py --methods paper_task_only $P --resume --tag paper_task_only --results-dir $OUT
    python benchmarks/rl_multiseed.py --methods paper_task_only $P --resume --tag paper_task_only --results-dir $OUT

At the paper's own scale (10⁵ steps per seed, 512 per update in 8 minibatches of 64; CPU, 10–11 min per
reward), with CleanRL's target-KL rule and the std a parameter (docs/safe_rl.md, "At the paper's own scale")::

    Q="--num-envs 8 --unroll-length 64 --paper-timesteps 99840 --timesteps 99840 --seeds 0,1,2 --budget-seconds 3000"
    python benchmarks/rl_multiseed.py --methods paper_task_only,paper --target-kl-rule epoch --policy-std parameter $Q --eval-every 25600 --eval-envs 128 --eval-actions sample,mode --tag paper_8x64

``--anneal-lr --timesteps N``: the learning rate (1e-3 in the playground preset) decays linearly to 0 over
N env steps per seed instead of staying constant (the paper preset always anneals); for long runs whose
late iterates collapse (docs/rl_task_design.md, Pick Egg's penalty phase). ``--anneal-entropy --timesteps N``:
the entropy coefficient (0.02) decays linearly to 0 over N env steps per seed, so that by the end PPO no longer
pays for the policy's noise (docs/safe_rl.md, "How the failures end": a mode that stops short of what its
samples do; on Place Plate's box counter it did not help, 4 of 6 runs meeting the bar by the mode).

CPU plumbing check (learns nothing)::

    python benchmarks/rl_multiseed.py --num-envs 16 --budget-seconds 60 --seeds 0,1 --eval-episodes 16
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import os
import shlex
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(ROOT, ".jax_cache"))

from mjx_damage import io, outputs, runtime  # noqa: E402

METHODS = ("task_only", "penalty", "lagrangian", "pid", "lagrangian_curriculum", "pid_curriculum", "paper",
           "paper_task_only")
EVAL_SEED = 12345
METRICS = ("completion", "safe_completion", "avg_env_health", "episode_cost")


def method_spec(name: str, args) -> dict:
  """Label and train() keywords of one method."""
  w = args.damage_weight
  spec = {
      "task_only": dict(label="task reward only (w=0)", preset=args.preset, damage_weight=0.0),
      "penalty": dict(label=f"damage penalty (w={w:g})", preset=args.preset, damage_weight=w),
      "lagrangian": dict(label=f"PPO-Lagrangian (ĉ={args.budget:g})", preset=args.preset, budget=args.budget,
                         multiplier="lagrangian"),
      "pid": dict(label=f"PID-Lagrangian (ĉ={args.budget:g})", preset=args.preset, budget=args.budget,
                  multiplier="pid"),
      "lagrangian_curriculum": dict(label=f"PPO-Lagrangian, budget curriculum (ĉ={args.budget:g} after "
                                          f"{args.budget_anneal_steps:.3g} steps)",
                                    preset=args.preset, budget=args.budget, multiplier="lagrangian",
                                    budget_anneal_steps=int(args.budget_anneal_steps)),
      "pid_curriculum": dict(label=f"PID-Lagrangian, budget curriculum (ĉ={args.budget:g} after "
                                   f"{args.budget_anneal_steps:.3g} steps)",
                             preset=args.preset, budget=args.budget, multiplier="pid",
                             budget_anneal_steps=int(args.budget_anneal_steps)),
      "paper": dict(label=f"paper PPO preset, penalty (w={w:g})", preset="paper", damage_weight=w),
      "paper_task_only": dict(label="paper PPO preset, task reward only", preset="paper", damage_weight=0.0),
  }[name]
  if args.cost_critic and name not in ("task_only", "paper_task_only"):
    spec = dict(spec, label=spec["label"] + " + cost critic", cost_critic=True)
  if name in ("lagrangian", "pid", "lagrangian_curriculum", "pid_curriculum"):
    gains = dict(lagrange_init=args.lagrange_init, lagrange_lr=args.lagrange_lr, pid_kp=args.pid_gains[0],
                 pid_ki=args.pid_gains[1], pid_kd=args.pid_gains[2])
    if gains != multiplier_defaults():
      tune = f"λ0={args.lagrange_init:g}, " + (f"lr={args.lagrange_lr:g}" if spec["multiplier"] == "lagrangian"
                                               else "K=" + "/".join(f"{g:g}" for g in args.pid_gains))
      spec = dict(spec, label=spec["label"].replace(")", f"; {tune})", 1), **gains)
  gate = args.damage_warmup_completion
  if name == "penalty" and (args.damage_warmup_steps or args.damage_ramp_steps or gate):
    then = f", then linear to {w:g} over {args.damage_ramp_steps:.3g}" if args.damage_ramp_steps else f", then {w:g}"
    if gate:
      sched = f"w=0 until training completion ≥ {gate:.0%}" + (
          f" and {args.damage_warmup_steps:.3g} steps" if args.damage_warmup_steps else "") + then
    elif args.damage_warmup_steps:
      sched = f"w=0 for {args.damage_warmup_steps:.3g} steps" + then
    else:
      sched = f"linear from 0 over {args.damage_ramp_steps:.3g} steps"
    spec = dict(spec, label=spec["label"].replace(")", f"; {sched})", 1),
                damage_warmup_steps=int(args.damage_warmup_steps), damage_ramp_steps=int(args.damage_ramp_steps),
                **({"damage_warmup_completion": gate} if gate else {}))
  if args.init_from:
    src = os.path.basename(args.init_from) + ("" if args.init_seed is None else f" seed {args.init_seed}")
    spec = dict(spec, label=spec["label"] + f", actor from {src}"
                + (f" (critic alone for {args.critic_warmup_iterations} iterations)"
                   if args.critic_warmup_iterations else ""),
                init_from=args.init_from, init_seed=args.init_seed,
                critic_warmup_iterations=args.critic_warmup_iterations)
  if args.anneal_lr and spec["preset"] != "paper":  # the paper preset anneals already
    spec = dict(spec, label=spec["label"] + f", lr annealed to 0 over {args.timesteps:.3g} steps",
                anneal_learning_rate=True)
  if args.anneal_entropy and spec["preset"] != "paper":  # the paper preset has no entropy term to anneal
    spec = dict(spec, label=spec["label"] + f", entropy annealed to 0 over {args.timesteps:.3g} steps",
                anneal_entropy=True)
  if args.target_kl_rule is not None and spec["preset"] == "paper":  # the only preset with a target KL
    spec = dict(spec, label=spec["label"] + f", target-KL rule {args.target_kl_rule}",
                target_kl_rule=args.target_kl_rule)
  if args.policy_std is not None:
    spec = dict(spec, label=spec["label"] + f", std a {args.policy_std}", policy_std=args.policy_std)
  if args.max_grad_norm is not None:
    clip = None if args.max_grad_norm == "none" else args.max_grad_norm
    spec = dict(spec, label=spec["label"] + (", no gradient clipping" if clip is None else f", grad-norm clip {clip:g}"),
                max_grad_norm=clip)
  if args.obs_clip is not None:
    spec = dict(spec, label=spec["label"] + f", observations clipped at ±{args.obs_clip:g}", obs_clip=args.obs_clip)
  if args.gae_per_iteration:
    spec = dict(spec, label=spec["label"] + ", GAE once per iteration", gae_per_iteration=True)
  if args.redraw_starts_steps:
    spec = dict(spec, label=spec["label"] + f", starts redrawn every {args.redraw_starts_steps:.3g} steps",
                redraw_starts_steps=int(args.redraw_starts_steps))
  if args.init_log_std is not None and spec["preset"] != "paper":  # the paper preset has its own
    spec = dict(spec, label=spec["label"] + f", init log-std {args.init_log_std[0]:g}/{args.init_log_std[1]:g}",
                init_log_std=args.init_log_std)
  if runtime.matmul_label():  # --matmul-precision or JAX_DEFAULT_MATMUL_PRECISION
    spec = dict(spec, label=spec["label"] + ", " + runtime.matmul_label())
  return spec


def multiplier_defaults() -> dict:
  """PPOConfig's multiplier settings (train/config.py): the flags' defaults, and unlabelled when unchanged."""
  from train.config import PPOConfig
  c = PPOConfig()
  return {k: getattr(c, k) for k in ("lagrange_init", "lagrange_lr", "pid_kp", "pid_ki", "pid_kd")}


def _ints(text):
  return tuple(int(s) for s in text.split(",") if s.strip())


def parse(argv):
  p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument("--task", default="place_plate", help="registered task, or package.module:EnvClass")
  p.add_argument("--obs-mode", default=None,
                 help="task obs_mode (default: the task's RL setting, tasks.RL_SETTINGS — for place_plate the "
                      "paper's 6-d observation and in-hand start — else the task's own)")
  p.add_argument("--task-settings", default=None, metavar="JSON",
                 help="registered tasks: task keyword arguments over its RL setting (tasks.RL_SETTINGS), e.g. "
                      "'{\"start\": \"pregrasp\"}'; rows record them")
  p.add_argument("--eval-task-settings", default=None, metavar="JSON",
                 help="task keywords changed for every evaluation (periodic and final) over the training ones, "
                      "e.g. '{\"start\": \"in_front\"}' after --task-settings '{\"start\": \"route\"}' "
                      "(default: evaluate in the training setting)")
  p.add_argument("--methods", default="task_only,penalty,lagrangian,pid", help=f"comma-separated of {','.join(METHODS)}")
  p.add_argument("--seeds", type=_ints, default=(0, 1, 2, 3, 4))
  p.add_argument("--preset", default="playground", help="preset of the non-paper methods (train/config.py)")
  p.add_argument("--budget-seconds", type=float, default=300.0, help="training wall clock per method, compile incl.")
  p.add_argument("--timesteps", type=float, default=None,
                 help="env steps per seed (upper bound; the budget stops first; default 1e9)")
  p.add_argument("--anneal-lr", action="store_true",
                 help="non-paper methods: the learning rate decays linearly to 0 over --timesteps (give it too; "
                      "the paper preset always anneals)")
  p.add_argument("--anneal-entropy", action="store_true",
                 help="non-paper methods: the entropy coefficient decays linearly to 0 over --timesteps (give it "
                      "too), so the policy's noise is no longer paid for by the end")
  p.add_argument("--paper-timesteps", type=float, default=1e7,
                 help="env steps per seed of the paper methods: their lr anneals linearly to 0 over this many")
  p.add_argument("--target-kl-rule", default=None,
                 help="paper methods: how the target KL stops the epochs — minibatch (SB3: before a step whose KL "
                      "> 1.5·target; the preset's) or epoch (CleanRL: after an epoch whose last step began above "
                      "the target); train/config.py")
  p.add_argument("--policy-std", default=None,
                 help="every method: the policy's std an output of the actor per state (brax's; the presets') or "
                      "one learned parameter per action dimension (SB3's, CleanRL's); train/config.py")
  p.add_argument("--num-envs", type=int, default=None, help="envs per seed (default: the preset's)")
  p.add_argument("--unroll-length", type=int, default=None, help="default: the preset's")
  p.add_argument("--damage-weight", type=float, default=2.0)
  p.add_argument("--damage-warmup-steps", type=float, default=0.0,
                 help="penalty method: task reward alone (w = 0) for this many env steps per seed, then "
                      "--damage-weight (train/config.py, the penalty schedule)")
  p.add_argument("--damage-warmup-completion", type=float, default=0.0, metavar="RATE",
                 help="penalty method: w = 0 until a rollout's finished training episodes complete the task at "
                      "this rate (0-1, per seed; and past --damage-warmup-steps if given), then the ramp")
  p.add_argument("--damage-ramp-steps", type=float, default=0.0,
                 help="penalty method: after the warm-up, w rises linearly to --damage-weight over this many env steps")
  p.add_argument("--redraw-starts-steps", type=float, default=0.0,
                 help="every method: env steps per seed between fresh starts of every training env, cutting the "
                      "episodes under way, as brax's num_resets_per_eval (train/config.py); 0 (default): each env "
                      "replays the start of its first reset")
  p.add_argument("--max-grad-norm", default=None, metavar="X|none",
                 help="every method: per-network gradient-norm clip, or none (brax's ppo.train default, which "
                      "Playground's PandaPickCube recipe keeps) (default: the preset's)")
  p.add_argument("--obs-clip", type=float, default=None, metavar="X",
                 help="every method: bound on |normalised observation| (default: none, brax's normaliser unbounded)")
  p.add_argument("--gae-per-iteration", action="store_true",
                 help="every method: advantages and value targets computed once per iteration, before the epochs "
                      "(CleanRL, SB3; train.iteration_targets), not brax's moving ones")
  p.add_argument("--budget", type=float, default=2.0, help="episode-cost budget ĉ of the Lagrangian methods")
  p.add_argument("--cost-critic", action="store_true",
                 help="damage-aware methods: separate reward and cost critics (train.constrained_loss)")
  mult = multiplier_defaults()
  p.add_argument("--lagrange-init", type=float, default=mult["lagrange_init"], help="Lagrangian methods: initial λ")
  p.add_argument("--lagrange-lr", type=float, default=mult["lagrange_lr"],
                 help="plain Lagrangian: dual step per health point of error")
  p.add_argument("--pid-gains", default=f"{mult['pid_kp']:g},{mult['pid_ki']:g},{mult['pid_kd']:g}",
                 metavar="KP,KI,KD", help="PID-Lagrangian gains")
  p.add_argument("--init-log-std", default=None, metavar="ARM,GRIPPER",
                 help="non-paper methods: initial policy log-std of the arm and the gripper (last action) "
                      "dimensions, e.g. --init-log-std=-0.5,-1.5 (the paper's); default: brax's init")
  p.add_argument("--budget-anneal-steps", type=float, default=6e6,
                 help="*_curriculum methods: env steps per seed over which the budget falls from the first "
                      "measured episode cost to --budget (train.multipliers)")
  p.add_argument("--eval-every", type=float, default=3e6,
                 help="env steps per seed between periodic evaluations (each: S calls of --eval-envs episodes)")
  p.add_argument("--eval-envs", type=int, default=256, help="episodes per seed of each periodic evaluation")
  p.add_argument("--eval-episodes", type=int, default=1024, help="episodes per seed of the final evaluation")
  p.add_argument("--eval-actions", default="mode",
                 help="comma-separated actions of the final evaluation, each of mode (tanh of the Gaussian's "
                      "mean: brax's deterministic policy), sample (the stochastic policy PPO trains) and mean "
                      "(E[tanh(u)] from 32 draws; train.networks.policy_apply); the first is the row's headline, "
                      "the others are kept per seed beside it")
  p.add_argument("--init-from", default=None, metavar="CHECKPOINT",
                 help="start every method's actor and observation normaliser from this checkpoint (a run "
                      "directory, a checkpoint.npz or a --export-policy file: one seed for all, or one per "
                      "seed); critic and optimizer start fresh")
  p.add_argument("--init-seed", type=int, default=None,
                 help="with --init-from: the checkpoint's seed whose actor starts every seed")
  p.add_argument("--critic-warmup-iterations", type=int, default=0,
                 help="with --init-from: iterations in which only the critic learns (the actor is held)")
  p.add_argument("--export-policy", action="store_true",
                 help="also write each method's final policy alone (train.checkpoint.export_policy: weights and "
                      "normaliser, no env states; ~0.1 MB) as rl_<task>_<device>_<tag>_<method>_policy.npz "
                      "beside the results, for --init-from on another machine")
  p.add_argument("--results-dir", default=os.path.join(ROOT, "benchmarks", "results"))
  p.add_argument("--work-dir", default=None,
                 help="folder of the run directories, one per method (default: a new temporary folder per call, "
                      "so two calls at once never share a run)")
  p.add_argument("--resume", action="store_true",
                 help="continue each method's run in --work-dir from its checkpoint for another --budget-seconds "
                      "(a run longer than one device call); the row lists every call's command. Refused when "
                      "--work-dir holds none of the methods' runs; a method without its folder starts afresh")
  p.add_argument("--deterministic", action="store_true",
                 help="deterministic XLA GPU kernels: a rerun of a command repeats it bit for bit, at 0.73–0.76× the "
                      "throughput on an H200 (mjx_damage.runtime); CPU runs repeat without it")
  p.add_argument("--matmul-precision", default=None, choices=runtime.MATMUL_PRECISIONS,
                 help="float32 matrix products (physics, networks) at the backend's default precision (TF32 on a "
                      "recent NVIDIA GPU) or at full float32 (mjx_damage.runtime); default: JAX's setting "
                      "(JAX_DEFAULT_MATMUL_PRECISION), recorded in the results either way")
  p.add_argument("--tag", default="", help="file-name suffix: rl_<task>_<device>_<tag>.{json,md}")
  p.add_argument("--combine", nargs="+", metavar="FILE.json", help="no training: merge earlier results into one table")
  p.add_argument("--headline-action", default=None,
                 help="with --combine: score every row by this action of its final evaluation (rows must have "
                      "scored it: --eval-actions); default: each row's own first action")
  args = p.parse_args(argv)
  from train.config import POLICY_STDS, TARGET_KL_RULES  # after argparse: --help answers without importing JAX
  from train.networks import POLICY_ACTIONS
  for flag, value, valid in (("--target-kl-rule", args.target_kl_rule, TARGET_KL_RULES),
                             ("--policy-std", args.policy_std, POLICY_STDS)):
    if value is not None and value not in valid:
      p.error(f"{flag}: one of {','.join(valid)}, got {value!r}")
  if args.tag and not all(c.isalnum() or c in "_-" for c in args.tag):
    p.error(f"--tag: letters, digits, '_' and '-' only, got {args.tag!r}")
  if args.combine:
    if not args.tag:
      p.error("--combine: give --tag for the combined table's file name")
    for path in args.combine:
      if not os.path.isfile(path):
        p.error(f"--combine: no such file {path!r}")
    if args.headline_action is not None and args.headline_action not in POLICY_ACTIONS:
      p.error(f"--headline-action: one of {','.join(POLICY_ACTIONS)}, got {args.headline_action!r}")
    return args
  args.methods = [m.strip() for m in args.methods.split(",") if m.strip()]
  bad = [m for m in args.methods if m not in METHODS]
  if bad or not args.methods:
    p.error(f"--methods: unknown {bad}; choose from {','.join(METHODS)}")
  if not args.seeds or len(set(args.seeds)) != len(args.seeds):
    p.error(f"--seeds: distinct integers, got {args.seeds}")
  if args.budget_seconds <= 0:
    p.error("--budget-seconds: must be > 0")
  if args.timesteps is not None and not (1 <= args.timesteps < math.inf):
    p.error(f"--timesteps: env steps per seed, a number >= 1, got {args.timesteps}")
  if args.anneal_lr and args.timesteps is None:
    p.error("--anneal-lr: the rate decays to 0 over --timesteps; give --timesteps (env steps per seed) too")
  if args.anneal_entropy and args.timesteps is None:
    p.error("--anneal-entropy: the coefficient decays to 0 over --timesteps; give --timesteps (env steps per seed) too")
  args.timesteps = 1e9 if args.timesteps is None else args.timesteps
  try:
    args.pid_gains = tuple(float(x) for x in args.pid_gains.split(","))
  except ValueError:
    args.pid_gains = ()
  if len(args.pid_gains) != 3 or not all(g >= 0 for g in args.pid_gains):
    p.error(f"--pid-gains: three numbers KP,KI,KD >= 0, got {args.pid_gains!r}")
  for flag, v in (("--lagrange-init", args.lagrange_init), ("--lagrange-lr", args.lagrange_lr)):
    if not v >= 0:
      p.error(f"{flag}: must be >= 0, got {v}")
  if args.init_log_std is not None:
    try:
      v = tuple(float(x) for x in args.init_log_std.split(","))
    except ValueError:
      v = ()
    if len(v) != 2 or not all(-10.0 <= x <= 2.0 for x in v):
      p.error(f"--init-log-std: two numbers ARM,GRIPPER in [-10, 2], got {args.init_log_std!r}")
    args.init_log_std = v
  args.eval_actions = [a.strip() for a in args.eval_actions.split(",") if a.strip()]
  if not args.eval_actions or len(set(args.eval_actions)) != len(args.eval_actions) or not set(
      args.eval_actions) <= set(POLICY_ACTIONS):
    p.error(f"--eval-actions: distinct values of {','.join(POLICY_ACTIONS)}, got {args.eval_actions}")
  if args.task_settings is not None:
    if ":" in args.task:
      p.error("--task-settings: only for registered tasks, not package.module:EnvClass")
    import tasks
    try:
      tasks.rl_settings(args.task, args.task_settings)
    except ValueError as e:
      p.error(f"--task-settings: {e}")
    if any(k in json.loads(args.task_settings) for k in ("damage_weight", "obs_mode")):
      p.error("--task-settings: damage_weight comes from the methods and obs_mode from --obs-mode")
  if args.eval_task_settings is not None:
    try:
      args.eval_overrides = eval_overrides(args.task, args.task_settings, args.eval_task_settings)
    except ValueError as e:
      p.error(f"--eval-task-settings: {e}")
  if not args.budget_anneal_steps >= 0:
    p.error(f"--budget-anneal-steps: must be >= 0, got {args.budget_anneal_steps}")
  if args.max_grad_norm is not None:
    text = args.max_grad_norm
    try:
      args.max_grad_norm = "none" if text.lower() == "none" else float(text)
    except ValueError:
      p.error(f"--max-grad-norm: a number > 0 or none, got {text!r}")
    if args.max_grad_norm != "none" and not (math.isfinite(args.max_grad_norm) and args.max_grad_norm > 0):
      p.error(f"--max-grad-norm: a number > 0 or none, got {text!r}")
  if args.obs_clip is not None and not (math.isfinite(args.obs_clip) and args.obs_clip > 0):
    p.error(f"--obs-clip: a finite number > 0, got {args.obs_clip}")
  if not (args.redraw_starts_steps >= 0 and float(args.redraw_starts_steps).is_integer()):
    p.error(f"--redraw-starts-steps: a whole number of env steps >= 0, got {args.redraw_starts_steps}")
  if not 0 <= args.damage_warmup_completion <= 1:
    p.error(f"--damage-warmup-completion: a rate in [0, 1], got {args.damage_warmup_completion}")
  for flag, v in (("--damage-warmup-steps", args.damage_warmup_steps), ("--damage-ramp-steps", args.damage_ramp_steps),
                  ("--damage-warmup-completion", args.damage_warmup_completion)):
    if not v >= 0:
      p.error(f"{flag}: must be >= 0, got {v}")
    if v and "penalty" not in args.methods:
      p.error(f"{flag}: schedules the penalty method's weight; --methods has no penalty")
    if v and not args.damage_weight > 0:
      p.error(f"{flag}: schedules the damage weight; --damage-weight must be > 0")
  if args.critic_warmup_iterations < 0:
    p.error(f"--critic-warmup-iterations: must be >= 0, got {args.critic_warmup_iterations}")
  if args.init_seed is not None and not args.init_from:
    p.error("--init-seed: picks a seed of the --init-from checkpoint; give --init-from")
  if args.critic_warmup_iterations and not args.init_from:
    p.error("--critic-warmup-iterations: holds a pre-trained actor while the critic learns; give --init-from")
  if args.init_from:
    from train import checkpoint as ckpt
    from train.ppo import init_source
    try:
      file, _, src = init_source(args.init_from, args.task)
    except ValueError as e:
      p.error(f"--init-from: {str(e).removeprefix('init_from: ')}")
    if args.init_seed is not None:
      try:
        ckpt.check_seed(file, src.seeds, args.init_seed, "--init-seed")
      except ValueError as e:
        p.error(str(e))
    if args.init_seed is None and len(src.seeds) not in (1, len(args.seeds)):
      p.error(f"--init-from: {file} holds {len(src.seeds)} seeds; give one seed or as many as --seeds "
              f"({len(args.seeds)})")
  if args.resume and not args.work_dir:
    p.error("--resume: give --work-dir, the folder of the runs to continue")
  if args.resume and not any(outputs.exists(os.path.join(args.work_dir, name)) for name in args.methods):
    # a wrong or lost --work-dir would otherwise train every method again from the start, a whole call's time
    p.error(f"--resume: {args.work_dir} holds no run of {', '.join(args.methods)} to continue (drop --resume "
            "to start them there); a method whose folder is missing while another's is there starts afresh")
  if args.work_dir and not args.resume:
    for name in args.methods:
      if outputs.exists(os.path.join(args.work_dir, name)):
        p.error(f"--work-dir: {os.path.join(args.work_dir, name)} already holds a run; pass --resume to continue "
                "it, or choose another --work-dir")
  for flag, v in (("--eval-envs", args.eval_envs), ("--eval-episodes", args.eval_episodes),
                  ("--eval-every", args.eval_every), ("--paper-timesteps", args.paper_timesteps)):
    if not (1 <= v < math.inf):
      p.error(f"{flag}: must be >= 1, got {v}")
  if not (math.isfinite(args.damage_weight) and args.damage_weight >= 0):
    p.error(f"--damage-weight: a finite number >= 0, got {args.damage_weight}")
  if min(args.seeds) < 0:
    p.error(f"--seeds: integers >= 0, got {args.seeds}")
  for name in args.methods:  # every method's training config, as train() builds it: sizes and the rest
    error = config_error(name, args)
    if error:
      p.error(f"--methods {name}: {error}")
  if args.deterministic:  # after every check, before main starts a backend: XLA reads its flags once
    try:
      runtime.use_deterministic_gpu_ops("--deterministic")
    except (ValueError, RuntimeError) as e:
      p.error(str(e))
  if args.matmul_precision is not None:  # before anything is traced
    runtime.use_matmul_precision(args.matmul_precision)
  return args


device_info = runtime.device_info  # (slug, description) of the first JAX device


def config_error(name: str, args) -> str | None:
  """Why train() would refuse method ``name``'s config (train.config.PPOConfig.validate, e.g. ``num_envs: must
  be a positive integer``), or None; checked before anything compiles."""
  from train.config import PPOConfig

  spec = method_spec(name, args)
  kw = {k: v for k, v in spec.items() if k not in ("label", "preset", "init_from", "init_seed")}
  kw.update(size_overrides(spec["preset"], args))
  steps = min(args.timesteps, args.paper_timesteps) if spec["preset"] == "paper" else args.timesteps
  try:
    PPOConfig.preset(spec["preset"], seeds=tuple(args.seeds), episode_length=1, num_timesteps=int(steps),
                     eval_every=int(args.eval_every), num_eval_envs=args.eval_envs, **kw).validate()
  except (ValueError, TypeError) as e:
    return str(e)
  return None


def size_overrides(preset: str, args) -> dict:
  """--num-envs / --unroll-length on a preset, keeping its rollouts per iteration and minibatch count."""
  from train.config import PPOConfig

  base = PPOConfig.preset(preset)
  out = {}
  if args.unroll_length is not None:
    out["unroll_length"] = args.unroll_length
  if args.num_envs is not None:  # 0 or less: refused by PPOConfig.validate (config_error), not the preset's
    n_mb = max(1, min(base.num_minibatches, args.num_envs))
    out.update(num_envs=args.num_envs, num_minibatches=n_mb,
               batch_size=max(1, args.num_envs * base.num_rollouts // n_mb))
  return out


def time_to_safe(rows, safe=0.8, completion=0.8, keys=("eval/safe_completion", "eval/completion", "wall_time")):
  """Wall clock (s from the start of training) of the first evaluation with safe ≥ 0.8 and completion ≥ 0.8.

  ``keys``: the rows' (safe completion, completion, clock) entries; the default reads our trainer's history
  (rl_brax_ppo.py passes its scored curve's)."""
  k_safe, k_completion, k_clock = keys
  for r in rows:
    if (r.get(k_safe) or 0) >= safe and (r.get(k_completion) or 0) >= completion:
      return r[k_clock]
  return None


def stats(values):
  import numpy as np

  v = np.asarray([x for x in values if x is not None], np.float64)
  if v.size == 0:
    return {"mean": None, "std": None, "min": None, "max": None, "n": 0}
  return {"mean": float(v.mean()), "std": float(v.std()), "min": float(v.min()), "max": float(v.max()),
          "n": int(v.size)}


def summarise(per_seed) -> dict:
  summary = {k: stats([p["final_eval"][k] for p in per_seed]) for k in METRICS}
  summary["time_to_80_safe_s"] = stats([p["time_to_80_safe_s"] for p in per_seed])
  return summary


def with_headline(row: dict, action: str, source: str) -> dict:
  """``row`` scored by ``action`` of its final evaluation (first in eval_actions, summary recomputed)."""
  if action not in _actions(row) or any("final_eval_by_action" not in p for p in row["per_seed"]):
    raise SystemExit(f"--headline-action: {source} row {row['label']!r} did not score the {action} action "
                     f"(its actions: {','.join(_actions(row))})")
  per_seed = [dict(p, final_eval=p["final_eval_by_action"][action]) for p in row["per_seed"]]
  return dict(row, per_seed=per_seed, summary=summarise(per_seed),
              eval_actions=[action] + [a for a in _actions(row) if a != action])


def eval_overrides(task: str, task_settings: str | None, eval_settings: str) -> dict:
  """The task keywords of the JSON object ``eval_settings`` (checked over ``task``'s training settings, its RL
  setting with ``task_settings``, by tasks.settings_over); damage_weight and obs_mode are refused (they come
  from the methods and --obs-mode). ValueError; before anything compiles."""
  import tasks

  if ":" in task:
    raise ValueError("only for registered tasks, not package.module:EnvClass")
  tasks.settings_over(task, tasks.rl_settings(task, task_settings), eval_settings, "eval_task_settings")  # checks
  extra = json.loads(eval_settings)
  if any(k in extra for k in ("damage_weight", "obs_mode")):
    raise ValueError("damage_weight comes from the methods and obs_mode from --obs-mode")
  return extra


def run_method(name: str, args, command: str, work: str) -> dict:
  import tasks
  import train
  from train import evaluate as E

  spec = method_spec(name, args)
  kw = {k: v for k, v in spec.items() if k != "label"}
  kw.update(size_overrides(spec["preset"], args))
  # a registered task in its RL setting (tasks.RL_SETTINGS: Place Plate's paper observation and in-hand
  # start, Pick Egg's carry); --obs-mode overrides the observation
  task_kwargs = None
  if ":" not in args.task:
    task_kwargs = tasks.rl_settings(args.task, args.task_settings)
    if args.obs_mode:
      task_kwargs["obs_mode"] = args.obs_mode
    task_kwargs = task_kwargs or None
  eval_kwargs = None  # None: evaluate in the training setting
  if getattr(args, "eval_overrides", None):
    eval_kwargs = {**(task_kwargs or {}), **args.eval_overrides}
  run_dir = os.path.join(work, name)
  print(f"== {name}: {spec['label']}, seeds {list(args.seeds)}, {args.budget_seconds:.0f} s", flush=True)
  steps = min(args.timesteps, args.paper_timesteps) if spec["preset"] == "paper" else args.timesteps
  calls_path = os.path.join(run_dir, "calls.json")
  calls = []
  if args.resume and os.path.exists(calls_path):
    with open(calls_path) as f:
      calls = json.load(f)
  res = train.train(args.task, task_kwargs=task_kwargs, seeds=args.seeds, num_timesteps=int(steps),
                    eval_every=int(args.eval_every), num_eval_envs=args.eval_envs, checkpoint_every=0,
                    out_dir=run_dir, time_limit=args.budget_seconds, progress=True, resume=args.resume,
                    eval_task_kwargs=eval_kwargs, **kw)
  calls.append({"command": command, "date": time.strftime("%Y-%m-%d %H:%M"), "device": device_info()[1],
                "matmul_precision": runtime.matmul_precision(),  # of this call; a resumed run's calls each say theirs
                "iterations_at_end": res.iterations, "env_steps_per_seed_at_end": res.env_steps,
                "wall_time_s": round(res.wall_time, 1)})
  io.write_json(calls_path, calls, indent=1)
  env, _ = train.resolve_task(args.task, task_kwargs if eval_kwargs is None else eval_kwargs)
  t0 = time.perf_counter()
  finals = {}  # action -> per-seed metrics, in args.seeds order
  for action in args.eval_actions:
    evaluator, finals[action] = None, []
    for s in args.seeds:  # one executable for all seeds: the weights are data
      policy = train.load_policy(run_dir, seed=s, action=action)
      if evaluator is None:
        evaluator = E.Evaluator(env, E.parametrized_policy(policy.apply, None), res.config.episode_length)
      per_ep = evaluator.run(E.episode_keys(EVAL_SEED, args.eval_episodes), 1.0, params=policy.params)
      finals[action].append(E.scalar_metrics(E.metrics(per_ep, env.entity_names, train.ppo.safe_threshold_of(env))))
  eval_s = time.perf_counter() - t0
  per_seed = []
  gate = res.train_state.penalty_start  # i32[S] with the completion gate, else None
  for i, s in enumerate(args.seeds):
    rows = [r for r in res.history if r["seed"] == s]
    per_seed.append({"seed": s, "final_eval": finals[args.eval_actions[0]][i],
                     "final_eval_by_action": {a: finals[a][i] for a in args.eval_actions},
                     "time_to_80_safe_s": time_to_safe(rows),
                     "final_lambda": rows[-1].get("lagrange") if rows else None})
    if gate is not None:  # env steps per seed at which w started to ramp; None: the gate never opened
      start = int(gate[i])
      per_seed[-1]["penalty_from_steps"] = None if start == train.iteration.NOT_YET else start * res.config.steps_per_iteration
  summary = summarise(per_seed)
  curves = f"rl_{name}_curves.png"
  return {
      "label": spec["label"], "method": name, "command": command, "calls": calls,
      "matmul_precision": runtime.matmul_precision(),
      "eval_actions": list(args.eval_actions),
      "train_kwargs": kw, "task_kwargs": task_kwargs,
      **({} if eval_kwargs is None else {"eval_task_kwargs": eval_kwargs}),
      "config": res.config.to_json(), "seeds": list(args.seeds), "per_seed": per_seed, "summary": summary,
      "env_steps_per_seed": res.env_steps, "wall_time_s": res.wall_time, "train_time_s": res.train_time,
      "throughput_all_seeds": res.throughput if math.isfinite(res.throughput) else None,  # None: 1 iteration, none timed
      "final_eval_s": eval_s, "timings": res.timings,
      "stopped_by_time_limit": res.stopped_early, "curves_src": os.path.join(run_dir, "curves.png"),
      "curves": curves, "history": res.history,
  }


def _pm(s, pct=True):
  if s["mean"] is None:
    return "—"
  f = (lambda x: f"{100 * x:.1f}") if pct else (lambda x: f"{x:.2f}")
  return f"{f(s['mean'])} ± {f(s['std'])} (min {f(s['min'])})"


def _rate(x):
  return "—" if x is None else f"{x:,.0f}"


def seeds_meeting(row: dict, safe: float = 0.8, completion: float = 0.9) -> int:
  """Seeds of a results row whose final policy reaches ``safe`` safe completion and ``completion`` completion."""
  return sum(p["final_eval"]["safe_completion"] >= safe and p["final_eval"]["completion"] >= completion
             for p in row["per_seed"])


def _actions(row: dict) -> list:
  return row.get("eval_actions") or ["mode"]  # rows written before the flag: the mode


def _labelled(row: dict) -> str:
  head = _actions(row)[0]
  return row["label"] if head == "mode" else f"{row['label']}, {head} action"


def _by_action(rows) -> list:
  """The final evaluation under every action a row scored (rows with one action add nothing)."""
  out = []
  for r in rows:
    if len(_actions(r)) < 2:
      continue
    for a in _actions(r):
      evals = [p["final_eval_by_action"][a] for p in r["per_seed"]]
      s = {k: stats([e[k] for e in evals]) for k in ("completion", "safe_completion", "episode_cost")}
      meet = sum(e["safe_completion"] >= 0.8 and e["completion"] >= 0.9 for e in evals)
      per = " / ".join(f"{e['safe_completion']:.1%}" for e in evals)
      out.append(f"| {r['label']} | {a} | {_pm(s['completion'])} | {_pm(s['safe_completion'])} "
                 f"| {meet}/{len(evals)} | {_pm(s['episode_cost'], False)} | {per} |")
  if not out:
    return []
  return ["", "## Final policy by action", "",
          "The same final weights scored with each action (train.networks.policy_apply): mode = tanh of the "
          "Gaussian's mean (brax's deterministic policy); sample = one draw per step, the policy PPO trains; "
          "mean = E[tanh(u)] from 32 draws per step.", "",
          "| method | action | completion % | safe completion % | seeds ≥ 80/90 | episode cost | safe per seed |",
          "|---|---|---|---|---|---|---|"] + out


def write_results(base: str, payload: dict) -> None:
  io.write_json(base + ".json", payload, indent=1)
  lines = [f"# {payload['task']}: multi-seed safe RL ({payload['device']})", "",
           f"Date: {payload['date']}. Evaluation: every seed's final policy (its mode, brax's deterministic "
           "policy, unless the method says which action) on "
           f"{payload['eval_episodes']} episodes (train.evaluate, key seed {EVAL_SEED}). Cells: mean ± std "
           "(min) over seeds, in % for rates. Safe completion = completed and every tracked entity's final "
           "health > 95. Time to 80 %: first periodic evaluation with ≥ 80 % safe and ≥ 80 % completion, "
           "s of training (compile incl.; summed over the calls of a resumed run); 'n/S' seeds got there. Seeds ≥ 80/90: seeds whose "
           "final policy has ≥ 80 % safe completion and ≥ 90 % completion.", ""]
  for r in payload["rows"]:
    if r.get("eval_task_kwargs"):  # trained in one setting, evaluated in another
      lines += [f"{r['label']}: trained with task settings `{json.dumps(r['task_kwargs'], sort_keys=True)}`, "
                f"evaluated (periodic and final) with `{json.dumps(r['eval_task_kwargs'], sort_keys=True)}`.", ""]
  lines += ["| method | seeds | completion % | safe completion % | seeds ≥ 80/90 | avg env health | episode cost "
            "| time to 80 % safe (s) | env-steps/s (all seeds) | env-steps per seed |",
            "|---|---|---|---|---|---|---|---|---|---|"]
  for r in payload["rows"]:
    r = dict(r, label=_labelled(r))
    s, t = r["summary"], r["summary"]["time_to_80_safe_s"]
    t80 = "—" if t["mean"] is None else f"{t['mean']:.0f} ± {t['std']:.0f} ({t['n']}/{len(r['seeds'])})"
    lines.append(f"| {r['label']} | {','.join(map(str, r['seeds']))} | {_pm(s['completion'])} "
                 f"| {_pm(s['safe_completion'])} | {seeds_meeting(r)}/{len(r['per_seed'])} "
                 f"| {_pm(s['avg_env_health'], False)} "
                 f"| {_pm(s['episode_cost'], False)} | {t80} | {_rate(r['throughput_all_seeds'])} "
                 f"| {r['env_steps_per_seed']:,} |")
  lines += _by_action(payload["rows"])
  lines += ["", "## Per seed", "", "| method | seed | completion | safe completion | avg env health | episode cost "
            "| time to 80 % safe (s) | final λ |", "|---|---|---|---|---|---|---|---|"]
  for r in payload["rows"]:
    r = dict(r, label=_labelled(r))
    for p in r["per_seed"]:
      e, t = p["final_eval"], p["time_to_80_safe_s"]
      lam = "—" if p["final_lambda"] is None or "Lagrangian" not in r["label"] else f"{p['final_lambda']:.3g}"
      lines.append(f"| {r['label']} | {p['seed']} | {e['completion']:.1%} | {e['safe_completion']:.1%} "
                   f"| {e['avg_env_health']:.2f} | {e['episode_cost']:.2f} | {'—' if t is None else f'{t:.0f}'} "
                   f"| {lam} |")
  for r in payload["rows"]:  # the completion gate's opening, per seed (none without --damage-warmup-completion)
    gated = [p for p in r["per_seed"] if "penalty_from_steps" in p]
    if gated:
      lines += ["", f"Penalty gate of {_labelled(r)}: w began to ramp at " + "; ".join(
          f"seed {p['seed']}: " + ("never (w = 0 throughout)" if p["penalty_from_steps"] is None
                                  else f"{p['penalty_from_steps']:,} env steps") for p in gated) + "."]
  lines += ["", "## Commands", ""]
  for r in payload["rows"]:
    lines.append(f"- {r['label']}: `{r['command']}` ({r['date']}, curves `{r['curves']}`)")
    if len(r.get("calls", [])) > 1:  # a run continued over several calls (--resume)
      lines += [f"  - call {i}: `{c['command']}` ({c['date']}, {c['device']}; iteration {c['iterations_at_end']}, "
                f"{c['env_steps_per_seed_at_end']:,} env steps per seed at its end, {c['wall_time_s']:.0f} s)"
                for i, c in enumerate(r["calls"], 1)]
  lines += ["", "## Settings per method", ""]
  for r in payload["rows"]:
    lines += [f"- {r['label']}: `{json.dumps(r['config'])}`"]
  lines.append("")
  io.write_text(base + ".md", "\n".join(lines))


def combine(args) -> int:
  payload = None
  for path in args.combine:
    with open(path) as f:
      src = json.load(f)
    if payload is None:
      payload = {k: v for k, v in src.items() if k != "rows"}
      payload["rows"], payload["sources"] = [], []
    elif (src["device"], src["task"], src["eval_episodes"]) != (payload["device"], payload["task"],
                                                                 payload["eval_episodes"]):
      raise SystemExit(f"--combine: {path} is from another device/task/evaluation size than the first file")
    rows = src["rows"]
    if args.headline_action:
      rows = [with_headline(r, args.headline_action, os.path.basename(path)) for r in rows]
    payload["rows"] += rows
    payload["sources"].append(os.path.basename(path))
  # Reruns of one command keep their own rows: number repeated labels so that neither hides the other.
  total, seen = collections.Counter(r["label"] for r in payload["rows"]), collections.Counter()
  for i, row in enumerate(payload["rows"]):
    if total[row["label"]] > 1:
      seen[row["label"]] += 1
      payload["rows"][i] = dict(row, label=f"{row['label']} — run {seen[row['label']]}")
  payload["date"] = time.strftime("%Y-%m-%d %H:%M")
  slug = payload["task"].rsplit(":", 1)[-1].lower()
  base = os.path.join(args.results_dir, f"rl_{slug}_combined_{args.tag}")
  write_results(base, payload)
  print(f"wrote {base}.md / .json", flush=True)
  return 0


def main(argv=None) -> int:
  args = parse(argv)
  if args.combine:
    return combine(args)
  import jax

  slug, device = device_info()
  task_slug = args.task.rsplit(":", 1)[-1].lower()
  base = os.path.join(args.results_dir, f"rl_{task_slug}_{slug}" + (f"_{args.tag}" if args.tag else ""))
  work = args.work_dir or tempfile.mkdtemp(prefix=f"rl_multiseed_{task_slug}_{slug}_")
  command = " ".join(shlex.quote(a) for a in ["benchmarks/rl_multiseed.py"]
                     + list(sys.argv[1:] if argv is None else argv))
  command += runtime.flags_in_force(args.deterministic, args.matmul_precision)  # set through the environment
  payload = {"device": device, "jax": jax.__version__, "task": args.task, "eval_episodes": args.eval_episodes,
             "date": time.strftime("%Y-%m-%d %H:%M"), "rows": []}
  from train.ppo import TrainingDiverged  # after argparse, as run_method's imports

  diverged = []
  for name in args.methods:
    try:
      row = run_method(name, args, command, work)
    except TrainingDiverged as e:  # no row; the other methods still run
      print(f"{name}: {e}", file=sys.stderr, flush=True)
      diverged.append(name)
      continue
    row["date"] = time.strftime("%Y-%m-%d %H:%M")
    src = row.pop("curves_src")
    row["curves"] = os.path.basename(base) + f"_{name}.png"
    if os.path.exists(src):
      with open(src, "rb") as f:
        io.write_bytes(os.path.join(os.path.dirname(base), row["curves"]), f.read())
    if args.export_policy:
      from train import checkpoint as ckpt
      row["policy_file"] = os.path.basename(base) + f"_{name}_policy.npz"
      ckpt.export_policy(os.path.join(work, name, ckpt.FILENAME), os.path.join(os.path.dirname(base),
                                                                                 row["policy_file"]))
    payload["rows"].append(row)
    write_results(base, payload)  # after every method: a timeout keeps the finished ones
    print(json.dumps({k: row[k] for k in ("label", "summary", "throughput_all_seeds", "env_steps_per_seed")},
                     indent=1), flush=True)
  if payload["rows"]:
    print(f"wrote {base}.md / .json", flush=True)
  if diverged:
    print(f"diverged (no row): {', '.join(diverged)}", file=sys.stderr)
    return 1
  return 0


if __name__ == "__main__":
  sys.exit(main())

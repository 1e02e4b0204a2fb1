"""PPO run configuration: one frozen dataclass, named presets, validation before anything compiles.

Presets (``PPOConfig.preset(name, **overrides)``, ``mjx-damage train --preset NAME``):

* ``playground`` (the default) — MuJoCo Playground 0.2.0's published Brax PPO
  settings for PandaPickCube (``mujoco_playground/config/manipulation_params.py``):
  2048 envs, 32 minibatches of 512 sequences, 8 epochs per batch, unroll 10,
  γ 0.97, lr 1e-3, entropy 2e-2, observation normalisation, policy MLP 32×4,
  value MLP 256×5 (swish). Brax's own trainer with these settings reaches
  99 % safe on the old place_plate in-hand start (one H100, before the task change of
  docs/rl_task_design.md; runs on the current task: benchmarks/rl_brax_ppo.py).
* ``paper`` — the oopsieverse paper's PPO appendix table: actor and critic MLP
  512×2 tanh, Gaussian + tanh squashing, initial log-std −0.5 (arm) / −1.5
  (gripper = last action dimension), lr 1e-3 linearly annealed to 0, rollout
  512 steps, 10 epochs × 8 minibatches, clip 0.2, entropy 0, value coef 0.5,
  grad-norm 0.5, target KL 0.01 (epochs stop early), γ 0.99, GAE λ 0.95
  (paper, table "PPO hyperparameters for Place Plate"). The paper trains one
  env for 1e5 steps (≈ 195 rollouts of 512); here the rollout is batched over
  256 envs (8 minibatches of 32 sequences × 512 steps). The table leaves the
  target-KL rule and where the std lives to the implementation:
  ``target_kl_rule`` and ``policy_std`` choose them (docs/safe_rl.md, "At the
  paper's own scale"); the preset keeps SB3's rule and brax's per-state std.
* ``legacy`` — this trainer's defaults before the multi-seed rewrite (1024
  envs, 8 minibatches, 4 epochs, entropy 1e-3, lr 3e-4, 256×2 swish); kept for
  comparison (the committed single-seed ``rl_place_plate_nvidia_h100_*`` rows of the
  old in-hand start were made with it).
  Its GPU variant (16384 envs, 8 × 2048 sequences, 4 epochs) did 8× fewer SGD
  steps per env step than ``playground`` and sat at 0 % completion for 30–60 M
  env-steps on place_plate (benchmarks/rl_collapse_evidence.py).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Optional

import numpy as np

ACTIVATION_NAMES = ("tanh", "swish", "relu", "elu")
MULTIPLIERS = ("lagrangian", "pid")
TARGET_KL_RULES = ("minibatch", "epoch")
POLICY_STDS = ("state", "parameter")

# Config fields that may change when a run is resumed: they decide how long to
# run and what to log, never what a training iteration computes.
RESUMABLE_CHANGES = ("num_timesteps", "eval_every", "checkpoint_every", "num_eval_envs")


@dataclasses.dataclass(frozen=True)
class PPOConfig:
  """Everything that defines a run. ``validate()`` raises ``ValueError("name: ...")``.

  Batch layout (as in brax): each iteration collects ``num_rollouts =
  batch_size·num_minibatches / num_envs`` unrolls of ``unroll_length`` steps
  from all ``num_envs`` envs, i.e. ``batch_size·num_minibatches`` sequences of
  length ``unroll_length``; each of ``num_updates_per_batch`` epochs shuffles
  them into ``num_minibatches`` minibatches of ``batch_size`` sequences.

  Reward for the policy: ``(r_task − (w + λ)·cost) / (1 + λ)`` (train.iteration);
  λ ≡ 0 without ``budget``; with a budget λ follows ``multiplier``
  (train.multipliers: plain Lagrangian, lr ``lagrange_lr``; or PID with gains
  ``pid_kp``/``pid_ki``/``pid_kd``).
  """

  num_envs: int = 2048
  num_timesteps: int = 1_000_000
  episode_length: int = 200
  unroll_length: int = 10
  num_minibatches: int = 32
  num_updates_per_batch: int = 8
  batch_size: Optional[int] = 512  # sequences per minibatch; None → num_envs // num_minibatches
  learning_rate: float = 1e-3
  anneal_learning_rate: bool = False  # linear decay to 0 over num_timesteps
  clipping_epsilon: float = 0.2
  discounting: float = 0.97
  gae_lambda: float = 0.95
  entropy_cost: float = 2e-2
  # True: the entropy coefficient decays linearly from entropy_cost to 0 over num_timesteps (per
  # iteration, as anneal_learning_rate does the rate), so the policy's noise is no longer paid for by the
  # end and its mode and its samples can come together (docs/safe_rl.md, "How the failures end": tried on
  # Place Plate, it did not remove the mode's failures there).
  anneal_entropy: bool = False
  value_cost: float = 0.5  # brax's PPO loss weights the value term by 0.5 (the paper's coefficient)
  reward_scaling: float = 1.0
  max_grad_norm: Optional[float] = 1.0
  target_kl: Optional[float] = None  # stop an iteration's epochs early once the update's KL is too large
  # How ``target_kl`` stops the epochs. "minibatch" (SB3's rule): before any minibatch step whose KL
  # exceeds 1.5·target, so the first step is always taken. "epoch" (CleanRL's rule): at the end of an
  # epoch whose last minibatch began above the target, so a whole epoch is always taken. The paper's
  # table names the target, not the rule; with 512×2 nets at lr 1e-3 one Adam step already passes
  # 1.5·0.01, so the minibatch rule takes one step per iteration (docs/safe_rl.md).
  target_kl_rule: str = "minibatch"
  policy_hidden_sizes: tuple[int, ...] = (32, 32, 32, 32)
  value_hidden_sizes: tuple[int, ...] = (256, 256, 256, 256, 256)
  activation: str = "swish"
  init_log_std: Optional[tuple[float, float]] = None  # (arm, gripper = last action dim); None: brax's init
  # Where the policy's std comes from. "state": brax's tanh-normal head, the scale an output of the actor's
  # MLP (so it can differ per state). "parameter": one learned log-std per action dimension, the same in
  # every state (SB3's log_std_init, CleanRL's actor_logstd: what a table's "initial log-std" names).
  policy_std: str = "state"
  normalize_observations: bool = True
  # Bound on |normalised observation| (brax's ``running_statistics.normalize(max_abs_value=)``; SB3's
  # VecNormalize clip_obs). None: unbounded, brax's default. The normaliser floors a std at 1e-6, so a
  # coordinate the first rollouts left still (a box resting on a shelf) is divided by ~1e-6 once a policy moves
  # it: inputs of 10³–10⁷ on Shelve Item (benchmarks/obs_scale.py, docs/rl_task_design.md).
  obs_clip: Optional[float] = None
  # False: the observation normaliser keeps the statistics the run started with. For fine-tuning a
  # pre-trained actor (train(init_from=...)): its weights were fitted to those statistics, and
  # re-estimating them from the new rollouts changes what the actor computes before it has learned
  # anything (benchmarks/bc_finetune.py ablation, move_glass_of_water: 88–89 % vs 4–35 % completion at
  # the first evaluation, 81.4 % vs 100 % at the end; docs/IMITATION.md).
  update_normalizer: bool = True
  # True: the SGD epochs normalise with the statistics the rollout was collected under and this rollout is
  # folded into them afterwards (SB3's order: VecNormalize normalises when collecting), so PPO's ratio
  # starts at exactly 1. False: brax's order, statistics updated first. With 512-step rollouts the update
  # moved the policy 0.9–24 nats from the rollout's logits before any step
  # (benchmarks/results/paper_preset_sgd_steps_cpu.md), leaving the clipped ratio little to learn from.
  normalizer_after_update: bool = False
  # w: one number for every seed, or one per seed (a sequence as long as ``seeds``), so the rewards of a
  # contrast (task reward alone, w = 0, beside w = 2) train as runs of one program, as seeds do.
  damage_weight: float | tuple[float, ...] = 0.0
  # Penalty schedule: w is 0 (task reward alone) for the first ``damage_warmup_steps`` env steps per seed,
  # then rises linearly to ``damage_weight`` over ``damage_ramp_steps`` (0: at once). Why: where the unsafe
  # shortcut is what the dense reward leads to and the safe strategy is reached only through it (Shelve
  # Item), a penalty from step 0 punishes every move towards the goal before any completion has been seen.
  damage_warmup_steps: int = 0
  damage_ramp_steps: int = 0
  # > 0: the warm-up ends only once the task is being done — at the first iteration (past
  # ``damage_warmup_steps``) whose finished training episodes completed the task at least at this rate, per
  # seed; the ramp starts with the next iteration. Why: from scratch a penalty can stop the search before the
  # task is found (Pick Egg: the untrained policy damages the egg in 71 % of episodes and lifts it in none,
  # so w = 2 learns to keep still), and a fixed step count has to guess when each seed finds it.
  damage_warmup_completion: float = 0.0
  budget: Optional[float] = None
  multiplier: str = "lagrangian"
  lagrange_lr: float = 0.1
  lagrange_init: float = 0.0
  lagrange_max: float = 5.0
  # PID gains for episode costs of O(1–100) health points against ĉ ≈ 2: K_P·e answers a violation at
  # once; K_I = 0.01 needs Σe = λ_max/K_I = 500 to saturate, so a short costly start does not pin λ.
  pid_kp: float = 0.1
  pid_ki: float = 0.01
  pid_kd: float = 0.05
  # Budget curriculum (train.multipliers): the Lagrangian's budget falls linearly from the first measured
  # episode cost to ``budget`` over this many env steps per seed; 0: ``budget`` from the start.
  budget_anneal_steps: int = 0
  # Separate value estimates for task reward and cost, advantages mixed with the current λ
  # (train.constrained_loss) instead of one critic on the shaped reward.
  cost_critic: bool = False
  # GAE advantages and value targets computed once per iteration from the critic the rollout ended with,
  # and kept for every epoch (CleanRL, SB3, purejaxrl; train.iteration_targets). False: brax's loss,
  # which recomputes them at every minibatch step with the critic being trained (moving targets).
  gae_per_iteration: bool = False
  num_eval_envs: int = 128
  eval_every: int = 0  # env steps between evaluations; 0 → only at the end
  checkpoint_every: int = 0  # env steps between checkpoints; 0 → only at the end
  # First iterations in which only the critic learns (the actor is held): for a run started from a
  # pre-trained actor (train(init_from=...)), whose fresh critic would otherwise steer it with noise.
  critic_warmup_iterations: int = 0
  # Env steps per seed between fresh draws of every training env's start (initial state, task constants,
  # randomised damage parameters), cutting the episodes under way, as brax's ``ppo.train`` does with
  # ``num_resets_per_eval`` > 0 (our Brax runs of its Playground recipe: every 1–3 iterations). 0: never, so
  # each env replays the start of its first reset for the whole run (brax's AutoResetWrapper restores that
  # first state at every episode end): 2048 fixed starts per seed with the playground preset.
  redraw_starts_steps: int = 0
  seeds: tuple[int, ...] = (0,)

  @classmethod
  def preset(cls, name: str, **overrides) -> "PPOConfig":
    """A named preset (see the module docstring) with ``overrides`` applied; not validated yet."""
    if name not in PRESETS:
      raise ValueError(f"preset: unknown {name!r} (valid: {', '.join(PRESETS)})")
    fields = {f.name for f in dataclasses.fields(cls)}
    bad = sorted(set(overrides) - fields)
    if bad:
      raise ValueError(f"{bad[0]}: not a PPOConfig field (valid: {', '.join(sorted(fields))})")
    return cls(**{**PRESETS[name], **overrides})

  @property
  def lagrangian(self) -> bool:
    return self.budget is not None

  @property
  def damage_schedule_iterations(self) -> tuple[int, int]:
    """``(damage_warmup_steps, damage_ramp_steps)`` in iterations, rounded up."""
    per = self.steps_per_iteration
    return -(-self.damage_warmup_steps // per), -(-self.damage_ramp_steps // per)

  @property
  def redraw_starts_iterations(self) -> int:
    """``redraw_starts_steps`` in iterations (nearest, at least 1); 0 when off."""
    return self.interval_iterations(self.redraw_starts_steps)

  @property
  def budget_anneal_iterations(self) -> int:
    """``budget_anneal_steps`` in iterations (multiplier updates), rounded up; 0 when off."""
    return -(-self.budget_anneal_steps // self.steps_per_iteration)

  @property
  def num_seeds(self) -> int:
    return len(self.seeds)

  @property
  def damage_weights(self) -> tuple[float, ...]:
    """w of each seed's run, in the order of ``seeds``."""
    w = self.damage_weight
    return tuple(float(x) for x in w) if isinstance(w, (tuple, list)) else (float(w),) * self.num_seeds

  @property
  def minibatch_sequences(self) -> int:
    return self.batch_size if self.batch_size is not None else self.num_envs // self.num_minibatches

  @property
  def num_rollouts(self) -> int:
    return self.minibatch_sequences * self.num_minibatches // self.num_envs

  @property
  def steps_per_iteration(self) -> int:
    """Env steps of ONE seed per iteration."""
    return self.num_envs * self.unroll_length * self.num_rollouts

  @property
  def num_iterations(self) -> int:
    return max(1, math.ceil(self.num_timesteps / self.steps_per_iteration))

  @property
  def sgd_steps_per_iteration(self) -> int:
    return self.num_minibatches * self.num_updates_per_batch

  def interval_iterations(self, env_steps: int) -> int:
    """Iterations between two events every ``env_steps`` (0 → never, i.e. only at the end)."""
    if env_steps <= 0:
      return 0
    return max(1, round(env_steps / self.steps_per_iteration))

  def validate(self) -> "PPOConfig":
    def is_int(v):
      return not isinstance(v, bool) and isinstance(v, (int, np.integer))

    def pos_int(name):
      v = getattr(self, name)
      if not is_int(v) or v < 1:
        raise ValueError(f"{name}: must be a positive integer, got {v!r}")

    def number(name, lo=None, hi=None, lo_open=False, allow_none=False):
      v = getattr(self, name)
      if v is None and allow_none:
        return
      if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not math.isfinite(v):
        raise ValueError(f"{name}: must be a finite number, got {v!r}")
      if lo is not None and (v <= lo if lo_open else v < lo):
        raise ValueError(f"{name}: must be {'>' if lo_open else '>='} {lo}, got {v!r}")
      if hi is not None and v > hi:
        raise ValueError(f"{name}: must be <= {hi}, got {v!r}")

    for name in ("num_envs", "num_timesteps", "episode_length", "unroll_length", "num_minibatches",
                 "num_updates_per_batch", "num_eval_envs"):
      pos_int(name)
    if self.batch_size is not None:
      pos_int("batch_size")
    elif self.num_envs % self.num_minibatches:
      raise ValueError(f"num_envs: {self.num_envs} must be divisible by num_minibatches "
                       f"({self.num_minibatches}) when batch_size is not given")
    if (self.minibatch_sequences * self.num_minibatches) % self.num_envs:
      raise ValueError(f"num_envs: {self.num_envs} must divide batch_size·num_minibatches = "
                       f"{self.minibatch_sequences}·{self.num_minibatches}")
    for name in ("eval_every", "checkpoint_every", "critic_warmup_iterations", "redraw_starts_steps"):
      v = getattr(self, name)
      if not is_int(v) or v < 0:
        raise ValueError(f"{name}: must be an integer >= 0, got {v!r}")
    s = self.seeds
    if (not isinstance(s, (tuple, list)) or not s or any(not is_int(x) or x < 0 for x in s)
        or len(set(s)) != len(s)):
      hint = (" (runs are named by their seed: give the runs of each damage weight their own seeds, e.g. "
              "--seeds 0,1,2,3 --damage-weight 0,0,2,2)" if isinstance(self.damage_weight, (tuple, list)) else "")
      raise ValueError(f"seeds: a non-empty sequence of distinct integers >= 0, got {s!r}{hint}")
    number("learning_rate", lo=0, lo_open=True)
    number("clipping_epsilon", lo=0, lo_open=True)
    number("discounting", lo=0, hi=1)
    number("gae_lambda", lo=0, hi=1)
    number("entropy_cost", lo=0)
    number("value_cost", lo=0)
    number("reward_scaling", lo=0, lo_open=True)
    number("max_grad_norm", lo=0, lo_open=True, allow_none=True)
    number("obs_clip", lo=0, lo_open=True, allow_none=True)
    if self.obs_clip is not None and not self.normalize_observations:
      raise ValueError("obs_clip: bounds normalised observations; set normalize_observations too")
    number("target_kl", lo=0, lo_open=True, allow_none=True)
    if self.policy_std not in POLICY_STDS:
      raise ValueError(f"policy_std: one of {', '.join(POLICY_STDS)}, got {self.policy_std!r}")
    if self.target_kl_rule not in TARGET_KL_RULES:
      raise ValueError(f"target_kl_rule: one of {', '.join(TARGET_KL_RULES)}, got {self.target_kl_rule!r}")
    w = self.damage_weight
    if isinstance(w, (tuple, list)):
      if len(w) != len(s) or any(isinstance(x, bool) or not isinstance(x, (int, float, np.number))
                                 or not math.isfinite(x) or x < 0 for x in w):
        raise ValueError(f"damage_weight: one finite number >= 0, or one per seed ({len(s)} for seeds "
                         f"{list(s)}), got {w!r}")
    else:
      number("damage_weight", lo=0)
    penalised = max(self.damage_weights) > 0  # a schedule of w = 0 runs leaves them at 0
    for name in ("damage_warmup_steps", "damage_ramp_steps"):
      v = getattr(self, name)
      if not is_int(v) or v < 0:
        raise ValueError(f"{name}: must be an integer >= 0 (env steps per seed), got {v!r}")
      if v and not penalised:
        raise ValueError(f"{name}: schedules the damage weight; set damage_weight > 0 too (got {self.damage_weight!r})")
    number("damage_warmup_completion", lo=0, hi=1)
    if self.damage_warmup_completion and not penalised:
      raise ValueError("damage_warmup_completion: gates the damage weight's schedule; set damage_weight > 0 too "
                       f"(got {self.damage_weight!r})")
    number("budget", lo=0, allow_none=True)
    for name in ("lagrange_lr", "lagrange_init", "lagrange_max", "pid_kp", "pid_ki", "pid_kd"):
      number(name, lo=0)
    v = self.budget_anneal_steps
    if not is_int(v) or v < 0:
      raise ValueError(f"budget_anneal_steps: must be an integer >= 0 (env steps per seed), got {v!r}")
    if v and self.budget is None:
      raise ValueError("budget_anneal_steps: anneals the Lagrangian's budget; set budget too (got budget=None)")
    for name in ("cost_critic", "update_normalizer", "normalizer_after_update", "anneal_entropy", "gae_per_iteration"):
      if not isinstance(getattr(self, name), bool):
        raise ValueError(f"{name}: true or false, got {getattr(self, name)!r}")
    if self.multiplier not in MULTIPLIERS:
      raise ValueError(f"multiplier: one of {', '.join(MULTIPLIERS)}, got {self.multiplier!r}")
    for name in ("policy_hidden_sizes", "value_hidden_sizes"):
      v = getattr(self, name)
      if not isinstance(v, (tuple, list)) or not v or any(not is_int(h) or h < 1 for h in v):
        raise ValueError(f"{name}: must be a non-empty sequence of positive integers, got {v!r}")
    if self.activation not in ACTIVATION_NAMES:
      raise ValueError(f"activation: one of {', '.join(ACTIVATION_NAMES)}, got {self.activation!r}")
    v = self.init_log_std
    if v is not None and (not isinstance(v, (tuple, list)) or len(v) != 2 or any(
        isinstance(x, bool) or not isinstance(x, (int, float)) or not -10 <= x <= 2 for x in v)):
      raise ValueError(f"init_log_std: (arm, gripper) log-stds in [-10, 2], or None; got {v!r}")
    return self

  def to_json(self) -> dict:
    d = dataclasses.asdict(self)
    for k in ("policy_hidden_sizes", "value_hidden_sizes", "seeds", "init_log_std", "damage_weight"):
      if isinstance(d[k], (tuple, list)):
        d[k] = list(d[k])
    return d

  @classmethod
  def from_json(cls, d: dict) -> "PPOConfig":
    d = dict(d)
    if "seeds" not in d and "seed" in d:  # checkpoints written before the seed axis
      d["seeds"] = [d.pop("seed")]
    for k in ("policy_hidden_sizes", "value_hidden_sizes", "seeds", "init_log_std", "damage_weight"):
      if isinstance(d.get(k), list):
        d[k] = tuple(d[k])
    names = {f.name for f in dataclasses.fields(cls)}
    # Older checkpoints lack the newer fields: they ran with what these were then.
    old = {"anneal_learning_rate": False, "target_kl": None, "init_log_std": None, "multiplier": "lagrangian",
           "value_cost": 0.5, "budget_anneal_steps": 0,
           "cost_critic": False, "update_normalizer": True, "normalizer_after_update": False,
           "target_kl_rule": "minibatch", "policy_std": "state", "anneal_entropy": False,
           "redraw_starts_steps": 0, "obs_clip": None, "gae_per_iteration": False}
    return cls(**{**old, **{k: v for k, v in d.items() if k in names}})


_PLAYGROUND = dict(
    num_envs=2048, unroll_length=10, num_minibatches=32, batch_size=512, num_updates_per_batch=8,
    learning_rate=1e-3, entropy_cost=2e-2, discounting=0.97, gae_lambda=0.95, clipping_epsilon=0.3,
    reward_scaling=1.0, max_grad_norm=1.0, policy_hidden_sizes=(32, 32, 32, 32),
    value_hidden_sizes=(256, 256, 256, 256, 256), activation="swish", normalize_observations=True)
_PAPER = dict(
    num_envs=256, unroll_length=512, num_minibatches=8, batch_size=None, num_updates_per_batch=10,
    learning_rate=1e-3, anneal_learning_rate=True, clipping_epsilon=0.2, entropy_cost=0.0, value_cost=0.5,
    max_grad_norm=0.5, target_kl=0.01, discounting=0.99, gae_lambda=0.95, reward_scaling=1.0,
    policy_hidden_sizes=(512, 512), value_hidden_sizes=(512, 512), activation="tanh",
    init_log_std=(-0.5, -1.5), normalize_observations=True, normalizer_after_update=True)
_LEGACY = dict(
    num_envs=1024, unroll_length=20, num_minibatches=8, batch_size=None, num_updates_per_batch=4,
    learning_rate=3e-4, entropy_cost=1e-3, discounting=0.97, gae_lambda=0.95, clipping_epsilon=0.2,
    max_grad_norm=1.0, policy_hidden_sizes=(256, 256), value_hidden_sizes=(256, 256), activation="swish")
PRESETS: dict[str, dict] = {"playground": _PLAYGROUND, "paper": _PAPER, "legacy": _LEGACY}

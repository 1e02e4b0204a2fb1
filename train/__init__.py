"""Training: PPO, PPO-Lagrangian and PID-Lagrangian on damage-aware tasks, S seeds in one program.

``train.train(task, seeds=(0, 1, 2), ...)`` runs a training job (:mod:`train.ppo`);
``train.load_policy(path, seed=None)`` gives back a trained policy as
``policy(state, rng) -> action`` for one env; ``train.evaluate_policy(task, policy,
num_episodes=...)`` evaluates it. Modules: ``config`` (PPOConfig, presets),
``networks``, ``multipliers``, ``iteration`` (one seed's pure iteration), ``ppo``
(the run loop), ``policy``, ``checkpoint``, ``plots``, ``cli``.

``train.evaluate`` is always the evaluation module (:mod:`train.evaluate`:
``Evaluator``, ``metrics``, ``evaluate(env, ...)``); this package exports no
function of that name. ``evaluate_policy`` lives in :mod:`train.task_eval`.
"""

from train import evaluate  # noqa: F401  (the module, bound before anything can shadow it)
from train.config import PRESETS, PPOConfig  # noqa: F401
from train.task_eval import evaluate_policy  # noqa: F401
from train.iteration import Trainer, TrainState  # noqa: F401
from train.multipliers import lagrange_update, pid_update  # noqa: F401
from train.policy import load_policy  # noqa: F401
from train.ppo import TrainResult, resolve_task, train  # noqa: F401

__all__ = ["PPOConfig", "PRESETS", "TrainResult", "TrainState", "Trainer", "evaluate_policy", "lagrange_update",
           "load_policy", "pid_update", "resolve_task", "train"]

"""Training: PPO and PPO-Lagrangian on damage-aware tasks (see :mod:`train.ppo`).

``train.train(task, ...)`` runs a training job; ``train.load_policy(path)``
gives back the trained policy as ``policy(state, rng) -> action`` for one env;
``train.evaluate_policy(task, policy, num_episodes=...)`` evaluates it.

``train.evaluate`` is always the evaluation module (:mod:`train.evaluate`:
``Evaluator``, ``metrics``, ``evaluate(env, ...)``); this package exports no
function of that name. ``evaluate_policy`` lives in :mod:`train.task_eval`.
"""

from train import evaluate  # noqa: F401  (the module, bound before anything can shadow it)
from train.task_eval import evaluate_policy  # noqa: F401
from train.ppo import (  # noqa: F401
    PPOConfig,
    TrainResult,
    Trainer,
    lagrange_update,
    load_policy,
    resolve_task,
    train,
)

__all__ = ["PPOConfig", "TrainResult", "Trainer", "evaluate_policy", "lagrange_update", "load_policy",
           "resolve_task", "train"]

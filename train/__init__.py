"""Training: PPO and PPO-Lagrangian on damage-aware tasks (see :mod:`train.ppo`).

``train.train(task, ...)`` runs a training job; ``train.load_policy(path)``
gives back the trained policy as ``policy(state, rng) -> action`` for one env.
"""

from train.ppo import (  # noqa: F401
    PPOConfig,
    TrainResult,
    Trainer,
    evaluate,
    lagrange_update,
    load_policy,
    resolve_task,
    train,
)

__all__ = ["PPOConfig", "TrainResult", "Trainer", "evaluate", "lagrange_update", "load_policy",
           "resolve_task", "train"]

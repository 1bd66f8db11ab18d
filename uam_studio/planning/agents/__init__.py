"""DQN agents: the masked networks (:mod:`.dqn`), training and the agent file format (:mod:`.training`),
retraining in a background process (:mod:`.retrain`), the grouped vector env (:mod:`.vec_env`),
learning curves (:mod:`.learning_curves`) and the agent as a planner (:mod:`.rollout`).

The only room of :mod:`uam_studio.planning` that imports torch and stable-baselines3 (an
import-linter contract in pyproject.toml). The names a notebook or a script needs are exported here
and imported when first used, so that importing this package (and :mod:`.retrain` and :mod:`.rollout`)
stays torch-free for the CLI and the app.
"""

import importlib

_LAZY = {
    "DQNTrainConfig": "training",
    "train_dqn": "training",
    "retrain_dqn": "retrain",
    "training_setup": "retrain",
    "bundled_agent_path": "rollout",
    "rollout_agent": "rollout",
    "episode_columns": "learning_curves",
    "moving_average": "learning_curves",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f"uam_studio.planning.agents.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'uam_studio.planning.agents' has no attribute {name!r}")

"""DQN agents: the masked networks (:mod:`.dqn`), training and the agent file format (:mod:`.training`),
retraining in a background process (:mod:`.retrain`), the grouped vector env (:mod:`.vec_env`),
learning curves (:mod:`.learning_curves`) and the agent as a planner (:mod:`.rollout`).

The only room of :mod:`uam_studio.planning` that imports torch and stable-baselines3 (an
import-linter contract in pyproject.toml). The names a notebook or a script needs are exported here
and imported when first used, so that importing this package (and :mod:`.retrain` and :mod:`.rollout`)
stays torch-free for the CLI and the app.
"""

from uam_studio.lazy_exports import lazy_getattr

_LAZY = {
    "DQNTrainConfig": "uam_studio.planning.agents.training",
    "train_dqn": "uam_studio.planning.agents.training",
    "retrain_dqn": "uam_studio.planning.agents.retrain",
    "training_setup": "uam_studio.planning.agents.retrain",
    "bundled_agent_path": "uam_studio.planning.agents.rollout",
    "rollout_agent": "uam_studio.planning.agents.rollout",
    "episode_columns": "uam_studio.planning.agents.learning_curves",
    "moving_average": "uam_studio.planning.agents.learning_curves",
    "EpisodeRecorder": "uam_studio.planning.agents.learning_curves",
}

__all__ = sorted(_LAZY)


__getattr__ = lazy_getattr(__name__, _LAZY)

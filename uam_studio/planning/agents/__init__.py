"""The learned planners: the attention planner (:mod:`.attention`, the default) and the paper's masked DQN
(:mod:`.dqn`), one folder each; retraining either in a background process and keeping retrained agents
(:mod:`.retrain`, :mod:`.run_result`), and the grouped subprocess vector env DQN training steps
(:mod:`.vec_env`).

The only room of :mod:`uam_studio.planning` that imports torch and stable-baselines3 (an
import-linter contract in pyproject.toml). The names a notebook or a script needs are exported here
and imported when first used, so that importing this package (and :mod:`.retrain` and
:mod:`.dqn.rollout`) stays torch-free for the CLI and the app.
"""

from uam_studio.lazy_exports import lazy_getattr

_DQN = ("DQNTrainConfig", "train_dqn", "bundled_agent_path", "rollout_agent", "episode_columns", "moving_average",
        "EpisodeRecorder")  # where each comes from: uam_studio.planning.agents.dqn's own exports
_LAZY = {
    **{name: "uam_studio.planning.agents.dqn" for name in _DQN},
    "retrain_dqn": "uam_studio.planning.agents.retrain",
    "training_setup": "uam_studio.planning.agents.retrain",
}

__all__ = sorted(_LAZY)


__getattr__ = lazy_getattr(__name__, _LAZY)

"""The paper's planner: a DQN with action masking on stable-baselines3, one folder as SB3 keeps one per
algorithm.

- :mod:`.masked`: :class:`MaskedDQN` (SB3's DQN with the mask in exploration, warm-up and the bootstrap
  target), :func:`greedy_action`, :func:`ranked_actions`;
- :mod:`.training`: :class:`DQNTrainConfig` and :func:`train_dqn`;
- :mod:`.agent_file`: :func:`save_agent` (atomic, with its model card inside the zip) and
  :func:`load_agent` (no unpickling);
- :mod:`.rollout`: the agent as a planner (:func:`rollout_agent`, :func:`bundled_agent_path`);
- :mod:`.learning_curves`: what a training run's episodes did.

Importing this package imports neither torch nor stable-baselines3: each name is read from its module
when first used.
"""

from uam_studio.lazy_exports import lazy_getattr

_LAZY = {
    "MaskedDQN": "uam_studio.planning.agents.dqn.masked",
    "greedy_action": "uam_studio.planning.agents.dqn.masked",
    "ranked_actions": "uam_studio.planning.agents.dqn.masked",
    "DQNTrainConfig": "uam_studio.planning.agents.dqn.training",
    "train_dqn": "uam_studio.planning.agents.dqn.training",
    "load_agent": "uam_studio.planning.agents.dqn.agent_file",
    "save_agent": "uam_studio.planning.agents.dqn.agent_file",
    "bundled_agent_path": "uam_studio.planning.agents.dqn.rollout",
    "rollout_agent": "uam_studio.planning.agents.dqn.rollout",
    "EpisodeRecorder": "uam_studio.planning.agents.dqn.learning_curves",
    "episode_columns": "uam_studio.planning.agents.dqn.learning_curves",
    "moving_average": "uam_studio.planning.agents.dqn.learning_curves",
}

__all__ = sorted(_LAZY)
__getattr__ = lazy_getattr(__name__, _LAZY)

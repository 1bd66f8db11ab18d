"""DQN agents: the masked networks (:mod:`.dqn`), training and the agent file format (:mod:`.training`),
retraining in a background process (:mod:`.retrain`), the grouped vector env (:mod:`.vec_env`),
learning curves (:mod:`.learning_curves`) and the agent as a planner (:mod:`.rollout`).

The only room of :mod:`uam_studio.planning` that imports torch and stable-baselines3 (an
import-linter contract in pyproject.toml). Nothing is imported here: :mod:`.retrain` and
:mod:`.rollout` stay torch-free at import time for the CLI and the app.
"""

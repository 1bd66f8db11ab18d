"""The Retrain tab: train a DQN agent or an attention planner with live learning curves. :mod:`.state`
(:class:`~uam_studio.app.retrain.state.RetrainState`) and :mod:`.view`."""

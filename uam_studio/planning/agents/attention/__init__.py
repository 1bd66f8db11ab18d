"""The attention planner: one network for maps of 1-20 destinations (features, model, decode, train)."""

"""The attention planner: one network for maps of 1-20 destinations (features, model, decode, train).

Nothing that imports torch is imported here, so the planner, the CLI and the app can name the weights
file without loading torch.
"""

WEIGHTS_NAME = "attention_planner.pt"  # the weights file, bundled (uam_studio.bundled) and written by training

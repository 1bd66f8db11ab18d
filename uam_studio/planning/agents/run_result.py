"""What a retraining run produced (a DQN agent or an attention planner), shared by both kinds of run."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["RetrainResult"]


@dataclass
class RetrainResult:
    """What a retraining run produced: the saved file and its model card.

    :param path: the agent zip (DQN) or the weights file (attention planner).
    :param episodes: episodes played (DQN) or epochs done (attention planner).
    :param timesteps: environment transitions (DQN) or epochs done (attention planner).
    :param stopped: stopped early by the stop event.
    :param model: the trained model (in the process that trained it; None across processes).
    """

    path: Path
    card: dict[str, Any]
    episodes: int
    timesteps: int
    stopped: bool
    model: Any = field(repr=False, default=None)

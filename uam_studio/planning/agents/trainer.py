"""What retraining asks of a learned planner: its :class:`Trainer`, named by the planner's entry in
:data:`~uam_studio.planning.planners.PLANNERS` (``trainer="module:Class"``, imported when first used).

:mod:`uam_studio.planning.agents.retrain` (the user's agents folder, a run in a child process), the app's
Retrain tab and ``uam-studio train`` read a planner's trainer through :func:`trainer` and :func:`trainers`;
none of them names a planner.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from uam_studio.errors import InputError
from uam_studio.planning.agents.run_result import RetrainResult
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.planners import PLANNERS

__all__ = ["SHARED_CLI_OPTIONS", "AgentFile", "TrainJob", "Trainer", "trainer", "trainers"]

# the options of ``uam-studio train`` that several models read (their own options are each model's);
# ``seed`` is every model's
SHARED_CLI_OPTIONS = ("out", "steps", "device", "init_from")


@dataclass(frozen=True)
class AgentFile:
    """A retrained agent file found in a folder: its path, name, scenario (None: every scenario), model card
    and modification time (s since the epoch)."""

    path: Path
    name: str
    scenario: str | None
    card: dict[str, Any] = field(repr=False)
    mtime: float = 0.0


@dataclass(frozen=True)
class TrainJob:
    """One run, set up and validated: where it saves (``path``), the map it trains on or is scored on
    (``mission``), its ``setup`` (:class:`~uam_studio.planning.agents.retrain.RetrainProcess`'s keywords), its
    progress ``target`` (DQN: environment steps; attention: missions solved by the oracle + epochs),
    ``epochs`` (0: a run counted in steps), a ``status`` sentence, and ``run(on_item, on_progress,
    stop_event)``: the run in this process."""

    path: Path
    mission: Mission | None
    setup: dict[str, Any]
    target: int
    status: str
    run: Callable[[Callable[[Any], Any], Callable[[str, int, int], Any], threading.Event], RetrainResult | None]
    epochs: int = 0


class Trainer(Protocol):
    """How a learned planner is retrained and how its retrained files are found.

    ``planner``: its planner's name (and its cards' ``"model"``); ``unit``: what each report of a run counts
    (``"episode"`` or ``"epoch"``); ``settings``: the Retrain tab's settings it reads besides ``scenario``,
    ``seed`` and where it starts from; ``trains_on_map``: a run on a map learns that map (else the map only
    scores each report). ``uam-studio train <planner>``: ``cli_title``, the title of its own options in
    ``--help``; ``cli_shared``, which of :data:`SHARED_CLI_OPTIONS` it reads, each with what it means for it.
    """

    planner: str
    unit: str
    settings: tuple[str, ...]
    trains_on_map: bool
    cli_title: str
    cli_shared: dict[str, str]

    def add_cli_arguments(self, group: Any) -> tuple[str, ...]:
        """Add its own options of ``uam-studio train`` to the argparse argument ``group`` (each defaulting to
        None: not given); the names (``dest``) of those options."""
        ...

    def train_cli(self, args: Any) -> str:
        """``uam-studio train``'s full run from the parsed options (``seed``, its :attr:`cli_shared` and its
        own options), saved into a run folder, never into the bundled one. Bad options raise
        :class:`~uam_studio.errors.InputError` (field: the option) before any work; returns the line printed."""
        ...

    def find(self, folder: Path) -> list[AgentFile]:
        """Its retrained files in ``folder`` (unreadable ones skipped)."""
        ...

    def describe(self, card: dict[str, Any], scenario: str | None) -> list[str | None]:
        """What a card says was learned, as label parts (None parts are left out)."""
        ...

    def owns(self, path: Path) -> bool:
        """``path`` is one of its agent files (by its name)."""
        ...

    def agent_name(self, path: Path) -> str:
        """The name the app shows for the agent file ``path``."""
        ...

    def bundled_init(self, scenario: str) -> str:
        """The bundled file a fine-tuning of a ``scenario`` mission starts from."""
        ...

    def check(self, mission: Mission | None, setup: dict[str, Any]) -> Any:
        """Validate a run's ``setup`` (raises :class:`~uam_studio.errors.InputError`); its config."""
        ...

    def job(self, values: dict[str, Any], mission: Mission | None, init_agent: str | None, source: str) -> TrainJob:
        """A run of the Retrain tab: ``values`` holds ``scenario``, ``seed`` and its :attr:`settings`; it
        trains on (or scores on) ``mission`` (None: random missions), from ``init_agent`` (None: random
        weights). Raises :class:`~uam_studio.errors.InputError` for bad settings."""
        ...

    def run(self, setup: dict[str, Any], agent_path: Path, mission: Mission | None,
            on_item: Callable[[Any], Any], on_progress: Callable[[str, int, int], Any],
            stop_event: threading.Event | Any, source: str | None) -> RetrainResult | None:
        """Train and save to ``agent_path``, reporting each ``unit`` to ``on_item``; None: stopped before
        the first, nothing saved."""
        ...


def trainers() -> dict[str, Trainer]:
    """Every retrainable planner's trainer, by planner name, in :data:`PLANNERS`' order."""
    return {name: cls() for name, info in PLANNERS.items() if (cls := info.trainer_class()) is not None}


def trainer(name: str, field: str = "kind") -> Trainer:
    """The trainer of the planner ``name``.

    :raises InputError: (field ``field``) a planner that cannot be retrained, listing those that can.
    """
    found = trainers()
    if name not in found:
        raise InputError(field, f"{name!r}: allowed {', '.join(found)}")
    return found[name]

"""Retraining the attention planner from the app: a short run, watched on one map, saved in the user folder.

Shared by the app's Retrain tab (through ``planning.agents.retrain.RetrainProcess``)
and by tests; ``uam-studio train attention`` runs the full recipe of
:mod:`uam_studio.planning.agents.attention.train`.

- :func:`attention_setup`: validate a short run's settings and build its
  :class:`~uam_studio.planning.agents.attention.train.AttentionTrainConfig` (imitation of the exact
  oracle on random missions of :data:`CLASS_DEST` destinations, one worker, no phase 2);
- :func:`map_score`: the score of the network so far on one map (its plan, checked on the physics
  model; an unsafe plan scores 0), the run's learning curve;
- :func:`new_attention_folder`: a fresh folder for a run's weights in the user's agents folder;
- :func:`retrain_attention`: train, watch, save (never into the bundled ``pretrained/`` folder);
- :class:`AttentionTrainer`: what :mod:`uam_studio.planning.agents.retrain` asks of the attention planner
  (its :class:`~uam_studio.planning.agents.trainer.Trainer`).
"""

from __future__ import annotations

import datetime
import json
import os
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from uam_studio.atomic_io import make_writable_folder
from uam_studio.bundled import agents_dir, refuse_bundled
from uam_studio.errors import InputError
from uam_studio.planning.agents.run_result import RetrainResult
from uam_studio.planning.agents.trainer import AgentFile, TrainJob
from uam_studio.planning.missions.mission import Mission, mission_to_dict

__all__ = ["CLASS_DEST", "CLASS_EPOCHS", "CLASS_MISSIONS", "AttentionTrainer", "attention_setup", "map_score",
           "new_attention_folder", "retrain_attention"]

CLASS_MISSIONS = 150  # training missions of a class run (each solved by the exact oracle: ~0.3 s on one core)
CLASS_EPOCHS = 20
CLASS_DEST = (2, 6)  # destinations per training mission: the exact oracle's time grows fast above 6
MISSIONS_RANGE = (10, 5000)
EPOCHS_RANGE = (1, 500)


def _count(name: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(name, f"{value!r} is out of range; allowed integers in [{lo}, {hi}]")
    return value


def attention_setup(missions: int = CLASS_MISSIONS, epochs: int = CLASS_EPOCHS, seed: int = 0) -> Any:
    """The :class:`~uam_studio.planning.agents.attention.train.AttentionTrainConfig` of a class run.

    :param missions: training missions, solved by the exact oracle, in [10, 5000].
    :param epochs: passes over their decisions, in [1, 500].
    :param seed: the training missions' seed (``[seed, k]``; never a held-out seed), >= 0.
    :raises InputError: a setting out of range.
    """
    from uam_studio.planning.agents.attention.train import AttentionTrainConfig

    _count("missions", missions, *MISSIONS_RANGE)
    _count("epochs", epochs, *EPOCHS_RANGE)
    _count("seed", seed, 0, 2**31 - 1)
    return AttentionTrainConfig(seed=seed, oracle_missions=missions, oracle_dest=CLASS_DEST, epochs=epochs,
                                search_missions=0, workers=1, device="cpu")


def _scored(plan: Any) -> tuple[int, bool, float | None]:
    """A plan's reached priority (0 if unsafe), safety and lowest voltage (V) on the physics model."""
    check = plan.check
    safe = bool(check is not None and check.safe)
    low = check.min_voltage_v if check is not None else None
    return (int(plan.reached_priority) if safe else 0), safe, (float(low) if low is not None else None)


def map_score(mission: Mission) -> Callable[[Any], dict[str, Any]]:
    """A function that scores a network on ``mission``: ``{"priority", "safe", "min_voltage_v"}`` of
    its plan with the Planner's own search
    (:func:`~uam_studio.planning.agents.attention.decode.attention_plan`: beams and the physics
    filter), and ``"priority_net"`` of the network's first choice at every step (beam width 1, no
    filter): what the network itself has learned, which the search hides. Priorities are reached
    priority on the physics model, 0 for an unsafe plan; V."""
    from uam_studio.planning.agents.attention.decode import attention_plan

    def score(net: Any) -> dict[str, Any]:
        priority, safe, low = _scored(attention_plan(mission, net))
        alone, _, _ = _scored(attention_plan(mission, net, beam_width=1, safety_filter=False))
        return {"priority": priority, "safe": safe, "min_voltage_v": low, "priority_net": alone}

    return score


def new_attention_folder(source: str, folder: str | os.PathLike[str] | None = None) -> Path:
    """A fresh folder ``attention-<source>-<UTC time>`` in ``folder`` (default: the user's agents folder)."""
    d = Path(folder) if folder is not None else agents_dir()
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%d-%H%M%S")
    base = "".join(c if c.isalnum() or c in "_.-" else "_" for c in f"attention-{source}-{stamp}")
    p, k = d / base, 1
    while p.exists():
        k += 1
        p = d / f"{base}-{k}"
    return p


def retrain_attention(config: Any, folder: str | os.PathLike[str], mission: Mission | None = None,
                      on_epoch: Callable[[Any], Any] | None = None,
                      on_progress: Callable[[str, int, int], Any] | None = None,
                      stop_event: threading.Event | None = None, source: str | None = None,
                      init_weights: str | os.PathLike[str] | None = None) -> Any:
    """Train the attention planner (:func:`~uam_studio.planning.agents.attention.train.train_attention`)
    into ``folder``.

    :return: a :class:`~uam_studio.planning.agents.run_result.RetrainResult` (``path``: the weights file;
        ``episodes`` and ``timesteps``: the epochs done), or None: stopped before the first epoch,
        nothing saved.

    :param mission: the map each epoch's network is scored on (:func:`map_score`; recorded in the
        card), or None for no score.
    :param init_weights: fine-tune this weights file (e.g. the bundled planner) instead of random weights.
    :raises InputError: ``folder`` inside ``pretrained/``; unreadable ``init_weights``.
    """
    from uam_studio.planning.agents.attention import WEIGHTS_NAME
    from uam_studio.planning.agents.attention.train import train_attention

    out = Path(folder)
    refuse_bundled(out, "agent_path")
    refuse_bundled(out / WEIGHTS_NAME, "agent_path")
    extra = {"source": source, "watched_map": mission_to_dict(mission) if mission is not None else None}
    weights = train_attention(replace(config), out, log=lambda _line: None, on_epoch=on_epoch,
                              evaluate=map_score(mission) if mission is not None else None,
                              on_progress=on_progress, stop_event=stop_event, init_weights=init_weights,
                              card_extra=extra)
    if weights is None:
        return None
    card = json.loads((out / "card.json").read_text())
    done = int(card["stats"]["epochs_done"])
    return RetrainResult(weights, card, done, done, bool(card["stopped_early"]))


class AttentionTrainer:
    """The attention planner's :class:`~uam_studio.planning.agents.trainer.Trainer`: a folder per run holding
    ``attention_planner.pt`` and its ``card.json``, one report per epoch. ``setup``: ``missions``,
    ``epochs``, ``seed`` of :func:`attention_setup` and ``init_agent`` (a weights file to start from)."""

    planner = "attention"
    unit = "epoch"
    settings = ("missions", "epochs")
    trains_on_map = False
    cli_title = "attention only (the default planner)"
    cli_shared = {
        "out": "default runs/attention, writes attention_planner.pt and card.json",
        "device": "auto (CUDA when available, default), cpu or cuda",
    }

    def add_cli_arguments(self, group: Any) -> tuple[str, ...]:
        return tuple(action.dest for action in (
            group.add_argument("--oracle-missions", type=int, default=None,
                               help="phase 1: missions of 2-8 destinations solved by the exact oracle "
                                    "(default 1200)"),
            group.add_argument("--search-missions", type=int, default=None,
                               help="phase 2: missions of 9-20 destinations per scenario planned by the "
                                    "network's own beam search (default 300; 0 skips the phase)"),
            group.add_argument("--epochs", type=int, default=None, help="phase 1 epochs (default 40)"),
        ))

    def train_cli(self, args: Any) -> str:
        """The full recipe of :func:`~uam_studio.planning.agents.attention.train.train_attention`."""
        from uam_studio.dynaformer.train import pick_device
        from uam_studio.planning.agents.attention.train import AttentionTrainConfig, train_attention

        out = Path(args.out or "runs/attention")
        refuse_bundled(out, "--out")
        cfg = AttentionTrainConfig(seed=args.seed)
        cfg.device = str(pick_device(args.device or "auto"))
        for name, lo in (("oracle_missions", 10), ("search_missions", 0), ("epochs", 1)):
            value = getattr(args, name)
            if value is not None:
                if value < lo:
                    raise InputError(f"--{name.replace('_', '-')}", f"must be >= {lo}")
                setattr(cfg, name, value)
        make_writable_folder(out, "--out")
        return f"wrote {train_attention(cfg, out)}"

    def _card(self, weights: Path) -> dict[str, Any] | None:
        """The card (``card.json``) beside an attention planner's weights, or None if it is not one."""
        try:
            card = json.loads((weights.parent / "card.json").read_text())
        except (OSError, ValueError):
            return None
        return card if isinstance(card, dict) and card.get("model") == self.planner else None

    def find(self, folder: Path) -> list[AgentFile]:
        """The attention planners (``*/attention_planner.pt`` with a ``card.json`` of model ``attention``
        beside it) in ``folder``."""
        from uam_studio.planning.agents.attention import WEIGHTS_NAME

        out = []
        for p in folder.glob(f"*/{WEIGHTS_NAME}"):
            card = self._card(p)
            try:
                mtime = p.stat().st_mtime
            except OSError:
                continue
            if card is not None:
                out.append(AgentFile(p, p.parent.name, None, card, mtime))
        return out

    def describe(self, card: dict[str, Any], scenario: str | None) -> list[str | None]:
        done = (card.get("stats") or {}).get("epochs_done")
        return ["attention", f"{done} epoch{'' if done == 1 else 's'}" if isinstance(done, int) else None]

    def owns(self, path: Path) -> bool:
        return path.suffix == ".pt"

    def agent_name(self, path: Path) -> str:
        return path.parent.name

    def bundled_init(self, scenario: str) -> str:
        from uam_studio.planning.agents.attention.decode import bundled_weights_path

        return str(bundled_weights_path())

    def check(self, mission: Mission | None, setup: dict[str, Any]) -> Any:
        return attention_setup(**{k: v for k, v in setup.items() if k != "init_agent"})

    def job(self, values: dict[str, Any], mission: Mission | None, init_agent: str | None, source: str) -> TrainJob:
        from uam_studio.planning.agents.attention import WEIGHTS_NAME

        cfg = attention_setup(values["missions"], values["epochs"], values["seed"])
        if mission is not None and mission.scenario != values["scenario"]:  # scored in this run's scenario
            mission = replace(mission, scenario=values["scenario"])
        folder = new_attention_folder("map" if mission is not None else "random")
        verb = "fine-tuning the bundled attention planner" if init_agent else "training the attention planner"

        def run(on_item: Callable[[Any], Any], on_progress: Callable[[str, int, int], Any],
                stop_event: threading.Event) -> RetrainResult | None:
            return retrain_attention(cfg, folder, mission=mission, on_epoch=on_item, on_progress=on_progress,
                                     stop_event=stop_event, source=source, init_weights=init_agent)

        score = "scored on the current map after each epoch" if mission is not None else "not scored on a map"
        return TrainJob(path=folder / WEIGHTS_NAME, mission=mission, target=cfg.oracle_missions + cfg.epochs,
                        epochs=cfg.epochs, run=run,
                        setup={"missions": values["missions"], "epochs": values["epochs"], "seed": values["seed"],
                               "init_agent": init_agent},
                        status=f"{verb}: {cfg.epochs} epochs on {cfg.oracle_missions} random missions of "
                               f"{cfg.oracle_dest[0]}-{cfg.oracle_dest[1]} destinations solved by the exact oracle, "
                               f"{score}")

    def run(self, setup: dict[str, Any], agent_path: Path, mission: Mission | None,
            on_item: Callable[[Any], Any], on_progress: Callable[[str, int, int], Any],
            stop_event: threading.Event | Any, source: str | None) -> RetrainResult | None:
        setup = dict(setup)
        init = setup.pop("init_agent", None)
        return retrain_attention(attention_setup(**setup), Path(agent_path).parent, mission=mission,
                                 on_epoch=on_item, on_progress=on_progress, stop_event=stop_event, source=source,
                                 init_weights=init)

"""Retraining the paper's DQN agent: its settings, its run and its card, and its :class:`DQNTrainer`.

Shared by ``uam-studio train dqn`` (:meth:`DQNTrainer.train_cli`) and the app's Retrain tab:

- :func:`training_setup`: validate the settings and build the :class:`DQNTrainConfig` and the env
  factory (a fixed map with a random cell each episode, or a random mission every episode);
- :func:`retrain_dqn`: train (stoppable, streaming :class:`EpisodeStats`), build the model card and
  save the agent atomically (never into the bundled ``pretrained/`` folder);
- :class:`DQNTrainer`: what :mod:`uam_studio.planning.agents.retrain` asks of the DQN (its
  :class:`~uam_studio.planning.agents.trainer.Trainer`).
"""

from __future__ import annotations

import datetime
import os
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from uam_studio.atomic_io import make_writable_folder, remove_stale_temps
from uam_studio.bundled import agents_dir, refuse_bundled
from uam_studio.errors import InputError, check_range
from uam_studio.planning.agents.run_result import RetrainResult
from uam_studio.planning.agents.trainer import AgentFile, TrainJob
from uam_studio.planning.env.environment import REWARD_DEFAULTS
from uam_studio.planning.missions.mission import SCENARIOS, Mission, load_mission, mission_to_dict
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO, check_scenario

__all__ = ["DQN_REWARD_DEFAULTS", "DQNTrainer", "new_agent_path", "retrain_dqn", "training_setup"]

DQN_REWARD_DEFAULTS = REWARD_DEFAULTS  # the paper's figures (UAMPlanningEnv's defaults)
STATS_WINDOW = 100  # final_stats average the last 100 episodes
MAX_STEPS = 10_000_000


_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def new_agent_path(scenario: str, source: str, folder: str | os.PathLike[str] | None = None) -> Path:
    """A fresh file name ``<scenario>-<source>-<UTC time>.zip`` in ``folder`` (default: the user's agents folder)."""
    d = Path(folder) if folder is not None else agents_dir()
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%d-%H%M%S")
    base = _SAFE.sub("_", f"{scenario}-{source}-{stamp}")
    p, k = d / f"{base}.zip", 1
    while p.exists():
        k += 1
        p = d / f"{base}-{k}.zip"
    return p


def training_setup(
    scenario: str | None = None,
    mission: Mission | None = None,
    alpha: float | None = None,
    beta: float | None = None,
    gamma: float | None = None,
    steps: int | None = None,
    seed: int = 0,
    safe_return: bool = False,
    init_agent: str | os.PathLike[str] | None = None,
) -> tuple[Any, Callable[[], Any]]:
    """Validate the settings of a DQN retraining and build ``(DQNTrainConfig, env_fn)``.

    :param scenario: default: the mission's, else ``single_charge``.
    :param mission: train on this map (the cell's q_max and R0 drawn at random each episode), or
        None for a random mission every episode.
    :param alpha: reward weight of a destination's priority (default :data:`DQN_REWARD_DEFAULTS`), in [0, 1e6].
    :param beta: penalty of a charging stop (default :data:`DQN_REWARD_DEFAULTS`), in [0, 1e6].
    :param gamma: penalty of an end of discharge (default :data:`DQN_REWARD_DEFAULTS`), in [0, 1e6].
    :param steps: env transitions (default: :class:`DQNTrainConfig`'s), in [1, 1e7].
    :param safe_return: train with the environment's ``safe_return`` rule (a leg that would leave
        no way home ends the episode with ``-gamma``); off is the paper's setting.
    :param init_agent: fine-tune this agent (zip) instead of starting from random weights: its
        network is copied in and exploration starts at :data:`~uam_studio.planning.agents.dqn.training.FINE_TUNE`
        settings (epsilon 0.2, not 1).
    :raises InputError: bad settings, or a map the environment cannot use (no destinations, more
        than 8, none far enough from the vertiport).
    """
    from uam_studio.planning.agents.dqn.training import DQNTrainConfig, fine_tuning
    from uam_studio.planning.env import make_env

    if scenario is not None:
        check_scenario(scenario)
    scenario = scenario or (mission.scenario if mission is not None else DEFAULT_SCENARIO)
    given = {"alpha": alpha, "beta": beta, "gamma": gamma}
    weights = {k: check_range(k, DQN_REWARD_DEFAULTS[k] if v is None else v, 0.0, 1e6) for k, v in given.items()}
    cfg = DQNTrainConfig(scenario=scenario, seed=int(seed), safe_return=bool(safe_return), alpha=weights["alpha"],
                         beta=weights["beta"], gamma=weights["gamma"])
    if init_agent is not None:
        cfg = fine_tuning(cfg, init_agent)  # fails here, before the env is built, on an unreadable agent
    if steps is not None:
        if isinstance(steps, bool) or int(steps) != steps or not 1 <= int(steps) <= MAX_STEPS:
            raise InputError("steps", f"{steps!r} is out of range; allowed integers in [1, {MAX_STEPS:g}]")
        cfg.steps = int(steps)
    env_kwargs: dict[str, Any] = {"scenario": scenario, "backend": "physics", "safe_return": cfg.safe_return,
                                  **weights}
    if mission is not None:
        env_kwargs.update(mission=mission, randomize_battery=True)
    env_fn = make_env(**env_kwargs)  # bad maps fail here, before training
    return cfg, env_fn


class _Tally:
    """Running count and the last :data:`STATS_WINDOW` episodes."""

    def __init__(self) -> None:
        self.n = 0
        self.last: deque = deque(maxlen=STATS_WINDOW)

    def add(self, e) -> None:
        self.n += 1
        self.last.append(e)

    def final(self, timesteps: int) -> dict[str, Any]:
        last = list(self.last)
        k = len(last)

        def mean(f) -> float | None:
            return float(sum(f(e) for e in last) / k) if k else None

        return {
            "episodes": self.n,
            "timesteps": int(timesteps),
            "last_episodes": k,
            "mean_reward": mean(lambda e: e.reward),
            "mean_reached": mean(lambda e: e.reached),
            "mean_reached_priority": mean(lambda e: e.reached_priority),
            "mean_charging_cycles": mean(lambda e: e.charging_cycles),
            "eod_rate": mean(lambda e: float(e.eod_breach)),
        }


def retrain_dqn(
    config: Any,
    env_fn: Callable[[], Any],
    agent_path: str | os.PathLike[str],
    mission: Mission | None = None,
    on_episode: Callable[[Any], Any] | None = None,
    stop_event: threading.Event | None = None,
    progress_bar: bool = False,
    source: str | None = None,
    card_path: str | os.PathLike[str] | None = None,
) -> RetrainResult | None:
    """Train a DQN agent (:func:`~uam_studio.planning.agents.dqn.training.train_dqn`) and save it with its card.

    :param config: a :class:`~uam_studio.planning.agents.dqn.training.DQNTrainConfig` (see :func:`training_setup`).
    :param env_fn: the env factory from :func:`training_setup`.
    :param agent_path: the agent zip to write (atomically); never inside ``pretrained/``.
    :param mission: the map trained on (recorded in the card), or None for random missions.
    :param on_episode: called with each :class:`~uam_studio.planning.agents.dqn.training.EpisodeStats`, in the
        training thread.
    :param stop_event: set it to stop early; the agent trained so far is saved, with
        ``"stopped_early": true`` in its card, unless it has not finished one episode: then nothing is
        saved (an agent that learned nothing is not an agent) and None is returned.
    :param source: a short note on where the run came from (``"cli"``, ``"app"``), kept in the card.
    :param card_path: also write the card as this JSON file, consistent with the agent (see
        :func:`~uam_studio.planning.agents.dqn.agent_file.save_agent`).
    :raises InputError: ``agent_path`` inside ``pretrained/``.

    Stale temp files left in the agent's folder by killed saves are deleted before training.
    """
    from uam_studio import __version__ as version
    from uam_studio.planning.agents.dqn.agent_file import save_agent
    from uam_studio.planning.agents.dqn.training import train_dqn
    from uam_studio.planning.env import OBS_DIM

    agent = Path(agent_path)
    refuse_bundled(agent, "agent_path")
    remove_stale_temps(agent.parent)
    tally = _Tally()

    def _on_episode(e) -> None:
        tally.add(e)
        if on_episode is not None:
            on_episode(e)

    started = datetime.datetime.now(datetime.timezone.utc)
    t0 = time.perf_counter()
    model = train_dqn(config, env_fn, callback=_on_episode, stop_event=stop_event, progress_bar=progress_bar)
    wall_s = time.perf_counter() - t0
    stopped = bool(stop_event is not None and stop_event.is_set() and model.num_timesteps < config.steps)
    if stopped and tally.n == 0:
        return None
    card = {
        "model": "dqn",
        "uam_studio_version": version,
        "scenario": config.scenario,
        "health": "fallback",  # physics-only health features (no Dynaformer), see planning.env.fallback_health
        "config": config.to_dict(),
        "env": {"mission": mission_to_dict(mission) if mission is not None else None,
                "randomize_battery": mission is not None, "backend": "physics",
                "obs_dim": OBS_DIM},
        "timing": {"started_utc": started.isoformat(timespec="seconds"), "wall_s": round(wall_s, 2),
                   "steps_per_s": round(model.num_timesteps / wall_s, 1) if wall_s > 0 else None},
        "final_stats": tally.final(model.num_timesteps),
        "stopped_early": stopped,
    }
    if source is not None:
        card["source"] = source
    save_agent(model, agent, card, card_file=card_path)
    return RetrainResult(agent, card, tally.n, int(model.num_timesteps), stopped, model)


class DQNTrainer:
    """The DQN's :class:`~uam_studio.planning.agents.trainer.Trainer`: agent zips with their model card,
    one report per episode. ``setup``: ``scenario``, ``alpha``, ``beta``, ``gamma``, ``steps``, ``seed``,
    ``init_agent`` of :func:`training_setup`."""

    planner = "dqn"
    unit = "episode"
    settings = ("alpha", "beta", "gamma", "steps")
    trains_on_map = True
    cli_title = "dqn only"
    cli_shared = {
        "out": "default runs/dqn_<scenario>, writes agent.zip and card.json (a path ending in .zip names the "
               "agent file itself)",
        "steps": "env transitions (default 50000)",
        "init_from": "fine-tune this agent zip (e.g. pretrained/dqn_single_charge.zip), exploration starting at "
                     "epsilon 0.2",
    }

    def add_cli_arguments(self, group: Any) -> tuple[str, ...]:
        return tuple(action.dest for action in (
            group.add_argument("--scenario", default=None,
                               help="single_flight, single_charge or multi_charge; default: the mission's, else "
                                    "single_charge"),
            group.add_argument("--mission", default=None, metavar="FILE",
                               help="train on this mission's map (battery health drawn at random each episode); "
                                    "default: a random mission every episode"),
            group.add_argument("--alpha", type=float, default=None,
                               help="reward per reached destination x priority (default 1)"),
            group.add_argument("--beta", type=float, default=None, help="penalty per charging stop (default 1)"),
            group.add_argument("--gamma", type=float, default=None, help="penalty for an end of discharge (default 5)"),
            group.add_argument("--safe-return", action="store_true", default=None,
                               help="a leg that would leave no way home ends the episode with -gamma (the "
                                    "planner's safety rule, learnt in training); default off, the paper's setting"),
        ))

    def train_cli(self, args: Any) -> str:
        if args.scenario is not None:
            check_scenario(args.scenario, "--scenario")
        mission = load_mission(args.mission) if args.mission is not None else None
        scenario = args.scenario or (mission.scenario if mission is not None else DEFAULT_SCENARIO)
        out = Path(args.out or f"runs/dqn_{scenario}")
        agent = out if out.suffix == ".zip" else out / "agent.zip"
        refuse_bundled(agent, "--out")
        if agent.exists() and not agent.is_file():
            raise InputError("--out", f"{agent} exists and is not a file")
        if args.steps is not None and args.steps < 1:
            raise InputError("--steps", "must be >= 1")
        # every option is checked here, before the run folder is made
        cfg, env_fn = training_setup(scenario, mission, args.alpha, args.beta, args.gamma, args.steps, args.seed,
                                     safe_return=bool(args.safe_return), init_agent=args.init_from)
        make_writable_folder(agent.parent, "--out")
        card_path = agent.with_name("card.json") if agent.name == "agent.zip" else agent.with_suffix(".card.json")
        res = retrain_dqn(cfg, env_fn, agent, mission=mission, progress_bar=True, source="cli", card_path=card_path)
        assert res is not None  # None only for a run stopped through its stop event, which is never set here
        card, final = res.card, res.card["final_stats"]
        summary = (f"{final['episodes']} episodes; last {final['last_episodes']}: mean reward "
                   f"{final['mean_reward']:.2f}, EOD rate {final['eod_rate']:.0%}" if final["last_episodes"]
                   else "no finished episode")
        return f"wrote {agent} ({summary}; {card['timing']['wall_s']:.0f} s)"

    def find(self, folder: Path) -> list[AgentFile]:
        """The DQN agents (``*.zip`` with a readable model card of model ``dqn``) in ``folder``."""
        from uam_studio.planning.agents.dqn.agent_file import load_card

        out = []
        for p in folder.glob("*.zip"):
            try:
                card = load_card(p)
                mtime = p.stat().st_mtime
            except (InputError, OSError):
                continue
            if card.get("model") != self.planner:
                continue
            scenario = card.get("scenario") if card.get("scenario") in SCENARIOS else None
            out.append(AgentFile(p, p.stem, scenario, card, mtime))
        return out

    def describe(self, card: dict[str, Any], scenario: str | None) -> list[str | None]:
        steps = (card.get("final_stats") or {}).get("timesteps")
        return ["DQN", f"{steps} steps" if isinstance(steps, int) else None, scenario]

    def owns(self, path: Path) -> bool:
        return path.suffix == ".zip"

    def agent_name(self, path: Path) -> str:
        return path.stem

    def bundled_init(self, scenario: str) -> str:
        from uam_studio.planning.agents.dqn.rollout import bundled_agent_path

        return str(bundled_agent_path(scenario))

    def check(self, mission: Mission | None, setup: dict[str, Any]) -> Any:
        return training_setup(mission=mission, **setup)[0]

    def job(self, values: dict[str, Any], mission: Mission | None, init_agent: str | None, source: str) -> TrainJob:
        setup = {k: values[k] for k in ("scenario", "alpha", "beta", "gamma", "steps", "seed")}
        cfg, env_fn = training_setup(mission=mission, init_agent=init_agent, **setup)
        path = new_agent_path(setup["scenario"], "map" if mission is not None else "random")
        verb = "fine-tuning the bundled agent" if init_agent else "training"

        def run(on_item: Callable[[Any], Any], on_progress: Callable[[str, int, int], Any],
                stop_event: threading.Event) -> RetrainResult | None:
            return retrain_dqn(cfg, env_fn, path, mission=mission, on_episode=on_item, stop_event=stop_event,
                               source=source)

        return TrainJob(path=path, mission=mission, setup={**setup, "init_agent": init_agent}, target=cfg.steps,
                        status=f"{verb} {cfg.steps} steps on {'the current map' if mission else 'random missions'}",
                        run=run)

    def run(self, setup: dict[str, Any], agent_path: Path, mission: Mission | None,
            on_item: Callable[[Any], Any], on_progress: Callable[[str, int, int], Any],
            stop_event: threading.Event | Any, source: str | None) -> RetrainResult | None:
        cfg, env_fn = training_setup(mission=mission, **setup)
        return retrain_dqn(cfg, env_fn, agent_path, mission=mission, on_episode=on_item, stop_event=stop_event,
                           source=source)

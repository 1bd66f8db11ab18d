"""Training the attention planner: imitation of the exact oracle, then of its own search on larger maps.

:func:`train_attention` runs both phases and writes one weights file (atomically; never over a
bundled file):

1. **Imitation of the exact oracle.** Random training missions of 2-8 destinations
   (:func:`~uam_studio.planning.missions.generate.random_mission`, health in the default box, seeds
   ``[seed, k]``: never the held-out seeds). One exact search
   (:func:`~uam_studio.planning.solvers.oracle.feasible_sorties`) per mission gives both scenarios'
   optimal plans: single_charge's best sortie and multi_charge's fewest sorties (ordered largest
   first). Every decision along them (and a stop where the oracle leaves destinations out) is an
   example; the loss is the cross-entropy of the oracle's choice under the loose mask, so the network
   has to learn when the battery is too weak for a leg.
2. **Imitation of its own search on larger maps** (expert iteration). Missions of 9-20 destinations,
   planned by the phase-1 network with the physics filter and a wide beam; the best plan found is the
   target of a second round of training on all the examples. No other planner is consulted.

Examples are generated in ``workers`` processes; training is full-batch-free minibatch Adam on CPU
(or ``device``). A caller can watch the run (``on_progress`` while examples are made, ``on_epoch``
after each epoch, with ``evaluate``'s score of the network so far), stop it (``stop_event``: the
network trained so far is saved, ``"stopped_early"`` in its card) and start from saved weights
(``init_weights``) instead of random ones.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from uam_studio.atomic_io import atomic_save, remove_stale_temps
from uam_studio.bundled import refuse_bundled
from uam_studio.errors import InputError
from uam_studio.planning.agents.attention import WEIGHTS_NAME
from uam_studio.planning.agents.attention.decode import FORMAT, DecodeSearch
from uam_studio.planning.agents.attention.features import mission_tokens, step_features
from uam_studio.planning.agents.attention.model import AttentionConfig, AttentionPolicy
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import N_MAX, LegTable
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.missions.scenario import scenario_rules
from uam_studio.planning.solvers.oracle import (
    best_single_sortie,
    coverable_mask,
    feasible_sorties,
    min_sortie_cover,
)

__all__ = ["AttentionTrainConfig", "EpochStats", "oracle_examples", "train_attention"]

SCENARIOS_TRAINED = ("single_charge", "multi_charge")


@dataclass
class AttentionTrainConfig:
    """Settings of one training run (all recorded in the model card)."""

    seed: int = 0
    oracle_missions: int = 1200  # phase 1 missions (each gives both scenarios)
    oracle_dest: tuple[int, int] = (2, N_MAX)
    search_missions: int = 300  # phase 2 missions per scenario
    search_dest: tuple[int, int] = (9, 20)
    search_beam: int = 16
    epochs: int = 40
    search_epochs: int = 20
    batch: int = 256
    lr: float = 1e-3
    workers: int = 2
    device: str = "cpu"
    network: AttentionConfig = AttentionConfig()

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["network"] = self.network.to_dict()
        return d


@dataclass(frozen=True)
class EpochStats:
    """One finished training epoch.

    :param phase: 1 (imitation of the exact oracle) or 2 (imitation of its own search)
    :param epoch: 1-based epoch counter over both phases
    :param epochs: epochs planned over both phases
    :param loss: mean cross-entropy of the target's choice over the epoch's decisions
    :param accuracy: share of the epoch's decisions where the network ranked the target's choice first (0-1)
    :param wall_s: seconds since the run started (s)
    :param evaluation: what the run's ``evaluate`` callback returned for the network after this epoch
        (None without one)
    """

    phase: int
    epoch: int
    epochs: int
    loss: float
    accuracy: float
    wall_s: float
    evaluation: dict[str, Any] | None = None


class _Watch:
    """A run's callbacks, its stop flag and its epoch counter."""

    def __init__(self, epochs: int, on_epoch: Callable[[EpochStats], Any] | None,
                 evaluate: Callable[[AttentionPolicy], dict[str, Any]] | None,
                 on_progress: Callable[[str, int, int], Any] | None, stop_event: threading.Event | None) -> None:
        self.t0 = time.perf_counter()
        self.epochs, self.on_epoch, self.evaluate, self.on_progress = epochs, on_epoch, evaluate, on_progress
        self.stop_event = stop_event
        self.done = 0

    @property
    def stopped(self) -> bool:
        return self.stop_event is not None and self.stop_event.is_set()

    def progress(self, stage: str, done: int, total: int) -> None:
        if self.on_progress is not None:
            self.on_progress(stage, done, total)

    def epoch(self, net: AttentionPolicy, phase: int, loss: float, accuracy: float) -> None:
        self.done += 1
        if self.on_epoch is None:
            return
        evaluation = None
        if self.evaluate is not None:
            net.eval()
            evaluation = self.evaluate(net)
            net.train()
        self.on_epoch(EpochStats(phase, self.done, self.epochs, loss, accuracy,
                                 time.perf_counter() - self.t0, evaluation))


# ----------------------------------------------------------------------------- examples


@dataclass
class Decision:
    """One example: the mission's tokens index ``mission``, and the decision's arrays and target token."""

    mission: int
    at: int
    context: np.ndarray
    candidates: np.ndarray
    mask: np.ndarray
    target: int


def _decisions(tok, scenario: str, sorties: list[list[int]], k: int) -> list[Decision]:
    """The decisions of flying ``sorties`` (token lists) in order, then stopping if anything is left."""
    n = tok.n
    visited = np.zeros(n, dtype=bool)
    out: list[Decision] = []
    n_sorties = 0
    for s in sorties:
        at, used = n, 0.0
        for t in [*s, n]:
            ctx, cand, mask = step_features(tok, at, visited, used, n_sorties)
            if not mask[t]:
                return out  # the table does not allow it (cannot happen for an oracle route)
            out.append(Decision(k, at, ctx, cand, mask, t))
            used += float(tok.charge[at, t]) if t != n else 0.0
            if t != n:
                visited[t] = True
            at = t
        n_sorties += 1
        if scenario_rules(scenario).one_sortie:
            return out
    ctx, cand, mask = step_features(tok, n, visited, 0.0, n_sorties)
    if mask[:n].any():  # destinations left that the table allows: the oracle could not fit them
        out.append(Decision(k, n, ctx, cand, mask, n))
    return out


def oracle_examples(mission: Mission) -> dict[str, list[list[int]]]:
    """The exact oracle's plans of ``mission`` (at most 8 destinations) for single_charge and
    multi_charge, as destination indices per sortie: ``{scenario: sorties}``."""
    legs = LegTable(mission)
    found = feasible_sorties(Episode.of(legs, "single_charge"))  # the sorties of one charge
    single = [list(best_single_sortie(found, legs).nodes)] if found else []
    cover = sorted(min_sortie_cover(found, coverable_mask(found)), key=lambda s: (-len(s.nodes), s.time_s))
    return {"single_charge": single, "multi_charge": [list(s.nodes) for s in cover]}


def _oracle_job(args: tuple[int, int, tuple[int, int]]) -> tuple[Mission, dict]:
    seed, k, dest = args
    m = random_mission(np.random.default_rng([seed, k]), dest, "single_charge", name=f"train {seed}/{k}")
    return m, oracle_examples(m)


_SEARCH_NET: AttentionPolicy | None = None  # phase 2's network: set before the workers fork, inherited by them


def _search_job(args: tuple[int, int, tuple[int, int], str, int]) -> tuple[Mission, list[list[int]]]:
    seed, k, dest, scenario, beam = args
    assert _SEARCH_NET is not None
    m = random_mission(np.random.default_rng([seed, 1, k]), dest, scenario, name=f"search {seed}/{k}")
    episode = Episode.of(LegTable(m, max(N_MAX, len(m.destinations))), scenario)
    tok = mission_tokens(episode.legs, scenario)
    best, _ = DecodeSearch(_SEARCH_NET, tok, episode, beam, True, min(beam, 4)).run()
    assert best is not None, "a search always ends with a beam (the way home is always a move)"
    sorties: list[list[int]] = [[]]
    for t in best.tokens:
        if t == tok.n:
            sorties.append([])
        else:
            sorties[-1].append(t)
    return m, [s for s in sorties if s]


def _map(fn: Callable, jobs: list, workers: int, watch: _Watch, stage: str) -> list:
    """``fn`` over ``jobs`` in order (in ``workers`` processes); stops early (fewer results) when the
    watch is stopped, and reports each result as progress."""
    out: list = []
    if workers <= 1:
        results: Any = map(fn, jobs)
        pool = None
    else:
        pool = mp.get_context("fork").Pool(workers, initializer=torch.set_num_threads, initargs=(1,))
        results = pool.imap(fn, jobs, chunksize=4)
    try:
        for r in results:
            out.append(r)
            watch.progress(stage, len(out), len(jobs))
            if watch.stopped:
                break
    finally:
        if pool is not None:
            pool.terminate()
            pool.join()
    return out


# ----------------------------------------------------------------------------- training


class _Data:
    """Decisions padded into tensors (tokens per mission, padded to the largest mission)."""

    def __init__(self, tokens: list[np.ndarray], decisions: list[Decision]) -> None:
        t_max = max(f.shape[0] for f in tokens)
        n_m = len(tokens)
        self.tokens = torch.zeros(n_m, t_max, tokens[0].shape[1])
        self.pad = torch.ones(n_m, t_max, dtype=torch.bool)
        for i, f in enumerate(tokens):
            self.tokens[i, : f.shape[0]] = torch.from_numpy(f)
            self.pad[i, : f.shape[0]] = False
        d = len(decisions)
        self.mission = torch.tensor([x.mission for x in decisions])
        self.at = torch.tensor([x.at for x in decisions])
        self.context = torch.from_numpy(np.stack([x.context for x in decisions]))
        self.candidates = torch.zeros(d, t_max, decisions[0].candidates.shape[1])
        self.mask = torch.zeros(d, t_max, dtype=torch.bool)
        for i, x in enumerate(decisions):
            self.candidates[i, : x.candidates.shape[0]] = torch.from_numpy(x.candidates)
            self.mask[i, : x.mask.shape[0]] = torch.from_numpy(x.mask)
        self.target = torch.tensor([x.target for x in decisions])

    def __len__(self) -> int:
        return int(self.target.shape[0])


def _fit(net: AttentionPolicy, data: _Data, epochs: int, cfg: AttentionTrainConfig, rng: np.random.Generator,
         log: Callable[[str], Any], watch: _Watch, phase: int) -> list[float]:
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(1, epochs))
    loss_fn = nn.CrossEntropyLoss()
    dev = torch.device(cfg.device)
    net.to(dev).train()
    losses = []
    for ep in range(epochs):
        order = torch.from_numpy(rng.permutation(len(data)))
        total, count, correct = 0.0, 0, 0
        for s in range(0, len(order), cfg.batch):
            idx = order[s: s + cfg.batch]
            mi = data.mission[idx]
            h, graph = net.encode(data.tokens[mi].to(dev), data.pad[mi].to(dev))
            logits = net.decide(h, graph, data.at[idx].to(dev), data.context[idx].to(dev),
                                data.candidates[idx].to(dev), data.mask[idx].to(dev))
            target = data.target[idx].to(dev)
            loss = loss_fn(logits, target)
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(net.parameters(), 1.0)
            opt.step()
            total += float(loss.detach()) * idx.numel()
            count += idx.numel()
            correct += int((logits.argmax(-1) == target).sum())
            if watch.stopped:
                break
        sched.step()
        losses.append(total / count)
        log(f"epoch {ep + 1}/{epochs}: loss {total / count:.4f}, oracle's choice first {correct / count:.3f}")
        net.to("cpu")
        watch.epoch(net, phase, total / count, correct / count)
        net.to(dev)
        if watch.stopped:
            break
    net.to("cpu").eval()
    return losses


def _check_out(out: Path) -> Path:
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("--out", f"{out} exists and is not a folder")
    refuse_bundled(out / WEIGHTS_NAME, "--out")
    return out


def train_attention(cfg: AttentionTrainConfig, out: str | os.PathLike[str],
                    log: Callable[[str], Any] = print, *,
                    on_epoch: Callable[[EpochStats], Any] | None = None,
                    evaluate: Callable[[AttentionPolicy], dict[str, Any]] | None = None,
                    on_progress: Callable[[str, int, int], Any] | None = None,
                    stop_event: threading.Event | None = None,
                    init_weights: str | os.PathLike[str] | None = None,
                    card_extra: dict[str, Any] | None = None) -> Path | None:
    """Train the attention planner (see the module docstring); returns the weights file ``out/attention_planner.pt``
    (a model card ``card.json`` beside it and inside it).

    :param log: called with each line of the run's log.
    :param on_epoch: called with each :class:`EpochStats`, in the training thread.
    :param evaluate: scores the network after each epoch (in eval mode), e.g. its plan of one map;
        what it returns is :attr:`EpochStats.evaluation`. Used only with ``on_epoch``.
    :param on_progress: called with ``(stage, done, total)`` as examples are made (stage ``"oracle"``:
        missions solved by the exact oracle; ``"search"``: missions searched in phase 2).
    :param stop_event: set it to stop: the network trained so far is saved (``"stopped_early": true``
        in its card); None is returned (nothing saved) when no epoch had finished.
    :param init_weights: start from this weights file's network (its size replaces ``cfg.network``)
        instead of random weights.
    :param card_extra: more entries for the model card (where the run came from, the map it watched).
    :raises InputError: ``out`` is not a folder or holds the bundled planner; ``init_weights`` unreadable.
    """
    out = _check_out(Path(out))
    watch = _Watch(cfg.epochs + (cfg.search_epochs if cfg.search_missions > 0 else 0), on_epoch, evaluate,
                   on_progress, stop_event)
    t0 = watch.t0
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    if init_weights is not None:
        from uam_studio.planning.agents.attention.decode import load_policy

        net, _ = load_policy(init_weights)
        cfg = replace(cfg, network=net.config)
    else:
        net = AttentionPolicy(cfg.network)
    log(f"phase 1: exact oracle on {cfg.oracle_missions} missions of {cfg.oracle_dest[0]}-{cfg.oracle_dest[1]} "
        "destinations")
    jobs = [(cfg.seed, k, tuple(cfg.oracle_dest)) for k in range(cfg.oracle_missions)]
    solved = _map(_oracle_job, jobs, cfg.workers, watch, "oracle")
    tokens: list[np.ndarray] = []
    decisions: list[Decision] = []
    for mission, plans in solved:
        legs = LegTable(mission)
        for scenario, sorties in plans.items():
            tok = mission_tokens(legs, scenario)
            decisions += _decisions(tok, scenario, sorties, len(tokens))
            tokens.append(tok.features)
    t_oracle = time.perf_counter() - t0
    log(f"  {len(decisions)} decisions in {t_oracle:.0f} s")
    if watch.stopped or not decisions:
        log("stopped before the first epoch: nothing saved")
        return None
    losses = _fit(net, _Data(tokens, decisions), cfg.epochs, cfg, rng, log, watch, 1)
    stats: dict[str, Any] = {"oracle_decisions": len(decisions), "oracle_s": round(t_oracle, 1),
                             "phase1_loss": round(losses[-1], 4)}
    if cfg.search_missions > 0 and not watch.stopped:
        t1 = time.perf_counter()
        global _SEARCH_NET
        _SEARCH_NET = net  # in eval mode after _fit
        log(f"phase 2: own beam search (width {cfg.search_beam}) on {cfg.search_missions} missions per scenario "
            f"of {cfg.search_dest[0]}-{cfg.search_dest[1]} destinations")
        jobs2 = [(cfg.seed, k + i * cfg.search_missions, tuple(cfg.search_dest), sc, cfg.search_beam)
                 for i, sc in enumerate(SCENARIOS_TRAINED) for k in range(cfg.search_missions)]
        try:
            searched = _map(_search_job, jobs2, cfg.workers, watch, "search")
        finally:
            _SEARCH_NET = None
        n2 = 0
        for (m, sorties), (_, _, _, sc, _) in zip(searched, jobs2):
            legs = LegTable(m, max(N_MAX, len(m.destinations)))
            tok = mission_tokens(legs, sc)
            new = _decisions(tok, sc, sorties, len(tokens))
            decisions += new
            n2 += len(new)
            tokens.append(tok.features)
        stats.update(search_decisions=n2, search_s=round(time.perf_counter() - t1, 1))
        log(f"  {n2} decisions in {stats['search_s']:.0f} s")
        if not watch.stopped:
            losses2 = _fit(net, _Data(tokens, decisions), cfg.search_epochs, replace(cfg, lr=cfg.lr * 0.5), rng,
                           log, watch, 2)
            stats["phase2_loss"] = round(losses2[-1], 4)
    stats.update(train_s=round(time.perf_counter() - t0, 1), epochs_done=watch.done)
    card = {"format": FORMAT, "model": "attention", "config": cfg.to_dict(), "stats": stats,
            "init_weights": str(init_weights) if init_weights is not None else None,
            "stopped_early": watch.stopped, **(card_extra or {}),
            "torch": torch.__version__, "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(out)
    path = out / WEIGHTS_NAME
    payload = {"format": FORMAT, "config": cfg.network.to_dict(), "state_dict": net.state_dict(),
               "card": json.loads(json.dumps(card))}
    # card.json is a sidecar of the same save: the old card is deleted before the weights are replaced,
    # so a card on disk always describes the weights beside it
    atomic_save(path, lambda f: torch.save(payload, f), sidecars={out / "card.json": json.dumps(card, indent=2) + "\n"},
                digest=True)
    log(f"saved {path} ({path.stat().st_size / 1024:.0f} KB) in {stats['train_s']:.0f} s")
    return path

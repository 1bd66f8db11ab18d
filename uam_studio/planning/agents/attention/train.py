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
(or ``device``).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from uam_studio.atomic_io import atomic_save, atomic_write_text
from uam_studio.bundled import is_bundled
from uam_studio.errors import InputError
from uam_studio.planning.agents.attention import WEIGHTS_NAME
from uam_studio.planning.agents.attention.decode import FORMAT, _Search
from uam_studio.planning.agents.attention.features import mission_tokens, step_features
from uam_studio.planning.agents.attention.model import AttentionConfig, AttentionPolicy
from uam_studio.planning.legs import N_MAX, LegTable
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.solvers.oracle import (
    best_single_sortie,
    coverable_mask,
    feasible_sorties,
    min_sortie_cover,
)

__all__ = ["AttentionTrainConfig", "oracle_examples", "train_attention"]

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
        if scenario == "single_charge":
            return out
    ctx, cand, mask = step_features(tok, n, visited, 0.0, n_sorties)
    if mask[:n].any():  # destinations left that the table allows: the oracle could not fit them
        out.append(Decision(k, n, ctx, cand, mask, n))
    return out


def oracle_examples(mission: Mission) -> dict[str, list[list[int]]]:
    """The exact oracle's plans of ``mission`` (at most 8 destinations) for single_charge and
    multi_charge, as destination indices per sortie: ``{scenario: sorties}``."""
    legs = LegTable(mission)
    found = feasible_sorties(legs)
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
    legs = LegTable(m, max(N_MAX, len(m.destinations)))
    tok = mission_tokens(legs, scenario)
    best, _ = _Search(_SEARCH_NET, tok, legs, scenario, beam, True, min(beam, 4)).run()
    sorties: list[list[int]] = [[]]
    for t in best.tokens:
        if t == tok.n:
            sorties.append([])
        else:
            sorties[-1].append(t)
    return m, [s for s in sorties if s]


def _map(fn: Callable, jobs: list, workers: int) -> list:
    if workers <= 1:
        return [fn(j) for j in jobs]
    with mp.get_context("fork").Pool(workers, initializer=torch.set_num_threads, initargs=(1,)) as pool:
        return pool.map(fn, jobs, chunksize=4)


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
         log: Callable[[str], Any]) -> list[float]:
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
        sched.step()
        losses.append(total / count)
        log(f"epoch {ep + 1}/{epochs}: loss {total / count:.4f}, oracle's choice first {correct / count:.3f}")
    net.to("cpu").eval()
    return losses


def _check_out(out: Path) -> Path:
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("--out", f"{out} exists and is not a folder")
    if is_bundled(out / WEIGHTS_NAME):
        raise InputError("--out", f"{out} holds the bundled planner; training never overwrites it")
    return out


def train_attention(cfg: AttentionTrainConfig, out: str | os.PathLike[str],
                    log: Callable[[str], Any] = print) -> Path:
    """Train the attention planner (see the module docstring); returns the weights file ``out/attention_planner.pt``
    (a model card ``card.json`` beside it and inside it)."""
    out = _check_out(Path(out))
    t0 = time.perf_counter()
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    log(f"phase 1: exact oracle on {cfg.oracle_missions} missions of {cfg.oracle_dest[0]}-{cfg.oracle_dest[1]} "
        "destinations")
    jobs = [(cfg.seed, k, tuple(cfg.oracle_dest)) for k in range(cfg.oracle_missions)]
    solved = _map(_oracle_job, jobs, cfg.workers)
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
    net = AttentionPolicy(cfg.network)
    losses = _fit(net, _Data(tokens, decisions), cfg.epochs, cfg, rng, log)
    stats: dict[str, Any] = {"oracle_decisions": len(decisions), "oracle_s": round(t_oracle, 1),
                             "phase1_loss": round(losses[-1], 4)}
    if cfg.search_missions > 0:
        t1 = time.perf_counter()
        global _SEARCH_NET
        _SEARCH_NET = net  # in eval mode after _fit
        log(f"phase 2: own beam search (width {cfg.search_beam}) on {cfg.search_missions} missions per scenario "
            f"of {cfg.search_dest[0]}-{cfg.search_dest[1]} destinations")
        jobs2 = [(cfg.seed, k + i * cfg.search_missions, tuple(cfg.search_dest), sc, cfg.search_beam)
                 for i, sc in enumerate(SCENARIOS_TRAINED) for k in range(cfg.search_missions)]
        try:
            searched = _map(_search_job, jobs2, cfg.workers)
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
        losses2 = _fit(net, _Data(tokens, decisions), cfg.search_epochs, replace(cfg, lr=cfg.lr * 0.5), rng, log)
        stats["phase2_loss"] = round(losses2[-1], 4)
    stats["train_s"] = round(time.perf_counter() - t0, 1)
    card = {"format": FORMAT, "config": cfg.to_dict(), "stats": stats,
            "torch": torch.__version__, "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    out.mkdir(parents=True, exist_ok=True)
    path = out / WEIGHTS_NAME
    payload = {"format": FORMAT, "config": cfg.network.to_dict(), "state_dict": net.state_dict(),
               "card": json.loads(json.dumps(card))}
    atomic_save(path, lambda f: torch.save(payload, f))
    atomic_write_text(out / "card.json", json.dumps(card, indent=2) + "\n")
    log(f"saved {path} ({path.stat().st_size / 1024:.0f} KB) in {stats['train_s']:.0f} s")
    return path

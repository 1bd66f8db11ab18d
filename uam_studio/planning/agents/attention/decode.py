"""Planning with the attention network: beam search behind the physics safety filter.

:func:`attention_plan` decodes a route one decision at a time. Each decision scores every candidate
(:mod:`~uam_studio.planning.agents.attention.features`) with the network
(:mod:`~uam_studio.planning.agents.attention.model`); every leg is flown at its lowest-charge level.

- **Safety filter** (default on): a destination is a candidate only if the physics battery model
  (:meth:`~uam_studio.planning.episode.Episode.fly`, the mission's q_max, R0 and cut-off) flies
  the leg there *and* the leg from there home without falling below the cut-off, from the battery
  state the route has reached. So the vertiport can always be reached and every plan is safe. The
  filter flies each beam's best ``expand`` candidates (more only when none is safe; moves from a full
  charge flown once per plan). At the vertiport it may stop only when no destination is safe.
- **Search** (:func:`default_search`): beam search. Each beam proposes its ``expand`` best safe
  moves by the network; children in the same situation (same visited set, node and sorties) are
  merged into the one with the most charge left; the ``beam_width`` best children go on, ranked by
  the network's log-probability (multi_charge: fewer sorties first, then log-probability). Every finished route is kept
  and the best by the scenario's objective is returned: single_charge the most priority (ties: less flight time);
  multi_charge the most destinations, then the fewest sorties, then less time. No hand-written rule proposes moves.
- **Raw agent** (``safety_filter=False, beam_width=1``): the network's first choice at each step,
  nothing flown while planning (the caller checks the plan; an unsafe plan scores 0).

single_flight chooses only its leg's level: filtered, the highest minimum voltage; raw, the least charge.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from uam_studio.errors import InputError
from uam_studio.planning.agents.attention import WEIGHTS_NAME
from uam_studio.planning.agents.attention.features import MissionTokens, mission_tokens, step_features
from uam_studio.planning.agents.attention.model import AttentionPolicy
from uam_studio.planning.agents.attention.weights import (
    FORMAT,
    bundled_weights_path,
    load_policy,
    load_policy_cached,
)
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import ALTITUDES_M
from uam_studio.planning.missions.check import Plan, make_plan
from uam_studio.planning.missions.mission import VERTIPORT, Mission
from uam_studio.planning.missions.scenario import scenario_rules
from uam_studio.planning.solvers.setup import (
    prepare_mission,
    safest_single_flight,
    single_flight_note,
    too_close,
)

MAX_BEAM = 64
MULTI_WIDE_MAX_DEST = 10  # multi_charge maps up to this size get the wide search


def default_search(scenario: str, n_dest: int) -> tuple[int, int]:
    """``(beam width, moves proposed per beam)`` of the default planner: (16, 4), and (8, 2) for
    multi_charge maps of more than :data:`MULTI_WIDE_MAX_DEST` destinations (about n + sorties steps of physics
    checks against about n / 3 in single charge: it keeps a 20-destination plan fast; benchmarks/RESULTS.md, "The
    learned planner")."""
    if scenario_rules(scenario).recharges and n_dest > MULTI_WIDE_MAX_DEST:
        return 8, 2
    return 16, 4


__all__ = ["FORMAT", "WEIGHTS_NAME", "attention_plan", "bundled_weights_path", "continue_route", "default_search",
           "load_policy", "load_policy_cached", "plan_with_weights"]


# ----------------------------------------------------------------------------- search


@dataclass
class _Beam:
    at: int  # token
    visited: np.ndarray  # bool [n]
    x: np.ndarray | None  # battery state [8] (None without the filter)
    used_c: float  # C given since the last charge
    sorties: int
    tokens: list[int] = field(default_factory=list)  # tokens flown to, the vertiport = n
    levels: list[int] = field(default_factory=list)
    logp: float = 0.0
    priority: int = 0
    time_s: float = 0.0
    stopped: bool = False  # chose to stop at the vertiport


class DecodeSearch:
    """One decode of one mission (see the module docstring)."""

    def __init__(self, net: AttentionPolicy, tok: MissionTokens, episode: Episode,
                 beam_width: int, safety_filter: bool, expand: int | None = None,
                 reserve: Episode | None = None) -> None:
        self.net, self.tok, self.episode, self.legs = net, tok, episode, episode.legs
        self.reserve = reserve  # legs under the take-off check's winds: each move must also pass there
        self.multi = episode.rules.recharges
        self.width = beam_width
        self.filter = safety_filter
        self.fresh = episode.fresh()
        self.legs_flown = 0
        self.from_home: dict[int, np.ndarray | None] = {}  # token -> state there from a full charge (None: unsafe)
        self.expand = expand or beam_width  # destinations checked per beam and step (more only when none is safe)
        with torch.no_grad():
            self.h, self.graph = net.encode(torch.from_numpy(tok.features).unsqueeze(0))

    def level(self, a: int, b: int) -> int:
        lv = self.legs.cheapest_level(int(self.tok.leg_index[a]), int(self.tok.leg_index[b]))
        assert lv is not None
        return lv

    def current(self, a: int, b: int) -> np.ndarray:
        return self.legs.current(int(self.tok.leg_index[a]), int(self.tok.leg_index[b]), self.level(a, b))

    def log_probs(self, beams: list[_Beam]) -> tuple[np.ndarray, np.ndarray]:
        feats = [step_features(self.tok, b.at, b.visited, b.used_c, b.sorties) for b in beams]
        ctx = torch.from_numpy(np.stack([f[0] for f in feats]))
        cand = torch.from_numpy(np.stack([f[1] for f in feats]))
        mask = np.stack([f[2] for f in feats])
        k = len(beams)
        with torch.no_grad():
            logits = self.net.decide(self.h.expand(k, -1, -1), self.graph.expand(k, -1),
                                     torch.tensor([b.at for b in beams]), ctx, cand, torch.from_numpy(mask))
            lp = torch.log_softmax(logits, dim=-1).numpy()
        return lp, mask

    def safe_children(self, beams: list[_Beam], lp: np.ndarray,
                      mask: np.ndarray) -> list[list[tuple[int, np.ndarray, float]]]:
        """For each beam, its safe destination moves ``(token, state after the leg, leg charge)``, checked
        in the network's order: the best ``expand``, then the rest only if none of those is safe (and
        none was left to another beam's equivalent move)."""
        n = self.tok.n
        out: list[list[tuple[int, np.ndarray, float]]] = [[] for _ in beams]
        order = [[int(t) for t in np.argsort(-lp[i, :n], kind="stable") if mask[i, t]] for i in range(len(beams))]
        todo = [(i, o[: self.expand]) for i, o in enumerate(order)]
        merged = [False] * len(beams)  # a candidate left to another beam's equivalent move
        for rnd in range(2):
            rows: list[np.ndarray] = []
            x0: list[np.ndarray] = []
            split: list[int] = []
            keys: list[tuple[int, int]] = []
            best: dict[tuple[bytes, int, int], tuple[float, int, int]] = {}
            for i, cands in todo:
                b = beams[i]
                fresh = b.x is self.fresh  # a full charge at the vertiport: the same for every beam
                for t in cands:
                    if fresh and t in self.from_home:
                        x_t = self.from_home[t]
                        if x_t is not None:
                            out[i].append((t, x_t, float(self.tok.charge[n, t])))
                        continue
                    # moves that end in the same situation (visited set, node, sorties): fly only the one
                    # that leaves the most charge (distinct() would keep only that child anyway)
                    vis = b.visited.copy()
                    vis[t] = True
                    key = (vis.tobytes(), t, b.sorties)
                    est = b.used_c + float(self.tok.charge[b.at, t])
                    old = best.get(key)
                    if old is None or est < old[0]:
                        if old is not None:
                            merged[old[1]] = True
                        best[key] = (est, i, t)
                    else:
                        merged[i] = True
            for _, i, t in best.values():
                b = beams[i]
                go = self.current(b.at, t)
                rows.append(np.concatenate([go, self.current(t, n)]))  # the leg there, then home
                split.append(go.size)
                assert b.x is not None  # the filter is on: every beam carries its battery state
                x0.append(b.x)
                keys.append((i, t))
            if not rows:
                break
            ok, _, _, x_there = self.episode.fly_currents(rows, np.stack(x0), split=np.array(split))
            self.legs_flown += 2 * len(rows)
            if self.reserve is not None:  # the same move under the take-off check's winds, its cheapest level
                ix = self.tok.leg_index
                ok &= self.reserve.there_and_home([(int(ix[beams[i].at]), int(ix[t]), None) for i, t in keys],
                                                  np.stack(x0))
                self.legs_flown += 2 * len(keys)
            for k, (i, t) in enumerate(keys):
                if beams[i].x is self.fresh:
                    self.from_home[t] = x_there[k] if ok[k] else None
                if ok[k]:
                    out[i].append((t, x_there[k], float(self.tok.charge[beams[i].at, t])))
            if rnd == 0:
                todo = [(i, order[i][self.expand:]) for i in range(len(beams))
                        if not out[i] and not merged[i] and len(order[i]) > self.expand]
        return out

    def run(self, start: _Beam | None = None, first_allowed: np.ndarray | None = None
            ) -> tuple[_Beam | None, list[_Beam]]:
        """The best finished route and all finished routes. ``start``: a route under way (default: at
        the vertiport on a full charge); ``first_allowed``: bool [n+1], the tokens the first move may
        go to (the vertiport: token n). None for the best when no first move is allowed."""
        n = self.tok.n
        if start is None:
            start = _Beam(n, np.zeros(n, dtype=bool), self.fresh if self.filter else None, 0.0, 0)
        active: list[_Beam] = [start]
        finished: list[_Beam] = []
        for step in range(4 * n + 4):  # each step visits a destination or ends a sortie
            if not active:
                break
            lp, mask = self.log_probs(active)
            if step == 0 and first_allowed is not None:
                mask &= np.asarray(first_allowed, dtype=bool)[None, :]
                lp = np.where(mask, lp, -np.inf)
            safe = self.safe_children(active, lp, mask) if self.filter else None
            children: list[_Beam] = []
            for i, b in enumerate(active):
                moves: list[tuple[int, np.ndarray | None, float]]
                if safe is not None:
                    moves = list(safe[i])
                else:
                    ranked = [int(t) for t in np.argsort(-lp[i], kind="stable") if mask[i, t] and t != n]
                    moves = [(t, None, float(self.tok.charge[b.at, t])) for t in ranked[: self.expand]]
                for t, x, leg_c in moves:
                    children.append(_Beam(t, b.visited.copy(), x, b.used_c + leg_c, b.sorties, b.tokens + [t],
                                          b.levels + [self.level(b.at, t)], b.logp + float(lp[i, t]),
                                          b.priority + int(self.tok.priority[t]),
                                          b.time_s + self.current(b.at, t).size))
                    children[-1].visited[t] = True
                # the vertiport: go home (end the sortie), or stop where already home
                home_ok = b.at != n or (safe is None or not safe[i])
                if home_ok and np.isfinite(lp[i, n]):
                    children.append(self.home(b, float(lp[i, n])))
            if self.filter:
                children = self.distinct(children)
            children.sort(key=self.rank)
            active = []
            for rank, c in enumerate(children):
                if c.stopped or (c.at == n and (not self.multi or c.visited.all())):
                    if rank < self.width or self.filter:  # finished routes outside the beam: safe, kept
                        finished.append(c)
                elif len(active) < self.width and rank < self.width:
                    active.append(c)
        finished += active  # the step limit: never reached in practice
        if not finished:
            return None, []
        if self.multi:
            best = max(finished, key=lambda c: (int(c.visited.sum()), -c.sorties, -c.time_s, c.logp))
        else:
            best = max(finished, key=lambda c: (c.priority, -c.time_s, c.logp))
        return best, finished

    @staticmethod
    def distinct(children: list[_Beam]) -> list[_Beam]:
        """One child per (visited set, node, sorties): the one that has used the least charge since its
        last charge (the others are the same situation with a weaker battery); ties: higher
        log-probability."""
        best: dict[tuple[bytes, int, int, bool], _Beam] = {}
        for c in children:
            key = (c.visited.tobytes(), c.at, c.sorties, c.stopped)
            old = best.get(key)
            if old is None or (c.used_c, -c.logp) < (old.used_c, -old.logp):
                best[key] = c
        return list(best.values())

    def rank(self, c: _Beam) -> tuple[float, ...]:
        """Beam order (smaller first): multi_charge with the filter, fewer sorties so far (at one step,
        the same as more destinations), then the network's log-probability; otherwise the
        log-probability alone."""
        if self.multi and self.filter:
            return (c.sorties, -c.logp)
        return (-c.logp,)

    def home(self, b: _Beam, lp: float) -> _Beam:
        n = self.tok.n
        if b.at == n:  # stop
            return _Beam(n, b.visited, b.x, b.used_c, b.sorties, list(b.tokens), list(b.levels), b.logp + lp,
                         b.priority, b.time_s, stopped=True)
        return _Beam(n, b.visited, self.fresh if self.filter else None, 0.0, b.sorties + 1, b.tokens + [n],
                     b.levels + [self.level(b.at, n)], b.logp + lp, b.priority,
                     b.time_s + self.current(b.at, n).size)


def _single_flight(episode: Episode, safety_filter: bool, msgs: list[str], stats: dict[str, Any]
                   ) -> tuple[list[str], list[float]]:
    """The one leg: with the filter, the exact safest level (the oracle's); raw, the lowest-charge level."""
    if safety_filter:
        return safest_single_flight(episode, range(len(ALTITUDES_M)), msgs, stats)
    legs = episode.legs
    dest = legs.mission.destinations[0]
    msgs.extend(filter(None, [single_flight_note(legs.mission)]))
    a = legs.cheapest_level(legs.home, 0)
    if a is None:
        msgs.append(too_close(legs, 0) or f"cannot reach {dest.name} at any altitude")
        return [], []
    return [dest.name], [ALTITUDES_M[a]]


@contextlib.contextmanager
def _one_thread() -> Iterator[None]:
    """torch on one thread for the block (a 21-token network: one thread is several times faster than a
    contended pool), the caller's setting restored after."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def attention_plan(mission: Mission | dict, net: AttentionPolicy | None = None, beam_width: int | None = None,
                   safety_filter: bool = True, scenario: str | None = None, expand: int | None = None) -> Plan:
    """Plan ``mission`` with the attention network (see the module docstring).

    :param mission: the mission (1 to 20 destinations; a dict in the JSON format is validated first).
    :param net: the network (default: the bundled one, :func:`load_policy_cached`).
    :param beam_width: beams kept per step (1: the network's best choice only), 1 to 64; None for
        :func:`default_search`.
    :param expand: moves each beam proposes per step (its best safe ones by the network); None for
        :func:`default_search`'s (at most ``beam_width``).
    :param safety_filter: fly every candidate on the physics model before taking it (default True).
    :param scenario: overrides ``mission.scenario``.
    :return: a :class:`~uam_studio.planning.missions.check.Plan` (policy ``"attention"``); ``stats`` has
        ``time_s``, ``beam_width``, ``safety_filter``, ``legs_flown`` and ``routes_finished``.
    """
    for name, value in (("beam_width", beam_width), ("expand", expand)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                  or not 1 <= value <= MAX_BEAM):
            raise InputError(name, f"{value!r} is out of range; allowed integers in [1, {MAX_BEAM}] or None")
    t0 = time.perf_counter()
    setup = prepare_mission(mission, scenario, "attention")
    if setup.early is not None:
        return setup.early
    assert (setup.mission is not None and setup.full_mission is not None and setup.scenario is not None
            and setup.episode is not None)
    mission, full, scenario, msgs, stats = (setup.mission, setup.full_mission, setup.scenario, setup.messages,
                                            setup.stats)
    n = len(mission.destinations)
    episode = setup.episode
    legs = episode.legs  # max(N_MAX, n) slots
    width, per_beam = default_search(scenario, n)
    width = int(beam_width) if beam_width is not None else width
    per_beam = min(width, int(expand) if expand is not None else per_beam)
    stats.update(beam_width=width, expand=per_beam, safety_filter=bool(safety_filter))

    def done(route: list[str], alts: list[float]) -> Plan:
        stats["time_s"] = round(time.perf_counter() - t0, 4)
        return make_plan(full, "attention", route, alts, msgs, stats)

    if episode.rules.one_leg:
        return done(*_single_flight(episode, safety_filter, msgs, stats))
    for k in range(n):
        reason = too_close(legs, k)
        if reason is not None:
            msgs.append(reason)
    net = net if net is not None else load_policy_cached()
    tok = mission_tokens(legs, scenario)
    with _one_thread():
        search = DecodeSearch(net, tok, episode, width, safety_filter, per_beam)
        best, finished = search.run()
    assert best is not None  # from the vertiport on a full charge, stopping is always allowed
    stats.update(legs_flown=search.legs_flown, routes_finished=len(finished))
    names = [VERTIPORT if t == n else mission.destinations[t].name for t in best.tokens]
    alts = [ALTITUDES_M[a] for a in best.levels]
    if names and names[-1] != VERTIPORT:  # the step limit cut a route short: not expected
        msgs.append("the search stopped before the route returned to the vertiport")
    left = [mission.destinations[k].name for k in range(n) if not best.visited[k]
            and np.isfinite(tok.charge[n, k]) and np.isfinite(tok.charge[k, n])]
    if left and safety_filter:
        msgs.append(f"not visited: {', '.join(left)} (no safe place in the route found for "
                        f"{'it' if len(left) == 1 else 'them'})")
    return done(names, alts)


def continue_route(episode: Episode, here: int, state: np.ndarray, visited: np.ndarray,
                   sorties: int, first_moves: np.ndarray | None = None, net: AttentionPolicy | None = None,
                   reserve: Episode | None = None) -> tuple[list[int], list[int]] | None:
    """The rest of a route under way, planned as :func:`attention_plan` plans (default search, filter
    on the episode's cell): from node ``here`` of the episode's legs (``legs.home`` for the vertiport)
    with battery state ``state`` [8], the destinations ``visited`` (bool [legs.n]) done and ``sorties``
    sorties finished.

    :param first_moves: bool [legs.slots + 1, N_ALTITUDES], the (node, level) pairs the first leg may
        take (its lowest-charge level must be one); default all.
    :param reserve: the same mission under the winds of the take-off check (same nodes, same cell):
        every destination move of the route must also get there and home on its legs, as the check at
        that take-off will ask; default: no such check.
    :return: ``(nodes, levels)``: the nodes flown to in order (``legs.home`` for the vertiport) and each
        leg's level index; None if no first move is allowed and safe.
    """
    net = net if net is not None else load_policy_cached()
    legs, scenario = episode.legs, episode.rules.name
    tok = mission_tokens(legs, scenario)
    n = tok.n
    token = n if here == legs.home else int(here)
    width, per_beam = default_search(scenario, n)
    full = episode.fresh()
    x = np.asarray(state, dtype=float).reshape(-1)
    used = max(0.0, float((full[4] + full[5]) - (x[4] + x[5])))  # charge drawn from the negative electrode (C)
    allowed = None
    if first_moves is not None:
        allowed = np.zeros(n + 1, dtype=bool)
        for t in range(n + 1):
            if t == token:
                continue
            lv = legs.cheapest_level(int(tok.leg_index[token]), int(tok.leg_index[t]))
            allowed[t] = lv is not None and bool(first_moves[int(tok.leg_index[t]), lv])
    with _one_thread():
        search = DecodeSearch(net, tok, episode, width, True, per_beam, reserve)
        start = _Beam(token, np.asarray(visited, dtype=bool)[:n].copy(), x, used, int(sorties))
        best, _ = search.run(start, allowed)
    if best is None or not best.tokens:
        return None
    return [int(tok.leg_index[t]) for t in best.tokens], list(best.levels)


def plan_with_weights(mission: Mission, *, agent_path: str | os.PathLike[str] | None = None) -> Plan:
    """The ``"attention"`` policy: :func:`attention_plan` with ``agent_path``'s weights (default: bundled)."""
    return attention_plan(mission, load_policy_cached(agent_path))

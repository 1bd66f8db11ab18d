"""The price of safety: many flights at each declared risk, their breach rate against the risk, and the priority
they serve against hindsight and against their own pre-flight plan flown blind.

:func:`price_of_safety` flies the same flights at every level (``benchmarks/bench_risk.py``, notebook 09 and the
Fly tab's "many flights" view call it): fresh missions of 5-8 destinations (the held-out generator), half
single-charge and half multi-charge, each with one change of every later leg's wind drawn from the declared envelope
(N(0, :data:`~uam_studio.risk.WEATHER_CHANGE_SD_KT`), clipped to +-60 kt) at a time uniform in 60-900 s (a change
that comes after the flight has ended is dropped: the flight is flown without it). Optionally each pack first flies
the mission ``logbook_flights`` times (its logbook, :func:`~uam_studio.planning.operations.simulate_logbook`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import binomtest

from uam_studio.battery.health.logbook import Logbook
from uam_studio.errors import InputError, check_range
from uam_studio.planning.missions.generate import held_out_missions
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.missions.scenario import scenario_rules
from uam_studio.planning.operations.fly import fly_mission
from uam_studio.planning.operations.operator import Operator
from uam_studio.planning.operations.pack_history import simulate_logbook
from uam_studio.planning.operations.world import DEFAULT_WORLD, parse_event
from uam_studio.risk import RISK_LEVELS, WEATHER_CHANGE_SD_KT, check_risk

__all__ = ["RATE_FLOOR", "RiskLevel", "RiskFlight", "fly_study_flight", "format_levels", "group_tests",
           "price_of_safety", "risk_flights", "risk_levels"]

STUDY_SEED = 58000  # missions 58000 (single-charge) and 58001 (multi-charge); worlds and packs +100, changes +200,
# the logbooks' earlier flights +300: seeds no tuning read
N_DEST = (5, 8)  # destinations of a mission (held_out_missions' range)
CHANGE_CLIP_KT = 60.0  # kt
CHANGE_WINDOW_S = (60.0, 900.0)  # s
RATE_FLOOR = 1e-3  # where the figures of the price of safety draw a breach rate of 0 on their log axis


@dataclass(frozen=True)
class RiskFlight:
    """One flight of the study: the declared ``risk``, the ``scenario``, the priority the operator reached
    (``priority``, 0 when it breached), its pre-flight plan flown blind (``blind``, 0 when that breached) and
    hindsight (``hindsight``), and whether each breached (``breached``, ``blind_breached``)."""

    risk: float
    scenario: str
    priority: int
    blind: int
    hindsight: int
    breached: bool
    blind_breached: bool


@dataclass(frozen=True)
class RiskLevel:
    """The flights at one declared ``risk``: ``flights``, ``breaches``, the breach ``rate`` with its two-sided 95%
    Clopper-Pearson interval (``rate_low``, ``rate_high``) and ``p_at_most`` (the one-sided binomial test of "at most
    the declared risk": >= 0.05 is consistent); the priority served over hindsight's, pooled (``priority_ratio``)
    and on single-charge missions (``single_ratio``); the blind plan's (``blind_ratio``, ``blind_single_ratio``,
    its ``blind_breaches``); and ``single_vs_blind``, the operator's single-charge priority over the blind plan's."""

    risk: float
    flights: int
    breaches: int
    rate: float
    rate_low: float
    rate_high: float
    p_at_most: float
    priority_ratio: float
    single_ratio: float
    blind_ratio: float
    blind_single_ratio: float
    blind_breaches: int
    single_vs_blind: float

    def row(self) -> dict[str, Any]:
        """The level as one table row (notebook 09, the Fly tab)."""
        return {"declared risk": self.risk, "flights": self.flights, "breaches": self.breaches,
                "breach rate": round(self.rate, 3), "95% interval": f"{self.rate_low:.3f}-{self.rate_high:.3f}",
                "p (at most the risk)": round(self.p_at_most, 2), "priority / hindsight": round(self.priority_ratio, 3),
                "single-charge": round(self.single_ratio, 3), "blind / hindsight": round(self.blind_ratio, 3),
                "blind breaches": self.blind_breaches}


def risk_flights(n: int, seed: int = STUDY_SEED) -> list[tuple[Mission, int, str]]:
    """The study's ``n`` flights (module docstring): ``(mission, world seed and pack, wind-change event)``."""
    n = int(check_range("n", n, 1, 5000))
    half = n // 2
    missions = held_out_missions(half, seed, n_dest=N_DEST, scenario="single_charge") if half else []
    missions += held_out_missions(n - half, seed + 1, n_dest=N_DEST, scenario="multi_charge")
    rng = np.random.default_rng(seed + 200)
    changes = np.clip(rng.normal(0.0, WEATHER_CHANGE_SD_KT, n), -CHANGE_CLIP_KT, CHANGE_CLIP_KT)
    times = rng.uniform(*CHANGE_WINDOW_S, n)
    return [(m, seed + 100 + k, f"wind{c:+.0f}@{t:.0f}") for k, (m, c, t) in enumerate(zip(missions, changes, times))]


def _logbook(job: tuple[Mission, int, int, int, str]) -> Logbook:
    mission, flights, seed, pack, world = job
    return simulate_logbook(mission, flights, seed, world=world, pack=pack)


def fly_study_flight(risk: float, mission: Mission, seed: int, event: str, world: str = DEFAULT_WORLD,
                     logbook: Logbook | None = None, operator: Callable[..., Operator] = Operator) -> RiskFlight:
    """One flight of the study (:func:`risk_flights`' ``(mission, seed, event)``) at declared ``risk``, flown by
    ``operator`` (:func:`~uam_studio.planning.operations.fly_mission`'s), on pack ``seed`` with its ``logbook``; a
    change that comes after the flight has ended is dropped."""
    kwargs: dict[str, Any] = dict(seed=seed, pack=seed, risk=risk, world=world, logbook=logbook, operator=operator)
    try:
        rec = fly_mission(mission, events=[parse_event(event)], **kwargs)
    except InputError as err:  # the change came after the flight: flown without it
        if err.field != "event":
            raise
        rec = fly_mission(mission, **kwargs)
    return RiskFlight(risk, rec.scenario, rec.reached_priority, rec.static.priority, rec.hindsight.priority,
                      rec.breached, rec.static.breached)


def _fly(job: tuple[float, Mission, int, str, str, Logbook | None]) -> RiskFlight:
    return fly_study_flight(*job)


def price_of_safety(risks: Sequence[float] = RISK_LEVELS, n: int = 60, logbook_flights: int = 0,
                    world: str = DEFAULT_WORLD, workers: int = 1, seed: int = STUDY_SEED,
                    progress: Callable[[int, int], None] | None = None) -> list[RiskFlight]:
    """Fly the study's ``n`` flights (:func:`risk_flights`) at each declared risk in ``risks``.

    :param logbook_flights: earlier flights of each mission's pack in its logbook (0: new packs; seeds ``seed`` + 300
        + k for flight k's logbook).
    :param world: the world the packs fly (:data:`~uam_studio.planning.operations.world.WORLDS`).
    :param workers: processes (1: in this process).
    :param progress: called with (flights done, flights in all) as they land (``workers`` 1 only).
    :returns: one :class:`RiskFlight` per flight and risk, the risks in the given order; :func:`risk_levels` sums them.
    """
    risks = [check_risk(r) for r in risks]
    flights = risk_flights(n, seed)
    book_jobs = [(m, logbook_flights, seed + 300 + k, pack, world) for k, (m, pack, _) in enumerate(flights)]

    def jobs_of(books: list[Logbook | None]) -> list[tuple]:
        return [(r, m, pack, event, world, book) for r in risks for (m, pack, event), book in zip(flights, books)]

    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            books: list[Logbook | None] = (list(pool.map(_logbook, book_jobs)) if logbook_flights
                                           else [None] * len(flights))
            return list(pool.map(_fly, jobs_of(books)))
    books = [_logbook(j) for j in book_jobs] if logbook_flights else [None] * len(flights)
    out = []
    jobs = jobs_of(books)
    for k, job in enumerate(jobs):
        out.append(_fly(job))
        if progress is not None:
            progress(k + 1, len(jobs))
    return out


def _ratio(a: float, b: float) -> float:
    return a / b if b else float("nan")


def risk_levels(flights: Sequence[RiskFlight]) -> list[RiskLevel]:
    """The flights summed per declared risk (:class:`RiskLevel`), in the order the risks first appear."""
    out = []
    for r in dict.fromkeys(f.risk for f in flights):
        sub = [f for f in flights if f.risk == r]
        single = [f for f in sub if scenario_rules(f.scenario).one_sortie]
        n, k = len(sub), sum(f.breached for f in sub)
        ci = binomtest(k, n).proportion_ci(0.95)
        hind, hind_one = sum(f.hindsight for f in sub), sum(f.hindsight for f in single)
        out.append(RiskLevel(
            risk=r, flights=n, breaches=k, rate=k / n, rate_low=float(ci.low), rate_high=float(ci.high),
            p_at_most=float(binomtest(k, n, r, alternative="greater").pvalue),
            priority_ratio=_ratio(sum(f.priority for f in sub), hind),
            single_ratio=_ratio(sum(f.priority for f in single), hind_one),
            blind_ratio=_ratio(sum(f.blind for f in sub), hind),
            blind_single_ratio=_ratio(sum(f.blind for f in single), hind_one),
            blind_breaches=sum(f.blind_breached for f in sub),
            single_vs_blind=_ratio(sum(f.priority for f in single), sum(f.blind for f in single))))
    return out


def format_levels(levels: Sequence[RiskLevel]) -> str:
    """The price-of-safety table (markdown) of :func:`risk_levels`."""
    lines = ["| declared risk | flights | breaches | breach rate (95% CI) | p (at most the risk) "
             "| priority / hindsight "
             "| single-charge | single-charge / blind | blind plan / hindsight (its breaches) | blind, single-charge |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for v in levels:
        lines.append(f"| {v.risk:g} | {v.flights} | {v.breaches} | {v.rate:.3f} ({v.rate_low:.3f}-{v.rate_high:.3f}) "
                     f"| {v.p_at_most:.2f} | {v.priority_ratio:.3f} | {v.single_ratio:.3f} | {v.single_vs_blind:.3f} "
                     f"| {v.blind_ratio:.3f} ({v.blind_breaches}) | {v.blind_single_ratio:.3f} |")
    return "\n".join(lines)


def group_tests(flights: Sequence[RiskFlight]) -> str:
    """Per declared risk and scenario: flights, breaches and the one-sided binomial test of "at most the declared
    risk" (p >= 0.05: consistent), one line each."""
    lines = []
    for r in dict.fromkeys(f.risk for f in flights):
        for scenario in dict.fromkeys(f.scenario for f in flights if f.risk == r):
            sub = [f for f in flights if f.risk == r and f.scenario == scenario]
            k = sum(f.breached for f in sub)
            p = binomtest(k, len(sub), r, alternative="greater").pvalue
            lines.append(f"risk {r:g}, {scenario}: {k} of {len(sub)} breached, p {p:.2f}")
    return "\n".join(lines)

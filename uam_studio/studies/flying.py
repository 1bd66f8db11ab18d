"""Studies of flying with surprises: many seeded flights, summaries and the sweep over forecast
error and sensor noise. The notebook "09 Flying with surprises" and the benchmarks call these
(their numbers: benchmarks/RESULTS.md, "Flying the mission").
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from uam_studio.planning.missions.generate import held_out_missions
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO
from uam_studio.planning.operations import FlightRecord, fly_mission


@dataclass(frozen=True)
class FlightSummary:
    """Totals over a set of flights.

    ``n`` flights; ``priority``, ``blind_priority`` and ``hindsight_priority``: summed reached
    priority (0 for a breached flight) of the operator, the blind pre-flight plan and the hindsight
    oracle; ``ratio`` and ``blind_ratio``: those over the hindsight's; ``breaches`` and
    ``blind_breaches``: flights that fell below the cut-off; ``not_worse_than_blind``: flights where
    the operator reached at least the blind plan's priority; ``extra_cycles``: recharges beyond the
    hindsight plan's, summed; ``replan_s_p50`` / ``replan_s_p95`` / ``replan_s_max`` (s) over every
    decision; ``fly_s_mean`` (s) per flight with its references.
    """

    n: int
    priority: int
    blind_priority: int
    hindsight_priority: int
    ratio: float
    blind_ratio: float
    breaches: int
    blind_breaches: int
    not_worse_than_blind: int
    extra_cycles: int
    replan_s_p50: float
    replan_s_p95: float
    replan_s_max: float
    fly_s_mean: float

    def to_dict(self) -> dict[str, Any]:
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


def study_missions(n: int, seed: int, scenario: str, n_dest: tuple[int, int] = (5, 8)) -> list[Mission]:
    """``n`` random missions of ``n_dest`` destinations (the held-out generator, its own ``seed``)."""
    return held_out_missions(n, seed, n_dest=n_dest, scenario=scenario)


def fly_many(missions: Sequence[Mission], first_seed: int = 0, **kwargs: Any) -> list[FlightRecord]:
    """Fly each mission once, mission k with world seed ``first_seed + k``; ``kwargs`` go to
    :func:`~uam_studio.planning.operations.fly_mission`."""
    return [fly_mission(m, seed=first_seed + k, **kwargs) for k, m in enumerate(missions)]


def summarize(records: Iterable[FlightRecord]) -> FlightSummary:
    """Totals of a set of flights (see :class:`FlightSummary`)."""
    recs = list(records)
    hind = sum(r.hindsight.priority for r in recs)
    replans = np.array([s for r in recs for s in r.replan_s] or [0.0])
    hind_cycles = [sum(1 for n in r.hindsight.route if n == "vertiport") for r in recs]
    return FlightSummary(
        n=len(recs),
        priority=sum(r.reached_priority for r in recs),
        blind_priority=sum(r.static.priority for r in recs),
        hindsight_priority=hind,
        ratio=sum(r.reached_priority for r in recs) / hind if hind else float("nan"),
        blind_ratio=sum(r.static.priority for r in recs) / hind if hind else float("nan"),
        breaches=sum(r.breached for r in recs),
        blind_breaches=sum(r.static.breached for r in recs),
        not_worse_than_blind=sum(r.reached_priority >= r.static.priority for r in recs),
        extra_cycles=int(sum(max(0, r.charging_cycles - c) for r, c in zip(recs, hind_cycles) if not r.breached)),
        replan_s_p50=float(np.percentile(replans, 50)),
        replan_s_p95=float(np.percentile(replans, 95)),
        replan_s_max=float(replans.max()),
        fly_s_mean=float(np.mean([r.wall_s for r in recs])) if recs else 0.0,
    )


def sweep(sigmas_kt: Sequence[float] = (0.0, 7.0, 13.0, 26.0), noises_mv: Sequence[float] = (0.0, 5.0, 10.0),
          n: int = 8, seed: int = 9090, scenario: str = DEFAULT_SCENARIO, n_dest: tuple[int, int] = (5, 8),
          first_seed: int = 50_000, **kwargs: Any) -> list[dict[str, Any]]:
    """The operator against hindsight and the blind plan over forecast error x sensor noise.

    Every cell flies the same ``n`` missions with the same world seeds; returns one row per cell:
    ``forecast_sigma_kt``, ``sensor_noise_mv``, the :class:`FlightSummary` fields and ``wall_s``.
    """
    missions = study_missions(n, seed, scenario, n_dest)
    rows = []
    for sigma in sigmas_kt:
        for noise in noises_mv:
            t0 = time.perf_counter()
            recs = fly_many(missions, first_seed, forecast_sigma_kt=sigma, sensor_noise_mv=noise, **kwargs)
            rows.append({"forecast_sigma_kt": sigma, "sensor_noise_mv": noise, **summarize(recs).to_dict(),
                         "wall_s": round(time.perf_counter() - t0, 1)})
    return rows


def format_rows(rows: Sequence[dict[str, Any]]) -> str:
    """A plain-text table of :func:`sweep` rows."""
    head = (f"{'sigma kt':>8} {'noise mV':>8} {'op/hind':>8} {'blind/hind':>10} {'op breach':>9} "
            f"{'blind breach':>12} {'replan p95 s':>12}")
    lines = [head]
    for r in rows:
        lines.append(f"{r['forecast_sigma_kt']:>8g} {r['sensor_noise_mv']:>8g} {r['ratio']:>8.3f} "
                     f"{r['blind_ratio']:>10.3f} {r['breaches']:>4}/{r['n']:<4} {r['blind_breaches']:>7}/{r['n']:<4} "
                     f"{r['replan_s_p95']:>12.3f}")
    return "\n".join(lines)


__all__ = ["FlightSummary", "fly_many", "format_rows", "study_missions", "summarize", "sweep"]

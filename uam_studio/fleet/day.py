"""A fleet's operating day and life as a discrete-event simulation (SimPy), flown in a hidden world.

The world holds each pack's true health (:class:`~uam_studio.fleet.aging.PackHealth`, aging with the
charge it delivers; in the varied world, the default, flown on the pack's own parameter set, which no belief
models) and the actual winds (the forecast plus a seeded error); the fleet's sensors have white noise only.
Dispatchers see only :class:`~uam_studio.fleet.dispatch.AircraftView` s (each aircraft's own belief). A served
request is a round trip at 500 m from full charge, flown on the true cell in the actual winds: below the cut-off
is a breach (the request scores 0 and the aircraft is grounded for the day). Each flight's noisy readings go
into its pack's logbook (``Fleet.logbooks``, :class:`~uam_studio.battery.health.logbook.Logbook`) with their
whole-record fit; the fleet keeps the logbooks only, and a dispatcher reads each aircraft's belief derived from its
logbook (:meth:`Fleet.belief`: the one belief value,
:class:`~uam_studio.battery.health.belief.PackBelief`, on the fleet's declared configuration). Landed, the
aircraft charges at 1 C back to full on one of its vertiport's chargers (a queue when all are busy).
A fleet may be based at several vertiports: each aircraft serves the requests of its own vertiport
and charges there.

A fleet's packs age by the law of their cell type (:data:`PACK_LAWS`): ``"nasa"`` (default; the paper's
cell, the law fitted to the NASA PCoE lives, :data:`~uam_studio.fleet.nasa_aging.NASA_AGING_LAW`) or
``"vtc6"`` (the law fitted to the CMU lives of Sony VTC6 cells). The aircraft's beliefs age by the same
law (a model the operator holds, not the pack's truth). Over a life, a pack that retired is replaced
overnight by a new one from the factory (:meth:`Fleet.renew_retired`), as an operator would.

Public API: :func:`simulate_day` (an :class:`OperatingDay` run), :func:`simulate_life`, :class:`DayResult`,
:class:`Fleet`, :data:`PACK_LAWS`, :func:`default_age_spread`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import simpy

from uam_studio.errors import InputError, check_range, check_seed
from uam_studio.fleet.demand import (
    DAY_S,
    DEFAULT_MAX_KM,
    DEFAULT_RATE_PER_H,
    Request,
    day_seed,
    poisson_demand,
)
from uam_studio.fleet.dispatch import (
    BLIND_RESERVE_V,
    DISPATCHERS,
    NOMINAL,
    AircraftView,
    assign,
    round_trip,
    round_trip_margin,
)
from uam_studio.fleet.hindsight import Job, day_bound
from uam_studio.fleet.packs import (
    AGE_SPREAD_LIFE,
    NOISE_A,
    NOISE_V,
    PACK_LAWS,
    Fleet,
    default_age_spread,
    pack_law,
)
from uam_studio.planning.operations.world import DEFAULT_WORLD
from uam_studio.risk import DEFAULT_RISK, caution, check_risk

__all__ = ["AGE_SPREAD_LIFE", "DayResult", "END_S", "Fleet", "OperatingDay", "PACK_LAWS",
           "day_of_life_seed", "default_age_spread", "fly_day_of_life", "hindsight_bound", "pack_law", "simulate_day",
           "simulate_life"]

FORECAST_SIGMA_KT = 8.0  # kt: the actual wind is the forecast plus N(0, this)
CHARGE_C_RATE = 1.0  # charge current, in q_max per hour
END_S = DAY_S + 6 * 3600.0  # s: the simulation's end (flights in the air at the day's end land)
SEED_STRIDE = 100_003  # day d of the life seeded ``seed`` is seeded ``seed * SEED_STRIDE + d``


def day_of_life_seed(seed: int, day: int) -> int:
    """The seed of day ``day`` (0-based) of the life seeded ``seed``: its demand and its world."""
    return seed * SEED_STRIDE + day


@dataclass(frozen=True, kw_only=True)
class DayResult:
    """One day: ``priority`` served (stars of the requests flown without a breach), ``served``,
    ``refused`` (never flown), ``breaches``, ``flights``, ``charge_ah`` (per cell, delivered),
    ``charger_wait_s`` (summed), each flight as (take-off s, aircraft, request, true margin V,
    duration s), and for the hindsight dispatcher ``bound``: the most stars any dispatcher could serve
    this day from the same fleet (:mod:`uam_studio.fleet.hindsight`; None for the others)."""

    priority: int
    served: int
    refused: int
    breaches: int
    flights: int
    charge_ah: float
    charger_wait_s: float
    log: tuple[tuple[float, int, str, float, float], ...]
    bound: int | None = None

    def to_dict(self) -> dict:
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.__dict__.items() if k != "log"}


def _world_winds(demand: list[Request], seed: int) -> dict[str, tuple[float, float]]:
    rng = np.random.default_rng([seed, 7])
    return {r.name: (r.wind_kts + float(rng.normal(0.0, FORECAST_SIGMA_KT)),
                     -r.wind_kts + float(rng.normal(0.0, FORECAST_SIGMA_KT))) for r in demand}


def _charger_counts(fleet: Fleet, demand: list[Request], chargers: int | Sequence[int]) -> list[int]:
    """Chargers per vertiport (one count for all, or one each, 1-50), every request at a fleet's vertiport."""
    ports = fleet.vertiports
    counts = [chargers] * ports if isinstance(chargers, (int, np.integer)) else list(chargers)
    if len(counts) != ports:
        raise InputError("chargers", f"{len(counts)} counts for {ports} vertiports: give one, or one per vertiport")
    counts = [int(check_range("chargers", c, 1, 50)) for c in counts]
    for req in demand:
        if req.vertiport >= ports:
            raise InputError("vertiport", f"request {req.name!r} at vertiport {req.vertiport}: the fleet is based "
                                          f"at vertiports 0-{ports - 1}")
    return counts


def _recharge_s(charge_c: float, q_max: float) -> float:
    """Time (s) to put ``charge_c`` (C) back at :data:`CHARGE_C_RATE` on a cell of ``q_max`` (C)."""
    return charge_c / (CHARGE_C_RATE * q_max) * 3600.0


def _delivered(sim) -> tuple[np.ndarray, float, float]:
    """A round trip's current (A) up to its end or its cut-off, the charge it drew (C) and its duration (s)."""
    k = int(np.count_nonzero(sim.valid)) if sim.eod_s is not None else len(sim.current_a)
    cur = np.asarray(sim.current_a[:k], dtype=float)
    return cur, float(np.sum(np.clip(cur, 0.0, None)) * sim.dt_s), float(k * sim.dt_s)


def hindsight_bound(fleet: Fleet, demand: list[Request], seed: int, chargers: int | Sequence[int] = 2) -> int:
    """The most stars any dispatcher could serve on this day from this fleet, knowing the whole ``demand``
    and, from the world seeded ``seed``, every pack's truth and the actual winds
    (:func:`uam_studio.fleet.hindsight.day_bound` over every safe true round trip of every aircraft in
    service). Reads the truth: a reference, never a dispatcher's view."""
    return _bound(fleet, demand, _world_winds(demand, day_seed(seed)), _charger_counts(fleet, demand, chargers))


def _bound(fleet: Fleet, demand: list[Request], winds: dict[str, tuple[float, float]], counts: list[int]) -> int:
    """:func:`hindsight_bound` in the day's world (``winds``, kt) with checked charger ``counts``."""
    jobs = []
    for i, truth in enumerate(fleet.truth):
        if not fleet.in_service[i]:
            continue
        for r, req in enumerate(demand):
            if req.vertiport != fleet.base[i]:
                continue
            sim = round_trip(req, truth.q_max, truth.r0, *winds[req.name], truth.params)
            if sim.safe:
                _, charge, flight_s = _delivered(sim)
                jobs.append(Job(request=r, aircraft=i, port=req.vertiport, earliest_s=req.t_s,
                                latest_s=req.t_s + req.window_s, flight_s=flight_s,
                                charge_s=_recharge_s(charge, truth.q_max), priority=int(req.priority)))
    per_port = [sum(1 for i, b in enumerate(fleet.base) if b == p and fleet.in_service[i]) for p in range(len(counts))]
    return day_bound(jobs, counts, per_port, END_S)


class OperatingDay:
    """One day of a fleet as SimPy processes on one object (see :func:`simulate_day`, which runs it).

    Processes: :meth:`arrivals` (requests arrive, and the last wait until their windows close) and one
    :meth:`fly` per dispatched request (the round trip, the health fit, the charger queue). The world's
    winds and the packs' truth are read only by :meth:`fly` and, for the hindsight dispatcher, by
    :meth:`margin`; the other dispatchers' margins read the aircraft's beliefs.
    """

    def __init__(self, fleet: Fleet, demand: list[Request], dispatcher: str, seed: int, counts: list[int],
                 risk: float = DEFAULT_RISK) -> None:
        self.fleet, self.demand, self.dispatcher = fleet, demand, dispatcher
        self.caution = caution(risk)  # the health-aware dispatcher's margins (uam_studio.risk)
        self.winds = _world_winds(demand, seed)
        self.bound = _bound(fleet, demand, self.winds, counts) if dispatcher == "hindsight" else None
        self.env = simpy.Environment()
        self.plugs = [simpy.Resource(self.env, capacity=c) for c in counts]
        self.noise = np.random.default_rng([seed, 11])
        self.n = len(fleet.truth)
        self.free = list(fleet.in_service)  # an aircraft is free when in service and not flying or charging
        self.version = [0] * self.n
        self.waiting: list[Request] = []
        self.cache: dict[tuple[str, int, int], float] = {}
        self.stats: dict[str, Any] = {"priority": 0, "served": 0, "breaches": 0, "flights": 0, "charge_c": 0.0,
                                      "wait_s": 0.0}
        self.log: list[tuple[float, int, str, float, float]] = []
        self.required = BLIND_RESERVE_V if dispatcher == "blind" else 0.0

    def margin(self, req: Request, a: AircraftView) -> float:
        """The voltage margin (V) over the cut-off that the dispatcher expects of ``a`` flying ``req``."""
        i = int(a.name)
        key = (req.name, i, a.key)
        if key not in self.cache:
            if self.dispatcher == "aware":
                b, c = a.belief.health, self.caution
                self.cache[key] = round_trip_margin(req, b.q_max_c - c.health_z * b.q_max_sd_c,
                                                    b.r0_ohm + c.health_z * b.r0_sd_ohm,
                                                    req.wind_kts + c.dispatch_wind_z * FORECAST_SIGMA_KT,
                                                    -req.wind_kts + c.dispatch_wind_z * FORECAST_SIGMA_KT)
            elif self.dispatcher == "blind":
                self.cache[key] = round_trip_margin(req, *NOMINAL, req.wind_kts, -req.wind_kts)
            else:  # hindsight: the truth (the world's), never the aircraft's view
                t = self.fleet.truth[i]
                self.cache[key] = round_trip_margin(req, t.q_max, t.r0, *self.winds[req.name], t.params)
        return self.cache[key]

    def dispatch(self) -> None:
        """Drop the requests whose windows closed; assign the rest to free aircraft, port by port."""
        fleet, now = self.fleet, self.env.now
        self.waiting[:] = [r for r in self.waiting if r.t_s + r.window_s >= now]
        for port in range(fleet.vertiports):
            views = [AircraftView(str(i), fleet.belief(i), self.version[i]) for i in range(self.n)
                     if self.free[i] and fleet.base[i] == port]
            asks = [r for r in self.waiting if r.vertiport == port]
            for req, view in assign(asks, views, self.margin, self.required):
                i = int(view.name)
                self.waiting.remove(req)
                self.free[i] = False
                self.env.process(self.fly(i, req))

    def fly(self, i: int, req: Request):
        """Aircraft ``i`` flies ``req`` on its true pack in the actual winds, learns, then charges."""
        fleet, env, stats = self.fleet, self.env, self.stats
        truth = fleet.truth[i]
        sim = round_trip(req, truth.q_max, truth.r0, *self.winds[req.name], truth.params)
        cur, charge, flight_s = _delivered(sim)
        k = len(cur)
        breached = not bool(sim.safe)
        stats["flights"] += 1
        stats["charge_c"] += charge
        self.log.append((float(env.now), i, req.name, float(sim.min_voltage_v) - sim.eod_v, flight_s))
        yield env.timeout(flight_s)
        fleet.truth[i] = truth.after(charge)
        # the flight's readings (the sensors', never the truth) go into the pack's logbook, fitted once there; the
        # belief a dispatcher reads next is the logbook's
        measured_i = cur + self.noise.normal(0.0, NOISE_A, k)
        measured_v = np.asarray(sim.voltage_v[:k]) + self.noise.normal(0.0, NOISE_V, k)
        fleet.logbooks[i] = fleet.logbooks[i].appended(measured_i, measured_v, sim.dt_s)
        self.version[i] += 1
        if breached:
            stats["breaches"] += 1
            return  # grounded for the day
        stats["priority"] += req.priority
        stats["served"] += 1
        t0 = env.now
        with self.plugs[fleet.base[i]].request() as plug:
            yield plug
            stats["wait_s"] += env.now - t0
            yield env.timeout(_recharge_s(charge, fleet.truth[i].q_max))
        if fleet.truth[i].retired:
            fleet.in_service[i] = False
            return
        self.free[i] = True
        self.dispatch()

    def arrivals(self):
        """Requests arrive at their times; the last wait until their windows close or an aircraft is free."""
        env = self.env
        for req in self.demand:
            yield env.timeout(max(0.0, req.t_s - env.now))
            self.waiting.append(req)
            self.dispatch()
        while env.now < DAY_S:
            yield env.timeout(min(600.0, DAY_S - env.now))
            self.dispatch()

    def run(self) -> DayResult:
        """Run the day to :data:`END_S` (flights in the air at the day's end land) and total it."""
        self.env.process(self.arrivals())
        self.env.run(until=END_S)
        stats, flown = self.stats, {entry[2] for entry in self.log}
        return DayResult(priority=stats["priority"], served=stats["served"], refused=len(self.demand) - len(flown),
                         breaches=stats["breaches"], flights=stats["flights"], charge_ah=stats["charge_c"] / 3600.0,
                         charger_wait_s=stats["wait_s"], log=tuple(self.log), bound=self.bound)


def simulate_day(fleet: Fleet, demand: list[Request], dispatcher: str, seed: int,
                 chargers: int | Sequence[int] = 2, risk: float = DEFAULT_RISK) -> DayResult:
    """Fly one day of ``demand`` with ``fleet`` under ``dispatcher`` (:data:`DISPATCHERS`); the fleet's
    truth and beliefs are updated in place (packs age, beliefs learn). ``chargers``: per vertiport (one
    count for all, or one each, 1-50). Each request is served by an aircraft based at its vertiport.
    ``risk``: the declared risk the health-aware dispatcher's margins follow from (:func:`uam_studio.risk.caution`).
    Seeded: the same inputs give the same day (:class:`OperatingDay`)."""
    if dispatcher not in DISPATCHERS:
        raise InputError("dispatcher", f"{dispatcher!r}: allowed {', '.join(DISPATCHERS)}")
    counts = _charger_counts(fleet, demand, chargers)
    return OperatingDay(fleet, demand, dispatcher, day_seed(seed), counts, risk).run()


def fly_day_of_life(fleet: Fleet, demand: list[Request], dispatcher: str, seed: int, day: int,
                    chargers: int | Sequence[int] = 2, renew: bool = True, risk: float = DEFAULT_RISK
                    ) -> tuple[DayResult, list[int]]:
    """Day ``day`` (0-based) of the life seeded ``seed``: :func:`simulate_day` with the day's seed
    (:func:`day_of_life_seed`), then, with ``renew``, each pack that retired replaced overnight
    (:meth:`Fleet.renew_retired`). The one way a life's day is flown (:func:`simulate_life`, the CLI's
    ``--demand`` days, the app's Fleet tab). Returns the day and the aircraft renewed after it."""
    result = simulate_day(fleet, demand, dispatcher, day_of_life_seed(seed, day), chargers, risk)
    return result, (fleet.renew_retired(seed, day + 1) if renew else [])


def simulate_life(aircraft: int, days: int, seed: int, dispatcher: str, rate_per_h: float = DEFAULT_RATE_PER_H,
                  chargers: int = 2, age_spread_efc: float | None = None,
                  progress: Callable[[int], None] | None = None, max_km: float = DEFAULT_MAX_KM,
                  vertiports: int = 1, law: str = "nasa", renew: bool = True, world: str = DEFAULT_WORLD,
                  risk: float = DEFAULT_RISK) -> dict:
    """A fleet's life over ``days`` operating days of Poisson demand, requests up to ``max_km`` (km) away
    (the same days for every dispatcher with the same ``seed``), the aircraft spread over ``vertiports``
    vertiports of ``chargers`` chargers each, packs of cell type ``law`` aged U(0, ``age_spread_efc``)
    equivalent full cycles at the start (default :func:`default_age_spread`). With ``renew`` a retired
    pack is replaced overnight (and one already retired at the start, before the first day). ``risk``: the declared
    risk of the health-aware dispatcher (:func:`simulate_day`).

    :return: per day its :class:`DayResult` (as a dict); ``retired_day``: for each pack that retired, the
        day it did (0: before the first day), and None for each pack in service at the end; the fleet at
        the end (truth and belief)."""
    days = int(check_range("days", days, 1, 3650))
    seed = check_seed("seed", seed)
    check_risk(risk)  # before any work: one line naming the risk
    fleet = Fleet.new(aircraft, seed, age_spread_efc, vertiports, law, world)
    retired: list[int | None] = [0 for s in fleet.in_service if not s]
    counted = [not s for s in fleet.in_service]
    if renew:
        for i in fleet.renew_retired(seed, 0):
            counted[i] = False
    results = []
    for d in range(days):
        demand = poisson_demand(day_of_life_seed(seed, d), rate_per_h, max_km=max_km, vertiports=vertiports)
        result, renewed = fly_day_of_life(fleet, demand, dispatcher, seed, d, chargers, renew, risk)
        results.append(result)
        for i in renewed if renew else [i for i, s in enumerate(fleet.in_service) if not s]:  # retired by tonight
            if not counted[i]:
                retired.append(d + 1)
                counted[i] = True
        for i in renewed:
            counted[i] = False
        if progress is not None:
            progress(d + 1)
    retired += [None] * sum(fleet.in_service)
    return {"dispatcher": dispatcher, "days": [r.to_dict() for r in results], "retired_day": retired,
            "truth": [(t.q_max, t.r0, t.fraction) for t in fleet.truth],
            "belief": [(h.q_max_c, h.q_max_sd_c, h.r0_ohm, h.r0_sd_ohm) for h in (b.health for b in fleet.beliefs)]}

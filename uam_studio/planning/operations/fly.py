"""Fly a mission in a world the planner cannot see: :func:`fly_mission` -> :class:`FlightRecord`.

The loop is the only place that touches both sides. It takes the sensor readings from the
:class:`~uam_studio.planning.operations.world.World` and hands them to the
:class:`~uam_studio.planning.operations.operator.Operator`, and it flies the legs the operator
chooses. The operator gets the mission with its forecast winds and a placeholder cell.

Two references are flown in the same world (:mod:`~uam_studio.planning.operations.references`): the operator's
pre-flight plan flown blind, and hindsight. :func:`fly_mission` flies them unless told not to;
:func:`with_references` flies them later for a record flown without (the Fly tab shows the flight first).

A flight that breaches the cut-off scores 0 priority.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from uam_studio.battery import DEFAULT_Q_MAX, DEFAULT_R0, simulate
from uam_studio.battery.health.logbook import Logbook
from uam_studio.errors import InputError
from uam_studio.planning.legs import DT_S, N_MAX, takeoff_current
from uam_studio.planning.missions.mission import VERTIPORT, Battery, Mission, check_destination_count
from uam_studio.planning.operations.decision import Decision
from uam_studio.planning.operations.defaults import fit_noise_v
from uam_studio.planning.operations.leg_interval import leg_load, leg_lowest_voltage, takeoff_belief
from uam_studio.planning.operations.operator import (
    HEALTH_Z,
    IN_FLIGHT_PLANNERS,
    PLAN_WIND_Z,
    WEATHER_RESERVE_KT,
    WIND_Z,
    Operator,
)
from uam_studio.planning.operations.references import ReferenceFlight, fly_references, priority_of
from uam_studio.planning.operations.world import (
    DEFAULT_FORECAST_SIGMA_KT,
    DEFAULT_SENSOR_NOISE_MA,
    DEFAULT_SENSOR_NOISE_MV,
    DEFAULT_WORLD,
    WindEvent,
    World,
    parse_event,
)
from uam_studio.risk import DEFAULT_RISK, caution


@dataclass
class FlightRecord:
    """One flight, both sides.

    ``risk``: the declared risk its cautions followed from (None: cautions set by hand).
    The world: ``world`` (``"varied"`` or ``"model"``) and ``pack`` (the pack's number, which seeds its own
    parameter set in the varied world).
    Executed: ``route`` (nodes in order; ``"vertiport"`` is a recharge), ``altitudes_m`` (m) and
    ``actual_winds_kts`` (kt) of each leg, ``events`` (each re-plan as a :class:`Decision`),
    ``breached`` (the cell fell below the cut-off), ``breach_cause`` (for a breach: whether the weather
    changed by more than the operator's weather reserve ``reserve_kt`` (kt), or the breach is a decision
    error; "" without a breach), ``reached`` and ``reached_priority`` (0 when breached),
    ``charging_cycles`` (returns to the vertiport).
    Time series at 1 Hz from the first take-off: ``time_s`` (s), ``measured_voltage_v`` and
    ``measured_current_a`` (the sensors), ``true_voltage_v`` and ``true_current_a`` (the world), and
    ``predicted_voltage_v`` (the operator's prediction for each leg at the decision that chose it,
    from its health estimate and predicted wind; NaN-free: the take-off check holds the measurement).
    References (:class:`ReferenceFlight`, each flown in the same world): ``static`` (the pre-flight plan
    flown blind) and ``hindsight`` (the best plan knowing the true cell and the actual winds at each leg's
    time).
    ``takeoff_belief``: the health belief the first decision planned on: ``q_max_c`` and ``q_max_sd_c`` (C),
    ``r0_ohm`` and ``r0_sd_ohm`` (ohm), ``source`` (``"logbook"``: it started from the pack's logbook;
    ``"take-off"``: from the fleet prior and the take-off's readings), ``flights`` (in the logbook),
    and, where it chose a first leg, ``model_error_v`` (V, its model-error term then), ``model_error_share`` (the
    term's share of the interval's variance, 0-1), ``first_leg_min_voltage_90_v``
    (V, its 90% interval of that leg's lowest voltage) and ``first_leg_min_voltage_median_v`` (V). What the world
    gave: ``first_leg_min_voltage_v`` (V, the first leg's true lowest voltage; None when no leg was flown).
    :meth:`logbook_after` is the pack's logbook with this flight appended (its readings, one flight per charge).
    """

    mission: str
    scenario: str
    seed: int
    forecast_sigma_kt: float
    sensor_noise_mv: float
    sensor_noise_ma: float
    wind_events: list[str]
    reserve_kt: float = 0.0
    world: str = DEFAULT_WORLD
    pack: int = 0
    risk: float | None = None
    route: list[str] = field(default_factory=list)
    altitudes_m: list[float] = field(default_factory=list)
    actual_winds_kts: list[float] = field(default_factory=list)
    forecast_winds_kts: list[float] = field(default_factory=list)
    leg_end_s: list[float] = field(default_factory=list)
    events: list[Decision] = field(default_factory=list)
    breached: bool = False
    breach_cause: str = ""
    reached: list[str] = field(default_factory=list)
    reached_priority: int = 0
    charging_cycles: int = 0
    min_voltage_v: float = 0.0
    first_leg_min_voltage_v: float | None = None
    time_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_voltage_v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_current_a: np.ndarray = field(default_factory=lambda: np.zeros(0))
    true_voltage_v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    true_current_a: np.ndarray = field(default_factory=lambda: np.zeros(0))
    predicted_voltage_v: np.ndarray = field(default_factory=lambda: np.zeros(0))
    static: ReferenceFlight = field(default_factory=ReferenceFlight)
    hindsight: ReferenceFlight = field(default_factory=ReferenceFlight)
    true_q_max: float = 0.0
    true_r0: float = 0.0
    takeoff_belief: dict[str, Any] = field(default_factory=dict)
    wall_s: float = 0.0
    logbook_before: Logbook = field(default_factory=Logbook, repr=False)
    flown_charges: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list, repr=False)

    def logbook_after(self) -> Logbook:
        """The pack's logbook with this flight appended, one logged flight per charge (its measured readings;
        each fitted once, here)."""
        return self.logbook_before.extended(self.flown_charges, DT_S)

    @property
    def replan_s(self) -> list[float]:
        """Wall time (s) of each decision."""
        return [d.compute_s for d in self.events]

    def to_dict(self, series: bool = True) -> dict[str, Any]:
        """JSON-ready dict (finite numbers only); ``series=False`` leaves out the time series."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name in ("logbook_before", "flown_charges"):
                continue
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                if not series:
                    continue
                v = [round(float(x), 5) for x in v]
            elif f.name == "events":
                v = [d.to_dict() for d in v]
            elif isinstance(v, ReferenceFlight):
                v = dataclasses.asdict(v)
            elif isinstance(v, float):
                v = round(v, 6)
            out[f.name] = v
        out["replan_s"] = [round(x, 4) for x in self.replan_s]
        return out


RECORD_CSV_COLUMNS = ("time_s", "measured_voltage_v", "measured_current_a", "predicted_voltage_v",
                      "true_voltage_v", "true_current_a")


def record_csv(rec: FlightRecord) -> str:
    """The record's 1 Hz series as CSV text, one row per second: time (s); what the operator had
    (``measured_*``: the sensors, V and A; ``predicted_voltage_v``: its prediction, V); and what the
    world was (``true_*``, V and A, hidden from the operator during the flight)."""
    lines = [",".join(RECORD_CSV_COLUMNS)]
    cols = [np.asarray(getattr(rec, c), dtype=float) for c in RECORD_CSV_COLUMNS]
    lines += [",".join(f"{x:.5g}" if i == 0 else f"{x:.5f}" for i, x in enumerate(row)) for row in zip(*cols)]
    return "\n".join(lines) + "\n"


def breach_cause(world: World, reserve_kt: float) -> str:
    """Why a flight in ``world`` breached, in one line: the change of the weather the legs flew in
    exceeded the weather reserve (kt), or it did not: the change within the reserve together with the forecast's
    error and the cell's (the risk the check takes: it holds them jointly), or a decision error."""
    worst = max((world.change_kts(leg.start_s) for leg in world.legs), default=0.0)
    if worst > reserve_kt:
        return f"the change exceeded the reserve ({worst:+g} kt against a {reserve_kt:g} kt reserve)"
    return (f"within the reserve: the weather changed by {worst:+g} kt (reserve {reserve_kt:g} kt), with the "
            "forecast's and the cell's errors: the risk taken, or a decision error"
            if worst else f"a decision error or the risk taken: no change of the weather (reserve {reserve_kt:g} kt)")


def fly_mission(mission: Mission, policy: str = "attention", seed: int = 0,
                forecast_sigma_kt: float = DEFAULT_FORECAST_SIGMA_KT,
                sensor_noise_mv: float = DEFAULT_SENSOR_NOISE_MV,
                sensor_noise_ma: float = DEFAULT_SENSOR_NOISE_MA,
                events: Sequence[WindEvent] = (), scenario: str | None = None,
                health_z: float = HEALTH_Z, wind_z: float = WIND_Z, plan_wind_z: float = PLAN_WIND_Z,
                references: bool = True, reserve_kt: float = WEATHER_RESERVE_KT,
                operator: Callable[..., Operator] = Operator, logbook: Logbook | None = None,
                world: str = DEFAULT_WORLD, pack: int | None = None, risk: float | None = None,
                progress: Callable[[FlightRecord], None] | None = None) -> FlightRecord:
    """Fly ``mission`` once: the operator plans from the take-off check, re-plans at every arrival.

    :param mission: the mission; its ``battery`` is the world's true cell, its winds the forecast.
    :param policy: the operator's planner: ``"attention"`` (the learned planner, default) or
        ``"oracle"`` (exact search); either plans on the operator's belief, never on the world.
    :param seed: seeds the forecast errors and the sensor noise.
    :param forecast_sigma_kt: std (kt) of the forecast error per node, [0, 60]; the operator is told it.
    :param sensor_noise_mv: voltage sensor noise std (mV), [0, 100]; the operator is told it.
    :param sensor_noise_ma: current sensor noise std (mA), [0, 1000].
    :param events: scripted wind changes (:func:`~uam_studio.planning.operations.world.parse_event`).
    :param health_z: the operator's margin on its health estimate (std).
    :param wind_z: the operator's margin on each unflown leg's wind (std) for its safety check.
    :param plan_wind_z: the wind margin (std) of the belief it searches plans on.
    :param references: also fly the blind pre-flight plan and the hindsight oracle.
    :param reserve_kt: the operator's weather reserve (kt, 0-60, default 25): every take-off keeps the
        next leg and the way home safe under its cautious belief plus this much more headwind.
    :param operator: makes the operator from :class:`Operator`'s arguments (default: :class:`Operator`); a
        reference study passes another (``benchmarks/bench_weather.py informed``: one told the true cell).
    :param logbook: the pack's logbook (:class:`~uam_studio.battery.health.logbook.Logbook`: its earlier flights,
        as measured); the operator's health belief starts from it. None: a new pack (the fleet prior).
    :param world: ``"varied"`` (default: the pack is not its model, its sensors drift) or ``"model"`` (the pack is
        its model; :mod:`~uam_studio.planning.operations.world`). The operator is never told which.
    :param pack: the pack's number, which seeds its own parameter set in the varied world (None: ``seed``); a
        logbook made for the same pack (:func:`~uam_studio.planning.operations.pack_history.simulate_logbook`)
        names the same number.
    :param risk: the flight's declared risk (0-0.5, exclusive; :mod:`uam_studio.risk`): when given, ``health_z``,
        ``wind_z`` and ``reserve_kt`` follow from it (:func:`~uam_studio.risk.caution`) and are not read.
    :param progress: called after each leg that landed with the flight so far: a new record holding the legs,
        decisions and series until that landing, and no result yet (the Fly tab shows a flight from its first
        leg on while the rest is flown).
    :raises InputError: for bad input, naming the field; an event that starts after the flight
        (and its references) ended is an error of field ``event``.
    """
    t_wall = time.perf_counter()
    if risk is not None:
        c = caution(risk)
        health_z, wind_z, reserve_kt = c.health_z, c.wind_z, c.reserve_kt
    default = caution()
    declared = risk if risk is not None else (
        DEFAULT_RISK if (health_z, wind_z, reserve_kt) == (default.health_z, default.wind_z, default.reserve_kt)
        else None)
    if policy not in IN_FLIGHT_PLANNERS:
        raise InputError("policy", f"{policy!r} is not an in-flight policy; allowed: {', '.join(IN_FLIGHT_PLANNERS)}")
    # the hindsight oracle and policy "oracle": exact, 8 at most
    check_destination_count(len(mission.destinations), N_MAX, "fly")
    scenario = scenario or mission.scenario
    def new_world() -> World:  # the same hidden truth for the operator, the blind plan and hindsight
        return World(mission, forecast_sigma_kt, sensor_noise_mv, sensor_noise_ma, events, seed, world, pack)

    truth = new_world()
    known = dataclasses.replace(mission, battery=Battery(DEFAULT_Q_MAX, DEFAULT_R0))  # the operator's view
    book = logbook if logbook is not None else Logbook(noise_v=fit_noise_v(truth.sensor_noise_mv), eod_v=mission.eod_v)
    op = operator(known, scenario, truth.forecast_sigma_kt, truth.sensor_noise_mv, health_z, wind_z, plan_wind_z,
                  policy, reserve_kt, logbook=book)
    rec = FlightRecord(mission.name, scenario, int(seed), truth.forecast_sigma_kt, truth.sensor_noise_mv,
                       truth.sensor_noise_ma, [e.text for e in truth.events], op.reserve_kt, truth.world, truth.pack,
                       true_q_max=mission.battery.q_max, true_r0=mission.battery.r0, logbook_before=book)
    takeoff = np.asarray(takeoff_current(), dtype=float)  # every leg's vertical take-off and first climb
    series: dict[str, list[np.ndarray]] = {name: [] for name in RECORD_CSV_COLUMNS}

    def take(r, pred: np.ndarray) -> None:
        for name, x in zip(RECORD_CSV_COLUMNS, (r.time_s, r.voltage_v, r.current_a, pred, truth.last_true_voltage_v,
                                                truth.last_true_current_a)):
            series[name].append(x)
        op.observe(r.time_s, r.current_a, r.voltage_v)

    r = truth.takeoff_check(takeoff)
    take(r, r.voltage_v)
    if truth.breached:  # a cell too weak for the take-off: it fails within the check, before any plan
        rec.events.append(op.abort(f"take-off check: the cell fell below the {mission.eod_v:g} V cut-off after "
                                   f"{r.time_s.size * DT_S:.0f} s of vertical take-off; nothing is flown"))
    first = True
    takeoff_leg = None
    while not truth.breached:
        d = op.decide()
        rec.events.append(d)
        if d.next_to is None:
            break
        if first:
            op.start_leg_at(0.0)
        pred = _predict_leg(op, d, first)
        if first:
            takeoff_leg = (*leg_lowest_voltage(op, d, True), op.health_belief.model_error)
        assert d.next_altitude_m is not None  # a decision's next leg has both
        r = truth.fly_leg(d.next_to, d.next_altitude_m)
        leg = truth.legs[-1]
        take(r, _fit_length(pred, r.time_s.size))
        rec.route.append(leg.to)
        rec.altitudes_m.append(leg.altitude_m)
        rec.actual_winds_kts.append(round(leg.wind_kts, 3))
        rec.forecast_winds_kts.append(mission.node(leg.to).wind_kts)
        rec.leg_end_s.append(leg.end_s)
        if not r.landed:
            break
        if progress is not None:
            so_far: dict[str, Any] = {name: list(getattr(rec, name)) for name in (
                "route", "altitudes_m", "actual_winds_kts", "forecast_winds_kts", "leg_end_s", "events")}
            so_far.update({name: np.concatenate(parts) for name, parts in series.items()})
            progress(dataclasses.replace(rec, **so_far))
        op.arrived(d.next_to)
        first = False
    rec.takeoff_belief = takeoff_belief(rec.events[0], op, takeoff_leg) if rec.events else {}
    rec.first_leg_min_voltage_v = float(truth.legs[0].min_voltage_v) if truth.legs else None
    rec.flown_charges = op.health_belief.flown()
    rec.breached = truth.breached
    rec.breach_cause = breach_cause(truth, op.reserve_kt) if rec.breached else ""
    rec.reached = [n for n in rec.route if n != VERTIPORT]
    if rec.breached:
        rec.reached = rec.reached[:-1] if rec.route and rec.route[-1] != VERTIPORT else rec.reached
    rec.reached_priority = 0 if rec.breached else priority_of(mission, rec.reached)
    rec.charging_cycles = sum(1 for n in rec.route if n == VERTIPORT)
    for name, parts in series.items():
        setattr(rec, name, np.concatenate(parts))
    rec.min_voltage_v = float(min(leg.min_voltage_v for leg in truth.legs)) if truth.legs else float(
        rec.true_voltage_v.min())
    end_s = truth.time_s
    if references:
        rec.static, rec.hindsight, blind_end_s = _references(mission, rec, new_world, takeoff)
        end_s = max(end_s, blind_end_s)
    late = [e for e in truth.events if e.start_s > end_s]
    if late:
        raise InputError("event", f"{late[0].text} starts at {late[0].start_s:g} s, after the flight ended "
                                  f"({end_s:.0f} s); allowed: a start within the flight")
    rec.risk = declared
    rec.wall_s = time.perf_counter() - t_wall
    return rec


def with_references(mission: Mission, rec: FlightRecord) -> FlightRecord:
    """``rec`` with its references (``static``, ``hindsight``) flown: a new record, the same as ``fly_mission``
    with ``references=True`` gives for the same inputs. ``rec`` is a flight of ``mission`` flown with
    ``references=False``; its world is made again from its own settings (seed, noise, events, world, pack)."""
    def new_world() -> World:
        return World(mission, rec.forecast_sigma_kt, rec.sensor_noise_mv, rec.sensor_noise_ma,
                     [parse_event(e) for e in rec.wind_events], rec.seed, rec.world, rec.pack)

    static, hindsight, _ = _references(mission, rec, new_world, np.asarray(takeoff_current(), dtype=float))
    return dataclasses.replace(rec, static=static, hindsight=hindsight)


def _references(mission: Mission, rec: FlightRecord, new_world: Callable[[], World], takeoff: np.ndarray
                ) -> tuple[ReferenceFlight, ReferenceFlight, float]:
    """:func:`~uam_studio.planning.operations.references.fly_references` of ``rec``: its first plan flown blind
    and hindsight, in ``new_world()``; with the blind flight's end (s)."""
    first_plan = next((e for e in rec.events if e.kind == "plan"), None)
    planned = (first_plan.route, first_plan.altitudes_m) if first_plan else ((), ())
    return fly_references(mission, rec.scenario, new_world, takeoff, planned, (rec.route, rec.altitudes_m))


def flight_before(rec: FlightRecord, event: WindEvent) -> FlightRecord | None:
    """``rec``'s flight until the landing of its last leg that took off before ``event`` starts, with the event
    added to its wind changes: what :func:`fly_mission` flies with the event too, up to there (the same seeds; a
    change reaches the legs that take off from its start on), as ``progress`` hands it (no result yet). None when no
    leg took off before the event starts. A leg takes off where the one before it landed (the first at 0 s, with its
    take-off check)."""
    starts = [0.0, *rec.leg_end_s[:-1]][:len(rec.leg_end_s)]  # no leg flown (a failed take-off check): none
    k = sum(1 for t in starts if t < event.start_s)
    if k == 0:
        return None
    end = rec.leg_end_s[k - 1]
    n = int(np.searchsorted(rec.time_s, end, side="right"))
    changes = sorted([*map(parse_event, rec.wind_events), event], key=lambda e: e.start_s)
    return FlightRecord(rec.mission, rec.scenario, rec.seed, rec.forecast_sigma_kt, rec.sensor_noise_mv,
                        rec.sensor_noise_ma, [e.text for e in changes], rec.reserve_kt, rec.world, rec.pack,
                        rec.risk, route=rec.route[:k], altitudes_m=rec.altitudes_m[:k],
                        actual_winds_kts=rec.actual_winds_kts[:k], forecast_winds_kts=rec.forecast_winds_kts[:k],
                        leg_end_s=rec.leg_end_s[:k], events=[d for d in rec.events if d.time_s < end],
                        true_q_max=rec.true_q_max, true_r0=rec.true_r0, logbook_before=rec.logbook_before,
                        **{name: getattr(rec, name)[:n] for name in RECORD_CSV_COLUMNS})


def _predict_leg(op: Operator, d: Decision, first: bool) -> np.ndarray:
    """The operator's predicted voltage (V) for the leg it chose: its median health, predicted wind."""
    assert d.next_to is not None  # a decision with a next leg
    hist, future = leg_load(op, d, first, op.winds.predict(d.next_to)[0])
    res = simulate(np.concatenate([hist, future]), DT_S, d.q_max_c, d.r0_ohm, 2.5)
    return np.asarray(res.voltage_v[hist.size:], dtype=float)


def position_at(rec: FlightRecord, mission: Mission, t_s: float) -> tuple[float, float, int]:
    """Where the aircraft of ``rec`` is at ``t_s`` (s): ``(x_km, y_km, leg index)``, moving linearly in
    time along each flown leg between its take-off and its landing (-1 before the first leg's start;
    the last leg's index after the flight)."""
    nodes = [VERTIPORT] + list(rec.route)
    starts = [0.0] + list(rec.leg_end_s[:-1])
    for k, (start, end) in enumerate(zip(starts, rec.leg_end_s)):
        if t_s <= end or k == len(rec.route) - 1:
            a, b = mission.node(nodes[k]), mission.node(nodes[k + 1])
            f = float(np.clip((t_s - start) / max(end - start, 1e-9), 0.0, 1.0))
            if rec.breached and k == len(rec.route) - 1:
                f = min(f, 0.999)
            return a.x_km + f * (b.x_km - a.x_km), a.y_km + f * (b.y_km - a.y_km), k
    vp = mission.vertiport
    return vp.x_km, vp.y_km, -1


def _fit_length(a: np.ndarray, n: int) -> np.ndarray:
    if a.size >= n:
        return a[:n]
    pad = a[-1] if a.size else 0.0
    return np.concatenate([a, np.full(n - a.size, pad)])


__all__ = ["FlightRecord", "fly_mission", "position_at"]

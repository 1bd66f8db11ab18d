"""Fly a route of a mission through the flight and battery models.

A route starts at the vertiport implicitly; each entry is a destination name or
``"vertiport"``. Landing at the vertiport recharges the cell instantly (its state is
reset to :func:`uam_studio.battery.full_charge`); the clock keeps running. Each leg
``a -> b`` is flown with :func:`uam_studio.flight.leg_profile` at its own altitude,
in the wind of ``b`` (:meth:`Mission.leg_wind`), followed by ``b``'s dwell, and is
simulated from the state the previous leg ended in, so a route without recharges
gives exactly what one :func:`uam_studio.battery.simulate` call on the concatenated
current gives.

Sample convention (as in :func:`uam_studio.battery.simulate`): ``current_a[k]`` flows
during ``[k dt, (k+1) dt)`` and ``voltage_v[k]`` is the terminal voltage at
``time_s[k] = (k+1) dt``, the clock starting at 0 at the first take-off. A leg takes
a whole number of steps (its last step averages the tail of the profile).

At end of discharge (EOD) the flight stops: the arrays end with the first sample
below ``eod_v`` (so ``eod_s == time_s[-1]``), that leg and all later ones have
``reached=False``, and legs never started have ``start_s``, ``end_s`` and
``min_voltage_v`` set to ``None``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from uam_studio.battery import EOD_RANGE, Q_MAX_RANGE, R0_RANGE, full_charge, simulate
from uam_studio.battery.parameters import CellParameters
from uam_studio.errors import InputError, check_range
from uam_studio.flight import ALTITUDE_RANGE_M, leg_feasible, leg_profile, min_leg_distance_km
from uam_studio.flight.profile import MAX_DISTANCE_KM
from uam_studio.planning.missions.mission import VERTIPORT, Mission

DT_RANGE_S = (1e-3, 60.0)  # accepted by both leg_profile and simulate
MAX_SAMPLES = 5_000_000  # whole route; guards against a tiny dt_s on a long route
MAX_ROUTE_LEGS = 200  # legs in one simulated route: 20 destinations with a recharge after each need 40
_ZERO_KM = 1e-9


@dataclass(frozen=True)
class LegResult:
    """One leg of a simulated route.

    ``start_s``/``end_s`` (s) are take-off and the end of the dwell after landing;
    ``end_s`` is ``None`` if the cell reached EOD on the way (``reached=False``), and
    ``start_s``, ``min_voltage_v`` are ``None`` too for legs never started.
    ``min_voltage_v`` (V) includes the sub-cut-off sample on the EOD leg.
    """

    to: str
    altitude_m: float
    start_s: float | None
    end_s: float | None
    min_voltage_v: float | None
    reached: bool
    from_node: str = VERTIPORT
    distance_km: float = 0.0


@dataclass(frozen=True, eq=False)
class RouteSimulation:
    """Result of :func:`simulate_route`: whole-route series, EOD and per-leg results.

    ``time_s`` (s), ``current_a`` (A, per cell), ``voltage_v`` (V), ``valid`` (False
    only at the EOD sample, the last one, if EOD was reached); ``eod_s`` (s) or ``None``;
    ``charging_cycles``: number of landings at the vertiport (each one recharges).
    """

    time_s: np.ndarray
    current_a: np.ndarray
    voltage_v: np.ndarray
    valid: np.ndarray
    eod_s: float | None
    legs: list[LegResult]
    charging_cycles: int
    q_max: float
    r0: float
    eod_v: float
    dt_s: float

    @property
    def safe(self) -> bool:
        """True if the whole route is flown without reaching EOD."""
        return self.eod_s is None

    @property
    def complete(self) -> bool:
        """True if the route ends back at the vertiport. A route that ends elsewhere is a part of a plan:
        ``safe`` then says only that the legs given were flown above the cut-off."""
        return bool(self.legs) and self.legs[-1].to == VERTIPORT

    @property
    def min_voltage_v(self) -> float:
        """Lowest voltage (V) over the route (the EOD sample included)."""
        return float(self.voltage_v.min())

    @property
    def reached(self) -> tuple[str, ...]:
        """Destinations reached (names, in first-visit order), up to the first leg that failed."""
        out: list[str] = []
        for leg in self.legs:
            if not leg.reached:
                break
            if leg.to != VERTIPORT and leg.to not in out:
                out.append(leg.to)
        return tuple(out)

    def sortie_cuts(self) -> list[int]:
        """Sample indices where the sorties start, then the number of samples: ``[0, ..., n]``.

        A sortie ends with each landing at the vertiport (a landing recharges); sortie ``k`` is
        samples ``cuts[k]:cuts[k + 1]``. The Dynaformer predicts a route sortie by sortie on these
        cuts (:func:`~uam_studio.planning.planner.plan_mission`, its prediction and band).
        """
        cuts = [0]
        for leg in self.legs:
            if leg.reached and leg.to == VERTIPORT and leg.end_s is not None:
                cuts.append(int(round(leg.end_s / self.dt_s)))
        n = self.current_a.size
        return sorted({c for c in cuts if c < n} | {n})

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dict: arrays as lists rounded to 6 decimals, ``None`` for missing values."""
        return {
            "time_s": _rounded(self.time_s),
            "current_a": _rounded(self.current_a),
            "voltage_v": _rounded(self.voltage_v),
            "eod_s": _round_opt(self.eod_s),
            "safe": self.safe,
            "complete": self.complete,
            "legs": [
                {
                    "to": leg.to,
                    "altitude_m": float(leg.altitude_m),
                    "start_s": _round_opt(leg.start_s),
                    "end_s": _round_opt(leg.end_s),
                    "min_voltage_v": _round_opt(leg.min_voltage_v),
                }
                for leg in self.legs
            ],
        }


def _rounded(arr: np.ndarray) -> list[float]:
    return [float(x) for x in np.round(np.asarray(arr, dtype=float), 6)]


def _round_opt(x: float | None) -> float | None:
    return None if x is None else round(float(x), 6)


@dataclass(frozen=True)
class _Leg:
    frm: str
    to: str
    altitude_m: float
    distance_km: float
    wind_kts: float
    dwell_s: float


def _plan_legs(mission: Mission, route: Sequence[str], altitudes_m: Sequence[float]) -> list[_Leg]:
    """Validate the route against the mission and return its legs."""
    if isinstance(route, str):
        raise InputError("route", f"expected a list of node names, got the string {route!r}")
    try:
        route = list(route)
    except TypeError:
        raise InputError("route", f"expected a list of node names, got {route!r}") from None
    valid_names = mission.node_names
    if not route:
        raise InputError("route", f"is empty; give at least one of: {', '.join(valid_names)}")
    for name in route:
        if not isinstance(name, str) or name not in valid_names:
            raise InputError("route", f"unknown node {name!r}; valid names: {', '.join(valid_names)}")
    if isinstance(altitudes_m, str):
        raise InputError("altitudes", f"expected a list of numbers (m), got the string {altitudes_m!r}")
    try:
        altitudes = list(altitudes_m)
    except TypeError:
        raise InputError("altitudes", f"expected a list of numbers (m), got {altitudes_m!r}") from None
    if len(altitudes) != len(route):
        raise InputError(
            "altitudes",
            f"has {len(altitudes)} value{'s' * (len(altitudes) != 1)} but the route has {len(route)} "
            f"leg{'s' * (len(route) != 1)}; give one altitude (m) per leg",
        )
    alts = [check_range(f"altitudes[{i}]", a, *ALTITUDE_RANGE_M, " m") for i, a in enumerate(altitudes)]

    legs: list[_Leg] = []
    prev = VERTIPORT
    for i, (name, h) in enumerate(zip(route, alts, strict=True)):
        d = mission.distance_km(prev, name)
        what = f"leg {i + 1} ({prev} -> {name})"
        if d <= _ZERO_KM:
            why = "flies to the node it starts from" if prev == name else "joins two nodes at the same place"
            raise InputError("route", f"{what} has zero length: it {why}")
        if d > MAX_DISTANCE_KM:
            raise InputError("route", f"{what} is {d:.1f} km; legs are limited to {MAX_DISTANCE_KM:g} km")
        if not leg_feasible(d, h):
            need = math.ceil(min_leg_distance_km(h) * 10) / 10
            raise InputError(
                f"altitudes[{i}]",
                f"{what} is {d:.1f} km, too short to cruise at {h:g} m (needs >= {need:.1f} km); "
                "fly it lower",
            )
        node = mission.node(name)
        legs.append(_Leg(prev, name, h, d, node.wind_kts, getattr(node, "dwell_s", 0.0)))
        prev = name
    return legs


def simulate_route(
    mission: Mission,
    route: Sequence[str],
    altitudes_m: Sequence[float],
    q_max: float | None = None,
    r0: float | None = None,
    eod_v: float | None = None,
    dt_s: float = 1.0,
    params: CellParameters | None = None,
) -> RouteSimulation:
    """Fly ``route`` (node names; ``"vertiport"`` recharges) at ``altitudes_m`` (m, one per leg).

    ``q_max`` (C), ``r0`` (ohm), ``eod_v`` (V) default to the mission's; ``dt_s`` (s) is
    the sample step; ``params``: the cell's parameter set (default: the mission's, the cell type's; a world's pack
    passes its own). The whole route is validated before anything is simulated.

    :raises InputError: ``route`` for an unknown name, an empty route, more than
        :data:`MAX_ROUTE_LEGS` legs, or a zero-length or over-long leg; ``altitudes`` for a count
        mismatch; ``altitudes[i]`` for an altitude out of range or too high for the leg's length; ``q_max``, ``r0``,
        ``eod_v``, ``dt_s`` for out-of-range values.
    """
    if not isinstance(mission, Mission):
        raise InputError("mission", f"expected a Mission, got {type(mission).__name__}")
    q = check_range("q_max", mission.battery.q_max if q_max is None else q_max, *Q_MAX_RANGE, " C")
    r = check_range("r0", mission.battery.r0 if r0 is None else r0, *R0_RANGE, " ohm")
    eod = check_range("eod_v", mission.eod_v if eod_v is None else eod_v, *EOD_RANGE, " V")
    dt = check_range("dt_s", dt_s, *DT_RANGE_S, " s")
    if len(route) > MAX_ROUTE_LEGS:
        raise InputError("route", f"{len(route)} legs; at most {MAX_ROUTE_LEGS} allowed in one route")
    legs = _plan_legs(mission, route, altitudes_m)

    # Sample count, from coarse profiles (cheap), before allocating anything large.
    total = sum(
        math.ceil(leg_profile(g.distance_km, g.altitude_m, g.wind_kts, 60.0, g.dwell_s).duration_s / dt)
        for g in legs
    )
    if total > MAX_SAMPLES:
        raise InputError(
            "dt_s", f"{dt_s!r} s gives ~{total:,} samples for this route (limit {MAX_SAMPLES:,}); use a larger step"
        )

    params = mission.cell.params if params is None else params
    state = full_charge(q, params)
    currents: list[np.ndarray] = []
    voltages: list[np.ndarray] = []
    valids: list[np.ndarray] = []
    results: list[LegResult] = []
    steps = 0
    eod_s: float | None = None
    cycles = 0
    for g in legs:
        if eod_s is not None:
            results.append(LegResult(g.to, g.altitude_m, None, None, None, False, g.frm, g.distance_km))
            continue
        profile = leg_profile(g.distance_km, g.altitude_m, g.wind_kts, dt, g.dwell_s)
        res = simulate(profile.current_a, dt, q, r, eod, initial_state=state, cell=params)
        start = steps * dt
        keep = int(np.argmin(res.valid)) + 1 if res.eod_reached else len(profile.current_a)
        currents.append(np.asarray(profile.current_a[:keep], dtype=float))
        voltages.append(np.asarray(res.voltage_v[:keep], dtype=float))
        valids.append(np.asarray(res.valid[:keep], dtype=bool))
        steps += keep
        v_min = float(voltages[-1].min())
        if res.eod_reached:
            eod_s = steps * dt
            results.append(LegResult(g.to, g.altitude_m, start, None, v_min, False, g.frm, g.distance_km))
            continue
        results.append(LegResult(g.to, g.altitude_m, start, steps * dt, v_min, True, g.frm, g.distance_km))
        if g.to == VERTIPORT:
            state = full_charge(q, params)
            cycles += 1
        else:
            state = res.final_state

    arrays = [np.concatenate(x) for x in (currents, voltages, valids)]
    for a in arrays:
        a.setflags(write=False)
    time_s = dt * np.arange(1, steps + 1)
    time_s.setflags(write=False)
    return RouteSimulation(time_s, arrays[0], arrays[1], arrays[2], eod_s, results, cycles, q, r, eod, dt)

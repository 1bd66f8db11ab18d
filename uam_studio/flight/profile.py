"""A flight leg as a piecewise-constant pack-power profile and its per-cell current.

Phases, in order: vertical take-off, climb, cruise, 45 deg descent to 500 m,
8 deg approach from 500 m, vertical landing, then an optional 0 kW dwell.
Non-cruise phases come from the paper's phase table (a 30 nm flight), cruise
from its wind table; see :mod:`uam_studio.flight.tables`. As in the paper, the
cruise covers the whole leg distance (climb and approach distances are not
subtracted), but a leg must be long enough to contain them: see
:func:`min_leg_distance_km`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from uam_studio.errors import InputError, check_range
from uam_studio.flight import tables
from uam_studio.flight.scaling import power_kw_to_cell_current_a

PHASES = (
    "vertical_takeoff",
    "climb",
    "cruise",
    "descent",
    "approach",
    "vertical_landing",
)
MAX_DISTANCE_KM = 500.0
MAX_DT_S = 60.0
MAX_DWELL_S = 86_400.0
MAX_SAMPLES = 2_000_000  # samples of one leg profile (about 48 MB of float64 arrays)
# Modelling assumption: the paper gives climb durations but no climb distances.
CLIMB_GROUND_SPEED_MPS = 30.0
APPROACH_START_ALTITUDE_M = 500.0
APPROACH_ANGLE_DEG = 8.0
DESCENT_ANGLE_DEG = 45.0

_TABLE_NAME = {"descent": "descent_45deg", "approach": "approach_8deg"}


class InfeasibleLegError(InputError):
    """The leg is too short to climb to, and come down from, its cruise altitude."""


def _check_open(field: str, value: float, hi: float, unit: str) -> float:
    x = check_range(field, value, 0.0, hi, unit)
    if x == 0.0:
        raise InputError(field, f"{value!r} is out of range; allowed (0, {hi:g}]{unit}")
    return x


def min_leg_distance_km(altitude_m: float) -> float:
    """Shortest leg (km) that fits climb, 45 deg descent and 8 deg approach at a cruise altitude (m).

    Climb: table climb duration x ``CLIMB_GROUND_SPEED_MPS``; descent: ``h - 500 m``
    horizontally; approach: ``500 m / tan 8 deg`` = 3.558 km. About 6.1 km at
    500 m and 22.8 km at 3000 m.
    """
    h = check_range("altitude_m", altitude_m, *tables.ALTITUDE_RANGE_M, " m")
    climb_m = tables.phase_duration_s("climb", h) * CLIMB_GROUND_SPEED_MPS
    descent_m = (h - APPROACH_START_ALTITUDE_M) / math.tan(
        math.radians(DESCENT_ANGLE_DEG)
    )
    approach_m = APPROACH_START_ALTITUDE_M / math.tan(math.radians(APPROACH_ANGLE_DEG))
    return (climb_m + descent_m + approach_m) / 1000.0


def leg_feasible(distance_km: float, altitude_m: float) -> bool:
    """True if a leg of ``distance_km`` (km) can be flown at ``altitude_m`` (m)."""
    d = _check_open("distance_km", distance_km, MAX_DISTANCE_KM, " km")
    return d >= min_leg_distance_km(altitude_m)


@dataclass(frozen=True, eq=False)
class LegProfile:
    """One leg: phases as ``(name, start_s, end_s, pack_power_kw)`` and sampled series.

    ``time_s[k] = k * dt_s`` is the start of step k; ``power_kw[k]`` (pack, kW) and
    ``current_a[k]`` (per cell, A) are exact averages over ``[k*dt, (k+1)*dt)``, so
    energy and charge are conserved for any ``dt_s``.
    """

    distance_km: float
    altitude_m: float
    wind_kts: float
    dt_s: float
    dwell_s: float
    phases: tuple[tuple[str, float, float, float], ...]
    duration_s: float
    time_s: np.ndarray
    power_kw: np.ndarray
    current_a: np.ndarray

    @property
    def energy_kwh(self) -> float:
        """Pack energy of the leg (kWh)."""
        return float(self.power_kw.sum() * self.dt_s / 3600.0)

    @property
    def charge_c(self) -> float:
        """Charge drawn from one cell (C)."""
        return float(self.current_a.sum() * self.dt_s)


def _phase_specs(distance_km, altitude_m, wind_kts, dwell_s) -> tuple[float, float, list[tuple[str, float, float]]]:
    """Checked (distance km, altitude m) and the phases as (name, duration s, pack power kW)."""
    d = _check_open("distance_km", distance_km, MAX_DISTANCE_KM, " km")
    h = check_range("altitude_m", altitude_m, *tables.ALTITUDE_RANGE_M, " m")
    w = check_range("wind_kts", wind_kts, *tables.WIND_RANGE_KTS, " kt")
    dwell = check_range("dwell_s", dwell_s, 0.0, MAX_DWELL_S, " s")
    need = min_leg_distance_km(h)
    if d < need:
        raise InfeasibleLegError(
            "distance_km",
            f"{d:.1f} km is too short for cruise at {h:g} m; needs >= {math.ceil(need * 10) / 10:.1f} km",
        )
    specs: list[tuple[str, float, float]] = []
    for name in PHASES:
        if name == "cruise":
            specs.append(
                (name, tables.cruise_duration_s(d, h, w), tables.cruise_power_kw(h, w))
            )
        else:
            key = _TABLE_NAME.get(name, name)
            specs.append(
                (name, tables.phase_duration_s(key, h), tables.phase_power_kw(key, h))
            )
    if dwell > 0:
        specs.append(("dwell", dwell, 0.0))
    return d, h, specs


def leg_profile(
    distance_km: float,
    altitude_m: float,
    wind_kts: float,
    dt_s: float = 1.0,
    dwell_s: float = 0.0,
) -> LegProfile:
    """Power profile of a leg of ``distance_km`` (km, (0, 500]) at ``altitude_m`` (m, [500, 3000])
    in ``wind_kts`` (kt, [-39, 39], negative = tailwind), sampled every ``dt_s`` (s, (0, 60]),
    followed by ``dwell_s`` (s, [0, 86400]) at 0 kW; at most ``MAX_SAMPLES`` samples.

    Raises :class:`InputError` for out-of-range inputs and :class:`InfeasibleLegError`
    if the leg is shorter than :func:`min_leg_distance_km`.
    """
    dt = _check_open("dt_s", dt_s, MAX_DT_S, " s")
    d, h, specs = _phase_specs(distance_km, altitude_m, wind_kts, dwell_s)
    dwell = float(dwell_s)
    w = float(wind_kts)

    phases, t = [], 0.0
    for name, dur, p in specs:
        phases.append((name, t, t + dur, p))
        t += dur
    duration = t

    # Cumulative pack energy (kJ) at the phase boundaries; linear in between, flat after the end.
    bounds = np.array([0.0] + [end for _, _, end, _ in phases])
    energy = np.concatenate(
        [[0.0], np.cumsum([p * (end - start) for _, start, end, p in phases])]
    )
    n = max(1, math.ceil(duration / dt - 1e-9))
    if n > MAX_SAMPLES:
        raise InputError("dt_s", f"{dt_s!r} s gives {n} samples for this {duration:.0f} s leg; at most "
                                 f"{MAX_SAMPLES} allowed, so dt_s >= {duration / MAX_SAMPLES:.3g} s here")
    edges = np.arange(n + 1) * dt
    power = np.diff(np.interp(edges, bounds, energy)) / dt
    current = np.asarray(power_kw_to_cell_current_a(power))
    time = edges[:-1]
    for arr in (time, power, current):
        arr.setflags(write=False)
    return LegProfile(d, h, w, dt, dwell, tuple(phases), duration, time, power, current)


def leg_charge_c(distance_km: float, altitude_m: float, wind_kts: float, dwell_s: float = 0.0) -> float:
    """Charge (C) one cell gives on a leg: :attr:`LegProfile.charge_c` without sampling the profile.

    The sampled current conserves energy exactly, so this equals ``leg_profile(...).charge_c`` for
    any ``dt_s`` (to float rounding). Same inputs and errors as :func:`leg_profile`.
    """
    _, _, specs = _phase_specs(distance_km, altitude_m, wind_kts, dwell_s)
    return float(power_kw_to_cell_current_a(sum(p * dur for _, dur, p in specs)))


def leg_charges_c(distance_km: np.ndarray, altitudes_m, wind_kts: np.ndarray) -> np.ndarray:
    """Charge (C) one cell gives on many legs at a few altitudes: :func:`leg_charge_c` elementwise,
    bit for bit (the same products summed in the same order), without the per-leg checks.

    ``distance_km`` (km) and ``wind_kts`` (kt) broadcast against each other to the legs' shape;
    the result is ``[*legs, len(altitudes_m)]`` (m). A dwell draws no charge, so none is taken.
    Legs too short for an altitude get a value too: callers mask them with
    :func:`min_leg_distance_km`. Raises :class:`InputError` for an altitude, distance or wind out
    of range (distances may be 0 here: a table's diagonal).
    """
    d = np.asarray(distance_km, dtype=float)
    w = np.asarray(wind_kts, dtype=float)
    if not np.all((d >= 0.0) & (d <= MAX_DISTANCE_KM)):
        raise InputError("distance_km", f"has values outside [0, {MAX_DISTANCE_KM:g}] km")
    if not np.all((w >= tables.WIND_RANGE_KTS[0]) & (w <= tables.WIND_RANGE_KTS[1])):
        raise InputError("wind_kts", f"has values outside [{tables.WIND_RANGE_KTS[0]:g}, "
                                     f"{tables.WIND_RANGE_KTS[1]:g}] kt")
    hs = tuple(float(h) for h in np.atleast_1d(altitudes_m))
    power, speed = tables.cruise_table_many(hs, w)  # [n_alt, *w.shape]
    power, speed = np.moveaxis(power, 0, -1), np.moveaxis(speed, 0, -1)  # [*w.shape, n_alt]
    d = d[..., None]
    total = np.zeros(np.broadcast_shapes(d.shape, power.shape))
    for term in _phase_charge_terms(hs):  # the order of _phase_specs, so the float sums match leg_charge_c's
        total += (d * 1000.0 / speed) * power if term is None else term
    return np.asarray(power_kw_to_cell_current_a(total))


@functools.lru_cache(maxsize=64)
def _phase_charge_terms(altitudes_m: tuple[float, ...]) -> tuple[np.ndarray | None, ...]:
    """Per phase, in ``PHASES`` order: power x duration (kW s) of a non-cruise phase at each
    altitude (m), None for the cruise (it depends on the leg)."""
    terms: list[np.ndarray | None] = []
    for name in PHASES:
        if name == "cruise":
            terms.append(None)
        else:
            key = _TABLE_NAME.get(name, name)
            term = np.array([tables.phase_duration_s(key, h) * tables.phase_power_kw(key, h) for h in altitudes_m])
            term.setflags(write=False)
            terms.append(term)
    return tuple(terms)


def leg_current(
    distance_km: float, altitude_m: float, wind_kts: float, dt_s: float = 1.0
) -> np.ndarray:
    """Per-cell current (A) of a leg, one value per ``dt_s`` step (see :func:`leg_profile`)."""
    return np.array(leg_profile(distance_km, altitude_m, wind_kts, dt_s).current_a)

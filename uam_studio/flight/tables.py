"""The paper's appendix flight tables and their interpolation.

Tables (``uam_studio/data``, transcribed from the appendix of "Prescribing Optimal
Health-Aware Operation for Urban Air Mobility with Deep RL"):

* ``paper_flight_phases.csv``: pack power (kW) and duration (s) of each phase of a
  30 nm flight in a 13 kt tailwind at cruise altitudes 500, 1000, 2000, 3000 m.
  The paper's "Negligible" descent/approach power is 0 kW.
* ``paper_cruise_wind.csv``: cruise airspeed (m/s), pack power (kW) and duration (s)
  of a 30 nm cruise per altitude and wind (-39, -26, -13, 13, 26, 39 kt;
  negative = tailwind, positive = headwind).

Interpolation is piecewise linear in altitude between the 4 table altitudes and,
for cruise, piecewise linear in wind between the 6 table winds (there is no 0 kt
row, so 0 kt lies halfway between -13 and +13 kt). Cruise time comes from an
*effective ground speed* = 55.56 km (30 nm) / tabulated duration, interpolated
the same way, so ``distance / ground speed`` reproduces every table duration
exactly for a 30 nm cruise.

Cruise power always comes from the wind table. The two tables disagree at one
point: 2000 m / -13 kt is 145.68 kW in the phase table and 148.68 kW in the wind
table; 148.68 fits the pattern of the other altitudes (see the shared data README),
so we use it.
"""

from __future__ import annotations

import csv
import io
from functools import cache, lru_cache
from importlib.resources import files
from typing import NamedTuple

import numpy as np

from uam_studio.errors import InputError, check_range

CRUISE_TABLE_DISTANCE_KM = 55.56  # 30 nm, the leg length behind every table row
ALTITUDE_RANGE_M = (500.0, 3000.0)  # table altitudes span this range
WIND_RANGE_KTS = (-39.0, 39.0)  # table winds span this range
TABLE_PHASES = (
    "vertical_takeoff",
    "climb",
    "descent_45deg",
    "approach_8deg",
    "vertical_landing",
)


class PhaseRow(NamedTuple):
    altitude_m: float
    phase: str
    power_kw: float
    duration_s: float


class CruiseRow(NamedTuple):
    altitude_m: float
    wind_kts: float
    airspeed_mps: float
    power_kw: float
    duration_s: float


def _read_csv(name: str) -> list[dict[str, str]]:
    text = (files("uam_studio") / "data" / name).read_text(encoding="utf-8")
    return list(csv.DictReader(io.StringIO(text)))


@cache
def phase_rows() -> tuple[PhaseRow, ...]:
    """Rows of ``paper_flight_phases.csv`` (m, phase, kW, s), as published."""
    return tuple(
        PhaseRow(
            float(r["cruise_altitude_m"]),
            r["phase"],
            float(r["power_kw"]),
            float(r["duration_s"]),
        )
        for r in _read_csv("paper_flight_phases.csv")
    )


@cache
def cruise_rows() -> tuple[CruiseRow, ...]:
    """Rows of ``paper_cruise_wind.csv`` (m, kt, m/s, kW, s), as published."""
    return tuple(
        CruiseRow(
            *(
                float(r[k])
                for k in (
                    "cruise_altitude_m",
                    "wind_kts",
                    "cruise_airspeed_mps",
                    "power_kw",
                    "duration_s",
                )
            )
        )
        for r in _read_csv("paper_cruise_wind.csv")
    )


@cache
def _grids() -> dict[str, np.ndarray]:
    alts = np.array(sorted({r.altitude_m for r in cruise_rows()}))
    winds = np.array(sorted({r.wind_kts for r in cruise_rows()}))
    g: dict[str, np.ndarray] = {"alt": alts, "wind": winds}
    for key in ("airspeed_mps", "power_kw", "speed_mps"):
        g[key] = np.full((alts.size, winds.size), np.nan)
    for r in cruise_rows():
        i, j = np.searchsorted(alts, r.altitude_m), np.searchsorted(winds, r.wind_kts)
        g["airspeed_mps"][i, j] = r.airspeed_mps
        g["power_kw"][i, j] = r.power_kw
        g["speed_mps"][i, j] = CRUISE_TABLE_DISTANCE_KM * 1000.0 / r.duration_s
    for phase in TABLE_PHASES:
        rows = sorted(
            (r for r in phase_rows() if r.phase == phase), key=lambda r: r.altitude_m
        )
        if [r.altitude_m for r in rows] != list(alts):
            raise RuntimeError(
                f"phase table altitudes for {phase} differ from the cruise table"
            )
        g[f"{phase}.power_kw"] = np.array([r.power_kw for r in rows])
        g[f"{phase}.duration_s"] = np.array([r.duration_s for r in rows])
    if any(np.isnan(g[k]).any() for k in ("airspeed_mps", "power_kw", "speed_mps")):
        raise RuntimeError(
            "paper_cruise_wind.csv does not fill the altitude x wind grid"
        )
    return g


def _check_alt(altitude_m: float) -> float:
    return check_range("altitude_m", altitude_m, *ALTITUDE_RANGE_M, " m")


@lru_cache(maxsize=4096)  # planners ask for the same few altitudes over and over (errors are not cached)
def _phase(phase: str, altitude_m: float, what: str) -> float:
    if phase not in TABLE_PHASES:
        raise InputError(
            "phase",
            f"{phase!r} is not a table phase; allowed {', '.join(TABLE_PHASES)}",
        )
    g = _grids()
    return float(np.interp(_check_alt(altitude_m), g["alt"], g[f"{phase}.{what}"]))


def phase_power_kw(phase: str, altitude_m: float) -> float:
    """Pack power (kW) of a non-cruise phase (one of ``TABLE_PHASES``) at a cruise altitude (m)."""
    return _phase(phase, altitude_m, "power_kw")


def phase_duration_s(phase: str, altitude_m: float) -> float:
    """Duration (s) of a non-cruise phase (one of ``TABLE_PHASES``) at a cruise altitude (m)."""
    return _phase(phase, altitude_m, "duration_s")


@lru_cache(maxsize=16384)  # one entry per (altitude, wind) of a mission's legs
def _cruise(key: str, altitude_m: float, wind_kts: float) -> float:
    g = _grids()
    h = _check_alt(altitude_m)
    w = check_range("wind_kts", wind_kts, *WIND_RANGE_KTS, " kt")
    per_alt = np.array([np.interp(w, g["wind"], row) for row in g[key]])
    return float(np.interp(h, g["alt"], per_alt))


def cruise_table_many(altitudes_m, wind_kts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cruise pack power (kW) and effective ground speed (m/s) for a few altitudes (m) and an
    array of winds (kt), each shaped ``[len(altitudes_m), *wind_kts.shape]``:
    :func:`cruise_power_kw` and :func:`cruise_ground_speed_mps` elementwise, bit for bit (the same
    interpolations), for a planner's table of legs. Winds are not range-checked here."""
    g = _grids()
    hs = tuple(float(h) for h in np.atleast_1d(altitudes_m))
    rows = _table_rows(hs)
    w = np.asarray(wind_kts, dtype=float)
    out = []
    for key in ("power_kw", "speed_mps"):
        if all(r is not None for r in rows):  # table altitudes: np.interp there returns that row exactly
            out.append(np.stack([np.interp(w, g["wind"], g[key][r]) for r in rows]))
            continue
        per_alt = np.stack([np.interp(w, g["wind"], row) for row in g[key]])  # [n_table_alt, *w.shape]
        flat = per_alt.reshape(per_alt.shape[0], -1)
        out.append(np.stack([per_alt[r] if r is not None else
                             np.array([np.interp(h, g["alt"], col) for col in flat.T]).reshape(w.shape)
                             for h, r in zip(hs, rows)]))
    return out[0], out[1]


@lru_cache(maxsize=64)
def _table_rows(altitudes_m: tuple[float, ...]) -> tuple[int | None, ...]:
    """Row of each (checked) altitude (m) in the tables, None between rows."""
    g = _grids()
    rows = []
    for h in altitudes_m:
        at = np.flatnonzero(g["alt"] == _check_alt(h))
        rows.append(int(at[0]) if at.size else None)
    return tuple(rows)


def cruise_power_kw(altitude_m: float, wind_kts: float) -> float:
    """Cruise pack power (kW) at altitude (m) and wind (kt, negative = tailwind)."""
    return _cruise("power_kw", altitude_m, wind_kts)


def cruise_ground_speed_mps(altitude_m: float, wind_kts: float) -> float:
    """Effective cruise ground speed (m/s): 30 nm / tabulated cruise duration, interpolated."""
    return _cruise("speed_mps", altitude_m, wind_kts)


def cruise_airspeed_mps(altitude_m: float, wind_kts: float) -> float:
    """Tabulated cruise airspeed (m/s), interpolated; informational only (not used for timing)."""
    return _cruise("airspeed_mps", altitude_m, wind_kts)


def cruise_duration_s(distance_km: float, altitude_m: float, wind_kts: float) -> float:
    """Cruise time (s) to cover ``distance_km`` (km) at the effective ground speed."""
    return float(distance_km) * 1000.0 / cruise_ground_speed_mps(altitude_m, wind_kts)

"""Sweeps of the flight model over altitude, wind and leg length (the classroom notebooks use them).

Public API:

- :func:`altitude_profiles`, :func:`wind_profiles`: one :class:`~uam_studio.flight.LegProfile` per
  cruise altitude (or per wind) for the same leg, skipping altitudes the leg is too short for.
- :func:`charge_line`: a leg's per-cell charge is exactly linear in its length,
  ``charge(d) = fixed_c + per_km_c * d``; this returns the two coefficients.
- :func:`charge_table`: per-cell charge (C) over distances x altitudes.
- :func:`breakeven_distance_km`: the leg length beyond which a higher cruise altitude uses less
  charge than a lower one (``math.inf`` if never).

Why the charge is linear in distance: as in the paper, the non-cruise phases (take-off, climb,
descent, approach, landing) have fixed durations and powers per altitude, and the cruise covers the
whole leg at a constant power and ground speed (:mod:`uam_studio.flight.profile`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from ..errors import InputError, check_range
from . import tables
from .profile import LegProfile, leg_feasible, leg_profile
from .scaling import power_kw_to_cell_current_a

__all__ = ["altitude_profiles", "breakeven_distance_km", "charge_line", "charge_table", "wind_profiles"]

PAPER_ALTITUDES_M = (500.0, 1000.0, 2000.0, 3000.0)


def altitude_profiles(distance_km: float, altitudes_m: Iterable[float] = PAPER_ALTITUDES_M,
                      wind_kts: float = 0.0, dt_s: float = 1.0) -> dict[float, LegProfile]:
    """One leg flown at each cruise altitude (m); altitudes the leg is too short for are left out."""
    return {float(h): leg_profile(distance_km, h, wind_kts, dt_s) for h in altitudes_m
            if leg_feasible(distance_km, h)}


def wind_profiles(distance_km: float, altitude_m: float, winds_kts: Iterable[float],
                  dt_s: float = 1.0) -> dict[float, LegProfile]:
    """One leg flown in each wind (kt, + = headwind) at one cruise altitude (m)."""
    return {float(w): leg_profile(distance_km, altitude_m, w, dt_s) for w in winds_kts}


def charge_line(altitude_m: float, wind_kts: float = 0.0) -> tuple[float, float]:
    """``(fixed_c, per_km_c)``: a leg of ``d`` km at ``altitude_m`` in ``wind_kts`` draws
    ``fixed_c + per_km_c * d`` coulombs from one cell.

    ``fixed_c`` is the charge of take-off, climb, descent, approach and landing; ``per_km_c`` is the
    cruise current times the time per km at the effective ground speed.
    """
    h = check_range("altitude_m", altitude_m, *tables.ALTITUDE_RANGE_M, " m")
    w = check_range("wind_kts", wind_kts, *tables.WIND_RANGE_KTS, " kt")
    fixed = sum(float(power_kw_to_cell_current_a(tables.phase_power_kw(p, h))) * tables.phase_duration_s(p, h)
                for p in tables.TABLE_PHASES)
    per_km = float(power_kw_to_cell_current_a(tables.cruise_power_kw(h, w))) * 1000.0 \
        / tables.cruise_ground_speed_mps(h, w)
    return fixed, per_km


def charge_table(distances_km: Sequence[float], altitudes_m: Sequence[float] = PAPER_ALTITUDES_M,
                 wind_kts: float = 0.0) -> np.ndarray:
    """Per-cell charge (C) of a leg, shape [len(distances_km), len(altitudes_m)]; NaN where the leg is
    too short for the altitude."""
    out = np.full((len(distances_km), len(altitudes_m)), np.nan)
    for j, h in enumerate(altitudes_m):
        fixed, per_km = charge_line(h, wind_kts)
        for i, d in enumerate(distances_km):
            if leg_feasible(d, h):
                out[i, j] = fixed + per_km * float(d)
    return out


def breakeven_distance_km(low_m: float, high_m: float, wind_kts: float = 0.0) -> float:
    """Leg length (km) beyond which cruising at ``high_m`` uses less charge than at ``low_m``.

    ``math.inf`` if the higher altitude never uses less (its cruise costs at least as much per km);
    0.0 if it always uses less.
    """
    if not high_m > low_m:
        raise InputError("high_m", f"{high_m!r} must be above low_m={low_m!r}")
    f_lo, k_lo = charge_line(low_m, wind_kts)
    f_hi, k_hi = charge_line(high_m, wind_kts)
    if k_hi >= k_lo:
        return 0.0 if f_hi < f_lo else math.inf
    return max(0.0, (f_hi - f_lo) / (k_lo - k_hi))

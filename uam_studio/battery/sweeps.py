"""Sweeps of the battery model over health and over load profiles (the classroom notebooks use them).

Public API:

- :class:`Curve`: one discharge trajectory, cut at end of discharge (EOD).
- :func:`curves`: the trajectories of a batched :class:`~uam_studio.battery.SimulationResult`, each
  cut after its first sample below the cut-off (that sample kept, so a plot shows where it fails).
- :func:`simulate_profiles`: simulate load profiles of *different* lengths in one batched call.
- :func:`eod_grid`: EOD time over a grid of q_max x R0 for one load profile.
- :func:`max_leg_distance_km`: the longest single leg a fresh cell can fly (bisection on distance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uam_studio.battery.parameters import DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.battery.simulate import SimulationResult, simulate
from uam_studio.errors import InputError, check_range
from uam_studio.flight import leg_feasible, leg_profile, min_leg_distance_km
from uam_studio.flight.profile import MAX_DISTANCE_KM

__all__ = ["Curve", "curves", "eod_grid", "max_leg_distance_km", "simulate_profiles"]


@dataclass(frozen=True, eq=False)
class Curve:
    """One discharge trajectory, up to and including the first sample below the cut-off.

    :param time_s: end time of each step (s)
    :param voltage_v: terminal voltage (V)
    :param current_a: per-cell current (A)
    :param eod_s: time of the first sample below the cut-off (s), None if the profile ends first
    :param q_max: the cell's q_max (C)
    :param r0: the cell's R0 (ohm)
    """

    time_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    eod_s: float | None
    q_max: float
    r0: float


def curves(result: SimulationResult, q_max=DEFAULT_Q_MAX, r0=DEFAULT_R0,
           lengths: Sequence[int] | None = None) -> list[Curve]:
    """Split a (batched) simulation result into :class:`Curve` objects cut at EOD.

    :param result: from :func:`~uam_studio.battery.simulate` ([T] or [B, T])
    :param q_max: the q_max (C) of the run, scalar or [B] (recorded in each curve)
    :param r0: the R0 (ohm) of the run, scalar or [B]
    :param lengths: samples of each profile (for zero-padded ragged batches); default: all of them
    """
    v = np.atleast_2d(result.voltage_v)
    valid = np.atleast_2d(result.valid)
    cur = np.atleast_2d(result.current_a)
    b, t = v.shape
    q = np.broadcast_to(np.asarray(q_max, dtype=float), (b,))
    r = np.broadcast_to(np.asarray(r0, dtype=float), (b,))
    n = np.full(b, t) if lengths is None else np.asarray(lengths, dtype=int)
    out = []
    for k in range(b):
        stop = int(n[k])
        bad = ~valid[k, :stop]
        eod = bool(bad.any())
        if eod:
            stop = int(np.argmax(bad)) + 1
        out.append(Curve(np.array(result.time_s[:stop]), v[k, :stop].copy(), cur[k, :stop].copy(),
                         float(result.time_s[stop - 1]) if eod else None, float(q[k]), float(r[k])))
    return out


def simulate_profiles(currents: Sequence[np.ndarray], dt_s: float = 1.0, q_max=DEFAULT_Q_MAX,
                      r0=DEFAULT_R0, eod_v: float = DEFAULT_EOD_V) -> list[Curve]:
    """Simulate per-cell current profiles of different lengths (A) in one batched call.

    Profiles are zero-padded to the longest one; each :class:`Curve` is cut to its own profile
    (and at EOD). ``q_max`` (C) and ``r0`` (ohm) are scalars or one value per profile.
    """
    profiles = [np.asarray(c, dtype=float).reshape(-1) for c in currents]
    if not profiles or any(p.size == 0 for p in profiles):
        raise InputError("currents", "expected at least one non-empty current profile")
    t = max(p.size for p in profiles)
    batch = np.zeros((len(profiles), t))
    for k, p in enumerate(profiles):
        batch[k, :p.size] = p
    res = simulate(batch, dt_s=dt_s, q_max=q_max, r0=r0, eod_v=eod_v)
    return curves(res, q_max, r0, lengths=[p.size for p in profiles])


def eod_grid(current_a, q_values: Sequence[float], r0_values: Sequence[float], dt_s: float = 1.0,
             eod_v: float = DEFAULT_EOD_V) -> np.ndarray:
    """EOD time (s) of one load profile for every cell of a q_max x R0 grid.

    :param current_a: per-cell current (A), shape [T]
    :param q_values: q_max values (C), length Q
    :param r0_values: R0 values (ohm), length R
    :return: array [R, Q]; NaN where the profile ends before EOD
    """
    cur = np.asarray(current_a, dtype=float)
    if cur.ndim != 1:
        raise InputError("current_a", f"expected one profile of shape [T], got {cur.shape}")
    q, r = np.meshgrid(np.asarray(q_values, dtype=float), np.asarray(r0_values, dtype=float))
    res = simulate(cur, dt_s=dt_s, q_max=q.ravel(), r0=r.ravel(), eod_v=eod_v)
    return np.asarray(res.eod_s, dtype=float).reshape(q.shape)


def _leg_safe(distance_km: float, altitude_m: float, wind_kts: float, q_max: float, r0: float,
              eod_v: float) -> bool:
    prof = leg_profile(distance_km, altitude_m, wind_kts)
    return not bool(simulate(prof.current_a, 1.0, q_max, r0, eod_v).eod_reached)


def max_leg_distance_km(altitude_m: float, wind_kts: float = 0.0, q_max: float = DEFAULT_Q_MAX,
                        r0: float = DEFAULT_R0, eod_v: float = DEFAULT_EOD_V, tol_km: float = 0.5) -> float:
    """Longest single leg (km) a fresh cell flies at ``altitude_m`` in ``wind_kts`` without reaching EOD.

    Bisection on the distance between the shortest feasible leg and ``MAX_DISTANCE_KM``, to
    ``tol_km``. Returns 0.0 if even the shortest leg at that altitude reaches EOD.
    """
    tol = check_range("tol_km", tol_km, 1e-3, 50.0, " km")
    lo = math.ceil(min_leg_distance_km(altitude_m) * 1000.0) / 1000.0
    if not leg_feasible(lo, altitude_m) or not _leg_safe(lo, altitude_m, wind_kts, q_max, r0, eod_v):
        return 0.0
    hi = MAX_DISTANCE_KM
    if _leg_safe(hi, altitude_m, wind_kts, q_max, r0, eod_v):
        return hi
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if _leg_safe(mid, altitude_m, wind_kts, q_max, r0, eod_v):
            lo = mid
        else:
            hi = mid
    return lo

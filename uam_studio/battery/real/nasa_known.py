"""What an operator knows of a NASA discharge at the prediction instant (:class:`KnownDischarge`,
:func:`known_before`), the load it plans after it (:func:`planned_load`: the context's load continued), and
the charge that load delivers (:func:`charge_ah`, :func:`time_for_charge_s`). Times are s, currents A, charge
Ah, voltages V. Nothing here reads a discharge's record after its context."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uam_studio.battery.real.nasa_data import LOADED_A, NasaDischarge

__all__ = ["HORIZON_S", "KnownDischarge", "charge_ah", "charge_to_cutoff_ah", "known_before", "planned_load",
           "time_for_charge_s"]

HORIZON_S = 12000.0  # s: how far a planned load is continued (the NASA runs end before 7000 s)


@dataclass(frozen=True)
class KnownDischarge:
    """What an operator knows of a discharge at the prediction instant: its samples (time s from the
    discharge's start, current A with + = discharge, voltage V) up to ``context_s`` after the first loaded
    sample and nothing later, its ambient (C) and the rest before it (``rest_s``, s; NaN where unknown).
    The load it will go on drawing is :func:`planned_load`: the context's load continued."""

    cell: str
    index: int
    uid: int
    ambient_c: float
    time_s: np.ndarray
    current_a: np.ndarray
    load_start: int
    context_s: float
    voltage_v: np.ndarray
    rest_s: float = math.nan

    @property
    def load_time_s(self) -> float:
        """Time (s from the discharge's start) of the first loaded sample."""
        return float(self.time_s[self.load_start])

    def mean_load_a(self) -> float:
        """Mean current (A) over the context's samples under load."""
        on = self.current_a > LOADED_A
        return float(self.current_a[on].mean()) if on.any() else 0.0


def known_before(d: NasaDischarge, context_s: float) -> KnownDischarge:
    """The view of ``d`` an operator has ``context_s`` (s) after its first loaded sample: its samples
    (times, current, voltage) up to there, copied; nothing of the record after it."""
    end = int(np.searchsorted(d.time_s, d.load_time_s + context_s, side="right"))
    return KnownDischarge(d.cell, d.index, d.uid, d.ambient_c, d.time_s[:end].copy(), d.current_a[:end].copy(),
                          d.load_start, float(context_s), d.voltage_v[:end].copy(), float(d.rest_s))


def planned_load(known: KnownDischarge, start: int, horizon_s: float = HORIZON_S) -> tuple[np.ndarray, np.ndarray]:
    """The load ``known`` will draw as its operator plans it: sample times (s from the discharge's start)
    and currents (A) from sample ``start``: the context's samples, then its last two samples repeated at the
    context's median loaded step (a constant load goes on; the square wave, whose samples alternate on and
    off, keeps its phase) up to ``horizon_s`` s after sample ``start``. It reads nothing after the context,
    so it never knows when the record ends."""
    t, i = known.time_s, known.current_a
    last = t.size - 1
    loaded = t[known.load_start:]
    step = float(np.median(np.diff(loaded))) if loaded.size > 1 else 10.0
    m = np.arange(1, max(int((t[start] + horizon_s - t[last]) / step), 0) + 2)
    pattern = i[[max(last - 1, known.load_start), last]]
    return np.r_[t[start:], t[last] + m * step], np.r_[i[start:], pattern[(m + 1) % 2]]


def charge_ah(time_s: np.ndarray, current_a: np.ndarray, start: int) -> np.ndarray:
    """Cumulative charge (Ah) delivered from sample ``start`` at each later sample (trapezoids)."""
    t, i = time_s[start:], np.clip(current_a[start:], 0.0, None)
    return np.r_[0.0, np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))] / 3600.0


def charge_to_cutoff_ah(d: NasaDischarge, cutoff_v: float) -> float | None:
    """The charge (Ah) ``d`` delivered from its first loaded sample to its first sample below ``cutoff_v``
    (V); None if it never got there."""
    t = d.time_to_cutoff_s(cutoff_v)
    if t is None:
        return None
    return float(np.interp(t, d.time_s[d.load_start:] - d.load_time_s, charge_ah(d.time_s, d.current_a, d.load_start)))


def time_for_charge_s(known: KnownDischarge, target_ah: float) -> float:
    """Time (s from the first loaded sample) at which :func:`planned_load` has delivered ``target_ah``
    (Ah); past its horizon, its mean current carries on."""
    t, i = planned_load(known, known.load_start)
    q = charge_ah(t, i, 0)
    t = t - t[0]
    if target_ah <= q[-1]:
        return float(np.interp(target_ah, q, t))
    rate = max(q[-1] * 3600.0 / max(t[-1], 1.0), LOADED_A)
    return float(t[-1] + (target_ah - q[-1]) * 3600.0 / rate)

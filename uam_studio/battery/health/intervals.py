"""Intervals and bands of a fitted health (:class:`~uam_studio.battery.health.estimate.HealthEstimate`)
along a planned profile (current in A), physics model.

- :func:`eod_interval_s`: (low, median, high) end-of-discharge time (s) for one estimate;
  :func:`eod_intervals` for B estimates and profiles, batched.
- :func:`voltage_band`: (low, median, high) voltage (V) along the profile, a band to draw.
- The first-order reduction behind them: the EOD crossing times (s) of the 5 sigma points in (w, R0),
  the direction in which the EOD grows fastest per standard deviation, and the interval's two ends
  (q_max C, R0 ohm) on it (:func:`interval_points`, :func:`interval_ends`).
- :func:`with_preroll`: the profiles with each estimate's pre-roll in front, for models that take no
  initial state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from uam_studio.battery.eod import first_below
from uam_studio.battery.health.estimate import (
    CURVE_CUTOFF_V,
    FIT_Q_RANGE,
    HealthEstimate,
    checked_array,
    cholesky_factor,
    prepend_preroll,
    preroll_states,
    rep_state,
    w_to_qr,
)
from uam_studio.battery.parameters import DEFAULT_CELL, DEFAULT_EOD_V, CellParameters
from uam_studio.battery.simulate import CURRENT_LIMIT_A, DT_RANGE, EOD_RANGE, simulate
from uam_studio.battery.state import BatteryState
from uam_studio.errors import InputError, check_range

__all__ = ["EodInterval", "band_from_sigma_points", "crossing_times", "eod_interval_s", "eod_intervals",
           "interval_ends", "interval_points", "two_sided_z", "voltage_band", "with_preroll"]


def _check_profile(current_a, dt_s: float, level: float) -> tuple[np.ndarray, float, float]:
    dt = check_range("dt_s", dt_s, *DT_RANGE, " s")
    cur = checked_array("current_a", current_a, (1,))
    if np.any(np.abs(cur) > CURRENT_LIMIT_A):
        raise InputError("current_a", f"|current| must be <= {CURRENT_LIMIT_A:g} A")
    lv = check_range("level", level, 0.5, 0.999)
    return cur, dt, lv


@dataclass(frozen=True)
class EodInterval:
    """An end-of-discharge interval (s from the log's first sample): ``low_s``, ``median_s``, ``high_s``.

    A bound that the planned profile ends before reaching is *censored*: it is stated as the profile's
    length ``horizon_s`` (s) with its flag in ``censored`` (low, median, high) set, and means "at least
    ``horizon_s``" (never ``inf``, which would poison a mean or a median). Unpacks and indexes as
    (low, median, high); :meth:`describe` writes it with the censored ends marked.
    """

    low_s: float
    median_s: float
    high_s: float
    horizon_s: float
    censored: tuple[bool, bool, bool] = (False, False, False)

    @classmethod
    def from_times(cls, low: float, median: float, high: float, horizon_s: float) -> EodInterval:
        """From times (s) where inf means "not within the profile" (:func:`crossing_times`)."""
        lo, med, hi = (float(v) if math.isfinite(v) else float(horizon_s) for v in (low, median, high))
        beyond = (not math.isfinite(low), not math.isfinite(median), not math.isfinite(high))
        return cls(lo, med, hi, float(horizon_s), beyond)

    def __iter__(self):
        return iter((self.low_s, self.median_s, self.high_s))

    def __getitem__(self, k):
        return (self.low_s, self.median_s, self.high_s)[k]

    def __len__(self) -> int:
        return 3

    @property
    def any_censored(self) -> bool:
        """Whether an end lies beyond the profile (the cut-off is not reached there)."""
        return any(self.censored)

    def describe(self) -> str:
        """E.g. ``"1200 s to 1500 s (median 1350 s)"``; a censored end reads ``">= 3600 s"``."""
        low, med, high = (f">= {v:.0f} s" if c else f"{v:.0f} s" for v, c in zip(self, self.censored))
        return f"{low} to {high} (median {med})"


def with_preroll(estimates: list[HealthEstimate], current: np.ndarray, dt: float) -> tuple[np.ndarray, int]:
    """Profiles [B, T] (A) with each estimate's pre-roll, rounded to whole samples, before them
    (``preroll_current_a``, after leading zeros: no-ops for a rested full cell), as [B, K + T]; and
    K, the samples to drop from the front of any result (times shift by K dt). For models that take
    no initial state (the Dynaformer decoder); the physics functions start from
    :meth:`HealthEstimate.initial_states` instead."""
    steps = np.array([int(round(e.preroll_s / dt)) for e in estimates])
    if not steps.any():
        return current, 0
    i0 = np.array([e.preroll_current_a for e in estimates])
    c, _, _ = prepend_preroll(np.asarray(current, float), np.zeros_like(current, dtype=float), steps, i0)
    return c, int(steps.max())


def _start_states(estimates: list[HealthEstimate], points: np.ndarray, per: int, dt: float,
                  cell: CellParameters, initial_state: BatteryState | None) -> BatteryState | None:
    """Initial states of trajectories whose rows come in groups of ``per`` per estimate, at ``points``
    [B * per, 2] (q_max C, r0 ohm): ``initial_state`` if given (one for all, or one per estimate),
    else each estimate's pre-roll (None: all full and rested)."""
    b = len(estimates)
    if initial_state is not None:
        return rep_state(initial_state, per) if initial_state.batch_size == b and b > 1 else initial_state
    if not any(e.preroll_s > 0.0 for e in estimates):
        return None
    i0 = np.repeat([e.preroll_current_a for e in estimates], per)
    p = np.repeat([e.preroll_s for e in estimates], per)
    return preroll_states(i0, p, points[:, 0], points[:, 1], dt, cell)


def two_sided_z(level: float) -> float:
    """Two-sided standard-normal quantile: P(|Z| <= z) = level."""
    return NormalDist().inv_cdf(0.5 + level / 2.0)


def crossing_times(voltage: np.ndarray, dt: float, eod_v: float) -> tuple[np.ndarray, np.ndarray]:
    """Per row of voltage [N, T] (sample k at (k+1) dt): (grid time of the first sample below
    ``eod_v``, linearly interpolated crossing time), both s, inf where the row stays above."""
    k = first_below(voltage, eod_v)
    hit = k >= 0
    k = np.maximum(k, 0)
    grid = np.where(hit, (k + 1) * dt, np.inf)
    prev = voltage[np.arange(voltage.shape[0]), np.maximum(k - 1, 0)]
    now = voltage[np.arange(voltage.shape[0]), k]
    frac = np.where((k > 0) & (prev > now), (prev - eod_v) / np.maximum(prev - now, 1e-12), 1.0)
    cont = np.where(hit, (k + np.clip(frac, 0.0, 1.0)) * dt, np.inf)
    return grid, cont


def interval_points(estimate: HealthEstimate, eod_cont: np.ndarray, level: float) -> np.ndarray | None:
    """(q_max, r0) [2, 2] of the low and high ends of the EOD interval from the EOD crossing times (s)
    of the 5 sigma points (:meth:`HealthEstimate.sigma_points`): the points -+z std along the
    direction in which the linearised EOD grows fastest per standard deviation (a first-order
    reliability reduction to 1-D; exact for an EOD monotone along that line with straight level
    sets). None when a sigma point's crossing time is not finite."""
    if not np.all(np.isfinite(eod_cont)):
        return None
    g = np.array([(eod_cont[1] - eod_cont[2]) / 2.0, (eod_cont[3] - eod_cont[4]) / 2.0])  # s per std
    norm = float(np.hypot(*g))
    chol = cholesky_factor(estimate.cov_w)
    centre = np.array([estimate.w, estimate.r0])
    d = chol @ (g / norm) if norm > 0 else np.zeros(2)
    z = two_sided_z(level)
    return w_to_qr(np.array([centre - z * d, centre + z * d]))


def interval_ends(estimates: list[HealthEstimate], current: np.ndarray, dt: float, level: float, eod_v: float,
                  initial_state: BatteryState | None = None, cell: CellParameters = DEFAULT_CELL) -> np.ndarray:
    """(q_max C, r0 ohm) [B, 2, 2] of the low and high ends of each row's first-order EOD interval
    (:func:`interval_points`), from one physics call over the 5 sigma points of all B rows of
    ``current`` [B, T] (A). A sigma point whose trajectory stays above the cut-off is continued at
    the profile's mean current (at least 1 A) until it crosses, so that the direction is defined for
    profiles that end before the cut-off too. Rows without a defined direction get the estimate.
    Trajectories start after each estimate's pre-roll (or from ``initial_state``)."""
    b, t = current.shape
    pts = np.stack([e.sigma_points() for e in estimates]).reshape(b * 5, 2)
    rows = np.repeat(current, 5, axis=0)
    res = simulate(rows, dt, pts[:, 0], pts[:, 1], eod_v=eod_v,
                   initial_state=_start_states(estimates, pts, 5, dt, cell, initial_state), cell=cell)
    _, cont = crossing_times(res.voltage_v, dt, eod_v)
    missing = np.where(~np.isfinite(cont))[0]
    if missing.size:
        i_ext = np.maximum(np.abs(rows[missing]).mean(axis=1), 1.0)
        n_ext = int(math.ceil(FIT_Q_RANGE[1] / 1.0 / dt))  # enough to empty the largest cell at 1 A
        ext = simulate(np.repeat(i_ext[:, None], n_ext, axis=1), dt, pts[missing, 0], pts[missing, 1], eod_v=eod_v,
                       initial_state=res.final_state[missing], cell=cell)
        _, c2 = crossing_times(ext.voltage_v, dt, eod_v)
        cont[missing] = t * dt + c2
    cont = cont.reshape(b, 5)
    out = np.empty((b, 2, 2))
    for r, e in enumerate(estimates):
        ends = interval_points(e, cont[r], level)
        out[r] = ends if ends is not None else np.array([[e.q_max, e.r0]] * 2)
    return out


def eod_intervals(estimates: list[HealthEstimate], current_a, dt_s: float = 1.0, level: float = 0.9,
                  eod_v: float = DEFAULT_EOD_V, initial_state: BatteryState | None = None,
                  cell: CellParameters = DEFAULT_CELL) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`eod_interval_s` (first-order) for B estimates and profiles [B, T] (or one [T] for all),
    two batched physics calls in all. Returns three arrays [B] (s; ``inf`` where the profile ends
    before the cut-off)."""
    dt = check_range("dt_s", dt_s, *DT_RANGE, " s")
    lv = check_range("level", level, 0.5, 0.999)
    eod = check_range("eod_v", eod_v, *EOD_RANGE, " V")
    cur = checked_array("current_a", current_a, (1, 2))
    if np.any(np.abs(cur) > CURRENT_LIMIT_A):
        raise InputError("current_a", f"|current| must be <= {CURRENT_LIMIT_A:g} A")
    ests = list(estimates)
    if not ests or not all(isinstance(e, HealthEstimate) for e in ests):
        raise InputError("estimate", "expected HealthEstimates (from fit_health)")
    b = len(ests)
    cur = np.broadcast_to(np.atleast_2d(cur), (b, cur.shape[-1])) if cur.ndim == 1 or cur.shape[0] == 1 else cur
    if cur.shape[0] != b:
        raise InputError("current_a", f"{cur.shape[0]} profiles for {b} estimates")
    ends = interval_ends(ests, np.ascontiguousarray(cur), dt, lv, eod, initial_state, cell)
    pts = np.concatenate([np.array([[e.q_max, e.r0] for e in ests])[:, None], ends], axis=1).reshape(b * 3, 2)
    state = _start_states(ests, pts, 3, dt, cell, initial_state)
    v = simulate(np.repeat(cur, 3, axis=0), dt, pts[:, 0], pts[:, 1], eod_v=eod, initial_state=state,
                 cell=cell).voltage_v
    grid, _ = crossing_times(v, dt, eod)
    grid = grid.reshape(b, 3)
    med = grid[:, 0]
    return np.minimum(grid[:, 1:].min(axis=1), med), med, np.maximum(grid[:, 1:].max(axis=1), med)


def eod_interval_s(estimate: HealthEstimate, current_a, dt_s: float = 1.0, level: float = 0.9,
                   eod_v: float = DEFAULT_EOD_V, n_draws: int | None = None,
                   initial_state: BatteryState | None = None, seed: int = 0,
                   cell: CellParameters = DEFAULT_CELL) -> EodInterval:
    """``level`` interval of the end-of-discharge time (s) along a planned profile, physics model.

    :param estimate: a :class:`HealthEstimate` (from :func:`~uam_studio.battery.health.fit.fit_health`).
    :param current_a: the whole per-cell current (A) from the log's t = 0, context included, [T].
    :param dt_s: sample step (s).
    :param level: central probability of the interval, in [0.5, 0.999].
    :param eod_v: cut-off (V).
    :param n_draws: None: the first-order reduction (:func:`interval_ends`: 5 sigma-point
        trajectories, then the two ends and the estimate, 8 in all); an int in [10, 10000]: quantiles
        over that many random draws (:meth:`HealthEstimate.sample`).
    :param initial_state: the state at the log's first sample, as given to
        :func:`~uam_studio.battery.health.fit.fit_health`.
    :param seed: seed of the draws.
    :return: an :class:`EodInterval` (low, median, high): time (s) from the log's first sample to the
        first sample below ``eod_v``, on ``current_a``'s grid; ``median`` at the fitted health; an end
        the profile does not reach is censored at the profile's length.
    """
    cur, dt, lv = _check_profile(current_a, dt_s, level)
    eod = check_range("eod_v", eod_v, *EOD_RANGE, " V")
    if not isinstance(estimate, HealthEstimate):
        raise InputError("estimate", "expected a HealthEstimate (from fit_health)")
    if n_draws is not None and not (isinstance(n_draws, (int, np.integer)) and 10 <= n_draws <= 10000):
        raise InputError("n_draws", f"{n_draws!r} is out of range; allowed None or integers in [10, 10000]")
    med: np.ndarray | float  # eod_intervals' per-estimate times, or the draws' median (s)
    if n_draws is None:
        lo, med, hi = eod_intervals([estimate], cur, dt, lv, eod, initial_state, cell)
        return EodInterval.from_times(lo[0], med[0], hi[0], cur.size * dt)
    draws = np.vstack([[estimate.q_max, estimate.r0], estimate.sample(int(n_draws), np.random.default_rng(seed))])
    state = _start_states([estimate], draws, draws.shape[0], dt, cell, initial_state)
    v = simulate(np.broadcast_to(cur, (draws.shape[0], cur.size)), dt, draws[:, 0], draws[:, 1], eod_v=eod,
                 initial_state=state, cell=cell).voltage_v
    grid, _ = crossing_times(v, dt, eod)
    lo, hi = np.quantile(grid[1:], [(1 - lv) / 2, (1 + lv) / 2], method="inverted_cdf")
    med = float(grid[0])
    return EodInterval.from_times(min(float(lo), med), med, max(float(hi), med), cur.size * dt)


def band_from_sigma_points(v: np.ndarray, level: float, extra_std_v: float = 0.0):
    """Pointwise (low, median, high) voltage from the 5 sigma-point curves [5, T] (centre first):
    centre -+ z * std, std from the central differences along each Cholesky column, plus
    ``extra_std_v`` (V) in quadrature."""
    d0 = (v[1] - v[2]) / 2.0
    d1 = (v[3] - v[4]) / 2.0
    std = np.sqrt(d0 ** 2 + d1 ** 2 + extra_std_v ** 2)
    z = two_sided_z(level)
    return np.clip(v[0] - z * std, 0.0, 5.0), v[0].copy(), np.clip(v[0] + z * std, 0.0, 5.0)


def voltage_band(estimate: HealthEstimate, current_a, dt_s: float = 1.0, level: float = 0.9,
                 initial_state: BatteryState | None = None,
                 cell: CellParameters = DEFAULT_CELL) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pointwise ``level`` band of the voltage (V) along a planned profile, physics model.

    Linearised in (w, R0): median = the voltage at the fitted health, band = median -+ z std with the
    std of each sample from the 5 sigma-point curves (:meth:`HealthEstimate.sigma_points`). Curves are
    simulated down to 2.5 V and hold their last value below it.

    :param current_a: the whole per-cell current (A) from the log's t = 0, context included, [T].
    :return: (low_v, median_v, high_v), each shape [T], sample k at (k+1) dt_s.
    """
    cur, dt, lv = _check_profile(current_a, dt_s, level)
    if not isinstance(estimate, HealthEstimate):
        raise InputError("estimate", "expected a HealthEstimate (from fit_health)")
    pts = estimate.sigma_points()
    v = simulate(np.broadcast_to(cur, (5, cur.size)), dt, pts[:, 0], pts[:, 1], eod_v=CURVE_CUTOFF_V,
                 initial_state=_start_states([estimate], pts, 5, dt, cell, initial_state), cell=cell).voltage_v
    return band_from_sigma_points(v, lv)

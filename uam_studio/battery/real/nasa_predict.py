"""Online prediction of a real NASA cell's end of discharge, from what an operator has before the end.

The protocol (:func:`known_before`): to predict discharge k of a cell, the predictor reads the same cell's
discharges 0..k-1 whole, discharge k's first ``context_s`` (s, from its first loaded sample) of voltage,
and discharge k's whole current profile (the planned load). A :class:`KnownDischarge` holds exactly that:
its voltage array stops at the prediction instant, so nothing later can be read.

What it predicts: the time (s, from the first loaded sample) to the first sample below a cut-off (V), as
a median, a 90% interval and one-sided lower bounds at 5% and 1% risk (:class:`EodPrediction`).

How (:class:`CellBelief`, one per cell, carried along its life):

- **history**: the latest finished discharge of the same cell at the same load and ambient (``p``) ended
  at ``T_p``. Discharge k's context is compared with ``p``'s at the same time since the load and the same
  current: a mean voltage shift ``dv`` (V). A cell that rested long recovers capacity and shows it as a
  higher voltage; one that faded shows a lower one. The median is ``T_p (1 + a + b dv + bias)``, with
  ``a`` (fade per discharge) and ``b`` (1/V) fitted across training cells, and ``bias`` the cell's own
  running mean error (its belief of its own fade). The spread is the cell's own running scale of
  relative error, shrunk to a prior scale for its ambient band, times studentized quantiles fitted
  across training cells: those of its ambient band, or, for a cell's first :data:`EARLY_ERRORS`
  predictions, those of the training cells' first predictions (heavier tailed: a new cell changes most).
- **prior** (a first discharge, or a load or ambient the cell has not run before): the charge the cell
  will deliver to the cut-off (Ah) is its latest discharge's, scaled by the training cells' median charge
  at the new and the old condition, or the young training cells' median at a first discharge; the time
  is when the planned current has delivered that charge. Its interval is the training cells' log-ratio
  quantiles for such predictions: wide, as it should be.

A condition outside what the training cells cover (a load or ambient with no training discharge near
it) is flagged, and its interval widened by :data:`UNSEEN_WIDEN`. The fitted numbers live in one
:class:`NasaEodModel` (see :mod:`uam_studio.battery.real.nasa_model` for the bundled one and how to refit it).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from uam_studio.battery.real.nasa_data import LOADED_A, NasaDischarge, RunConditions, same_conditions

__all__ = ["EARLY_ERRORS", "OWN_ERROR_WINDOW", "RISKS", "UNSEEN_WIDEN", "CellBelief", "charge_to_cutoff_ah",
           "EodPrediction", "KnownDischarge", "NasaEodModel", "ambient_band", "known_before", "own_error_factor",
           "voltage_shift_v"]

RISKS = (0.01, 0.05, 0.5, 0.95)  # the quantiles every prediction carries: bound99, bound95/low, median, high
Z_LEVELS = (0.001, 0.0025, 0.005, 0.01, 0.02, 0.035, 0.05, 0.075, 0.1, 0.15, 0.25, 0.5, 0.75, 0.85, 0.9, 0.925,
            0.95, 0.965, 0.98, 0.99, 0.995)  # the levels at which a model holds its studentized error quantiles
ACI_GAIN = 0.01  # how fast a cell's own misses move its quantile levels
UNSEEN_WIDEN = 2.0  # an unseen condition's log-ratio quantiles are multiplied by this
BAND_EDGES_C = (12.0, 34.0)  # ambient (C) below the first is cold, above the second hot
N0_SCALE = 5.0  # weight (discharges) of the prior scale against the cell's own errors
N0_BIAS = 10.0  # weight (discharges) of zero bias against the cell's own mean error
SCALE_WINDOW = 20  # the cell's own scale reads its latest this many errors
EARLY_ERRORS = 5  # until a cell has this many errors of its own, its prior scale is at least the 'early' one
OWN_ERROR_WINDOW = 10  # discharges: a method's running bias on a cell is the median of this many last errors


def ambient_band(ambient_c: float) -> str:
    """'cold', 'room' or 'hot' for an ambient temperature (C)."""
    if ambient_c < BAND_EDGES_C[0]:
        return "cold"
    return "hot" if ambient_c > BAND_EDGES_C[1] else "room"


@dataclass(frozen=True)
class KnownDischarge:
    """What an operator knows of a discharge at the prediction instant: its planned current (A, + =
    discharge) at every sample time (s from the discharge's start), its ambient (C), and its voltage (V)
    only up to ``context_s`` after the first loaded sample (``voltage_v`` is that much shorter than
    ``time_s``)."""

    cell: str
    index: int
    uid: int
    ambient_c: float
    time_s: np.ndarray
    current_a: np.ndarray
    load_start: int
    context_s: float
    voltage_v: np.ndarray

    @property
    def load_time_s(self) -> float:
        """Time (s from the discharge's start) of the first loaded sample."""
        return float(self.time_s[self.load_start])

    def mean_load_a(self) -> float:
        """Mean planned current (A) over the samples under load."""
        on = self.current_a > LOADED_A
        return float(self.current_a[on].mean()) if on.any() else 0.0


def known_before(d: NasaDischarge, context_s: float) -> KnownDischarge:
    """The view of ``d`` an operator has ``context_s`` (s) after its first loaded sample: the voltage is
    cut there (a copy), the current and times are whole."""
    end = int(np.searchsorted(d.time_s, d.load_time_s + context_s, side="right"))
    return KnownDischarge(d.cell, d.index, d.uid, d.ambient_c, d.time_s.copy(), d.current_a.copy(), d.load_start,
                          float(context_s), d.voltage_v[:end].copy())


def own_error_factor(past: Iterable[tuple[RunConditions, float | None]], target: RunConditions,
                     window: int = OWN_ERROR_WINDOW) -> float:
    """One plus the median of a method's latest ``window`` relative errors (predicted / true time - 1, -) on
    the cell's finished discharges ``past`` (each with its error, None where it made no prediction) that
    ran at ``target``'s load and ambient; 1.0 where there is none. A method's predicted time divided by it
    loses the bias it has shown on this cell: the online protocol allows it, as those discharges are
    finished."""
    rel = [e for d, e in past if e is not None and same_conditions(d, target)][-window:]
    return 1.0 + float(np.median(rel)) if rel else 1.0


def voltage_shift_v(known: KnownDischarge, prev: NasaDischarge) -> float:
    """Mean voltage (V) of ``known``'s loaded context samples minus ``prev``'s at the same time since the
    load and about the same current (interpolated among ``prev``'s samples within 25% of that current)."""
    n = known.voltage_v.size
    tau = known.time_s[known.load_start:n] - known.load_time_s
    cur = known.current_a[known.load_start:n]
    v = known.voltage_v[known.load_start:n]
    ptau = prev.time_s[prev.load_start:] - prev.load_time_s
    pcur = prev.current_a[prev.load_start:]
    pv = prev.voltage_v[prev.load_start:]
    on = cur > LOADED_A
    tau, cur, v = tau[on], cur[on], v[on]
    diffs = []
    levels = np.round(cur / 0.05) * 0.05  # samples at about the same current share one mask
    for level in np.unique(levels):
        at = levels == level
        i = float(np.mean(cur[at]))
        near = np.abs(pcur - i) <= 0.25 * i + 0.05
        if near.sum() < 2:
            continue
        diffs.append(v[at] - np.interp(tau[at], ptau[near], pv[near]))
    return float(np.mean(np.concatenate(diffs))) if diffs else 0.0


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


def time_for_charge_s(time_s: np.ndarray, current_a: np.ndarray, start: int, target_ah: float) -> float:
    """Time (s from sample ``start``) at which the current delivers ``target_ah`` (Ah); past the profile's
    end, its last loaded current carries on."""
    q = charge_ah(time_s, current_a, start)
    t = time_s[start:] - time_s[start]
    if target_ah <= q[-1]:
        return float(np.interp(target_ah, q, t))
    on = current_a[start:] > LOADED_A
    last = float(current_a[start:][on][-1]) if on.any() else 1.0
    return float(t[-1] + (target_ah - q[-1]) * 3600.0 / max(last, LOADED_A))


@dataclass(frozen=True)
class NasaEodModel:
    """The numbers fitted across training cells, for one context (s) and cut-off (V).

    :param a: mean relative change of the time to cut-off from one discharge to the next at the same
        conditions (fade per discharge, -).
    :param b: relative change per volt of context shift (1/V).
    :param scale: prior scale of the log error of a history prediction, per ambient band, and 'early': that
        of a cell's first :data:`EARLY_ERRORS` history predictions (a new cell's first cycles change most).
    :param z: studentized quantiles of that error at :data:`Z_LEVELS`, per ambient band, 'all' (the
        quantiles of a band with few training errors) and 'early' (of the training cells' first
        :data:`EARLY_ERRORS` predictions each, where there are enough).
    :param charge: (load A, ambient C, median charge to the cut-off Ah over all discharges, over the first
        five of each cell) per training condition.
    :param prior_log: quantiles at :data:`RISKS` of log(true / predicted) of a prior prediction.
    :param trained_on: the training cells' names.
    """

    context_s: float
    cutoff_v: float
    a: float
    b: float
    scale: dict[str, float]
    z: dict[str, tuple[float, ...]]
    charge: tuple[tuple[float, float, float, float], ...]
    prior_log: tuple[float, ...]
    trained_on: tuple[str, ...] = ()

    def condition_charge_ah(self, load_a: float, ambient_c: float, young: bool) -> tuple[float, bool]:
        """The training median charge (Ah) to the cut-off at the nearest training condition, and whether
        that condition is near (within 0.5 A and 6 C)."""
        rows = np.array(self.charge)
        dist = np.abs(rows[:, 0] - load_a) / 0.5 + np.abs(rows[:, 1] - ambient_c) / 6.0
        k = int(np.argmin(dist))
        near = abs(rows[k, 0] - load_a) <= 0.5 and abs(rows[k, 1] - ambient_c) <= 6.0
        return float(rows[k, 3] if young else rows[k, 2]), near


@dataclass(frozen=True)
class EodPrediction:
    """A prediction of the time (s, from the first loaded sample) to the first sample below the cut-off:
    ``median_s``, a 90% interval (``low_s``, ``high_s``), lower bounds at 5% (``bound95_s``) and 1%
    (``bound99_s``) risk, how it was made (``method``: 'history' or 'prior') and ``flag`` (None, or why
    the model has no evidence for this discharge)."""

    median_s: float
    low_s: float
    high_s: float
    bound95_s: float
    bound99_s: float
    method: str
    flag: str | None


@dataclass
class CellBelief:
    """What one cell's operator believes of it, updated from each finished discharge: the discharges run
    (whole, once finished) and the cell's own record of its history-prediction errors (relative, -)."""

    model: NasaEodModel
    finished: list[NasaDischarge] = field(default_factory=list)
    errors: list[float] = field(default_factory=list)
    levels: list[float] = field(default_factory=lambda: list(RISKS))
    _centres: dict[tuple[int, int, float], float] = field(default_factory=dict, repr=False)

    def bias(self) -> float:
        """The median of the cell's latest log errors, shrunk to zero (its fade beyond the training mean)."""
        recent = self.errors[-SCALE_WINDOW:]
        return float(np.median(recent)) * len(recent) / (N0_BIAS + len(recent)) if recent else 0.0

    def scale(self, band: str) -> float:
        """The log-error scale: the band's prior scale and the robust scale (1.4826 MAD) of the cell's latest
        errors, pooled."""
        s0 = self.model.scale.get(band, max(self.model.scale.values()))
        if len(self.errors) < EARLY_ERRORS:
            s0 = max(s0, self.model.scale.get("early", s0))
        recent = np.array(self.errors[-SCALE_WINDOW:])
        own = 1.4826 * float(np.median(np.abs(recent - np.median(recent)))) if recent.size else 0.0
        return float(math.sqrt((N0_SCALE * s0 ** 2 + recent.size * own ** 2) / (N0_SCALE + recent.size)))

    def spread(self, known: KnownDischarge, p: NasaDischarge) -> float:
        """The log-error scale of a history prediction of ``known`` from ``p``: :meth:`scale`, grown with the
        square root of the discharges run since ``p``."""
        gap = sum(1 for q in self.finished if q.index > p.index) + 1
        return self.scale(ambient_band(known.ambient_c)) * math.sqrt(gap)

    def previous(self, known: KnownDischarge) -> NasaDischarge | None:
        """The latest finished discharge at ``known``'s load and ambient that reached the cut-off."""
        for p in reversed(self.finished):
            if same_conditions(p, known) and p.time_to_cutoff_s(self.model.cutoff_v) is not None:
                return p
        return None

    def centre_s(self, known: KnownDischarge, p: NasaDischarge) -> float:
        """The history prediction of ``known`` from ``p`` before the cell's own bias (s)."""
        key = (known.index, p.index, known.context_s)
        if key not in self._centres:
            t_p = p.time_to_cutoff_s(self.model.cutoff_v)
            assert t_p is not None  # previous() returns only discharges that reached the cut-off
            self._centres[key] = t_p * max(1.0 + self.model.a + self.model.b * voltage_shift_v(known, p), 0.05)
        return self._centres[key]

    def _history(self, known: KnownDischarge, p: NasaDischarge) -> np.ndarray:
        """The quantiles (s) at :data:`RISKS` of a history prediction from ``p``."""
        table = self.model.z.get(ambient_band(known.ambient_c), self.model.z["all"])
        if len(self.errors) < EARLY_ERRORS:  # a cell's first predictions: the training cells' first errors' tails
            table = self.model.z.get("early", table)
        z = np.interp(self.levels, Z_LEVELS, table)
        return self.centre_s(known, p) * np.exp(self.bias() + self.spread(known, p) * np.array(z))

    def _prior(self, known: KnownDischarge) -> tuple[np.ndarray, str | None]:
        cut = self.model.cutoff_v
        load = known.mean_load_a()
        last = next((p for p in reversed(self.finished) if p.time_to_cutoff_s(cut) is not None), None)
        target, near = self.model.condition_charge_ah(load, known.ambient_c, young=last is None)
        if last is None:
            charge = target
        else:
            reached = charge_to_cutoff_ah(last, cut)
            assert reached is not None  # ``last`` reached the cut-off
            delivered = float(reached)
            then, near_then = self.model.condition_charge_ah(last.mean_load_a(), last.ambient_c, young=False)
            charge = delivered * target / then
            near = near and near_then
        centre = time_for_charge_s(known.time_s, known.current_a, known.load_start, charge)
        logs = np.array(self.model.prior_log)
        flag = None
        if not near:
            logs = logs * UNSEEN_WIDEN
            flag = (f"no training discharge near {load:.1f} A at {known.ambient_c:.0f} C: interval widened "
                    f"{UNSEEN_WIDEN:g}x")
        return centre * np.exp(logs), flag

    def predict(self, known: KnownDischarge) -> EodPrediction:
        """Predict ``known``'s time to the model's cut-off from what the belief holds and ``known``."""
        p = self.previous(known)
        band = ambient_band(known.ambient_c)
        flag = None if band == "room" else (
            f"{band} ({known.ambient_c:.0f} C, outside {BAND_EDGES_C[0]:g}-{BAND_EDGES_C[1]:g} C): the interval "
            f"carries the {band} training cells' larger errors")
        if p is not None:
            q = self._history(known, p)
            method = "history"
        else:
            q, unseen = self._prior(known)
            flag = unseen or flag
            method = "prior"
        # the cut-off was not reached within the context: the true time is at least the context's end
        n = known.voltage_v.size
        seen = float(known.time_s[n - 1] - known.load_time_s) if n > known.load_start else 0.0
        q = np.maximum(np.sort(q), seen)
        return EodPrediction(float(q[2]), float(q[1]), float(q[3]), float(q[1]), float(q[0]), method, flag)

    def walk(self, discharges: Iterable[NasaDischarge]) -> Iterator[tuple[int, NasaDischarge, KnownDischarge,
                                                                           EodPrediction, float]]:
        """Run ``discharges`` (a cell's, in order) through the belief. Each that ends after the context is
        predicted and yielded as (position, discharge, known view, prediction, true time s) *before* the
        belief takes it in, so the caller reads the belief as the prediction saw it; every discharge is
        then observed (with its prediction, where one was made)."""
        for k, d in enumerate(discharges):
            t = d.time_to_cutoff_s(self.model.cutoff_v)
            if t is None or t <= self.model.context_s:
                self.observe(d)
                continue
            known = known_before(d, self.model.context_s)
            prediction = self.predict(known)
            yield k, d, known, prediction, t
            self.observe(d, prediction, known)

    def observe(self, d: NasaDischarge, prediction: EodPrediction | None = None,
                known: KnownDischarge | None = None) -> None:
        """Take a finished discharge in; with the history prediction made for it, record its error."""
        t = d.time_to_cutoff_s(self.model.cutoff_v)
        if known is not None and prediction is not None and prediction.method == "history" and t is not None:
            p = self.previous(known)
            if p is not None:
                self.errors.append(math.log(t / self.centre_s(known, p)))
            # adaptive conformal levels: each quantile's level moves towards the miss rate it declares
            for k, (risk, q) in enumerate(zip(RISKS, (prediction.bound99_s, prediction.bound95_s, None,
                                                        prediction.high_s))):
                if q is not None:
                    level = self.levels[k] + ACI_GAIN * (risk - float(t < q))
                    self.levels[k] = float(np.clip(level, Z_LEVELS[0], Z_LEVELS[-1]))
        self.finished.append(d)

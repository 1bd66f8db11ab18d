"""Online prediction of a real NASA cell's end of discharge, from what an operator has before the end.

The protocol (:func:`known_before`): to predict discharge k of a cell, the predictor reads the same cell's
discharges 0..k-1 whole, the rest before discharge k (from the run's start time) and discharge k's
samples (time, current, voltage) up to ``context_s`` (s) after its first loaded sample. A
:class:`KnownDischarge` holds exactly that; the load after the context is :func:`planned_load`, the
context's load continued (the record's own end, where the rig stopped the load, is never read).

What it predicts: the time (s, from the first loaded sample) to the first sample below a cut-off (V), as
a median, a 90% interval and one-sided lower bounds at 5% and 1% risk (:class:`EodPrediction`). Every
interval is finite, at least :func:`min_width_s` wide, and its high end at most
:func:`high_cap_s` (:data:`CAP_RATIO` times the median, the time to deliver :data:`CAP_AH`, :data:`HORIZON_S`).

How (:class:`CellBelief`, one per cell, carried along its life):

- **history**: a finished discharge of the same cell at the same load and ambient (``p``, ended at
  ``T_p``; :meth:`CellBelief.previous`: the latest of the last :data:`LOOKBACK` whose context is within
  :data:`DV_PLAUSIBLE_V` of this one's, so that one outlying discharge is not the reference). Discharge
  k's context is compared with ``p``'s at the same time since the load and the same current: a mean
  voltage shift ``dv`` (V). A cell that rested long recovers capacity and shows it as a higher voltage;
  one that faded shows a lower one. The median is ``T_p exp(a + b dv + c dr + bias)``, with ``(a, b, c)``
  fitted across training cells per ambient band (``dr``: the change of :func:`rest_feature` from ``p``'s
  rest to this one's; shrunk towards persistence where a band's data are thin) and ``bias`` the cell's
  own running median error (its belief of its own fade; errors enter clipped at :data:`CLIP_SPREADS` spreads).
  The spread is the cell's own running scale of log error, shrunk to a prior scale for its ambient
  band, times studentized quantiles fitted across training cells: those of its ambient band, or, for a
  cell's first :data:`EARLY_ERRORS` predictions, those of the training cells' first predictions (heavier
  tailed: a new cell changes most).
- **prior** (a first discharge, or a load or ambient the cell has not run before): the charge (Ah) the
  training cells delivered to the cut-off at the nearest condition, moved along that condition's fitted
  dependence on the context voltage (:func:`context_voltage_v`: what the cell's first seconds show of its
  health); the time is when the planned load has delivered that charge. Its interval is the training
  cells' log-ratio quantiles for such predictions: wide, as it should be.

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
from uam_studio.battery.real.nasa_known import (
    HORIZON_S,
    KnownDischarge,
    charge_to_cutoff_ah,
    known_before,
    planned_load,
    time_for_charge_s,
)

__all__ = ["CAP_AH", "CAP_RATIO", "EARLY_ERRORS", "HORIZON_S", "OWN_ERROR_WINDOW", "RISKS", "UNSEEN_WIDEN",
           "CellBelief", "EodPrediction", "KnownDischarge", "NasaEodModel", "ambient_band", "as_prediction",
           "charge_to_cutoff_ah",
           "context_voltage_v", "high_cap_s", "history_log_change", "known_before", "min_width_s", "own_error_factor",
           "planned_load", "rest_feature", "seen_s", "time_for_charge_s", "voltage_shift_v"]

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
CAP_AH = 2.2  # Ah: no interval reaches past the time the planned load delivers this (the cells are rated 2 Ah;
# the most any of the 26 lives delivers to 3.0 V is 1.86 Ah)
CAP_RATIO = 3.0  # and none reaches past this many times its own median
MIN_WIDTH = 0.01  # an interval is at least this share of the context's length wide (and 1 s)
DV_PLAUSIBLE_V = 0.05  # V: a previous discharge whose context differs by more is not a reference while a
# nearer one is (about the 95th percentile of |shift| between consecutive discharges at one condition)
LOOKBACK = 4  # the latest this many finished discharges at a condition are a prediction's candidate references
CLIP_SPREADS = 4.0  # a history error enters the cell's bias and scale clipped at this many of its spreads
N0_SLOPE = 30.0  # weight (pairs) of persistence (no change) against a band's fitted slopes


def ambient_band(ambient_c: float) -> str:
    """'cold', 'room' or 'hot' for an ambient temperature (C)."""
    if ambient_c < BAND_EDGES_C[0]:
        return "cold"
    return "hot" if ambient_c > BAND_EDGES_C[1] else "room"


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


def rest_feature(rest_s: float) -> float:
    """log(1 + rest in hours), the rest's term in a history prediction; 0 where the rest is unknown (NaN)."""
    return math.log1p(max(rest_s, 0.0) / 3600.0) if math.isfinite(rest_s) else 0.0


def context_voltage_v(known: KnownDischarge) -> float:
    """Mean voltage (V) of ``known``'s loaded context samples: a fresh cell holds a higher one."""
    on = known.current_a[known.load_start:] > LOADED_A
    v = known.voltage_v[known.load_start:][on]
    return float(v.mean()) if v.size else float("nan")


def seen_s(known: KnownDischarge) -> float:
    """How long (s) ``known`` has run under load without reaching the cut-off: its context's end."""
    return float(known.time_s[-1] - known.load_time_s)


def min_width_s(known: KnownDischarge) -> float:
    """The narrowest 90% interval (s): :data:`MIN_WIDTH` of the context's length, and 1 s."""
    return max(MIN_WIDTH * seen_s(known), 1.0)


def high_cap_s(known: KnownDischarge, median_s: float, cap_charge_s: float | None = None) -> float:
    """The most an interval's high end may be (s from the first loaded sample): the least of
    :data:`CAP_RATIO` times its median, the time :func:`planned_load` takes to deliver :data:`CAP_AH`
    (``cap_charge_s`` where the caller has it already), and :data:`HORIZON_S`; never less than the context's
    end plus :func:`min_width_s`."""
    if cap_charge_s is None:
        cap_charge_s = time_for_charge_s(known, CAP_AH)
    return max(min(CAP_RATIO * median_s, cap_charge_s, HORIZON_S), seen_s(known) + min_width_s(known))


def history_log_change(coefficients: tuple[float, float, float], shift_v: float, rest_change: float) -> float:
    """A history prediction's log change of the time to the cut-off from its reference's: ``a + b dv + c dr``
    of ``coefficients`` (a, b, c), the context shift ``shift_v`` (V) and the :func:`rest_feature` change
    ``rest_change``, clipped to +-1."""
    a, b, c = coefficients
    return float(np.clip(a + b * shift_v + c * rest_change, -1.0, 1.0))


@dataclass(frozen=True)
class NasaEodModel:
    """The numbers fitted across training cells, for one context (s) and cut-off (V).

    :param a: mean log change of the time to cut-off from one discharge to the next at the same
        conditions (fade per discharge, -), pooled over ambient bands.
    :param b: log change per volt of context shift (1/V), pooled.
    :param scale: prior scale of the log error of a history prediction, per ambient band, and 'early': that
        of a cell's first :data:`EARLY_ERRORS` history predictions (a new cell's first cycles change most).
    :param z: studentized quantiles of that error at :data:`Z_LEVELS`, per ambient band, 'all' (the
        quantiles of a band with few training errors) and 'early' (of the training cells' first
        :data:`EARLY_ERRORS` predictions each, where there are enough).
    :param charge: per training condition: (load A, ambient C, median charge to the cut-off Ah over all
        discharges, over the first five of each cell, median context voltage V, d log(charge) / d context
        voltage 1/V).
    :param prior_log: quantiles at :data:`RISKS` of log(true / predicted) of a prior prediction.
    :param trained_on: the training cells' names.
    :param slope: per ambient band, (a, b, c): a history prediction's log change is ``a + b dv + c dr``,
        with ``dv`` the context shift (V) and ``dr`` the change of :func:`rest_feature` from the
        reference's rest to this one's; each fitted in the band and shrunk towards persistence (0) by
        :data:`N0_SLOPE`. A band not here takes (``a``, ``b``, 0).
    """

    context_s: float
    cutoff_v: float
    a: float
    b: float
    scale: dict[str, float]
    z: dict[str, tuple[float, ...]]
    charge: tuple[tuple[float, ...], ...]
    prior_log: tuple[float, ...]
    trained_on: tuple[str, ...] = ()
    slope: dict[str, tuple[float, float, float]] = field(default_factory=dict)

    def coefficients(self, band: str) -> tuple[float, float, float]:
        """(a, b, c) of a history prediction in ambient ``band``."""
        return self.slope.get(band, (self.a, self.b, 0.0))

    def condition_charge_ah(self, load_a: float, ambient_c: float, context_v: float) -> tuple[float, bool]:
        """The training charge (Ah) to the cut-off at the nearest training condition, and whether that
        condition is near (within 0.5 A and 6 C): the condition's median moved along its fitted dependence
        on the context voltage ``context_v`` (V, :func:`context_voltage_v`); where that is not a number, or
        the model holds no such dependence, the median over the first five discharges of each cell."""
        rows = np.array([r[:4] for r in self.charge])
        dist = np.abs(rows[:, 0] - load_a) / 0.5 + np.abs(rows[:, 1] - ambient_c) / 6.0
        k = int(np.argmin(dist))
        near = abs(rows[k, 0] - load_a) <= 0.5 and abs(rows[k, 1] - ambient_c) <= 6.0
        row = self.charge[k]
        if math.isfinite(context_v) and len(row) >= 6:
            shift = float(np.clip(row[5] * (context_v - row[4]), -1.0, 1.0))
            return float(row[2] * math.exp(shift)), near
        return float(rows[k, 3]), near


@dataclass(frozen=True)
class EodPrediction:
    """A prediction of the time (s, from the first loaded sample) to the first sample below the cut-off:
    ``median_s``, a 90% interval (``low_s``, ``high_s``; finite, ``low_s < high_s`` and ``high_s`` at
    most :func:`high_cap_s`), lower bounds at 5% (``bound95_s``) and 1% (``bound99_s``) risk, how it was
    made (``method``: 'history' or 'prior') and ``flag`` (None, or why the model has no evidence for this
    discharge)."""

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
    (whole, once finished) and the cell's own record of its history-prediction errors (log, -, each
    clipped at :data:`CLIP_SPREADS` of the spread it was predicted with)."""

    model: NasaEodModel
    finished: list[NasaDischarge] = field(default_factory=list)
    errors: list[float] = field(default_factory=list)
    levels: list[float] = field(default_factory=lambda: list(RISKS))
    _centres: dict[tuple[int, int, float], float] = field(default_factory=dict, repr=False)
    _shifts: dict[tuple[int, int, float], float] = field(default_factory=dict, repr=False)

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

    def shift_v(self, known: KnownDischarge, p: NasaDischarge) -> float:
        """:func:`voltage_shift_v` of ``known`` from ``p`` (V), computed once."""
        key = (known.index, p.index, known.context_s)
        if key not in self._shifts:
            self._shifts[key] = voltage_shift_v(known, p)
        return self._shifts[key]

    def previous(self, known: KnownDischarge) -> NasaDischarge | None:
        """The reference of a history prediction: among the latest :data:`LOOKBACK` finished discharges at
        ``known``'s load and ambient that reached the cut-off after the context (``known`` has not), the
        latest whose context differs from ``known``'s by at most :data:`DV_PLAUSIBLE_V`, else the one that
        differs least; None if there is none."""
        cut = self.model.cutoff_v
        same: list[NasaDischarge] = []
        for p in reversed(self.finished):
            if len(same) == LOOKBACK:
                break
            t_p = p.time_to_cutoff_s(cut)
            if same_conditions(p, known) and t_p is not None and t_p > known.context_s:
                same.append(p)
        if not same:
            return None
        shifts = [abs(self.shift_v(known, p)) for p in same]
        plausible = [p for p, dv in zip(same, shifts) if dv <= DV_PLAUSIBLE_V]
        return plausible[0] if plausible else same[int(np.argmin(shifts))]

    def centre_s(self, known: KnownDischarge, p: NasaDischarge) -> float:
        """The history prediction of ``known`` from ``p`` before the cell's own bias (s)."""
        key = (known.index, p.index, known.context_s)
        if key not in self._centres:
            t_p = p.time_to_cutoff_s(self.model.cutoff_v)
            assert t_p is not None  # previous() returns only discharges that reached the cut-off
            dr = rest_feature(known.rest_s) - rest_feature(p.rest_s)
            change = history_log_change(self.model.coefficients(ambient_band(known.ambient_c)),
                                        self.shift_v(known, p), dr)
            self._centres[key] = t_p * math.exp(change)
        return self._centres[key]

    def _history(self, known: KnownDischarge, p: NasaDischarge) -> np.ndarray:
        """The quantiles (s) at :data:`RISKS` of a history prediction from ``p``."""
        table = self.model.z.get(ambient_band(known.ambient_c), self.model.z["all"])
        if len(self.errors) < EARLY_ERRORS:  # a cell's first predictions: the training cells' first errors' tails
            table = self.model.z.get("early", table)
        z = np.interp(self.levels, Z_LEVELS, table)
        return self.centre_s(known, p) * np.exp(self.bias() + self.spread(known, p) * np.array(z))

    def _prior(self, known: KnownDischarge) -> tuple[np.ndarray, str | None]:
        """A prediction with no reference: the charge the training cells delivered at the nearest condition,
        moved along that condition's dependence on the context voltage to what ``known``'s first seconds
        show, delivered by the planned load."""
        load = known.mean_load_a()
        charge, near = self.model.condition_charge_ah(load, known.ambient_c, context_voltage_v(known))
        centre = time_for_charge_s(known, charge)
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
        return as_prediction(known, q, method, flag)

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
        """Take a finished discharge in; with the history prediction made for it, record its error
        (clipped at :data:`CLIP_SPREADS` spreads, so that one outlying discharge does not set the cell's bias)."""
        t = d.time_to_cutoff_s(self.model.cutoff_v)
        if known is not None and prediction is not None and prediction.method == "history" and t is not None:
            p = self.previous(known)
            if p is not None:
                limit = CLIP_SPREADS * self.spread(known, p)
                self.errors.append(float(np.clip(math.log(t / self.centre_s(known, p)), -limit, limit)))
            # adaptive conformal levels: each quantile's level moves towards the miss rate it declares
            for k, (risk, q) in enumerate(zip(RISKS, (prediction.bound99_s, prediction.bound95_s, None,
                                                        prediction.high_s))):
                if q is not None:
                    level = self.levels[k] + ACI_GAIN * (risk - float(t < q))
                    self.levels[k] = float(np.clip(level, Z_LEVELS[0], Z_LEVELS[-1]))
        self.finished.append(d)


def as_prediction(known: KnownDischarge, q: np.ndarray, method: str, flag: str | None = None) -> EodPrediction:
    """The quantiles ``q`` (s, at :data:`RISKS`) as a prediction that is an interval: none before the
    context's end (the cut-off was not reached within it), the high end at most :func:`high_cap_s`, every
    value finite, and the 90% interval at least :func:`min_width_s` wide."""
    seen, width = seen_s(known), min_width_s(known)
    q = np.sort(np.nan_to_num(np.asarray(q, dtype=float), nan=seen, posinf=HORIZON_S, neginf=seen))
    q = np.clip(q, seen, HORIZON_S)
    cap_charge_s = time_for_charge_s(known, CAP_AH)  # the planned load's charge curve, walked once
    q = np.minimum(q, high_cap_s(known, float(q[2]), cap_charge_s))
    cap = high_cap_s(known, float(q[2]), cap_charge_s)
    if q[3] - q[1] < width:  # widen upwards where the cap leaves room, else downwards to the context's end
        q[3] = min(q[1] + width, cap)
        q[1] = max(q[3] - width, seen)
    q[0], q[2] = min(q[0], q[1]), float(np.clip(q[2], q[1], q[3]))
    return EodPrediction(float(q[2]), float(q[1]), float(q[3]), float(q[1]), float(q[0]), method, flag)

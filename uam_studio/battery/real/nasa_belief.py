"""The one health belief on real NASA lives: ``uam-studio evaluate nasa --method belief``.

A cell's logbook is its earlier discharges (:class:`~uam_studio.battery.health.logbook.Logbook`): each finished
discharge on a 1 s grid from its first loaded sample (the current held between samples, the voltage interpolated
between them, down to :data:`FIT_ABOVE_V`), its ambient, and its whole-record likelihood fit on the identified NASA cell
(``NASA_IDENTIFIED``, fitted on B0005's first three discharges only) at that ambient. (The physics method's health,
its end matched to the cut-off, with this fit's covariance, was tried: no better on B0007, B0018, B0029 and B0033,
at twice the time; RESULTS.md, "A pack's logbook and one health belief".) Discharge k is predicted from
the :class:`~uam_studio.battery.health.belief.HealthBelief` over that logbook (the NASA cell's fleet prior, each
discharge's fit, aged between discharges by the NASA aging law; where the cell has run at the discharge's load and
ambient before, only those discharges' fits are read, as the physics method reads its last one), sharpened by
discharge k's own first ``context_s`` of readings (built from the
:func:`~uam_studio.battery.real.nasa_predict.known_before` view alone); the operator plans the load every
model-based method plans (:func:`~uam_studio.battery.real.nasa_physics.planned_current`: the context's load
continued) from the ambient it knows. The median is the physics model's time to the cut-off at the belief's mean,
divided by the model's discrepancy on this cell (:func:`~uam_studio.battery.real.nasa_predict.own_error_factor` over
:data:`DISCREPANCY_WINDOW` discharges: the model's error on the cell's latest finished discharge at the same load and
ambient). Its interval and bounds
are the median times the quantiles of ``true / median`` over the training cells (every cell given but the scored
one: leave one cell out) in the prediction's group: a cell's first
:data:`~uam_studio.battery.real.nasa_predict.EARLY_ERRORS` predictions take those of the training cells' first
predictions, the others those of all their later ones; once the cell has
:data:`~uam_studio.battery.real.nasa_predict.SCALE_WINDOW` errors of its own (finished discharges), its interval and
bounds are widened to its own latest errors' quantiles where those run wider. They are made an interval as the
history method's are (:func:`~uam_studio.battery.real.nasa_predict.as_prediction`: none past
:func:`~uam_studio.battery.real.nasa_predict.high_cap_s`, the median included, none before the context's end, at
least :func:`~uam_studio.battery.real.nasa_predict.min_width_s` wide). The rows are
:class:`~uam_studio.battery.real.nasa_eval.ScoredDischarge` s, as the history method's.

Public API: :func:`belief_life` (one cell's raw predictions), :func:`evaluate_belief` (rows for a folder of cells).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from uam_studio.battery.health.belief import HealthBelief
from uam_studio.battery.health.config import NASA_CELL_BELIEF
from uam_studio.battery.health.logbook import Logbook, LoggedFlight, fit_flight
from uam_studio.battery.parameters import NASA_IDENTIFIED, ZERO_C, Cell
from uam_studio.battery.real.nasa_data import NasaCell, NasaDischarge, persistence_s, same_conditions
from uam_studio.battery.real.nasa_eval import ScoredDischarge, condition_of, conservative_quantile, progpy_default_s
from uam_studio.battery.real.nasa_known import KnownDischarge
from uam_studio.battery.real.nasa_physics import (
    DT_S,
    fit_segment,
    grid_current,
    planned_current,
    time_to_cutoff_s,
)
from uam_studio.battery.real.nasa_predict import (
    EARLY_ERRORS,
    RISKS,
    SCALE_WINDOW,
    as_prediction,
    known_before,
    own_error_factor,
)

__all__ = ["DISCREPANCY_WINDOW", "FIT_ABOVE_V", "BeliefPrediction", "belief_life", "evaluate_belief"]

FIT_ABOVE_V = 2.8  # V: a discharge's record is fitted down to here (the model is not run far below its cut-off)
METHOD = "belief"
MIN_BAND = 100  # a group with fewer training errors takes the pooled quantiles
# discharges: the model's discrepancy on a cell is its error on the latest one at the same load and ambient. The
# discrepancy moves along a life; the median of the last 10 (the physics method's window) lags it: on the 26 shared
# lives a window of 1, 2, 3, 5 and 10 gave median errors of 0.81, 0.95, 1.04, 1.02 and 1.03% (RESULTS.md, "The belief
# on real lives tracks its discrepancy"; a choice made on those lives: in-sample)
DISCREPANCY_WINDOW = 1


@dataclass(frozen=True)
class BeliefPrediction:
    """One discharge predicted by :func:`belief_life`: times (s from the first loaded sample) to the cut-off,
    the median (``median_s``, bias-corrected), the physics model's time at the belief's mean along the planned
    load before that correction (``raw_s``) and the truth (``true_s``, None if never reached); the believed
    health (q_max C, R0 ohm, and the q_max std C) and whether it is among the cell's first predictions."""

    discharge: NasaDischarge
    median_s: float
    true_s: float | None
    q_max: float
    q_max_sd: float
    r0: float
    early: bool
    raw_s: float = math.nan


def _on_grid(d: NasaDischarge) -> tuple[np.ndarray, np.ndarray]:
    """Finished discharge ``d`` on a 1 s grid from its first loaded sample: (current A, voltage V), down to
    :data:`FIT_ABOVE_V` (what its logbook entry holds)."""
    seg = fit_segment(d)
    return _above_fit(seg.current_a, np.interp(np.arange(seg.current_a.size), seg.observed, seg.voltage_v))


def _context_on_grid(known: KnownDischarge) -> tuple[np.ndarray, np.ndarray]:
    """The readings an operator holds at ``known``'s prediction instant on the same 1 s grid: (current A,
    voltage V) from the first loaded sample up to the context's last sample, built from ``known`` alone (no
    sample after the context can reach it), down to :data:`FIT_ABOVE_V`."""
    cur = grid_current(known.time_s, known.current_a, known.load_start, extend=False)
    t = known.time_s[known.load_start:] - known.load_time_s
    obs = np.round(t / DT_S).astype(int) - 1
    keep = (obs >= 0) & (obs < cur.size)
    if not keep.any():
        return cur[:0], cur[:0]
    return _above_fit(cur, np.interp(np.arange(cur.size), obs[keep], known.voltage_v[known.load_start:][keep]))


def _above_fit(current_a: np.ndarray, voltage_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Readings (A, V) on the grid up to their first voltage below :data:`FIT_ABOVE_V`."""
    below = np.flatnonzero(voltage_v < FIT_ABOVE_V)
    n = int(below[0]) if below.size else voltage_v.size
    return current_a[:n], voltage_v[:n]


def belief_life(cell: NasaCell, cell_type: Cell = NASA_IDENTIFIED, cutoff_v: float = 3.0,
                context_s: float = 300.0) -> list[BeliefPrediction]:
    """Every discharge of ``cell`` predicted online from the belief over its logbook (module docstring); each reads
    the earlier discharges and a :func:`~uam_studio.battery.real.nasa_predict.known_before` view of its own."""
    book = Logbook(q_nominal_c=cell_type.q_max, eod_v=cutoff_v)
    past: list[tuple[NasaDischarge, float | None]] = []
    out = []
    for d in cell.discharges:
        known = known_before(d, context_s)
        params = replace(cell_type.params, t_ambient_k=ZERO_C + float(d.ambient_c))
        belief = HealthBelief(None, cutoff_v, _read_at(book, [p for p, _ in past], known),
                              replace(NASA_CELL_BELIEF, params=params))
        cur, volt = _context_on_grid(known)
        if cur.size:
            belief.observe(cur, volt)
        h = belief.health()
        raw = time_to_cutoff_s(planned_current(known), h.q_max_c, h.r0_ohm, params, ZERO_C + float(known.ambient_c),
                               cutoff_v)
        median = raw / own_error_factor(past, known, DISCREPANCY_WINDOW)
        true = d.time_to_cutoff_s(cutoff_v)  # the discharge has finished: from here on it is history
        out.append(BeliefPrediction(d, median, true, h.q_max_c, h.q_max_sd_c, h.r0_ohm,
                                    sum(e is not None for _, e in past) < EARLY_ERRORS, raw))
        past.append((d, raw / true - 1.0 if true else None))
        whole_cur, whole_v = _on_grid(d)
        fit = fit_flight(whole_cur, whole_v, 1.0, None, cutoff_v, params)
        book = replace(book, flights=book.flights + (LoggedFlight(whole_cur.astype(np.float32),
                                                                    whole_v.astype(np.float32), 1.0,
                                                                    ambient_c=float(d.ambient_c), fit=fit),))
    return out


def _band(p: BeliefPrediction) -> str:
    """The group whose errors set a prediction's interval: a cell's first predictions ('early'), else the rest
    ('later'). (Per ambient band was tried: the room band's quantiles are too narrow for its heavy-tailed cells;
    RESULTS.md, "A pack's logbook and one health belief".)"""
    return "early" if p.early else "later"


def _read_at(book: Logbook, logged: list[NasaDischarge], known) -> Logbook:
    """The logbook as read for a discharge at ``known``'s load and ambient: where the cell has run at them before,
    only those discharges' fits are read (the model's error depends on the load and the temperature, as the physics
    method's choice of the last discharge at the same conditions), every discharge still aging the belief by its
    charge; else every fit."""
    same = [same_conditions(d, known) for d in logged]
    if not any(same):
        return book
    return replace(book, flights=tuple(f if keep else replace(f, fit=None) for f, keep in zip(book.flights, same)))


def _quantiles(errors: list[float]) -> tuple[float, ...]:
    """log(true / median) at each of :data:`~uam_studio.battery.real.nasa_predict.RISKS`, one order statistic
    further out (split-conformal style)."""
    x = np.array(errors)
    return tuple(conservative_quantile(x, r) for r in RISKS)


def evaluate_belief(cells: list[NasaCell], cutoff_v: float = 3.0, context_s: float = 300.0, progpy: bool = True,
                    every: int = 1) -> list[ScoredDischarge]:
    """Rows for every cell (each ``every``-th discharge that ends after the context), each cell's interval from the
    other cells' errors (leave one cell out: ``fit`` 'loco'; with one cell, its own: 'in-sample')."""
    lives = {c.name: belief_life(c, cutoff_v=cutoff_v, context_s=context_s) for c in cells}
    errors: dict[str, dict[str, list[float]]] = {}
    for name, preds in lives.items():
        errs = errors.setdefault(name, {})
        for p in preds:
            if p.true_s is not None and p.true_s > context_s:
                errs.setdefault(_band(p), []).append(math.log(p.true_s / p.median_s))
    rows = []
    for c in cells:
        others = [n for n in lives if n != c.name] or [c.name]
        fit = "loco" if others != [c.name] else "in-sample"
        pooled = [e for n in others for errs in errors[n].values() for e in errs]
        own: list[float] = []  # the cell's own errors on its finished discharges, in order
        for k, p in enumerate(lives[c.name]):
            if p.true_s is None or p.true_s <= context_s:
                continue
            band = [e for n in others for e in errors[n].get(_band(p), [])]
            q = _quantiles(band if len(band) >= MIN_BAND else pooled)
            if len(own) >= SCALE_WINDOW:  # a cell whose own errors run wider than the training cells' widens
                mine = _quantiles(own[-SCALE_WINDOW:])
                q = (min(q[0], mine[0]), min(q[1], mine[1]), q[2], max(q[3], mine[3]))
            own.append(math.log(p.true_s / p.median_s))
            if k % every:
                continue
            d = p.discharge
            b99, b95, _, hi = (p.median_s * math.exp(x) for x in q)
            e = as_prediction(known_before(d, context_s), np.array([b99, b95, p.median_s, hi]), METHOD)
            rows.append(ScoredDischarge(
                c.name, d.index, d.ambient_c, condition_of(d), context_s, p.true_s, e.median_s, e.low_s, e.high_s,
                e.bound95_s, e.bound99_s, persistence_s(c, k, cutoff_v),
                progpy_default_s(d, cutoff_v) if progpy else None, METHOD, None, fit))
    return rows

"""The NASA 18650 as a physics cell of its own, and a physics method that predicts a life's discharges.

- :func:`identify_nasa`: the Daigle & Kulkarni model's parameters identified (``identify.identify_cell``)
  on the first :data:`IDENTIFY_DISCHARGES` discharges of one cell (:data:`IDENTIFY_CELL`, B0005: 2 A, 24 C).
  Nothing else is read, so every other cell of the data set is held out from it. The result is
  ``NASA_IDENTIFIED`` in :mod:`uam_studio.battery.parameters`, beside progpy's set (the paper's default
  cell, unchanged): ``uam-studio identify nasa-cell --data DIR`` prints its literal.
- :func:`discharge_health`: a finished discharge's health (q_max C, R0 ohm) on a parameter set: R0 and
  q_max fitted to its voltage above the cut-off, then q_max moved so that the model reaches the cut-off
  (V) when the cell did.
- :func:`predict_life`: the physics method, online. Discharge k is predicted from discharges 0..k-1 whole
  and a :class:`KnownDischarge` of discharge k (nothing after its context): the model at the health of the
  cell's last finished discharge at the same load and ambient (else its last discharge), run along the
  planned current (``nasa_predict.planned_load``: the context's load continued), divided by one plus the
  median of the method's own relative errors on that cell's last :data:`BIAS_WINDOW` discharges at the
  same load and ambient (``nasa_data.same_conditions``; a cell's drift between discharges: fade and rest
  recovery).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import brentq, least_squares

from uam_studio.battery.eod import first_below
from uam_studio.battery.parameters import (
    DEFAULT_CELL,
    NASA_ID_FLEET_Q_RANGE,
    NASA_ID_FLEET_R0_RANGE,
    ZERO_C,
    Cell,
    CellParameters,
)
from uam_studio.battery.real.identify import FitSegment, identify_cell
from uam_studio.battery.real.nasa_data import (
    LOADED_A,
    NasaCell,
    NasaDataError,
    NasaDischarge,
    load_nasa_cell,
    nasa_folder,
    same_conditions,
)
from uam_studio.battery.real.nasa_predict import (
    OWN_ERROR_WINDOW,
    KnownDischarge,
    known_before,
    own_error_factor,
    planned_load,
)
from uam_studio.battery.simulate import simulate

__all__ = ["BIAS_WINDOW", "IDENTIFY_CELL", "IDENTIFY_DISCHARGES", "LifePrediction", "discharge_health",
           "fit_segment", "grid_current", "identify_nasa", "nasa_cell_literal", "planned_current", "predict_life",
           "time_to_cutoff_s"]

IDENTIFY_CELL = "B0005"
IDENTIFY_DISCHARGES = (0, 1, 2)
BIAS_WINDOW = OWN_ERROR_WINDOW  # discharges: the method's running bias is the median of this many last errors
DT_S = 1.0  # s: the model's step on a discharge's grid
SIM_FLOOR_V = 2.5  # V: the lowest cut-off the model runs to
FIT_ABOVE_V = 2.8  # V: a discharge's health is fitted to its samples above this
Q_BOUNDS = (2000.0, 20000.0)  # C: the health fit's box
R0_BOUNDS = (1e-3, 1.0)  # ohm


def grid_current(time_s: np.ndarray, current_a: np.ndarray, start: int, extend: bool) -> np.ndarray:
    """The current (A) on a :data:`DT_S` grid from sample ``start``. ``extend``: the last loaded current
    carries on past the profile's end for twice its loaded length (a plan does not know when it ends)."""
    t = time_s[start:] - time_s[start]
    grid = np.arange(0.0, t[-1], DT_S)
    cur = np.interp(grid + DT_S / 2, t, current_a[start:])
    if not extend:
        return cur
    on = np.flatnonzero(cur > LOADED_A)
    if on.size == 0:
        return cur
    last = on[-1]
    return np.r_[cur[:last + 1], np.full(2 * last + 600, cur[last])]


def fit_segment(d: NasaDischarge, name: str | None = None) -> FitSegment:
    """``d`` from its first loaded sample as a :class:`FitSegment` (1 s grid, the cell's surface
    temperature at the load as its start and its measured temperatures fitted beside the voltage)."""
    t = d.time_s[d.load_start:] - d.load_time_s
    cur = grid_current(d.time_s, d.current_a, d.load_start, extend=False)
    obs = np.round(t / DT_S).astype(int) - 1
    keep = (obs >= 0) & (obs < cur.size)
    k = np.arange(d.load_start, d.time_s.size)[keep]
    return FitSegment(name or f"{d.cell}:{d.index}", cur, DT_S, obs[keep], d.voltage_v[k],
                      ZERO_C + float(d.temperature_c[d.load_start]), temperature_c=d.temperature_c[k])


def _start() -> CellParameters:
    """The identification's start: progpy's set with guessed heat and Arrhenius terms, at 24 C, and the
    identified cell's fleet ranges (``parameters.NASA_ID_FLEET_*``)."""
    return replace(DEFAULT_CELL, r0_activation_k=2000.0, k_activation_k=2000.0, thermal_mass=45.0,
                   thermal_tau_s=300.0, t_ambient_k=ZERO_C + 24.0, fleet_q_range=NASA_ID_FLEET_Q_RANGE,
                   fleet_r0_range=NASA_ID_FLEET_R0_RANGE)


def identify_nasa(folder: str | os.PathLike | None = None, max_nfev: int = 300) -> Cell:
    """Identify the NASA 18650 on :data:`IDENTIFY_CELL`'s first :data:`IDENTIFY_DISCHARGES` discharges in
    ``folder`` (default: :func:`nasa_folder`); about a minute. Reads no other cell.

    :raises NasaDataError: (field ``data``) the folder holds no such cell file; or the file's own errors.
    """
    data = nasa_folder(folder)
    path = data / f"{IDENTIFY_CELL}.csv.gz"
    if not path.is_file():
        raise NasaDataError(path, "data", f"no {path.name} in {data}")
    cell = load_nasa_cell(path)
    segs = [fit_segment(cell.discharges[i]) for i in IDENTIFY_DISCHARGES]
    fit = identify_cell(segs, _start(), 7000.0, 0.1, max_nfev=max_nfev)
    name = f"NASA 18650 (identified on {IDENTIFY_CELL}'s first {len(IDENTIFY_DISCHARGES)} discharges)"
    return Cell(name, fit.cell, fit.q_max, fit.r0)


def _voltage(current_a: np.ndarray, q_max: float, r0: float, params: CellParameters, t0_k: float) -> np.ndarray:
    return simulate(current_a, DT_S, q_max, r0, eod_v=SIM_FLOOR_V, cell=replace(params, t_ambient_k=t0_k)).voltage_v


def time_to_cutoff_s(current_a: np.ndarray, q_max: float, r0: float, params: CellParameters, t0_k: float,
                     cutoff_v: float) -> float:
    """Time (s) the model takes along ``current_a`` (A, :data:`DT_S` grid) to fall below ``cutoff_v`` (V);
    the profile's length if it never does."""
    k = int(first_below(_voltage(current_a, q_max, r0, params, t0_k), cutoff_v))
    return float((k + 1) * DT_S) if k >= 0 else float(current_a.size * DT_S)


def discharge_health(d: NasaDischarge, params: CellParameters, start: tuple[float, float],
                     cutoff_v: float = 3.0) -> tuple[float, float]:
    """The health (q_max C, R0 ohm) of finished discharge ``d`` on ``params`` (module docstring), the fit
    starting at ``start``. Where the model cannot reach the cut-off when the cell did, the curve fit's."""
    seg = fit_segment(d)
    m = seg.voltage_v > FIT_ABOVE_V
    obs, v = seg.observed[m], seg.voltage_v[m]
    t0 = seg.t_ambient_k

    def res(theta: np.ndarray) -> np.ndarray:
        sim = _voltage(seg.current_a, float(np.exp(theta[0])), float(np.exp(theta[1])), params, t0)
        out = sim[np.minimum(obs, sim.size - 1)] - v
        out[obs >= sim.size] = 0.5
        return out

    lo, hi = np.log([Q_BOUNDS[0], R0_BOUNDS[0]]), np.log([Q_BOUNDS[1], R0_BOUNDS[1]])
    x0 = np.clip(np.log(start), lo + 1e-9, hi - 1e-9)
    sol = least_squares(res, x0, bounds=(lo, hi), diff_step=1e-3, max_nfev=50, loss="soft_l1", f_scale=0.02)
    q, r0 = (float(x) for x in np.exp(sol.x))
    true = d.time_to_cutoff_s(cutoff_v)
    if true is None:
        return q, r0
    ext = grid_current(d.time_s, d.current_a, d.load_start, extend=True)

    def gap(qq: float) -> float:
        return time_to_cutoff_s(ext, qq, r0, params, t0, cutoff_v) - true

    a, b = max(0.6 * q, Q_BOUNDS[0]), min(1.5 * q, Q_BOUNDS[1])
    if gap(a) < 0 < gap(b):
        q = float(brentq(gap, a, b, xtol=1.0))
    return q, r0


@dataclass(frozen=True)
class LifePrediction:
    """One discharge predicted by :func:`predict_life`: times (s from the first loaded sample) to the
    cut-off, predicted (``median_s``, None for a cell's first discharge) and true (None if never reached);
    the health it was predicted with (q_max C, R0 ohm)."""

    index: int
    median_s: float | None
    true_s: float | None
    q_max: float
    r0: float


def planned_current(known: KnownDischarge) -> np.ndarray:
    """The current (A, :data:`DT_S` grid from the first loaded sample) an operator plans for the discharge it
    knows up to ``known``'s context: :func:`~uam_studio.battery.real.nasa_predict.planned_load`, the context's
    load continued. Every model-based method plans this load."""
    t, i = planned_load(known, known.load_start)
    return grid_current(t, i, 0, extend=False)


def _predict(known: KnownDischarge, health: tuple[float, float], params: CellParameters, t0_k: float,
             cutoff_v: float) -> float:
    return time_to_cutoff_s(planned_current(known), health[0], health[1], params, t0_k, cutoff_v)


def predict_life(cell: NasaCell, cell_type: Cell, cutoff_v: float = 3.0,
                 context_s: float = 300.0) -> list[LifePrediction]:
    """Every discharge of ``cell`` predicted online by the physics method on ``cell_type`` (module
    docstring). Each prediction reads the earlier discharges and a :func:`known_before` view of its own."""
    out: list[LifePrediction] = []
    past: list[tuple[NasaDischarge, tuple[float, float], float | None]] = []  # discharge, health, rel error
    for d in cell.discharges:
        known = known_before(d, context_s)
        same = [p for p in past if same_conditions(p[0], known)]
        base = same or past
        health = base[-1][1] if base else (cell_type.q_max, cell_type.r0)
        median = raw = None
        if past:
            raw = _predict(known, health, cell_type.params, ZERO_C + float(known.ambient_c), cutoff_v)
            median = raw / own_error_factor(((p[0], p[2]) for p in past), known, BIAS_WINDOW)
        true = d.time_to_cutoff_s(cutoff_v)  # the discharge has finished: from here on it is history
        out.append(LifePrediction(d.index, median, true, health[0], health[1]))
        err = raw / true - 1.0 if raw is not None and true else None
        past.append((d, discharge_health(d, cell_type.params, health, cutoff_v), err))
    return out


def nasa_cell_literal(cell: Cell) -> str:
    """``cell`` as the literal in :mod:`uam_studio.battery.parameters` (9 significant digits)."""
    p = cell.params
    names = ("t_ohmic_s", "kn", "kp", "t_sn_s", "t_sp_s", "r0_activation_k", "k_activation_k", "thermal_mass",
             "thermal_tau_s", "t_diffusion_s", "vol_s_fraction", "u0p", "t_ambient_k")
    body = "".join(f"    {n}={float(getattr(p, n)):.9g},\n" for n in names)
    ap = [f"{float(a):.9g}" for a in p.ap]
    rows = ",\n        ".join(", ".join(ap[i:i + 6]) for i in range(0, len(ap), 6))
    assert (p.fleet_q_range, p.fleet_r0_range) == (NASA_ID_FLEET_Q_RANGE, NASA_ID_FLEET_R0_RANGE)
    ranges = "    fleet_q_range=NASA_ID_FLEET_Q_RANGE,\n    fleet_r0_range=NASA_ID_FLEET_R0_RANGE,\n"
    return (f"NASA_IDENTIFIED_PARAMS = replace(\n    DEFAULT_CELL,\n{body}    ap=({rows}),\n{ranges})\n"
            f"NASA_IDENTIFIED = Cell({cell.name!r}, NASA_IDENTIFIED_PARAMS, {cell.q_max:.4f}, {cell.r0:.10f})\n")



"""Identify the electrochemistry model's parameters for a real cell from measured logs.

The model's structure stays Daigle & Kulkarni's (2013); what a different chemistry changes is
identified from data: the mobile charge q_max (C), the ohmic resistance R0 (ohm), the positive
electrode's reference potential and its 13 Redlich-Kister coefficients (the open-circuit-voltage
curve, kept smooth by a small curvature penalty), the Butler-Volmer rate constants, the time constants
of the ohmic and surface overpotentials and of the surface-bulk diffusion, the surface volume share,
the lumped thermal mass and cooling time, and Arrhenius activations of R0 and the rate constants
(:data:`NONLINEAR`). The negative electrode's potential and the mole-fraction ranges keep the published
values (the positive electrode's curve absorbs the difference). A log may start partly charged, its
charge out of full fitted too; measured temperatures are fitted beside the voltage.

The fit (variable projection). With the current as the input, the states (charges, overpotentials,
temperature) do not depend on the open-circuit-voltage parameters, and the voltage is linear in them.
So for each trial of the nonlinear parameters, the logs are simulated once and the OCV parameters
solved by linear least squares; ``scipy.optimize.least_squares`` moves the nonlinear ones (in log
space). Each log is a :class:`FitSegment`: current (A), voltage (V), its own start temperature and a
weight (residuals per sample are weighted by ``weight / sqrt(n)``, so a 600-sample C/5 discharge and a
900-sample mission count alike).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from uam_studio.battery.electrochem import equilibrium_voltage, model_constants, redlich_kister, surface_fractions
from uam_studio.battery.parameters import ZERO_C, CellParameters
from uam_studio.battery.simulate import simulate
from uam_studio.battery.solver import integrate_current
from uam_studio.battery.state import rested_state

# The nonlinear parameters, in the order of the fit's vector (log space).
NONLINEAR = ("q_max", "r0", "t_ohmic_s", "kn", "kp", "t_sn_s", "t_sp_s", "r0_activation_k", "k_activation_k",
             "thermal_mass", "thermal_tau_s", "diffusion_tau_s", "vol_s_fraction")
# Bounds of the nonlinear parameters (same units as the fields; a search box, not a prior). The time
# constants stay above 1.5 s: the fit's logs are simulated at 1 s steps (explicit Euler needs dt < tau).
# The surface-bulk diffusion is fitted by its time constant (CellParameters.diffusion_tau_s).
BOUNDS = {"q_max": (2000.0, 20000.0), "r0": (1e-3, 1.0), "t_ohmic_s": (1.5, 100.0), "kn": (1.0, 1e7),
          "kp": (1.0, 1e7), "t_sn_s": (1.5, 1e4), "t_sp_s": (1.5, 1e4), "r0_activation_k": (1.0, 1e4),
          "k_activation_k": (1.0, 1e4), "thermal_mass": (5.0, 500.0), "thermal_tau_s": (10.0, 1e4),
          "diffusion_tau_s": (1.5, 1e6), "vol_s_fraction": (1e-3, 0.5)}
REMOVED_BOUNDS_KC = (0.0, 10.0)  # kC: a fitted start's charge out of full
TEMPERATURE_WEIGHT_V_PER_K = 2e-3  # V: a 1 K miss of the measured temperature counts as 2 mV
_RIDGE = 1e-8  # relative ridge of the OCV least squares (keeps the 14 columns well posed)


@dataclass(frozen=True)
class FitSegment:
    """One measured log to fit, from a full, rested cell at ``t_ambient_k`` (K): the current (A, + =
    discharge) on a uniform grid of ``dt_s`` (s), ``current_a[k]`` flowing during [k dt, (k+1) dt), and
    the voltage (V) measured after steps ``observed`` (indices into that grid, [M])."""

    name: str
    current_a: np.ndarray
    dt_s: float
    observed: np.ndarray
    voltage_v: np.ndarray
    t_ambient_k: float
    weight: float = 1.0
    temperature_c: np.ndarray | None = None  # measured at ``observed`` (C), fitted too when given
    removed_c: float = 0.0  # C taken out of a full charge before the log (a rested, partly charged start)
    fit_removed: bool = False  # fit removed_c too (a start whose charge is unknown)


@dataclass(frozen=True)
class IdentifiedCell:
    """Result of :func:`identify_cell`: the parameter set and the cell's health (q_max C, R0 ohm)."""

    cell: CellParameters
    q_max: float
    r0: float
    rms_v: dict  # segment name -> RMS voltage residual (V)
    removed_c: dict  # segment name -> fitted charge out of full at its start (C), where fitted
    cost: float = float("nan")  # the fit's objective at the solution: half the sum of squared residuals (V^2)


def _ocv_basis(xps: np.ndarray, n_ap: int) -> np.ndarray:
    """The positive electrode's potential terms that are linear in (u0p, AP_0..n_ap-1) at mole fractions
    ``xps``: columns [1, RK_0(x), ..., RK_{n_ap-1}(x)] (V per unit coefficient), shape [N, 1 + n_ap]."""
    cols = [np.ones_like(xps)]
    for k in range(n_ap):
        cols.append(redlich_kister(xps, tuple(1.0 if j == k else 0.0 for j in range(k + 1))))
    return np.stack([c.ravel() for c in cols], axis=1)


def _ocv_columns(states: dict, q_total: float, cell: CellParameters) -> tuple[np.ndarray, np.ndarray]:
    """Columns of the voltage that are linear in (u0p, AP_0..12), and the rest of the voltage (V): the
    equilibrium voltage without those terms, less the overpotentials."""
    xns, xps = surface_fractions(states["qns"], states["qps"], q_total * cell.vol_s_fraction)
    bare = replace(cell, u0p=0.0, ap=(0.0,) * len(cell.ap))
    ocv = equilibrium_voltage(xns, xps, states["tb"], model_constants(bare))
    fixed = ocv - states["vo"] - states["vsn"] - states["vsp"]
    return _ocv_basis(xps, len(cell.ap)), fixed.ravel()


def _with(cell: CellParameters, theta: np.ndarray) -> tuple[CellParameters, float, float]:
    vals = dict(zip(NONLINEAR, np.exp(theta[:len(NONLINEAR)])))
    q_max, r0 = vals.pop("q_max"), vals.pop("r0")
    tau = vals.pop("diffusion_tau_s", None)
    cell = replace(cell, **vals)
    if tau is not None:
        cell = replace(cell, t_diffusion_s=tau * (1.0 / cell.vol_b + 1.0 / cell.vol_s))
    return cell, q_max, r0


def _design(theta: np.ndarray, segments: list[FitSegment], base: CellParameters):
    cell, q_max, r0 = _with(base, theta)
    q_total = cell.q_total(q_max)
    rows, rhs, weights, temps = [], [], [], []
    removed = iter(theta[len(NONLINEAR):])
    for seg in segments:
        c = replace(cell, t_ambient_k=seg.t_ambient_k)
        x0 = rested_state(np.array([q_max]), next(removed) * 1000.0 if seg.fit_removed else seg.removed_c, c)
        _, states = integrate_current(np.asarray(seg.current_a, float)[None], x0, np.array([q_total]),
                                      np.array([r0]), seg.dt_s, c)
        a, fixed = _ocv_columns({k: v[:, seg.observed] for k, v in states.items()}, q_total, c)
        rows.append(a)
        rhs.append(np.asarray(seg.voltage_v, float) - fixed)
        weights.append(np.full(len(fixed), seg.weight / np.sqrt(len(fixed))))
        if seg.temperature_c is not None:
            miss = states["tb"][0, seg.observed] - ZERO_C - seg.temperature_c
            temps.append(miss * TEMPERATURE_WEIGHT_V_PER_K * seg.weight / np.sqrt(len(miss)))
    extra = np.concatenate(temps) if temps else np.zeros(0)
    return cell, q_max, r0, np.concatenate(rows), np.concatenate(rhs), np.concatenate(weights), extra


_CURVE_X = np.linspace(0.35, 0.999, 200)  # positive-electrode mole fractions where the OCV is kept smooth
CURVATURE_WEIGHT = 3e-4  # weight of the OCV curve's second differences (V) against the data's residuals


def _curvature_rows(n_coef: int) -> np.ndarray:
    """Second differences over :data:`_CURVE_X` of each OCV column (rows of the smoothness penalty)."""
    a = _ocv_basis(_CURVE_X, n_coef - 1)
    return (a[2:] - 2 * a[1:-1] + a[:-2]) / np.sqrt(len(_CURVE_X))


def _solve_ocv(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    curv = _curvature_rows(a.shape[1]) * CURVATURE_WEIGHT / 1e-4
    a = np.vstack([a, curv])
    b = np.concatenate([b, np.zeros(len(curv))])
    w = np.concatenate([w, np.ones(len(curv))])
    aw = a * w[:, None]
    scale = np.linalg.norm(aw, axis=0)
    scale[scale == 0] = 1.0
    an = aw / scale
    lhs = an.T @ an + _RIDGE * np.eye(an.shape[1])
    coef = np.linalg.solve(lhs, an.T @ (b * w))
    return coef / scale


def _residuals(theta, segments, base):
    cell, q_max, r0, a, b, w, extra = _design(theta, segments, base)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(extra))):
        return np.full(len(b) + len(extra), 1.0)
    coef = _solve_ocv(a, b, w)
    return np.concatenate([(a @ coef - b) * w, extra])


def identify_cell(segments: list[FitSegment], start: CellParameters, q_max0: float, r0_0: float,
                  max_nfev: int = 200, verbose: int = 0) -> IdentifiedCell:
    """Fit the model to ``segments`` (see the module docstring), starting from ``start`` and the health
    (``q_max0`` C, ``r0_0`` ohm). Returns the identified parameter set with the OCV solved in."""
    from scipy.optimize import least_squares

    theta0 = np.r_[np.log([q_max0, r0_0] + [getattr(start, n) for n in NONLINEAR[2:]]),
                   [seg.removed_c / 1000.0 for seg in segments if seg.fit_removed]]
    n_removed = len(theta0) - len(NONLINEAR)
    lo = np.r_[np.log([BOUNDS[n][0] for n in NONLINEAR]), np.full(n_removed, REMOVED_BOUNDS_KC[0])]
    hi = np.r_[np.log([BOUNDS[n][1] for n in NONLINEAR]), np.full(n_removed, REMOVED_BOUNDS_KC[1])]
    sol = least_squares(_residuals, np.clip(theta0, lo, hi), args=(segments, start), bounds=(lo, hi), method="trf",
                        x_scale=1.0,
                        diff_step=1e-4, max_nfev=max_nfev, verbose=verbose)
    cell, q_max, r0, a, b, w, _ = _design(sol.x, segments, start)
    coef = _solve_ocv(a, b, w)
    cell = replace(cell, u0p=float(coef[0]), ap=tuple(float(c) for c in coef[1:]))
    removed = dict(zip([s.name for s in segments if s.fit_removed], 1000.0 * sol.x[len(NONLINEAR):]))
    rms = {}
    for seg in segments:
        c = replace(cell, t_ambient_k=seg.t_ambient_k)
        x0 = rested_state(np.array([q_max]), removed.get(seg.name, seg.removed_c), c)
        res = simulate(seg.current_a, seg.dt_s, q_max, r0, eod_v=2.5, initial_state=x0, cell=c)
        rms[seg.name] = float(np.sqrt(np.mean((res.voltage_v[seg.observed] - seg.voltage_v) ** 2)))
    return IdentifiedCell(cell, float(q_max), float(r0), rms, removed, float(sol.cost))

"""Health (q_max, R0) of a cell from measured current and voltage: a maximum-likelihood fit of the
physics model, with a Laplace (Gauss-Newton) covariance.

Public API:

- :func:`fit_health`: one context (current in A, voltage in V, from the log's first sample) ->
  :class:`~uam_studio.battery.health.estimate.HealthEstimate` (q_max in C, R0 in ohm, their
  covariance, the voltage noise).
- :func:`fit_health_batch`: the same for B contexts of one length, fitted together (one batched
  :func:`~uam_studio.battery.simulate` call per iteration for all of them).

The EOD intervals (s) and voltage bands (V) along a planned profile are in
:mod:`uam_studio.battery.health.intervals`; the likelihood (residuals, Levenberg-Marquardt, the pre-roll
search) in :mod:`uam_studio.battery.health.likelihood`.

The model. The cell is full and rested at the log's first sample (or in ``initial_state``); a log
that starts at rest before the take-off has 0 A samples first, which leave a rested, full cell
unchanged. A log that starts under load may have begun up to 60 s into it: that pre-roll (the first
logged current since full charge, for a fitted, continuous time) becomes a third parameter when it
explains the data significantly better (see :func:`fit_health`). Voltage noise is Gaussian and white with an unknown std
(estimated from the residuals, never below
:data:`~uam_studio.battery.health.likelihood.NOISE_FLOOR_V`). The measured current is used as
the model's input: current-sensor noise enters only through the ohmic lag (tau 6 s) and the charge
integral, both small against the voltage noise at tens of mA (errors-in-variables are ignored).

The fit. Levenberg-Marquardt over (w, R0) with w = 6500 C / q_max, in which the voltage is close to
linear. Each iteration simulates the trial point and its finite-difference neighbours in one
batched call, over the whole context (the state depends on all of it; every sample is a residual). A coarse start
(5 values of w, R0 solved in closed form for each: the voltage is linear in R0 up to the weak thermal
coupling) keeps it out of local minima. The estimate is bounded to the box
:data:`~uam_studio.battery.health.estimate.FIT_Q_RANGE` x
:data:`~uam_studio.battery.health.estimate.FIT_R0_RANGE`.

The uncertainty. Covariance of (w, R0) = sigma^2 f (J^T J)^-1 at the optimum (sigma: the noise
std; f >= 1: the model-discrepancy factor of :mod:`uam_studio.battery.health.quality`, from the
residuals' HAC covariance where they are correlated or, with a stated noise, above it; 1 where they
look like white noise), plus a weak Gaussian prior as wide as the box; with a fitted pre-roll, the (w, R0)
marginal. A context that does not fit the model, or whose likelihood puts the cell outside its type's
fleet range, is flagged (``HealthEstimate.flags``).
By default (``prior=True``) this Gaussian is then multiplied by the cell type's fleet prior
(:func:`~uam_studio.battery.health.prior.fleet_prior`: the health range its fleet spans, which is
known before any measurement): it decides the estimate only where the context says little (a short
take-off, a noisy sensor). Draws and intervals are Gaussian in (w, R0) and clipped to the box. No
calibration factor (coverage per noise x context cell: ``benchmarks/bench_intervals.py``).
"""

from __future__ import annotations

import numpy as np

from uam_studio.battery.health.estimate import (
    PRIOR_PRECISION,
    HealthEstimate,
    check_context,
    check_noise,
    cov_qr,
    rep_state,
)
from uam_studio.battery.health.likelihood import (
    NOISE_FLOOR_V,
    current_noise_covariance,
    levenberg_marquardt,
    search_preroll,
    start_point,
)
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, disagrees, fleet_prior
from uam_studio.battery.health.quality import (
    FLEET_Z,
    MAX_FIT_RMS_V,
    current_noise_a,
    excess_factor,
    fit_flags,
    hac_covariance,
    not_white,
    residual_autocorrelation,
)
from uam_studio.battery.parameters import DEFAULT_CELL, DEFAULT_EOD_V, CellParameters
from uam_studio.battery.simulate import EOD_RANGE
from uam_studio.battery.state import BatteryState
from uam_studio.errors import InputError, check_range

__all__ = ["PREROLL_CHI2", "REST_CURRENT_A", "fit_health", "fit_health_batch"]

REST_CURRENT_A = 0.1  # A: a log whose first sample draws less starts at rest
PREROLL_CHI2 = 10.83  # the pre-roll is kept when it lowers the chi-square by more (1 dof, p = 0.001)


def fit_health_batch(current_a, voltage_v, dt_s: float = 1.0, noise_v: float | None = None,
                     initial_state: BatteryState | None = None, start: str = "auto",
                     cell: CellParameters = DEFAULT_CELL, prior: bool | HealthPrior = True) -> list[HealthEstimate]:
    """Fit (q_max, R0) to each of B contexts of one length; see :func:`fit_health`.

    :param current_a: measured per-cell current (A), shape [B, T], from the log's first sample.
    :param voltage_v: measured voltage (V), shape [B, T].
    :return: one :class:`HealthEstimate` per row.
    """
    cur, volt, dt = check_context(current_a, voltage_v, dt_s, ndim=(1, 2))
    noise = check_noise(noise_v)
    if start not in ("auto", "full"):
        raise InputError("start", f"{start!r} is not allowed; use 'auto' or 'full'")
    cur, volt = np.atleast_2d(cur), np.atleast_2d(volt)
    net = cur.sum(axis=-1) * dt
    if initial_state is None and np.any(net < 0.0):  # from a full cell, a net charge is impossible
        k = int(np.argmax(net < 0.0))
        raise InputError("current_a", "the context charges the cell "
                         f"(net {net[k]:.3g} C{f' in row {k}' if len(net) > 1 else ''}); "
                         "the fit reads a discharge from a full cell (+ = discharge)")
    if initial_state is not None and not isinstance(initial_state, BatteryState):
        raise InputError("initial_state", "expected a BatteryState (e.g. a result's final_state)")
    if initial_state is not None and initial_state.batch_size not in (1, cur.shape[0]):
        raise InputError("initial_state", f"batch {initial_state.batch_size} does not match {cur.shape[0]}")
    if initial_state is not None and initial_state.batch_size == 1 and cur.shape[0] > 1:
        initial_state = rep_state(initial_state, cur.shape[0])
    if not isinstance(prior, (bool, HealthPrior)):
        raise InputError("prior", "expected True (the cell type's fleet prior), False or a HealthPrior")
    fleet = fleet_prior(cell)
    known = fleet if prior is True else (prior or None)
    b = cur.shape[0]
    preroll = np.zeros(b)
    with np.errstate(all="ignore"):
        wr0, _ = start_point(cur, volt, dt, initial_state, cell)
        wr, cost, jac, mask, iters, resid = levenberg_marquardt(cur, volt, dt, initial_state, cell, wr0)
        n_par = np.full(b, 2)
        jac3: dict[int, np.ndarray] = {}  # the 3-parameter Jacobians of rows with a pre-roll
        if start == "auto" and initial_state is None:
            # Logs under load at the first sample, unless the fit from full charge is already exact.
            exact = cost / np.maximum(mask.sum(-1), 1) < (0.1 * NOISE_FLOOR_V) ** 2
            under = np.where((np.abs(cur[:, 0]) >= REST_CURRENT_A) & ~exact)[0]
            if under.size:
                steps, wr_s = search_preroll(cur[under], volt[under], dt, cell)
                alt = under[steps > 0]
                if alt.size:  # fit (w, r0, pre-roll) for those rows; keep it where it fits significantly better
                    start3 = np.column_stack([wr_s[steps > 0], steps[steps > 0] * dt])
                    p3, c3, j3, m3, it3, r3 = levenberg_marquardt(cur[alt], volt[alt], dt, None, cell, start3,
                                                                  i0=cur[alt, 0])
                    sig2 = np.maximum(c3 / np.maximum(m3.sum(-1) - 3, 1), NOISE_FLOOR_V ** 2)
                    win = (cost[alt] - c3) / sig2 > PREROLL_CHI2
                    for k, row in enumerate(alt):
                        if win[k]:
                            wr[row], cost[row], mask[row], resid[row] = p3[k, :2], c3[k], m3[k], r3[k]
                            iters[row] += it3[k]
                            preroll[row] = p3[k, 2]
                            n_par[row] = 3
                            jac3[row] = j3[k]
        n_ok = np.maximum(mask.sum(-1), 4)
        rms = np.sqrt(cost / n_ok)
        for bad in np.flatnonzero(~(rms <= MAX_FIT_RMS_V)):
            row = f" (row {bad})" if b > 1 else ""
            raise InputError("voltage_v", f"the cell model cannot explain these readings{row}: RMS residual "
                             f"{rms[bad]:.3g} V, at most {MAX_FIT_RMS_V:g} V; check the units (V, A) and the cell type")
        sig = np.sqrt(np.maximum(cost / (n_ok - n_par), NOISE_FLOOR_V ** 2)) if noise is None else \
            np.full(b, max(noise, NOISE_FLOOR_V))
        rho = residual_autocorrelation(resid, mask)
        suspect = not_white(rho, n_ok, cost, n_ok - n_par, None if noise is None else sig[0]) & (rms > NOISE_FLOOR_V)
        # errors in variables: the current sensor's noise, read off the current, through the model (fit_quality)
        sigma_i = np.array([current_noise_a(c) for c in cur])
        cov_cur: dict[int, tuple[np.ndarray, float]] = {}
        for three in (False, True):  # one batched model call per parameter count
            rows = [k for k in range(b) if sigma_i[k] > 0.0 and (k in jac3) == three]
            if not rows:
                continue
            pts = np.column_stack([wr[rows], preroll[rows]]) if three else wr[rows]
            states = None if initial_state is None else BatteryState.from_array(initial_state.as_array()[rows])
            covs, dv2 = current_noise_covariance(cur[rows], pts, cur[rows, 0] if three else None, dt, states, cell,
                                                 np.stack([jac3[k] if three else jac[k] for k in rows]), mask[rows],
                                                 sigma_i[rows])
            cov_cur.update({k: (covs[i], dv2[i]) for i, k in enumerate(rows)})
    out = []
    for k in range(b):
        j = jac3.get(k, jac[k])
        # a context that says nothing (at rest: J = 0) gets an unbounded covariance, not a singular matrix
        a_inv = np.linalg.inv(np.einsum("ti,tj->ij", j, j) + np.eye(j.shape[1]) * 1e-300)
        var = sig[k] ** 2
        cov_data = var * a_inv
        if k in cov_cur:
            if noise is None:  # the fitted noise std less what the current noise explains
                var = max(var - cov_cur[k][1], NOISE_FLOOR_V ** 2)
            cov_data = var * a_inv + cov_cur[k][0]
        # the model's discrepancy: residuals still not white noise of the assumed std -> HAC, where larger
        factor = excess_factor(cov_data, hac_covariance(j, resid[k], mask[k], float(rho[k]))) if suspect[k] else 1.0
        prior_prec = np.diag(PRIOR_PRECISION[:j.shape[1]])
        cw = np.linalg.inv(np.linalg.inv(cov_data * factor) + prior_prec)[:2, :2]  # with a pre-roll: the marginal
        face = np.linalg.inv(np.linalg.inv(cov_data) + prior_prec)[:2, :2]  # at face value: without the factor
        w, r = float(wr[k, 0]), float(wr[k, 1])
        cw = 0.5 * (cw + cw.T)
        outside = bool(disagrees(np.array([w, r]), face, fleet, FLEET_Z).any())
        est = HealthEstimate(q_max=Q_REF_C / w, r0=r, cov=cov_qr(w, cw), noise_v=float(sig[k]),
                             n_samples=int(mask[k].sum()), cov_w=cw, rms_residual_v=float(rms[k]),
                             iterations=int(iters[k]), preroll_s=float(preroll[k]),
                             preroll_current_a=float(cur[k, 0]) if preroll[k] > 0 else 0.0,
                             residual_autocorr=float(rho[k]), discrepancy_factor=float(factor),
                             flags=fit_flags(factor > 1.0, outside))
        out.append(est if known is None else est.with_prior(known))
    return out


def fit_health(current_a, voltage_v, dt_s: float = 1.0, noise_v: float | None = None,
               eod_v: float = DEFAULT_EOD_V, initial_state: BatteryState | None = None, start: str = "auto",
               cell: CellParameters = DEFAULT_CELL, prior: bool | HealthPrior = True) -> HealthEstimate:
    """Maximum-likelihood (q_max, R0) of one cell from a measured context, with its covariance.

    :param current_a: measured per-cell current (A), shape [T], ``current_a[k]`` flowing during
        [k dt, (k+1) dt) from the log's first sample; at least
        :data:`~uam_studio.battery.health.estimate.MIN_CONTEXT_S` s.
    :param voltage_v: measured terminal voltage (V) at the end of each step, shape [T].
    :param dt_s: sample step (s).
    :param noise_v: voltage-noise std (V); None: estimated from the residuals. Never below
        :data:`~uam_studio.battery.health.likelihood.NOISE_FLOOR_V`.
    :param eod_v: the cut-off (V) of later predictions; checked here, the fit itself uses every
        sample the model keeps above :data:`~uam_studio.battery.health.estimate.CURVE_CUTOFF_V`.
    :param initial_state: the cell's state at the log's first sample; default: see ``start``.
    :param start: where the log starts, without ``initial_state``. ``"auto"``: a log whose first
        sample draws under :data:`REST_CURRENT_A` starts full and at rest; one that starts under load
        may have begun up to 60 s into the load: unless the fit from full charge is exact, a
        third parameter, the pre-roll (0-60 s of the first logged current from full charge,
        continuous; started from the best whole step of
        :func:`~uam_studio.battery.health.likelihood.search_preroll`), is fitted as well, and kept
        where it lowers the chi-square by more than :data:`PREROLL_CHI2`
        (``HealthEstimate.preroll_s``; the covariance is then the (w, R0) marginal).
        ``"full"``: full and rested at the first sample.
    :param cell: the cell type's parameter set (its fleet's health range is the default prior).
    :param prior: True: the likelihood's Gaussian in (w, R0) multiplied by the fleet prior of ``cell``
        (:func:`~uam_studio.battery.health.prior.fleet_prior`); a :class:`HealthPrior`: by that one;
        False: the likelihood alone (with a weak prior as wide as the fit's box), for a caller that
        combines several fits with its own prior once.
    :raises InputError: NaN or inf, a context shorter than 20 s, mismatched lengths, a negative
        noise level, a context that charges the cell (net), or one the model cannot explain at all
        (RMS residual above :data:`~uam_studio.battery.health.quality.MAX_FIT_RMS_V`), naming the field.
    """
    check_range("eod_v", eod_v, *EOD_RANGE, " V")
    cur, volt, dt = check_context(current_a, voltage_v, dt_s, ndim=(1,))
    check_noise(noise_v)
    return fit_health_batch(cur[None], volt[None], dt, noise_v, initial_state, start, cell, prior)[0]

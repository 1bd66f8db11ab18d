"""Health (q_max, R0) of a cell from measured current and voltage: a maximum-likelihood fit of the
physics model, with a Laplace (Gauss-Newton) covariance, EOD intervals and voltage bands.

Public API:

- :func:`fit_health`: one context (current in A, voltage in V, from the log's first sample) ->
  :class:`HealthEstimate` (q_max in C, R0 in ohm, their covariance, the voltage noise).
- :func:`fit_health_batch`: the same for B contexts of one length, fitted together (one batched
  :func:`~uam_studio.battery.simulate` call per iteration for all of them).
- :func:`eod_interval_s`: (low, median, high) end-of-discharge time (s) along a planned profile.
- :func:`voltage_band`: (low, median, high) voltage (V) along a planned profile, a band to draw.

The model. The cell is full and rested at the log's first sample (or in ``initial_state``); a log
that starts at rest before the take-off has 0 A samples first, which leave a rested, full cell
unchanged. A log that starts under load may have begun up to 60 s into it: that pre-roll (the first
logged current since full charge, for a fitted, continuous time) becomes a third parameter when it
explains the data significantly better (see :func:`fit_health`). Voltage noise is Gaussian and white with an unknown std
(estimated from the residuals, never below :data:`NOISE_FLOOR_V`). The measured current is used as
the model's input: current-sensor noise enters only through the ohmic lag (tau 6 s) and the charge
integral, both small against the voltage noise at tens of mA (errors-in-variables are ignored).

The fit. Levenberg-Marquardt over (w, R0) with w = 6500 C / q_max, in which the voltage is close to
linear. Each iteration simulates the trial point and its finite-difference neighbours in one
batched call, over the whole context (the state depends on all of it; every sample is a residual). A coarse start (5 values
of w, R0 solved in closed form for each: the voltage is linear in R0 up to the weak thermal
coupling) keeps it out of local minima. The estimate is bounded to the box :data:`FIT_Q_RANGE` x
:data:`FIT_R0_RANGE`.

The uncertainty. Covariance of (w, R0) = sigma^2 (J^T J)^-1 at the optimum (sigma: the noise
std), plus a weak Gaussian prior as wide as the box; with a fitted pre-roll, the (w, R0) marginal.
By default (``prior=True``) this Gaussian is then multiplied by the cell type's fleet prior
(:func:`~uam_studio.battery.health_prior.fleet_prior`: the health range its fleet spans, which is
known before any measurement): it decides the estimate only where the context says little (a short
take-off, a noisy sensor). Draws and intervals are Gaussian in (w, R0) and clipped to the box. No
calibration factor (coverage per noise x context cell: ``benchmarks/bench_intervals.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from statistics import NormalDist

import numpy as np

from ..errors import InputError, check_range
from ..flight.context import TAKEOFF_CONTEXT_S
from .eod import first_below
from .health_prior import Q_REF_C, HealthPrior, combine, fleet_prior
from .parameters import DEFAULT_CELL, DEFAULT_EOD_V, PAPER_Q_RANGE, PAPER_R0_RANGE, CellParameters
from .simulate import CURRENT_LIMIT_A, DT_RANGE, EOD_RANGE, simulate
from .solver import integrate_current
from .state import STATE_NAMES, BatteryState, full_charge

__all__ = ["FIT_Q_RANGE", "FIT_R0_RANGE", "MIN_CONTEXT_S", "NOISE_FLOOR_V", "HealthEstimate",
           "band_from_sigma_points", "check_context", "crossing_times", "eod_interval_s", "eod_intervals",
           "fit_health", "fit_health_batch", "interval_ends", "interval_points", "preroll_states", "two_sided_z",
           "voltage_band", "with_preroll"]

MIN_CONTEXT_S = float(TAKEOFF_CONTEXT_S)  # s: shortest context accepted: the take-off context
FIT_Q_RANGE = (2000.0, 16000.0)  # C: box of the estimate and of its draws
FIT_R0_RANGE = (0.0, 1.0)  # ohm
NOISE_FLOOR_V = 0.5e-3  # V: the noise std used is never below this
CURVE_CUTOFF_V = EOD_RANGE[0]  # V: contexts and bands are simulated down to here
MAX_ITER = 30
PREROLL_MAX_S = 60.0  # s: longest load before the log's first sample that the fit looks for
_H = np.array([1e-4, 1e-4, 1e-2])  # finite-difference steps in (w, R0 ohm, pre-roll s)
_W_BOX = (Q_REF_C / FIT_Q_RANGE[1], Q_REF_C / FIT_Q_RANGE[0])
_LO = np.array([_W_BOX[0], FIT_R0_RANGE[0], 0.0])
_HI = np.array([_W_BOX[1], FIT_R0_RANGE[1], PREROLL_MAX_S])
_PRIOR_PREC = 1.0 / (_HI - _LO) ** 2  # weak prior: std = box width, in (w, R0, pre-roll)
_START_W = (0.65, 0.8, 1.0, 1.2, 1.45)  # q_max 10000, 8125, 6500, 5417, 4483 C (the NASA cell's fleet)
_START_R0 = (0.1, 0.3)  # ohm (the NASA cell's fleet, R0 up to 0.45 ohm)
_START_FLEET = (sum(PAPER_Q_RANGE) / 2, PAPER_R0_RANGE[1])  # C, ohm: the fleet the start grid is written for (the paper's box: its centre, top)


def _start_grid(cell: CellParameters, ws=_START_W) -> tuple[np.ndarray, tuple[float, float]]:
    """The coarse start's w values and R0 pair (ohm) for the cell type: the NASA grid scaled to the type's
    fleet (q_max by its centre, R0 by its top), so a cell of another size or resistance starts among its
    own kind (R0 of 0.1-0.3 ohm puts a VTC6 at 15 A below the cut-off, and then no start fits)."""
    q_scale = sum(cell.fleet_q_range) / 2 / _START_FLEET[0]
    r_scale = cell.fleet_r0_range[1] / _START_FLEET[1]
    return np.asarray(ws) / q_scale, (_START_R0[0] * r_scale, _START_R0[1] * r_scale)
REST_CURRENT_A = 0.1  # A: a log whose first sample draws less starts at rest
PREROLL_CANDIDATES_S = (0, 1, 2, 3, 4, 6, 8, 10, 13, 16, 20, 25, 30, 40, 50, 60)  # s: the pre-roll's start
PREROLL_WINDOW_S = 60.0  # s of the context that the pre-roll search reads
PREROLL_CHI2 = 10.83  # the pre-roll is kept when it lowers the chi-square by more (1 dof, p = 0.001)


@dataclass(frozen=True, eq=False)
class HealthEstimate:
    """A fitted cell health with its uncertainty.

    :param q_max: maximum-likelihood q_max (C).
    :param r0: maximum-likelihood R0 (ohm).
    :param cov: 2x2 covariance of (q_max, r0) (C^2, C ohm, ohm^2), the delta-method image of
        ``cov_w``.
    :param noise_v: voltage-noise std used for the covariance (V).
    :param n_samples: context samples used by the fit.
    :param cov_w: 2x2 covariance of (w, r0), w = 6500 C / q_max, in which draws are Gaussian.
    :param rms_residual_v: RMS of the fit's voltage residuals (V).
    :param iterations: Levenberg-Marquardt iterations.
    :param preroll_s: load time (s) before the log's first sample, for a log that starts under load:
        the cell was full and rested ``preroll_s`` earlier and drew ``preroll_current_a`` (A, the
        first logged current) since. 0 for a log that starts at the take-off or at rest.
    """

    q_max: float
    r0: float
    cov: np.ndarray
    noise_v: float
    n_samples: int
    cov_w: np.ndarray
    rms_residual_v: float = 0.0
    iterations: int = 0
    preroll_s: float = 0.0
    preroll_current_a: float = 0.0

    @property
    def w(self) -> float:
        """6500 C / q_max (-)."""
        return Q_REF_C / self.q_max

    @property
    def std(self) -> tuple[float, float]:
        """Standard deviations of (q_max in C, r0 in ohm)."""
        return float(math.sqrt(self.cov[0, 0])), float(math.sqrt(self.cov[1, 1]))

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws of (q_max C, r0 ohm), shape [n, 2]: Gaussian in (w, r0), clipped to the box."""
        n = int(n)
        z = rng.standard_normal((n, 2)) @ _chol(self.cov_w).T
        return _to_qr(np.array([self.w, self.r0]) + z)

    def initial_states(self, points: np.ndarray, dt: float, cell: CellParameters = DEFAULT_CELL) -> BatteryState | None:
        """The state at the log's first sample for cells (q_max C, r0 ohm) ``points`` [N, 2]: after
        this estimate's pre-roll (:func:`preroll_states`); None (full and rested) without one."""
        if self.preroll_s <= 0.0:
            return None
        n = points.shape[0]
        return preroll_states(np.full(n, self.preroll_current_a), np.full(n, self.preroll_s), points[:, 0],
                              points[:, 1], dt, cell)

    def with_prior(self, prior: HealthPrior) -> HealthEstimate:
        """This estimate's Gaussian in (w, R0) multiplied by ``prior`` (and clipped to the fit's box):
        the posterior that :func:`fit_health` returns by default."""
        mean, cov_w = combine([(np.array([self.w, self.r0]), self.cov_w), (prior.mean, prior.cov)])
        w, r = (float(x) for x in np.clip(mean, _LO[:2], _HI[:2]))
        cov_w = 0.5 * (cov_w + cov_w.T)
        return replace(self, q_max=Q_REF_C / w, r0=r, cov=_cov_qr(w, cov_w), cov_w=cov_w)

    def sigma_points(self, scale: float = 1.0) -> np.ndarray:
        """(q_max C, r0 ohm) at the estimate and at +-``scale`` along each Cholesky column of
        ``cov_w``, shape [5, 2] (rows: centre, +col0, -col0, +col1, -col1), clipped to the box."""
        chol = _chol(self.cov_w)
        centre = np.array([self.w, self.r0])
        pts = [centre]
        for i in range(2):
            pts += [centre + scale * chol[:, i], centre - scale * chol[:, i]]
        return _to_qr(np.array(pts))


def _cov_qr(w: float, cov_w: np.ndarray) -> np.ndarray:
    """Covariance of (q_max C, r0 ohm) from that of (w, r0): the delta method at w."""
    t = np.array([[-Q_REF_C / w ** 2, 0.0], [0.0, 1.0]])  # d(q_max, r0) / d(w, r0)
    return t @ cov_w @ t.T


def _chol(cov: np.ndarray) -> np.ndarray:
    c = 0.5 * (cov + cov.T) + np.diag([1e-18, 1e-18])
    try:
        return np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(c)
        return vecs * np.sqrt(np.clip(vals, 0.0, None))


def _to_qr(wr: np.ndarray) -> np.ndarray:
    """(w, r0) [..., 2] -> (q_max C, r0 ohm), clipped to the box."""
    w = np.clip(wr[..., 0], *_W_BOX)
    r = np.clip(wr[..., 1], *FIT_R0_RANGE)
    return np.stack([Q_REF_C / w, r], axis=-1)


# ------------------------------------------------------------------------------------ input checks
def _array(field: str, value, ndim: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(field, "expected an array of numbers") from None
    if arr.ndim not in ndim or arr.shape[-1] == 0:
        shapes = " or ".join({1: "[T]", 2: "[B, T]"}[d] for d in ndim)
        raise InputError(field, f"expected shape {shapes} with T >= 1, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(field, "contains NaN or inf; every sample must be finite")
    return arr


def check_context(current_a, voltage_v, dt_s: float, ndim: tuple[int, ...] = (1,),
                  names: tuple[str, str] = ("current_a", "voltage_v")) -> tuple[np.ndarray, np.ndarray, float]:
    """Validated (current A, voltage V, dt s) of a context; :class:`InputError` naming the field."""
    dt = check_range("dt_s", dt_s, *DT_RANGE, " s")
    cur = _array(names[0], current_a, ndim)
    volt = _array(names[1], voltage_v, ndim)
    if np.any(np.abs(cur) > CURRENT_LIMIT_A):
        raise InputError(names[0], f"|current| must be <= {CURRENT_LIMIT_A:g} A, got {np.abs(cur).max():g}")
    if np.any((volt < 0.0) | (volt > 5.0)):
        raise InputError(names[1], "voltages must be in [0, 5] V")
    if cur.shape != volt.shape:
        raise InputError(names[1], f"shape {volt.shape} does not match {names[0]} {cur.shape}")
    if cur.shape[-1] * dt < MIN_CONTEXT_S - 1e-9:
        raise InputError(names[0], f"needs at least {MIN_CONTEXT_S:g} s of context, got "
                         f"{cur.shape[-1] * dt:g} s ({cur.shape[-1]} samples at {dt:g} s)")
    return cur, volt, dt


def _check_noise(noise_v) -> float | None:
    if noise_v is None:
        return None
    return check_range("noise_v", noise_v, 0.0, 1.0, " V")


# --------------------------------------------------------------------------------------- the fit
def preroll_states(current_a: np.ndarray, preroll_s: np.ndarray, q_max: np.ndarray, r0: np.ndarray, dt: float,
                   cell: CellParameters = DEFAULT_CELL) -> BatteryState:
    """State of each of N cells (q_max C, r0 ohm, [N]) after ``preroll_s`` (s, [N], continuous, >= 0) of
    constant ``current_a`` (A, [N]) from full charge: the explicit-Euler states at whole steps of
    ``dt``, interpolated linearly in between."""
    q = np.asarray(q_max, float)
    p = np.maximum(np.asarray(preroll_s, float), 0.0) / dt
    x0 = full_charge(q, cell)
    n = int(math.ceil(p.max() - 1e-9)) if p.size else 0
    if n == 0:
        return x0
    _, seq = integrate_current(np.repeat(np.asarray(current_a, float)[:, None], n, axis=1), x0, cell.q_total(q),
                               np.asarray(r0, float), dt, cell)
    arr = np.concatenate([x0.as_array()[:, None, :], np.stack([seq[k] for k in STATE_NAMES], axis=-1)], axis=1)
    lo = np.floor(p).astype(int)
    hi = np.minimum(lo + 1, n)
    frac = (p - lo)[:, None]
    rows = np.arange(q.size)
    return BatteryState.from_array(arr[rows, lo] * (1.0 - frac) + arr[rows, hi] * frac)


def _simulate_pts(current: np.ndarray, pts: np.ndarray, i0: np.ndarray | None, dt: float,
                  initial_state: BatteryState | None, cell: CellParameters, eod_v: float = CURVE_CUTOFF_V):
    """Voltage [N, T] and valid [N, T] for N points [N, 2] (w, r0) or [N, 3] (w, r0, pre-roll s; with the
    pre-roll current i0 [N], A) under current [N, T]."""
    q, r = Q_REF_C / pts[:, 0], np.clip(pts[:, 1], 0.0, None)
    state = initial_state
    if pts.shape[1] == 3:
        with np.errstate(all="ignore"):
            state = preroll_states(i0, pts[:, 2], q, r, dt, cell)
    res = simulate(np.broadcast_to(current, (pts.shape[0], current.shape[-1])), dt, q, r, eod_v=eod_v,
                   initial_state=state, cell=cell)
    return res.voltage_v, res.valid


def _start(cur: np.ndarray, volt: np.ndarray, dt: float, state, cell,
           obs: np.ndarray | None = None, ws=_START_W) -> tuple[np.ndarray, np.ndarray]:
    """Coarse start (w, r0) [B, 2] and its mean squared residual [B] (V^2): each w of ``ws`` with R0
    solved in closed form (the voltage is linear in R0 up to the weak thermal coupling), best kept.
    ``obs`` [B, T]: the samples that count (default all)."""
    b = cur.shape[0]
    ws, start_r0 = _start_grid(cell, ws)
    nw, nr = len(ws), len(start_r0)
    grid = np.array([(w, r) for w in ws for r in start_r0])  # [nw * nr, 2]
    pts = np.tile(grid, (b, 1))
    v, ok = _simulate_pts(np.repeat(cur, nw * nr, axis=0), pts, None, dt, _rep_state(state, nw * nr), cell)
    v = v.reshape(b, nw, nr, -1)
    ok = ok.reshape(b, nw, nr, -1).all(axis=2)
    if obs is not None:
        ok = ok & obs[:, None, :]
    ra, rb = start_r0
    slope = (v[:, :, 1] - v[:, :, 0]) / (rb - ra)  # dV/dR0 [b, nw, T]
    err = (volt[:, None, :] - v[:, :, 0]) * ok
    s = slope * ok
    r_star = ra + (s * err).sum(-1) / np.maximum((s * s).sum(-1), 1e-30)
    r_star = np.clip(r_star, *FIT_R0_RANGE)
    resid = err - s * (r_star - ra)[..., None]
    cost = (resid ** 2).sum(-1) / np.maximum(ok.sum(-1), 1)
    cost = np.where(ok.sum(-1) >= 2, cost, np.inf)
    k = np.argmin(cost, axis=1)
    return np.column_stack([np.asarray(ws)[k], r_star[np.arange(b), k]]), cost[np.arange(b), k]


def _rep_state(state: BatteryState | None, n: int) -> BatteryState | None:
    """Repeat each row of a batched state n times (None stays None)."""
    if state is None:
        return None
    return BatteryState.from_array(np.repeat(state.as_array(), n, axis=0))


def _eval(cur: np.ndarray, volt: np.ndarray, pts: np.ndarray, i0: np.ndarray | None, dt: float, state, cell,
          obs: np.ndarray | None = None):
    """Residuals [B, T], Jacobian dV/dparams [B, T, P] and mask [B, T] at points [B, P]; ``obs``
    [B, T]: the samples that count (default all)."""
    b, n_par = pts.shape
    m = n_par + 1
    trial = np.repeat(pts, m, axis=0)
    for k in range(n_par):
        trial[k + 1::m, k] += _H[k]
    v, ok = _simulate_pts(np.repeat(cur, m, axis=0), trial, None if i0 is None else np.repeat(i0, m), dt,
                          _rep_state(state, m), cell)
    v = v.reshape(b, m, -1)
    mask = ok.reshape(b, m, -1).all(axis=1)
    if obs is not None:
        mask = mask & obs
    jac = np.stack([(v[:, k + 1] - v[:, 0]) / _H[k] for k in range(n_par)], axis=-1)
    resid = (volt - v[:, 0]) * mask
    return resid, jac * mask[..., None], mask


def _lm(cur: np.ndarray, volt: np.ndarray, dt: float, state: BatteryState | None, cell: CellParameters,
        start: np.ndarray, i0: np.ndarray | None = None):
    """Levenberg-Marquardt for all rows at once from ``start`` [B, P]: P = 2 (w, r0), or 3 (w, r0,
    pre-roll s of ``i0`` A). Returns (params [B, P], sum of squared residuals [B], Jacobian
    [B, T, P], mask of counted samples [B, T], iterations [B])."""
    b, n_par = start.shape
    lo, hi, prior_prec = _LO[:n_par], _HI[:n_par], _PRIOR_PREC[:n_par]
    pts = start.copy()
    resid, jac, mask = _eval(cur, volt, pts, i0, dt, state, cell)
    cost = (resid ** 2).sum(-1)
    lam = np.full(b, 1e-3)
    iters = np.zeros(b, int)
    active = np.arange(b)
    eye = np.eye(n_par)[None]
    for _ in range(MAX_ITER):
        if active.size == 0:
            break
        j, r = jac[active], resid[active]
        jtj = np.einsum("bti,btj->bij", j, j)
        jtr = np.einsum("bti,bt->bi", j, r)
        n_ok = np.maximum(mask[active].sum(-1), n_par + 1)
        sig2 = np.maximum(cost[active] / (n_ok - n_par), NOISE_FLOOR_V ** 2)
        prior = prior_prec[None, :] * sig2[:, None]  # the weak prior, in units of the data term
        a = jtj + eye * (prior + lam[active, None] * np.diagonal(jtj, axis1=1, axis2=2))[:, :, None]
        g = jtr - prior * (pts[active] - 0.5 * (lo + hi))
        step = np.linalg.solve(a, g[..., None])[..., 0]
        trial = np.clip(pts[active] + step, lo, hi)
        r_t, j_t, m_t = _eval(cur[active], volt[active], trial, None if i0 is None else i0[active], dt,
                              state[active] if state is not None else None, cell)
        c_t = (r_t ** 2).sum(-1)
        better = c_t <= cost[active]
        acc = active[better]
        moved = trial - pts[active]
        gain = np.einsum("bi,bij,bj->b", moved, jtj, moved)  # squared voltage change of the step
        pts[acc], resid[acc], jac[acc], mask[acc], cost[acc] = trial[better], r_t[better], j_t[better], \
            m_t[better], c_t[better]
        lam[active] = np.where(better, np.maximum(lam[active] * 0.3, 1e-9), lam[active] * 10.0)
        iters[active] += 1
        done = (gain < 1e-4 * sig2) | (lam[active] > 1e6)
        active = active[~done]
    return pts, cost, jac, mask, iters


def _prepend_preroll(cur: np.ndarray, volt: np.ndarray, steps: np.ndarray, i0: np.ndarray):
    """Rows [B, K + T] with ``steps`` samples of ``i0`` (A) before each log, after leading zeros (a
    rested full cell is unchanged by them), K = max steps; the mask of the log's samples."""
    b, t = cur.shape
    k = int(steps.max())
    c = np.zeros((b, k + t))
    v = np.repeat(volt[:, :1], k + t, axis=1)
    for r in range(b):
        c[r, k - steps[r]:k] = i0[r]
    c[:, k:] = cur
    v[:, k:] = volt
    obs = np.zeros((b, k + t), bool)
    obs[:, k:] = True
    return c, v, obs


def _search_preroll(cur: np.ndarray, volt: np.ndarray, dt: float, cell: CellParameters):
    """Start of the pre-roll fit per row: the whole-step pre-roll among :data:`PREROLL_CANDIDATES_S`
    with the least coarse residual (q_max 8125 or 5417 C for the NASA fleet, R0 in closed form) on the first
    :data:`PREROLL_WINDOW_S` s, and the coarse (w, r0) there. Returns (steps [B], (w, r0) [B, 2])."""
    b = cur.shape[0]
    w = min(cur.shape[1], int(math.ceil(PREROLL_WINDOW_S / dt)))
    cands = np.unique(np.round(np.asarray(PREROLL_CANDIDATES_S) / dt).astype(int))
    nc = cands.size
    c, v, obs = _prepend_preroll(np.repeat(cur[:, :w], nc, axis=0), np.repeat(volt[:, :w], nc, axis=0),
                                 np.tile(cands, b), np.repeat(cur[:, 0], nc))
    _, cost = _start(c, v, dt, None, cell, obs, ws=(0.8, 1.2))
    best = cands[np.argmin(cost.reshape(b, nc), axis=1)]
    c, v, obs = _prepend_preroll(cur[:, :w], volt[:, :w], best, cur[:, 0])
    wr, _ = _start(c, v, dt, None, cell, obs)
    return best, wr


def fit_health_batch(current_a, voltage_v, dt_s: float = 1.0, noise_v: float | None = None,
                     initial_state: BatteryState | None = None, start: str = "auto",
                     cell: CellParameters = DEFAULT_CELL, prior: bool | HealthPrior = True) -> list[HealthEstimate]:
    """Fit (q_max, R0) to each of B contexts of one length; see :func:`fit_health`.

    :param current_a: measured per-cell current (A), shape [B, T], from the log's first sample.
    :param voltage_v: measured voltage (V), shape [B, T].
    :return: one :class:`HealthEstimate` per row.
    """
    cur, volt, dt = check_context(current_a, voltage_v, dt_s, ndim=(1, 2))
    noise = _check_noise(noise_v)
    if start not in ("auto", "full"):
        raise InputError("start", f"{start!r} is not allowed; use 'auto' or 'full'")
    cur, volt = np.atleast_2d(cur), np.atleast_2d(volt)
    if initial_state is not None and not isinstance(initial_state, BatteryState):
        raise InputError("initial_state", "expected a BatteryState (e.g. a result's final_state)")
    if initial_state is not None and initial_state.batch_size not in (1, cur.shape[0]):
        raise InputError("initial_state", f"batch {initial_state.batch_size} does not match {cur.shape[0]}")
    if initial_state is not None and initial_state.batch_size == 1 and cur.shape[0] > 1:
        initial_state = _rep_state(initial_state, cur.shape[0])
    if not isinstance(prior, (bool, HealthPrior)):
        raise InputError("prior", "expected True (the cell type's fleet prior), False or a HealthPrior")
    known = fleet_prior(cell) if prior is True else (prior or None)
    b = cur.shape[0]
    preroll = np.zeros(b)
    with np.errstate(all="ignore"):
        wr0, _ = _start(cur, volt, dt, initial_state, cell)
        wr, cost, jac, mask, iters = _lm(cur, volt, dt, initial_state, cell, wr0)
        n_par = np.full(b, 2)
        prec_full: dict[int, np.ndarray] = {}
        if start == "auto" and initial_state is None:
            # Logs under load at the first sample, unless the fit from full charge is already exact.
            exact = cost / np.maximum(mask.sum(-1), 1) < (0.1 * NOISE_FLOOR_V) ** 2
            under = np.where((np.abs(cur[:, 0]) >= REST_CURRENT_A) & ~exact)[0]
            if under.size:
                steps, wr_s = _search_preroll(cur[under], volt[under], dt, cell)
                alt = under[steps > 0]
                if alt.size:  # fit (w, r0, pre-roll) for those rows; keep it where it fits significantly better
                    start3 = np.column_stack([wr_s[steps > 0], steps[steps > 0] * dt])
                    p3, c3, j3, m3, it3 = _lm(cur[alt], volt[alt], dt, None, cell, start3, i0=cur[alt, 0])
                    sig2 = np.maximum(c3 / np.maximum(m3.sum(-1) - 3, 1), NOISE_FLOOR_V ** 2)
                    win = (cost[alt] - c3) / sig2 > PREROLL_CHI2
                    for k, row in enumerate(alt):
                        if win[k]:
                            wr[row], cost[row], mask[row] = p3[k, :2], c3[k], m3[k]
                            iters[row] += it3[k]
                            preroll[row] = p3[k, 2]
                            n_par[row] = 3
                            prec_full[row] = np.einsum("ti,tj->ij", j3[k], j3[k])
        n_ok = np.maximum(mask.sum(-1), 4)
        rms = np.sqrt(cost / n_ok)
        sig = np.sqrt(np.maximum(cost / (n_ok - n_par), NOISE_FLOOR_V ** 2)) if noise is None else \
            np.full(b, max(noise, NOISE_FLOOR_V))
        jtj = np.einsum("bti,btj->bij", jac, jac)
    out = []
    for k in range(b):
        if n_par[k] == 3:  # the (w, r0) marginal of the 3-parameter Laplace covariance
            cov3 = np.linalg.inv(prec_full[k] / sig[k] ** 2 + np.diag(_PRIOR_PREC))
            cw = cov3[:2, :2]
        else:
            cw = np.linalg.inv(jtj[k] / sig[k] ** 2 + np.diag(_PRIOR_PREC[:2]))
        w, r = float(wr[k, 0]), float(wr[k, 1])
        cw = 0.5 * (cw + cw.T)
        est = HealthEstimate(q_max=Q_REF_C / w, r0=r, cov=_cov_qr(w, cw), noise_v=float(sig[k]),
                             n_samples=int(mask[k].sum()), cov_w=cw, rms_residual_v=float(rms[k]),
                             iterations=int(iters[k]), preroll_s=float(preroll[k]),
                             preroll_current_a=float(cur[k, 0]) if preroll[k] > 0 else 0.0)
        out.append(est if known is None else est.with_prior(known))
    return out


def fit_health(current_a, voltage_v, dt_s: float = 1.0, noise_v: float | None = None,
               eod_v: float = DEFAULT_EOD_V, initial_state: BatteryState | None = None, start: str = "auto",
               cell: CellParameters = DEFAULT_CELL, prior: bool | HealthPrior = True) -> HealthEstimate:
    """Maximum-likelihood (q_max, R0) of one cell from a measured context, with its covariance.

    :param current_a: measured per-cell current (A), shape [T], ``current_a[k]`` flowing during
        [k dt, (k+1) dt) from the log's first sample; at least :data:`MIN_CONTEXT_S` s.
    :param voltage_v: measured terminal voltage (V) at the end of each step, shape [T].
    :param dt_s: sample step (s).
    :param noise_v: voltage-noise std (V); None: estimated from the residuals. Never below
        :data:`NOISE_FLOOR_V`.
    :param eod_v: the cut-off (V) of later predictions; checked here, the fit itself uses every
        sample the model keeps above :data:`CURVE_CUTOFF_V`.
    :param initial_state: the cell's state at the log's first sample; default: see ``start``.
    :param start: where the log starts, without ``initial_state``. ``"auto"``: a log whose first
        sample draws under :data:`REST_CURRENT_A` starts full and at rest; one that starts under load
        may have begun up to 60 s into the load: unless the fit from full charge is exact, a
        third parameter, the pre-roll (0-60 s of the first logged current from full charge,
        continuous; started from the best whole step of :func:`_search_preroll`), is fitted as
        well, and kept where it lowers the chi-square by more than :data:`PREROLL_CHI2`
        (``HealthEstimate.preroll_s``; the covariance is then the (w, R0) marginal).
        ``"full"``: full and rested at the first sample.
    :param cell: the cell type's parameter set (its fleet's health range is the default prior).
    :param prior: True: the likelihood's Gaussian in (w, R0) multiplied by the fleet prior of ``cell``
        (:func:`~uam_studio.battery.health_prior.fleet_prior`); a :class:`HealthPrior`: by that one;
        False: the likelihood alone (with a weak prior as wide as the fit's box), for a caller that
        combines several fits with its own prior once.
    :raises InputError: NaN or inf, a context shorter than 20 s, mismatched lengths, a negative
        noise level, naming the field.
    """
    check_range("eod_v", eod_v, *EOD_RANGE, " V")
    cur, volt, dt = check_context(current_a, voltage_v, dt_s, ndim=(1,))
    _check_noise(noise_v)
    return fit_health_batch(cur[None], volt[None], dt, noise_v, initial_state, start, cell, prior)[0]


# ------------------------------------------------------------------------------- intervals, bands
def _check_profile(current_a, dt_s: float, level: float) -> tuple[np.ndarray, float, float]:
    dt = check_range("dt_s", dt_s, *DT_RANGE, " s")
    cur = _array("current_a", current_a, (1,))
    if np.any(np.abs(cur) > CURRENT_LIMIT_A):
        raise InputError("current_a", f"|current| must be <= {CURRENT_LIMIT_A:g} A")
    lv = check_range("level", level, 0.5, 0.999)
    return cur, dt, lv


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
    c, _, _ = _prepend_preroll(np.asarray(current, float), np.zeros_like(current, dtype=float), steps, i0)
    return c, int(steps.max())


def _start_states(estimates: list[HealthEstimate], points: np.ndarray, per: int, dt: float,
                  cell: CellParameters, initial_state: BatteryState | None) -> BatteryState | None:
    """Initial states of trajectories whose rows come in groups of ``per`` per estimate, at ``points``
    [B * per, 2] (q_max C, r0 ohm): ``initial_state`` if given (one for all, or one per estimate),
    else each estimate's pre-roll (None: all full and rested)."""
    b = len(estimates)
    if initial_state is not None:
        return _rep_state(initial_state, per) if initial_state.batch_size == b and b > 1 else initial_state
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
    chol = _chol(estimate.cov_w)
    centre = np.array([estimate.w, estimate.r0])
    d = chol @ (g / norm) if norm > 0 else np.zeros(2)
    z = two_sided_z(level)
    return _to_qr(np.array([centre - z * d, centre + z * d]))


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
    cur = _array("current_a", current_a, (1, 2))
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
                   cell: CellParameters = DEFAULT_CELL) -> tuple[float, float, float]:
    """``level`` interval of the end-of-discharge time (s) along a planned profile, physics model.

    :param estimate: a :class:`HealthEstimate` (from :func:`fit_health`).
    :param current_a: the whole per-cell current (A) from the log's t = 0, context included, [T].
    :param dt_s: sample step (s).
    :param level: central probability of the interval, in [0.5, 0.999].
    :param eod_v: cut-off (V).
    :param n_draws: None: the first-order reduction (:func:`interval_ends`: 5 sigma-point
        trajectories, then the two ends and the estimate, 8 in all); an int in [10, 10000]: quantiles
        over that many random draws (:meth:`HealthEstimate.sample`).
    :param initial_state: the state at the log's first sample, as given to :func:`fit_health`.
    :param seed: seed of the draws.
    :return: (low, median, high): time (s) from the log's first sample to the first sample below
        ``eod_v``, on ``current_a``'s grid; ``median`` at the fitted health; ``math.inf`` where the
        profile ends before the cut-off.
    """
    cur, dt, lv = _check_profile(current_a, dt_s, level)
    eod = check_range("eod_v", eod_v, *EOD_RANGE, " V")
    if not isinstance(estimate, HealthEstimate):
        raise InputError("estimate", "expected a HealthEstimate (from fit_health)")
    if n_draws is not None and not (isinstance(n_draws, (int, np.integer)) and 10 <= n_draws <= 10000):
        raise InputError("n_draws", f"{n_draws!r} is out of range; allowed None or integers in [10, 10000]")
    if n_draws is None:
        lo, med, hi = eod_intervals([estimate], cur, dt, lv, eod, initial_state, cell)
        return float(lo[0]), float(med[0]), float(hi[0])
    draws = np.vstack([[estimate.q_max, estimate.r0], estimate.sample(int(n_draws), np.random.default_rng(seed))])
    state = _start_states([estimate], draws, draws.shape[0], dt, cell, initial_state)
    v = simulate(np.broadcast_to(cur, (draws.shape[0], cur.size)), dt, draws[:, 0], draws[:, 1], eod_v=eod,
                 initial_state=state, cell=cell).voltage_v
    grid, _ = crossing_times(v, dt, eod)
    lo, hi = np.quantile(grid[1:], [(1 - lv) / 2, (1 + lv) / 2], method="inverted_cdf")
    med = float(grid[0])
    return min(float(lo), med), med, max(float(hi), med)


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

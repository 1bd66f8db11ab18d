"""The likelihood of the health fit: the physics model of a context (current in A, voltage in V)
at trial points (w, R0 in ohm[, pre-roll in s]), w = 6500 C / q_max, its residuals (V) and
finite-difference Jacobian, the coarse start, the Levenberg-Marquardt iteration, and the search for
the pre-roll of a log that starts under load.

Every sample the model keeps above :data:`~uam_studio.battery.health.estimate.CURVE_CUTOFF_V` is a
residual; the noise std (V) estimated from them is never below :data:`NOISE_FLOOR_V`. The entry
point is :func:`uam_studio.battery.health.fit.fit_health`.
"""

from __future__ import annotations

import math

import numpy as np

from uam_studio.battery.health.estimate import (
    CURVE_CUTOFF_V,
    FIT_R0_RANGE,
    PARAM_HI,
    PARAM_LO,
    PRIOR_PRECISION,
    prepend_preroll,
    preroll_states,
    rep_state,
)
from uam_studio.battery.health.prior import Q_REF_C
from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE, CellParameters
from uam_studio.battery.simulate import simulate
from uam_studio.battery.state import BatteryState

__all__ = ["NOISE_FLOOR_V", "current_noise_covariance"]

NOISE_FLOOR_V = 0.5e-3  # V: the noise std used is never below this
MAX_ITER = 30
_H = np.array([1e-4, 1e-4, 1e-2])  # finite-difference steps in (w, R0 ohm, pre-roll s)
_START_W = (0.65, 0.8, 1.0, 1.2, 1.45)  # q_max 10000, 8125, 6500, 5417, 4483 C (the NASA cell's fleet)
_START_R0 = (0.1, 0.3)  # ohm (the NASA cell's fleet, R0 up to 0.45 ohm)
# C, ohm: the fleet the start grid is written for (the paper's box: its centre, top)
_START_FLEET = (sum(PAPER_Q_RANGE) / 2, PAPER_R0_RANGE[1])
PREROLL_CANDIDATES_S = (0, 1, 2, 3, 4, 6, 8, 10, 13, 16, 20, 25, 30, 40, 50, 60)  # s: the pre-roll's start
PREROLL_WINDOW_S = 60.0  # s of the context that the pre-roll search reads


def _start_grid(cell: CellParameters, ws=_START_W) -> tuple[np.ndarray, tuple[float, float]]:
    """The coarse start's w values and R0 pair (ohm) for the cell type: the NASA grid scaled to the type's
    fleet (q_max by its centre, R0 by its top), so a cell of another size or resistance starts among its
    own kind (R0 of 0.1-0.3 ohm puts a VTC6 at 15 A below the cut-off, and then no start fits)."""
    q_scale = sum(cell.fleet_q_range) / 2 / _START_FLEET[0]
    r_scale = cell.fleet_r0_range[1] / _START_FLEET[1]
    return np.asarray(ws) / q_scale, (_START_R0[0] * r_scale, _START_R0[1] * r_scale)


def _simulate_pts(current: np.ndarray, pts: np.ndarray, i0: np.ndarray | None, dt: float,
                  initial_state: BatteryState | None, cell: CellParameters, eod_v: float = CURVE_CUTOFF_V):
    """Voltage [N, T] and valid [N, T] for N points [N, 2] (w, r0) or [N, 3] (w, r0, pre-roll s; with the
    pre-roll current i0 [N], A) under current [N, T]."""
    q, r = Q_REF_C / pts[:, 0], np.clip(pts[:, 1], 0.0, None)
    state = initial_state
    if pts.shape[1] == 3:
        assert i0 is not None, "a pre-roll point needs its pre-roll current i0"
        with np.errstate(all="ignore"):
            state = preroll_states(i0, pts[:, 2], q, r, dt, cell)
    res = simulate(np.broadcast_to(current, (pts.shape[0], current.shape[-1])), dt, q, r, eod_v=eod_v,
                   initial_state=state, cell=cell)
    return res.voltage_v, res.valid


def start_point(cur: np.ndarray, volt: np.ndarray, dt: float, state, cell,
           obs: np.ndarray | None = None, ws=_START_W) -> tuple[np.ndarray, np.ndarray]:
    """Coarse start (w, r0) [B, 2] and its mean squared residual [B] (V^2): each w of ``ws`` with R0
    solved in closed form (the voltage is linear in R0 up to the weak thermal coupling), best kept.
    ``obs`` [B, T]: the samples that count (default all)."""
    b = cur.shape[0]
    ws, start_r0 = _start_grid(cell, ws)
    nw, nr = len(ws), len(start_r0)
    grid = np.array([(w, r) for w in ws for r in start_r0])  # [nw * nr, 2]
    pts = np.tile(grid, (b, 1))
    v, ok = _simulate_pts(np.repeat(cur, nw * nr, axis=0), pts, None, dt, rep_state(state, nw * nr), cell)
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
                          rep_state(state, m), cell)
    v = v.reshape(b, m, -1)
    mask = ok.reshape(b, m, -1).all(axis=1)
    if obs is not None:
        mask = mask & obs
    jac = np.stack([(v[:, k + 1] - v[:, 0]) / _H[k] for k in range(n_par)], axis=-1)
    resid = (volt - v[:, 0]) * mask
    return resid, jac * mask[..., None], mask


def levenberg_marquardt(cur: np.ndarray, volt: np.ndarray, dt: float, state: BatteryState | None, cell: CellParameters,
        start: np.ndarray, i0: np.ndarray | None = None):
    """Levenberg-Marquardt for all rows at once from ``start`` [B, P]: P = 2 (w, r0), or 3 (w, r0,
    pre-roll s of ``i0`` A). Returns (params [B, P], sum of squared residuals [B], Jacobian
    [B, T, P], mask of counted samples [B, T], iterations [B], residuals [B, T] V)."""
    b, n_par = start.shape
    lo, hi, prior_prec = PARAM_LO[:n_par], PARAM_HI[:n_par], PRIOR_PRECISION[:n_par]
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
    return pts, cost, jac, mask, iters, resid


def search_preroll(cur: np.ndarray, volt: np.ndarray, dt: float, cell: CellParameters):
    """Start of the pre-roll fit per row: the whole-step pre-roll among :data:`PREROLL_CANDIDATES_S`
    with the least coarse residual (q_max 8125 or 5417 C for the NASA fleet, R0 in closed form) on the first
    :data:`PREROLL_WINDOW_S` s, and the coarse (w, r0) there. Returns (steps [B], (w, r0) [B, 2])."""
    b = cur.shape[0]
    w = min(cur.shape[1], int(math.ceil(PREROLL_WINDOW_S / dt)))
    cands = np.unique(np.round(np.asarray(PREROLL_CANDIDATES_S) / dt).astype(int))
    nc = cands.size
    c, v, obs = prepend_preroll(np.repeat(cur[:, :w], nc, axis=0), np.repeat(volt[:, :w], nc, axis=0),
                                 np.tile(cands, b), np.repeat(cur[:, 0], nc))
    _, cost = start_point(c, v, dt, None, cell, obs, ws=(0.8, 1.2))
    best = cands[np.argmin(cost.reshape(b, nc), axis=1)]
    c, v, obs = prepend_preroll(cur[:, :w], volt[:, :w], best, cur[:, 0])
    wr, _ = start_point(c, v, dt, None, cell, obs)
    return best, wr


CURRENT_NOISE_DRAWS = 48  # draws of the current noise propagated through the model (a fixed seed)


def current_noise_covariance(current: np.ndarray, pts: np.ndarray, i0: np.ndarray | None, dt: float,
                             state: BatteryState | None, cell: CellParameters, jac: np.ndarray, mask: np.ndarray,
                             sigma_i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What white current-sensor noise of std ``sigma_i`` [R] (A) does to least-squares fits at ``pts``
    [R, P] (w, r0[, pre-roll s of ``i0`` [R] A]) of R contexts (``current`` [R, T] A, from ``state``
    (R rows) or full; their Jacobians ``jac`` [R, T, P] and counted samples ``mask`` [R, T]): (the
    covariances [R, P, P] it adds to the parameters, the mean squares [R] (V^2) it adds to the counted
    residuals). :data:`CURRENT_NOISE_DRAWS` noise draws (one fixed-seed pattern, scaled by each row's
    std), flown on the model in one batched call for all rows; each voltage change is mapped to a
    parameter change by the linearised least squares (J^T J)^-1 J^T."""
    m = CURRENT_NOISE_DRAWS
    r, t = current.shape
    z = np.random.default_rng(0).standard_normal((m, t))
    cur = np.concatenate([current[:, None], current[:, None] + sigma_i[:, None, None] * z[None]], axis=1)
    p = np.repeat(np.asarray(pts, float), m + 1, axis=0)
    v, ok = _simulate_pts(cur.reshape(r * (m + 1), t), p, None if i0 is None else np.repeat(i0, m + 1), dt,
                          rep_state(state, m + 1), cell)
    v, ok = v.reshape(r, m + 1, t), ok.reshape(r, m + 1, t)
    n_par = jac.shape[-1]
    covs, dv2 = np.zeros((r, n_par, n_par)), np.zeros(r)
    for k in range(r):
        counted = mask[k] & ok[k].all(axis=0)
        dv = (v[k, 1:] - v[k, 0]) * counted
        j = jac[k] * counted[:, None]
        try:
            dtheta = np.linalg.solve(j.T @ j, j.T @ dv.T).T  # [m, P]
        except np.linalg.LinAlgError:
            continue
        cov = dtheta.T @ dtheta / m
        covs[k], dv2[k] = 0.5 * (cov + cov.T), float(np.sum(dv ** 2) / (m * max(counted.sum(), 1)))
    return covs, dv2

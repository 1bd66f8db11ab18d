"""A fitted cell health and what the health fit and its intervals share.

- The fit's parameter box: q_max in :data:`FIT_Q_RANGE` (C), R0 in :data:`FIT_R0_RANGE` (ohm), a
  pre-roll of up to :data:`PREROLL_MAX_S` (s); in the fit's coordinates w = 6500 C / q_max (-), in
  which the voltage is close to linear, with a weak Gaussian prior as wide as the box.
- :class:`HealthEstimate`: (q_max C, R0 ohm) with its Gaussian in (w, R0), its draws, its sigma
  points and its product with a fleet prior (:class:`~uam_studio.battery.health.prior.HealthPrior`).
- The checks of a context (current in A, voltage in V, step in s; at least :data:`MIN_CONTEXT_S` s).
- The pre-roll of a log that starts under load: the state after it (:func:`preroll_states`) and the
  profiles with it in front (:func:`prepend_preroll`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, combine, hold_to_fleet
from uam_studio.battery.health.quality import FLAG_OUTSIDE_FLEET
from uam_studio.battery.parameters import DEFAULT_CELL, CellParameters
from uam_studio.battery.simulate import CURRENT_LIMIT_A, DT_RANGE, EOD_RANGE
from uam_studio.battery.solver import integrate_current
from uam_studio.battery.state import STATE_NAMES, BatteryState, full_charge
from uam_studio.errors import InputError, check_range
from uam_studio.flight.context import TAKEOFF_CONTEXT_S

__all__ = ["CURVE_CUTOFF_V", "FIT_Q_RANGE", "FIT_R0_RANGE", "MIN_CONTEXT_S", "PREROLL_MAX_S", "HealthEstimate",
           "clip_to_box",
           "check_context", "preroll_states"]

MIN_CONTEXT_S = float(TAKEOFF_CONTEXT_S)  # s: shortest context accepted: the take-off context
FIT_Q_RANGE = (2000.0, 16000.0)  # C: box of the estimate and of its draws
FIT_R0_RANGE = (0.0, 1.0)  # ohm
CURVE_CUTOFF_V = EOD_RANGE[0]  # V: contexts and bands are simulated down to here
PREROLL_MAX_S = 60.0  # s: longest load before the log's first sample that the fit looks for
_W_BOX = (Q_REF_C / FIT_Q_RANGE[1], Q_REF_C / FIT_Q_RANGE[0])
PARAM_LO = np.array([_W_BOX[0], FIT_R0_RANGE[0], 0.0])
PARAM_HI = np.array([_W_BOX[1], FIT_R0_RANGE[1], PREROLL_MAX_S])
PRIOR_PRECISION = 1.0 / (PARAM_HI - PARAM_LO) ** 2  # weak prior: std = box width, in (w, R0, pre-roll)


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
    :param residual_autocorr: lag-1 autocorrelation of the fit's residuals (-).
    :param discrepancy_factor: the model-discrepancy factor (>= 1) the likelihood's covariance was
        multiplied by (:mod:`uam_studio.battery.health.quality`).
    :param flags: :data:`~uam_studio.battery.health.quality.FLAG_MISFIT` and/or
        :data:`~uam_studio.battery.health.quality.FLAG_OUTSIDE_FLEET`; empty for a context that fits.
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
    residual_autocorr: float = 0.0
    discrepancy_factor: float = 1.0
    flags: tuple[str, ...] = ()

    @property
    def flagged(self) -> bool:
        """Whether the fit is flagged (:mod:`uam_studio.battery.health.quality`): a context that does not
        fit the model, or a cell outside its type's fleet range."""
        return bool(self.flags)

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
        z = rng.standard_normal((n, 2)) @ cholesky_factor(self.cov_w).T
        return w_to_qr(np.array([self.w, self.r0]) + z)

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
        the posterior that :func:`~uam_studio.battery.health.fit.fit_health` returns by default. An estimate
        flagged outside the fleet's range (:data:`~uam_studio.battery.health.quality.FLAG_OUTSIDE_FLEET`)
        on the optimistic side (a better cell than any of its fleet) is not trusted over its fleet:
        :func:`~uam_studio.battery.health.prior.hold_to_fleet`."""
        mean, cov_w = combine([(np.array([self.w, self.r0]), self.cov_w), (prior.mean, prior.cov)])
        if FLAG_OUTSIDE_FLEET in self.flags:
            # the flag has decided (at face value): hold every component beyond the fleet's optimistic edge
            mean, cov_w = hold_to_fleet(mean, cov_w, np.array([self.w, self.r0]), self.cov_w, prior, 0.0)
        w, r = (float(x) for x in np.clip(mean, PARAM_LO[:2], PARAM_HI[:2]))
        cov_w = 0.5 * (cov_w + cov_w.T)
        return replace(self, q_max=Q_REF_C / w, r0=r, cov=cov_qr(w, cov_w), cov_w=cov_w)

    def sigma_points(self, scale: float = 1.0) -> np.ndarray:
        """(q_max C, r0 ohm) at the estimate and at +-``scale`` along each Cholesky column of
        ``cov_w``, shape [5, 2] (rows: centre, +col0, -col0, +col1, -col1), clipped to the box."""
        chol = cholesky_factor(self.cov_w)
        centre = np.array([self.w, self.r0])
        pts = [centre]
        for i in range(2):
            pts += [centre + scale * chol[:, i], centre - scale * chol[:, i]]
        return w_to_qr(np.array(pts))


def cov_qr(w: float, cov_w: np.ndarray) -> np.ndarray:
    """Covariance of (q_max C, r0 ohm) from that of (w, r0): the delta method at w."""
    t = np.array([[-Q_REF_C / w ** 2, 0.0], [0.0, 1.0]])  # d(q_max, r0) / d(w, r0)
    return t @ cov_w @ t.T


def cholesky_factor(cov: np.ndarray) -> np.ndarray:
    c = 0.5 * (cov + cov.T) + np.diag([1e-18, 1e-18])
    try:
        return np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(c)
        return vecs * np.sqrt(np.clip(vals, 0.0, None))


def clip_to_box(wr: np.ndarray) -> np.ndarray:
    """(w, r0 ohm) [..., 2] clipped to the fit's box (w = Q_REF_C / q_max)."""
    wr = np.asarray(wr, dtype=float)
    return np.stack([np.clip(wr[..., 0], *_W_BOX), np.clip(wr[..., 1], *FIT_R0_RANGE)], axis=-1)


def w_to_qr(wr: np.ndarray) -> np.ndarray:
    """(w, r0) [..., 2] -> (q_max C, r0 ohm), clipped to the box."""
    box = clip_to_box(wr)
    return np.stack([Q_REF_C / box[..., 0], box[..., 1]], axis=-1)


# ------------------------------------------------------------------------------------ input checks
def checked_array(field: str, value, ndim: tuple[int, ...]) -> np.ndarray:
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
    cur = checked_array(names[0], current_a, ndim)
    volt = checked_array(names[1], voltage_v, ndim)
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


def check_noise(noise_v) -> float | None:
    if noise_v is None:
        return None
    return check_range("noise_v", noise_v, 0.0, 1.0, " V")


# ------------------------------------------------------------------------------------ the pre-roll
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


def rep_state(state: BatteryState | None, n: int) -> BatteryState | None:
    """Repeat each row of a batched state n times (None stays None)."""
    if state is None:
        return None
    return BatteryState.from_array(np.repeat(state.as_array(), n, axis=0))


def prepend_preroll(cur: np.ndarray, volt: np.ndarray, steps: np.ndarray, i0: np.ndarray):
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

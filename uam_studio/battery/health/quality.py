"""Does a context fit the model? The health fit's error terms beyond white sensor noise, and its flags.

The health fit's Laplace covariance sigma^2 (J^T J)^-1 assumes the model is right, its input exact and
the residuals white noise of std sigma. Two terms widen it where that does not hold:

- **Current-sensor noise** (errors in variables): the measured current is the model's input, so its
  noise reaches the voltage through the model's lags and moves the fit. Its std is read off the
  current itself (:func:`current_noise_a`), and its effect on the parameters is propagated through the
  model (:func:`~uam_studio.battery.health.likelihood.current_noise_covariance`); it is added to the
  sensor-noise term (whose std then excludes what the current noise explains).
- **Model discrepancy** (:func:`not_white`, :func:`hac_covariance`, :func:`excess_factor`): where the
  residuals are still not white noise of the assumed std (a significant lag-1 autocorrelation,
  rho sqrt(n) > :data:`WHITE_Z`, a one-sided 1% test; or, with a stated sensor noise, a chi-square
  above its (1 - :data:`NOISE_P`) quantile) and their RMS is above the fit's noise floor, the
  heteroscedasticity-and-autocorrelation-consistent (Newey-West) covariance from the context's own
  residuals and Jacobian (Bartlett weights up to the lag of Andrews' AR(1) rule,
  :func:`andrews_bandwidth`) is compared with the covariance above; the whole covariance is multiplied
  by its largest ratio in any direction, when that is above 1 (``HealthEstimate.discrepancy_factor``).

Flags (:data:`FLAG_MISFIT`, :data:`FLAG_OUTSIDE_FLEET`; see :func:`fit_flags`): a context that does
not fit the model (the discrepancy factor is above 1), and a likelihood estimate more than
:data:`FLEET_Z` std (at face value: its covariance without the discrepancy factor) outside the cell
type's fleet range in q_max or R0
(:func:`~uam_studio.battery.health.prior.disagrees`: a cell unlike its fleet, or a model that does not
describe it). The glossary explains them; a cell better than any of its fleet is held to the fleet's
best (:func:`~uam_studio.battery.health.prior.hold_to_fleet`).
"""

from __future__ import annotations

import numpy as np

from uam_studio.risk import ONE_PERCENT_Z

__all__ = ["FLAG_MISFIT", "FLAG_OUTSIDE_FLEET", "FLEET_Z", "MAX_FIT_RMS_V", "MAX_RHO", "WHITE_Z", "andrews_bandwidth",
           "current_noise_a", "describe_flags", "excess_factor", "fit_flags", "hac_covariance", "not_white",
           "residual_autocorrelation"]

WHITE_Z = ONE_PERCENT_Z  # rho sqrt(n) above this: the residuals are not white (one-sided, p = 0.01)
MAX_RHO = 0.99  # rho is capped here in the bandwidth rule
NOISE_P = 0.01  # significance of residuals above a stated sensor noise
MAX_FIT_RMS_V = 0.5  # V: residuals above this are not a reading of the cell type (units, cell or sensor)
FLEET_Z = 2.0  # std of the likelihood estimate outside the fleet range that flags it
FLAG_MISFIT = "misfit"
FLAG_OUTSIDE_FLEET = "outside fleet range"
_FLAG_TEXT = {
    FLAG_MISFIT: "the context does not fit the model (its residuals are correlated or above the sensor noise): "
                 "the interval is widened by what they imply",
    FLAG_OUTSIDE_FLEET: "the fit puts this cell outside its type's fleet range: an unusual cell or a model "
                        "that does not describe it; a cell better than any of its fleet is planned as the "
                        "fleet's best",
}


def residual_autocorrelation(residual_v: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Lag-1 autocorrelation (-) of each row of residuals [B, T] (V) over its counted samples
    (``mask`` [B, T], default all; uncounted samples are skipped, not zeroed); 0 for a row with fewer
    than 3 counted samples or no variance."""
    r = np.atleast_2d(np.asarray(residual_v, float))
    m = np.ones(r.shape, bool) if mask is None else np.atleast_2d(np.asarray(mask, bool))
    out = np.zeros(r.shape[0])
    for k in range(r.shape[0]):
        x = r[k, m[k]]
        if x.size < 3:
            continue
        x = x - x.mean()
        den = float(np.dot(x, x))
        out[k] = float(np.dot(x[:-1], x[1:])) / den if den > 0 else 0.0
    return out


def not_white(rho: np.ndarray, n: np.ndarray, sse_v2: np.ndarray | None = None, dof: np.ndarray | None = None,
              noise_v: float | None = None) -> np.ndarray:
    """Whether residuals are not white noise of the assumed std: lag-1 autocorrelation ``rho`` with
    rho sqrt(n) > :data:`WHITE_Z`, or (with a stated ``noise_v`` V) a sum of squares ``sse_v2`` (V^2)
    whose chi-square against it, with ``dof`` degrees of freedom, is above its (1 - :data:`NOISE_P`)
    quantile."""
    rho = np.asarray(rho, float)
    out = rho * np.sqrt(np.maximum(np.asarray(n, float), 1.0)) > WHITE_Z
    if noise_v is not None and sse_v2 is not None and dof is not None:
        from scipy.special import chdtri  # chi-square quantile, 1 - p: scipy.stats's chi2.ppf(1 - p, d)

        d = np.maximum(np.asarray(dof, float), 1.0)
        out = out | (np.asarray(sse_v2, float) / noise_v ** 2 > chdtri(d, NOISE_P))
    return out


def andrews_bandwidth(rho: float, n: int) -> int:
    """Bartlett-kernel lag truncation (samples) for ``n`` residuals with lag-1 autocorrelation ``rho``:
    Andrews' (1991) AR(1) plug-in, 1.1447 (alpha n)^(1/3), alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2),
    rho capped at :data:`MAX_RHO`; between 1 and n - 1."""
    r = min(max(float(rho), 0.0), MAX_RHO)
    alpha = 4.0 * r ** 2 / ((1.0 - r) ** 2 * (1.0 + r) ** 2)
    return int(min(max(np.ceil(1.1447 * (alpha * n) ** (1.0 / 3.0)), 1), max(n - 1, 1)))


def hac_covariance(jac: np.ndarray, residual_v: np.ndarray, mask: np.ndarray, rho: float) -> np.ndarray | None:
    """The HAC (Newey-West) covariance A^-1 S A^-1 of a least-squares fit's parameters: ``jac`` [T, P]
    (V per parameter unit), ``residual_v`` [T] (V), ``mask`` [T] (the counted samples), ``rho`` the
    residuals' lag-1 autocorrelation (for the bandwidth, :func:`andrews_bandwidth`). None when the
    counted samples do not determine the parameters or hold a value that is not a number."""
    m = np.asarray(mask, bool)
    j = np.asarray(jac, float)[m]
    r = np.asarray(residual_v, float)[m]
    n = r.size
    if n <= j.shape[1] or not (np.all(np.isfinite(j)) and np.all(np.isfinite(r))):
        return None
    u = j * r[:, None]
    s = u.T @ u
    lags = andrews_bandwidth(rho, n)
    for k in range(1, lags + 1):
        g = u[k:].T @ u[:-k]
        s += (1.0 - k / (lags + 1.0)) * (g + g.T)
    try:
        a_inv = np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        return None
    out = a_inv @ s @ a_inv
    return 0.5 * (out + out.T) if np.all(np.isfinite(out)) else None


def excess_factor(reference_cov: np.ndarray, other_cov: np.ndarray | None) -> float:
    """Largest ratio (>= 1), in any direction of the parameters, of ``other_cov`` to ``reference_cov``
    (the largest generalised eigenvalue); 1 without ``other_cov`` or where it is not finite."""
    from scipy.linalg import eigh

    if other_cov is None:
        return 1.0
    ref = np.asarray(reference_cov, float)
    ref = ref + np.eye(ref.shape[0]) * 1e-12 * max(np.trace(ref), 1e-300)
    try:
        lam = float(eigh(np.asarray(other_cov, float), ref, eigvals_only=True)[-1])
    except (np.linalg.LinAlgError, ValueError):
        return 1.0
    return max(1.0, lam) if np.isfinite(lam) else 1.0


def current_noise_a(current_a: np.ndarray) -> float:
    """The current sensor's noise std (A) read off a measured current [T]: 1.4826 median |first
    difference| / sqrt(2) (robust: the steps between flight phases are a few samples of many); 0 for
    fewer than 3 samples."""
    c = np.asarray(current_a, float)
    if c.size < 3:
        return 0.0
    return float(1.4826 * np.median(np.abs(np.diff(c))) / np.sqrt(2.0))


def fit_flags(misfit: bool, outside: bool) -> tuple[str, ...]:
    """The flags of a fit, in a fixed order."""
    return tuple(f for f, on in ((FLAG_MISFIT, misfit), (FLAG_OUTSIDE_FLEET, outside)) if on)


def describe_flags(flags: tuple[str, ...]) -> str:
    """One sentence per flag (empty for none)."""
    return " ".join(f"{f}: {_FLAG_TEXT[f]}." for f in flags if f in _FLAG_TEXT)


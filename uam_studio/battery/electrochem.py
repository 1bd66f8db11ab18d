"""Equations of the Daigle & Kulkarni (2013) model, vectorised over any array shape.

Written from the published equations:
* bulk-to-surface diffusion of Li charge in each electrode;
* Butler-Volmer surface overpotentials and an ohmic drop, each a first-order lag;
* equilibrium electrode potentials from the Nernst term plus a Redlich-Kister
  expansion (13 terms);
* a lumped thermal state heated by the overpotential losses and cooled towards
  ambient.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from uam_studio.battery.parameters import FARADAY, GAS_CONSTANT, CellParameters

_X_EPS = 1e-12  # mole fractions are clipped into (eps, 1-eps); only reached after EOD


@lru_cache(maxsize=8)
def _rk_polynomial(coeffs: tuple[float, ...]) -> tuple[float, ...]:
    """Coefficients (highest power first) of the Redlich-Kister sum as a polynomial in z = 2x - 1.

    With 2x(1-x) = (1 - z^2)/2, term k >= 1 is (1 + k/2) z^(k+1) - (k/2) z^(k-1) and
    term 0 is z, so the whole sum is one polynomial evaluated by Horner's rule.
    """
    poly = np.zeros(len(coeffs) + 1)  # poly[p] multiplies z^p
    for k, a in enumerate(coeffs):
        if k == 0:
            poly[1] += a
        else:
            poly[k + 1] += a * (1.0 + k / 2.0)
            poly[k - 1] -= a * (k / 2.0)
    return tuple((poly / FARADAY)[::-1])


def redlich_kister(x: np.ndarray, coeffs: tuple[float, ...]) -> np.ndarray:
    """Sum over k of A_k/F * ((2x-1)^(k+1) - 2 k x (1-x) (2x-1)^(k-1)) (V)."""
    poly = _rk_polynomial(tuple(coeffs))
    z = 2.0 * x - 1.0
    while len(poly) > 1 and poly[0] == 0.0:
        poly = poly[1:]
    total = np.full_like(z, poly[0])
    for c in poly[1:]:
        total *= z
        if c != 0.0:
            total += c
    return total


def surface_fractions(qns, qps, q_surface_max):
    """Surface mole fractions (xnS, xpS), clipped into the open interval (0, 1)."""
    xns = np.clip(qns / q_surface_max, _X_EPS, 1.0 - _X_EPS)
    xps = np.clip(qps / q_surface_max, _X_EPS, 1.0 - _X_EPS)
    return xns, xps


def equilibrium_voltage(xns, xps, tb, cell: CellParameters) -> np.ndarray:
    """Open-circuit voltage Vep - Ven (V) at surface fractions xns, xps and temperature tb (K)."""
    rt_f = GAS_CONSTANT * tb / FARADAY
    ven = cell.u0n + rt_f * np.log((1.0 - xns) / xns) + redlich_kister(xns, cell.an)
    vep = cell.u0p + rt_f * np.log((1.0 - xps) / xps) + redlich_kister(xps, cell.ap)
    return vep - ven


def overpotential_gains(current_a, xns, xps, cell: CellParameters, rate_factor=1.0):
    """Steady-state surface overpotentials per kelvin, (R/(F alpha)) asinh(J / 2 J0) (V/K).

    Multiply by the temperature (K) to get the nominal Vsn and Vsp. ``rate_factor`` scales both rate
    constants (:meth:`CellParameters.rate_factor` of the cell's temperature).
    """
    c = GAS_CONSTANT / FARADAY / cell.alpha
    jn0 = cell.kn * rate_factor * ((1.0 - xns) * xns) ** cell.alpha
    jp0 = cell.kp * rate_factor * ((1.0 - xps) * xps) ** cell.alpha
    gn = c * np.arcsinh((current_a / cell.sn) / (2.0 * jn0))
    gp = c * np.arcsinh((current_a / cell.sp) / (2.0 * jp0))
    return gn, gp

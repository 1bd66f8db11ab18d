"""Equations of the Daigle & Kulkarni (2013) model: the one home of the cell model's arithmetic.

Written from the published equations:
* bulk-to-surface diffusion of Li charge in each electrode;
* Butler-Volmer surface overpotentials and an ohmic drop, each a first-order lag;
* equilibrium electrode potentials from the Nernst term plus a Redlich-Kister
  expansion (13 terms);
* a lumped thermal state heated by the overpotential losses and cooled towards
  ambient;
* optional Arrhenius temperature factors of R0 and of the rate constants.

Every function here is element-wise: it takes numpy arrays of any shape (the numpy
solvers in :mod:`uam_studio.battery.solver`) or plain floats, and each is registered with
numba (``register_jitable``), so the compiled kernel (:mod:`uam_studio.battery.kernel`)
calls these same functions on one trajectory's scalars. The cell's numbers reach them as
:class:`ModelConstants` (:func:`model_constants` of a
:class:`~uam_studio.battery.parameters.CellParameters`), a named tuple numba can read.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit
from numba.extending import register_jitable

from uam_studio.battery.parameters import FARADAY, GAS_CONSTANT, CellParameters, arrhenius

_X_EPS = 1e-12  # mole fractions are clipped into (eps, 1-eps); only reached after EOD


class ModelConstants(NamedTuple):
    """The numbers of one :class:`CellParameters` as the equations read them (units as there).

    ``an_poly`` and ``ap_poly`` are the Redlich-Kister sums as polynomials in z = 2x - 1, highest power
    first, divided by the Faraday constant (V); ``bv_gain`` is R / (F alpha) (V/K) and ``rt_f`` R / F (V/K).
    """

    vol_s_fraction: float
    inv_vb: float  # 1/m^3
    inv_vs: float  # 1/m^3
    alpha: float
    bv_gain: float
    kn: float
    kp: float
    u0n: float
    u0p: float
    rt_f: float
    an_poly: np.ndarray
    ap_poly: np.ndarray
    t_ambient_k: float
    r0_activation_k: float
    k_activation_k: float
    t_reference_k: float
    # The time constants, thermal mass and electrode areas as reciprocals: a step multiplies (1/s, 1/(J/K), 1/m^2)
    inv_t_diffusion: float
    inv_t_ohmic: float
    inv_t_sn: float
    inv_t_sp: float
    inv_thermal_mass: float
    inv_thermal_tau: float
    inv_sn: float
    inv_sp: float


@lru_cache(maxsize=64)
def rk_polynomial(coeffs: tuple[float, ...]) -> np.ndarray:
    """Coefficients (highest power first, leading zeros dropped) of the Redlich-Kister sum with
    coefficients ``coeffs`` (J/mol) as a polynomial in z = 2x - 1, divided by F (V).

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
    out = (poly / FARADAY)[::-1]
    nonzero = np.flatnonzero(out != 0.0)
    out = out[nonzero[0]:] if nonzero.size else out[-1:]
    out.setflags(write=False)
    return out


@lru_cache(maxsize=32)
def model_constants(cell: CellParameters) -> ModelConstants:
    """The :class:`ModelConstants` of ``cell`` (cached: a cell's numbers are fixed)."""
    return ModelConstants(
        vol_s_fraction=float(cell.vol_s_fraction), inv_vb=1.0 / cell.vol_b, inv_vs=1.0 / cell.vol_s,
        alpha=float(cell.alpha), bv_gain=GAS_CONSTANT / FARADAY / cell.alpha, kn=float(cell.kn), kp=float(cell.kp),
        u0n=float(cell.u0n), u0p=float(cell.u0p), rt_f=GAS_CONSTANT / FARADAY,
        an_poly=rk_polynomial(tuple(float(a) for a in cell.an)),
        ap_poly=rk_polynomial(tuple(float(a) for a in cell.ap)),
        t_ambient_k=float(cell.t_ambient_k), r0_activation_k=float(cell.r0_activation_k),
        k_activation_k=float(cell.k_activation_k), t_reference_k=float(cell.t_reference_k),
        inv_t_diffusion=1.0 / cell.t_diffusion_s, inv_t_ohmic=1.0 / cell.t_ohmic_s, inv_t_sn=1.0 / cell.t_sn_s,
        inv_t_sp=1.0 / cell.t_sp_s, inv_thermal_mass=1.0 / cell.thermal_mass, inv_thermal_tau=1.0 / cell.thermal_tau_s,
        inv_sn=1.0 / cell.sn, inv_sp=1.0 / cell.sp,
    )


@register_jitable
def horner(z, poly):
    """The polynomial ``poly`` (highest power first) at ``z``."""
    total = z * 0.0 + poly[0]
    for k in range(1, len(poly)):
        total = total * z + poly[k]
    return total


def redlich_kister(x: np.ndarray, coeffs: tuple[float, ...]) -> np.ndarray:
    """Sum over k of A_k/F * ((2x-1)^(k+1) - 2 k x (1-x) (2x-1)^(k-1)) (V)."""
    return horner(2.0 * np.asarray(x, dtype=float) - 1.0, rk_polynomial(tuple(coeffs)))


@register_jitable(inline="always")
def surface_fractions(qns, qps, q_surface_max):
    """Surface mole fractions (xnS, xpS), clipped into the open interval (0, 1)."""
    xns = np.minimum(np.maximum(qns / q_surface_max, _X_EPS), 1.0 - _X_EPS)
    xps = np.minimum(np.maximum(qps / q_surface_max, _X_EPS), 1.0 - _X_EPS)
    return xns, xps


@register_jitable(inline="always")
def equilibrium_voltage(xns, xps, tb, k):
    """Open-circuit voltage Vep - Ven (V) at surface fractions xns, xps and temperature tb (K) of the
    cell whose :class:`ModelConstants` are ``k``."""
    rt_f = k.rt_f * tb
    ven = k.u0n + rt_f * np.log((1.0 - xns) / xns) + horner(2.0 * xns - 1.0, k.an_poly)
    vep = k.u0p + rt_f * np.log((1.0 - xps) / xps) + horner(2.0 * xps - 1.0, k.ap_poly)
    return vep - ven


@register_jitable(inline="always")
def overpotential_gains(current_a, xns, xps, k, rate_factor):
    """Steady-state surface overpotentials per kelvin, (R/(F alpha)) asinh(J / 2 J0) (V/K).

    Multiply by the temperature (K) to get the nominal Vsn and Vsp. ``rate_factor`` scales both rate
    constants (:func:`arrhenius` of the cell's temperature with ``-k.k_activation_k``).
    """
    if k.alpha == 0.5:  # the published cells' value: a square root, as numpy's ``** 0.5`` takes it
        jn0 = k.kn * rate_factor * np.sqrt((1.0 - xns) * xns)
        jp0 = k.kp * rate_factor * np.sqrt((1.0 - xps) * xps)
    else:
        jn0 = k.kn * rate_factor * ((1.0 - xns) * xns) ** k.alpha
        jp0 = k.kp * rate_factor * ((1.0 - xps) * xps) ** k.alpha
    gn = k.bv_gain * np.arcsinh((current_a * k.inv_sn) / (2.0 * jn0))
    gp = k.bv_gain * np.arcsinh((current_a * k.inv_sp) / (2.0 * jp0))
    return gn, gp


@register_jitable(inline="always")
def voltage_at(tb, vo, vsn, vsp, xns, xps, k):
    """Terminal voltage (V) of a state (tb K; vo, vsn, vsp V) whose surface mole fractions are xns, xps."""
    return equilibrium_voltage(xns, xps, tb, k) - vo - vsn - vsp


@register_jitable(inline="always")
def terminal_voltage(tb, vo, vsn, vsp, qns, qps, q_total, k):
    """Terminal voltage (V) of a state (tb K; vo, vsn, vsp V; qns, qps C) of total charge ``q_total`` (C)."""
    xns, xps = surface_fractions(qns, qps, q_total * k.vol_s_fraction)
    return voltage_at(tb, vo, vsn, vsp, xns, xps, k)


@register_jitable(inline="always")
def step_at(tb, vo, vsn, vsp, qnb, qns, qpb, qps, xns, xps, current_a, r0, dt_s, k):
    """One explicit-Euler step of ``dt_s`` (s) under ``current_a`` (A) from the state (tb K; vo, vsn,
    vsp V; qnb, qns, qpb, qps C) whose surface mole fractions are xns, xps, of a cell with resistance ``r0``
    (ohm): the next state, in that order."""
    diff_n = (qnb * k.inv_vb - qns * k.inv_vs) * k.inv_t_diffusion
    diff_p = (qpb * k.inv_vb - qps * k.inv_vs) * k.inv_t_diffusion
    gn, gp = overpotential_gains(current_a, xns, xps, k, arrhenius(tb, -k.k_activation_k, k.t_reference_k))
    eta = vo + vsn + vsp
    return (
        tb + dt_s * (eta * current_a * k.inv_thermal_mass + (k.t_ambient_k - tb) * k.inv_thermal_tau),
        vo + dt_s * (current_a * r0 * arrhenius(tb, k.r0_activation_k, k.t_reference_k) - vo) * k.inv_t_ohmic,
        vsn + dt_s * (gn * tb - vsn) * k.inv_t_sn,
        vsp + dt_s * (gp * tb - vsp) * k.inv_t_sp,
        qnb - dt_s * diff_n,
        qns + dt_s * (diff_n - current_a),
        qpb - dt_s * diff_p,
        qps + dt_s * (diff_p + current_a),
    )


@register_jitable(inline="always")
def euler_step(tb, vo, vsn, vsp, qnb, qns, qpb, qps, current_a, q_total, r0, dt_s, k):
    """:func:`step_at` of a cell with total charge ``q_total`` (C), its surface fractions computed here."""
    xns, xps = surface_fractions(qns, qps, q_total * k.vol_s_fraction)
    return step_at(tb, vo, vsn, vsp, qnb, qns, qpb, qps, xns, xps, current_a, r0, dt_s, k)


# The compiled loops (:mod:`uam_studio.battery.kernel` calls them). They live in this file so that numba's disk
# cache, which is keyed on the source file of the compiled function, is invalidated by any change to the
# equations above.

@register_jitable(inline="always")
def _row(x, b):
    """Row ``b`` of states ``x`` [B, 8]: (tb, vo, vsn, vsp, qnb, qns, qpb, qps)."""
    return x[b, 0], x[b, 1], x[b, 2], x[b, 3], x[b, 4], x[b, 5], x[b, 6], x[b, 7]


@register_jitable(inline="always")
def _put(out, b, tb, vo, vsn, vsp, qnb, qns, qpb, qps):
    """Write a state into row ``b`` of ``out`` [B, 8]."""
    out[b, 0], out[b, 1], out[b, 2], out[b, 3] = tb, vo, vsn, vsp
    out[b, 4], out[b, 5], out[b, 6], out[b, 7] = qnb, qns, qpb, qps


@njit(cache=True, nogil=True, error_model="numpy")
def run_current(current, x0, q_total, r0, dt_s, k, voltage, states):
    n_rows, n_steps = current.shape
    for b in range(n_rows):
        tb, vo, vsn, vsp, qnb, qns, qpb, qps = _row(x0, b)
        q_s, r = q_total[b] * k.vol_s_fraction, r0[b]
        xns, xps = surface_fractions(qns, qps, q_s)
        for t in range(n_steps):
            tb, vo, vsn, vsp, qnb, qns, qpb, qps = step_at(tb, vo, vsn, vsp, qnb, qns, qpb, qps, xns, xps,
                                                           current[b, t], r, dt_s, k)
            xns, xps = surface_fractions(qns, qps, q_s)
            voltage[b, t] = voltage_at(tb, vo, vsn, vsp, xns, xps, k)
            states[0, b, t] = tb
            states[1, b, t] = vo
            states[2, b, t] = vsn
            states[3, b, t] = vsp
            states[4, b, t] = qnb
            states[5, b, t] = qns
            states[6, b, t] = qpb
            states[7, b, t] = qps


@njit(cache=True, nogil=True, error_model="numpy")
def run_to_cutoff(load, power_mode, x0, q_total, r0, dt_s, k, eod_v, voltage, current, final, k_eod):
    n_rows, n_steps = load.shape
    for b in range(n_rows):
        tb, vo, vsn, vsp, qnb, qns, qpb, qps = _row(x0, b)
        q_s, r = q_total[b] * k.vol_s_fraction, r0[b]
        k_eod[b] = n_steps
        xns, xps = surface_fractions(qns, qps, q_s)
        v = voltage_at(tb, vo, vsn, vsp, xns, xps, k)
        for t in range(n_steps):
            if power_mode:
                i = load[b, t] / max(v, 0.5) if v > 0.5 else 0.0
                current[b, t] = i
            else:
                i = load[b, t]
            n_tb, n_vo, n_vsn, n_vsp, n_qnb, n_qns, n_qpb, n_qps = step_at(tb, vo, vsn, vsp, qnb, qns, qpb, qps, xns,
                                                                           xps, i, r, dt_s, k)
            xns, xps = surface_fractions(n_qns, n_qps, q_s)
            v = voltage_at(n_tb, n_vo, n_vsn, n_vsp, xns, xps, k)
            voltage[b, t] = v
            if not v >= eod_v:  # below the cut-off, or NaN (uam_studio.battery.eod's rule)
                k_eod[b] = t
                # This sample and the rest hold its value, made finite and >= 0 (NaN and inf give 0 V).
                hold = max(v, 0.0) if abs(v) < np.inf else 0.0
                for s in range(t, n_steps):
                    voltage[b, s] = hold
                if power_mode:
                    for s in range(t + 1, n_steps):
                        current[b, s] = 0.0
                break
            tb, vo, vsn, vsp, qnb, qns, qpb, qps = n_tb, n_vo, n_vsn, n_vsp, n_qnb, n_qns, n_qpb, n_qps
        _put(final, b, tb, vo, vsn, vsp, qnb, qns, qpb, qps)  # after the last sample above the cut-off


@njit(cache=True, nogil=True, error_model="numpy")
def run_rows(flat, starts, lengths, x0, q_total, r0, dt_s, k, eod_v, split, ok, x_end, v_min, x_split):
    q_s = q_total * k.vol_s_fraction
    for b in range(lengths.size):
        tb, vo, vsn, vsp, qnb, qns, qpb, qps = _row(x0, b)
        for j in range(8):
            x_end[b, j] = x0[b, j]
            x_split[b, j] = x0[b, j]
        ok[b] = True
        lowest = np.inf
        off = starts[b]
        xns, xps = surface_fractions(qns, qps, q_s)
        for t in range(lengths[b]):
            tb, vo, vsn, vsp, qnb, qns, qpb, qps = step_at(tb, vo, vsn, vsp, qnb, qns, qpb, qps, xns, xps,
                                                           flat[off + t], r0, dt_s, k)
            xns, xps = surface_fractions(qns, qps, q_s)
            v = voltage_at(tb, vo, vsn, vsp, xns, xps, k)
            if v != v:  # NaN: below the cut-off, and the lowest voltage is not a number
                lowest = v
                ok[b] = False
                break
            lowest = min(lowest, v)
            if not v >= eod_v:
                ok[b] = False
                break
            if t + 1 == split[b]:
                _put(x_split, b, tb, vo, vsn, vsp, qnb, qns, qpb, qps)
        if ok[b]:
            _put(x_end, b, tb, vo, vsn, vsp, qnb, qns, qpb, qps)
        v_min[b] = lowest

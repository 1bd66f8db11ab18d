"""Batched time integration of the electrochemistry model (explicit Euler, like progpy).

:func:`integrate_current` and :func:`step` are what the library runs: the first is the compiled kernel
(:mod:`uam_studio.battery.kernel`, one pass per step and trajectory), the second one Euler step of numpy
arrays. Both evaluate :func:`uam_studio.battery.electrochem.euler_step`, the model's one home.

:func:`integrate_current_vectorised` is the numpy solver the kernel replaced, kept as a tested reference
(tests and ``benchmarks/bench_battery.py`` hold the kernel to it). With the current known in advance, the
charge states and the ohmic voltage follow linear time-invariant first-order recurrences
x[k+1] = a x[k] + u[k]: each is a unit lower-bidiagonal linear system, which LAPACK's banded triangular
solve (``?tbtrs``) evaluates for all steps and all trajectories in one call, the same forward
substitution as the Euler steps. The surface overpotentials depend on temperature and the temperature on
the overpotentials (one step delayed); that weak loop is solved by a fixed-point (Picard) iteration over
whole trajectories, which converges to round-off in a few passes. The result equals step-by-step Euler
to ~1e-12 V.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dtbtrs

from uam_studio.battery import kernel
from uam_studio.battery.electrochem import (
    euler_step,
    model_constants,
    overpotential_gains,
    surface_fractions,
    terminal_voltage,
)
from uam_studio.battery.parameters import CellParameters
from uam_studio.battery.state import STATE_NAMES, BatteryState

# K. The temperature iterates contract by about 1e-3 a pass, so the accepted pass is far closer to
# the fixed point than this: against a 1e-13 K solve, 1e-5 K moves the voltage by < 1e-11 V
# (measured over 40 random 3-leg flights, q_max 4000-9000 C, R0 0.017-0.5 ohm: at most 2.4e-12 V),
# and saves about one of the ~4 passes per leg that 1e-7 K took. Held-out plans of every policy were
# unchanged; their minimum voltages moved by at most 1.4e-10 V.
_PICARD_TOL_K = 1e-5
_PICARD_MAX_ITER = 30


def _solve_recurrence(rhs: np.ndarray, a: float) -> np.ndarray:
    """Solve x[0] = rhs[0], x[k] = a x[k-1] + rhs[k] along each row of ``rhs`` [B, T+1] (C-ordered; the
    solve overwrites it): x[0..T], shape [B, T+1].

    One unit lower-bidiagonal system, every row a right-hand side (LAPACK ``dtbtrs``): forward
    substitution, the same arithmetic as the Euler steps."""
    n = rhs.shape[1]
    band = np.empty((n, 2)).T  # Fortran order; row 0 (the unit diagonal) is not read
    band[1] = -a
    out, info = dtbtrs(band, rhs.T, uplo="L", diag="U", overwrite_b=1)
    if info != 0:  # a unit-diagonal system is never singular: only a malformed call gets here
        raise RuntimeError(f"dtbtrs failed with info={info}")
    return out.T


def _lag(inputs: np.ndarray, x0: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    """Euler first-order lag x[k+1] = x[k] + dt (u[k] - x[k]) / tau from x[0] = ``x0`` [B], inputs u
    [B, T]: x[0..T], shape [B, T+1] (x[1..T] is ``[:, 1:]``, x[0..T-1] is ``[:, :-1]``)."""
    gain = dt_s / tau_s
    rhs = np.empty((inputs.shape[0], inputs.shape[1] + 1))
    rhs[:, 0] = x0
    np.multiply(gain, inputs, out=rhs[:, 1:])
    return _solve_recurrence(rhs, 1.0 - gain)


def _shift(seq_1_to_t: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """x[0..T-1] from x[1..T] and x[0]."""
    return np.concatenate([x0[:, None], seq_1_to_t[:, :-1]], axis=1)


def output_voltage(state_seq: dict, q_total, cell: CellParameters) -> np.ndarray:
    """Terminal voltage (V) from (sequences of) states; q_total broadcastable against them."""
    s = state_seq
    return terminal_voltage(s["tb"], s["vo"], s["vsn"], s["vsp"], s["qns"], s["qps"], q_total, model_constants(cell))


def integrate_current(current: np.ndarray, x0: BatteryState, q_total: np.ndarray,
                      r0: np.ndarray, dt_s: float, cell: CellParameters):
    """Integrate a known current (A), shape [B, T], on the compiled kernel. Returns (voltage [B, T], states
    at 1..T: a dict of [B, T] arrays named as :data:`STATE_NAMES`)."""
    voltage, seq = kernel.integrate(current, x0.as_array(), q_total, r0, dt_s, model_constants(cell))
    return voltage, dict(zip(STATE_NAMES, seq))


def integrate_current_vectorised(current: np.ndarray, x0: BatteryState, q_total: np.ndarray,
                                 r0: np.ndarray, dt_s: float, cell: CellParameters):
    """The time-vectorised numpy solver (module docstring), the kernel's reference: same arguments and
    result as :func:`integrate_current`."""
    k = model_constants(cell)
    dt = dt_s
    tdiff = cell.t_diffusion_s
    inv_vb, inv_vs = 1.0 / cell.vol_b, 1.0 / cell.vol_s
    a_diff = 1.0 - dt / tdiff * (inv_vb + inv_vs)

    # Bulk-minus-surface concentration gaps follow d[k+1] = a d[k] -/+ (dt/VolS) i[k].
    gap_n0 = x0.qnb * inv_vb - x0.qns * inv_vs
    gap_p0 = x0.qpb * inv_vb - x0.qps * inv_vs
    # Both gaps share one recurrence: -gap_p obeys gap_n's, so one solve on the stacked rows
    # [current; current] from [gap_n0; -gap_p0] gives both.
    batch = current.shape[0]
    rhs = np.empty((2 * batch, current.shape[1] + 1))
    rhs[:batch, 0], rhs[batch:, 0] = gap_n0, -gap_p0
    np.multiply(dt * inv_vs, current, out=rhs[:batch, 1:])
    rhs[batch:, 1:] = rhs[:batch, 1:]
    gaps = _solve_recurrence(rhs, a_diff)
    gap_n = gaps[:batch, :-1]  # d[0..T-1]
    gap_p = -gaps[batch:, :-1]
    flux_n = dt * gap_n / tdiff
    flux_p = dt * gap_p / tdiff
    qnb = x0.qnb[:, None] - np.cumsum(flux_n, axis=1)
    qns = x0.qns[:, None] + np.cumsum(flux_n - dt * current, axis=1)
    qpb = x0.qpb[:, None] - np.cumsum(flux_p, axis=1)
    qps = x0.qps[:, None] + np.cumsum(flux_p + dt * current, axis=1)

    vo = _lag(current * r0[:, None], x0.vo, cell.t_ohmic_s, dt)  # [B, T+1], as every lag below

    # Overpotential gains at the start of each step (they need x[k], k = 0..T-1).
    q_surface_max = (q_total * cell.vol_s_fraction)[:, None]
    xns_k, xps_k = surface_fractions(_shift(qns, x0.qns), _shift(qps, x0.qps), q_surface_max)
    gn, gp = overpotential_gains(current, xns_k, xps_k, k, 1.0)

    tb_k = np.broadcast_to(x0.tb[:, None], current.shape).copy()
    heat_scale = cell.thermal_tau_s / cell.thermal_mass
    for _ in range(_PICARD_MAX_ITER):
        if cell.temperature_dependent:  # R0 and the rate constants follow the temperature iterate
            vo = _lag(current * r0[:, None] * cell.r0_factor(tb_k), x0.vo, cell.t_ohmic_s, dt)
            gn, gp = overpotential_gains(current, xns_k, xps_k, k, cell.rate_factor(tb_k))
        vsn = _lag(gn * tb_k, x0.vsn, cell.t_sn_s, dt)
        vsp = _lag(gp * tb_k, x0.vsp, cell.t_sp_s, dt)
        eta_k = vo[:, :-1] + vsn[:, :-1] + vsp[:, :-1]
        tb = _lag(heat_scale * eta_k * current + cell.t_ambient_k, x0.tb, cell.thermal_tau_s, dt)
        tb_next = tb[:, :-1]
        converged = not np.any(np.abs(tb_next - tb_k) > _PICARD_TOL_K)  # NaN-safe
        tb_k = tb_next
        if converged:
            # vsn/vsp used a temperature within the tolerance of the fixed point:
            # the voltage error is < tol * R/(F alpha) * asinh(...) ~ 1e-11 V.
            break

    states = {"tb": tb[:, 1:], "vo": vo[:, 1:], "vsn": vsn[:, 1:], "vsp": vsp[:, 1:], "qnb": qnb, "qns": qns,
              "qpb": qpb, "qps": qps}
    voltage = output_voltage(states, q_total[:, None], cell)
    return voltage, states


def step(x: BatteryState, current: np.ndarray, q_total: np.ndarray, r0: np.ndarray,
         dt_s: float, cell: CellParameters) -> BatteryState:
    """One explicit-Euler step of all trajectories under current (A), shape [B]."""
    return BatteryState(*euler_step(x.tb, x.vo, x.vsn, x.vsp, x.qnb, x.qns, x.qpb, x.qps, current, q_total, r0,
                                    dt_s, model_constants(cell)))

"""How a pack ages with use: capacity fade and resistance growth against the charge it has delivered,
fitted to the CMU eVTOL lives (``../shared/data/cmu_evtol``: cells VAH07, VAH09, VAH27, VAH30 flying the
baseline mission until end of life, with a C/5 reference discharge every few dozen missions).

The law, per cell, with ``efc`` the equivalent full cycles delivered (discharge throughput over the
cell's first capacity) and ``T`` the cell's temperature (C):

- capacity fraction ``c(efc, T) = 1 - a * exp(ea_k * (1/T_ref - 1/T)) * efc ** b`` (of the first
  capacity; ``T_ref`` 25 C);
- resistance ratio ``r(efc) = 1 + k_r * efc`` (of the first resistance).

The capacity comes from the reference discharges' integrated charge (Ah, measured). The resistance is
a proxy: the voltage step over the first loaded sample of each reference discharge over its current
(ohm); the lives are resampled every 30-190 s, so the step holds some polarisation and the proxy is
noisy (steps under half the cell's median are dropped as resampling artefacts). ``k_r`` is fitted with a
free starting resistance per cell.

:class:`AgingLaw` and its fitted numbers :data:`AGING_LAW` live in :mod:`uam_studio.battery.aging` (the one place
for them); ``python -m uam_studio.fleet.aging`` refits and prints them, with each cell's error when the law is fitted
on the other three.

A pack of the paper's NASA cell ages by the same law on the same clock: its ``efc`` is the charge it
delivered over its first q_max, its q_max is ``q_max0 * c`` and its R0 ``r0_0 * r``
(:class:`PackHealth`). It retires below :data:`END_OF_LIFE_FRACTION` of its first capacity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from uam_studio.battery.aging import AGING_LAW, END_OF_LIFE_FRACTION, T_REF_C, AgingLaw
from uam_studio.battery.parameters import ZERO_C, CellParameters
from uam_studio.battery.real.cmu_data import (
    data_folder,
    load_cell_log,
    reference_discharges,
    resampled_missions,
)
from uam_studio.errors import InputError, check_range

__all__ = ["AGING_LAW", "END_OF_LIFE_FRACTION", "LIFE_FILES", "AgingLaw", "LifePoints", "PackHealth",
           "fit_aging_law", "fit_resistance_growth", "leave_one_cell_out", "life_points"]

LIFE_FILES = ("VAH07.csv.mat", "VAH09.csv.mat", "VAH27.csv.mat", "VAH30.csv.mat")
IR_ARTEFACT = 0.5  # resistance-proxy steps under this share of the cell's median are resampling artefacts




@dataclass(frozen=True)
class LifePoints:
    """One CMU life's reference discharges: ``efc`` (equivalent full cycles delivered before each),
    ``capacity_ah`` (measured, Ah), ``missions`` (mission cycles flown before each), ``temperature_c``
    (the life's median, C), and the resistance proxy ``ir_efc`` / ``ir_ohm`` (artefacts dropped).
    ``rest_h`` (h), where the data date each discharge: the time since the one before (NaN for the first)."""

    cell: str
    efc: np.ndarray
    capacity_ah: np.ndarray
    missions: np.ndarray
    temperature_c: float
    ir_efc: np.ndarray
    ir_ohm: np.ndarray
    rest_h: np.ndarray | None = None

    @property
    def fraction(self) -> np.ndarray:
        """Capacity as a fraction of the life's first reference discharge."""
        return self.capacity_ah / self.capacity_ah[0]


def life_points(data: str | Path | None = None) -> list[LifePoints]:
    """The four lives' reference discharges (:class:`LifePoints`), from the dataset's folder (``data``,
    else :func:`~uam_studio.battery.real.cmu_data.data_folder`'s search)."""
    folder = data_folder(data, needs=LIFE_FILES[0])
    out = []
    for name in LIFE_FILES:
        log = load_cell_log(folder / name)
        refs = reference_discharges(log)
        if len(refs) < 3:
            raise InputError("data", f"{name}: {len(refs)} reference discharges, the aging fit needs 3 or more")
        t = log.time_s
        dt = np.diff(t, append=t[-1] + float(np.median(np.diff(t))))
        delivered_ah = np.cumsum(np.clip(log.current_a, 0.0, None) * dt) / 3600.0
        first_ah = refs[0].capacity_ah
        starts = np.array([m.index[0] for m in resampled_missions(log)])
        efc = np.array([delivered_ah[r.start - 1] - delivered_ah[refs[0].start - 1] for r in refs]) / first_ah
        steps = np.array([(log.voltage_v[r.start - 1] - log.voltage_v[r.start]) / log.current_a[r.start]
                          for r in refs])
        keep = steps >= IR_ARTEFACT * float(np.median(steps))
        out.append(LifePoints(log.name, efc, np.array([r.capacity_ah for r in refs]),
                              np.array([int((starts < r.start).sum()) for r in refs]),
                              float(np.median(log.temperature_c)), efc[keep], steps[keep]))
    return out


def fit_aging_law(lives: list[LifePoints]) -> AgingLaw:
    """Least-squares fit of :class:`AgingLaw` to ``lives``: ``a``, ``b``, ``ea_k`` on every capacity
    fraction after the first, ``k_r`` (with a starting resistance per life) on the resistance proxy."""
    if not lives:
        raise InputError("lives", "no life to fit")
    e = np.concatenate([lf.efc[1:] for lf in lives])
    f = np.concatenate([lf.fraction[1:] for lf in lives])
    inv_t = np.concatenate([np.full(lf.efc.size - 1, 1.0 / (T_REF_C + ZERO_C) - 1.0 / (lf.temperature_c + ZERO_C))
                            for lf in lives])
    temps = {round(lf.temperature_c, 1) for lf in lives}

    def residual(p: np.ndarray) -> np.ndarray:
        ln_a, b, ea = p
        return 1.0 - np.exp(ln_a + ea * inv_t) * e ** b - f

    ea_bound = 2e4 if len(temps) > 1 else 1e-9  # one temperature: no Arrhenius term to fit
    fit = least_squares(residual, x0=[math.log(1e-3), 0.8, 0.0], bounds=([-20.0, 0.1, -ea_bound], [0.0, 2.0, ea_bound]))
    ln_a, b, ea = (float(v) for v in fit.x)
    return AgingLaw(a=math.exp(ln_a), b=b, ea_k=ea if len(temps) > 1 else 0.0, k_r=fit_resistance_growth(lives))


def fit_resistance_growth(lives: list[LifePoints]) -> float:
    """``k_r`` (per equivalent full cycle, >= 0): ``ir = r_i (1 + k_r efc)`` with a starting resistance
    ``r_i`` per life, linear in (r_i, r_i k_r) and fitted by least squares; the lives' pooled growth."""
    rows, y = [], []
    for i, lf in enumerate(lives):
        for ee, ir in zip(lf.ir_efc, lf.ir_ohm):
            row = np.zeros(2 * len(lives))
            row[2 * i], row[2 * i + 1] = 1.0, ee
            rows.append(row)
            y.append(ir)
    coef = np.linalg.lstsq(np.array(rows), np.array(y), rcond=None)[0]
    r_i, slope_i = coef[0::2], coef[1::2]
    return max(float(np.sum(slope_i) / np.sum(r_i)), 0.0)  # the lives' pooled growth per cycle, relative


def leave_one_cell_out(lives: list[LifePoints]) -> list[dict]:
    """Each life scored by the law fitted on the other lives: capacity error (Ah; measured capacity
    against the first capacity times the law's fraction) as RMS and worst, and at its last test."""
    out = []
    for i, lf in enumerate(lives):
        law = fit_aging_law([x for j, x in enumerate(lives) if j != i])
        pred = lf.capacity_ah[0] * law.capacity_fraction(lf.efc, lf.temperature_c)
        err = pred - lf.capacity_ah
        out.append({"cell": lf.cell, "tests": int(lf.efc.size), "missions": int(lf.missions[-1]),
                    "efc": float(lf.efc[-1]), "temperature_c": lf.temperature_c,
                    "first_ah": float(lf.capacity_ah[0]), "last_ah": float(lf.capacity_ah[-1]),
                    "rms_ah": float(np.sqrt(np.mean(err[1:] ** 2))), "worst_ah": float(np.max(np.abs(err))),
                    "last_error_ah": float(err[-1]), "last_error_pct": float(100 * err[-1] / lf.capacity_ah[-1])})
    return out


@dataclass(frozen=True)
class PackHealth:
    """A pack's true health as it ages: its first ``q_max0`` (C) and ``r0_0`` (ohm), the charge it has
    delivered (``delivered_c``, C) and its temperature (C). ``q_max`` and ``r0`` follow :data:`AGING_LAW`
    (or ``law``) on ``efc = delivered_c / q_max0``. ``params``: the pack's own parameter set (None: the cell type's,
    the pack is its model)."""

    q_max0: float
    r0_0: float
    delivered_c: float = 0.0
    temperature_c: float = T_REF_C
    law: AgingLaw | None = None
    params: CellParameters | None = None

    @property
    def efc(self) -> float:
        return self.delivered_c / self.q_max0

    @property
    def fraction(self) -> float:
        return float((self.law or AGING_LAW).capacity_fraction(self.efc, self.temperature_c))

    @property
    def q_max(self) -> float:
        return self.q_max0 * self.fraction

    @property
    def r0(self) -> float:
        return float(self.r0_0 * (self.law or AGING_LAW).resistance_ratio(self.efc))

    @property
    def retired(self) -> bool:
        return self.fraction < END_OF_LIFE_FRACTION

    def after(self, charge_c: float) -> PackHealth:
        """The pack after delivering ``charge_c`` (C, >= 0) more."""
        c = check_range("charge_c", float(charge_c), 0.0, 1e9, " C")
        return replace(self, delivered_c=self.delivered_c + c)


def _main() -> None:  # pragma: no cover - the fitting command (RESULTS.md, "Packs that age")
    lives = life_points()
    law = fit_aging_law(lives)
    print(f"AgingLaw(a={law.a:.6g}, b={law.b:.6g}, ea_k={law.ea_k:.6g}, k_r={law.k_r:.6g})  (fitted on all four lives)")
    print(f"cycles to {END_OF_LIFE_FRACTION:.0%} at 25 C: {law.cycles_to():.0f} equivalent full cycles")
    print("leave-one-cell-out (law fitted on the other three; capacity error, Ah):")
    print(f"{'cell':6} {'T C':>5} {'tests':>5} {'missions':>8} {'efc':>6} {'first':>6} {'last':>6} {'rms':>6} "
          f"{'worst':>6} {'last err':>8}")
    for r in leave_one_cell_out(lives):
        print(f"{r['cell']:6} {r['temperature_c']:5.1f} {r['tests']:5d} {r['missions']:8d} {r['efc']:6.0f} "
              f"{r['first_ah']:6.3f} {r['last_ah']:6.3f} {r['rms_ah']:6.3f} {r['worst_ah']:6.3f} "
              f"{r['last_error_ah']:+8.3f} ({r['last_error_pct']:+.1f}%)")


if __name__ == "__main__":  # pragma: no cover
    _main()

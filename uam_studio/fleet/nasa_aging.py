"""How the paper's NASA cell ages: the aging law's form (:class:`~uam_studio.fleet.aging.AgingLaw`) fitted to
the NASA PCoE lives (``../shared/data/nasa_pcoe``: 26 cells cycled to end of life at 4, 24 and 43 C), and a
pack's belief of its own capacity, updated from its own discharges.

- :func:`nasa_life_points`: each life's measured capacity per discharge (Ah, the dataset's ``Capacity``
  column of ``metadata.csv``: each discharge to the cell's cut-off), the equivalent full cycles delivered
  before it (the sum of the earlier discharges' capacities over the first), the cell's median ambient (C)
  and its impedance tests' resistance ``Re + Rct`` (ohm): a measurement, where the CMU law has a proxy.
- :func:`fit_nasa_law` / :func:`nasa_leave_one_cell_out`: the law on NASA lives, and each life scored by
  the law fitted on the others, beside the VTC6 law (:data:`~uam_studio.fleet.aging.AGING_LAW`) on the
  same life as the baseline.
- :class:`CapacityBelief`: capacity ``C0 (1 - s g(efc))`` with ``g`` the law's fade, a Gaussian belief on
  (``C0``, ``C0 s``) updated by each discharge's measured capacity; :func:`forecast_score` scores its
  next-``horizon`` forecasts (RMS, Ah, and 90% band coverage) on lives held out of the law's fit.

:data:`NASA_AGING_LAW` holds the numbers fitted on all 26 lives (in-sample for them); ``python -m
uam_studio.fleet.nasa_aging`` refits and prints them with the leave-one-cell-out table.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from uam_studio.battery.real.nasa_data import NasaDataError, load_nasa_folder, nasa_folder
from uam_studio.errors import InputError
from uam_studio.fleet.aging import AGING_LAW, T_REF_C, ZERO_C_K, AgingLaw, LifePoints, fit_resistance_growth

__all__ = ["NASA_AGING_LAW", "CapacityBelief", "fit_nasa_law", "forecast_score", "nasa_leave_one_cell_out",
           "nasa_life_points"]

NASA_AGING_LAW = AgingLaw(a=0.0213434, b=0.49731, ea_k=-778.876, k_r=0.00145988)  # fit_nasa_law, all 25 lives
MIN_POINTS = 10  # a life with fewer measured capacities is too short to fit or score
REFERENCE_N = 5  # a life's reference capacity is the median of its first this many
DRIFT = 0.3  # a belief's C0 random walk per discharge, in units of its noise (0.3: 90-96% coverage on the 2 A lives)


def _number(text: str) -> float:
    """A number as the table writes it (ohm or Ah): a complex entry (``(a+bj)``) gives its real part, an
    empty or ``[]`` one NaN."""
    try:
        return float(complex(text.strip()).real)
    except ValueError:
        return math.nan  # '' and '[]': no measurement


def nasa_life_points(data: str | Path | None = None) -> list[LifePoints]:
    """Each NASA life of ``data`` with at least :data:`MIN_POINTS` measured capacities at its most common
    load and ambient (the capacity of a 4 A discharge at 4 C is not that of a 1 A one: a law of one
    condition reads one). ``efc`` counts every discharge's capacity, over the life's reference (the median
    of its first :data:`REFERENCE_N` kept capacities)."""
    folder = nasa_folder(data)
    path = folder / "metadata.csv"
    if not path.is_file():
        raise NasaDataError(path, "file", "no such file (the dataset's cycle table)")
    rows: dict[str, list[dict]] = {}
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            rows.setdefault(r["battery_id"], []).append(r)
    condition = {}
    for cell in load_nasa_folder(folder, [c for c in sorted(rows) if (folder / f"{c}.csv.gz").is_file()]):
        for d in cell.discharges:
            condition[(cell.name, d.uid)] = (round(d.mean_load_a() * 2) / 2, round(d.ambient_c / 5) * 5)
    out = []
    for cell, rs in sorted(rows.items()):
        rs.sort(key=lambda r: int(r["uid"]))
        dis = [r for r in rs if r["type"] == "discharge" and _number(r["Capacity"] or "nan") > 0.05]
        conds = [condition.get((cell, int(r["uid"]))) for r in dis]
        counted = [c for c in conds if c is not None]
        if not counted:
            continue
        main = max(set(counted), key=counted.count)
        cap_all = np.array([_number(r["Capacity"]) for r in dis])
        keep = np.array([c == main for c in conds])
        if keep.sum() < MIN_POINTS:
            continue
        ref = float(np.median(cap_all[keep][:REFERENCE_N]))
        efc = (np.r_[0.0, np.cumsum(cap_all[:-1])] / ref)[keep]
        uid = np.array([int(r["uid"]) for r in dis], dtype=float)
        imp = [r for r in rs if r["type"] == "impedance" and r["Re"] and r["Rct"]]
        ir = np.array([_number(r["Re"]) + _number(r["Rct"]) for r in imp])
        ir_uid = np.array([int(r["uid"]) for r in imp], dtype=float)
        good = np.isfinite(ir) & (ir > 0) & (ir < 1.0)
        out.append(LifePoints(cell, efc, cap_all[keep], np.flatnonzero(keep), float(main[1]),
                              np.interp(ir_uid[good], uid, np.r_[0.0, np.cumsum(cap_all[:-1])] / ref), ir[good]))
    return out


def reference_ah(lf: LifePoints) -> float:
    """A life's reference capacity (Ah): the median of its first :data:`REFERENCE_N` measured ones."""
    return float(np.median(lf.capacity_ah[:REFERENCE_N]))


def fit_nasa_law(lives: list[LifePoints]) -> AgingLaw:
    """The law's capacity fade (``a``, ``b``, ``ea_k``) fitted to ``lives`` with a free starting capacity
    per life and a robust loss (a rest's recovery is not fade), and ``k_r`` from the impedance tests
    (:func:`~uam_studio.fleet.aging.fit_resistance_growth`)."""
    if not lives:
        raise InputError("lives", "no life to fit")
    inv = [1.0 / (T_REF_C + ZERO_C_K) - 1.0 / (lf.temperature_c + ZERO_C_K) for lf in lives]
    n = len(lives)

    def residual(p: np.ndarray) -> np.ndarray:
        ln_a, b, ea, c0 = p[0], p[1], p[2], p[3:]
        return np.concatenate([c0[i] * (1.0 - np.exp(ln_a + ea * inv[i]) * lf.efc ** b) - lf.capacity_ah
                               for i, lf in enumerate(lives)])

    x0 = np.r_[math.log(2e-3), 1.0, 0.0, [reference_ah(lf) for lf in lives]]
    lo = np.r_[-25.0, 0.2, -2e4, np.full(n, 0.01)]
    hi = np.r_[0.0, 3.0, 2e4, np.full(n, 3.0)]
    fit = least_squares(residual, x0, bounds=(lo, hi), loss="soft_l1", f_scale=0.02)
    return AgingLaw(a=math.exp(fit.x[0]), b=float(fit.x[1]), ea_k=float(fit.x[2]), k_r=fit_resistance_growth(lives))


def _rms(law: AgingLaw, lf: LifePoints) -> float:
    """RMS (Ah) over the life of the law's capacity from the life's reference capacity."""
    err = reference_ah(lf) * law.capacity_fraction(lf.efc, lf.temperature_c) - lf.capacity_ah
    return float(np.sqrt(np.mean(err[1:] ** 2)))


def nasa_leave_one_cell_out(lives: list[LifePoints]) -> list[dict]:
    """Per life: capacity RMS (Ah) of the NASA law fitted on the other lives, and of the VTC6 law."""
    return [{"cell": lf.cell, "temperature_c": lf.temperature_c, "discharges": int(lf.efc.size),
             "first_ah": float(lf.capacity_ah[0]), "last_ah": float(lf.capacity_ah[-1]),
             "rms_ah": _rms(fit_nasa_law([x for x in lives if x.cell != lf.cell]), lf),
             "vtc6_rms_ah": _rms(AGING_LAW, lf)} for lf in lives]


@dataclass
class CapacityBelief:
    """A pack's Gaussian belief on (``C0`` Ah, ``C0 s`` Ah): capacity at ``efc`` is ``C0 - C0 s g(efc)``,
    ``g`` the law's fade at the pack's temperature. Starts at the first measured capacity (sd
    ``c0_sd``) and the law's fade (s = 1, sd ``s_sd``); each measured capacity (noise sd ``noise_ah``)
    updates it."""

    law: AgingLaw
    temperature_c: float
    mean: np.ndarray
    cov: np.ndarray
    noise_ah: float

    @classmethod
    def start(cls, law: AgingLaw, first_ah: float, temperature_c: float, noise_ah: float,
              c0_sd: float = 0.03, s_sd: float = 0.7) -> CapacityBelief:
        return cls(law, temperature_c, np.array([first_ah, first_ah]),
                   np.diag([c0_sd ** 2, (s_sd * first_ah) ** 2]), noise_ah)

    def _row(self, efc: float) -> np.ndarray:
        return np.array([1.0, -(1.0 - float(self.law.capacity_fraction(efc, self.temperature_c)))])

    def observe(self, efc: float, capacity_ah: float) -> None:
        """Take one measured capacity (Ah) at ``efc`` in (a Kalman update), after the belief's random walk
        of one discharge (``C0`` drifts by ``noise_ah`` * :data:`DRIFT` a discharge: rests and recoveries
        the law does not hold)."""
        self.cov = self.cov + np.diag([(DRIFT * self.noise_ah) ** 2, 0.0])
        h = self._row(efc)
        s = float(h @ self.cov @ h) + self.noise_ah ** 2
        k = self.cov @ h / s
        self.mean = self.mean + k * (capacity_ah - float(h @ self.mean))
        self.cov = self.cov - np.outer(k, h @ self.cov)

    def forecast(self, efc: np.ndarray, z: float = 1.6449) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(mean, low, high) capacity (Ah) at each ``efc``, the h-th of them h discharges ahead (the random
        walk grows with h): the 90% band by default."""
        rows = np.array([self._row(e) for e in np.atleast_1d(efc)])
        mean = rows @ self.mean
        walk = (DRIFT * self.noise_ah) ** 2 * np.arange(1, rows.shape[0] + 1)
        sd = np.sqrt(np.einsum("ij,jk,ik->i", rows, self.cov, rows) + walk + self.noise_ah ** 2)
        return mean, mean - z * sd, mean + z * sd


def _noise(law: AgingLaw, lives: list[LifePoints]) -> float:
    """The discharge-to-discharge scatter (Ah) about each life's own fade: the robust scale of the
    residuals of a per-life (C0, C0 s) fit."""
    res = []
    for lf in lives:
        g = 1.0 - law.capacity_fraction(lf.efc, lf.temperature_c)
        coef = np.linalg.lstsq(np.column_stack([np.ones_like(g), -g]), lf.capacity_ah, rcond=None)[0]
        res.append(lf.capacity_ah - coef[0] + coef[1] * g)
    r = np.concatenate(res)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def forecast_score(lives: list[LifePoints], horizon: int = 20, start: int = 5,
                   cells: list[str] | None = None) -> list[dict]:
    """Each life, held out of the law's fit (and of the noise's): after each of its discharges from
    ``start`` on, the belief forecasts the next ``horizon`` capacities. Per life (only ``cells`` if given):
    forecasts scored, RMS error (Ah) and the 90% band's coverage."""
    out = []
    for lf in lives:
        if cells is not None and lf.cell not in cells:
            continue
        others = [x for x in lives if x.cell != lf.cell]
        law = fit_nasa_law(others)
        noise = _noise(law, others)
        belief = CapacityBelief.start(law, reference_ah(lf), lf.temperature_c, noise)
        errs, inside = [], []
        for k in range(1, lf.efc.size):
            if k >= start and k + 1 < lf.efc.size:
                ahead = slice(k, min(k + horizon, lf.efc.size))
                mean, lo, hi = belief.forecast(lf.efc[ahead])
                truth = lf.capacity_ah[ahead]
                errs += list(mean - truth)
                inside += list((lo <= truth) & (truth <= hi))
            belief.observe(float(lf.efc[k]), float(lf.capacity_ah[k]))
        if errs:
            out.append({"cell": lf.cell, "temperature_c": lf.temperature_c, "forecasts": len(errs),
                        "rms_ah": float(math.sqrt(np.mean(np.square(errs)))), "coverage90": float(np.mean(inside))})
    return out


def _main() -> None:  # pragma: no cover - the fitting command; its numbers go to RESULTS.md
    lives = nasa_life_points()
    law = fit_nasa_law(lives)
    print(f"AgingLaw(a={law.a:.6g}, b={law.b:.6g}, ea_k={law.ea_k:.6g}, k_r={law.k_r:.6g})  (all {len(lives)} lives)")
    print(f"{'cell':6} {'T C':>5} {'n':>4} {'first':>6} {'last':>6} {'NASA law rms':>12} {'VTC6 law rms':>12}")
    for r in nasa_leave_one_cell_out(lives):
        print(f"{r['cell']:6} {r['temperature_c']:5.0f} {r['discharges']:4d} {r['first_ah']:6.3f} {r['last_ah']:6.3f} "
              f"{r['rms_ah']:12.4f} {r['vtc6_rms_ah']:12.4f}")
    print("next-20 forecasts, each life held out:")
    for r in forecast_score(lives):
        print(f"{r['cell']:6} {r['temperature_c']:5.0f} {r['forecasts']:5d} rms {r['rms_ah']:.4f} Ah, "
              f"90% band coverage {r['coverage90']:.3f}")


if __name__ == "__main__":  # pragma: no cover
    _main()

"""How the paper's NASA cell ages: the aging law's form (:class:`~uam_studio.fleet.aging.AgingLaw`) fitted to
the NASA PCoE lives (``../shared/data/nasa_pcoe``: 26 cells cycled to end of life at 4, 24 and 43 C), and a
pack's belief of its own capacity, updated from its own discharges.

- :func:`nasa_life_points`: each life's measured capacity per discharge (Ah, the dataset's ``Capacity``
  column of ``metadata.csv``: each discharge to the cell's cut-off), the equivalent full cycles delivered
  before it (the sum of the earlier discharges' capacities over the first), the cell's median ambient (C)
  and its impedance tests' resistance ``Re + Rct`` (ohm): a measurement, where the CMU law has a proxy; and
  the rest before each discharge (h, from the table's ``start_time``).
- :func:`fit_nasa_law` / :func:`nasa_leave_one_cell_out`: the law on NASA lives, and each life scored by
  the law fitted on the others, beside the VTC6 law (:data:`~uam_studio.fleet.aging.AGING_LAW`) on the
  same life as the baseline.
- :class:`RestRecovery` / :func:`fit_rest_recovery`: the capacity a long rest gives back for some discharges
  (the NASA lives jump 2-6% after rests of a day or more, then fade back to their trend).
- :class:`CapacityBelief`: capacity ``C0 (1 - s g(efc)) + r`` with ``g`` the law's fade and ``r`` what rests
  gave back, a Gaussian belief updated by each discharge's measured capacity and the rest before it;
  :func:`forecast_score` scores its next-``horizon`` forecasts (RMS, Ah, and 90% band coverage) on lives
  held out of the law's and the rests' fits.

:data:`NASA_AGING_LAW` and :data:`NASA_REST_RECOVERY` hold the numbers fitted on all 25 lives (in-sample for
them); ``python -m uam_studio.fleet.nasa_aging`` refits and prints them with the leave-one-cell-out tables.
"""

from __future__ import annotations

import csv
import datetime
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from uam_studio.battery.aging import AGING_LAW, NASA_AGING_LAW, T_REF_C, AgingLaw
from uam_studio.battery.parameters import ZERO_C
from uam_studio.battery.real.nasa_data import NasaDataError, load_nasa_folder, nasa_folder
from uam_studio.errors import InputError
from uam_studio.fleet.aging import LifePoints, fit_resistance_growth
from uam_studio.risk import INTERVAL_Z

__all__ = ["NASA_AGING_LAW", "NASA_REST_RECOVERY", "CapacityBelief", "RestRecovery", "fit_nasa_law",
           "fit_rest_recovery", "forecast_score", "law_floor_rms", "nasa_leave_one_cell_out",
           "nasa_life_points", "smooth_floor_rms"]

MIN_POINTS = 10  # a life with fewer measured capacities is too short to fit or score
REFERENCE_N = 5  # a life's reference capacity is the median of its first this many
REST_REF_H = 8.0  # h: a longer rest than this (about two charges and their pauses) gives capacity back
DRIFT = 0.3  # a belief's C0 random walk per discharge, in units of its noise (in-sample: chosen for 90-96% coverage
# on the 2 A lives before rests were modelled)


def _number(text: str) -> float:
    """A number as the table writes it (ohm or Ah): a complex entry (``(a+bj)``) gives its real part, an
    empty or ``[]`` one NaN."""
    try:
        return float(complex(text.strip()).real)
    except ValueError:
        return math.nan  # '' and '[]': no measurement


def _start_s(text: str) -> float:
    """A cycle's start as the table writes it (``[2010. 7. 21. 15. 0. 35.093]``: year, month, day, hour,
    minute, second) in seconds (UTC taken as its clock), or NaN if it does not read."""
    try:
        y, mo, d, h, mi, sec = (float(v) for v in text.strip().strip("[]").split())
        start = datetime.datetime(int(y), int(mo), int(d), int(h), int(mi), tzinfo=datetime.timezone.utc)
    except ValueError:
        return math.nan
    return start.timestamp() + sec


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
    for nasa in load_nasa_folder(folder, [c for c in sorted(rows) if (folder / f"{c}.csv.gz").is_file()]):
        for d in nasa.discharges:
            condition[(nasa.name, d.uid)] = (round(d.mean_load_a() * 2) / 2, round(d.ambient_c / 5) * 5)
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
        start = np.array([_start_s(r["start_time"]) for r in dis])
        rest_h = np.r_[np.nan, np.diff(start) / 3600.0][keep]
        out.append(LifePoints(cell, efc, cap_all[keep], np.flatnonzero(keep), float(main[1]),
                              np.interp(ir_uid[good], uid, np.r_[0.0, np.cumsum(cap_all[:-1])] / ref), ir[good],
                              rest_h))
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
    inv = [1.0 / (T_REF_C + ZERO_C) - 1.0 / (lf.temperature_c + ZERO_C) for lf in lives]
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


def law_floor_rms(lf: LifePoints) -> float:
    """The least RMS (Ah) :func:`_rms` can give on ``lf`` for any law of the fleet's form: at the life's
    temperature the law is ``reference (1 - A efc^b)``, so (``A``, ``b``) fitted to the life itself by least
    squares (in-sample; several starts of ``b`` in 0.2-3) bound from below every fit of it on other lives."""
    x, c, ref = lf.efc[1:], lf.capacity_ah[1:], reference_ah(lf)
    best = math.inf
    for b0 in (0.3, 0.5, 1.0, 1.5, 2.5):
        start = np.r_[math.log(0.1) - b0 * math.log(max(float(x.max()), 2.0)), b0]  # 10% fade at the life's end
        sol = least_squares(lambda p: ref * (1.0 - np.exp(p[0]) * x ** p[1]) - c, start,
                            bounds=(np.r_[-40.0, 0.2], np.r_[5.0, 3.0]))
        best = min(best, float(np.sqrt(np.mean(sol.fun ** 2))))
    return best


def smooth_floor_rms(lf: LifePoints, degree: int = 3) -> float:
    """RMS (Ah), over the points :func:`_rms` scores, of the best polynomial of ``degree`` in equivalent full
    cycles fitted to the life itself (in-sample, least squares, its own level): the scatter and the rests'
    jumps that a smooth curve of as many parameters leaves, whatever its form."""
    x, c = lf.efc[1:], lf.capacity_ah[1:]
    fit = np.polynomial.Polynomial.fit(x, c, min(degree, max(x.size - 1, 0)))
    return float(np.sqrt(np.mean((c - fit(x)) ** 2)))


def nasa_leave_one_cell_out(lives: list[LifePoints]) -> list[dict]:
    """Per life: capacity RMS (Ah) of the NASA law fitted on the other lives, of the VTC6 law, and the life's
    :func:`law_floor_rms` and :func:`smooth_floor_rms`."""
    return [{"cell": lf.cell, "temperature_c": lf.temperature_c, "discharges": int(lf.efc.size),
             "first_ah": float(lf.capacity_ah[0]), "last_ah": float(lf.capacity_ah[-1]),
             "rms_ah": _rms(fit_nasa_law([x for x in lives if x.cell != lf.cell]), lf),
             "vtc6_rms_ah": _rms(AGING_LAW, lf), "law_floor_rms_ah": law_floor_rms(lf),
             "cubic_floor_rms_ah": smooth_floor_rms(lf)} for lf in lives]


@dataclass(frozen=True)
class RestRecovery:
    """Capacity a long rest gives back for a while (a cell's electrolyte re-equilibrates): a discharge after a
    rest of ``h`` hours holds ``beta * C_ref * ln(h / REST_REF_H)`` Ah more (nothing for ``h <=``
    :data:`REST_REF_H`; ``C_ref`` the life's reference capacity, Ah), and what was given back fades by the
    factor ``rho`` each discharge; what successive rests give back adds up. ``RestRecovery()`` gives nothing
    back."""

    rho: float = 0.0
    beta: float = 0.0

    def boost(self, rest_h: np.ndarray, ref_ah: float) -> np.ndarray:
        """Capacity (Ah) each rest (h; NaN: unknown, nothing) gives back at the next discharge."""
        h = np.nan_to_num(np.asarray(rest_h, dtype=float), nan=0.0)
        return self.beta * ref_ah * np.log(np.maximum(h / REST_REF_H, 1.0))

    def series(self, lf: LifePoints, ref_ah: float) -> np.ndarray:
        """What the rests of a life give back (Ah) at each of its discharges (zeros without ``rest_h``)."""
        if lf.rest_h is None:
            return np.zeros(lf.efc.size)
        out, r = np.zeros(lf.efc.size), 0.0
        for k, b in enumerate(self.boost(lf.rest_h, ref_ah)):
            r = self.rho * r + b
            out[k] = r
        return out


NASA_REST_RECOVERY = RestRecovery(rho=0.96, beta=0.0159001)  # fit_rest_recovery with NASA_AGING_LAW, all 25 lives


def fit_rest_recovery(law: AgingLaw, lives: list[LifePoints]) -> RestRecovery:
    """``rho`` (on a grid of 0.50-0.98) and ``beta`` of :class:`RestRecovery` fitted to ``lives`` with the
    law's fade and a free (``C0``, ``C0 s``) per life, robust loss as :func:`fit_nasa_law`'s. Lives without
    ``rest_h`` say nothing of rests: with none, nothing is given back."""
    dated = [lf for lf in lives if lf.rest_h is not None]
    if not dated:
        return RestRecovery()
    g = [1.0 - law.capacity_fraction(lf.efc, lf.temperature_c) for lf in dated]
    refs = [reference_ah(lf) for lf in dated]
    best: tuple[float, RestRecovery] | None = None
    for rho in np.linspace(0.5, 0.98, 25):
        shape = [RestRecovery(float(rho), 1.0).series(lf, ref) for lf, ref in zip(dated, refs)]

        def residual(p: np.ndarray, shape: list[np.ndarray] = shape) -> np.ndarray:
            return np.concatenate([p[1 + 2 * i] - p[2 + 2 * i] * g[i] + p[0] * shape[i] - lf.capacity_ah
                                   for i, lf in enumerate(dated)])

        x0 = np.r_[0.0, np.ravel([[ref, ref] for ref in refs])]
        fit = least_squares(residual, x0, loss="soft_l1", f_scale=0.02)
        if best is None or fit.cost < best[0]:
            best = (float(fit.cost), RestRecovery(float(rho), float(max(fit.x[0], 0.0))))
    assert best is not None
    return best[1]


@dataclass
class CapacityBelief:
    """A pack's Gaussian belief on (``C0`` Ah, ``C0 s`` Ah, ``r`` Ah): capacity at ``efc`` is
    ``C0 - C0 s g(efc) + r``, ``g`` the law's fade at the pack's temperature and ``r`` what rests gave back
    (:class:`RestRecovery`: it grows by a rest's boost before a discharge and fades by ``rho`` each one).
    Starts at the first measured capacity (sd ``c0_sd``), the law's fade (s = 1, sd ``s_sd``) and r = 0;
    each measured capacity (noise sd ``noise_ah``) updates it. A forecast knows no rest ahead: what was given
    back fades."""

    law: AgingLaw
    temperature_c: float
    mean: np.ndarray
    cov: np.ndarray
    noise_ah: float
    recovery: RestRecovery = RestRecovery()
    ref_ah: float = 0.0

    @classmethod
    def start(cls, law: AgingLaw, first_ah: float, temperature_c: float, noise_ah: float,
              c0_sd: float = 0.03, s_sd: float = 0.7, recovery: RestRecovery | None = None) -> CapacityBelief:
        return cls(law, temperature_c, np.array([first_ah, first_ah, 0.0]),
                   np.diag([c0_sd ** 2, (s_sd * first_ah) ** 2, 0.0]), noise_ah,
                   recovery if recovery is not None else RestRecovery(), first_ah)

    def _row(self, efc: float) -> np.ndarray:
        return np.array([1.0, -(1.0 - float(self.law.capacity_fraction(efc, self.temperature_c))), 1.0])

    def observe(self, efc: float, capacity_ah: float, rest_h: float = math.nan) -> None:
        """Take one measured capacity (Ah) at ``efc``, after a rest of ``rest_h`` hours (NaN: unknown), in (a
        Kalman update), after the belief's random walk of one discharge (``C0`` drifts by ``noise_ah`` *
        DRIFT a discharge: what the law and the rests do not hold) and the rest's boost."""
        rho = self.recovery.rho
        boost = float(self.recovery.boost(np.array([rest_h]), self.ref_ah)[0])
        self.mean = np.array([self.mean[0], self.mean[1], rho * self.mean[2] + boost])
        f = np.diag([1.0, 1.0, rho])
        self.cov = f @ self.cov @ f.T + np.diag([(DRIFT * self.noise_ah) ** 2, 0.0, 0.0])
        h = self._row(efc)
        s = float(h @ self.cov @ h) + self.noise_ah ** 2
        k = self.cov @ h / s
        self.mean = self.mean + k * (capacity_ah - float(h @ self.mean))
        self.cov = self.cov - np.outer(k, h @ self.cov)

    def forecast(self, efc: np.ndarray, z: float = INTERVAL_Z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(mean, low, high) capacity (Ah) at each ``efc``, the h-th of them h discharges ahead (the random
        walk grows with h, what rests gave back fades by ``rho ** h``): the 90% band by default."""
        rows = np.array([self._row(e) for e in np.atleast_1d(efc)])
        rows[:, 2] = self.recovery.rho ** np.arange(1, rows.shape[0] + 1)
        mean = rows @ self.mean
        walk = (DRIFT * self.noise_ah) ** 2 * np.arange(1, rows.shape[0] + 1)
        sd = np.sqrt(np.einsum("ij,jk,ik->i", rows, self.cov, rows) + walk + self.noise_ah ** 2)
        return mean, mean - z * sd, mean + z * sd


def _noise(law: AgingLaw, lives: list[LifePoints], recovery: RestRecovery = RestRecovery()) -> float:
    """The discharge-to-discharge scatter (Ah) about each life's own fade and what its rests gave back: the
    robust scale of the residuals of a per-life (C0, C0 s) fit."""
    res = []
    for lf in lives:
        g = 1.0 - law.capacity_fraction(lf.efc, lf.temperature_c)
        cap = lf.capacity_ah - recovery.series(lf, reference_ah(lf))
        coef = np.linalg.lstsq(np.column_stack([np.ones_like(g), -g]), cap, rcond=None)[0]
        res.append(cap - coef[0] + coef[1] * g)
    r = np.concatenate(res)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def _forecast_errors(lf: LifePoints, belief: CapacityBelief, horizon: int, start: int
                     ) -> tuple[list[float], list[bool]]:
    """A life flown through ``belief``: after each of its discharges from ``start`` on, the next ``horizon``
    capacities forecast; (errors Ah, inside the 90% band)."""
    rest_h = lf.rest_h if lf.rest_h is not None else np.full(lf.efc.size, np.nan)
    errs: list[float] = []
    inside: list[bool] = []
    for k in range(1, lf.efc.size):
        if k >= start and k + 1 < lf.efc.size:
            ahead = slice(k, min(k + horizon, lf.efc.size))
            mean, lo, hi = belief.forecast(lf.efc[ahead])
            truth = lf.capacity_ah[ahead]
            errs += list(mean - truth)
            inside += list((lo <= truth) & (truth <= hi))
        belief.observe(float(lf.efc[k]), float(lf.capacity_ah[k]), float(rest_h[k]))
    return errs, inside


def forecast_score(lives: list[LifePoints], horizon: int = 20, start: int = 5,
                   cells: list[str] | None = None, rests: bool = True, in_sample: bool = False) -> list[dict]:
    """Each life, held out of the law's fit, of the rests' (:func:`fit_rest_recovery`; ``rests=False``: none)
    and of the noise's: after each of its discharges from ``start`` on, the belief forecasts the next
    ``horizon`` capacities. Per life (only ``cells`` if given): forecasts scored, RMS error (Ah) and the 90%
    band's coverage. ``in_sample``: a reference, not a prediction: the law fitted on all ``lives`` and the
    rests and the noise on the scored life itself, so what the belief's form reaches with the life's own
    numbers."""
    out = []
    law_all = fit_nasa_law(lives) if in_sample else None
    for lf in lives:
        if cells is not None and lf.cell not in cells:
            continue
        others = [x for x in lives if x.cell != lf.cell]
        law = law_all if law_all is not None else fit_nasa_law(others)
        fitted_on = [lf] if in_sample else others
        recovery = fit_rest_recovery(law, fitted_on) if rests else RestRecovery()
        noise = _noise(law, fitted_on, recovery)
        belief = CapacityBelief.start(law, reference_ah(lf), lf.temperature_c, noise, recovery=recovery)
        errs, inside = _forecast_errors(lf, belief, horizon, start)
        if errs:
            out.append({"cell": lf.cell, "temperature_c": lf.temperature_c, "forecasts": len(errs),
                        "rms_ah": float(math.sqrt(np.mean(np.square(errs)))), "coverage90": float(np.mean(inside))})
    return out


def _main() -> None:  # pragma: no cover - the fitting command (RESULTS.md, "NASA lives in the fleet's aging law")
    lives = nasa_life_points()
    law = fit_nasa_law(lives)
    print(f"AgingLaw(a={law.a:.6g}, b={law.b:.6g}, ea_k={law.ea_k:.6g}, k_r={law.k_r:.6g})  (all {len(lives)} lives)")
    print(f"{'cell':6} {'T C':>5} {'n':>4} {'first':>6} {'last':>6} {'NASA law rms':>12} {'VTC6 law rms':>12} "
          f"{'law floor':>9} {'cubic':>7}  (floors: the law's form, and a cubic, fitted to the life itself)")
    for r in nasa_leave_one_cell_out(lives):
        print(f"{r['cell']:6} {r['temperature_c']:5.0f} {r['discharges']:4d} {r['first_ah']:6.3f} {r['last_ah']:6.3f} "
              f"{r['rms_ah']:12.4f} {r['vtc6_rms_ah']:12.4f} {r['law_floor_rms_ah']:9.4f} "
              f"{r['cubic_floor_rms_ah']:7.4f}"
              + ("  half the VTC6 rms out of this form's reach" if r["law_floor_rms_ah"] > r["vtc6_rms_ah"] / 2
                 else ""))
    rec = fit_rest_recovery(law, lives)
    print(f"RestRecovery(rho={rec.rho:.6g}, beta={rec.beta:.6g})  (all {len(lives)} lives)")
    print("next-20 forecasts, each life held out; then in-sample (the life's own rests and noise; a reference):")
    for r, own in zip(forecast_score(lives), forecast_score(lives, in_sample=True)):
        print(f"{r['cell']:6} {r['temperature_c']:5.0f} {r['forecasts']:5d} rms {r['rms_ah']:.4f} Ah, "
              f"90% band coverage {r['coverage90']:.3f} | in-sample rms {own['rms_ah']:.4f} Ah, "
              f"coverage {own['coverage90']:.3f}")


if __name__ == "__main__":  # pragma: no cover
    _main()

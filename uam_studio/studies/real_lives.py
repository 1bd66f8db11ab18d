"""Leave one cell out over the four resampled lives of the CMU eVTOL dataset: every baseline mission's
landing predicted from the pack's own earlier flight, on a parameter set that never read the cell.

For each life (VAH07, VAH09, VAH27, VAH30) held out in turn:

1. **The parameter set** is identified on the other three (:func:`identify_without`: each one's first
   C/5 reference discharge and first four missions, the recipe of
   :func:`~uam_studio.battery.real.cmu_replay.vtc6_fit_segments`); nothing of the held-out cell is read.
2. **The health** for mission k comes from mission k-1 of the same cell (:func:`fit_mission`): q_max
   (C) and R0 (ohm) fitted to all its clean samples along its interpolated current, from a rested start
   whose charge matches the rest voltage measured before its take-off (the rule of step 3; a sample
   before the take-off that is below a later one of the mission is no rest before it,
   :func:`rest_before`: that mission gives no health and is not predicted), with a
   Laplace covariance whose std is the residuals' own and, where they are not white noise, the HAC
   factor of :mod:`uam_studio.battery.health.quality` (the model's discrepancy).
3. **The prediction** (:func:`predict_landing`): mission k flown along its own interpolated current from
   a rested start whose charge matches the rest voltage measured just before its take-off, for 200
   draws of that health; the 90% interval of the voltage at each of its landing's sampled times. A
   drawn cell that passed the cut-off (2.5 V) reads the cut-off from then on; within the landing,
   which holds one current, each draw's voltage is its lowest so far (a rise under that load is the
   model past its fitted charge range, not the cell).

Scored at the sampled times, never against a sampled minimum (sampling misses the true minimum):
coverage of the 90% interval, and per cut-off from 3.0 to 3.3 V, missed breaches (the interval's lower
end at or above the cut-off where the measured voltage is below it), also for a one-sided safety
bound at :data:`SAFETY_LEVEL`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from uam_studio.battery.health.estimate import FIT_Q_RANGE
from uam_studio.battery.health.quality import (
    excess_factor,
    hac_covariance,
    not_white,
    residual_autocorrelation,
)
from uam_studio.battery.parameters import ZERO_C, Cell, CellParameters
from uam_studio.battery.real.cmu_data import (
    LANDING,
    LIFE_FILES,
    CellLog,
    ResampledMission,
    data_folder,
    load_cell_log,
)
from uam_studio.battery.real.cmu_data import resampled_missions as find_missions
from uam_studio.battery.real.cmu_replay import (
    START_Q_MAX,
    START_R0,
    mission_current,
    mission_segment,
    reference_segment,
    vtc6_start,
)
from uam_studio.battery.real.identify import FitSegment, identify_cell
from uam_studio.battery.simulate import simulate
from uam_studio.battery.solver import output_voltage
from uam_studio.battery.state import rested_state
from uam_studio.errors import InputError, check_range

CUTOFFS_V = (3.0, 3.05, 3.1, 3.15, 3.2, 3.25, 3.3)
LEVEL = 0.9
SAFETY_LEVEL = 0.99  # the one-sided safety bound: a measurement below it 1 time in 100 at most
N_DRAWS = 200
EOD_V = 2.5  # V: the simulations' cut-off; a drawn cell past it reads this voltage
REMOVED_START_C = 2160.0  # C: the identification's start for a mission's charge out of full (a 4.0 V charge)
_STEP = np.array([1e-4, 1e-4])  # finite-difference steps in (ln q_max, ln R0)
LIFE_NAMES = tuple(name.split(".")[0] for name in LIFE_FILES)  # the cells' names, "VAH07" ...
_LN_R0 = (np.log(1e-4), np.log(1.0))  # ln ohm: the box of R0 (draws and fits); q_max: the health fit's box


@dataclass
class MissionFit:
    """:func:`fit_mission`'s result: (ln q_max, ln R0) with its covariance (already multiplied by
    ``factor``), the RMS residual (V) and the model-discrepancy factor (>= 1)."""

    theta: np.ndarray
    cov: np.ndarray
    rms_v: float
    factor: float


@dataclass
class LifeScore:
    """One held-out cell: missions predicted (``unfit``: those whose previous mission gave no health
    fit, predicted from the last health that an earlier one gave; ``grounded``: those with no rest
    before their take-off, :func:`rest_before`, not predicted and so never cleared: their breaches
    are counted, none missed, their samples not scored), landing samples scored, breaches
    (over all cut-offs x samples); covered samples and missed breaches of the calibrated interval
    (the model's error included, :func:`conformal_margin`) and of the health-only one (``raw_``); each
    sample's (measured, low, median, high) voltage (V) of the calibrated interval (an infinite end: no
    calibration yet). ``strict_missed``: missed breaches of the one-sided safety bound at
    :data:`SAFETY_LEVEL` (the health-only low end less the conformal margin of earlier low-side
    scores at that level)."""

    cell: str
    missions: int = 0
    unfit: int = 0
    grounded: int = 0
    samples: int = 0
    breaches: int = 0
    inside: int = 0
    missed: int = 0
    raw_inside: int = 0
    raw_missed: int = 0
    strict_missed: int = 0
    rows: list[tuple[float, float, float, float]] = field(default_factory=list)

    @property
    def coverage(self) -> float:
        return self.inside / self.samples if self.samples else float("nan")

    @property
    def raw_coverage(self) -> float:
        return self.raw_inside / self.samples if self.samples else float("nan")

    @property
    def median_width_mv(self) -> float | None:
        """Median width (mV) of the calibrated intervals that are finite; None where none is."""
        finite = [1000 * (hi - lo) for _, lo, _, hi in self.rows if np.isfinite(hi - lo)]
        return float(np.median(finite)) if finite else None

    @property
    def goals_met(self) -> bool:
        """The issue's goals for one cell: coverage 80-98% and no missed breach of the 90% interval."""
        return bool(0.8 <= self.coverage <= 0.98 and self.missed == 0)

    def as_dict(self) -> dict:
        """The counts, coverages, median width and :attr:`goals_met`, without the per-sample rows (JSON-ready:
        None for a coverage or width with no sample behind it)."""
        out = {k: v for k, v in asdict(self).items() if k != "rows"}
        return out | {"coverage": self.coverage if self.samples else None,
                      "raw_coverage": self.raw_coverage if self.samples else None,
                      "median_width_mv": self.median_width_mv, "goals_met": self.goals_met}


def conformal_margin(scores: list[float], level: float = LEVEL) -> float:
    """The split-conformal margin (V) from the nonconformity scores of earlier predictions (each
    max(low - measured, measured - high), V): their ceil((n + 1) level)-th smallest, negative where
    earlier intervals held their measurements with room to spare; inf while there are too few (fewer
    than level / (1 - level)) for a finite one."""
    n = len(scores)
    k = int(np.ceil((n + 1) * level))
    if k > n:
        return float("inf")
    return float(np.sort(scores)[k - 1])


def calibrated(low: float, median: float, high: float, margin: float) -> tuple[float, float]:
    """The health-only interval (V) moved out by ``margin`` (V) at both ends (in, where it is negative),
    never past the median draw's voltage: the prediction stays inside its interval."""
    return min(low - margin, median), max(high + margin, median)


def segments_without(folder: str | Path, held: str, n_missions: int = 4) -> list[FitSegment]:
    """The identification data without the life ``held`` (a file name of
    :data:`~uam_studio.battery.real.cmu_data.LIFE_FILES`): each other life's first C/5 reference discharge
    and its first ``n_missions`` missions, named after their cell."""
    if held not in LIFE_FILES:
        raise InputError("held", f"{held!r}; allowed {', '.join(LIFE_FILES)}")
    folder = Path(folder)
    segs = []
    for name in LIFE_FILES:
        if name == held:
            continue
        log = load_cell_log(folder / name)
        segs.append(reference_segment(log, name=f"{log.name} c5"))
        segs += [mission_segment(log, m, f"{log.name} mission {j}", REMOVED_START_C)
                 for j, m in enumerate(find_missions(log)[:n_missions])]
    return segs


def identify_without(folder: str | Path, held: str, n_missions: int = 4, max_nfev: int = 300) -> Cell:
    """The VTC6 parameter set identified on :func:`segments_without` ``held``."""
    fit = identify_cell(segments_without(folder, held, n_missions), vtc6_start(), START_Q_MAX, START_R0,
                        max_nfev=max_nfev)
    return Cell(f"VTC6 identified without {held}", fit.cell, fit.q_max, fit.r0)


def _params(cell: Cell, log: CellLog, mission: ResampledMission) -> CellParameters:
    return replace(cell.params, t_ambient_k=ZERO_C + float(log.temperature_c[mission.index[0]]))


def _voltages(thetas: np.ndarray, rest_v: float, current: np.ndarray, params: CellParameters) -> np.ndarray:
    """Voltage [N, T] (V) of cells at (ln q_max, ln R0) ``thetas`` [N, 2], each from the rested charge
    that shows ``rest_v`` (V), along ``current`` [T] (A, 1 s steps); :data:`EOD_V` after a cell's cut-off."""
    q, r = np.exp(thetas[:, 0]), np.exp(thetas[:, 1])
    x0 = rested_state(q, _removed_for_rest(q, rest_v, params), params)
    res = simulate(np.broadcast_to(current, (len(thetas), current.size)), 1.0, q, r, eod_v=EOD_V, initial_state=x0,
                   cell=params)
    return np.where(res.valid, res.voltage_v, EOD_V)


def rest_before(log: CellLog, mission: ResampledMission) -> float | None:
    """The voltage (V) of the sample before the mission's take-off, where it can be the cell's rest
    before it: at least every voltage the mission's clean samples show after it (a loaded or recovering
    cell is never above its rest before a discharge); None otherwise (that sample is not the rest the
    mission started from)."""
    rest = float(log.voltage_v[mission.index[0]])
    after = log.voltage_v[mission.index[1:]][mission.segment[1:] >= 0]
    return rest if after.size == 0 or rest >= float(after.max()) else None


def fit_mission(log: CellLog, mission: ResampledMission, cell: Cell, max_iter: int = 40) -> MissionFit | None:
    """q_max and R0 of one resampled mission (module docstring, step 2); None where it has too few clean
    samples (fewer than 5), no rest before its take-off (:func:`rest_before`) or a covariance that is
    not positive definite (the data do not fix both)."""
    cur, observed = mission_current(log, mission, 1.0)
    keep = observed >= 0
    rest_v = rest_before(log, mission)
    if keep.sum() < 5 or rest_v is None:
        return None
    obs, meas = observed[keep], log.voltage_v[mission.index[keep]]
    params = _params(cell, log, mission)
    theta = np.array([np.log(cell.q_max), np.log(cell.r0)])
    low, high = [np.log(FIT_Q_RANGE[0]), _LN_R0[0]], [np.log(FIT_Q_RANGE[1]), _LN_R0[1]]
    lam = 1e-2

    def evaluate(t):
        pts = np.vstack([t, t + np.diag(_STEP)])
        v = _voltages(pts, rest_v, cur, params)[:, obs]
        return meas - v[0], (v[1:] - v[0]).T / _STEP

    r, j = evaluate(theta)
    cost = float(r @ r)
    for _ in range(max_iter):
        a = j.T @ j
        step = np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-12), j.T @ r)
        trial = theta + step
        trial = np.clip(trial, low, high)
        r_t, j_t = evaluate(trial)
        if np.all(np.isfinite(r_t)) and float(r_t @ r_t) <= cost:
            done = cost - float(r_t @ r_t) < 1e-10
            theta, r, j, cost, lam = trial, r_t, j_t, float(r_t @ r_t), max(lam * 0.3, 1e-9)
            if done:
                break
        else:
            lam *= 10.0
            if lam > 1e8:
                break
    n = r.size
    s2 = max(cost / max(n - 2, 1), (0.5e-3) ** 2)
    try:
        cov = s2 * np.linalg.inv(j.T @ j)
        rho = float(residual_autocorrelation(r[None])[0])
        white = not not_white(np.asarray(rho), np.asarray(n))
        factor = 1.0 if white else excess_factor(cov, hac_covariance(j, r, np.ones(n, bool), rho))
        np.linalg.cholesky(cov * factor)
    except np.linalg.LinAlgError:
        return None
    return MissionFit(theta, cov * factor, float(np.sqrt(cost / n)), factor)


def _removed_for_rest(q: np.ndarray, rest_v: float, params: CellParameters) -> np.ndarray:
    """Charge out of full (C) at which a rested cell of each q_max (C) shows ``rest_v`` (V): bisection."""
    lo, hi = np.zeros_like(q), 0.95 * q
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        x = rested_state(q, mid, params)
        v = output_voltage(x.__dict__, params.q_total(q), params)
        above = v > rest_v  # still too full
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return 0.5 * (lo + hi)


def _landing_samples(log: CellLog, mission: ResampledMission) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mission's interpolated current (A, 1 s steps), and the step and measured voltage (V) of each
    of its landing's clean samples."""
    cur, observed = mission_current(log, mission, 1.0)
    at = (mission.segment == LANDING) & (observed >= 0)
    return cur, observed[at], log.voltage_v[mission.index[at]]


def predict_landing(log: CellLog, mission: ResampledMission, cell: Cell, health: MissionFit,
                    rng: np.random.Generator) -> list[tuple[float, float, float, float]]:
    """(measured, low, median, high) voltage (V) at each sampled time of the mission's landing, the
    interval at :data:`LEVEL` over :data:`N_DRAWS` draws of ``health`` (module docstring, step 3); none
    where the mission has no rest before its take-off (:func:`rest_before`)."""
    cur, steps, meas = _landing_samples(log, mission)
    rest_v = rest_before(log, mission)
    if not steps.size or rest_v is None:
        return []
    params = _params(cell, log, mission)
    chol = np.linalg.cholesky(health.cov + np.eye(2) * 1e-14)
    draws = np.vstack([health.theta, health.theta + rng.standard_normal((N_DRAWS, 2)) @ chol.T])
    draws = np.column_stack([np.clip(draws[:, 0], *np.log(FIT_Q_RANGE)), np.clip(draws[:, 1], *_LN_R0)])
    v = _voltages(draws, rest_v, cur, params)
    land = int(mission.phase_starts_s()[LANDING])
    v[:, land:] = np.minimum.accumulate(v[:, land:], axis=1)
    v = v[:, steps]
    lo, hi = np.quantile(v[1:], [(1 - LEVEL) / 2, (1 + LEVEL) / 2], axis=0)
    return [(float(m), float(a), float(c), float(b)) for m, a, c, b in zip(meas, lo, v[0], hi)]


def score_life(log: CellLog, cell: Cell, seed: int = 38200, every: int = 1) -> LifeScore:
    """Every ``every``-th mission of a life predicted from the one before it (module docstring). The
    calibrated interval moves the health-only one's ends by :func:`conformal_margin` of the scores of
    this cell's earlier predictions (:func:`calibrated`; its own earlier flights only: online, never the
    mission scored)."""
    missions = find_missions(log)
    score = LifeScore(log.name)
    rng = np.random.default_rng([seed, sum(map(ord, log.name))])
    past: list[float] = []
    past_low: list[float] = []  # how far earlier measurements fell below the health-only low end (V)
    health = None
    for k in range(1, len(missions), every):
        fit = fit_mission(log, missions[k - 1], cell)
        score.unfit += fit is None
        health = fit or health  # no fit: the last health the cell's flights gave
        if rest_before(log, missions[k]) is None:  # its start unknown: not predicted, so never cleared
            score.grounded += 1
            score.breaches += sum(int(m < c) for m in _landing_samples(log, missions[k])[2] for c in CUTOFFS_V)
            continue
        if health is None:
            continue
        rows = predict_landing(log, missions[k], cell, health, rng)
        if not rows:
            continue
        margin = conformal_margin(past)
        strict = max(conformal_margin(past_low, SAFETY_LEVEL), 0.0)  # never above the health-only low end
        score.missions += 1
        for meas, lo, med, hi in rows:
            low, high = calibrated(lo, med, hi, margin)
            score.samples += 1
            score.raw_inside += lo <= meas <= hi
            score.inside += low <= meas <= high
            score.rows.append((meas, low, med, high))
            for cut in CUTOFFS_V:
                breached = meas < cut
                score.breaches += breached
                score.raw_missed += breached and lo >= cut
                score.missed += breached and low >= cut
                score.strict_missed += breached and lo - strict >= cut
        past += [max(lo - meas, meas - hi) for meas, lo, _, hi in rows]
        past_low += [lo - meas for meas, lo, _, _ in rows]
    return score


def life_file(cell: str) -> str:
    """The file of :data:`~uam_studio.battery.real.cmu_data.LIFE_FILES` for a cell's name ("VAH27") or file name."""
    for name, short in zip(LIFE_FILES, LIFE_NAMES):
        if cell in (name, short):
            return name
    raise InputError("cell", f"{cell!r}; allowed {', '.join(LIFE_NAMES)}")


def leave_one_cell_out(data: str | Path | None = None, every: int = 1, seed: int = 38200,
                       max_nfev: int = 100, cells: Sequence[str] | None = None) -> list[LifeScore]:
    """The table of the module docstring: one :class:`LifeScore` per life (``cells``: only these, by
    name, e.g. ``["VAH27"]``; default all four), each on the parameter set identified without it
    (``max_nfev``: the identification's evaluations, each with a 25-column finite-difference Jacobian;
    100 take about 1.5 min per set); every ``every``-th mission scored."""
    check_range("every", every, 1, 1000)
    check_range("max_nfev", max_nfev, 1, 10_000)
    if isinstance(cells, str):
        raise InputError("cells", f"{cells!r}: a list of cell names, e.g. [{cells!r}]")
    names = [life_file(c) for c in cells] if cells is not None else list(LIFE_FILES)
    if not names:
        raise InputError("cells", f"an empty list; allowed None (all four) or names from {', '.join(LIFE_NAMES)}")
    folder = data_folder(data, needs=names[0])
    return [score_life(load_cell_log(folder / name), identify_without(folder, name, max_nfev=max_nfev), seed, every)
            for name in dict.fromkeys(names)]


def totals_line(scores: Sequence[LifeScore]) -> str:
    """The missed breaches of all cells, and whether every cell met the goals (:attr:`LifeScore.goals_met`)."""
    return (f"missed breaches: 90% interval {sum(s.missed for s in scores)}, one-sided 99% bound "
            f"{sum(s.strict_missed for s in scores)}, health-only {sum(s.raw_missed for s in scores)} of "
            f"{sum(s.breaches for s in scores)} breaching (cut-off x sample) pairs; goals (coverage 80-98% per "
            "cell, 0 missed breaches): " + ("met" if scores and all(s.goals_met for s in scores) else "NOT met"))


def format_scores(scores: list[LifeScore]) -> str:
    """The table as plain text: calibrated (health-only in brackets)."""
    out = [f"{'cell':6s} {'missions':>8s} {'landing samples':>15s} {'90% coverage':>16s} "
           f"{'median width mV':>15s} {'breaches':>8s} {'missed':>11s} {'missed, 99% bound':>17s} {'unfit':>5s} "
           f"{'grounded':>8s}  (health-only interval in brackets; width over the finite intervals; unfit: missions "
           "whose previous one gave no health fit, predicted from the last health fitted; grounded: no rest before "
           "the take-off, not predicted, their breaches counted, none missed)"]
    for s in scores:
        width = s.median_width_mv
        width = width if width is not None else float("nan")
        out.append(f"{s.cell:6s} {s.missions:8d} {s.samples:15d} {s.coverage:7.3f} ({s.raw_coverage:.3f}) "
                   f"{width:15.0f} {s.breaches:8d} {s.missed:4d} ({s.raw_missed:4d}) {s.strict_missed:17d} "
                   f"{s.unfit:5d} {s.grounded:8d}")
    return "\n".join(out)

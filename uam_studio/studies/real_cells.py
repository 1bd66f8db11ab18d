"""Validation on real cells (the CMU eVTOL dataset): how wrong are the battery, health and safety
models on a real VTC6? Every row is scored on measurements; the held-out status of each is named.

:func:`real_cell_report` computes the table that ``uam-studio evaluate real --data PATH`` prints and
``benchmarks/bench_real_cells.py`` times. Sections:

- physics: the mission flown on the model by its protocol's power (W per segment, from a full cell),
  against the measured voltage of cell VAH01's 1 Hz mission: RMSE (mV) and the error of the lowest
  (landing) voltage (mV), for the bundled VTC6 set (its fit read this mission), refits that held out the
  landing or the whole cell, and the NASA cell (as bundled, and with q_max/R0 fitted to the mission);
- health: q_max/R0 fitted to the first 20/60/120 s of the mission (with the VTC6 fleet's prior, as by
  default), the landing's lowest voltage predicted by power with its 90% interval (draws of the fit's
  uncertainty, model-discrepancy factor and flags included: :mod:`uam_studio.battery.health.quality`);
  and the same without the prior (the likelihood alone). On three parameter sets: the two refits that
  never read the scored landing (:data:`SET_LANDING`, :data:`SET_CELL`; held out, the default: the
  bundled literals ``VTC6_LANDING_HELD_OUT`` and ``VTC6_CELL_HELD_OUT``, or identified again from the
  data with ``refit=True``), and the bundled set as the in-sample reference (:data:`SET_BUNDLED`; only
  it with ``held_out=False``);
- Dynaformer: the bundled model (trained on the NASA cell, 0.05-3 A; held out), the ones fine-tuned
  on each held-out set's synthetic data (``dynaformer_vtc6_landing_held_out.pt``,
  ``dynaformer_vtc6_cell_held_out.pt``; held out: neither their set nor their weights read this landing),
  and the one fine-tuned on the bundled VTC6 set's (``dynaformer_vtc6.pt``; in-sample: that set read this
  landing), on the same contexts along the measured current; beside each, the reference in the same
  run: the same physics fit flown along the same current;
- capacity: q_max fitted to each C/5 reference discharge of the four resampled lives (the whole discharge,
  and only its part above 3.4 V), the capacity to 2.5 V it gives against the dataset's integrated capacity;
- safety: for cut-offs from 3.0 to 3.3 V, would the health fit's 90% lower bound have called the
  landing safe where the measured voltage went below the cut-off? Per parameter set
  (:func:`held_out_summary`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from uam_studio.battery import HealthEstimate, fit_health, simulate, simulate_constant_power
from uam_studio.battery.parameters import (
    NASA_18650,
    VTC6,
    VTC6_CELL_HELD_OUT,
    VTC6_LANDING_HELD_OUT,
    ZERO_C,
    Cell,
)
from uam_studio.battery.real.cmu_data import (
    LANDING,
    LIFE_FILES,
    MISSION_FILE,
    MissionLog,
    data_folder,
    load_cell_log,
    mission_cycle,
    reference_discharges,
)
from uam_studio.battery.real.cmu_replay import identify_vtc6, replay_mission
from uam_studio.errors import InputError

CONTEXTS_S = (20, 60, 120)
SET_LANDING = "landing held out"  # the VTC6 refit that never read VAH01's landing and the rest after it
SET_CELL = "cell VAH01 held out"  # the VTC6 refit on VAH07 alone
SET_BUNDLED = "bundled (in-sample)"  # the bundled VTC6 set: its fit read this landing
# the bundled Dynaformer fine-tuned on each held-out set (uam_studio.dynaformer.cells)
HELD_OUT_DYNAFORMERS = ((SET_LANDING, "vtc6_landing_held_out"), (SET_CELL, "vtc6_cell_held_out"))
SAFETY_CUTOFFS_V = (3.0, 3.05, 3.1, 3.15, 3.2, 3.25, 3.3)
CAPACITY_FIT_ABOVE_V = 3.4  # V: the part of each C/5 discharge the capacity fit reads
CAPACITY_DT_S = 1.0  # s: simulation step of the C/5 discharges (below the VTC6's fastest time constant)
N_DRAWS = 200
LEVEL = 0.9


@dataclass
class RealCellReport:
    """The validation table's sections (see the module docstring); voltages in V, errors in mV."""

    physics: list[dict] = field(default_factory=list)
    health: list[dict] = field(default_factory=list)
    health_likelihood: list[dict] = field(default_factory=list)
    dynaformer: list[dict] = field(default_factory=list)
    dynaformer_vtc6: list[dict] = field(default_factory=list)
    dynaformer_held_out: list[dict] = field(default_factory=list)  # rows with their "set"
    capacity: list[dict] = field(default_factory=list)
    safety: list[dict] = field(default_factory=list)
    measured_landing_min_v: float = math.nan

    def as_dict(self) -> dict:
        return {"measured_landing_min_v": self.measured_landing_min_v, "physics": self.physics,
                "health": self.health, "health_likelihood": self.health_likelihood, "dynaformer": self.dynaformer,
                "dynaformer_vtc6": self.dynaformer_vtc6, "dynaformer_held_out": self.dynaformer_held_out,
                "capacity": self.capacity,
                "safety": self.safety, "summary": held_out_summary(self)}


def _landing_min(voltage: np.ndarray, mission: MissionLog) -> np.ndarray:
    """Lowest voltage (V) of the landing segment, per row of ``voltage`` [..., T]."""
    return np.min(voltage[..., mission.phase_mask(LANDING)], axis=-1)


def physics_row(label: str, held_out: str, cell: Cell, mission: MissionLog) -> dict:
    """The mission flown on ``cell`` by power (and by the measured current), scored on the measurement."""
    measured = mission.log.voltage_v
    row: dict[str, Any] = {"model": label, "held out": held_out}
    for how, by_power in (("power", True), ("current", False)):
        res = replay_mission(mission, cell, by_power=by_power)
        n = int(np.sum(res.valid))
        err = res.voltage_v[:n] - measured[:n]
        row[f"rmse_mv_{how}"] = float(1000 * np.sqrt(np.mean(err ** 2))) if n else math.nan
        row[f"landing_min_err_mv_{how}"] = float(1000 * (_landing_min(res.voltage_v, mission)
                                                         - _landing_min(measured, mission)))
        row[f"cutoff_s_{how}"] = float(res.time_s[n - 1]) if n < len(measured) else None
    return row


def _mission_fitted_nasa(mission: MissionLog) -> Cell:
    """The NASA parameter set with only q_max and R0 fitted to the whole mission (current-driven)."""
    params = replace(NASA_18650.params, t_ambient_k=ZERO_C + float(mission.log.temperature_c[0]))
    est = fit_health(mission.log.current_a, mission.log.voltage_v, 1.0, cell=params, start="full",
                     prior=False)  # a reference fit: the NASA fleet is not this cell's
    return Cell("NASA set, q_max and R0 fitted to this mission", NASA_18650.params, est.q_max, est.r0)


def health_rows(cell: Cell, mission: MissionLog, rng: np.random.Generator, prior: bool = True,
                label: str = "") -> list[dict]:
    """q_max/R0 from the mission's first seconds (with the cell type's fleet prior, or without:
    ``prior``) on the parameter set ``cell`` (``label``: its name in the rows' ``"set"``); the
    landing's lowest voltage predicted by power, with the fit's flags."""
    params = replace(cell.params, t_ambient_k=ZERO_C + float(mission.log.temperature_c[0]))
    log = mission.log
    truth = float(_landing_min(log.voltage_v, mission))
    rows = []
    for ctx in CONTEXTS_S:
        est = fit_health(log.current_a[:ctx], log.voltage_v[:ctx], 1.0, cell=params, start="full", prior=prior)
        draws = np.vstack([[est.q_max, est.r0], est.sample(N_DRAWS, rng)])
        res = simulate_constant_power(np.broadcast_to(mission.power_w, (len(draws), len(mission.power_w))), 1.0,
                                      draws[:, 0], draws[:, 1], eod_v=2.5, cell=params)
        mins = _landing_min(res.voltage_v, mission)
        lo, hi = np.quantile(mins[1:], [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
        rows.append({"set": label, "context_s": ctx, "q_max_c": est.q_max, "r0_ohm": est.r0,
                     "predicted_v": float(mins[0]), "low_v": float(lo), "high_v": float(hi),
                     "error_mv": float(1000 * (mins[0] - truth)), "inside": bool(lo <= truth <= hi),
                     "flags": list(est.flags), "discrepancy_factor": est.discrepancy_factor})
    return rows


def dynaformer_rows(mission: MissionLog, cell: str = "nasa18650") -> list[dict]:
    """A bundled Dynaformer (``cell``: a key of :data:`uam_studio.dynaformer.cells.DYNAFORMER_CELLS`) on
    the mission's contexts along its
    measured current (A), with its default health (the physics fit of the context on the weights' cell);
    ``physics_error_mv``: that fit flown on the physics model along the same current (the reference).
    A refusal or a missing weights file is a row with its one-line ``error``."""
    from uam_studio.battery.health.intervals import voltage_band as physics_band
    from uam_studio.dynaformer import load_pretrained

    log = mission.log
    truth = float(_landing_min(log.voltage_v, mission))
    rows: list[dict[str, Any]] = []
    try:
        pred = load_pretrained(cell)
    except Exception as exc:  # a missing or broken weights file is reported in the table, not raised
        return [{"context_s": c, "error": str(exc).splitlines()[0]} for c in CONTEXTS_S]
    for ctx in CONTEXTS_S:
        try:
            # a 1-D context: one estimate
            est = cast(HealthEstimate, pred.health_estimate(log.current_a[:ctx], log.voltage_v[:ctx]))
            lo, med, hi = pred.voltage_band(log.current_a[:ctx], log.voltage_v[:ctx], log.current_a, estimate=est)
            med_min, lo_min, hi_min = (float(_landing_min(np.asarray(x), mission)) for x in (med, lo, hi))
            phys = float(_landing_min(np.asarray(physics_band(est, log.current_a, cell=pred.cell)[1]), mission))
            rows.append({"context_s": ctx, "q_max_c": est.q_max, "r0_ohm": est.r0, "predicted_v": med_min,
                         "low_v": lo_min, "high_v": hi_min, "error_mv": 1000 * (med_min - truth),
                         "inside": bool(lo_min <= truth <= hi_min), "physics_error_mv": 1000 * (phys - truth)})
        except InputError as exc:
            rows.append({"context_s": ctx, "error": str(exc)})
    return rows


def capacity_rows(folder: Path, cell: Cell) -> list[dict]:
    """q_max fitted to each C/5 reference discharge above 3.4 V, its capacity to 2.5 V against the data's, over
    the lives of :data:`LIFE_FILES` that ``folder`` holds (the bundled sample: VAH27 only)."""
    rows = []
    for name in LIFE_FILES:
        if not (folder / name).is_file():
            continue
        log = load_cell_log(folder / name)
        params = cell.params
        for k, ref in enumerate(reference_discharges(log)):
            t = log.time_s[ref.start - 1:ref.stop] - log.time_s[ref.start - 1]
            grid = np.arange(CAPACITY_DT_S, t[-1] + 1e-9, CAPACITY_DT_S)
            cur = np.interp(grid - CAPACITY_DT_S / 2, t, log.current_a[ref.start - 1:ref.stop])
            cur = np.where(grid <= t[1], log.current_a[ref.start], cur)
            volt = np.interp(grid, t, log.voltage_v[ref.start - 1:ref.stop])
            p = replace(params, t_ambient_k=ZERO_C + float(log.temperature_c[ref.start - 1]))
            row = {"cell": log.name, "test": k, "time_h": ref.time_h, "measured_ah": ref.capacity_ah}
            above = int(np.argmax(volt < CAPACITY_FIT_ABOVE_V)) or len(volt)
            for key, n in (("", above), ("_whole", len(volt))):
                est = fit_health(cur[:n], volt[:n], CAPACITY_DT_S, cell=p, start="full",
                                 prior=False)  # the fleet range came from these discharges
                steps = int(2 * ref.capacity_ah * 3600 / ref.current_a / CAPACITY_DT_S)
                res = simulate(np.full(steps, ref.current_a), CAPACITY_DT_S, est.q_max, est.r0, eod_v=2.5, cell=p)
                cap = float(res.eod_s * ref.current_a / 3600) if res.eod_reached else math.nan
                row.update({f"q_max_c{key}": est.q_max, f"predicted_ah{key}": cap,
                            f"error_pct{key}": 100 * (cap - ref.capacity_ah) / ref.capacity_ah})
            rows.append(row)
    return rows


def safety_rows(health: list[dict], measured_min: float) -> list[dict]:
    """Per cut-off: the health fit (each context) judged the landing safe (90% lower bound above the
    cut-off) where the measured lowest voltage fell below it: a missed breach."""
    rows = []
    for h in health:
        for cut in SAFETY_CUTOFFS_V:
            judged_safe = h["low_v"] >= cut
            breached = measured_min < cut
            rows.append({"set": h.get("set", ""), "cutoff_v": cut, "context_s": h["context_s"],
                         "judged_safe": judged_safe, "measured_breach": breached,
                         "missed_breach": judged_safe and breached})
    return rows


def real_cell_report(data: str | Path | None = None, held_out: bool = True, refit: bool = False,
                     capacity: bool = True, seed: int = 20260) -> RealCellReport:
    """The validation table (module docstring) from the dataset's folder (``data`` or
    ``$UAM_STUDIO_CMU_DATA``). ``held_out=False`` scores only the bundled (in-sample) set;
    ``refit=True`` identifies the two held-out sets again from the data (about 10 s each) instead of
    reading their bundled literals; ``capacity=False`` skips the reference discharges (62 in the four
    resampled lives)."""
    folder = data_folder(data)
    mission = mission_cycle(load_cell_log(folder / MISSION_FILE))
    report = RealCellReport(measured_landing_min_v=float(_landing_min(mission.log.voltage_v, mission)))
    report.physics.append(physics_row("VTC6 (bundled)", "none: its fit read this mission", VTC6, mission))
    sets = []  # (label, cell): the held-out sets first, the bundled set as the in-sample reference
    if held_out:
        for hold_out, label, what, bundled in (
                ("landing", SET_LANDING, "this mission's landing and rest", VTC6_LANDING_HELD_OUT),
                ("cell", SET_CELL, "cell VAH01 (fit on VAH07 only)", VTC6_CELL_HELD_OUT)):
            cell = identify_vtc6(folder, hold_out=hold_out) if refit else bundled
            report.physics.append(physics_row("VTC6 refit" if refit else "VTC6 held-out set", what, cell, mission))
            sets.append((label, cell))
    sets.append((SET_BUNDLED, VTC6))
    report.physics.append(physics_row("NASA 18650 (default)", "all (not fitted)", NASA_18650, mission))
    report.physics.append(physics_row("NASA set, q_max/R0 fitted", "none", _mission_fitted_nasa(mission), mission))
    for label, cell in sets:
        report.health += health_rows(cell, mission, np.random.default_rng(seed), label=label)
        report.health_likelihood += health_rows(cell, mission, np.random.default_rng(seed), prior=False, label=label)
    report.dynaformer = dynaformer_rows(mission)
    report.dynaformer_vtc6 = dynaformer_rows(mission, "vtc6")
    if held_out:
        for label, key in HELD_OUT_DYNAFORMERS:
            report.dynaformer_held_out += [{"set": label, **r} for r in dynaformer_rows(mission, key)]
    if capacity:
        report.capacity = capacity_rows(folder, VTC6)
    report.safety = safety_rows(report.health, report.measured_landing_min_v)
    return report


def held_out_summary(report: RealCellReport) -> dict:
    """Per parameter set of the health rows: missed breaches (of all cut-offs x contexts), the
    contexts whose 90% interval holds the measured landing minimum, the median interval width (mV)."""
    out = {}
    for label in dict.fromkeys(r["set"] for r in report.health):
        rows = [r for r in report.health if r["set"] == label]
        safety = [r for r in report.safety if r["set"] == label]
        out[label] = {"missed_breaches": sum(r["missed_breach"] for r in safety), "cases": len(safety),
                      "inside": sum(r["inside"] for r in rows), "contexts": len(rows),
                      "median_width_mv": float(np.median([1000 * (r["high_v"] - r["low_v"]) for r in rows]))}
    return out


def _fmt(x, spec: str) -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and not math.isfinite(x):
        return "n/a"
    return format(x, spec)


def format_report(report: RealCellReport) -> str:
    """The report as plain-text tables."""
    out = [f"Real mission VAH01 cycle 20 (1 Hz): measured lowest landing voltage {report.measured_landing_min_v:.3f} V",
           "", "physics model on the real mission (flown by power; by measured current in brackets)",
           f"{'model':28s} {'held out':36s} {'RMSE mV':>16s} {'landing min err mV':>22s}  cut-off"]
    for r in report.physics:
        cut = r["cutoff_s_power"]
        out.append(f"{r['model']:28s} {r['held out']:36s} {_fmt(r['rmse_mv_power'], '7.1f'):>7s} "
                   f"({_fmt(r['rmse_mv_current'], '6.1f')}) {_fmt(r['landing_min_err_mv_power'], '+9.1f'):>11s} "
                   f"({_fmt(r['landing_min_err_mv_current'], '+8.1f')})  "
                   + (f"reached at {cut:.0f} s" if cut is not None else "never"))
    for title, rows in (("health fit (VTC6 fleet prior: the default)", report.health),
                        ("health fit (likelihood alone: prior=False)", report.health_likelihood)):
        if not rows:
            continue
        out += ["", f"{title} from the mission's first seconds: landing's lowest voltage, 90% interval; "
                "x: the model-discrepancy factor on the covariance",
                f"{'parameter set':22s} {'context':>8s} {'q_max C':>8s} {'R0 ohm':>8s} {'predicted V':>11s} "
                f"{'90% interval V':>17s} {'error mV':>9s} inside  {'x':>5s}  flags"]
        for r in rows:
            out.append(f"{r['set']:22s} {r['context_s']:>6d} s {r['q_max_c']:8.0f} {r['r0_ohm']:8.4f} "
                       f"{r['predicted_v']:11.3f} {r['low_v']:8.3f}-{r['high_v']:.3f} {r['error_mv']:+9.1f} "
                       f"{'yes' if r['inside'] else 'NO ':3s}  {r['discrepancy_factor']:5.1f}  "
                       f"{', '.join(r['flags']) or '-'}")
    from uam_studio.dynaformer.cells import dynaformer_cell

    sections = [("Dynaformer as bundled (trained on the NASA cell, 0.05-3 A)", report.dynaformer)]
    for label, key in HELD_OUT_DYNAFORMERS:
        rows = [r for r in report.dynaformer_held_out if r["set"] == label]
        if rows:
            sections.append((f"Dynaformer fine-tuned on the {label} set's synthetic data "
                             f"({dynaformer_cell(key).weights_file}; "
                             "held out: neither the set nor the weights read this landing)", rows))
    sections.append(("Dynaformer fine-tuned on the bundled VTC6 set's synthetic data (dynaformer_vtc6.pt; "
                     "in-sample: that set read this landing)", report.dynaformer_vtc6))
    for title, rows in sections:
        out += ["", f"{title}, same contexts, along the measured current; physics: its own fit (the weights' "
                "cell) flown along the same current"]
        for r in rows:
            if "error" in r:
                out.append(f"{r['context_s']:>6d} s  refused: {r['error']}")
            else:
                out.append(f"{r['context_s']:>6d} s  q_max {r['q_max_c']:6.0f} C, R0 {r['r0_ohm']:.4f} ohm: predicted "
                           f"{r['predicted_v']:.3f} V, 90% {r['low_v']:.3f}-{r['high_v']:.3f} V, error "
                           f"{r['error_mv']:+.1f} mV, inside: {'yes' if r['inside'] else 'NO'}; physics "
                           f"{r['physics_error_mv']:+.1f} mV")
    if report.capacity:
        out += ["", "capacity: q_max fitted to each C/5 reference discharge (the whole discharge; only the part "
                f"above {CAPACITY_FIT_ABOVE_V} V), the capacity to 2.5 V it gives against the integrated one",
                f"{'cell':6s} {'tests':>5s} {'life h':>11s} {'measured Ah':>13s} {'worst error %':>22s} "
                f"{'median |error| %':>22s}"]

        def worst(e: np.ndarray) -> float:
            return float(e[np.nanargmax(np.abs(e))]) if np.isfinite(e).any() else math.nan

        for name in dict.fromkeys(r["cell"] for r in report.capacity):
            rs = [r for r in report.capacity if r["cell"] == name]
            e = np.array([r["error_pct"] for r in rs])
            ew = np.array([r["error_pct_whole"] for r in rs])
            out.append(f"{name:6s} {len(rs):5d} {rs[0]['time_h']:5.0f}-{rs[-1]['time_h']:<5.0f} "
                       f"{rs[0]['measured_ah']:6.3f}-{rs[-1]['measured_ah']:.3f} {worst(ew):+10.2f} ({worst(e):+7.2f}) "
                       f"{np.nanmedian(np.abs(ew)):10.2f} ({np.nanmedian(np.abs(e)):7.2f})")
        for key, what in (("_whole", "whole discharge"), ("", f"above {CAPACITY_FIT_ABOVE_V} V")):
            errs = np.array([r[f"error_pct{key}"] for r in report.capacity])
            out.append(f"{what}: worst |error| {np.nanmax(np.abs(errs)):.2f}%, within 3%: "
                       f"{int(np.sum(np.abs(errs) <= 3))} of {len(errs)}")
    breaches = {r["cutoff_v"] for r in report.safety if r["measured_breach"]}
    out += ["", "safety: cut-offs 3.00-3.30 V; the landing breached at "
            + (", ".join(f"{c:.2f}" for c in sorted(breaches)) or "none") + " V; missed breaches: judged safe by "
            "the 90% lower bound, breached in the measurement"]
    for label, summary in held_out_summary(report).items():
        missed = [r for r in report.safety if r["set"] == label and r["missed_breach"]]
        out.append(f"{label:22s} missed {summary['missed_breaches']} of {summary['cases']}"
                   + (" (" + ", ".join(f"{r['cutoff_v']:.2f} V from {r['context_s']} s" for r in missed) + ")"
                      if missed else "")
                   + f"; measured minimum inside the 90% interval in {summary['inside']} of {summary['contexts']} "
                   f"contexts; median width {summary['median_width_mv']:.0f} mV")
    return "\n".join(out)

"""The Sony-Murata VTC6 cell of the CMU eVTOL dataset: what its identification reads, and how a real
mission is replayed on the model.

Identification data (:func:`vtc6_fit_segments`), all from cell VAH07 early in its life:

- its first C/5 reference discharge (30 s samples; capacity and open-circuit-voltage curve);
- its first ``n_missions`` mission cycles (30 s samples, charged to 4.0 V; resistance, kinetics, heat).

Held out from it: cell VAH01's 1 Hz mission (``VAH01_20.csv``), VAH07's later cycles and the other
cells (VAH09, VAH27, VAH30). ``uam-studio identify vtc6 --data PATH`` runs the fit and prints the
parameter set that :data:`~uam_studio.battery.parameters.VTC6` holds.
"""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from uam_studio.battery.parameters import (
    DEFAULT_CELL,
    VTC6_FLEET_Q_RANGE,
    VTC6_FLEET_R0_RANGE,
    VTC6_PARAMS,
    ZERO_C,
    Cell,
    CellParameters,
)
from uam_studio.battery.real.cmu_data import (
    CRUISE,
    LANDING,
    MISSION_DURATIONS_S,
    MISSION_FILE,
    MISSION_POWER_W,
    REST_AFTER,
    TAKEOFF,
    CellLog,
    MissionLog,
    ResampledMission,
    last_rest,
    load_cell_log,
    mission_cycle,
    reference_discharges,
    resampled_missions,
)
from uam_studio.battery.real.identify import FitSegment, identify_cell
from uam_studio.battery.simulate import SimulationResult, simulate, simulate_constant_power
from uam_studio.errors import InputError

IDENTIFICATION_FILE = "VAH07.csv.mat"
FINE_DT_S = 1.0  # s: largest step of the fit's simulations of resampled logs
HOLD_OUTS = ("none", "landing", "cell")


REST_STEPS = 10  # steps at 0 A before a reference discharge: the full cell's rest voltage is observed too


def reference_segment(log: CellLog, number: int = 0, name: str = "c5", weight: float = 1.0) -> FitSegment:
    """The ``number``-th C/5 reference discharge of a resampled life as a fit segment: the full cell at
    rest (the sample before the discharge), then the discharge."""
    ref = reference_discharges(log)[number]
    k = int(np.ceil(log.dt_s / FINE_DT_S))
    rest = last_rest(log, ref.start)  # the last sample at rest before it (the one before may be half loaded)
    n = ref.stop - ref.start
    current = np.concatenate([np.zeros(REST_STEPS), np.repeat(log.current_a[ref.start:ref.stop], k)])
    observed = np.concatenate([[REST_STEPS - 1], REST_STEPS + np.arange(1, n + 1) * k - 1])
    pick = np.r_[rest, ref.start:ref.stop]
    return FitSegment(name, current, log.dt_s / k, observed, log.voltage_v[pick], ZERO_C + log.temperature_c[rest],
                      weight=weight, temperature_c=log.temperature_c[pick])


def mission_current(log: CellLog, mission: ResampledMission, dt_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A resampled mission's current on a ``dt_s`` grid from its start (A), and the grid index of each
    cleanly segmented sample (-1 for the others): the current of each segment interpolated in time
    between that segment's clean samples, held at its ends."""
    starts = mission.phase_starts_s()
    end = starts[REST_AFTER] + (log.time_s[mission.index[-1]] - mission.t0_s)
    grid = dt_s * np.arange(int(np.floor(end / dt_s)))
    t = log.time_s[mission.index] - mission.t0_s
    cur = np.zeros_like(grid)
    for code in (TAKEOFF, CRUISE, LANDING):
        in_seg = (grid >= starts[code]) & (grid < starts[code] + MISSION_DURATIONS_S[code])
        clean = mission.segment == code
        if clean.any():
            cur[in_seg] = np.interp(grid[in_seg], t[clean], log.current_a[mission.index][clean])
        else:  # no clean sample: the protocol's power at a nominal 3.6 V
            cur[in_seg] = MISSION_POWER_W[code] / 3.6
    observed = np.where(mission.segment >= 0, np.round(t / dt_s).astype(int) - 1, -1)
    observed[(observed < 0) | (observed >= len(grid))] = -1
    return cur, observed


def mission_segment(log: CellLog, mission: ResampledMission, name: str, removed_c0: float) -> FitSegment:
    cur, observed = mission_current(log, mission, 1.0)
    keep = observed >= 0
    k = mission.index[keep]
    return FitSegment(name, cur, 1.0, observed[keep], log.voltage_v[k], ZERO_C + log.temperature_c[mission.index[0]],
                      temperature_c=log.temperature_c[k], removed_c=removed_c0, fit_removed=True)


def vtc6_fit_segments(folder: str | Path, n_missions: int = 4, hold_out: str = "none") -> list[FitSegment]:
    """The identification data (module docstring). ``hold_out``: ``"none"`` (the bundled set), ``"landing"``
    (VAH01's landing and the rest after it left out) or ``"cell"`` (VAH01 left out entirely)."""
    if hold_out not in HOLD_OUTS:
        raise InputError("hold_out", f"{hold_out!r}; allowed {', '.join(HOLD_OUTS)}")
    folder = Path(folder)
    log = load_cell_log(folder / IDENTIFICATION_FILE)
    segs = [reference_segment(log)]
    # VAH07 charges to 4.0 V before a mission: about 0.6 Ah (2160 C) below full, fitted per mission.
    segs += [mission_segment(log, m, f"VAH07 mission {j}", 2160.0)
             for j, m in enumerate(resampled_missions(log)[:n_missions])]
    if hold_out != "cell":
        ml = mission_cycle(load_cell_log(folder / MISSION_FILE)).log
        keep = np.ones(len(ml), bool) if hold_out == "none" else ~np.isin(ml.segment, (LANDING, REST_AFTER))
        idx = np.flatnonzero(keep)
        segs.append(FitSegment("VAH01 mission", ml.current_a[:idx[-1] + 1], 1.0, idx, ml.voltage_v[idx],
                               ZERO_C + ml.temperature_c[0], weight=2.0, temperature_c=ml.temperature_c[idx]))
    return segs


START_Q_MAX = 11000.0  # C: the fit's start, near the C/5 discharge's 10.9 kC
START_R0 = 0.02  # ohm: the fit's start


def vtc6_start() -> CellParameters:
    """The parameter set the VTC6 fit starts from: the NASA set with guessed heat and Arrhenius terms."""
    return replace(DEFAULT_CELL, r0_activation_k=2000.0, k_activation_k=2000.0, thermal_mass=45.0,
                   thermal_tau_s=300.0, t_ambient_k=298.15, fleet_q_range=VTC6_FLEET_Q_RANGE,
                   fleet_r0_range=VTC6_FLEET_R0_RANGE)


def identify_vtc6(folder: str | Path, n_missions: int = 4, hold_out: str = "none", max_nfev: int = 300) -> Cell:
    """Identify the VTC6 cell from the dataset in ``folder`` (see the module docstring); about a minute.
    One start (:func:`vtc6_start`, q_max START_Q_MAX C, R0 START_R0 ohm): the fit is local."""
    fit = identify_cell(vtc6_fit_segments(folder, n_missions, hold_out), vtc6_start(), START_Q_MAX, START_R0,
                        max_nfev=max_nfev)
    return Cell(f"Sony-Murata VTC6 (identified, held out: {hold_out})", fit.cell, fit.q_max, fit.r0)


def replay_mission(mission: MissionLog, cell: Cell, by_power: bool = True) -> SimulationResult:
    """Fly a real 1 Hz mission on the model from a full, rested cell at the log's first temperature:
    by its protocol's power per segment (W; the default, as a planner knows a flight), or by its
    measured current (A)."""
    params = replace(cell.params, t_ambient_k=ZERO_C + float(mission.log.temperature_c[0]))
    if by_power:
        return simulate_constant_power(mission.power_w, 1.0, cell.q_max, cell.r0, eod_v=2.5, cell=params)
    return simulate(mission.log.current_a, 1.0, cell.q_max, cell.r0, eod_v=2.5, cell=params)



# The fleet ranges' names in parameters.py, printed in place of their values.
FLEET_RANGE_NAMES = {"fleet_q_range": "VTC6_FLEET_Q_RANGE", "fleet_r0_range": "VTC6_FLEET_R0_RANGE"}

# The name of each identification's literals in parameters.py and its Cell's label, by what it holds out.
LITERAL_NAMES = {
    "none": ("VTC6", "Sony-Murata VTC6 18650 (identified on the CMU eVTOL dataset)"),
    "landing": ("VTC6_LANDING_HELD_OUT", "Sony-Murata VTC6 18650 (identified without VAH01's landing)"),
    "cell": ("VTC6_CELL_HELD_OUT", "Sony-Murata VTC6 18650 (identified without cell VAH01)"),
}


def cell_literal(cell: Cell, hold_out: str = "none") -> str:
    """Python source of ``cell`` as parameters.py holds it (what ``uam-studio identify vtc6`` prints),
    named for what its identification held out (:data:`LITERAL_NAMES`)."""
    name, label = LITERAL_NAMES[hold_out]
    p = cell.params
    changed = [f.name for f in fields(p) if getattr(p, f.name) != getattr(DEFAULT_CELL, f.name)]
    lines = [f"{name}_PARAMS = replace(", "    DEFAULT_CELL,"]
    for n in changed:
        v = getattr(p, n)
        if n in FLEET_RANGE_NAMES and v == getattr(VTC6_PARAMS, n):
            text = FLEET_RANGE_NAMES[n]
        elif isinstance(v, tuple):
            text = "(" + ", ".join(f"{float(x):.9g}" for x in v) + ")"
        else:
            text = f"{float(v):.9g}"
        lines.append(f"    {n}={text},")
    lines.append(")")
    lines.append(f'{name} = Cell("{label}", {name}_PARAMS, {cell.q_max:.9g}, {cell.r0:.9g})')
    return "\n".join(lines)

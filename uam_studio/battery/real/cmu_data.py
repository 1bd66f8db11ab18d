"""Loader of the CMU eVTOL battery dataset (Sony-Murata VTC6 18650 cells; Bills et al., Scientific Data 10,
344 (2023), DOI 10.1184/R1/14226830, CC BY 4.0).

The data stay outside this project: every function takes a path. Two formats are read:

- the dataset's CSV (one row per sample): the published column names ``time_s, Ecell_V, I_mA,
  Temperature__C, cycleNumber, Ns`` or the shorter ``times, EcellV, ImA, TemperatureC, cycleNumber, Ns``
  of the 1 Hz mission file ``VAH01_20.csv``; current in mA, negative = discharge;
- uniformly resampled lives (``VAHxx.csv.mat``): a MATLAB v5 struct ``batteryData`` with
  ``Time_s, Current (A, + = discharge), Voltage_V, Temperature_C``.

Both come back as a :class:`CellLog`: time (s, from 0), current (A, + = discharge), voltage (V),
temperature (C), segment (the dataset's ``Ns``: 4 take-off, 5 cruise, 6 landing, 7 rest after it;
-1 where the file has none) and cycle. A file of another shape (a missing column, NaN rows, a
truncated file, values no VTC6 shows) raises :class:`CellDataError`: one line naming the file and
the field.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uam_studio.battery.real.places import SAMPLE_NOTES, SAMPLES, beside_checkout, in_checkout
from uam_studio.errors import DataFileError, InputError

DATA_ENV = "UAM_STUDIO_CMU_DATA"  # environment variable: the dataset's folder
DATASET_DOI = "10.1184/R1/14226830"
MISSION_FILE = "VAH01_20.csv"  # the 1 Hz baseline mission (cell VAH01, cycle 20)
# Where a source checkout finds the dataset without being told: a shared/data/cmu_evtol folder beside it.
BESIDE_CHECKOUT = beside_checkout("cmu_evtol")
# The sample that ships with the package: the 1 Hz mission and one resampled life (VAH27).
SAMPLE = SAMPLES / "cmu_evtol"
SAMPLE_NOTE = SAMPLE_NOTES["cmu_evtol"]
CELL_GLOB = "VAH*"  # the dataset's cell files: missions (VAHnn_cc.csv) and resampled lives (VAHnn.csv.mat)
LIFE_FILES = ("VAH07.csv.mat", "VAH09.csv.mat", "VAH27.csv.mat", "VAH30.csv.mat")

# Segment codes (Ns) of a mission cycle in the dataset.
TAKEOFF, CRUISE, LANDING, REST_AFTER = 4, 5, 6, 7
MISSION_SEGMENTS = {TAKEOFF: "take-off", CRUISE: "cruise", LANDING: "landing", REST_AFTER: "rest"}
# The baseline mission's power per cell (W) in each segment (the dataset's protocol).
MISSION_POWER_W = {TAKEOFF: 54.0, CRUISE: 16.0, LANDING: 54.0, REST_AFTER: 0.0}

# What a VTC6 log can hold: anything outside is another cell, another unit or a broken file.
VOLTAGE_RANGE_V = (2.0, 4.25)  # V: the VTC6 charges to 4.2 V and is discharged to 2.5 V
CURRENT_LIMIT_A = 40.0  # A: |current|; the VTC6's pulse limit is 30 A
TEMPERATURE_RANGE_C = (-30.0, 80.0)
MIN_SAMPLES = 10

# Column names: ours -> the names each CSV flavour uses for it.
_CSV_COLUMNS = {
    "time_s": ("time_s", "times"),
    "voltage_v": ("Ecell_V", "EcellV"),
    "current_ma": ("I_mA", "ImA"),
    "temperature_c": ("Temperature__C", "TemperatureC"),
    "cycle": ("cycleNumber",),
    "segment": ("Ns",),
}
_MAT_FIELDS = {"time_s": "Time_s", "current_a": "Current", "voltage_v": "Voltage_V", "temperature_c": "Temperature_C"}


class CellDataError(DataFileError):
    """A cell data file that is not a CMU eVTOL (VTC6) log; ``str(err)`` names the file and the field."""


@dataclass(frozen=True)
class CellLog:
    """One cell's measured log, all arrays of shape [T].

    time_s: time since the log's first sample (s); current_a: cell current (A, + = discharge);
    voltage_v: terminal voltage (V); temperature_c: cell surface temperature (C); segment: the
    dataset's segment code ``Ns`` (-1 where unknown); cycle: the tester's cycle number (-1 where unknown).
    """

    source: str
    time_s: np.ndarray
    current_a: np.ndarray
    voltage_v: np.ndarray
    temperature_c: np.ndarray
    segment: np.ndarray
    cycle: np.ndarray

    @property
    def name(self) -> str:
        """The cell's name from its file name, e.g. ``VAH01``."""
        return Path(self.source).name.split(".")[0].split("_")[0]

    @property
    def dt_s(self) -> float:
        """Median sample spacing (s)."""
        return float(np.median(np.diff(self.time_s)))

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    def select(self, mask: np.ndarray) -> CellLog:
        """The samples where ``mask`` is True (time kept as it is)."""
        m = np.asarray(mask, dtype=bool)
        return CellLog(self.source, self.time_s[m], self.current_a[m], self.voltage_v[m], self.temperature_c[m],
                       self.segment[m], self.cycle[m])


def _fail(path, field: str, message: str) -> CellDataError:
    return CellDataError(path, field, message)


def _check_log(path, time_s, current_a, voltage_v, temperature_c) -> None:
    """Shape and range checks shared by both formats."""
    n = time_s.shape[0]
    if n < MIN_SAMPLES:
        raise _fail(path, "rows", f"{n} samples; a log needs at least {MIN_SAMPLES} (truncated file?)")
    for field, arr in (("time_s", time_s), ("current_a", current_a), ("voltage_v", voltage_v),
                       ("temperature_c", temperature_c)):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise _fail(path, field, f"{int(bad.sum())} NaN or empty values (first at sample {int(np.argmax(bad))})")
    if np.any(np.diff(time_s) <= 0):
        k = int(np.argmax(np.diff(time_s) <= 0)) + 1
        raise _fail(path, "time_s", f"not increasing at sample {k}")
    lo, hi = VOLTAGE_RANGE_V
    if voltage_v.min() < lo or voltage_v.max() > hi:
        raise _fail(path, "voltage_v", f"values {voltage_v.min():.3f}-{voltage_v.max():.3f} V outside a VTC6's "
                    f"[{lo:g}, {hi:g}] V (another cell type or unit?)")
    if np.abs(current_a).max() > CURRENT_LIMIT_A:
        raise _fail(path, "current_a", f"|current| up to {np.abs(current_a).max():.4g} A, above a VTC6's "
                    f"{CURRENT_LIMIT_A:g} A (another cell type or unit?)")
    lo, hi = TEMPERATURE_RANGE_C
    if temperature_c.min() < lo or temperature_c.max() > hi:
        raise _fail(path, "temperature_c", f"values outside [{lo:g}, {hi:g}] C")


def load_csv(path: str | os.PathLike) -> CellLog:
    """Read one of the dataset's CSV files (e.g. ``VAH01_20.csv`` at 1 Hz, or a whole ``VAHxx.csv``).

    :raises CellDataError: missing or unreadable file, missing column, a non-number, NaN rows, a truncated
        file, or values outside a VTC6's range.
    """
    p = Path(path)
    try:
        with open(p, newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            rows = list(reader)
    except OSError as exc:
        raise _fail(p, "path", f"cannot read ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, csv.Error):
        raise _fail(p, "path", "not a text CSV file") from None
    if not header:
        raise _fail(p, "header", "empty file")
    header = [h.strip() for h in header]
    index = {}
    for ours, names in _CSV_COLUMNS.items():
        found = [header.index(n) for n in names if n in header]
        if not found:
            raise _fail(p, "columns", f"no {' or '.join(names)} column; a CMU eVTOL CSV has "
                        f"{', '.join(n[0] for n in _CSV_COLUMNS.values())} (another dataset?)")
        index[ours] = found[0]
    cols = {k: np.empty(len(rows)) for k in index}
    for r, row in enumerate(rows):
        if len(row) < len(header):
            raise _fail(p, "rows", f"row {r + 2} has {len(row)} of {len(header)} fields (truncated file?)")
        for k, j in index.items():
            text = row[j].strip()
            try:
                cols[k][r] = float(text) if text else np.nan
            except ValueError:
                raise _fail(p, k, f"row {r + 2}: {text[:20]!r} is not a number") from None
    time_s = cols["time_s"]
    current_a = -cols["current_ma"] / 1000.0  # mA, negative = discharge -> A, + = discharge
    voltage_v, temperature_c = cols["voltage_v"], cols["temperature_c"]
    _check_log(p, time_s, current_a, voltage_v, temperature_c)
    for k in ("segment", "cycle"):
        if not np.all(np.isfinite(cols[k])):
            raise _fail(p, k, "NaN or empty values")
    return CellLog(str(p), time_s - time_s[0], current_a, voltage_v, temperature_c,
                   cols["segment"].astype(int), cols["cycle"].astype(int))


def load_mat(path: str | os.PathLike) -> CellLog:
    """Read a uniformly resampled life (``VAHxx.csv.mat``: MATLAB v5 struct ``batteryData``).

    :raises CellDataError: as :func:`load_csv`, and for a MATLAB file without the struct or its fields.
    """
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    p = Path(path)
    if not p.is_file():  # scipy's own message for a missing file does not say so
        raise _fail(p, "path", "not a file" if p.exists() else "no such file")
    try:
        mat = loadmat(p, squeeze_me=True, struct_as_record=False)
    except OSError as exc:
        raise _fail(p, "path", f"cannot read ({exc.strerror or exc})") from None
    except (MatReadError, ValueError, TypeError, EOFError, IndexError) as exc:
        raise _fail(p, "path", "not a readable MATLAB file "
                    f"({str(exc).splitlines()[0][:80] if str(exc) else 'truncated?'})") from None
    data = mat.get("batteryData")
    if data is None or not hasattr(data, "_fieldnames"):
        raise _fail(p, "batteryData", "no batteryData struct (another dataset?)")
    arrays = {}
    for ours, field in _MAT_FIELDS.items():
        if field not in data._fieldnames:
            raise _fail(p, field, f"missing from batteryData; it has {', '.join(data._fieldnames)}")
        try:
            arr = np.asarray(getattr(data, field), dtype=float).ravel()
        except (TypeError, ValueError):
            raise _fail(p, field, "not numeric") from None
        arrays[ours] = arr
    sizes = {k: a.shape[0] for k, a in arrays.items()}
    if len(set(sizes.values())) != 1:
        raise _fail(p, "rows", f"fields of different lengths {sizes} (truncated file?)")
    _check_log(p, arrays["time_s"], arrays["current_a"], arrays["voltage_v"], arrays["temperature_c"])
    n = arrays["time_s"].shape[0]
    cycle = (np.asarray(data.cycle_no, dtype=int).ravel() if "cycle_no" in data._fieldnames else np.full(n, -1))
    if cycle.shape[0] != n:
        cycle = np.full(n, -1)
    t = arrays["time_s"]
    return CellLog(str(p), t - t[0], arrays["current_a"], arrays["voltage_v"], arrays["temperature_c"],
                   np.full(n, -1), cycle)


def load_cell_log(path: str | os.PathLike) -> CellLog:
    """Read a CMU eVTOL file by its suffix: ``.mat`` (resampled life) or ``.csv``."""
    p = Path(path)
    if p.suffix.lower() == ".mat":
        return load_mat(p)
    if p.suffix.lower() == ".csv":
        return load_csv(p)
    raise _fail(p, "path", "expected a .csv or .mat file of the CMU eVTOL dataset")


def data_folder(path: str | os.PathLike | None = None, needs: str = MISSION_FILE) -> Path:
    """The dataset's folder: ``path`` if given, else ``$UAM_STUDIO_CMU_DATA``, else :data:`BESIDE_CHECKOUT`
    where a source checkout has it, else the bundled :data:`SAMPLE` if it holds ``needs``
    (``places.sample_note`` says so).

    :param needs: the file the folder must hold (default the 1 Hz mission, :data:`MISSION_FILE`; a
        study of the resampled lives passes one of :data:`LIFE_FILES`).
    :raises InputError: none found, or the folder lacks ``needs``. The message says how to get the data
        (``uam-studio data``) and point at it from a notebook, a shell or the CLI.
    """
    text = str(path) if path is not None else os.environ.get(DATA_ENV, "")
    if not text and in_checkout() and (BESIDE_CHECKOUT / needs).is_file():
        text = str(BESIDE_CHECKOUT)
    if not text and (SAMPLE / needs).is_file():
        text = str(SAMPLE)
    if not text:
        raise InputError("data", f"no dataset folder holds {needs}: the bundled sample has only "
                         f"{', '.join(sorted(p.name for p in SAMPLE.glob(CELL_GLOB)))}; get the CMU eVTOL dataset (DOI "
                         f"{DATASET_DOI}, see `uam-studio data`) and point at it with "
                         f"os.environ['{DATA_ENV}'] = '/path/to/cmu_evtol' in a notebook's first cell, "
                         f"export {DATA_ENV}=/path/to/cmu_evtol in a shell, or --data PATH on the command line")
    folder = Path(text).expanduser()
    if not (folder / needs).is_file():
        what = "1 Hz mission" if needs == MISSION_FILE else "resampled life"
        raise InputError("data", f"{folder} has no {needs} (the CMU eVTOL dataset's {what}, DOI {DATASET_DOI})")
    return folder


@dataclass(frozen=True)
class MissionLog:
    """The take-off, cruise, landing and rest of one real mission cycle, from a :class:`CellLog`.

    ``log`` holds those samples only, time from 0 at the first take-off sample (s); ``power_w`` is the
    protocol's power per cell (W) of each sample's segment.
    """

    log: CellLog
    power_w: np.ndarray

    def segment_start_s(self, code: int) -> float:
        """Start time (s) of a segment (:data:`TAKEOFF`, :data:`CRUISE`, :data:`LANDING`, :data:`REST_AFTER`)."""
        return float(self.log.time_s[np.argmax(self.log.segment == code)])

    def phase_mask(self, *codes: int) -> np.ndarray:
        return np.isin(self.log.segment, codes)


def mission_cycle(log: CellLog) -> MissionLog:
    """The first mission cycle (segments 4-7) of a 1 Hz log.

    :raises CellDataError: the log has no take-off, cruise and landing segments in that order.
    """
    seg = log.segment
    present = [code for code in (TAKEOFF, CRUISE, LANDING) if np.any(seg == code)]
    if present != [TAKEOFF, CRUISE, LANDING]:
        raise _fail(log.source, "Ns", "no take-off (4), cruise (5) and landing (6) segments: not a mission cycle")
    start = int(np.argmax(seg == TAKEOFF))
    stop = start
    while stop < len(seg) and seg[stop] in MISSION_SEGMENTS:
        stop += 1
    keep = np.zeros(len(seg), bool)
    keep[start:stop] = True
    part = log.select(keep)
    part = CellLog(part.source, part.time_s - part.time_s[0], part.current_a, part.voltage_v, part.temperature_c,
                   part.segment, part.cycle)
    power = np.array([MISSION_POWER_W[int(s)] for s in part.segment])
    return MissionLog(part, power)


@dataclass(frozen=True)
class ReferenceDischarge:
    """One C/5 reference discharge of a resampled life, from a full rest (>= 4.1 V) to the cut-off.

    ``start``/``stop``: sample indices in the life's log; ``capacity_ah``: the integrated charge (Ah);
    ``time_h``: when it started in the life (h).
    """

    start: int
    stop: int
    capacity_ah: float
    current_a: float
    time_h: float


REFERENCE_CURRENT_A = (0.45, 0.8)  # A: a C/5 reference discharge of the 3.0 Ah VTC6 draws about 0.6 A
REFERENCE_MIN_H = 3.0  # h: shorter runs are partial tests (the dataset notes several)
REFERENCE_REST_V = 4.1  # V: the sample before the discharge rests full (a 4.2 V charge; not a 4.0 V one)
REFERENCE_END_V = 2.8  # V: and reaches the cut-off region


def reference_discharges(log: CellLog, max_gap: int = 2) -> list[ReferenceDischarge]:
    """The complete C/5 reference discharges of a life: runs of 0.45-0.8 A discharge (gaps of up to
    ``max_gap`` samples bridged) that last >= 3 h, start from a full rest (>= 4.1 V) and end near the cut-off.

    Capacity is the current integrated over the run's samples (sample-and-hold, Ah).
    """
    cur, volt, t = log.current_a, log.voltage_v, log.time_s
    on = (cur > REFERENCE_CURRENT_A[0]) & (cur < REFERENCE_CURRENT_A[1])
    edges = np.diff(np.r_[0, on.astype(int), 0])
    starts, stops = list(np.flatnonzero(edges == 1)), list(np.flatnonzero(edges == -1))
    runs: list[list[np.intp]] = []
    for a, b in zip(starts, stops):
        if runs and a - runs[-1][1] <= max_gap:
            runs[-1][1] = b
        else:
            runs.append([a, b])
    dt = np.diff(t, append=t[-1] + np.median(np.diff(t)))
    found = []
    for a, b in runs:
        hours = (t[b - 1] - t[a]) / 3600.0
        if hours < REFERENCE_MIN_H or a == 0 or volt[a - 1] < REFERENCE_REST_V or volt[b - 1] > REFERENCE_END_V:
            continue
        sel = slice(a, b)
        cap = float(np.sum(np.clip(cur[sel], 0.0, None) * dt[sel]) / 3600.0)
        found.append(ReferenceDischarge(int(a), int(b), cap, float(np.mean(cur[sel][on[sel]])), float(t[a] / 3600.0)))
    return found


# Protocol durations (s) of the baseline mission's segments: take-off, cruise, landing.
MISSION_DURATIONS_S = {TAKEOFF: 75.0, CRUISE: 800.0, LANDING: 105.0}
POWER_TOLERANCE = 0.05  # a resampled sample keeps its phase when I*V is within 5% of the protocol's power
REST_CURRENT_A = 0.05  # A


def last_rest(log: CellLog, before: int) -> int:
    """Index of the last sample before index ``before`` that draws under REST_CURRENT_A (A), at least 0."""
    rest = before - 1
    while rest > 0 and abs(log.current_a[rest]) >= REST_CURRENT_A:
        rest -= 1
    return rest


@dataclass(frozen=True)
class ResampledMission:
    """One mission cycle found in a resampled life: its estimated start ``t0_s`` (s, in the life's
    time), the indices of its samples up to ``rest_s`` after the landing, and each sample's segment
    code (-1 for a sample that mixes two segments: the resampling interpolated across a boundary)."""

    t0_s: float
    index: np.ndarray
    segment: np.ndarray

    def phase_starts_s(self) -> dict[int, float]:
        """Start time (s, from ``t0_s``) of each segment."""
        t, out = 0.0, {}
        for code in (TAKEOFF, CRUISE, LANDING, REST_AFTER):
            out[code] = t
            t += MISSION_DURATIONS_S.get(code, 0.0)
        return out


def resampled_missions(log: CellLog, rest_s: float = 300.0) -> list[ResampledMission]:
    """The baseline mission cycles (54 W / 16 W / 54 W) of a resampled life, each with its start time
    bounded by the samples that fall cleanly inside a segment (the middle of that bound is ``t0_s``)."""
    cur, volt, t = log.current_a, log.voltage_v, log.time_s
    power = cur * volt
    takeoff = np.abs(power - MISSION_POWER_W[TAKEOFF]) < POWER_TOLERANCE * MISSION_POWER_W[TAKEOFF]
    cruise = np.abs(power - MISSION_POWER_W[CRUISE]) < POWER_TOLERANCE * MISSION_POWER_W[CRUISE]
    rest = np.abs(cur) < REST_CURRENT_A
    starts = np.flatnonzero((cur[1:] > 1.0) & rest[:-1]) + 1
    total = sum(MISSION_DURATIONS_S.values())
    edges = np.cumsum([0.0] + [MISSION_DURATIONS_S[c] for c in (TAKEOFF, CRUISE, LANDING)])
    span = {TAKEOFF: (edges[0], edges[1]), CRUISE: (edges[1], edges[2]), LANDING: (edges[2], edges[3]),
            REST_AFTER: (edges[3], np.inf)}  # s from the mission's start
    found = []
    for s in starts:
        stop = int(np.searchsorted(t, t[s] + total + rest_s))
        idx = np.arange(s - 1, min(stop, len(t)))
        if stop >= len(t) or not takeoff[idx].any() or not cruise[idx].any():
            continue
        # Bounds on t0 from each sample whose segment is certain.
        lo, hi = t[s - 1], t[s]
        seen_cruise = False
        labels = np.full(idx.shape, -1)
        for j, k in enumerate(idx):
            if cruise[k]:
                seen_cruise, code = True, CRUISE
            elif takeoff[k]:
                code = LANDING if seen_cruise else TAKEOFF
            elif rest[k] and seen_cruise:
                code = REST_AFTER
            else:
                continue
            labels[j] = code
            a, b = span[code]
            lo, hi = max(lo, t[k] - b), min(hi, t[k] - a)
        if not (lo <= hi) or not np.any(labels == LANDING):
            continue
        found.append(ResampledMission(float(0.5 * (lo + hi)), idx, labels))
    return found

"""Loader of NASA PCoE's Li-ion battery lives (Saha & Goebel 2007, "Battery Data Set", NASA Prognostics
Data Repository): 18650 cells of the type the Daigle & Kulkarni model was built for, cycled to end of
life, in the repacked format of the project's data folder (its PROVENANCE.md; ``uam-studio data import nasa``
writes it from NASA's own ``.mat`` files, and one cell of it ships with the package as a sample).

The data stay outside this project: every function takes a path. One gzip CSV per cell (``BXXXX.csv.gz``)
holds every discharge of that cell in order, with the columns ``discharge, uid, ambient_C, time_s,
voltage_V, current_A (negative = discharge), temperature_C, current_load_A, voltage_load_V``.

A discharge comes back as a :class:`NasaDischarge` (time s from the discharge's start, voltage V, current
A with + = discharge, cell temperature C, ambient C, and the rest before it, s), a cell as a :class:`NasaCell`.
The rest before each run is read from the folder's ``discharges.csv`` (column ``start_time``, a MATLAB date
vector) where it is there: the time from the end of the cell's previous run to this run's start. Runs that cannot be
scored (too short, never under load, already under load at the first sample, never below the cut-off)
(or below it at the first sample under load) are listed in ``NasaCell.skipped`` with their reason,
never raised. :func:`persistence_s` is the baseline
any health-aware prediction must beat where the load repeats: the same cell's previous discharge. A file that is not in
this format (missing, a folder, a truncated gzip, a missing column, NaN, time that does not increase within a discharge,
no discharge at all) raises :class:`NasaDataError`: one line naming the file and the field.
"""

from __future__ import annotations

import csv
import datetime
import functools
import gzip
import io
import math
import os
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from uam_studio.battery.parameters import DEFAULT_EOD_V
from uam_studio.battery.real.places import SAMPLE_NOTES, SAMPLES, beside_checkout, in_checkout
from uam_studio.errors import DataFileError

__all__ = ["COLUMNS", "LOADED_A", "MIN_SAMPLES", "SAMPLE", "SAMPLE_NOTE", "NasaCell", "NasaDataError",
           "NasaDischarge", "RunConditions", "load_nasa_cell", "load_nasa_folder", "nasa_cell_files", "nasa_folder",
           "persistence_s", "same_conditions", "available_cells"]

COLUMNS = ("discharge", "uid", "ambient_C", "time_s", "voltage_V", "current_A", "temperature_C",
           "current_load_A", "voltage_load_V")
LOADED_A = 0.1  # A: a sample drawing more discharge current than this is under load
MIN_SAMPLES = 10  # a discharge with fewer samples is too short to score
CELL_GLOB = "B*.csv.gz"
DATA_ENV = "UAM_STUDIO_NASA_DATA"
BESIDE_CHECKOUT = beside_checkout("nasa_pcoe")
"""Where the data sit beside a source checkout (a ``shared/data/nasa_pcoe`` folder next to the repository);
looked at only when the package runs from a source checkout."""
SAMPLE = SAMPLES / "nasa_pcoe"
"""The sample that ships with the package: cell B0005's whole life (24 C, 2 A), with its start times."""
SAMPLE_NOTE = SAMPLE_NOTES["nasa_pcoe"]


class NasaDataError(DataFileError):
    """A file that is not a cell of the NASA PCoE format; ``str(err)`` names the file and the field."""


@dataclass(frozen=True)
class NasaDischarge:
    """One discharge of a cell: ``index`` (0, 1, ... in the order run), ``uid`` (the cycle's number across
    the dataset), ``ambient_c`` (C), and at each sample ``time_s`` (s from the discharge's start),
    ``voltage_v`` (V at the cell), ``current_a`` (A, + = discharge), ``temperature_c`` (C, the cell's
    surface); ``load_start`` is the index of the first sample under load (current above
    :data:`LOADED_A`); ``rest_s`` (s) the time from the end of the cell's previous run (charges and
    impedance tests between them included) to this one's start, NaN where unknown (no start times, or
    the cell's first run)."""

    cell: str
    index: int
    uid: int
    ambient_c: float
    time_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    temperature_c: np.ndarray
    load_start: int
    rest_s: float = math.nan

    @property
    def load_time_s(self) -> float:
        """Time (s from the discharge's start) of the first sample under load."""
        return float(self.time_s[self.load_start])

    def time_to_cutoff_s(self, cutoff_v: float = DEFAULT_EOD_V) -> float | None:
        """Time (s) from the first sample under load to the first later sample below ``cutoff_v`` (V); None
        if the voltage never falls below it (computed once per cut-off)."""
        cache = self.__dict__.setdefault("_time_to_cutoff", {})
        if cutoff_v not in cache:
            below = np.flatnonzero(self.voltage_v[self.load_start:] < cutoff_v)
            cache[cutoff_v] = (None if below.size == 0 else
                               float(self.time_s[self.load_start + below[0]] - self.time_s[self.load_start]))
        return cache[cutoff_v]

    def mean_load_a(self) -> float:
        """Mean current (A) over the samples under load (computed once)."""
        if "_mean_load_a" not in self.__dict__:
            on = self.current_a > LOADED_A
            self.__dict__["_mean_load_a"] = float(self.current_a[on].mean()) if on.any() else 0.0
        return self.__dict__["_mean_load_a"]


@dataclass(frozen=True)
class NasaCell:
    """Every discharge of one cell that can be scored, in order, and the runs left out with their reason
    (``skipped``: (discharge index, reason)). ``cutoff_v``: the cut-off (V) the runs were checked against."""

    name: str
    path: str
    discharges: tuple[NasaDischarge, ...]
    skipped: tuple[tuple[int, str], ...]
    cutoff_v: float


def _read(path: Path) -> np.ndarray:
    """The file's numeric rows, columns in :data:`COLUMNS` order."""
    if not path.exists():
        raise NasaDataError(path, "file", "no such file")
    if not path.is_file():
        raise NasaDataError(path, "file", "not a file (a cell is one BXXXX.csv.gz)")
    try:
        with gzip.open(path, "rt", newline="") as fh:
            text = fh.read()
    except (EOFError, OSError, zlib.error) as err:
        raise NasaDataError(path, "file", f"not a complete gzip file ({type(err).__name__})") from None
    except UnicodeDecodeError:
        raise NasaDataError(path, "file", "not a text CSV inside the gzip") from None
    lines = text.splitlines()
    if not lines:
        raise NasaDataError(path, "discharge", "no discharge in the file (it is empty)")
    header = [h.strip() for h in lines[0].split(",")]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise NasaDataError(path, missing[0], f"missing column; expected the columns {', '.join(COLUMNS)}")
    if len(lines) < 2:
        raise NasaDataError(path, "discharge", "no discharge in the file (a header and no rows)")
    try:
        rows = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2,
                          usecols=[header.index(c) for c in COLUMNS])
    except ValueError as err:
        raise NasaDataError(path, "row", f"not a number table: {str(err).splitlines()[0][:80]}") from None
    return rows


def _start_times(path: Path, name: str) -> dict[int, float]:
    """Start time (s since 1970, UTC taken as the lab's clock) of each of cell ``name``'s runs, by index,
    from the ``discharges.csv`` beside ``path``; empty where there is none or it cannot be read."""
    table = path.parent / "discharges.csv"
    try:
        stamp = table.stat().st_mtime_ns
    except OSError:
        return {}
    return _start_table(str(table), stamp).get(name, {})


@functools.lru_cache(maxsize=4)
def _start_table(table: str, stamp: int) -> dict[str, dict[int, float]]:
    """Every cell's start times in ``table`` (read once per file version ``stamp``)."""
    out: dict[str, dict[int, float]] = {}
    try:
        with open(table, newline="") as fh:
            for row in csv.DictReader(fh):
                v = [float(x) for x in row["start_time"].strip("[] ").split()]
                whole = datetime.datetime(int(v[0]), int(v[1]), int(v[2]), int(v[3]), int(v[4]),
                                          tzinfo=datetime.timezone.utc)
                out.setdefault(row["battery_id"], {})[int(row["discharge"])] = whole.timestamp() + v[5]
    except (OSError, KeyError, ValueError, IndexError, TypeError):
        return {}
    return out


def load_nasa_cell(path: str | os.PathLike, cutoff_v: float = DEFAULT_EOD_V) -> NasaCell:
    """Load one cell file; runs that cannot be scored at ``cutoff_v`` (V) are listed in ``skipped``.
    Each run's rest before it comes from the folder's ``discharges.csv`` where that holds the cell's start
    times (else NaN).

    :raises NasaDataError: the file is missing, not a complete gzip CSV of this format, holds NaN or a
        time that does not increase within a discharge, or no discharge.
    """
    path = Path(path)
    rows = _read(path)
    col = {c: rows[:, k] for k, c in enumerate(COLUMNS)}
    for c in ("discharge", "time_s", "voltage_V", "current_A", "ambient_C"):
        bad = ~np.isfinite(col[c])
        if bad.any():
            where = col["discharge"][np.argmax(bad)]
            at = f"discharge {int(where)}" if np.isfinite(where) else "a row"
            raise NasaDataError(path, c, f"not a finite number in {at} (row {int(np.argmax(bad)) + 2})")
    index = col["discharge"].astype(int)
    starts = np.flatnonzero(np.r_[True, np.diff(index) != 0])
    ends = np.r_[starts[1:], index.size]
    name = path.name.split(".")[0]
    started = _start_times(path, name)
    out, skipped = [], []
    ended = math.nan  # s since 1970: the end of the previous run
    for a, b in zip(starts, ends):
        k = int(index[a])
        t = col["time_s"][a:b]
        begun = started.get(k, math.nan)
        rest = begun - ended
        ended = begun + float(t[-1])
        if np.any(np.diff(t) <= 0):
            raise NasaDataError(path, "time_s", f"does not increase within discharge {k}")
        v, i = col["voltage_V"][a:b], -col["current_A"][a:b]
        if b - a < MIN_SAMPLES:
            skipped.append((k, f"too short: {b - a} samples (at least {MIN_SAMPLES})"))
            continue
        on = np.flatnonzero(i > LOADED_A)
        if on.size == 0:
            skipped.append((k, f"never under load (largest current {i.max():.3f} A)"))
            continue
        if on[0] == 0:
            skipped.append((k, f"already under load at the first sample ({i[0]:.2f} A): no rest voltage"))
            continue
        d = NasaDischarge(name, k, int(col["uid"][a]), float(col["ambient_C"][a]), t.copy(), v.copy(), i.copy(),
                          col["temperature_C"][a:b].copy(), int(on[0]), rest if rest >= 0 else math.nan)
        t_cut = d.time_to_cutoff_s(cutoff_v)
        if t_cut is None:
            skipped.append((k, f"never below the cut-off {cutoff_v:g} V (lowest {v[on[0]:].min():.3f} V)"))
            continue
        if t_cut == 0.0:
            skipped.append((k, f"below the cut-off {cutoff_v:g} V at the first sample under load ({v[on[0]]:.3f} V)"))
            continue
        out.append(d)
    return NasaCell(name, str(path), tuple(out), tuple(skipped), float(cutoff_v))


def nasa_folder(path: str | os.PathLike | None = None) -> Path:
    """The data's folder: ``path`` if given, else ``$UAM_STUDIO_NASA_DATA``, else :data:`BESIDE_CHECKOUT`
    where a source checkout has it, else the bundled :data:`SAMPLE` (one cell; ``places.sample_note`` says so).

    :raises NasaDataError: none found (the package's sample removed); the message says what to do.
    """
    text = str(path) if path is not None else os.environ.get(DATA_ENV, "")
    if not text and in_checkout() and any(BESIDE_CHECKOUT.glob(CELL_GLOB)):
        text = str(BESIDE_CHECKOUT)
    if not text and any(SAMPLE.glob(CELL_GLOB)):
        text = str(SAMPLE)
    if not text:
        raise NasaDataError(SAMPLE, "data", f"no NASA PCoE folder given, none at ${DATA_ENV}, and the bundled "
                                            "sample is missing; pass --data DIR (see `uam-studio data`)")
    return Path(text).expanduser()


def available_cells(folder: str | os.PathLike, wanted: list[str]) -> list[str]:
    """The cells of ``wanted`` (names such as ``B0005``) that ``folder`` holds, in that order; where it holds
    none of them, every cell it holds (the sample: B0005)."""
    held = [f.name.split(".")[0] for f in sorted(Path(folder).glob(CELL_GLOB))]
    return [c for c in wanted if c in held] or held


def nasa_cell_files(folder: str | os.PathLike, cells: list[str] | None = None) -> list[Path]:
    """The cell files (``BXXXX.csv.gz``) in ``folder``, sorted; only ``cells`` (names such as ``B0005``)
    if given.

    :raises NasaDataError: no such folder, no cell file in it, or a named cell that is not there.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise NasaDataError(folder, "data", "no such folder")
    files = sorted(folder.glob(CELL_GLOB))
    if not files:
        raise NasaDataError(folder, "data", f"no cell file ({CELL_GLOB}) in the folder")
    if cells:
        by_name = {f.name.split(".")[0]: f for f in files}
        missing = [c for c in cells if c not in by_name]
        if missing:
            raise NasaDataError(folder, "cell", f"{missing[0]!r} is not in the folder; allowed: "
                                                f"{', '.join(sorted(by_name))}")
        files = [by_name[c] for c in cells]
    return files


def load_nasa_folder(folder: str | os.PathLike, cells: list[str] | None = None,
                     cutoff_v: float = DEFAULT_EOD_V) -> list[NasaCell]:
    """Every cell file of ``folder`` (or only ``cells``), loaded with :func:`load_nasa_cell`."""
    return [load_nasa_cell(f, cutoff_v) for f in nasa_cell_files(folder, cells)]


class RunConditions(Protocol):
    """What :func:`same_conditions` reads of a discharge, finished or known only up to its context: its
    ambient (C) and its mean load (A)."""

    @property
    def ambient_c(self) -> float: ...

    def mean_load_a(self) -> float: ...


def same_conditions(a: RunConditions, b: RunConditions, load_tol_a: float = 0.1, ambient_tol_c: float = 3.0) -> bool:
    """Whether two discharges ran at the same mean load (within ``load_tol_a``, A) and ambient (within
    ``ambient_tol_c``, C): where a previous discharge can stand for the next."""
    return abs(a.mean_load_a() - b.mean_load_a()) <= load_tol_a and abs(a.ambient_c - b.ambient_c) <= ambient_tol_c


def persistence_s(cell: NasaCell, position: int, cutoff_v: float = DEFAULT_EOD_V) -> float | None:
    """The persistence baseline for the discharge at ``position`` in ``cell.discharges``: the time to
    ``cutoff_v`` (s from the first loaded sample) of the latest earlier discharge of the same cell at the
    same load and ambient (:func:`same_conditions`); None where there is none."""
    target = cell.discharges[position]
    for prev in reversed(cell.discharges[:position]):
        if same_conditions(prev, target):
            return prev.time_to_cutoff_s(cutoff_v)
    return None

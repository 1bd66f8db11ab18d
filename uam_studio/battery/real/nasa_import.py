"""NASA PCoE's own published files (one MATLAB ``.mat`` file per cell, ``BXXXX.mat``) converted into the format
:mod:`uam_studio.battery.real.nasa_data` reads.

A source file holds one struct named after the cell with a field ``cycle``: a struct array, one element per
run, each with ``type`` ('charge', 'discharge' or 'impedance'), ``ambient_temperature`` (C), ``time`` (the
run's start, a MATLAB date vector: year, month, day, hour, minute, seconds) and ``data``. A discharge's
``data`` holds ``Voltage_measured`` (V), ``Current_measured`` (A, negative = discharge),
``Temperature_measured`` (C), ``Current_load`` (A), ``Voltage_load`` (V), ``Time`` (s from the run's start)
and ``Capacity`` (Ah); an impedance run's holds ``Re`` and ``Rct`` (ohm) among others.

:func:`import_nasa` writes, for every ``.mat`` file of a folder:

- ``BXXXX.csv.gz``: every discharge, in order (the columns of :data:`nasa_data.COLUMNS`; ``uid`` is the
  run's position among all of the cell's runs, from 1);
- ``discharges.csv``: one row per discharge (cell, index, uid, test id, start time, ambient, capacity,
  samples, source file), which gives the loader each run's rest;
- ``metadata.csv``: the cycle table (charge, discharge and impedance rows, with ``Re`` and ``Rct``).

Every file is written to a temporary name and renamed into place only once all files have been read and
converted, so a missing, damaged or foreign file leaves the output folder as it was, and running it again
rewrites the same bytes. Nothing reaches the network.
"""

from __future__ import annotations

import csv
import gzip
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.io

from uam_studio.atomic_io import atomic_write_bytes
from uam_studio.battery.real.nasa_data import COLUMNS, NasaDataError

__all__ = ["ImportedCell", "import_nasa", "read_nasa_mat"]

DISCHARGE_FIELDS = ("Voltage_measured", "Current_measured", "Temperature_measured", "Current_load",
                    "Voltage_load", "Time")
TABLE_HEAD = ("battery_id", "discharge", "uid", "test_id", "start_time", "ambient_C", "capacity_Ah", "samples",
              "source_file")
META_HEAD = ("type", "start_time", "ambient_temperature", "battery_id", "test_id", "uid", "filename", "Capacity",
             "Re", "Rct")


@dataclass(frozen=True)
class ImportedCell:
    """One converted cell: its name, the cell file's bytes (gzip CSV), and the rows it adds to
    ``discharges.csv`` and ``metadata.csv``."""

    name: str
    cell_file: bytes
    discharges: list[list[str]]
    metadata: list[list[str]]


def _field(obj, name: str, path: Path, where: str):
    if not hasattr(obj, name):
        raise NasaDataError(path, name, f"missing in {where}: not NASA PCoE's cell format")
    return getattr(obj, name)


def _vector(obj, name: str, path: Path, where: str) -> np.ndarray:
    raw = np.asarray(_field(obj, name, path, where))
    if raw.size == 0:
        raise NasaDataError(path, name, f"missing or empty in {where}: not NASA PCoE's cell format")
    try:
        v = np.atleast_1d(raw.astype(float)).ravel()
    except (TypeError, ValueError):
        raise NasaDataError(path, name, f"not numbers in {where}") from None
    return v


def _date(vec: np.ndarray) -> str:
    return "[" + " ".join(f"{x:.4e}" for x in vec) + "]"


def _num(x: float | None) -> str:
    return "" if x is None or not np.isfinite(x) else repr(float(x))


def read_nasa_mat(path: str | os.PathLike) -> ImportedCell:
    """Convert one NASA PCoE ``BXXXX.mat`` file (module docstring).

    :raises NasaDataError: the file is missing, not a MATLAB file, holds no cell struct named after the
        file, or a run lacks a field or holds something other than numbers; one line naming the file and
        the field.
    """
    path = Path(path)
    name = path.stem
    if not path.is_file():
        raise NasaDataError(path, "file", "no such file")
    try:
        mat = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except (ValueError, TypeError, OSError, NotImplementedError, scipy.io.matlab.MatReadError) as err:
        raise NasaDataError(path, "file", f"not a complete MATLAB .mat file ({type(err).__name__}: {err})") from None
    if name not in mat:
        found = ", ".join(k for k in mat if not k.startswith("__")) or "nothing"
        raise NasaDataError(path, "cell", f"no struct named {name!r} in the file (it holds {found})")
    cycles = np.atleast_1d(_field(mat[name], "cycle", path, name))
    rows: list[str] = []
    table: list[list[str]] = []
    meta: list[list[str]] = []
    k = 0
    for uid, cyc in enumerate(cycles, start=1):
        where = f"cycle {uid}"
        kind = str(_field(cyc, "type", path, where)).strip()
        ambient = float(np.asarray(_field(cyc, "ambient_temperature", path, where), dtype=float))
        start = _vector(cyc, "time", path, where)
        data = _field(cyc, "data", path, where)
        re = rct = capacity = None
        if kind == "impedance":
            re = float(np.real(np.asarray(data.Re))) if hasattr(data, "Re") else None
            rct = float(np.real(np.asarray(data.Rct))) if hasattr(data, "Rct") else None
        if kind == "discharge":
            cols = [_vector(data, f, path, f"{where} (discharge)") for f in DISCHARGE_FIELDS]
            n = cols[0].size
            if any(c.size != n for c in cols):
                raise NasaDataError(path, "data", f"{where}: the discharge's fields differ in length")
            if n == 0:
                raise NasaDataError(path, "data", f"{where}: a discharge with no samples")
            cap = _vector(data, "Capacity", path, f"{where} (discharge)") if hasattr(data, "Capacity") else None
            capacity = float(cap[0]) if cap is not None and cap.size else None
            v, i, temp, i_load, v_load, t = cols
            for j in range(n):
                rows.append(f"{k},{uid},{ambient:g},{t[j]:.3f},{v[j]:.6f},{i[j]:.6f},{temp[j]:.4f},"
                            f"{i_load[j]:.6f},{v_load[j]:.6f}")
            table.append([name, str(k), str(uid), str(uid - 1), _date(start), f"{ambient:g}", _num(capacity), str(n),
                          path.name])
            k += 1
        meta.append([kind, _date(start), f"{ambient:g}", name, str(uid - 1), str(uid), path.name, _num(capacity),
                     _num(re), _num(rct)])
    if k == 0:
        raise NasaDataError(path, "cycle", "no discharge run in the file")
    text = ",".join(COLUMNS) + "\n" + "\n".join(rows) + "\n"
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=0) as gz:  # mtime 0: the same input gives the same bytes
        gz.write(text.encode())
    return ImportedCell(name, buf.getvalue(), table, meta)


def _csv(head: tuple[str, ...], rows: list[list[str]]) -> bytes:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(head)
    w.writerows(rows)
    return out.getvalue().encode()


def import_nasa(source: str | os.PathLike, out: str | os.PathLike) -> list[ImportedCell]:
    """Convert every ``B*.mat`` file of ``source`` into ``out`` (created if needed; module docstring). All
    files are read and converted before any is written; each is then written atomically.

    :raises NasaDataError: ``source`` is not a folder or holds no ``B*.mat`` file; or any file's own error
        (:func:`read_nasa_mat`). ``out`` is then left as it was.
    """
    src, dst = Path(source), Path(out)
    if not src.is_dir():
        raise NasaDataError(src, "source", "no such folder (the folder of NASA's BXXXX.mat files)")
    files = sorted(src.glob("B*.mat"))
    if not files:
        raise NasaDataError(src, "source", "no BXXXX.mat file in the folder")
    if dst.exists() and not dst.is_dir():
        raise NasaDataError(dst, "out", "exists and is not a folder")
    cells = [read_nasa_mat(f) for f in files]
    dst.mkdir(parents=True, exist_ok=True)
    for c in cells:
        atomic_write_bytes(dst / f"{c.name}.csv.gz", c.cell_file)
    atomic_write_bytes(dst / "discharges.csv", _csv(TABLE_HEAD, [r for c in cells for r in c.discharges]))
    atomic_write_bytes(dst / "metadata.csv", _csv(META_HEAD, [r for c in cells for r in c.metadata]))
    return cells

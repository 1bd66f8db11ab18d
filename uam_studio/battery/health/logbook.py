"""A pack's logbook: every finished flight of one pack, as its sensors measured it.

A flight is the record from a full charge to the landing that ends it: its current (A) and voltage (V) at a
fixed step (s), the ambient temperature (C) where known, and the rest (s) since the previous flight ended
(NaN: unknown). Each flight carries its whole-record health fit (:class:`FlightFit`, the likelihood of its
readings alone, :func:`~uam_studio.battery.health.fit.fit_health` with ``prior=False``), computed once when the
flight is logged and stored in the file, so that reading a logbook of 100 flights refits nothing.

The file is JSON (never pickle), tagged ``"format": "uam_studio.logbook"`` and ``"version": 1``; it is written
atomically (:mod:`uam_studio.atomic_io`). A damaged, truncated or foreign file is refused with one line naming
the file and the problem (:class:`LogbookError`, an :class:`~uam_studio.errors.InputError` of field
``logbook``); the file on disk is never changed by a failed load.

Public API: :class:`Logbook` (``appended``, ``save``, :meth:`Logbook.load`), :class:`LoggedFlight`,
:class:`FlightFit`, :func:`fit_flight`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from uam_studio.atomic_io import atomic_write_text
from uam_studio.battery.health.estimate import MIN_CONTEXT_S
from uam_studio.battery.health.fit import fit_health
from uam_studio.battery.parameters import DEFAULT_CELL, DEFAULT_Q_MAX, CellParameters
from uam_studio.battery.simulate import CURRENT_LIMIT_A, DEFAULT_EOD_V, R0_RANGE
from uam_studio.errors import InputError

__all__ = ["LOGBOOK_FORMAT", "LOGBOOK_VERSION", "FlightFit", "Logbook", "LogbookError", "LoggedFlight",
           "delivered_charge_c", "fit_flight"]

LOGBOOK_FORMAT = "uam_studio.logbook"
LOGBOOK_VERSION = 1
MAX_FLIGHTS = 10_000
VOLTAGE_RANGE_V = (0.0, 5.0)  # V: a reading of the cell type
DT_RANGE_S = (0.1, 60.0)  # s: a flight's sample step
MAX_CYCLES = 10_000  # equivalent full cycles a pack may have delivered before its log: far past any 18650's life
MAX_REST_S = 10 * 365.25 * 86400.0  # s: ten years on a shelf
MAX_DEPTH = 5  # nesting of a logbook document: its object, flights, a flight, its fit, the fit's covariance
# The keys each level of the document may hold (what to_dict writes); any other is refused by name.
DOC_KEYS = ("format", "version", "pack", "delivered_before_c", "q_nominal_c", "noise_v", "eod_v", "flights")
FLIGHT_KEYS = ("dt_s", "rest_s", "ambient_c", "current_a", "voltage_v", "fit")
FIT_KEYS = ("w", "r0_ohm", "cov_w", "discrepancy_factor", "flags")


class LogbookError(InputError):
    """A logbook file that cannot be read: ``str(err)`` is one line, ``logbook: <file>: <problem>``."""

    def __init__(self, path: str | os.PathLike[str], problem: str) -> None:
        super().__init__("logbook", f"{path}: {problem}")


@dataclass(frozen=True)
class FlightFit:
    """One flight's whole-record health fit, the likelihood of its readings alone: (``w``, ``r0_ohm``) with
    ``w = 6500 C / q_max`` and the 2x2 covariance ``cov_w`` of (w, R0) (-, -ohm, ohm^2), the model-discrepancy
    factor the covariance holds (>= 1) and the fit's flags."""

    w: float
    r0_ohm: float
    cov_w: tuple[float, float, float, float]
    discrepancy_factor: float = 1.0
    flags: tuple[str, ...] = ()

    @property
    def mean(self) -> np.ndarray:
        """(w, R0 ohm)."""
        return np.array([self.w, self.r0_ohm])

    @property
    def cov(self) -> np.ndarray:
        """The 2x2 covariance of (w, R0)."""
        return np.array(self.cov_w, dtype=float).reshape(2, 2)


def fit_flight(current_a: np.ndarray, voltage_v: np.ndarray, dt_s: float = 1.0, noise_v: float | None = None,
               eod_v: float = DEFAULT_EOD_V, cell: CellParameters = DEFAULT_CELL) -> FlightFit | None:
    """The whole-record fit of one flight from a full charge (current A, voltage V, step s; ``noise_v``: the
    voltage sensor's stated noise std, V, or None to estimate it) on the parameter set ``cell``; None for a record
    shorter than the fit's shortest context or one the fit refuses."""
    cur, volt = np.asarray(current_a, dtype=float), np.asarray(voltage_v, dtype=float)
    if cur.size * dt_s < MIN_CONTEXT_S:
        return None
    try:
        est = fit_health(cur, volt, dt_s, noise_v=noise_v, eod_v=eod_v, cell=cell, prior=False)
    except InputError:
        return None
    c = est.cov_w
    return FlightFit(float(est.w), float(est.r0), (float(c[0, 0]), float(c[0, 1]), float(c[1, 0]), float(c[1, 1])),
                     float(est.discrepancy_factor), tuple(est.flags))


def delivered_charge_c(current_a: np.ndarray, dt_s: float) -> float:
    """The charge (C) a pack delivered over readings ``current_a`` (A, discharge positive) at step ``dt_s`` (s):
    the aging clock's tick (charging current does not count)."""
    return float(np.sum(np.clip(current_a, 0.0, None), dtype=float) * dt_s)


@dataclass(frozen=True, eq=False)
class LoggedFlight:
    """One finished flight of the pack, as measured: ``current_a`` (A) and ``voltage_v`` (V; both kept in single
    precision, far finer than the sensors) at step ``dt_s`` (s) from a full charge, ``rest_s`` (s) since the
    previous flight ended (NaN: unknown), ``ambient_c`` (C; NaN: unknown) and its stored :class:`FlightFit` (None:
    too short to fit)."""

    current_a: np.ndarray
    voltage_v: np.ndarray
    dt_s: float = 1.0
    rest_s: float = math.nan
    ambient_c: float = math.nan
    fit: FlightFit | None = None

    @property
    def charge_c(self) -> float:
        """The charge it delivered (C): its measured current integrated over the record."""
        return delivered_charge_c(self.current_a, self.dt_s)

    @property
    def duration_s(self) -> float:
        """Its length (s)."""
        return float(self.current_a.size * self.dt_s)


@dataclass(frozen=True)
class Logbook:
    """The record of every finished flight of one pack, oldest first.

    :param flights: the flights (:class:`LoggedFlight`).
    :param delivered_before_c: charge (C) the pack delivered before its first logged flight (its coulomb
        counter; 0 for a pack logged from new).
    :param q_nominal_c: the aging clock's unit (C): a pack's equivalent full cycles are its delivered charge
        over this.
    :param noise_v: the voltage sensor's stated noise std (V) the fits used (None: estimated per flight).
    :param eod_v: the cut-off (V) the fits used.
    :param pack: the pack's name.
    """

    flights: tuple[LoggedFlight, ...] = ()
    delivered_before_c: float = 0.0
    q_nominal_c: float = DEFAULT_Q_MAX
    noise_v: float | None = None
    eod_v: float = DEFAULT_EOD_V
    pack: str = "pack"

    def __len__(self) -> int:
        return len(self.flights)

    def delivered_c(self, flights: int | None = None) -> float:
        """Charge (C) the pack had delivered when its flight ``flights`` began (None: after the last)."""
        k = len(self.flights) if flights is None else flights
        return self.delivered_before_c + sum(f.charge_c for f in self.flights[:k])

    def appended(self, current_a: np.ndarray, voltage_v: np.ndarray, dt_s: float = 1.0, rest_s: float = math.nan,
                 ambient_c: float = math.nan, cell: CellParameters = DEFAULT_CELL) -> Logbook:
        """This logbook with one more flight (its readings from a full charge), fitted now on the parameter set
        ``cell`` and kept with its fit."""
        cur, volt = _series("current_a", current_a), _series("voltage_v", voltage_v)
        if cur.size != volt.size or cur.size == 0:
            raise InputError("flight", f"current ({cur.size}) and voltage ({volt.size}) readings: allowed the same "
                                       "number, at least one")
        fit = fit_flight(cur, volt, dt_s, self.noise_v, self.eod_v, cell)
        flight = LoggedFlight(cur.astype(np.float32), volt.astype(np.float32), float(dt_s), float(rest_s),
                              float(ambient_c), fit)
        return replace(self, flights=self.flights + (flight,))

    def extended(self, records: Sequence[tuple[np.ndarray, np.ndarray]], dt_s: float = 1.0,
                 rest_s: float = math.nan, ambient_c: float = math.nan, cell: CellParameters = DEFAULT_CELL
                 ) -> Logbook:
        """This logbook with several flights appended (``(current A, voltage V)`` each; the first after
        ``rest_s`` (s), the others back to back), each at ``ambient_c`` (C) and fitted on ``cell``, as
        :meth:`appended`."""
        book = self
        for k, (cur, volt) in enumerate(records):
            book = book.appended(cur, volt, dt_s, rest_s if k == 0 else 0.0, ambient_c, cell)
        return book

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict[str, Any]:
        """The JSON document (finite numbers; an unknown rest or ambient is null)."""
        def num(x: float) -> float | None:
            return None if not math.isfinite(x) else round(float(x), 6)

        return {"format": LOGBOOK_FORMAT, "version": LOGBOOK_VERSION, "pack": self.pack,
                "delivered_before_c": num(self.delivered_before_c), "q_nominal_c": num(self.q_nominal_c),
                "noise_v": None if self.noise_v is None else num(self.noise_v), "eod_v": num(self.eod_v),
                "flights": [{"dt_s": f.dt_s, "rest_s": num(f.rest_s), "ambient_c": num(f.ambient_c),
                             "current_a": [round(float(x), 5) for x in f.current_a],
                             "voltage_v": [round(float(x), 5) for x in f.voltage_v],
                             "fit": None if f.fit is None else {
                                 "w": f.fit.w, "r0_ohm": f.fit.r0_ohm, "cov_w": list(f.fit.cov_w),
                                 "discrepancy_factor": f.fit.discrepancy_factor, "flags": list(f.fit.flags)}}
                            for f in self.flights]}

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the logbook to ``path`` atomically (the old file stays whole until the new one replaces it)."""
        atomic_write_text(path, json.dumps(self.to_dict(), allow_nan=False, separators=(",", ":")) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Logbook:
        """Read a logbook file.

        :raises LogbookError: one line naming the file and the problem (missing, not JSON or truncated, another
            format or a newer version, a field missing or out of range)."""
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise LogbookError(p, f"cannot be read ({type(err).__name__}: {getattr(err, 'strerror', None) or err})"
                               ) from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as err:
            raise LogbookError(p, f"not a logbook: invalid or truncated JSON at line {err.lineno} column {err.colno}"
                               ) from None
        except RecursionError:
            raise LogbookError(p, "not a logbook: nested deeper than Python's parser goes; allowed at most "
                                  f"{MAX_DEPTH} levels") from None
        return cls.from_dict(doc, p)

    @classmethod
    def from_dict(cls, doc: Any, where: str | os.PathLike[str] = "logbook") -> Logbook:
        """The logbook of a JSON document (:meth:`to_dict`); :class:`LogbookError` naming ``where`` otherwise."""
        if not isinstance(doc, dict) or doc.get("format") != LOGBOOK_FORMAT:
            raise LogbookError(where, f"not a logbook: expected \"format\": \"{LOGBOOK_FORMAT}\"")
        depth = _depth(doc)
        if depth > MAX_DEPTH:
            raise LogbookError(where, f"nested {depth} levels deep; allowed at most {MAX_DEPTH}")
        _known_keys(where, "the logbook", doc, DOC_KEYS)
        if doc.get("version") != LOGBOOK_VERSION:
            raise LogbookError(where, f"version {doc.get('version')!r}: this uam_studio reads version "
                                      f"{LOGBOOK_VERSION}")
        flights = doc.get("flights")
        if not isinstance(flights, list) or len(flights) > MAX_FLIGHTS:
            raise LogbookError(where, f"flights: expected a list of at most {MAX_FLIGHTS} flights")
        noise = doc.get("noise_v")
        q_nominal = _number(where, "q_nominal_c", doc.get("q_nominal_c"), 100.0, 1e6)
        book = cls(delivered_before_c=_number(where, "delivered_before_c", doc.get("delivered_before_c"), 0.0,
                                              MAX_CYCLES * q_nominal),
                   q_nominal_c=q_nominal,
                   noise_v=None if noise is None else _number(where, "noise_v", noise, 0.0, 1.0),
                   eod_v=_number(where, "eod_v", doc.get("eod_v"), *VOLTAGE_RANGE_V),
                   pack=str(doc.get("pack", "pack"))[:200])
        out = [_flight(where, k, f) for k, f in enumerate(flights)]
        return replace(book, flights=tuple(out))


def _depth(value: Any) -> int:
    """Levels of lists and objects in a JSON value (a number or a string: 0), counted without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, dict):
            item = list(item.values())
        if isinstance(item, list):
            deepest = max(deepest, level)
            # a list comprehension, not a generator: a 100-flight logbook's sample lists in 22 ms, not 37
            stack += [(x, level + 1) for x in item if isinstance(x, (list, dict))]
    return deepest


def _known_keys(where: str | os.PathLike[str], what: str, obj: dict, allowed: tuple[str, ...]) -> None:
    unknown = sorted(str(k) for k in obj if k not in allowed)
    if unknown:
        raise LogbookError(where, f"{what}: unknown key {unknown[0][:40]!r}; allowed {', '.join(allowed)}")


def _series(name: str, value: Any) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise InputError(name, "expected a 1-D series of finite numbers")
    return arr


def _number(where: str | os.PathLike[str], name: str, value: Any, lo: float, hi: float, nan_ok: bool = False) -> float:
    if value is None and nan_ok:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= float(value) <= hi:
        raise LogbookError(where, f"{name}: {value!r}; allowed a number in [{lo:g}, {hi:g}]")
    return float(value)


def _flight(where: str | os.PathLike[str], k: int, f: Any) -> LoggedFlight:
    if not isinstance(f, dict):
        raise LogbookError(where, f"flights[{k}]: expected an object")
    _known_keys(where, f"flights[{k}]", f, FLIGHT_KEYS)
    dt = _number(where, f"flights[{k}].dt_s", f.get("dt_s"), *DT_RANGE_S)
    arrays = []
    for name, (lo, hi) in (("current_a", (-CURRENT_LIMIT_A, CURRENT_LIMIT_A)), ("voltage_v", VOLTAGE_RANGE_V)):
        raw = f.get(name)
        if not isinstance(raw, list) or not raw or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in raw):
            raise LogbookError(where, f"flights[{k}].{name}: expected a non-empty list of numbers")
        arr = np.asarray(raw, dtype=float)
        if not np.all(np.isfinite(arr)) or arr.min() < lo or arr.max() > hi:
            raise LogbookError(where, f"flights[{k}].{name}: values outside [{lo:g}, {hi:g}]")
        arrays.append(arr.astype(np.float32))
    if arrays[0].size != arrays[1].size:
        raise LogbookError(where, f"flights[{k}]: {arrays[0].size} currents against {arrays[1].size} voltages")
    fit = f.get("fit")
    stored = None
    if fit is not None:
        if not isinstance(fit, dict) or not isinstance(fit.get("cov_w"), list) or len(fit["cov_w"]) != 4:
            raise LogbookError(where, f"flights[{k}].fit: expected w, r0_ohm, cov_w (4 numbers)")
        _known_keys(where, f"flights[{k}].fit", fit, FIT_KEYS)
        cov = tuple(_number(where, f"flights[{k}].fit.cov_w", c, -1e6, 1e6) for c in fit["cov_w"])
        symmetric = abs(cov[1] - cov[2]) <= 1e-9 * max(abs(cov[1]), abs(cov[2]), 1e-300)
        if not (cov[0] > 0 and cov[3] > 0 and symmetric and cov[0] * cov[3] - cov[1] * cov[2] > 0):
            raise LogbookError(where, f"flights[{k}].fit.cov_w: {list(cov)}; allowed a symmetric positive-definite 2x2 "
                                      "covariance (variances > 0, |correlation| < 1)")
        flags = fit.get("flags", [])
        stored = FlightFit(_number(where, f"flights[{k}].fit.w", fit.get("w"), 0.01, 100.0),
                           _number(where, f"flights[{k}].fit.r0_ohm", fit.get("r0_ohm"), *R0_RANGE),
                           (cov[0], cov[1], cov[2], cov[3]),
                           _number(where, f"flights[{k}].fit.discrepancy_factor", fit.get("discrepancy_factor", 1.0),
                                   1.0, 1e6),
                           tuple(str(x) for x in flags) if isinstance(flags, list) else ())
    return LoggedFlight(arrays[0], arrays[1], dt,
                        _number(where, f"flights[{k}].rest_s", f.get("rest_s"), 0.0, MAX_REST_S, nan_ok=True),
                        _number(where, f"flights[{k}].ambient_c", f.get("ambient_c"), -60.0, 100.0, nan_ok=True),
                        stored)

"""Missions: a vertiport, destinations, a scenario and a battery, with a stable JSON format.

JSON format (public and stable)::

    {
      "name": "Bay shuttle",
      "vertiport": {"x_km": 0.0, "y_km": 0.0, "wind_kts": 8.0},
      "destinations": [
        {"name": "Richmond", "x_km": 14.0, "y_km": 16.0, "priority": 2, "wind_kts": 13.0,
         "dwell_s": 300.0}
      ],
      "scenario": "single_charge",
      "battery": {"q_max": 7600.0, "r0": 0.117215},
      "eod_v": 3.0
    }

* coordinates ``x_km``/``y_km`` (km) in [-200, 200]; distances are euclidean;
* ``wind_kts`` (kt, [-39, 39], negative = tailwind): a destination's wind applies to
  legs flown *to* it, the vertiport's to legs flown back to the vertiport;
* ``priority`` is an integer 1-3; ``dwell_s`` (s, optional, default 0) is the time
  spent on the ground at a destination after landing;
* ``scenario`` is one of :data:`SCENARIOS`; ``battery.q_max`` (C), ``battery.r0``
  (ohm) and ``eod_v`` (V) use the ranges of :mod:`uam_studio.battery`.

Destination names must be non-empty, unique, free of commas (the CLI separates
route entries with commas) and must not be ``"vertiport"`` (any case), the name
of the vertiport node. A mission with no destinations is valid; planners report it.
A file holds at most :data:`MAX_DESTINATIONS` (20) destinations
(``destinations: 21 destinations; allowed 1 to 20``).
Unknown keys are rejected, so a misspelt optional field never passes silently.

Every validation error is an :class:`~uam_studio.errors.InputError` whose field is
the JSON path, e.g. ``destinations[2].priority: 4 is out of range; allowed [1, 3]``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import stat
import unicodedata
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from uam_studio.atomic_io import atomic_write_text, remove_stale_temps
from uam_studio.battery import DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0, EOD_RANGE, Q_MAX_RANGE, R0_RANGE
from uam_studio.battery.parameters import DEFAULT_CELL, Cell
from uam_studio.errors import InputError, check_range, short_repr
from uam_studio.flight.profile import MAX_DWELL_S
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO, check_scenario
from uam_studio.planning.missions.scenario import (
    SCENARIOS as SCENARIOS,  # re-exported: the mission format names them
)

VERTIPORT = "vertiport"
COORD_RANGE_KM = (-200.0, 200.0)
PRIORITY_RANGE = (1, 3)
MAX_NAME_LEN = 64
MAX_FILE_BYTES = 1_000_000  # mission JSON (bytes)
MAX_DESTINATIONS = 20  # the most destinations a mission may have (planners not tied to the paper's 8)
PAPER_DESTINATIONS = 8  # the paper's missions: at most 8 destinations (its DQN's slots, the exact oracle's limit)


def check_destination_count(n: int, limit: int = MAX_DESTINATIONS, who: str | None = None) -> int:
    """``n`` if a mission of ``n`` destinations can be planned (1 to ``limit``, default
    :data:`MAX_DESTINATIONS`), else :class:`InputError`, one line, e.g.
    ``destinations: 21 destinations; allowed 1 to 20``. ``who`` names a part with its own, smaller
    limit (``"fly"``: ``destinations: 9 destinations; fly plans at most 8 (allowed 1 to 8)``)."""
    if n < 1:
        raise InputError("destinations", f"a mission needs at least 1 destination (allowed 1 to {limit})")
    if n > limit:
        what = f"{who} plans at most {limit} (allowed 1 to {limit})" if who else f"allowed 1 to {limit}"
        raise InputError("destinations", f"{n} destinations; {what}")
    return n

_NUMBER = (int, float)


# --------------------------------------------------------------------------- helpers


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


@contextlib.contextmanager
def _under(prefix: str) -> Iterator[None]:
    """Re-raise an :class:`InputError` from inside with ``prefix.`` put before its field."""
    try:
        yield
    except InputError as err:
        if not prefix:
            raise
        message = str(err)[len(err.field) + 2:]
        raise InputError(_join(prefix, err.field), message) from None


def _number(field_name: str, value: Any, lo: float, hi: float, unit: str = "") -> float:
    """A JSON number (not a bool, not a string) in [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, _NUMBER):
        raise InputError(field_name, f"expected a number in [{lo:g}, {hi:g}]{unit}, got {short_repr(value)}")
    return check_range(field_name, value, lo, hi, unit)


# Unicode categories a name may not hold: controls, lone surrogates (not encodable: printing one
# fails), and invisible format characters such as right-to-left overrides and zero-width spaces.
_NOT_NAME_TEXT = {"Cc": "control character", "Cs": "lone surrogate", "Cf": "invisible format character"}


def _name(field_name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise InputError(field_name, f"expected a string, got {short_repr(value)}")
    if len(value) > MAX_NAME_LEN:
        raise InputError(field_name, f"is {len(value)} characters long; at most {MAX_NAME_LEN} allowed")
    bad = next((c for c in value if unicodedata.category(c) in _NOT_NAME_TEXT), None)
    if bad is not None:
        kind = _NOT_NAME_TEXT[unicodedata.category(bad)]
        raise InputError(field_name, f"{ascii(value)} contains the {kind} {ascii(bad)}; names are printable text")
    if not value.strip():
        raise InputError(field_name, "must not be empty")
    if value != value.strip():
        raise InputError(field_name, f"{value!r} has leading or trailing spaces")
    return value


def _key_text(key: Any) -> str:
    """A JSON key as it goes into an error's field name: as is when printable and short, else its repr."""
    return key if isinstance(key, str) and key.isprintable() and len(key) <= MAX_NAME_LEN else short_repr(key)


def _check_keys(path: str, d: Any, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> None:
    where = path or "mission"
    if not isinstance(d, Mapping):
        raise InputError(where, f"expected a JSON object, got {type(d).__name__}")
    for key in required:
        if key not in d:
            raise InputError(_join(path, key), "missing required field")
    allowed = required + optional
    for key in d:
        if key not in allowed:
            raise InputError(
                _join(path, _key_text(key)), f"unknown field; allowed fields are {', '.join(allowed)}"
            )


# --------------------------------------------------------------------------- dataclasses


@dataclass(frozen=True)
class Vertiport:
    """The base: position (km) and the wind (kt) on legs flown back to it."""

    x_km: float
    y_km: float
    wind_kts: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_km", _number("x_km", self.x_km, *COORD_RANGE_KM, " km"))
        object.__setattr__(self, "y_km", _number("y_km", self.y_km, *COORD_RANGE_KM, " km"))
        object.__setattr__(self, "wind_kts", _number("wind_kts", self.wind_kts, *WIND_RANGE_KTS, " kt"))


@dataclass(frozen=True)
class Destination:
    """A destination: position (km), priority 1-3, wind (kt) on legs flown to it, dwell (s)."""

    name: str
    x_km: float
    y_km: float
    priority: int
    wind_kts: float = 0.0
    dwell_s: float = 0.0

    def __post_init__(self) -> None:
        name = _name("name", self.name)
        if name.lower() == VERTIPORT:
            raise InputError("name", f"{name!r} is reserved for the vertiport node")
        if "," in name:
            raise InputError("name", f"{name!r} contains a comma; route entries are comma-separated")
        p: object = self.priority
        if isinstance(p, float) and p.is_integer():
            p = int(p)
        if isinstance(p, bool) or not isinstance(p, int):
            raise InputError("priority", f"expected an integer in [1, 3], got {short_repr(self.priority)}")
        if not PRIORITY_RANGE[0] <= p <= PRIORITY_RANGE[1]:
            raise InputError("priority", f"{short_repr(p)} is out of range; allowed [1, 3]")
        object.__setattr__(self, "priority", p)
        object.__setattr__(self, "x_km", _number("x_km", self.x_km, *COORD_RANGE_KM, " km"))
        object.__setattr__(self, "y_km", _number("y_km", self.y_km, *COORD_RANGE_KM, " km"))
        object.__setattr__(self, "wind_kts", _number("wind_kts", self.wind_kts, *WIND_RANGE_KTS, " kt"))
        object.__setattr__(self, "dwell_s", _number("dwell_s", self.dwell_s, 0.0, MAX_DWELL_S, " s"))


@dataclass(frozen=True)
class Battery:
    """Health parameters of the cell: ``q_max`` (C) and ``r0`` (ohm)."""

    q_max: float = DEFAULT_Q_MAX
    r0: float = DEFAULT_R0

    def __post_init__(self) -> None:
        object.__setattr__(self, "q_max", _number("q_max", self.q_max, *Q_MAX_RANGE, " C"))
        object.__setattr__(self, "r0", _number("r0", self.r0, *R0_RANGE, " ohm"))


@dataclass(frozen=True)
class Mission:
    """A validated mission. Build one with :func:`mission_from_dict` or directly (also validated)."""

    name: str
    vertiport: Vertiport
    destinations: tuple[Destination, ...] = field(default_factory=tuple)
    scenario: str = DEFAULT_SCENARIO
    battery: Battery = field(default_factory=Battery)
    eod_v: float = DEFAULT_EOD_V

    def __post_init__(self) -> None:
        _name("name", self.name)
        if not isinstance(self.vertiport, Vertiport):
            raise InputError("vertiport", f"expected a Vertiport, got {type(self.vertiport).__name__}")
        dests = tuple(self.destinations)
        if len(dests) > MAX_DESTINATIONS:  # the one check of the mission's size; planners check their own caps
            check_destination_count(len(dests))
        seen: dict[str, int] = {}
        for i, d in enumerate(dests):
            if not isinstance(d, Destination):
                raise InputError(f"destinations[{i}]", f"expected a Destination, got {type(d).__name__}")
            if d.name in seen:
                raise InputError(
                    f"destinations[{i}].name",
                    f"{d.name!r} is already used by destinations[{seen[d.name]}]; names must be unique",
                )
            seen[d.name] = i
        object.__setattr__(self, "destinations", dests)
        check_scenario(self.scenario)
        if not isinstance(self.battery, Battery):
            raise InputError("battery", f"expected a Battery, got {type(self.battery).__name__}")
        object.__setattr__(self, "eod_v", _number("eod_v", self.eod_v, *EOD_RANGE, " V"))

    # ----------------------------------------------------------------- nodes

    @property
    def node_names(self) -> tuple[str, ...]:
        """``"vertiport"`` followed by the destination names, in file order."""
        return (VERTIPORT,) + tuple(d.name for d in self.destinations)

    def node(self, name: str) -> Vertiport | Destination:
        """The vertiport (``"vertiport"``) or the destination called ``name``."""
        if name == VERTIPORT:
            return self.vertiport
        for d in self.destinations:
            if d.name == name:
                return d
        raise InputError("node", f"unknown node {name!r}; valid names: {', '.join(self.node_names)}")

    def distance_km(self, a: str, b: str) -> float:
        """Euclidean distance (km) between two named nodes."""
        na, nb = self.node(a), self.node(b)
        return math.hypot(na.x_km - nb.x_km, na.y_km - nb.y_km)

    def leg_wind(self, to_name: str) -> float:
        """Wind (kt, negative = tailwind) on a leg flown to ``to_name``."""
        return self.node(to_name).wind_kts

    @property
    def cell(self) -> Cell:
        """The cell the mission is flown with: the default parameter set (the paper's 18650) at the
        mission's health (``battery.q_max`` C, ``battery.r0`` ohm), flown to ``eod_v`` (V)."""
        return Cell(f"{self.name} cell", DEFAULT_CELL, self.battery.q_max, self.battery.r0, self.eod_v)

    def with_battery(self, q_max: float | None = None, r0: float | None = None) -> Mission:
        """A copy with ``q_max`` (C) and/or ``r0`` (ohm) replaced (validated)."""
        battery = Battery(
            self.battery.q_max if q_max is None else q_max,
            self.battery.r0 if r0 is None else r0,
        )
        return dataclasses.replace(self, battery=battery)


# --------------------------------------------------------------------------- dict / JSON


def _vertiport_from_dict(d: Any) -> Vertiport:
    _check_keys("vertiport", d, ("x_km", "y_km", "wind_kts"))
    with _under("vertiport"):
        return Vertiport(d["x_km"], d["y_km"], d["wind_kts"])


def _destination_from_dict(i: int, d: Any) -> Destination:
    path = f"destinations[{i}]"
    _check_keys(path, d, ("name", "x_km", "y_km", "priority", "wind_kts"), ("dwell_s",))
    with _under(path):
        return Destination(d["name"], d["x_km"], d["y_km"], d["priority"], d["wind_kts"], d.get("dwell_s", 0.0))


def mission_from_dict(d: Any) -> Mission:
    """Validate a mission in the JSON format (see the module docstring) and build it.

    :raises InputError: naming the JSON path of the first bad field.
    """
    _check_keys("", d, ("name", "vertiport", "destinations", "scenario", "battery", "eod_v"))
    name = _name("name", d["name"])
    vertiport = _vertiport_from_dict(d["vertiport"])
    raw = d["destinations"]
    if not isinstance(raw, list):
        raise InputError("destinations", f"expected a list, got {type(raw).__name__}")
    if len(raw) > MAX_DESTINATIONS:  # before reading them: the same check as Mission's
        check_destination_count(len(raw))
    destinations = tuple(_destination_from_dict(i, x) for i, x in enumerate(raw))
    scenario = check_scenario(d["scenario"])
    _check_keys("battery", d["battery"], ("q_max", "r0"))
    with _under("battery"):
        battery = Battery(d["battery"]["q_max"], d["battery"]["r0"])
    return Mission(name, vertiport, destinations, scenario, battery, d["eod_v"])


def mission_to_dict(m: Mission) -> dict[str, Any]:
    """The JSON-format dict of a mission (``mission_from_dict(mission_to_dict(m)) == m``)."""
    return {
        "name": m.name,
        "vertiport": {"x_km": m.vertiport.x_km, "y_km": m.vertiport.y_km, "wind_kts": m.vertiport.wind_kts},
        "destinations": [
            {
                "name": d.name,
                "x_km": d.x_km,
                "y_km": d.y_km,
                "priority": d.priority,
                "wind_kts": d.wind_kts,
                "dwell_s": d.dwell_s,
            }
            for d in m.destinations
        ],
        "scenario": m.scenario,
        "battery": {"q_max": m.battery.q_max, "r0": m.battery.r0},
        "eod_v": m.eod_v,
    }


def mission_from_json(data: str | bytes, field: str = "file") -> Mission:
    """Parse and validate a mission from JSON text (or UTF-8 bytes) of at most ``MAX_FILE_BYTES``.

    Hostile JSON (duplicate keys, numbers of thousands of digits, arrays nested thousands deep)
    is an :class:`InputError` like any other bad input.

    :param field: the name errors about the text itself carry (``"file"``, or the app's upload field).
    :raises InputError: ``field`` for text that is empty, too large, not UTF-8 or not valid JSON,
        else the JSON path of the first bad field.
    """
    if data is None or len(data) == 0:
        raise InputError(field, "is empty; expected a mission JSON file")
    if len(data) > MAX_FILE_BYTES:
        raise InputError(field, f"is {len(data)} bytes; at most {MAX_FILE_BYTES} allowed")
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError as err:
            raise InputError(field, f"is not UTF-8 text (byte {err.start})") from None

    def no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in pairs:
            if key in out:
                raise InputError(field, f"duplicate key {short_repr(key)} in a JSON object")
            out[key] = value
        return out

    try:
        obj = json.loads(data, object_pairs_hook=no_duplicate_keys)
    except json.JSONDecodeError as err:
        raise InputError(field, f"is not valid JSON: {err.msg} at line {err.lineno}, column {err.colno}") \
            from None
    except InputError:
        raise
    except RecursionError:
        raise InputError(field, "is nested too deeply; a mission file is at most 4 levels deep") from None
    except ValueError as err:  # e.g. an integer of more than sys.get_int_max_str_digits() digits
        raise InputError(field, f"is not valid mission JSON: {' '.join(str(err).split())[:120]}") from None
    return mission_from_dict(obj)


def load_mission(path: str | os.PathLike[str]) -> Mission:
    """Read and validate a mission JSON file.

    Only a regular file is read, and at most ``MAX_FILE_BYTES + 1`` bytes of it: a device
    (``/dev/zero``), a named pipe (which would wait for a writer) or a socket is refused before it is
    opened.

    :raises InputError: field ``"file"`` if the file cannot be read, is not a regular file, is larger than
        ``MAX_FILE_BYTES`` or is not valid JSON (with line and column), else the JSON path of the first bad
        field.
    """
    p = Path(path)
    try:
        mode = p.stat().st_mode
        if stat.S_ISDIR(mode):
            raise IsADirectoryError
        if not stat.S_ISREG(mode):
            raise InputError("file", f"{str(p)!r} is not a regular file (a device, pipe or socket); "
                                     "expected a mission JSON file")
        with p.open("rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
        if len(data) > MAX_FILE_BYTES:
            size = max(p.stat().st_size, len(data))
            raise InputError("file", f"{str(p)!r} is {size} bytes; at most {MAX_FILE_BYTES} allowed")
    except FileNotFoundError:
        raise InputError("file", f"{str(p)!r} does not exist") from None
    except IsADirectoryError:
        raise InputError("file", f"{str(p)!r} is a directory, expected a mission JSON file") from None
    except OSError as err:
        raise InputError("file", f"cannot read {str(p)!r}: {err.strerror or err}") from None
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise InputError("file", f"{str(p)!r} is not UTF-8 text (byte {err.start})") from None
    try:
        return mission_from_json(data, "file")
    except InputError as err:
        rest = str(err)[len("file: "):]
        if err.field != "file" or not rest.startswith("is "):
            raise
        raise InputError("file", f"{str(p)!r} {rest}") from None


def as_mission(mission: Mission | dict | str | os.PathLike[str]) -> Mission:
    """``mission`` itself, a dict in the JSON format validated (:func:`mission_from_dict`) or a mission
    file read (:func:`load_mission`). :raises InputError: as those do."""
    if isinstance(mission, Mission):
        return mission
    if isinstance(mission, (str, os.PathLike)):
        return load_mission(mission)
    return mission_from_dict(mission)


def save_mission(m: Mission, path: str | os.PathLike[str]) -> None:
    """Write ``m`` as JSON atomically (:func:`uam_studio.atomic_io.atomic_write_text`).

    Readers see either the old file or the complete new one, never a partial write. Stale temp
    files of this file name (left by a killed save) are deleted first. An existing file's
    permission bits are kept.
    """
    p = Path(path)
    text = json.dumps(mission_to_dict(m), indent=2, allow_nan=False) + "\n"
    remove_stale_temps(p.parent, names=[p.name])
    atomic_write_text(p, text)

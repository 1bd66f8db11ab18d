"""A fleet's demand over an operating day: requests to fly to a place, with 1-3 stars and a time window.

Public API: :class:`Request`, :func:`poisson_demand` (a seeded Poisson day) and :func:`load_demand` (a
user's CSV or JSON file; bad rows get one line naming the field and its allowed range).
"""

from __future__ import annotations

import csv
import json
import math
import numbers
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from uam_studio.errors import InputError, check_range
from uam_studio.flight.tables import WIND_RANGE_KTS

__all__ = ["DAY_S", "MAX_REQUESTS", "MAX_VERTIPORTS", "RADIUS_KM", "Request", "day_seed", "load_demand",
           "poisson_demand"]

DAY_S = 12 * 3600.0  # s: the operating day (06:00-18:00)
RADIUS_KM = (8.0, 100.0)  # km: how far a request may be from the vertiport (500 m cruise needs over 6.2 km)
DEFAULT_MAX_KM = 45.0  # km: the Poisson day's farthest request
WIND_KTS = WIND_RANGE_KTS  # kt: the flight tables' range
MAX_REQUESTS = 2000  # in one day's file
DEFAULT_RATE_PER_H = 4.0  # requests per hour
DEFAULT_WINDOW_S = 2 * 3600.0  # s: a request waits this long for an aircraft, then it is refused
MAX_VERTIPORTS = 10  # vertiports of one fleet (each with its own aircraft and chargers)
FIELDS = ("t_s", "name", "x_km", "y_km", "priority", "wind_kts", "window_s", "vertiport")


def _check_small_int(field: str, value: object, lo: int, hi: int, allowed: str) -> None:
    """An integer (not a bool, not a float) from ``lo`` to ``hi``, else one line naming ``field`` and
    the ``allowed`` values."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= int(value) <= hi:
        raise InputError(field, f"{value!r}: allowed {allowed}")


def _ascii_digits(value: Any) -> Any:
    """A CSV cell of ASCII digits as an int; anything else unchanged (for the checks to refuse)."""
    return int(value) if isinstance(value, str) and value.strip().isdigit() and value.isascii() else value


@dataclass(frozen=True)
class Request:
    """Fly to (``x_km``, ``y_km``) km from vertiport number ``vertiport`` (0-9; aircraft based there serve
    it) and back, asked at ``t_s`` (s into the day), worth ``priority`` (1-3 stars), in a forecast wind of
    ``wind_kts`` (kt, + = headwind on the way out), served if an aircraft takes off before ``t_s + window_s``."""

    t_s: float
    name: str
    x_km: float
    y_km: float
    priority: int
    wind_kts: float = 0.0
    window_s: float = DEFAULT_WINDOW_S
    vertiport: int = 0

    def __post_init__(self) -> None:
        check_range("t_s", self.t_s, 0.0, DAY_S, " s")
        if not isinstance(self.name, str) or not self.name.strip() or len(self.name) > 60 \
                or not self.name.isprintable() or self.name.strip().lower() == "vertiport":
            raise InputError("name", f"{str(self.name)[:60]!r}: a printable name of 1-60 characters, not 'vertiport'")
        d = math.hypot(check_range("x_km", self.x_km, -100.0, 100.0, " km"),
                       check_range("y_km", self.y_km, -100.0, 100.0, " km"))
        if not RADIUS_KM[0] <= d <= RADIUS_KM[1]:
            raise InputError("x_km", f"({self.x_km:g}, {self.y_km:g}) is {d:.1f} km from the vertiport; "
                                     f"allowed {RADIUS_KM[0]:g}-{RADIUS_KM[1]:g} km")
        _check_small_int("priority", self.priority, 1, 3, "1, 2 or 3")
        check_range("wind_kts", self.wind_kts, *WIND_KTS, " kt")
        check_range("window_s", self.window_s, 60.0, DAY_S, " s")
        _check_small_int("vertiport", self.vertiport, 0, MAX_VERTIPORTS - 1, f"0-{MAX_VERTIPORTS - 1}")

    @property
    def distance_km(self) -> float:
        return math.hypot(self.x_km, self.y_km)


def day_seed(value: object) -> int:
    """A day's seed: any integer >= 0 (a life's seed times a stride plus the day; numpy takes any size).

    :raises InputError: (field ``seed``) for anything else."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < 0:
        raise InputError("seed", f"{str(value)[:40]!r}: expected an integer >= 0")
    return int(value)


def poisson_demand(seed: int, rate_per_h: float = DEFAULT_RATE_PER_H, day_s: float = DAY_S,
                   wind_sd_kts: float = 10.0, max_km: float = DEFAULT_MAX_KM, vertiports: int = 1) -> list[Request]:
    """A day of requests: a Poisson process of ``rate_per_h`` requests per hour over ``day_s`` s, each at
    a uniform bearing and a distance uniform in 8-``max_km`` km, 1-3 stars (half 1, a third 2, a
    sixth 3), a forecast wind ~ N(0, ``wind_sd_kts``) clipped to the tables, a 2 h window, from one of
    ``vertiports`` (1-10) vertiports drawn uniformly (a stream of its own: one vertiport draws the
    same requests as before there were several)."""
    seed = day_seed(seed)
    rate = check_range("rate_per_h", rate_per_h, 0.0, 60.0, " per h")
    day = check_range("day_s", day_s, 0.0, DAY_S, " s")
    far = check_range("max_km", max_km, RADIUS_KM[0], RADIUS_KM[1], " km")
    rng = np.random.default_rng(seed)
    n = int(rng.poisson(rate * day / 3600.0))
    times = np.sort(rng.uniform(0.0, day, n))
    bearing = rng.uniform(0.0, 2 * math.pi, n)
    dist = rng.uniform(RADIUS_KM[0] + 0.05, max(far - 0.05, RADIUS_KM[0] + 0.05), n)  # inside after rounding to 10 m
    prio = rng.choice([1, 2, 3], size=n, p=[0.5, 1 / 3, 1 / 6])
    wind = np.clip(rng.normal(0.0, wind_sd_kts, n), *WIND_KTS)
    n_ports = int(check_range("vertiports", vertiports, 1, MAX_VERTIPORTS))
    port = np.random.default_rng([seed, 3]).integers(0, n_ports, n) if n_ports > 1 else np.zeros(n, dtype=int)
    return [Request(float(t), f"R{k + 1}", round(float(d * math.cos(b)), 2), round(float(d * math.sin(b)), 2),
                    int(p), round(float(w), 1), vertiport=int(v))
            for k, (t, b, d, p, w, v) in enumerate(zip(times, bearing, dist, prio, wind, port))]


def _request(row: dict, where: str) -> Request:
    missing = [f for f in ("t_s", "x_km", "y_km", "priority") if row.get(f) in (None, "")]
    if missing:
        raise InputError(missing[0], f"{where}: missing (columns: {', '.join(FIELDS)})")
    try:
        return Request(float(row["t_s"]), str(row.get("name") or where), float(row["x_km"]), float(row["y_km"]),
                       _ascii_digits(row["priority"]), float(row.get("wind_kts") or 0.0),
                       float(row.get("window_s") or DEFAULT_WINDOW_S),
                       vertiport=_ascii_digits(row.get("vertiport") or 0))
    except InputError as err:
        raise InputError(err.field, f"{where}: {str(err)[len(err.field) + 2:]}") from None
    except (TypeError, ValueError) as err:
        raise InputError("demand", f"{where}: not a number ({err})") from None


def load_demand(path: str | Path) -> list[Request]:
    """Requests from a CSV file (a header row naming :data:`FIELDS`; ``name``, ``wind_kts``,
    ``window_s`` and ``vertiport`` optional) or a JSON file (a list of objects with those keys), sorted by time.

    :raises InputError: (field ``demand`` or the bad column's name) for anything else, in one line
        naming the row.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError("demand", f"{p}: not a file")
    if p.stat().st_size > 5_000_000:
        raise InputError("demand", f"{p}: {p.stat().st_size} bytes; allowed up to 5 MB")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError("demand", f"{p}: not readable UTF-8 text ({type(err).__name__})") from None
    if p.suffix.lower() == ".json":
        try:
            rows = json.loads(text)
        except ValueError as err:
            raise InputError("demand", f"{p}: not JSON ({err})") from None
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise InputError("demand", f"{p}: expected a JSON list of request objects")
    elif p.suffix.lower() == ".csv":
        rows = list(csv.DictReader(text.splitlines()))
    else:
        raise InputError("demand", f"{p}: expected a .csv or .json file")
    if len(rows) > MAX_REQUESTS:
        raise InputError("demand", f"{p}: {len(rows)} requests; allowed up to {MAX_REQUESTS}")
    out = [_request(r, f"request {k + 1}") for k, r in enumerate(rows)]
    names = [r.name for r in out]
    if len(set(names)) != len(names):
        raise InputError("name", f"{p}: request names must be unique")
    return sorted(out, key=lambda r: r.t_s)


def demand_rows(requests: list[Request]) -> list[dict]:
    """The requests as rows of :data:`FIELDS` (what :func:`load_demand` reads back)."""
    return [asdict(r) for r in requests]

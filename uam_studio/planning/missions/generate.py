"""Random missions for training and deterministic held-out missions for evaluation.

:func:`random_mission` places 1-8 (up to 20) destinations around a vertiport at the origin,
``radius_km`` (default 8-60 km) from it, at least :data:`MIN_SEPARATION_KM` apart so
that every leg can be flown at least at 500 m (:func:`uam_studio.flight.min_leg_distance_km`
is 6.1 km there). Priorities are integers 1-3, the wind on legs to each node is
uniform in [-39, 39] kt (negative = tailwind), and the cell's health is uniform in
``q_range`` (C) x ``r0_range`` (ohm).

Why ``r0`` stops at 0.35 ohm by default (the paper uses 0.017-0.45): every leg
starts with a ~2.9 A take-off and climb (100 s to 500 m, up to 573 s to 3000 m).
A cell with ``r0`` above about 0.36 ohm falls below the 3.0 V cut-off before that
climb to 500 m ends, whatever ``q_max`` (measured with
:func:`uam_studio.battery.simulate`), so such a mission has no decision to make.
Pass ``r0_range=(0.017, 0.45)`` to train on the paper's full range anyway.

Missions are honest: nothing guarantees that a destination can be reached and
left again with the sampled cell and winds. :func:`held_out_missions` draws
8-45 km radii, so most destinations are reachable.
"""

from __future__ import annotations

import math

import numpy as np

from uam_studio.battery.parameters import DEFAULT_EOD_V, PAPER_Q_RANGE, PAPER_R0_RANGE
from uam_studio.errors import InputError
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.missions.mission import (
    MAX_DESTINATIONS,
    PAPER_DESTINATIONS,
    SCENARIOS,
    Battery,
    Destination,
    Mission,
    Vertiport,
)
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO, check_scenario, scenario_rules

DEFAULT_Q_RANGE = PAPER_Q_RANGE
DEFAULT_R0_RANGE = (PAPER_R0_RANGE[0], 0.35)  # ohm; the paper's is 0.017-0.45, see the module docstring
DEFAULT_RADIUS_KM = (8.0, 60.0)
HELD_OUT_RADIUS_KM = (8.0, 45.0)
MIN_SEPARATION_KM = 7.0  # > 6.11 km, the shortest leg at 500 m
_MAX_TRIES = 2000


def _n_range(n_dest) -> tuple[int, int]:
    lo, hi = (n_dest, n_dest) if np.isscalar(n_dest) else tuple(n_dest)
    lo, hi = int(lo), int(hi)
    if not 1 <= lo <= hi <= MAX_DESTINATIONS:
        raise InputError("n_dest", f"{n_dest!r} is out of range; allowed 1 <= lo <= hi <= {MAX_DESTINATIONS}")
    return lo, hi


def _pair(field: str, value, lo: float, hi: float) -> tuple[float, float]:
    a, b = (float(v) for v in value)
    if not (lo <= a <= b <= hi):
        raise InputError(field, f"{tuple(value)!r} is out of range; allowed lo <= hi within [{lo:g}, {hi:g}]")
    return a, b


def random_mission(
    rng: np.random.Generator,
    n_dest=(1, PAPER_DESTINATIONS),
    scenario: str = DEFAULT_SCENARIO,
    r0_range=DEFAULT_R0_RANGE,
    q_range=DEFAULT_Q_RANGE,
    radius_km=DEFAULT_RADIUS_KM,
    eod_v: float = DEFAULT_EOD_V,
    name: str = "random mission",
) -> Mission:
    """A random mission (see the module docstring).

    :param rng: numpy random generator (all randomness comes from it).
    :param n_dest: number of destinations, an int or an inclusive ``(lo, hi)`` range within
        [1, 20] (``MAX_DESTINATIONS``; default 1 to ``PAPER_DESTINATIONS = 8``, the paper's missions);
        ``single_flight`` missions always have exactly one destination.
    :param scenario: one of ``single_flight``, ``single_charge``, ``multi_charge``.
    :param r0_range: uniform range of the cell's ohmic resistance (ohm).
    :param q_range: uniform range of the cell's mobile charge q_max (C).
    :param radius_km: uniform range of each destination's distance from the vertiport (km).
    :param eod_v: end-of-discharge cut-off (V).
    """
    check_scenario(scenario)
    lo, hi = _n_range(n_dest)
    r_lo, r_hi = _pair("radius_km", radius_km, MIN_SEPARATION_KM, 190.0)
    q_lo, q_hi = _pair("q_range", q_range, 1.0, 20000.0)
    r0_lo, r0_hi = _pair("r0_range", r0_range, 0.0, 5.0)
    n = 1 if scenario_rules(scenario).one_leg else int(rng.integers(lo, hi + 1))
    pts: list[tuple[float, float]] = []
    for _ in range(_MAX_TRIES):
        if len(pts) == n:
            break
        radius = rng.uniform(r_lo, r_hi)
        angle = rng.uniform(0.0, 2.0 * math.pi)
        x, y = round(radius * math.cos(angle), 1), round(radius * math.sin(angle), 1)
        if math.hypot(x, y) < r_lo - 0.1:
            continue
        if all(math.hypot(x - px, y - py) >= MIN_SEPARATION_KM for px, py in pts):
            pts.append((x, y))
    w_lo, w_hi = WIND_RANGE_KTS
    dests = tuple(
        Destination(f"D{k + 1}", x, y, int(rng.integers(1, 4)), round(float(rng.uniform(w_lo, w_hi)), 1))
        for k, (x, y) in enumerate(pts)
    )
    vertiport = Vertiport(0.0, 0.0, round(float(rng.uniform(w_lo, w_hi)), 1))
    battery = Battery(round(float(rng.uniform(q_lo, q_hi)), 1), round(float(rng.uniform(r0_lo, r0_hi)), 5))
    return Mission(name, vertiport, dests, scenario, battery, eod_v)


def held_out_missions(
    n: int,
    seed: int,
    n_dest=(6, PAPER_DESTINATIONS),
    scenario: str = DEFAULT_SCENARIO,
    r0_range=DEFAULT_R0_RANGE,
    q_range=DEFAULT_Q_RANGE,
    radius_km=HELD_OUT_RADIUS_KM,
) -> list[Mission]:
    """``n`` random missions, the same for the same arguments (``numpy.random.default_rng(seed)``).

    Use a seed never used in training; named ``"held-out <seed>/<k>"``.
    """
    rng = np.random.default_rng(seed)
    return [
        random_mission(rng, n_dest, scenario, r0_range, q_range, radius_km, name=f"held-out {seed}/{k}")
        for k in range(int(n))
    ]


ANY_SQUARE_KM = 35.0  # half side (km) of the square around the vertiport that any_valid_mission draws in
_PLACEMENTS = ("anywhere", "anywhere", "near another", "near the vertiport")
_DWELLS_S = (0.0, 0.0, 60.0, 600.0)


def any_valid_mission(rng: np.random.Generator, max_dest: int = MAX_DESTINATIONS,
                      scenarios: tuple[str, ...] = SCENARIOS) -> Mission:
    """A mission anywhere in the documented ranges, not where training and tuning drew theirs:
    1-``max_dest`` destinations in a 70 km square around the vertiport, placed anywhere, within 2 km of
    another (near-duplicates) or within 3 km of the vertiport; winds uniform in [-39, 39] kt; priorities
    1-3; dwell 0, 60 or 600 s; q_max and R0 uniform over the paper's health box; any of ``scenarios``.
    For robustness checks (benchmarks/bench_properties.py; tests/test_properties.py draws the same way
    with hypothesis)."""
    scenario = str(rng.choice(scenarios))
    n = 1 if scenario_rules(scenario).one_leg else int(rng.integers(1, max_dest + 1))
    pts: list[tuple[float, float]] = []
    half = ANY_SQUARE_KM
    for _ in range(n):
        kind = str(rng.choice(_PLACEMENTS))
        if kind == "near another" and pts:
            x0, y0 = pts[int(rng.integers(len(pts)))]
            x, y = x0 + rng.uniform(-2, 2), y0 + rng.uniform(-2, 2)
        elif kind == "near the vertiport":
            x, y = rng.uniform(-3, 3), rng.uniform(-3, 3)
        else:
            x, y = rng.uniform(-half, half), rng.uniform(-half, half)
        pts.append((round(float(np.clip(x, -half, half)), 1), round(float(np.clip(y, -half, half)), 1)))
    w_lo, w_hi = WIND_RANGE_KTS
    dests = tuple(Destination(f"D{k + 1}", x, y, int(rng.integers(1, 4)), round(float(rng.uniform(w_lo, w_hi)), 1),
                              float(rng.choice(_DWELLS_S))) for k, (x, y) in enumerate(pts))
    battery = Battery(round(float(rng.uniform(*PAPER_Q_RANGE)), 1), round(float(rng.uniform(*PAPER_R0_RANGE)), 5))
    return Mission("any valid mission", Vertiport(0.0, 0.0, round(float(rng.uniform(w_lo, w_hi)), 1)), dests,
                   scenario, battery, DEFAULT_EOD_V)

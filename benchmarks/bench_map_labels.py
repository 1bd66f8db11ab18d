"""How often the Planner map's leg labels cover another label, a place's marker or its name.

On random maps (``random_mission``, seeds ``[777, n, k]``) of 1-20 destinations planned by the greedy
rule, at the map's default zoom (the text sizes of :mod:`uam_studio.app.planner.map_geometry`), it counts the maps
where any leg label overlaps another label or a place (marker or name), for the app's placement
(:func:`~uam_studio.app.planner.map_geometry.altitude_labels`) and, in the same run, for a naive reference: every
label at its leg's midpoint, on the leg's left.

    python benchmarks/bench_map_labels.py [--maps 40]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uam_studio.app.planner.map_geometry import altitude_labels, label_overlaps, route_legs
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.solvers.greedy import greedy_plan


def _naive(legs: dict[str, list], *_: object) -> dict[str, list]:
    placed = altitude_labels(legs)  # the texts, one per pair of places
    out: dict[str, list] = {"x": [], "y": [], "text": placed["text"]}
    seen: set[tuple[str, str]] = set()
    for a, b, x0, y0, x1, y1 in zip(legs["from"], legs["to"], legs["x0"], legs["y0"], legs["x1"], legs["y1"]):
        key = tuple(sorted((a, b)))
        if key in seen:
            continue
        seen.add(key)
        norm = float(np.hypot(x1 - x0, y1 - y0)) or 1.0
        out["x"].append((x0 + x1) / 2 - 4.0 * (y1 - y0) / norm)
        out["y"].append((y0 + y1) / 2 + 4.0 * (x1 - x0) / norm)
    return out


def _overlaps(mission, place) -> tuple[bool, bool]:
    """(a label covers another label, a label covers a place or its name) on ``mission``'s greedy plan."""
    p = greedy_plan(mission)
    plan = {"route": p.route, "altitudes_m": p.altitudes_m, "reached": p.reached, "safe": True}
    rows = [{"name": d.name, "x_km": d.x_km, "y_km": d.y_km} for d in mission.destinations]
    legs = route_legs(plan, rows, (mission.vertiport.x_km, mission.vertiport.y_km))
    names = ["vertiport"] + [f"{d.name} {'*' * d.priority}" for d in mission.destinations]
    nodes = [(mission.vertiport.x_km, mission.vertiport.y_km)] + [(d.x_km, d.y_km) for d in mission.destinations]
    found = label_overlaps(place(legs, nodes, names), nodes, names)
    return any(b != "a place or its name" for _, b in found), any(b == "a place or its name" for _, b in found)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=int, default=40, help="maps per size")
    args = ap.parse_args()
    t0 = time.perf_counter()
    print(f"maps of n destinations with an overlap ({args.maps} maps each; labels / places)")
    print(f"{'n':>3} | {'app: labels':>11} {'app: places':>11} | {'naive: labels':>13} {'naive: places':>13}")
    for n in (1, 2, 3, 4, 6, 8, 12, 20):
        counts = np.zeros(4, dtype=int)
        for k in range(args.maps):
            m = random_mission(np.random.default_rng([777, n, k]), (n, n), "multi_charge")
            counts += np.array([*_overlaps(m, altitude_labels), *_overlaps(m, _naive)], dtype=int)
        print(f"{n:>3} | {counts[0]:>11} {counts[1]:>11} | {counts[2]:>13} {counts[3]:>13}")
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()

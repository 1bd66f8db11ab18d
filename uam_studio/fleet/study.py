"""Many fleet lives at once on Dask: one task per (fleet size, seed, dispatcher), on a local cluster by
default or on a running Dask scheduler (``address``). Each task is seeded by its own key, so the
results are the same whatever the number of workers.

Public API: :func:`fleet_study` (the results, one row per task, in task order) and :func:`summarize`
(per dispatcher and fleet size: priority per day with its 5-95% range, refusals, breaches, retirements).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import product

import numpy as np

from uam_studio.engine import run_tasks
from uam_studio.errors import InputError, check_range, check_seed
from uam_studio.fleet.day import pack_law, simulate_life
from uam_studio.fleet.dispatch import DISPATCHERS
from uam_studio.planning.operations.world import DEFAULT_WORLD, check_world
from uam_studio.risk import DEFAULT_RISK, check_risk

__all__ = ["fleet_study", "summarize"]


def _life_row(size: int, seed: int, dispatcher: str, days: int, rate: float, chargers: int, spread: float | None,
              max_km: float, vertiports: int = 1, law: str = "nasa", renew: bool = True,
              world: str = DEFAULT_WORLD, risk: float = DEFAULT_RISK) -> dict:
    """One task: a fleet's life, reduced to what the summary needs (picklable, small)."""
    life = simulate_life(size, days, seed, dispatcher, rate, chargers, spread, max_km=max_km, vertiports=vertiports,
                         law=law, renew=renew, world=world, risk=risk)
    return {"aircraft": size, "seed": seed, "dispatcher": dispatcher,
            "priority": [d["priority"] for d in life["days"]], "refused": [d["refused"] for d in life["days"]],
            "breaches": [d["breaches"] for d in life["days"]], "served": [d["served"] for d in life["days"]],
            "bound": [d["bound"] for d in life["days"]], "retired_day": life["retired_day"]}


def fleet_study(aircraft: Sequence[int] = (6,), days: int = 90, seeds: Sequence[int] = (0, 1, 2, 3, 4),
                dispatchers: Sequence[str] = DISPATCHERS, rate_per_h: float = 4.0, chargers: int = 2,
                age_spread_efc: float | None = None, workers: int | None = None, address: str | None = None,
                progress: Callable[[int, int], None] | None = None, max_km: float = 45.0,
                vertiports: int = 1, law: str = "nasa", renew: bool = True, world: str = DEFAULT_WORLD,
                risk: float = DEFAULT_RISK) -> list[dict]:
    """Every (fleet size, seed, dispatcher) life as a Dask task (:func:`uam_studio.engine.run_tasks`): on
    the scheduler at ``address`` (``tcp://host:8786``) if given, else on a local cluster of ``workers``
    processes (default: one per core), one thread each. ``workers=0`` runs the tasks here, one after
    another (no Dask). ``law``, ``renew``, ``world``, ``risk`` and ``age_spread_efc`` (None: the law's default) as in
    :func:`~uam_studio.fleet.day.simulate_life`.

    :return: one row per task in task order (sizes, then seeds, then dispatchers): per day its
        priority, refusals, breaches, served requests and bound (hindsight; None for the others), and
        each pack's retirement day.
    """
    for d in dispatchers:
        if d not in DISPATCHERS:
            raise InputError("dispatcher", f"{d!r}: allowed {', '.join(DISPATCHERS)}")
    days = int(check_range("days", days, 1, 3650))
    tasks = [(int(check_range("aircraft", a, 1, 50)), check_seed("seed", s), d)
             for a, s, d in product(aircraft, seeds, dispatchers)]
    if not tasks:
        raise InputError("seeds", "no task: give at least one fleet size, seed and dispatcher")
    pack_law(law)  # before any task: one line naming the law
    check_world(world)
    check_risk(risk)
    spread = None if age_spread_efc is None else float(age_spread_efc)
    args = (days, float(rate_per_h), int(chargers), spread, float(max_km), int(vertiports), law, bool(renew), world,
            float(risk))
    return run_tasks(_life_row, [(*t, *args) for t in tasks], workers=workers, address=address,
                     progress=progress, name="fleet-life")


def summarize(rows: list[dict]) -> list[dict]:
    """Per (fleet size, dispatcher): served priority per day (mean, 5% and 95% over every day of every
    seed), refusals, breaches and packs retired (with the mean retirement day; a retired pack renewed
    overnight counts once per retirement) over all lives; for
    hindsight ``bound_per_day``, the mean of each day's upper bound on any dispatcher's stars from its
    fleet (None for the others)."""
    out = []
    keys = sorted({(r["aircraft"], r["dispatcher"]) for r in rows}, key=lambda k: (k[0], DISPATCHERS.index(k[1])))
    for size, d in keys:
        group = [r for r in rows if (r["aircraft"], r["dispatcher"]) == (size, d)]
        p = np.concatenate([np.asarray(r["priority"], dtype=float) for r in group])
        retired = [day for r in group for day in r["retired_day"] if day is not None]
        bounds = [b for r in group for b in r.get("bound", []) if b is not None]
        out.append({"aircraft": size, "dispatcher": d, "lives": len(group), "days": int(p.size),
                    "priority_per_day": float(p.mean()), "p5": float(np.percentile(p, 5)),
                    "p95": float(np.percentile(p, 95)), "refused": int(sum(sum(r["refused"]) for r in group)),
                    "breaches": int(sum(sum(r["breaches"]) for r in group)),
                    "served": int(sum(sum(r["served"]) for r in group)), "packs_retired": len(retired),
                    "mean_retirement_day": float(np.mean(retired)) if retired else None,
                    "bound_per_day": float(np.mean(bounds)) if bounds and len(bounds) == p.size else None})
    return out

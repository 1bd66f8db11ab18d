"""State of the Fleet tab: one fleet per dispatcher, the same demand each day, a day at a time.

:class:`FleetState` holds the settings (aircraft, demand rate, packs' age spread, seed), a
:class:`~uam_studio.fleet.day.Fleet` per dispatcher (the same packs at the start) and the days flown
so far. The packs are the paper's NASA cell, aging by the law fitted to the NASA lives.
:meth:`FleetState.next_day` flies the next day of Poisson demand for the three dispatchers
(:func:`~uam_studio.fleet.day.fly_day_of_life`, the call ``uam-studio fleet`` makes) in the flights' thread
pool, the newest request winning; a pack that retired is replaced overnight. The tables the view draws come from here:
the last day's flights per aircraft (:meth:`timeline`), each pack's belief against its truth (:meth:`packs`) and the
served priority per day (:meth:`per_day`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import param

from uam_studio.app.services import FLIGHT_POOL, LatestWorker, one_line
from uam_studio.errors import InputError
from uam_studio.fleet.day import DayResult, Fleet, day_of_life_seed, default_age_spread, fly_day_of_life
from uam_studio.fleet.demand import poisson_demand
from uam_studio.fleet.dispatch import DISPATCHERS
from uam_studio.risk import HEALTH_Z

LABELS = {"aware": "health-aware", "blind": "health-blind", "hindsight": "hindsight"}


def _fly_day(job: tuple[dict[str, Fleet], int, float, int, int]) -> tuple[int, dict[str, DayResult], str]:
    fleets, day, rate, seed, vertiports = job
    try:
        # the days of `uam-studio fleet`
        demand = poisson_demand(day_of_life_seed(seed, day), rate, vertiports=vertiports)
        results = {d: fly_day_of_life(f, demand, d, seed, day)[0] for d, f in fleets.items()}  # renewed overnight
        return day, results, ""
    except InputError as err:
        return day, {}, one_line(err)


def _day_failed(job: Any, exc: BaseException) -> tuple[int, dict[str, DayResult], str]:
    return job[1], {}, f"the day failed: {type(exc).__name__}: {one_line(exc)}"


class FleetState(param.Parameterized):
    """A fleet per dispatcher and the days flown (see the module docstring).

    Inputs: ``aircraft``, ``vertiports`` (the aircraft spread over them, each with its own requests and
    two chargers; at most one per aircraft), ``rate_per_h`` (requests per hour, all vertiports),
    ``age_spread_efc`` (equivalent full cycles), ``seed``. Outputs: ``days`` (one dict per day: the day and each
    dispatcher's :meth:`DayResult.to_dict`), ``last`` (the last day's :class:`DayResult` per dispatcher), ``running``,
    ``status``, ``error`` (one line).
    """

    aircraft = param.Integer(default=6, bounds=(1, 12))
    vertiports = param.Integer(default=1, bounds=(1, 4))
    rate_per_h = param.Number(default=4.0, bounds=(0.5, 20.0))
    age_spread_efc = param.Number(default=default_age_spread("nasa"), bounds=(0.0, 150.0))  # 80% near 90 cycles
    seed = param.Integer(default=0, bounds=(0, 10**9))
    days = param.List(default=[])
    last = param.Dict(default={})
    running = param.Boolean(default=False)
    status = param.String(default="")
    error = param.String(default="")

    def __init__(self, background: bool = False,
                 dispatch: Callable[[Callable[[], None]], None] | None = None, **params: Any) -> None:
        super().__init__(**params)
        self.background = background
        self.fleets: dict[str, Fleet] = {}
        self._worker: LatestWorker[Any, Any] = LatestWorker(_fly_day, self._flown, _day_failed, dispatch=dispatch,
                                                            pool=FLIGHT_POOL)
        self.reset()

    @param.depends("aircraft", "vertiports", "age_spread_efc", "seed", "rate_per_h", watch=True)
    def reset(self) -> None:
        """New fleets (the same packs for every dispatcher) and no day flown."""
        try:
            self.fleets = {d: Fleet.new(self.aircraft, self.seed, self.age_spread_efc, self.vertiports)
                           for d in DISPATCHERS}
        except InputError as err:  # more vertiports than aircraft
            self.fleets = {}
            self.param.update(days=[], last={}, error=one_line(err), status="")
            return
        where = f" at {self.vertiports} vertiports" if self.vertiports > 1 else ""
        self.param.update(days=[], last={}, error="",
                          status=f"{self.aircraft} aircraft{where} ready; "
                                 "run a day to see the dispatchers side by side")

    def next_day(self) -> None:
        """Fly the next day for the three dispatchers (in the pool when ``background``)."""
        if self.running or not self.fleets:
            return
        job = (self.fleets, len(self.days), float(self.rate_per_h), int(self.seed), int(self.vertiports))
        self.param.update(running=True, status=f"flying day {len(self.days) + 1}...")
        if self.background:
            self._worker.submit(job)
        else:
            self._worker.run(job)

    def _flown(self, res: tuple[int, dict[str, DayResult], str], latest: bool) -> None:
        day, results, err = res
        self.running = False
        if err:
            self.param.update(error=err, status="")
            return
        row = {"day": day + 1, **{d: r.to_dict() for d, r in results.items()}}
        self.param.update(days=[*self.days, row], last=results, error="",
                          status=f"day {day + 1}: " + " · ".join(
                              f"{LABELS[d]} {r.priority} stars, {r.refused} refused, {r.breaches} breach"
                              f"{'' if r.breaches == 1 else 'es'}"
                              + ("" if r.bound is None else f" (at most {r.bound} possible)")
                              for d, r in results.items()))

    def wait_idle(self, timeout: float = 120.0) -> bool:
        """Block until the newest day asked for is shown (tests)."""
        return self._worker.wait_idle(timeout)

    # ------------------------------------------------------------------ tables for the view
    def timeline(self, dispatcher: str = "aware") -> list[dict]:
        """The last day's flights of ``dispatcher``: aircraft, take-off and landing (h into the day),
        request, and whether it breached."""
        r = self.last.get(dispatcher)
        if r is None:
            return []
        return [{"aircraft": f"#{i + 1}", "start_h": t / 3600.0, "end_h": (t + dur) / 3600.0, "request": name,
                 "breached": margin < 0} for t, i, name, margin, dur in r.log]

    def packs(self, dispatcher: str = "aware") -> list[dict]:
        """Each pack after the days flown under ``dispatcher``: its true q_max (C) and its aircraft's
        belief with the cautious bound the dispatcher uses (HEALTH_Z std)."""
        f = self.fleets[dispatcher]
        health = [b.health for b in f.beliefs]
        return [{"aircraft": f"#{i + 1}", "true_q_max": t.q_max, "belief_q_max": h.q_max_c,
                 "low": h.q_max_c - HEALTH_Z * h.q_max_sd_c, "high": h.q_max_c + HEALTH_Z * h.q_max_sd_c,
                 "in_service": s} for i, (t, h, s) in enumerate(zip(f.truth, health, f.in_service))]

    def per_day(self) -> dict[str, tuple[list[int], list[int]]]:
        """Served priority per day for each dispatcher: (days, stars); under ``"bound"`` the most stars any
        dispatcher could have served from hindsight's fleet each day."""
        days = [row["day"] for row in self.days]
        out = {d: (days, [row[d]["priority"] for row in self.days]) for d in DISPATCHERS}
        out["bound"] = (days, [row["hindsight"]["bound"] for row in self.days])
        return out


__all__ = ["LABELS", "FleetState"]

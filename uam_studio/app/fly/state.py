"""State of the Fly tab: one flight of the Planner's mission in a hidden world, played back.

:class:`FlyState` holds the world's settings (seed, forecast error, sensor noise, scripted wind
events), the :class:`~uam_studio.planning.operations.FlightRecord` of the last flight (from
:func:`~uam_studio.planning.operations.fly_mission`, the call ``uam-studio fly`` makes) and the
playback clock. Injecting a wind change re-flies the mission with one more event starting at the
playback time: everything before it is the same flight (same seeds), so the playback goes on from
where it was. Flights run in the flights' own thread pool, the newest request winning
(:class:`~uam_studio.app.services.LatestWorker`). A flight is shown from its first leg on (for a wind change,
from the first leg that reaches the playback time) while the rest of it is flown; its references (the blind
pre-flight plan and hindsight, :func:`~uam_studio.planning.operations.with_references`), which only the landing
shows, are flown after it.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import param

from uam_studio.app.fly.many import ManyFlights
from uam_studio.app.services import FLIGHT_POOL, LatestWorker, one_line
from uam_studio.errors import InputError
from uam_studio.planning import VERTIPORT, Mission
from uam_studio.planning.operations import (
    WEATHER_RESERVE_KT,
    FlightRecord,
    WindEvent,
    flight_before,
    fly_mission,
    parse_event,
    position_at,
    with_references,
)
from uam_studio.planning.operations.operator import RESERVE_RANGE_KT
from uam_studio.planning.operations.pack_history import simulate_logbook
from uam_studio.planning.operations.world import (
    DEFAULT_FORECAST_SIGMA_KT,
    DEFAULT_SENSOR_NOISE_MV,
    MAX_NOISE_MV,
    MAX_SIGMA_KT,
)
from uam_studio.risk import DEFAULT_RISK, RISK_LEVELS, caution
from uam_studio.wording import charging_cycles_text

SPEEDS = (10, 30, 100, 300, 1000)  # playback speed-ups (simulated s per wall s)
PACKS = {"a new pack (no logbook)": 0, "its logbook: 3 flights": 3, "its logbook: 10 flights": 10}
RISKS = RISK_LEVELS  # the declared risks the tab offers (uam_studio.risk)
# the world the pack flies (planning.operations.world.WORLDS), by the label the tab shows
WORLD_LABELS = {"a pack unlike its model": "varied", "its model (teaching)": "model"}
ERROR_CHARS = 300  # an error line is cut here


@dataclass(frozen=True)
class _Flight:
    """One flight to compute: the mission, :func:`fly_mission`'s settings, and whether the playback
    keeps its time."""

    mission: Mission
    kwargs: dict[str, Any]
    keep_time: bool
    pack_flights: int = 0
    from_s: float = 0.0  # s: the playback time the flight so far must reach before it is shown


@functools.lru_cache(maxsize=8)
def _pack_logbook(mission: Mission, flights: int, seed: int, sensor_noise_mv: float, world: str):
    """The logbook of the mission's pack after ``flights`` earlier flights in ``world`` (the same for the same
    inputs; the pack is the flight's, numbered by its seed)."""
    return simulate_logbook(mission, flights, seed, sensor_noise_mv=sensor_noise_mv, world=world)


class _Superseded(Exception):
    """A flight stopped because a newer one was asked for."""


def _fly(flight: _Flight, progress: Callable[[FlightRecord], None] | None = None,
         ) -> tuple[_Flight, FlightRecord | None, str]:
    """``(flight, its record, '')``, or ``(flight, None, one line)`` for bad input; ``progress`` gets the flight
    so far after each leg (``fly_mission``'s)."""
    try:
        kwargs = flight.kwargs
        if flight.pack_flights:
            book = _pack_logbook(flight.mission, flight.pack_flights, kwargs["seed"], kwargs["sensor_noise_mv"],
                                 kwargs["world"])
            kwargs = {**kwargs, "logbook": book}
        return flight, fly_mission(flight.mission, references=False, progress=progress, **kwargs), ""
    except InputError as exc:
        return flight, None, one_line(exc, ERROR_CHARS)
    except _Superseded:
        return flight, None, "superseded"  # never shown: a newer flight was asked for


def _flight_failed(flight: _Flight, exc: BaseException) -> tuple[_Flight, FlightRecord | None, str]:
    """A flight that raised: never a traceback in the app (the server log has it)."""
    return flight, None, f"flight failed: {type(exc).__name__}: {one_line(exc, ERROR_CHARS)}"


_Shown = tuple[Mission, FlightRecord]  # a flight shown: its mission and its record, flown without references


def _fly_references(shown: _Shown) -> tuple[_Shown, FlightRecord | None, str]:
    """``(shown, its record with the references flown, '')``."""
    return shown, with_references(*shown), ""


def _references_failed(shown: _Shown, exc: BaseException) -> tuple[_Shown, FlightRecord | None, str]:
    return shown, None, f"references failed: {type(exc).__name__}: {one_line(exc, ERROR_CHARS)}"


class FlyState(param.Parameterized):
    """One flight and its playback (see the module docstring).

    Inputs: ``pack`` (a key of :data:`PACKS`: a new pack, or one whose logbook holds that many earlier flights of
    the mission, :func:`~uam_studio.planning.operations.pack_history.simulate_logbook`), ``world`` (a key of
    :data:`WORLD_LABELS`: a pack unlike its model, the default, or one that is its model), ``seed``,
    ``forecast_sigma_kt`` (kt), ``sensor_noise_mv`` (mV), ``risk`` (the flight's declared risk, one of
    :data:`RISKS`: choosing one sets the cautions that follow from it, the reserve included), ``reserve_kt`` (kt, the
    operator's weather reserve; moved by hand, the flight declares no risk), ``speed`` (playback speed-up),
    ``inject_kts`` (kt, the wind change :meth:`inject` adds). Outputs: ``record``, ``complete`` (the record holds
    the whole flight; False while the legs after the shown ones are flown), ``t_s``
    (the playback clock, s), ``mission_flown``, ``running`` (a flight is being computed, none of it shown yet),
    ``references`` (the record's references are flown: the record is replaced by one that holds them),
    ``playing``, ``status``, ``error`` (one line).
    """

    pack: param.Selector = param.Selector(default=next(iter(PACKS)), objects=list(PACKS))
    world: param.Selector = param.Selector(default=next(iter(WORLD_LABELS)), objects=list(WORLD_LABELS))
    seed = param.Integer(default=0, bounds=(0, 10**9))
    forecast_sigma_kt = param.Number(default=DEFAULT_FORECAST_SIGMA_KT, bounds=(0.0, MAX_SIGMA_KT))
    sensor_noise_mv = param.Number(default=DEFAULT_SENSOR_NOISE_MV, bounds=(0.0, MAX_NOISE_MV))
    risk: param.Selector = param.Selector(default=DEFAULT_RISK, objects=list(RISKS))
    reserve_kt = param.Number(default=WEATHER_RESERVE_KT, bounds=RESERVE_RANGE_KT)
    speed: param.Selector = param.Selector(default=100, objects=list(SPEEDS))
    inject_kts = param.Number(default=25.0, bounds=(-60.0, 60.0))
    events = param.List(default=[], item_type=WindEvent)
    record = param.ClassSelector(class_=FlightRecord, default=None, allow_None=True)
    mission_flown = param.ClassSelector(class_=Mission, default=None, allow_None=True)
    t_s = param.Number(default=0.0, bounds=(0.0, None))
    running = param.Boolean(default=False)
    complete = param.Boolean(default=True)
    references = param.Boolean(default=False)
    playing = param.Boolean(default=False)
    status = param.String(default="")
    error = param.String(default="")

    def __init__(self, mission: Callable[[], Mission], background: bool = False,
                 dispatch: Callable[[Callable[[], None]], None] | None = None, **params: Any) -> None:
        """:param mission: returns the mission to fly (the Planner's current one).
        :param background: fly in the flights' thread pool (:data:`~uam_studio.app.services.FLIGHT_POOL`; served app)
            instead of in place.
        :param dispatch: hands a flight computed in the pool back to the session's thread."""
        super().__init__(**params)
        self._mission = mission
        self.background = background
        self.dispatch = dispatch
        self._worker: LatestWorker[_Flight, tuple[_Flight, FlightRecord | None, str]] = LatestWorker(
            self._compute, self._flown, _flight_failed, dispatch=dispatch, pool=FLIGHT_POOL)
        self._asked: _Flight | None = None  # the newest flight asked for
        self._shown: _Flight | None = None  # the flight shown (a part of it, or all)
        self._refs: LatestWorker[_Shown, tuple[_Shown, FlightRecord | None, str]] = LatestWorker(
            _fly_references, self._references_flown, _references_failed, dispatch=dispatch, pool=FLIGHT_POOL)
        # the "many flights" view: the price of safety at the risks this tab offers, in the world it selects
        self.many = ManyFlights(background, dispatch, risks=list(RISKS), world=WORLD_LABELS[self.world])

    @param.depends("world", watch=True)
    def _many_world(self) -> None:
        self.many.world = WORLD_LABELS[self.world]

    # ------------------------------------------------------------------ flying
    def fly(self, keep_time: bool = False, before: FlightRecord | None = None) -> None:
        """Fly the Planner's mission with the current settings (the playback restarts unless ``keep_time``);
        ``before``, the part of the flight known already, is shown at once."""
        try:
            mission = self._mission()
        except InputError as err:
            self.error = one_line(err, ERROR_CHARS)
            return
        c = caution(self.risk)
        cautions = ({"risk": self.risk} if self.reserve_kt == c.reserve_kt else
                    {"health_z": c.health_z, "wind_z": c.wind_z, "reserve_kt": self.reserve_kt})
        flight = _Flight(mission, dict(seed=self.seed, forecast_sigma_kt=self.forecast_sigma_kt,
                                       sensor_noise_mv=self.sensor_noise_mv, events=list(self.events),
                                       world=WORLD_LABELS[self.world], **cautions), keep_time, PACKS[self.pack],
                         self.t_s if keep_time else 0.0)
        self._asked = flight
        self.running = True
        self.status = "flying..."
        if not keep_time:
            self.playing = False  # the shown flight waits, as it is, for the new one
        if before is not None:
            self._first_legs(flight, before)
        if self.background:
            self._worker.submit(flight)
        else:
            self._worker.run(flight)

    def _compute(self, flight: _Flight) -> tuple[_Flight, FlightRecord | None, str]:
        """Fly ``flight``, handing the flight so far to the session's thread once it reaches ``flight.from_s``."""
        handed = False

        def progress(so_far: FlightRecord) -> None:
            nonlocal handed
            if flight is not self._asked:  # a newer flight was asked for: stop here, at a landing
                raise _Superseded
            if not handed and so_far.time_s.size and so_far.time_s[-1] >= flight.from_s:
                handed = True
                show = functools.partial(self._first_legs, flight, so_far)
                self.dispatch(show) if self.dispatch is not None else show()

        return _fly(flight, progress)

    def _first_legs(self, flight: _Flight, so_far: FlightRecord) -> None:
        """Show the flight so far, unless a newer flight was asked for meanwhile."""
        if flight is not self._asked:
            return
        self.running = False
        self.error = ""
        self._show(flight, so_far, complete=False)

    def _show(self, flight: _Flight, rec: FlightRecord, complete: bool) -> None:
        """Show ``rec``, a part of ``flight`` or all of it; the playback starts again at a flight's first showing
        unless the flight keeps the time."""
        update: dict[str, Any] = dict(record=rec, mission_flown=flight.mission, complete=complete, references=False)
        if flight is not self._shown and not flight.keep_time:
            update.update(t_s=0.0, playing=True)
        self._shown = flight
        self.param.update(**update)
        self._show_status()

    def _flown(self, res: tuple[_Flight, FlightRecord | None, str], latest: bool) -> None:
        """Show a computed flight, unless a newer one was asked for meanwhile."""
        if not latest:
            return
        flight, rec, err = res
        self.running = False
        if err:
            self.error, self.status = err, ""
            if not self.complete:  # the legs shown of a flight that failed after them
                self.param.update(record=None, complete=True, playing=False)
            return
        self.error = ""
        assert rec is not None  # a flight without an error has its record
        self._show(flight, rec, complete=True)
        if self.background:
            self._refs.submit((flight.mission, rec))
        else:
            self._refs.run((flight.mission, rec))

    def _references_flown(self, res: tuple[_Shown, FlightRecord | None, str], latest: bool) -> None:
        """Put the references into the shown record, unless another flight is shown meanwhile (it asked for its
        own references when it was shown: these are then not the latest)."""
        _shown, rec, err = res
        if not latest:
            return
        if err:
            self.error = err
            return
        self.param.update(record=rec, references=True)
        self._show_status()

    @param.depends("risk", watch=True)
    def _risk_cautions(self) -> None:
        self.reserve_kt = caution(self.risk).reserve_kt

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the newest flight asked for is shown, at most ``timeout`` s (tests; not from the
        session's own thread when a dispatcher schedules on it)."""
        deadline = time.monotonic() + timeout
        return self._worker.wait_idle(timeout) and self._refs.wait_idle(max(deadline - time.monotonic(), 0.0))

    def inject(self) -> None:
        """Add a wind change of ``inject_kts`` from the playback time on (its whole second) and re-fly from there;
        meanwhile the flight shown until the landing of the leg in the air, with the change marked
        (:func:`~uam_studio.planning.operations.flight_before`: the re-flown flight is the same until then)."""
        if self.record is None:
            self.error = "fly first: the wind change starts at the playback time"
            return
        event = WindEvent(int(self.t_s), float(self.inject_kts))
        # the shown flight (or its part, which holds the leg in the air too), unless a newer one is being flown
        before = flight_before(self.record, event) if self._shown is self._asked else None
        self.events = [*self.events, event]
        self.fly(keep_time=True, before=before)

    def clear_events(self) -> None:
        """Remove the injected wind changes and fly again."""
        self.events = []
        self.fly()

    # ------------------------------------------------------------------ playback
    @property
    def end_s(self) -> float:
        """The last reading's time (s), 0 without a flight."""
        return float(self.record.time_s[-1]) if self.record is not None and self.record.time_s.size else 0.0

    def tick(self, wall_s: float) -> None:
        """Advance the playback by ``wall_s`` seconds of wall time at the current speed."""
        if not self.playing or self.record is None:
            return
        t = min(self.end_s, self.t_s + wall_s * float(self.speed))
        self.t_s = t
        if t >= self.end_s and self.complete:
            self.playing = False

    def position(self) -> tuple[float, float, int]:
        """The aircraft's (x_km, y_km, leg index) at the playback time."""
        if self.record is None or self.mission_flown is None:
            return 0.0, 0.0, -1
        return position_at(self.record, self.mission_flown, self.t_s)

    def decisions_until(self) -> list[dict[str, Any]]:
        """The decisions made up to the playback time, newest first, as table rows, each with where its health
        belief came from (``belief from``: the pack's logbook and its flights, or the take-off's readings; then
        this flight's readings)."""
        r = self.record
        if r is None:
            return []
        tb = r.takeoff_belief
        first = f"logbook ({tb.get('flights', 0)} flights)" if tb.get("source") == "logbook" else "take-off only"
        rows = []
        for k, d in enumerate(r.events):
            row = d.row()
            rows.append({"t (s)": row.pop("t (s)"), "at": row.pop("at"),
                         "belief from": first if k == 0 else "+ in flight", **row})
        return [row for row, d in zip(reversed(rows), reversed(r.events)) if d.time_s <= self.t_s]

    @param.depends("t_s", watch=True)
    def _show_status(self) -> None:
        if self.record is not None and not self.running:
            self.status = self.summary()

    @property
    def landed(self) -> bool:
        """The playback has reached the flight's end: its result may be shown."""
        return self.record is not None and self.complete and self.t_s >= self.end_s

    def series_until(self) -> dict[str, Any]:
        """The record's series up to the playback time (time in min): ``measured``, ``true`` and
        ``predicted`` voltages (V), the ``decisions`` made so far (time min, the measured voltage then V,
        reason) and the wind
        ``changes`` that have started (time min, text)."""
        r = self.record
        if r is None:
            return {"measured": ([], []), "true": ([], []), "predicted": ([], []), "decisions": [], "changes": []}
        k = int(np.searchsorted(r.time_s, self.t_s, side="right"))
        t = r.time_s[:k] / 60.0
        return {"measured": (t, r.measured_voltage_v[:k]), "true": (t, r.true_voltage_v[:k]),
                "predicted": (t, r.predicted_voltage_v[:k]),
                "decisions": [(d.time_s / 60.0, float(np.interp(d.time_s, r.time_s, r.measured_voltage_v)), d.reason)
                              for d in r.events if d.time_s <= self.t_s],
                "changes": [(e.start_s / 60.0, f"wind {e.delta_kts:+g} kt from the next take-off")
                            for e in map(parse_event, r.wind_events) if e.start_s <= self.t_s]}

    def summary(self) -> str:
        """One line on the flight as far as the playback has gone: the time and the destinations reached
        so far while it plays; the result and its references (the blind plan, hindsight) once it has
        landed. Nothing from the future of the playback."""
        r = self.record
        if r is None:
            return ""
        if not self.landed:
            reached = [to for to, end in zip(r.route, r.leg_end_s) if end <= self.t_s and to != VERTIPORT]
            of = f" of {self.end_s / 60:.1f}" if self.complete else ""
            return (f"flying: {self.t_s / 60:.1f}{of} min · reached so far: "
                    f"{', '.join(reached) or 'none'} · the results show at the landing")
        own = f"BREACHED the cut-off (priority 0; {r.breach_cause})" if r.breached else f"priority {r.reached_priority}"
        flown = f"flown: {own}, {charging_cycles_text(r.charging_cycles)}, min {r.min_voltage_v:.3f} V · "
        if not self.references:
            return flown + "the blind pre-flight plan and hindsight are being flown" + _first_leg_text(r)
        blind = "breached" if r.static.breached else f"priority {r.static.priority}"
        return (flown + f"blind pre-flight plan: {blind} · "
                f"hindsight oracle{'' if r.hindsight.exact else ' (best known plan)'}: priority {r.hindsight.priority}"
                + _first_leg_text(r))


def _first_leg_text(r: FlightRecord) -> str:
    """The take-off belief's interval of the first leg's lowest voltage, its model-error term and what the world
    gave ("" when no leg was flown)."""
    tb = r.takeoff_belief
    if "first_leg_min_voltage_90_v" not in tb or r.first_leg_min_voltage_v is None:
        return ""
    lo, hi = tb["first_leg_min_voltage_90_v"]
    above, below = 1e3 * tb["model_error_v"], 1e3 * tb.get("model_error_low_v", tb["model_error_v"])
    error = f"{above:.0f} mV" if round(below) == round(above) else f"{above:.0f} mV above, {below:.0f} mV below"
    return (f" · first leg's lowest voltage: believed {lo:.3f}-{hi:.3f} V (90%; model error {error}, "
            f"{tb['model_error_share']:.0%} of its variance), the world gave {r.first_leg_min_voltage_v:.3f} V")


__all__ = ["RISKS", "SPEEDS", "WORLD_LABELS", "FlyState"]

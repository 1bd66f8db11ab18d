"""State models of the app: plain ``param.Parameterized`` classes, no widgets, no plots.

- :class:`PlannerState`: the mission being edited (destinations, winds, cell, EOD, scenario), the
  chosen policy and the latest plan. Every edit is validated by the library's mission model first;
  a rejected edit sets :attr:`PlannerState.error` (one line naming the field and the allowed range)
  and leaves the mission as it was. Accepted edits replan, either at once (:meth:`replan`; tests,
  notebooks) or in a shared thread pool with only the latest request kept (``background=True``;
  the served app), so a slow planner never blocks the session.
- :class:`BatteryLabState`: one leg and one cell, and a family of curves varying one factor.
- :class:`RetrainState`: a DQN retraining in a background thread with a stop flag; episode stats
  go through a queue that the view drains on its own (periodic) callback.
- :class:`AgentRegistry`: the retrained agents in the user folder, shared by all sessions.

Planning, physics and training all come from the library (:func:`~uam_studio.planning.planner.plan_mission`,
:mod:`uam_studio.planning.agents.retrain`, :func:`uam_studio.flight.leg_profile`,
:func:`uam_studio.battery.simulate`); this module only holds state and calls them.
"""

from __future__ import annotations

import collections
import copy
import functools
import json
import math
import os
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import param

from uam_studio.errors import InputError, check_range
from uam_studio.flight.tables import ALTITUDE_RANGE_M, WIND_RANGE_KTS
from uam_studio.planning.legs import N_MAX, check_destination_count
from uam_studio.planning.missions.mission import (
    COORD_RANGE_KM,
    SCENARIOS,
    Battery,
    Destination,
    Mission,
    Vertiport,
    mission_from_dict,
    mission_from_json,
    mission_to_dict,
)

__all__ = [
    "APP_EOD_RANGE",
    "APP_Q_RANGE",
    "APP_R0_RANGE",
    "EXAMPLE_MISSION",
    "AgentRegistry",
    "BatteryLabState",
    "PlanRequest",
    "PlannerState",
    "RetrainState",
    "compute_plan",
    "population",
    "registry",
]

APP_Q_RANGE = (5000.0, 8000.0)  # C, the paper's range of q_max
APP_R0_RANGE = (0.017, 0.45)  # ohm, the paper's range of R0
APP_EOD_RANGE = (2.5, 3.5)  # V; the Dynaformer is trained down to 2.5 V
RUNNER_ENV = "UAM_STUDIO_RETRAIN_RUNNER"  # "process" (default) or "thread", for comparisons
POPULATION_N = 300
PLAN_CACHE_SIZE = 256  # plans kept for all sessions (compute_plan)

EXAMPLE_MISSION: dict[str, Any] = {
    "name": "Bay shuttle",
    "vertiport": {"x_km": 0.0, "y_km": 0.0, "wind_kts": 8.0},
    "destinations": [
        {"name": "Richmond", "x_km": 14.0, "y_km": 16.0, "priority": 2, "wind_kts": 13.0, "dwell_s": 300.0},
        {"name": "Hayward", "x_km": 27.0, "y_km": -18.0, "priority": 1, "wind_kts": -10.0, "dwell_s": 600.0},
        {"name": "Fremont", "x_km": 38.0, "y_km": -32.0, "priority": 3, "wind_kts": -5.0},
        {"name": "Napa", "x_km": 18.0, "y_km": 55.0, "priority": 2, "wind_kts": 20.0, "dwell_s": 300.0},
    ],
    "scenario": "single_charge",
    "battery": {"q_max": 7600.0, "r0": 0.117215},
    "eod_v": 3.0,
}
"""The bundled example (``assets/example_mission.json``), the app's starting mission."""

POLICY_LABELS = {"DQN (bundled)": "dqn", "Oracle (exact, slow)": "oracle", "Greedy": "greedy"}
AGENT_PREFIX = "agent:"

# Planning runs here in the served app: a few workers shared by all sessions, one request per session.
_POOL = ThreadPoolExecutor(max_workers=4, thread_name_prefix="uam-plan")


class PlanningActivity:
    """Which sessions are planning right now, as a ``multiprocessing`` Event that retraining child
    processes watch: while any session plans (from the request to the views updated, plus
    :attr:`grace_s` for the server to send the changes and the browser to draw them), they pause
    between episodes (:class:`~uam_studio.planning.agents.retrain.RetrainProcess`)."""

    def __init__(self, grace_s: float = 1.0) -> None:
        self.grace_s = grace_s
        self._lock = threading.Lock()
        self._active: set[int] = set()
        self._event: Any = None
        self._timer: threading.Timer | None = None

    @property
    def event(self) -> Any:
        with self._lock:
            if self._event is None:
                import multiprocessing

                self._event = multiprocessing.get_context("spawn").Event()
                if self._active:
                    self._event.set()
            return self._event

    def mark(self, key: int, active: bool) -> None:
        with self._lock:
            (self._active.add if active else self._active.discard)(key)
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            if self._event is None:
                return
            if self._active:
                self._event.set()
            elif self.grace_s > 0 and self._event.is_set():
                self._timer = threading.Timer(self.grace_s, self._clear_if_idle)
                self._timer.daemon = True
                self._timer.start()
            else:
                self._event.clear()

    def _clear_if_idle(self) -> None:
        with self._lock:
            if not self._active and self._event is not None:
                self._event.clear()
            self._timer = None


ACTIVITY = PlanningActivity()


# ----------------------------------------------------------------------------- shared, cached


@functools.lru_cache(maxsize=1)
def _predictor_or_error() -> tuple[Any, str | None]:
    try:
        from uam_studio.dynaformer import WeightsError, load_pretrained
    except ImportError as err:  # pragma: no cover - torch is a dependency
        return None, f"Dynaformer unavailable ({err})"
    try:
        return load_pretrained(), None
    except WeightsError as err:
        return None, f"no Dynaformer weights ({err})"


def predictor() -> Any:
    """The bundled Dynaformer (loaded once per process), or None if it cannot be loaded."""
    return _predictor_or_error()[0]


@functools.lru_cache(maxsize=1)
def population() -> Any:
    """Health PCs of :data:`POPULATION_N` cells over the training ranges (computed once per process),
    a :class:`~uam_studio.dynaformer.population.HealthPopulation`, or None without a Dynaformer."""
    from uam_studio.dynaformer.population import health_population
    from uam_studio.planning.env import takeoff_context_current

    p = predictor()
    if p is None:
        return None
    return health_population(p, takeoff_context_current(), n=POPULATION_N, seed=0)


@functools.lru_cache(maxsize=512)
def health_estimate(q_max: float, r0: float) -> tuple[float, float] | None:
    """The Dynaformer's (PC1, PC2) for a cell, from the first 20 s of its take-off (physics model)."""
    from uam_studio.planning.env import CONTEXT_S, observe_takeoff

    p = predictor()
    if p is None:
        return None
    ci, cv = observe_takeoff(q_max, r0)
    pc = np.asarray(p.health(ci[:CONTEXT_S], cv[:CONTEXT_S]), dtype=float).reshape(-1)
    return float(pc[0]), float(pc[1])


def warm_up() -> None:
    """Load the Dynaformer and the health population, and plan the example mission with the default
    policy, now (server start), so the first session shows its first plan at once."""
    population()
    mission = mission_from_dict(EXAMPLE_MISSION)
    policy = "dqn" if _bundled_exists(mission.scenario) else "greedy"
    compute_plan(PlanRequest(mission, policy))


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


# ----------------------------------------------------------------------------- agents


class AgentRegistry(param.Parameterized):
    """Retrained agents in the user folder (:func:`uam_studio.planning.agents.retrain.agents_dir`), newest first.

    One instance per process (:func:`registry`); sessions watch :attr:`agents`.
    """

    agents = param.List(default=[], doc="AgentInfo of each agent found")

    def refresh(self) -> None:
        from uam_studio.planning.agents.retrain import list_agents

        found = list_agents()
        if [(a.path, a.card.get("timing")) for a in found] != [(a.path, a.card.get("timing")) for a in self.agents]:
            self.agents = found


@functools.lru_cache(maxsize=1)
def registry() -> AgentRegistry:
    """The process-wide :class:`AgentRegistry` (scanned on first use, after deleting the temp files
    that killed saves left in the agents folder)."""
    from uam_studio.atomic_io import remove_stale_temps
    from uam_studio.planning.agents.retrain import agents_dir

    remove_stale_temps(agents_dir())
    reg = AgentRegistry()
    reg.refresh()
    return reg


def policy_options(agents: list[Any]) -> dict[str, str]:
    """Select options (label -> value): the three planners and one ``agent:<path>`` per retrained agent."""
    opts = dict(POLICY_LABELS)
    for a in agents:
        opts[f"Retrained: {a.label}"] = f"{AGENT_PREFIX}{a.path}"
    return opts


# ----------------------------------------------------------------------------- planning


@dataclass(frozen=True)
class PlanRequest:
    """Everything a plan depends on (a snapshot, safe to hand to another thread)."""

    mission: Mission
    policy: str  # dqn | oracle | greedy | agent:<path>


def _agent_stamp(req: PlanRequest) -> tuple[str, int, int] | None:
    """(path, mtime ns, size) of the agent file a DQN plan uses (retrained, or the bundled one for the
    mission's scenario), so a plan cached for another or an older file is never reused."""
    from uam_studio.planning.agents.rollout import bundled_agent_path

    if req.policy.startswith(AGENT_PREFIX):
        path = Path(req.policy[len(AGENT_PREFIX):])
    elif req.policy == "dqn":
        path = bundled_agent_path(req.mission.scenario)
    else:
        return None
    try:
        st = path.stat()
    except OSError:
        return str(path), -1, -1
    return str(path), st.st_mtime_ns, st.st_size


_PLAN_CACHE: collections.OrderedDict[tuple, dict[str, Any]] = collections.OrderedDict()
_PLAN_CACHE_LOCK = threading.Lock()


def compute_plan(req: PlanRequest) -> dict[str, Any]:
    """Plan ``req`` with the library and estimate the cell's health. Never raises.

    Plans are deterministic in the request (mission, battery, cut-off, policy; a retrained agent's
    file stamp), so the last :data:`PLAN_CACHE_SIZE` results are shared by all sessions: a new
    session, an undo or a slider dragged back re-shows a plan at once. Unexpected failures
    ("planning failed: ...") are not cached.

    :return: ``{"plan": plan_mission's dict or None, "error": one line or None, "health": (pc1, pc2)
        or None, "elapsed_s": float, "request": req, "cached": bool}``.
    """
    t0 = time.perf_counter()
    key = (req, _agent_stamp(req))
    with _PLAN_CACHE_LOCK:
        hit = _PLAN_CACHE.get(key)
        if hit is not None:
            _PLAN_CACHE.move_to_end(key)
    cached = hit is not None
    if not cached:
        res = _compute_plan(req)
        if not (res["error"] or "").startswith("planning failed"):
            with _PLAN_CACHE_LOCK:
                _PLAN_CACHE[key] = res
                while len(_PLAN_CACHE) > PLAN_CACHE_SIZE:
                    _PLAN_CACHE.popitem(last=False)
        hit = res
    out = copy.deepcopy(hit)
    out["cached"] = cached
    if cached:
        out["elapsed_s"] = time.perf_counter() - t0
    return out


def _compute_plan(req: PlanRequest) -> dict[str, Any]:
    from uam_studio.planning.planner import plan_mission

    t0 = time.perf_counter()
    out: dict[str, Any] = {"plan": None, "error": None, "health": None, "request": req}
    pred = predictor()
    policy, agent_path = req.policy, None
    if policy.startswith(AGENT_PREFIX):
        policy, agent_path = "dqn", policy[len(AGENT_PREFIX):]
    try:
        out["plan"] = plan_mission(req.mission, policy, agent_path=agent_path,
                                   predictor=pred if pred is not None else False)
        if pred is None:
            out["plan"]["messages"].append(_predictor_or_error()[1] or "no Dynaformer")
    except InputError as err:
        out["error"] = _one_line(err)
    except Exception as err:  # never a traceback in the app; the server log keeps it
        traceback.print_exc()
        out["error"] = f"planning failed: {type(err).__name__}: {_one_line(err)}"
    try:
        b = req.mission.battery
        out["health"] = health_estimate(float(b.q_max), float(b.r0))
    except Exception:  # the health view is optional
        traceback.print_exc()
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def _clean_float(value: Any, default: float) -> Any:
    """NaN/None/'' -> default; numbers as float; anything else unchanged (the library names it)."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return default
    if isinstance(value, (bool, np.bool_)):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        f = float(value)
        return default if math.isnan(f) else f
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


class PlannerState(param.Parameterized):
    """The mission being edited, the policy, and the latest plan.

    Inputs (validated; change them with :meth:`apply`, :meth:`set_destinations`, :meth:`load_json`
    so that a bad value becomes :attr:`error` instead of an exception): ``mission_name``,
    ``destinations``, ``vertiport_x_km``, ``vertiport_y_km``, ``return_wind``, ``scenario``,
    ``q_max``, ``r0``, ``eod_v``, ``policy``.

    Outputs: ``plan`` (:func:`~uam_studio.planning.planner.plan_mission`'s dict), ``plan_request``
    (what it was computed for), ``health`` (PC1, PC2), ``plan_error`` (a planner error, e.g. an
    unreadable agent), ``busy`` (a plan is being computed), ``plan_count``.
    """

    mission_name = param.String(default="Bay shuttle")
    destinations = param.List(default=[], item_type=Destination)
    vertiport_x_km = param.Number(default=0.0, bounds=COORD_RANGE_KM)
    vertiport_y_km = param.Number(default=0.0, bounds=COORD_RANGE_KM)
    return_wind = param.Number(default=0.0, bounds=WIND_RANGE_KTS, doc="wind (kt) on legs back to the vertiport")
    scenario = param.Selector(default="single_charge", objects=list(SCENARIOS))
    q_max = param.Number(default=7600.0, bounds=APP_Q_RANGE, doc="mobile lithium charge q_max (C)")
    r0 = param.Number(default=0.117215, bounds=APP_R0_RANGE, doc="ohmic resistance R0 (ohm)")
    eod_v = param.Number(default=3.0, bounds=APP_EOD_RANGE, doc="end-of-discharge cut-off (V)")
    policy = param.Selector(default="greedy", objects=list(POLICY_LABELS.values()), check_on_set=False)
    policy_objects = param.Dict(default=dict(POLICY_LABELS), doc="policy select options: label -> value")

    plan = param.Dict(default=None, allow_None=True, doc="plan_mission's result for plan_request")
    plan_request = param.ClassSelector(class_=PlanRequest, default=None, allow_None=True)
    plan_error = param.String(default="")
    health = param.Tuple(default=None, allow_None=True, length=2)
    busy = param.Boolean(default=False)
    plan_count = param.Integer(default=0, doc="plans applied so far")
    error = param.String(default="", doc="why the last edit was rejected (one line), '' if it was accepted")
    notice = param.String(default="", doc="a short note about the last accepted action")

    INPUTS = ("mission_name", "destinations", "vertiport_x_km", "vertiport_y_km", "return_wind", "scenario",
              "q_max", "r0", "eod_v", "policy")

    def __init__(self, mission: Mission | dict | None = None, background: bool = False,
                 dispatch: Callable[[Callable[[], None]], None] | None = None, auto: bool = True,
                 **params: Any) -> None:
        """
        :param mission: the starting mission (default :data:`EXAMPLE_MISSION`).
        :param background: replan in the shared thread pool (served app) instead of in place.
        :param dispatch: how a finished background plan is handed back to the session's thread
            (default: applied in the worker thread; the served app passes a next-tick dispatcher).
        :param auto: replan on every accepted change (False: call :meth:`replan` yourself).
        """
        super().__init__(**params)
        self.background = background
        self.dispatch = dispatch or (lambda cb: cb())
        self.auto = auto
        self._lock = threading.Lock()
        self._seq = 0
        self._latest: tuple[int, PlanRequest] | None = None
        self._running = False
        self._applied_seq = 0
        self._done = threading.Condition(self._lock)
        m = mission if mission is not None else EXAMPLE_MISSION
        m = m if isinstance(m, Mission) else mission_from_dict(m)
        self._set_mission(m)
        reg = registry()
        self._update_policy_options(reg.agents)
        self._agents_watcher = reg.param.watch(self._on_agents, "agents")
        if "policy" not in params and _bundled_exists(self.scenario):
            self.policy = "dqn"  # the bundled agent is the default planner where there is one
        self.param.watch(self._on_inputs, list(self.INPUTS))
        if self.auto:
            self.request_plan()

    # ------------------------------------------------------------------ mission <-> state

    @property
    def mission(self) -> Mission:
        """The current (always valid) mission."""
        return self._build()

    def _build(self, **changes: Any) -> Mission:
        v = {k: changes.get(k, getattr(self, k)) for k in self.INPUTS}
        return Mission(
            v["mission_name"],
            Vertiport(v["vertiport_x_km"], v["vertiport_y_km"], v["return_wind"]),
            tuple(v["destinations"]),
            v["scenario"],
            Battery(v["q_max"], v["r0"]),
            v["eod_v"],
        )

    def _set_mission(self, m: Mission) -> None:
        self.param.update(**self._mission_params(m))

    @staticmethod
    def _mission_params(m: Mission) -> dict[str, Any]:
        return {
            "mission_name": m.name,
            "destinations": list(m.destinations),
            "vertiport_x_km": m.vertiport.x_km,
            "vertiport_y_km": m.vertiport.y_km,
            "return_wind": m.vertiport.wind_kts,
            "scenario": m.scenario,
            "q_max": m.battery.q_max,
            "r0": m.battery.r0,
            "eod_v": m.eod_v,
        }

    def _validate(self, changes: dict[str, Any]) -> dict[str, Any]:
        """The changes, checked; raises InputError naming the field and its allowed range."""
        unknown = set(changes) - set(self.INPUTS)
        if unknown:
            raise InputError(sorted(unknown)[0], f"not an input; inputs are {', '.join(self.INPUTS)}")
        out = dict(changes)
        for key, (lo, hi), unit in (("q_max", APP_Q_RANGE, " C"), ("r0", APP_R0_RANGE, " ohm"),
                                    ("eod_v", APP_EOD_RANGE, " V"), ("return_wind", WIND_RANGE_KTS, " kt")):
            if key in out:
                out[key] = check_range(key, out[key], lo, hi, unit)
        if "policy" in out and out["policy"] not in self.param["policy"].objects:
            raise InputError("policy", f"{out['policy']!r} is not a policy; allowed: "
                                       f"{', '.join(map(str, self.param['policy'].objects))}")
        if "destinations" in out:
            n = len(out["destinations"])
            if n == 0:
                raise InputError("destinations", "a mission needs at least 1 destination (allowed 1 to "
                                                 f"{N_MAX}); add another before removing the last one")
            if n > N_MAX:
                check_destination_count(n)
        self._build(**out)  # the library validates the rest (names, priorities, coordinates...)
        return out

    def apply(self, **changes: Any) -> bool:
        """Validate and apply ``changes`` to the inputs together. On a bad value set :attr:`error` and
        keep everything as it was. Returns True if applied."""
        try:
            ok = self._validate(changes)
        except InputError as err:
            self.error = _one_line(err)
            return False
        self.error = ""
        self.param.update(**ok)
        return True

    def set_destinations(self, rows: list[dict[str, Any]]) -> bool:

        """Replace the destinations from table or map rows (``name``, ``x_km``, ``y_km``, ``priority``,
        ``wind_kts``, ``dwell_s``). Rows fresh from the map may lack values: a missing name becomes
        the first free ``D<k>``, a missing or 0 priority 1 (PointDraw's empty value), wind and dwell 0.
        Coordinates are rounded to 0.1 km. Returns True if accepted (see :meth:`apply`)."""
        try:
            dests = self._rows_to_destinations(rows)
        except InputError as err:
            self.error = _one_line(err)
            return False
        if dests == list(self.destinations):
            self.error = ""
            return True
        return self.apply(destinations=dests)

    def _rows_to_destinations(self, rows: list[dict[str, Any]]) -> list[Destination]:
        used = {str(r.get("name")).strip() for r in rows if isinstance(r.get("name"), str)}
        k, dests = 1, []
        for i, r in enumerate(rows):
            name = r.get("name")
            if not isinstance(name, str) or not name.strip():
                while f"D{k}" in used:
                    k += 1
                name = f"D{k}"
                used.add(name)
            prio = _clean_float(r.get("priority"), 1.0)
            if isinstance(prio, float) and prio == 0.0:
                prio = 1.0
            x = _clean_float(r.get("x_km"), float("nan"))
            y = _clean_float(r.get("y_km"), float("nan"))
            if isinstance(x, float) and math.isfinite(x):
                x = round(x, 1)
            if isinstance(y, float) and math.isfinite(y):
                y = round(y, 1)
            try:
                dests.append(Destination(name.strip(), x, y, prio, _clean_float(r.get("wind_kts"), 0.0),
                                         _clean_float(r.get("dwell_s"), 0.0)))
            except InputError as err:
                label = f"destinations[{i}] ({name.strip()})"
                raise InputError(f"{label}.{err.field}", str(err)[len(err.field) + 2:]) from None
        return dests

    def destination_rows(self) -> list[dict[str, Any]]:
        """The destinations as rows (the table's and the map's data)."""
        return [{"name": d.name, "x_km": d.x_km, "y_km": d.y_km, "priority": d.priority,
                 "wind_kts": d.wind_kts, "dwell_s": d.dwell_s} for d in self.destinations]

    # ------------------------------------------------------------------ files

    def to_json(self) -> str:
        """The mission in the CLI's JSON format (as :func:`~uam_studio.planning.save_mission` writes it)."""
        return json.dumps(mission_to_dict(self.mission), indent=2, allow_nan=False) + "\n"

    def load_json(self, data: bytes | str | None, filename: str | None = None) -> bool:
        """Replace the mission with a mission file's content. A bad file sets :attr:`error` (naming
        the file and the first bad field) and keeps the current mission. Returns True if loaded."""
        what = f"file {filename}" if filename else "file"
        try:
            m = self._parse(data, what)
            self._validate({"destinations": list(m.destinations)})
            self._validate({k: v for k, v in self._mission_params(m).items()
                            if k in ("q_max", "r0", "eod_v")})
        except InputError as err:
            self.error = f"{what}: {_one_line(err)}" if not str(err).startswith(what) else _one_line(err)
            return False
        self.error = ""
        self.param.update(**self._mission_params(m))
        self.notice = f"loaded {filename or 'mission'} ({len(m.destinations)} destinations)"
        return True

    @staticmethod
    def _parse(data: bytes | str | None, what: str) -> Mission:
        return mission_from_json(data if data is not None else b"", what)

    def reset_example(self) -> None:
        """Back to the bundled example mission."""
        self.error = ""
        self._set_mission(mission_from_dict(EXAMPLE_MISSION))

    # ------------------------------------------------------------------ policies

    def _on_agents(self, event: param.parameterized.Event) -> None:
        self.dispatch(lambda: self._update_policy_options(event.new))

    def _update_policy_options(self, agents: list[Any]) -> None:
        opts = policy_options(agents)
        self.param["policy"].objects = list(opts.values())
        self.policy_objects = opts  # views refresh their options
        if self.policy not in self.param["policy"].objects:  # its agent file is gone
            self.policy = "greedy"

    def close(self) -> None:
        """Stop following the agent registry and count as idle (the session ended)."""
        ACTIVITY.mark(id(self), False)
        if self._agents_watcher is not None:
            registry().param.unwatch(self._agents_watcher)
            self._agents_watcher = None

    # ------------------------------------------------------------------ replanning

    def _on_inputs(self, *events: param.parameterized.Event) -> None:
        if self.auto:
            self.request_plan()

    def request(self) -> PlanRequest:
        return PlanRequest(self.mission, self.policy)

    def replan(self) -> dict[str, Any]:
        """Plan the current mission now, in this thread, and apply the result."""
        with self._lock:
            self._seq += 1
            seq = self._seq
        res = compute_plan(self.request())
        self._apply(seq, res)
        return res

    def request_plan(self) -> None:
        """Replan: in place, or (``background``) in the pool, where a request arriving while one is
        computed replaces any waiting one, so at most one plan per session runs and the last wins."""
        if not self.background:
            self.replan()
            return
        req = self.request()
        with self._lock:
            self._seq += 1
            self._latest = (self._seq, req)
            start = not self._running
            self._running = True
        ACTIVITY.mark(id(self), True)
        if not self.busy:
            self.busy = True
        if start:
            _POOL.submit(self._work)

    def _work(self) -> None:
        while True:
            with self._lock:
                assert self._latest is not None
                seq, req = self._latest
            try:
                res = compute_plan(req)
            except BaseException as err:  # compute_plan never raises; belt and braces
                res = {"plan": None, "error": f"planning failed: {_one_line(err)}", "health": None,
                       "request": req, "elapsed_s": 0.0}
            with self._lock:
                if self._latest is not None and self._latest[0] != seq:
                    continue  # a newer request came in meanwhile: plan that one instead
                self._running = False
            self.dispatch(functools.partial(self._apply, seq, res))
            return

    def _apply(self, seq: int, res: dict[str, Any]) -> None:

        with self._lock:
            if seq < self._applied_seq:
                return
            self._applied_seq = seq
            latest = seq >= self._seq
        changes: dict[str, Any] = {"plan_error": res["error"] or "", "plan_request": res["request"],
                                   "plan_count": self.plan_count + 1}
        if res["plan"] is not None or res["error"]:
            changes["plan"] = res["plan"]
        if res["health"] is not None:
            changes["health"] = tuple(res["health"])
        if latest:
            changes["busy"] = False
        self.last_elapsed_s = res.get("elapsed_s")
        try:
            self.param.update(**changes)
        finally:
            if latest:
                ACTIVITY.mark(id(self), False)  # the views are updated too: training may go on
        with self._done:
            self._done.notify_all()

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the latest requested plan is applied (tests and benchmarks; not from the
        session's own thread when a dispatcher schedules on it)."""
        deadline = time.monotonic() + timeout
        with self._done:
            while self._applied_seq < self._seq:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._done.wait(left)
        return True


def _bundled_exists(scenario: str) -> bool:
    from uam_studio.planning.agents.rollout import bundled_agent_path

    return bundled_agent_path(scenario).is_file()


# ----------------------------------------------------------------------------- battery lab

VARY = {
    "altitude": ("altitude_m", (500.0, 1000.0, 2000.0, 3000.0), "m"),
    "wind": ("wind_kts", (-39.0, -13.0, 0.0, 13.0, 39.0), "kt"),
    "R0": ("r0", (0.017, 0.1, 0.2, 0.3, 0.45), "ohm"),
    "q_max": ("q_max", (5000.0, 6000.0, 7000.0, 8000.0), "C"),
}


class BatteryLabState(param.Parameterized):
    """One leg flown by one cell, plus a family of curves that vary one factor (the paper's figures).

    :meth:`curves` returns, for the chosen setting and each family member, the per-cell current and
    the voltage (physics model) of the leg, flown ``legs`` times back to back without recharging.
    """

    q_max = param.Number(default=7600.0, bounds=APP_Q_RANGE, doc="q_max (C)")
    r0 = param.Number(default=0.117215, bounds=APP_R0_RANGE, doc="R0 (ohm)")
    altitude_m = param.Number(default=1000.0, bounds=ALTITUDE_RANGE_M)
    wind_kts = param.Number(default=0.0, bounds=WIND_RANGE_KTS)
    distance_km = param.Number(default=55.6, bounds=(10.0, 150.0), doc="leg length (km); 30 nm = 55.6 km")
    legs = param.Integer(default=3, bounds=(1, 10), doc="legs flown back to back (no recharge)")
    eod_v = param.Number(default=3.0, bounds=APP_EOD_RANGE)
    vary = param.Selector(default="altitude", objects=list(VARY))

    def _setting(self, **override: float) -> dict[str, float]:
        s = {k: float(getattr(self, k)) for k in ("q_max", "r0", "altitude_m", "wind_kts")}
        s.update(override)
        return s

    def curves(self) -> dict[str, Any]:
        """``{"setting": [curve], "family": [curve...], "factor", "unit", "error", "skipped"}``; each curve is
        ``{"label", "value", "time_s", "current_a", "voltage_v", "eod_s"}`` (voltage up to EOD)."""
        key, values, unit = VARY[self.vary]
        out: dict[str, Any] = {"factor": self.vary, "unit": unit, "setting": [], "family": [], "error": "",
                               "skipped": []}
        try:
            out["setting"] = [self._curve(self._setting(), "this setting")]
        except InputError as err:
            out["error"] = _one_line(err)
            return out
        for v in values:
            label = f"{self.vary} {v:g} {unit}"
            try:
                out["family"].append(self._curve(self._setting(**{key: v}), label))
            except InputError as err:  # e.g. a leg too short for 3000 m
                out["skipped"].append(f"{label}: {_one_line(err)}")
        return out

    def _curve(self, s: dict[str, float], label: str) -> dict[str, Any]:
        from uam_studio.battery import simulate
        from uam_studio.flight import leg_profile

        prof = leg_profile(float(self.distance_km), s["altitude_m"], s["wind_kts"])
        cur = np.tile(np.asarray(prof.current_a), int(self.legs))
        sim = simulate(cur, prof.dt_s, s["q_max"], s["r0"], eod_v=float(self.eod_v))
        n = int(np.count_nonzero(sim.valid))
        return {"label": label, "value": s, "time_s": np.asarray(sim.time_s), "current_a": cur,
                "voltage_v": np.asarray(sim.voltage_v)[:max(n, 1)], "eod_s": sim.eod_s}


# ----------------------------------------------------------------------------- retraining


class RetrainState(param.Parameterized):
    """A DQN retraining run in the background (one per session at a time).

    :meth:`start` validates the settings (:func:`uam_studio.planning.agents.retrain.training_setup`) and
    starts the run: in a child process (``runner="process"``, the served app's default:
    :class:`~uam_studio.planning.agents.retrain.RetrainProcess`, lower CPU priority, no GIL shared with
    the sessions) or in a thread of this process (``runner="thread"``). :meth:`stop` sets the stop
    flag (the agent trained so far is still saved). Neither touches the param values: :meth:`poll`,
    called on the session's own thread (a periodic callback in the app), drains the episodes into
    the values that views watch and returns the new ones.
    """

    source = param.Selector(default="map", objects=["map", "random"], doc="current map or random missions")
    scenario = param.Selector(default="single_charge", objects=list(SCENARIOS))
    alpha = param.Number(default=1.0, bounds=(0.0, 100.0), doc="reward per destination x priority")
    beta = param.Number(default=1.0, bounds=(0.0, 100.0), doc="penalty per charging stop")
    gamma = param.Number(default=5.0, bounds=(0.0, 100.0), doc="penalty for an end of discharge")
    steps = param.Integer(default=5000, bounds=(100, 1_000_000), doc="environment transitions")
    seed = param.Integer(default=0, bounds=(0, 2**31 - 1))
    start_from = param.Selector(default="scratch", objects=["scratch", "bundled"],
                                doc="random weights, or fine-tune the scenario's bundled agent "
                                    "(pretrained/dqn_<scenario>.zip; exploration from epsilon 0.2)")

    running = param.Boolean(default=False)
    timesteps = param.Integer(default=0)
    episodes = param.Integer(default=0)
    status = param.String(default="")
    error = param.String(default="")
    agent_path = param.String(default="", doc="the last saved agent")
    runner = param.Selector(default="process", objects=["process", "thread"],
                            doc="train in a child process (default; $UAM_STUDIO_RETRAIN_RUNNER overrides) "
                                "or in a thread of this process")

    MA_WINDOW = 50

    def __init__(self, **params: Any) -> None:
        env = os.environ.get(RUNNER_ENV, "").strip()
        if "runner" not in params and env in ("process", "thread"):
            params["runner"] = env
        super().__init__(**params)
        self._proc: Any = None
        self._queue: collections.deque = collections.deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._result: Any = None
        self._failure: str | None = None
        self._finished = False
        self._target_steps = 0
        self._reached: list[float] = []
        self._cycles: list[float] = []

    def start(self, mission: Mission | None = None) -> bool:
        """Start training on ``mission`` (``source == "map"``) or on random missions. Returns False
        (with :attr:`error` set) for bad settings or while a run is going."""
        from uam_studio.planning.agents.retrain import new_agent_path, training_setup

        if self.running:
            self.error = "training: a run is already going; stop it first"
            return False
        m = mission if self.source == "map" else None
        if self.source == "map" and mission is None:
            self.error = "training: no map to train on"
            return False
        init_agent = None
        if self.start_from == "bundled":
            from uam_studio.planning.agents.rollout import bundled_agent_path

            init_agent = str(bundled_agent_path(self.scenario))
        try:
            cfg, env_fn = training_setup(self.scenario, m, self.alpha, self.beta, self.gamma, self.steps, self.seed,
                                         init_agent=init_agent)
        except InputError as err:
            what = "current map" if m is not None else "settings"
            self.error = f"training ({what}): {_one_line(err)}"
            return False
        path = new_agent_path(self.scenario, "map" if m is not None else "random")
        self.error = ""
        self._queue.clear()
        self._stop.clear()
        self._result, self._failure, self._finished = None, None, False
        self._reached, self._cycles = [], []
        self._target_steps = cfg.steps
        verb = "fine-tuning the bundled agent" if init_agent else "training"
        self.param.update(running=True, timesteps=0, episodes=0, agent_path="",
                          status=f"{verb} {cfg.steps} steps on {'the current map' if m else 'random missions'}")
        if self.runner == "process":
            from uam_studio.planning.agents.retrain import RetrainProcess

            self._proc = RetrainProcess(path, mission=m, source="app", pause_event=ACTIVITY.event,
                                        scenario=self.scenario, alpha=self.alpha, beta=self.beta,
                                        gamma=self.gamma, steps=self.steps, seed=self.seed, init_agent=init_agent)
            self._proc.start()
            return True
        self._proc = None
        self._thread = threading.Thread(target=self._run, args=(cfg, env_fn, path, m), daemon=True,
                                        name="uam-retrain")
        self._thread.start()
        return True

    def _run(self, cfg: Any, env_fn: Callable[[], Any], path: Path, mission: Mission | None) -> None:
        import torch

        from uam_studio.planning.agents.retrain import retrain_dqn

        torch.set_num_threads(1)  # leave the other core to the sessions
        try:
            self._result = retrain_dqn(cfg, env_fn, path, mission=mission, on_episode=self._queue.append,
                                       stop_event=self._stop, source="app")
        except Exception as err:
            traceback.print_exc()
            self._failure = f"training failed: {type(err).__name__}: {_one_line(err)}"
        finally:
            self._finished = True

    def stop(self) -> None:
        """Ask the run to stop at the next environment step (the agent so far is saved)."""
        if self.running:
            self._stop.set()
            if self._proc is not None:
                self._proc.stop()
            self.status = "stopping..."

    @property
    def progress(self) -> float:
        """Fraction of the steps done, 0-1."""
        return min(1.0, self.timesteps / self._target_steps) if self._target_steps else 0.0

    def poll(self) -> list[dict[str, float]]:
        """Drain the episode queue (call on the session's thread). Returns the new episodes as rows
        ``{"episode", "reached", "cycles", "reached_ma", "cycles_ma"}`` (moving averages over
        :attr:`MA_WINDOW` episodes); updates the progress and, at the end, the status."""
        if self._proc is not None and not self._finished:
            self._queue.extend(self._proc.poll())
            if self._proc.finished:
                self._result = self._proc.result
                self._failure = f"training failed: {self._proc.error}" if self._proc.error else None
                self._finished = True
        rows = []
        while self._queue:
            e = self._queue.popleft()
            self._reached.append(float(e.reached))
            self._cycles.append(float(e.charging_cycles))
            w = self.MA_WINDOW
            rows.append({"episode": float(e.episode), "reached": float(e.reached),
                         "cycles": float(e.charging_cycles),
                         "reached_ma": float(np.mean(self._reached[-w:])),
                         "cycles_ma": float(np.mean(self._cycles[-w:]))})
            last_t = e.timestep
        changes: dict[str, Any] = {}
        if rows:
            changes.update(timesteps=int(last_t), episodes=self.episodes + len(rows))
        if self.running and self._finished:
            changes["running"] = False
            if self._failure:
                changes.update(error=self._failure, status="training failed")
            elif self._result is not None:
                r = self._result
                changes.update(timesteps=r.timesteps, agent_path=str(r.path), error="",
                               status=f"{'stopped' if r.stopped else 'done'}: {r.episodes} episodes, "
                                      f"{r.timesteps} steps; saved {r.path.name} (now in the Planner's "
                                      "policy list)")
        if changes:
            self.param.update(**changes)
        return rows

    def join(self, timeout: float | None = None) -> None:
        """Wait for the training thread or process (tests)."""
        if self._proc is not None:
            self._proc.join(timeout)
        elif self._thread is not None:
            self._thread.join(timeout)

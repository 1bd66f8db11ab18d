"""State of the Planner tab: the mission being edited, the chosen policy and the latest plan.

:class:`PlannerState` validates every edit with the library's mission model first; a rejected edit
sets :attr:`PlannerState.error` (one line naming the field and the allowed range) and leaves the
mission as it was. Accepted edits replan, either at once (:meth:`PlannerState.replan`; tests,
notebooks) or in the shared thread pool with only the latest request kept (``background=True``; the
served app; :class:`~uam_studio.app.services.LatestWorker`), so a slow planner never blocks the
session. Each plan comes from :func:`~uam_studio.app.planner.plans.compute_plan` (the library's
:func:`~uam_studio.planning.planner.plan_mission` with the Dynaformer's voltage band and the failed
take-off of a cell that cannot take off); :meth:`PlannerState.verdict` is the library's
:func:`~uam_studio.planning.safety.safety_verdict` of it, and :attr:`PlannerState.comparison` the
agent / greedy / oracle comparison of its mission (:mod:`uam_studio.app.planner.comparison`, kept by
:class:`~uam_studio.app.planner.comparison_state.PlannerComparison`).

The starting mission, the digest of what a plan depends on and the rows-to-destinations rules are in
:mod:`~uam_studio.app.planner.mission`.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import param

from uam_studio.app.planner.comparison import COMPARE_MODES
from uam_studio.app.planner.comparison_state import PlannerComparison
from uam_studio.app.planner.mission import EXAMPLE_MISSION, rows_to_destinations
from uam_studio.app.planner.plans import PlanRequest, cached_plan, compute_plan, request_key
from uam_studio.app.services import (
    ACTIVITY,
    APP_EOD_RANGE,
    APP_Q_RANGE,
    APP_R0_RANGE,
    POLICY_LABELS,
    LatestWorker,
    agent_policy,
    default_policy,
    one_line,
    policy_options,
    registry,
)
from uam_studio.battery import DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.errors import InputError, check_range
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.missions.mission import (
    COORD_RANGE_KM,
    MAX_DESTINATIONS,
    SCENARIOS,
    Battery,
    Destination,
    Mission,
    Vertiport,
    mission_from_dict,
    mission_from_json,
    mission_to_dict,
)
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO
from uam_studio.planning.planners import PLANNERS
from uam_studio.planning.safety import safety_verdict

__all__ = ["PlannerState"]


class PlannerState(PlannerComparison, param.Parameterized):
    """The mission being edited, the policy, and the latest plan.

    Inputs (validated; change them with :meth:`apply`, :meth:`set_destinations`, :meth:`load_json`
    so that a bad value becomes :attr:`error` instead of an exception): ``mission_name``,
    ``destinations``, ``vertiport_x_km``, ``vertiport_y_km``, ``return_wind``, ``scenario``,
    ``q_max``, ``r0``, ``eod_v``, ``policy``.

    Outputs: ``plan`` (:func:`~uam_studio.planning.planner.plan_mission`'s result as a dict), ``plan_request``
    (what it was computed for), ``health`` (PC1, PC2), ``plan_error`` (a planner error, e.g. an
    unreadable agent), ``busy`` (a plan is being computed), ``plan_count``.
    """

    mission_name = param.String(default="Bay shuttle")
    destinations = param.List(default=[], item_type=Destination)
    vertiport_x_km = param.Number(default=0.0, bounds=COORD_RANGE_KM)
    vertiport_y_km = param.Number(default=0.0, bounds=COORD_RANGE_KM)
    return_wind = param.Number(default=0.0, bounds=WIND_RANGE_KTS, doc="wind (kt) on legs back to the vertiport")
    scenario: param.Selector[str] = param.Selector(default=DEFAULT_SCENARIO, objects=list(SCENARIOS))
    q_max = param.Number(default=DEFAULT_Q_MAX, bounds=APP_Q_RANGE, doc="mobile lithium charge q_max (C)")
    r0 = param.Number(default=DEFAULT_R0, bounds=APP_R0_RANGE, doc="ohmic resistance R0 (ohm)")
    eod_v = param.Number(default=3.0, bounds=APP_EOD_RANGE, doc="end-of-discharge cut-off (V)")
    policy: param.Selector[str] = param.Selector(default="greedy", objects=list(POLICY_LABELS.values()),
                                                 check_on_set=False)
    policy_objects = param.Dict(default=dict(POLICY_LABELS), doc="policy select options: label -> value")

    plan = param.Dict(default=None, allow_None=True, doc="plan_mission's result for plan_request")
    plan_request = param.ClassSelector(class_=PlanRequest, default=None, allow_None=True)
    plan_error = param.String(default="")
    band = param.Dict(default=None, allow_None=True, doc="the Dynaformer's voltage band of the plan "
                                                          "(the plan's band), None without one")
    takeoff = param.Dict(default=None, allow_None=True, doc="the failed take-off on the physics model "
                                                             "(takeoff_attempt), None if the cell takes off")
    comparison = param.Dict(default=None, allow_None=True,
                            doc="agent, greedy and oracle plans of the shown plan's mission: {'scenario', "
                                "'inputs', 'rows': {name: row}} (compare_row; status 'pending' until done)")
    health = param.Tuple(default=None, allow_None=True, length=2)
    busy = param.Boolean(default=False)
    plan_count = param.Integer(default=0, doc="plans applied so far")
    error = param.String(default="", doc="why the last edit was rejected (one line), '' if it was accepted")
    notice = param.String(default="", doc="a short note about the last accepted action")

    MISSION_INPUTS = ("mission_name", "destinations", "vertiport_x_km", "vertiport_y_km", "return_wind", "scenario",
                      "q_max", "r0", "eod_v")
    INPUTS = (*MISSION_INPUTS, "policy")

    def __init__(self, mission: Mission | dict | None = None, background: bool = False,
                 dispatch: Callable[[Callable[[], None]], None] | None = None, auto: bool = True,
                 compare: str = "off", **params: Any) -> None:
        """
        :param mission: the starting mission (default :data:`EXAMPLE_MISSION`).
        :param background: replan in the shared thread pool (served app) instead of in place; a first
            plan already in the shared cache (:func:`~uam_studio.app.planner.plans.cached_plan`) is applied
            at once, so a served page is built with it.
        :param dispatch: how a finished background plan is handed back to the session's thread
            (default: applied in the worker thread; the served app passes a next-tick dispatcher).
        :param auto: replan on every accepted change (False: call :meth:`replan` yourself).
        :param compare: where the plan comparison (:attr:`comparison`) is computed: ``"process"`` or
            ``"thread"`` (:func:`~uam_studio.app.planner.comparison.comparison_runner`,
            :data:`~uam_studio.app.planner.comparison.COMPARE_DELAY_S` after the shown plan
            settles), ``"inline"`` (at once, in the thread that applies the plan) or ``"off"``.
        """
        super().__init__(**params)
        if compare not in COMPARE_MODES:
            raise InputError("compare", f"{compare!r}: allowed {', '.join(COMPARE_MODES)}")
        self.background = background
        self.dispatch = dispatch or (lambda cb: cb())
        self.auto = auto
        self.compare = compare
        self._compare_key: tuple | None = None
        self._compare_timer: threading.Timer | None = None
        self._worker: LatestWorker[PlanRequest, dict[str, Any]] = LatestWorker(
            compute_plan, self._apply, _plan_failed, dispatch=self.dispatch)
        m = mission if mission is not None else EXAMPLE_MISSION
        m = m if isinstance(m, Mission) else mission_from_dict(m)
        self._set_mission(m)
        self._mission = self._build()
        # first of all watchers: every reader (the replan below, the views) sees the mission of the new inputs
        self.param.watch(self._sync_mission, list(self.MISSION_INPUTS))
        reg = registry()
        self._update_policy_options(reg.agents)
        self._agents_watcher: param.parameterized.Watcher | None = reg.param.watch(self._on_agents, "agents")
        if "policy" not in params:
            self.policy = default_policy(self.scenario)
        self.param.watch(self._on_inputs, list(self.INPUTS))
        if self.auto:
            if self.background and cached_plan(request_key(self.request())) is not None:
                # Known already (the server's warm-up planned the example mission, or another session
                # this one): applied here, so a served page is built with its plan and nothing of the
                # plan is sent again after the page.
                self.replan()
            else:
                self.request_plan()

    # ------------------------------------------------------------------ mission <-> state

    @property
    def mission(self) -> Mission:
        """The current (always valid) mission: one value, built once per accepted edit of its inputs."""
        return self._mission

    def _sync_mission(self, *events: param.parameterized.Event) -> None:
        self._mission = self._build()

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
                                                 f"{MAX_DESTINATIONS}); add another before removing the last one")
        self._build(**out)  # the library validates the rest (Mission: 1-20 destinations, names, priorities...)
        return out

    def apply(self, **changes: Any) -> bool:
        """Validate and apply ``changes`` to the inputs together. On a bad value set :attr:`error` and
        keep everything as it was. Returns True if applied."""
        try:
            ok = self._validate(changes)
        except InputError as err:
            self.error = one_line(err)
            return False
        self.error = ""
        self.param.update(**ok)
        return True

    def set_destinations(self, rows: list[dict[str, Any]]) -> bool:

        """Replace the destinations from table or map rows (``name``, ``x_km``, ``y_km``, ``priority``,
        ``wind_kts``, ``dwell_s``). Rows fresh from the map may lack values: a missing name becomes
        the first free ``D<k>``, a missing or 0 priority 1 (the map's point-drawing tool's empty value), wind and
        dwell 0. Coordinates are rounded to 0.1 km. Returns True if accepted (see :meth:`apply`)."""
        try:
            dests = rows_to_destinations(rows)
        except InputError as err:
            self.error = one_line(err)
            return False
        if dests == list(self.destinations):
            self.error = ""
            return True
        return self.apply(destinations=dests)

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
            m = mission_from_json(data if data is not None else b"", what)
            self._validate({"destinations": list(m.destinations)})
            self._validate({k: v for k, v in self._mission_params(m).items()
                            if k in ("q_max", "r0", "eod_v")})
        except InputError as err:
            self.error = f"{what}: {one_line(err)}" if not str(err).startswith(what) else one_line(err)
            return False
        self.error = ""
        self.param.update(**self._mission_params(m))
        self.notice = f"loaded {filename or 'mission'} ({len(m.destinations)} destinations)"
        return True

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
            self.policy = default_policy(self.scenario)

    def policy_label(self, value: str) -> str:
        """The policy select's label of a policy value (``"dqn"`` -> ``"DQN (paper, up to 8)"``, an
        ``agent:<path>`` -> ``"Retrained: <file> (<scenario>)"``)."""
        for label, v in self.policy_objects.items():
            if v == value:
                return label
        policy, path = agent_policy(value)
        if path is not None:  # e.g. an attention planner's weights are named by their folder
            from uam_studio.planning.agents.trainer import trainer

            return f"Retrained: {trainer(policy).agent_name(Path(path))}"
        return value

    def plan_label(self) -> str:
        """Which planner made the shown plan: its policy label, and for the oracle whether the plan is
        proven optimal (``exact``: up to 8 destinations) or the reference solver's (9-20); '' before
        the first plan."""
        req, plan = self.plan_request, self.plan
        if req is None:
            return ""
        label = self.policy_label(req.policy)
        reports_exact = req.policy in PLANNERS and PLANNERS[req.policy].reports_exact
        if plan is not None and reports_exact and plan.get("exact") is not None:
            label = ("Oracle (exact optimum)" if plan["exact"]
                     else "Oracle: the reference solver's plan (OR-Tools), not proven optimal")
        return label

    def verdict(self) -> dict[str, Any]:
        """:func:`~uam_studio.planning.safety.safety_verdict` of the shown plan."""
        eod = self.plan_request.mission.eod_v if self.plan_request is not None else self.eod_v
        return safety_verdict(self.plan, self.band, self.takeoff, eod)

    def close(self) -> None:
        """Stop following the agent registry, drop waiting comparisons and count as idle (the session ended)."""
        self._stop_comparison()
        ACTIVITY.mark(id(self), False)
        if self._agents_watcher is not None:
            registry().param.unwatch(self._agents_watcher)
            self._agents_watcher = None

    # ------------------------------------------------------------------ replanning

    def _on_inputs(self, *events: param.parameterized.Event) -> None:
        if self.auto:
            self.request_plan()

    def request(self) -> PlanRequest:
        """What a plan of the current inputs depends on."""
        return PlanRequest(self.mission, self.policy)

    def replan(self) -> dict[str, Any]:
        """Plan the current mission now, in this thread, and apply the result."""
        return self._worker.run(self.request())

    def request_plan(self) -> None:
        """Replan: in place, or (``background``) in the pool, where a request arriving while one is
        computed replaces any waiting one, so at most one plan per session runs and the last wins."""
        if not self.background:
            self.replan()
            return
        req = self.request()
        ACTIVITY.mark(id(self), True)
        if not self.busy:
            self.busy = True
        self._worker.submit(req)

    def _apply(self, res: dict[str, Any], latest: bool) -> None:
        """Show a computed plan (``latest``: no newer request is on its way)."""
        changes: dict[str, Any] = {"plan_error": res["error"] or "", "plan_request": res["request"],
                                   "plan_count": self.plan_count + 1}
        if res["plan"] is not None or res["error"]:
            changes["plan"] = res["plan"]
            changes["band"] = res.get("band")
            changes["takeoff"] = res.get("takeoff")
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
        if latest:
            self._update_comparison()

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the latest requested plan is applied (tests and benchmarks; not from the
        session's own thread when a dispatcher schedules on it)."""
        return self._worker.wait_idle(timeout)


def _plan_failed(req: PlanRequest, err: BaseException) -> dict[str, Any]:
    """The result of a plan whose computation raised (:func:`compute_plan` never does)."""
    return {"plan": None, "error": f"planning failed: {one_line(err)}", "health": None, "request": req,
            "elapsed_s": 0.0}

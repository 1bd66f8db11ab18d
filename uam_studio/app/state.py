"""State models of the app: plain ``param.Parameterized`` classes, no widgets, no plots.

- :class:`PlannerState`: the mission being edited (destinations, winds, cell, EOD, scenario), the
  chosen policy and the latest plan. Every edit is validated by the library's mission model first;
  a rejected edit sets :attr:`PlannerState.error` (one line naming the field and the allowed range)
  and leaves the mission as it was. Accepted edits replan, either at once (:meth:`replan`; tests,
  notebooks) or in a shared thread pool with only the latest request kept (``background=True``;
  the served app), so a slow planner never blocks the session. With each plan come the
  Dynaformer's voltage band (:func:`prediction_band`), the failed take-off of a cell that cannot
  take off (:func:`takeoff_attempt`), the safety verdict by source (:func:`safety_verdict`) and the
  agent / greedy / oracle comparison of the mission (:func:`compare_row`, computed apart from the
  plans by a :class:`ComparisonRunner`).
- :class:`BatteryLabState`: one leg and one cell, and a family of curves varying one factor.
- :class:`RetrainState`: a DQN retraining in a child process or a thread with a stop flag; episode
  stats go through a queue that the view drains on its own (periodic) callback; progress with
  elapsed time and time left; the exact oracle's plan of the map as the curves' reference.
- :class:`AgentRegistry`: the retrained agents in the user folder, shared by all sessions.

Planning, physics and training all come from the library (:func:`~uam_studio.planning.planner.plan_mission`,
:mod:`uam_studio.planning.agents.retrain`, :func:`uam_studio.flight.leg_profile`,
:func:`uam_studio.battery.simulate`, ``DynaformerPredictor.voltage_band``); this module holds state
and calls them.
"""

from __future__ import annotations

import collections
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
from typing import TYPE_CHECKING, Any

import numpy as np
import param

from uam_studio.errors import InputError, check_range
from uam_studio.flight.tables import ALTITUDE_RANGE_M, WIND_RANGE_KTS
from uam_studio.planning.agents.attention import WEIGHTS_NAME
from uam_studio.planning.legs import MAX_DESTINATIONS, check_destination_count
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

if TYPE_CHECKING:
    from uam_studio.planning.planner import PlanResult

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
    "ComparisonRunner",
    "compare_mode",
    "compare_row",
    "comparison_runner",
    "comparison_table",
    "compute_plan",
    "default_policy",
    "mission_digest",
    "population",
    "prediction_band",
    "safety_verdict",
    "takeoff_attempt",
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

POLICY_LABELS = {"Attention (bundled, default)": "attention", "DQN (paper, up to 8)": "dqn",
                 "Oracle (exact up to 8)": "oracle", "Greedy": "greedy"}
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


def warm_up(compare: str | None = None) -> None:
    """Load the Dynaformer and the health population, and plan the example mission with the default
    policy, now (server start), so the first session shows its first plan at once. With a
    comparison runner (``compare``: default :func:`compare_mode` of a server), also start it and
    compare the example's planners, so the first session's comparison is ready too."""
    population()
    mission = mission_from_dict(EXAMPLE_MISSION)
    policy = default_policy(mission.scenario)
    compute_plan(PlanRequest(mission, policy))
    mode = compare or compare_mode(True)
    if mode in ("process", "thread"):
        runner = comparison_runner(mode)
        runner.start()
        agent = policy if policy in LEARNED_POLICIES else "attention"
        todo = [PlanRequest(mission, p) for p in (agent, "greedy", "oracle")
                if cached_row(PlanRequest(mission, p)) is None]
        runner.submit("warm-up", [(r, lambda _row: None) for r in todo])


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
    """Select options (label -> value): the four planners (the attention planner first) and one
    ``agent:<path>`` per retrained DQN agent."""
    opts = dict(POLICY_LABELS)
    if not _attention_exists():  # an install without the weights: the label must not promise them
        opts = {("Attention (not installed)" if v == "attention" else k): v for k, v in opts.items()}
    for a in agents:
        opts[f"Retrained: {a.label}"] = f"{AGENT_PREFIX}{a.path}"
    return opts


# ----------------------------------------------------------------------------- planning


@dataclass(frozen=True)
class PlanRequest:
    """Everything a plan depends on (a snapshot, safe to hand to another thread)."""

    mission: Mission
    policy: str  # attention | dqn | oracle | greedy | agent:<path>


def mission_digest(m: Mission) -> str:
    """What a plan of ``m`` depends on, compactly: scenario, cell, EOD, return wind and
    ``name:priority:wind`` of each destination (the app's ``data-inputs`` attributes)."""
    dests = "|".join(f"{d.name}:{d.priority}:{d.wind_kts:g}" for d in m.destinations)
    return (f"{m.scenario};q_max={m.battery.q_max:g};r0={m.battery.r0:g};eod={m.eod_v:g};"
            f"return_wind={m.vertiport.wind_kts:g};{dests}")


def _agent_stamp(req: PlanRequest) -> tuple[str, int, int] | None:
    """(path, mtime ns, size) of the agent file a learned plan uses (the bundled attention planner; a
    retrained DQN agent, or the bundled one for the mission's scenario), so a plan cached for another
    or an older file is never reused."""
    from uam_studio.bundled import bundled_path
    from uam_studio.planning.agents.rollout import bundled_agent_path

    if req.policy.startswith(AGENT_PREFIX):
        path = Path(req.policy[len(AGENT_PREFIX):])
    elif req.policy == "attention":
        path = bundled_path(WEIGHTS_NAME)
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

    :return: ``{"plan": plan_mission's result as a dict (``PlanResult.to_dict()``) or None, "error": one line or None, "health": (pc1, pc2)
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
    out = _copy_plain(hit)
    out["cached"] = cached
    if cached:
        out["elapsed_s"] = time.perf_counter() - t0
    return out


def _copy_plain(obj: Any) -> Any:
    """A copy of a plain-data result (dicts, lists, tuples of numbers, strings...) that a session may
    change without touching the cache; much faster than ``copy.deepcopy`` on long series. Other
    objects (a frozen :class:`PlanRequest`) are shared."""
    if isinstance(obj, dict):
        return {k: _copy_plain(v) for k, v in obj.items()}
    if isinstance(obj, list):
        if all(isinstance(v, (int, float, str, bool)) or v is None for v in obj):
            return list(obj)
        return [_copy_plain(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(_copy_plain(v) for v in obj)
    return obj


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
                                   predictor=pred if pred is not None else False).to_dict()  # JSON state
        if pred is None:
            out["plan"]["messages"].append(_predictor_or_error()[1] or "no Dynaformer")
    except InputError as err:
        out["error"] = _one_line(err)
    except Exception as err:  # never a traceback in the app; the server log keeps it
        traceback.print_exc()
        out["error"] = f"planning failed: {type(err).__name__}: {_one_line(err)}"
    out["band"], out["takeoff"] = None, None
    plan = out["plan"]
    if plan is not None:
        try:
            if plan["route"] and pred is not None:
                out["band"] = prediction_band(req.mission, plan, pred)
            elif not plan["route"]:
                out["takeoff"] = takeoff_attempt(req.mission)
        except (InputError, ValueError, RuntimeError) as err:
            plan["messages"].append(f"Dynaformer band unavailable ({_one_line(err)})")
        except Exception:  # the band and the take-off trace are extras: the plan stands without them
            traceback.print_exc()
    try:
        b = req.mission.battery
        out["health"] = health_estimate(float(b.q_max), float(b.r0))
    except Exception:  # the health view is optional
        traceback.print_exc()
    out["elapsed_s"] = time.perf_counter() - t0
    return out


BAND_LEVEL = 0.9  # coverage of the Dynaformer's voltage band in the Planner
BAND_METHOD = "voltage_band"  # DynaformerPredictor method giving (low, median, high) on a current profile


def _sortie_cuts(sim: Any) -> list[int]:
    """Sample indices where the route's sorties start and end (a landing at the vertiport recharges),
    as :func:`~uam_studio.planning.planner.plan_mission` cuts the route for the Dynaformer."""
    from uam_studio.planning.missions.mission import VERTIPORT

    cuts = [0]
    for leg in sim.legs:
        if leg.reached and leg.to == VERTIPORT and leg.end_s is not None:
            cuts.append(int(round(leg.end_s / sim.dt_s)))
    n = sim.current_a.size
    return sorted({c for c in cuts if c < n} | {n})


def prediction_band(mission: Mission, plan: dict[str, Any], pred: Any, level: float = BAND_LEVEL) \
        -> dict[str, Any] | None:
    """The Dynaformer's pointwise ``level`` voltage band along ``plan``'s route.

    Each sortie is predicted as :func:`~uam_studio.planning.planner.plan_mission` predicts it (context:
    the first 20 s of the take-off on the physics model; profile: the route's current since the last
    recharge), with the predictor's :data:`BAND_METHOD` (``voltage_band``). The band is returned on
    the plan's own time samples, its lowest values from every sample.

    :return: ``{"time_s", "low_v", "high_v", "level", "min_low_v", "min_high_v"}``, or None when the
        route is empty or the predictor has no :data:`BAND_METHOD`.
    """
    from uam_studio.planning.env import CONTEXT_S, observe_takeoff
    from uam_studio.planning.missions.check import check_plan

    band_fn = getattr(pred, BAND_METHOD, None)
    if band_fn is None or not plan.get("route"):
        return None
    sim = check_plan(mission, plan["route"], plan["altitudes_m"]).sim
    if sim is None:
        return None
    ci, cv = observe_takeoff(sim.q_max, sim.r0)
    ci, cv = ci[:CONTEXT_S], cv[:CONTEXT_S]
    cuts = _sortie_cuts(sim)
    lows, highs = [], []
    for a, b in zip(cuts[:-1], cuts[1:]):
        lo, _, hi = band_fn(ci, cv, sim.current_a[a:b], dt_s=sim.dt_s, level=level)
        lows.append(np.asarray(lo, dtype=float).reshape(-1)[: b - a])
        highs.append(np.asarray(hi, dtype=float).reshape(-1)[: b - a])
    low, high = np.concatenate(lows), np.concatenate(highs)
    t = np.asarray(plan["physics"]["time_s"], dtype=float)
    full_t = np.asarray(sim.time_s, dtype=float)[: low.size]
    return {"time_s": [float(x) for x in t],
            "low_v": [round(float(x), 4) for x in np.interp(t, full_t, low)],
            "high_v": [round(float(x), 4) for x in np.interp(t, full_t, high)],
            "level": float(level), "min_low_v": float(low.min()), "min_high_v": float(high.min())}


def takeoff_attempt(mission: Mission) -> dict[str, Any] | None:
    """The physics model's take-off and climb to 500 m for the mission's cell if it falls below the
    cut-off before the end (the cell cannot take off), else None.

    :return: ``{"time_s", "voltage_v", "eod_s"}``: the samples up to the first one below the cut-off.
    """
    from uam_studio.battery import simulate
    from uam_studio.planning.legs import DT_S, takeoff_current

    b = mission.battery
    sim = simulate(takeoff_current(), DT_S, float(b.q_max), float(b.r0), eod_v=float(mission.eod_v))
    if not bool(sim.eod_reached):
        return None
    n = min(int(np.count_nonzero(sim.valid)) + 1, sim.voltage_v.size)
    return {"time_s": [float(x) for x in sim.time_s[:n]], "voltage_v": [float(x) for x in sim.voltage_v[:n]],
            "eod_s": float(sim.eod_s)}


def _margin_words(margin: float) -> str:
    return f"safe by {_volts(margin)}" if margin >= 0 else f"below EOD by {_volts(-margin)}"


def _volts(x: float) -> str:
    """A voltage difference: 2 decimals, 3 under 0.1 V (so a margin of a few mV does not read 0.00)."""
    return f"{x:.2f} V" if abs(x) >= 0.1 else f"{x:.3f} V"


def _signed_volts(x: float) -> str:
    return f"{x:+.2f} V" if abs(x) >= 0.1 else f"{x:+.3f} V"


def safety_verdict(plan: dict[str, Any] | None, band: dict[str, Any] | None, takeoff: dict[str, Any] | None,
                   eod_v: float) -> dict[str, Any]:
    """Whether the plan stays above the cut-off, by source: the physics model and the Dynaformer.

    Levels: ``"safe"`` (both above, and the Dynaformer's band too), ``"uncertain"`` (both above, but
    the band reaches the cut-off), ``"disagree"`` (one above, one below), ``"unsafe"`` (both below,
    or the cell cannot take off), ``"none"`` (nothing is flown). Without a Dynaformer prediction the
    physics model decides alone.

    :return: ``{"level", "headline", "text", "physics_margin_v", "predicted_margin_v",
        "band_margin_v"}`` (margins: lowest voltage minus ``eod_v``; band: (low, high) or None).
    """
    out: dict[str, Any] = {"level": "none", "headline": "Nothing is flown", "text": "",
                           "physics_margin_v": None, "predicted_margin_v": None, "band_margin_v": None}
    if takeoff is not None:
        out.update(level="unsafe", headline="Not safe: the cell cannot take off",
                   text=f"physics: below EOD ({eod_v:g} V) {takeoff['eod_s']:.0f} s into the take-off and climb")
        return out
    if not plan or not plan.get("route") or plan.get("min_voltage_v") is None:
        return out
    phys = float(plan["min_voltage_v"]) - eod_v
    phys_safe = bool(plan["safe"])
    out["physics_margin_v"] = phys
    parts = [f"physics: {_margin_words(phys)}"]
    pred = plan.get("predicted")
    pred_safe = None
    if pred and pred.get("voltage_v"):
        pm = min(pred["voltage_v"]) - eod_v
        pred_safe = pm >= 0
        out["predicted_margin_v"] = pm
        words = f"predicted: {_margin_words(pm)}"
        if band is not None:
            lo, hi = band["min_low_v"] - eod_v, band["min_high_v"] - eod_v
            out["band_margin_v"] = (lo, hi)
            words += f" ({100 * band['level']:.0f}%: {_signed_volts(lo)} to {_signed_volts(hi)})"
        parts.append(words)
    else:
        parts.append("predicted: - (no Dynaformer prediction)")
    out["text"] = "; ".join(parts)
    band_low_safe = out["band_margin_v"] is None or out["band_margin_v"][0] >= 0
    if pred_safe is None:
        out.update(level="safe" if phys_safe else "unsafe",
                   headline="Safe (physics model)" if phys_safe else "Not safe (physics model)")
    elif phys_safe and pred_safe:
        if band_low_safe:
            out.update(level="safe", headline="Safe: physics and Dynaformer agree")
        else:
            out.update(level="uncertain", headline=f"Check: safe on both models, but the Dynaformer's "
                                                   f"{100 * band['level']:.0f}% band reaches EOD")
    elif not phys_safe and not pred_safe:
        out.update(level="unsafe", headline="Not safe: physics and Dynaformer agree")
    else:
        which = "physics safe, Dynaformer below EOD" if phys_safe else "Dynaformer safe, physics below EOD"
        out.update(level="disagree", headline=f"Models disagree: {which}")
    return out


# ----------------------------------------------------------------------------- plan comparison

COMPARE_ENV = "UAM_STUDIO_COMPARE"  # where comparison plans run: "process", "thread", "inline" or "off"
COMPARE_MODES = ("process", "thread", "inline", "off")
COMPARE_DELAY_S = 0.3  # a comparison starts once the shown plan has been stable this long (slider drags)
COMPARE_CACHE_SIZE = 512


def compare_mode(served: bool) -> str:
    """Where this process computes plan comparisons: ``$UAM_STUDIO_COMPARE`` if set to one of
    :data:`COMPARE_MODES`, else ``"process"`` for a server and ``"thread"`` elsewhere (Jupyter)."""
    env = os.environ.get(COMPARE_ENV, "").strip()
    return env if env in COMPARE_MODES else ("process" if served else "thread")


def _row_from_plan(plan: PlanResult | dict[str, Any], mission: Mission) -> dict[str, Any]:
    """A comparison row from a :class:`~uam_studio.planning.planner.PlanResult` or its ``to_dict()``
    (the app's state keeps the dict)."""
    return {"status": "done", "error": None, "priority": int(plan["reached_priority"]),
            "reached": len(plan["reached"]), "of": len(mission.destinations),
            "cycles": int(plan["charging_cycles"]), "min_voltage_v": plan["min_voltage_v"],
            "safe": bool(plan["safe"]), "route": list(plan["route"]), "altitudes_m": list(plan["altitudes_m"]),
            "exact": plan["exact"]}


def _agent_reads_dynaformer(agent_path: str | None, scenario: str) -> bool:
    from uam_studio.planning.agents.rollout import bundled_agent_path, load_agent_cached

    try:
        card = load_agent_cached(agent_path or bundled_agent_path(scenario))[1]
    except InputError:
        return False
    return card.get("health") == "dynaformer"


def compare_row(mission: Mission, policy: str) -> dict[str, Any]:
    """One row of the plan comparison: :func:`~uam_studio.planning.planner.plan_mission` (the CLI's
    call) for ``policy`` (``attention``, ``dqn``, ``oracle``, ``greedy`` or ``agent:<path>``) on
    ``mission``. The Dynaformer is loaded only for a DQN agent that reads its health features (the
    route does not depend on it otherwise). Never raises.

    :return: ``{"status": "done" | "error", "error", "priority", "reached", "of", "cycles",
        "min_voltage_v", "safe", "route", "altitudes_m", "exact", "elapsed_s"}`` (``exact``: the
        plan's, True or False for the oracle, None for the others).
    """
    from uam_studio.planning.planner import plan_mission

    t0 = time.perf_counter()
    name, agent_path = policy, None
    if policy.startswith(AGENT_PREFIX):
        name, agent_path = "dqn", policy[len(AGENT_PREFIX):]
    try:
        pred: Any = False
        if name == "dqn" and _agent_reads_dynaformer(agent_path, mission.scenario):
            pred = predictor() or False
        row = _row_from_plan(plan_mission(mission, name, agent_path=agent_path, predictor=pred), mission)
    except InputError as err:
        row = {"status": "error", "error": _one_line(err)}
    except Exception as err:  # never a traceback in the app; the server log keeps it
        traceback.print_exc()
        row = {"status": "error", "error": f"planning failed: {type(err).__name__}: {_one_line(err)}"}
    row["elapsed_s"] = time.perf_counter() - t0
    return row


_COMPARE_CACHE: collections.OrderedDict[tuple, dict[str, Any]] = collections.OrderedDict()


def cached_row(req: PlanRequest) -> dict[str, Any] | None:
    """The comparison row of ``req`` if this process has it: computed for a comparison before, or
    from a plan the sessions computed (:func:`compute_plan`'s cache; the same library call)."""
    key = (req, _agent_stamp(req))
    with _PLAN_CACHE_LOCK:
        row = _COMPARE_CACHE.get(key)
        if row is not None:
            _COMPARE_CACHE.move_to_end(key)
            return dict(row)
        res = _PLAN_CACHE.get(key)
    if res is None:
        return None
    if res["plan"] is not None:
        return {**_row_from_plan(res["plan"], req.mission), "elapsed_s": res["elapsed_s"]}
    if res["error"]:
        return {"status": "error", "error": res["error"], "elapsed_s": res["elapsed_s"]}
    return None


def store_row(req: PlanRequest, row: dict[str, Any]) -> None:
    """Keep a computed comparison row for all sessions (not an unexpected failure)."""
    if (row.get("error") or "").startswith(("planning failed", "comparison failed")):
        return
    with _PLAN_CACHE_LOCK:
        _COMPARE_CACHE[(req, _agent_stamp(req))] = dict(row)
        while len(_COMPARE_CACHE) > COMPARE_CACHE_SIZE:
            _COMPARE_CACHE.popitem(last=False)


def _runner_main(requests: Any, results: Any, parent_pid: int, nice: int) -> None:
    """The comparison child process: :func:`compare_row` for each request, until the parent is gone."""
    import queue

    if nice:
        try:
            os.nice(nice)
        except OSError:
            pass
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover - torch is a dependency
        pass
    while True:
        try:
            item = requests.get(timeout=2.0)
        except queue.Empty:
            if os.getppid() != parent_pid:  # the server was killed: do not linger
                return
            continue
        if item is None:
            return
        results.put(compare_row(*item))


@dataclass
class _Task:
    req: PlanRequest
    callback: Callable[[dict[str, Any]], None]


class ComparisonRunner:
    """Computes comparison rows one at a time for all sessions of a process, apart from their plans.

    ``mode="process"`` (the served app): in one ``spawn`` child process at a lower CPU priority
    (``nice``), with one torch thread, so that an exact oracle taking seconds shares neither the GIL
    nor a core's priority with the sessions' own replanning. ``mode="thread"``: in a thread of this
    process. Each owner (a session) has a list of waiting tasks, replaced by :meth:`submit` and
    dropped by :meth:`cancel`; a task already running finishes. Owners take turns. Each result is
    stored (:func:`store_row`) and handed to the task's callback in the runner's thread.
    """

    def __init__(self, mode: str = "thread", nice: int = 10) -> None:
        if mode not in ("process", "thread"):
            raise InputError("mode", f"{mode!r}: allowed process or thread")
        self.mode = mode
        self.nice = nice
        self._cv = threading.Condition()
        self._pending: collections.OrderedDict[Any, list[_Task]] = collections.OrderedDict()
        self._thread: threading.Thread | None = None
        self._proc: Any = None
        self._requests: Any = None
        self._results: Any = None
        self.busy = False

    def submit(self, owner: Any, tasks: list[tuple[PlanRequest, Callable[[dict[str, Any]], None]]]) -> None:
        """Replace ``owner``'s waiting tasks with ``tasks`` (run in this order)."""
        with self._cv:
            if tasks:
                self._pending[owner] = [_Task(r, cb) for r, cb in tasks]
                self._pending.move_to_end(owner)
            else:
                self._pending.pop(owner, None)
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, daemon=True, name="uam-compare")
                self._thread.start()
            self._cv.notify_all()

    def cancel(self, owner: Any) -> None:
        """Drop ``owner``'s waiting tasks."""
        with self._cv:
            self._pending.pop(owner, None)

    def idle(self) -> bool:
        """No task waiting or running."""
        with self._cv:
            return not self._pending and not self.busy

    def start(self) -> None:
        """Start the child process now (``mode="process"``; its imports take seconds)."""
        if self.mode == "process":
            with self._cv:
                self._ensure_process()

    def _ensure_process(self) -> None:
        if self._proc is not None and self._proc.is_alive():
            return
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")  # no fork of a threaded server
        self._requests, self._results = ctx.Queue(), ctx.Queue()
        self._proc = ctx.Process(target=_runner_main, name="uam-compare", daemon=True,
                                 args=(self._requests, self._results, os.getpid(), self.nice))
        self._proc.start()

    def _next(self) -> _Task:
        with self._cv:
            while not self._pending:
                self._cv.wait()
            owner, tasks = next(iter(self._pending.items()))
            task = tasks.pop(0)
            if tasks:
                self._pending.move_to_end(owner)  # the next owner's turn
            else:
                del self._pending[owner]
            self.busy = True
            return task

    def _loop(self) -> None:
        while True:
            task = self._next()
            try:
                row = cached_row(task.req) or self._run(task.req)
                store_row(task.req, row)
                task.callback(row)
            except Exception as err:  # a callback of a closed session, a broken pipe: keep serving
                traceback.print_exc()
                try:
                    task.callback({"status": "error", "error": f"comparison failed: {_one_line(err)}"})
                except Exception:
                    pass
            finally:
                with self._cv:
                    self.busy = False
                    self._cv.notify_all()

    def _run(self, req: PlanRequest) -> dict[str, Any]:
        if self.mode == "thread":
            return compare_row(req.mission, req.policy)
        import queue

        with self._cv:
            self._ensure_process()
            proc, requests, results = self._proc, self._requests, self._results
        requests.put((req.mission, req.policy))
        while True:
            try:
                return results.get(timeout=1.0)
            except queue.Empty:
                if not proc.is_alive():
                    return {"status": "error", "error": f"comparison failed: the worker process exited "
                                                        f"(code {proc.exitcode})"}

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until no task is waiting or running (tests, benchmarks)."""
        deadline = time.monotonic() + timeout
        with self._cv:
            while self._pending or self.busy:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(left)
        return True


_RUNNERS: dict[str, ComparisonRunner] = {}
_RUNNERS_LOCK = threading.Lock()


def comparison_runner(mode: str) -> ComparisonRunner:
    """The process-wide :class:`ComparisonRunner` of ``mode`` (``"process"`` or ``"thread"``)."""
    with _RUNNERS_LOCK:
        if mode not in _RUNNERS:
            _RUNNERS[mode] = ComparisonRunner(mode)
        return _RUNNERS[mode]


COMPARE_ROWS = ("agent", "greedy", "oracle")
COMPARE_LABELS = {"attention": "Attention (default)", "dqn": "DQN (paper)"}
"""Short labels of the learned planners in the comparison table (its rows do not wrap)."""
ORACLE_REFERENCE_LABEL = "Oracle (reference)"
"""The comparison's oracle row where the oracle returned the reference solver's plan (9-20
destinations, not proven optimal)."""


def comparison_table(comparison: dict[str, Any] | None) -> list[dict[str, Any]]:
    """The comparison's rows in display order, each with ``gap``: the difference to the oracle in
    the scenario's objective (priority reached; in multi charge also charging cycles), as text, ''
    while either is missing. Where the oracle's plan is the reference solver's (``exact`` False), its
    row is labelled :data:`ORACLE_REFERENCE_LABEL`."""
    if not comparison:
        return []
    rows = [dict(comparison["rows"][k], key=k) for k in COMPARE_ROWS if k in comparison["rows"]]
    oracle = comparison["rows"].get("oracle", {})
    for r in rows:
        if r["key"] == "oracle" and r.get("exact") is False:
            r["label"] = ORACLE_REFERENCE_LABEL
        r["gap"] = ""
        if r.get("status") != "done" or oracle.get("status") != "done":
            continue
        if r["key"] == "oracle":
            r["gap"] = "reference"
            continue
        dp, dc = r["priority"] - oracle["priority"], r["cycles"] - oracle["cycles"]
        parts = []
        if dp:
            pct = f" ({100 * dp / oracle['priority']:+.0f}%)" if oracle["priority"] else ""
            parts.append(f"{dp:+d} priority{pct}")
        if dc and comparison.get("scenario") == "multi_charge":
            parts.append(f"{dc:+d} cycle{'s' * (abs(dc) != 1)}")
        r["gap"] = ", ".join(parts) or "matches"
    return rows


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

    Outputs: ``plan`` (:func:`~uam_studio.planning.planner.plan_mission`'s result as a dict), ``plan_request``
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
    band = param.Dict(default=None, allow_None=True, doc="the Dynaformer's voltage band of the plan "
                                                          "(prediction_band), None without one")
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

    INPUTS = ("mission_name", "destinations", "vertiport_x_km", "vertiport_y_km", "return_wind", "scenario",
              "q_max", "r0", "eod_v", "policy")

    def __init__(self, mission: Mission | dict | None = None, background: bool = False,
                 dispatch: Callable[[Callable[[], None]], None] | None = None, auto: bool = True,
                 compare: str = "off", **params: Any) -> None:
        """
        :param mission: the starting mission (default :data:`EXAMPLE_MISSION`).
        :param background: replan in the shared thread pool (served app) instead of in place.
        :param dispatch: how a finished background plan is handed back to the session's thread
            (default: applied in the worker thread; the served app passes a next-tick dispatcher).
        :param auto: replan on every accepted change (False: call :meth:`replan` yourself).
        :param compare: where the plan comparison (:attr:`comparison`) is computed: ``"process"`` or
            ``"thread"`` (:func:`comparison_runner`, :data:`COMPARE_DELAY_S` after the shown plan
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
        if "policy" not in params:
            self.policy = default_policy(self.scenario)
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
                                                 f"{MAX_DESTINATIONS}); add another before removing the last one")
            if n > MAX_DESTINATIONS:
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
            self.policy = default_policy(self.scenario)

    def policy_label(self, value: str) -> str:
        """The policy select's label of a policy value (``"dqn"`` -> ``"DQN (paper, up to 8)"``, an
        ``agent:<path>`` -> ``"Retrained: <file> (<scenario>)"``)."""
        for label, v in self.policy_objects.items():
            if v == value:
                return label
        if value.startswith(AGENT_PREFIX):
            return f"Retrained: {Path(value[len(AGENT_PREFIX):]).stem}"
        return value

    def plan_label(self) -> str:
        """Which planner made the shown plan: its policy label, and for the oracle whether the plan is
        proven optimal (``exact``: up to 8 destinations) or the reference solver's (9-20); '' before
        the first plan."""
        req, plan = self.plan_request, self.plan
        if req is None:
            return ""
        label = self.policy_label(req.policy)
        if plan is not None and req.policy == "oracle" and plan.get("exact") is not None:
            label = ("Oracle (exact optimum)" if plan["exact"]
                     else "Oracle: the reference solver's plan (OR-Tools), not proven optimal")
        return label

    def verdict(self) -> dict[str, Any]:
        """:func:`safety_verdict` of the shown plan."""
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
        with self._done:
            self._done.notify_all()
        if latest:
            self._update_comparison()

    # ------------------------------------------------------------------ comparison

    def _compare_specs(self, req: PlanRequest) -> dict[str, tuple[str, str]]:
        """Row name -> (policy value, label): the agent (the selected learned planner: the attention
        planner, the paper's DQN or a retrained agent; with greedy or the oracle selected, the
        default learned planner), greedy and the oracle."""
        from uam_studio.planning.solvers.oracle import EXACT_MAX

        if req.policy in LEARNED_POLICIES or req.policy.startswith(AGENT_PREFIX):
            agent = req.policy
        else:
            agent = default_policy(req.mission.scenario)
            agent = agent if agent in LEARNED_POLICIES else "attention"
        oracle = "Oracle (exact)" if len(req.mission.destinations) <= EXACT_MAX else ORACLE_REFERENCE_LABEL
        label = COMPARE_LABELS.get(agent) or self.policy_label(agent)
        return {"agent": (agent, label), "greedy": ("greedy", "Greedy"), "oracle": ("oracle", oracle)}

    def _update_comparison(self) -> None:
        """Compare the shown plan's mission across planners: rows known to this process at once, the
        others computed as :attr:`compare` says (their rows stay ``pending`` until then)."""
        req = self.plan_request
        if self.compare == "off" or req is None:
            return
        specs = self._compare_specs(req)
        key = (req.mission, specs["agent"][0])
        if key == self._compare_key:
            return  # e.g. only the policy changed between greedy and the oracle: same rows
        self._stop_comparison()
        self._compare_key = key
        rows: dict[str, dict[str, Any]] = {}
        missing = []
        for name, (value, label) in specs.items():
            preq = PlanRequest(req.mission, value)
            row = cached_row(preq)
            rows[name] = {"label": label, "policy": value, **(row or {"status": "pending", "error": None})}
            if row is None:
                missing.append((name, preq))
        self.comparison = {"scenario": req.mission.scenario, "inputs": mission_digest(req.mission),
                           "rows": rows}
        if not missing:
            return
        if self.compare == "inline":
            for name, preq in missing:
                row = compare_row(preq.mission, preq.policy)
                store_row(preq, row)
                self._comparison_result(key, name, row)
            return
        tasks = [(preq, functools.partial(self._on_row, key, name)) for name, preq in missing]
        runner = comparison_runner(self.compare)
        timer = threading.Timer(COMPARE_DELAY_S, runner.submit, args=(id(self), tasks))
        timer.daemon = True
        self._compare_timer = timer
        timer.start()

    def _stop_comparison(self) -> None:
        if self._compare_timer is not None:
            self._compare_timer.cancel()
            self._compare_timer = None
        if self.compare in ("process", "thread") and self.compare in _RUNNERS:
            _RUNNERS[self.compare].cancel(id(self))

    def _on_row(self, key: tuple, name: str, row: dict[str, Any]) -> None:
        self.dispatch(functools.partial(self._comparison_result, key, name, row))

    def _comparison_result(self, key: tuple, name: str, row: dict[str, Any]) -> None:
        if key != self._compare_key or self.comparison is None:
            return  # the mission changed meanwhile
        rows = dict(self.comparison["rows"])
        rows[name] = {**rows[name], **row}
        self.comparison = {**self.comparison, "rows": rows}

    def comparison_pending(self) -> bool:
        """Some comparison row is still being computed."""
        c = self.comparison
        return c is not None and any(r.get("status") == "pending" for r in c["rows"].values())

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


LEARNED_POLICIES = ("attention", "dqn")


def _bundled_exists(scenario: str) -> bool:
    from uam_studio.planning.agents.rollout import bundled_agent_path

    return bundled_agent_path(scenario).is_file()


def _attention_exists() -> bool:
    from uam_studio.bundled import bundled_path

    return bundled_path(WEIGHTS_NAME).is_file()


def default_policy(scenario: str) -> str:
    """The app's default planner: the bundled attention planner (1-20 destinations) where its weights
    are installed, else the scenario's bundled DQN agent, else greedy."""
    if _attention_exists():
        return "attention"
    return "dqn" if _bundled_exists(scenario) else "greedy"


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
    Every input change recomputes :attr:`result` (:meth:`refresh`): at once, or (``background``) in
    the shared thread pool with :attr:`busy` set meanwhile and only the newest request kept.
    """

    q_max = param.Number(default=7600.0, bounds=APP_Q_RANGE, doc="q_max (C)")
    r0 = param.Number(default=0.117215, bounds=APP_R0_RANGE, doc="R0 (ohm)")
    altitude_m = param.Number(default=1000.0, bounds=ALTITUDE_RANGE_M)
    wind_kts = param.Number(default=0.0, bounds=WIND_RANGE_KTS)
    distance_km = param.Number(default=55.6, bounds=(10.0, 150.0), doc="leg length (km); 30 nm = 55.6 km")
    legs = param.Integer(default=3, bounds=(1, 10), doc="legs flown back to back (no recharge)")
    eod_v = param.Number(default=3.0, bounds=APP_EOD_RANGE)
    vary = param.Selector(default="altitude", objects=list(VARY))

    result = param.Dict(default=None, allow_None=True, doc=":meth:`curves` of the current inputs")
    busy = param.Boolean(default=False, doc="a newer result is being computed")

    INPUTS = ("q_max", "r0", "altitude_m", "wind_kts", "distance_km", "legs", "eod_v", "vary")
    MAX_POINTS = 1500  # samples per drawn series (every EOD time and minimum is computed at 1 s)

    def __init__(self, background: bool = False, dispatch: Callable[[Callable[[], None]], None] | None = None,
                 **params: Any) -> None:
        """
        :param background: compute in the shared thread pool (served app) instead of in place.
        :param dispatch: how a result computed in the pool is handed back to the session's thread.
        """
        super().__init__(**params)
        self.background = background
        self.dispatch = dispatch or (lambda cb: cb())
        self._lock = threading.Lock()
        self._seq = 0
        self._running = False
        self.param.watch(lambda *_: self.refresh(), list(self.INPUTS))
        self.refresh()

    def refresh(self) -> None:
        """Recompute :attr:`result` for the current inputs."""
        if not self.background:
            self.result = self.curves()
            return
        with self._lock:
            self._seq += 1
            start = not self._running
            self._running = True
        if not self.busy:
            self.busy = True
        if start:
            _POOL.submit(self._work)

    def _work(self) -> None:
        while True:
            with self._lock:
                seq = self._seq
            try:
                res = self.curves()
            except Exception as err:  # curves() reports input errors itself; belt and braces
                traceback.print_exc()
                res = {"error": f"battery lab failed: {_one_line(err)}"}
            with self._lock:
                if seq != self._seq:
                    continue  # inputs changed meanwhile: compute the newest
                self._running = False
            self.dispatch(functools.partial(self._apply, seq, res))
            return

    def _apply(self, seq: int, res: dict[str, Any]) -> None:
        with self._lock:
            latest = seq == self._seq
        self.param.update(result=res, **({"busy": False} if latest else {}))

    def _setting(self, **override: float) -> dict[str, float]:
        s = {k: float(getattr(self, k)) for k in ("q_max", "r0", "altitude_m", "wind_kts")}
        s.update(override)
        return s

    def curves(self) -> dict[str, Any]:
        """``{"setting": [curve], "family": [curve...], "factor", "unit", "error", "skipped", "t_end_s",
        "eod_v"}``.

        The family is in the factor's order (ascending); ``t_end_s`` is the end of the longest
        current profile, one time range for every plot. Each curve is ``{"label", "value", "time_s",
        "current_a", "voltage_time_s", "voltage_v", "eod_s", "min_voltage_v"}``: the current over
        the whole flight, the voltage up to and including the first sample below the cut-off, both
        thinned to at most :data:`MAX_POINTS` samples; ``eod_s`` is None where the cut-off is never
        reached and ``min_voltage_v`` the lowest voltage (every sample).
        """
        key, values, unit = VARY[self.vary]
        out: dict[str, Any] = {"factor": self.vary, "unit": unit, "setting": [], "family": [], "error": "",
                               "skipped": [], "t_end_s": 0.0, "eod_v": float(self.eod_v)}
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
        out["t_end_s"] = max(float(c["time_s"][-1]) for c in out["setting"] + out["family"])
        return out

    def _curve(self, s: dict[str, float], label: str) -> dict[str, Any]:
        from uam_studio.battery import simulate
        from uam_studio.flight import leg_profile

        prof = leg_profile(float(self.distance_km), s["altitude_m"], s["wind_kts"])
        cur = np.tile(np.asarray(prof.current_a), int(self.legs))
        sim = simulate(cur, prof.dt_s, s["q_max"], s["r0"], eod_v=float(self.eod_v))
        t = np.asarray(sim.time_s, dtype=float)
        v = np.asarray(sim.voltage_v, dtype=float)
        n = min(int(np.count_nonzero(sim.valid)) + 1, v.size)  # the first sample below the cut-off too
        eod = float(sim.eod_s)
        it = _thin_index(t.size, self.MAX_POINTS)
        iv = _thin_index(n, self.MAX_POINTS, keep=int(np.argmin(v[:n])))
        return {"label": label, "value": s, "time_s": t[it], "current_a": cur[it],
                "voltage_time_s": t[iv], "voltage_v": v[iv], "eod_s": eod if math.isfinite(eod) else None,
                "min_voltage_v": float(v[:n].min())}


def _clock(seconds: float) -> str:
    """``m:ss`` (``h:mm:ss`` from an hour)."""
    t = int(round(seconds))
    h, rest = divmod(t, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60}:{rest % 60:02d}"


def _replace_scenario(mission: Mission, scenario: str) -> Mission:
    import dataclasses

    return dataclasses.replace(mission, scenario=scenario)


def _thin_index(n: int, limit: int, keep: int | None = None) -> np.ndarray:
    """At most about ``limit`` indices of ``n`` samples, evenly spread, with the first, the last and ``keep``."""
    if n <= limit:
        return np.arange(n)
    idx = np.linspace(0, n - 1, limit).round().astype(int)
    return np.unique(np.append(idx, np.asarray([] if keep is None else [keep], dtype=int)))


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
    reference = param.Dict(default=None, allow_None=True,
                           doc="the exact oracle's plan of the map (compare_row, plus 'label' and 'cell'), the "
                               "learning curves' reference; None for random missions or until computed")
    runner = param.Selector(default="process", objects=["process", "thread"],
                            doc="train in a child process (default; $UAM_STUDIO_RETRAIN_RUNNER overrides) "
                                "or in a thread of this process")

    MA_WINDOW = 50

    def __init__(self, dispatch: Callable[[Callable[[], None]], None] | None = None, compare: str = "off",
                 **params: Any) -> None:
        """
        :param dispatch: how a result computed elsewhere (the oracle reference) is handed back to the
            session's thread (default: applied in the computing thread).
        :param compare: where the oracle reference is computed (see :class:`PlannerState`'s ``compare``).
        """
        env = os.environ.get(RUNNER_ENV, "").strip()
        if "runner" not in params and env in ("process", "thread"):
            params["runner"] = env
        super().__init__(**params)
        if compare not in COMPARE_MODES:
            raise InputError("compare", f"{compare!r}: allowed {', '.join(COMPARE_MODES)}")
        self.dispatch = dispatch or (lambda cb: cb())
        self.compare = compare
        self._reference_req: PlanRequest | None = None
        self._t_start: float | None = None
        self._t_end: float | None = None
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
        self._t_start, self._t_end = time.monotonic(), None
        self.request_reference(mission)
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

    @property
    def elapsed_s(self) -> float:
        """Seconds since the run started (until it ended), 0 before any run."""
        if self._t_start is None:
            return 0.0
        return (self._t_end if self._t_end is not None else time.monotonic()) - self._t_start

    def progress_text(self) -> str:
        """Steps done of the total, percent, elapsed time and (while running) the time left at the
        pace so far, e.g. ``"1200 of 5000 steps (24%) · 0:12 elapsed · about 0:38 left"``."""
        if not self._target_steps:
            return "not started"
        p = self.progress
        text = f"{self.timesteps} of {self._target_steps} steps ({100 * p:.0f}%) \u00b7 {_clock(self.elapsed_s)} elapsed"
        if self.running:
            eta = self.elapsed_s * (1 - p) / p if p > 0 else None
            text += f" \u00b7 about {_clock(eta)} left" if eta is not None else " \u00b7 time left: after the first episodes"
        return text

    def request_reference(self, mission: Mission | None) -> None:
        """Compute the learning curves' reference for ``mission`` with this run's scenario: the exact
        oracle's plan (:func:`compare_row`; at once if this process has it), or none (``mission``
        None: random missions)."""
        if mission is None or self.source != "map" or self.compare == "off":
            self._reference_req = None
            self.reference = None
            return
        m = mission if mission.scenario == self.scenario else _replace_scenario(mission, self.scenario)
        req = PlanRequest(m, "oracle")
        if req == self._reference_req:
            return
        self._reference_req = req
        extra = {"label": "exact oracle (this map)", "cell": f"q_max {m.battery.q_max:g} C, R0 {m.battery.r0:.3g} ohm"}
        row = cached_row(req)
        if row is None and self.compare == "inline":
            row = compare_row(m, "oracle")
            store_row(req, row)
        if row is not None:
            self.reference = {**row, **extra}
            return
        self.reference = None

        def done(row: dict[str, Any]) -> None:
            self.dispatch(lambda: self._reference_result(req, {**row, **extra}))

        comparison_runner(self.compare).submit(("retrain", id(self)), [(req, done)])

    def _reference_result(self, req: PlanRequest, row: dict[str, Any]) -> None:
        if req == self._reference_req:
            self.reference = row

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
            self._t_end = time.monotonic()
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

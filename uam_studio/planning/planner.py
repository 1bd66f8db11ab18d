"""One entry point for planning a mission with any policy: :func:`plan_mission`.

The CLI (``uam-studio plan``) and the Panel app call only this function. It

1. runs the chosen planner: ``"attention"`` (the default: the bundled attention network with beam
   search behind the physics safety filter, any map of 1-20 destinations,
   :func:`~uam_studio.planning.agents.attention.decode.attention_plan`), ``"oracle"``
   (:func:`~uam_studio.planning.solvers.oracle.oracle_plan`: exact up to 8 destinations, an OR-Tools reference plan for
   9-20, ``exact`` in the result says which),
   ``"greedy"`` (baseline, :func:`~uam_studio.planning.solvers.greedy.greedy_plan`) or ``"dqn"`` (a trained
   masked DQN agent rolled out greedily in a :class:`~uam_studio.planning.env.UAMPlanningEnv` built
   on this mission with the physics battery);
2. re-checks the route with the physics model (:func:`~uam_studio.planning.missions.check.check_plan`):
   ``reached``, ``charging_cycles``, ``safe`` and ``min_voltage_v`` always come from this check,
   whoever planned the route;
3. predicts the route's voltage with the Dynaformer, sortie by sortie (context: the first 20 s of
   the take-off as the physics model flies it for this cell; profile: the route's current since the
   last recharge), and concatenates the sorties.

The result is a typed :class:`PlanResult` (``to_dict()`` is its plain-JSON form). Hard missions (no destinations, more
than 20, unreachable destinations, a cell that cannot finish the take-off) and a missing Dynaformer
give messages, never exceptions; bad input (an invalid mission, an unknown policy, out-of-range
``q_max``/``r0``, an explicit ``agent_path`` that cannot be loaded, more than 8 destinations for
``dqn``) and a missing bundled agent
(``dqn`` without ``agent_path``, :func:`~uam_studio.planning.agents.dqn.rollout.bundled_agent_path`) raise
:class:`~uam_studio.errors.InputError`.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields
from typing import Any, cast

import numpy as np

from uam_studio.bundled import require_bundled
from uam_studio.errors import InputError, check_range
from uam_studio.planning.env import observe_takeoff
from uam_studio.planning.missions.check import Plan, PlanCheck, check_plan
from uam_studio.planning.missions.mission import SCENARIOS, Mission, as_mission
from uam_studio.planning.planners import LEARNED_POLICIES, PLANNERS, POLICIES, planner_info
from uam_studio.planning.voltage_predictor import BandPredictor, HealthFittingPredictor, VoltagePredictor

MAX_POINTS = 2000  # samples per series in the result (JSON size)
DECIMALS = 4

__all__ = ["MAX_POINTS", "POLICIES", "PlanResult", "plan_mission"]


# ----------------------------------------------------------------------------- helpers


def _round_list(a: np.ndarray) -> list[float]:
    a = np.nan_to_num(np.asarray(a, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
    return [float(x) for x in np.round(a, DECIMALS)]


def _round_opt(x: float | None) -> float | None:
    return None if x is None else round(float(x), DECIMALS)


def _sample_index(n: int, keep: list[int]) -> np.ndarray:
    """At most ``MAX_POINTS`` indices of ``n`` samples, evenly spread, always with the first, last and ``keep``."""
    if n <= MAX_POINTS:
        return np.arange(n)
    base = np.linspace(0, n - 1, MAX_POINTS - len(keep)).round().astype(int)
    return np.unique(np.concatenate([base, np.asarray(keep, dtype=int)]))


def _dedupe(messages: list[str]) -> list[str]:
    out: list[str] = []
    for m in messages:
        if m and m not in out:
            out.append(m)
    return out


# ----------------------------------------------------------------------------- Dynaformer prediction


def _load_predictor(predictor: VoltagePredictor | bool | None, messages: list[str]) -> VoltagePredictor | None:
    if predictor is False:
        return None
    if predictor is not None:
        if not isinstance(predictor, VoltagePredictor):
            raise InputError("predictor", "expected an object with predict(context_current_a, context_voltage_v, "
                                          "current_a, dt_s), None for the bundled Dynaformer, or False")
        return predictor
    try:
        from uam_studio.dynaformer import WeightsError, load_pretrained
    except ImportError as err:  # torch missing
        messages.append(f"Dynaformer unavailable ({err}); showing the physics model only")
        return None
    try:
        # DynaformerPredictor.predict names its keywords, where the protocol's takes **kwargs
        return cast(VoltagePredictor, load_pretrained())
    except WeightsError as err:
        messages.append(f"no Dynaformer weights ({err}); showing the physics model only")
        return None


def _predict(check: PlanCheck, predictor: VoltagePredictor, messages: list[str], band_level: float | None
             ) -> tuple[np.ndarray | None, tuple[np.ndarray, np.ndarray] | None]:
    """Dynaformer voltage (V) on the physics route's time grid, sortie by sortie (each from a full
    charge, read from the take-off's first 20 s on the physics model), or None; with ``band_level``,
    also its pointwise band (low, high V) at that coverage from the predictor's ``voltage_band``
    (None where it has none or fails: a message)."""
    sim = check.sim
    assert sim is not None
    ci, cv = observe_takeoff(sim.q_max, sim.r0)  # the take-off context
    cuts = sim.sortie_cuts()
    parts, lows, highs = [], [], []
    band_fn = predictor.voltage_band if band_level is not None and isinstance(predictor, BandPredictor) else None
    try:  # every sortie reads the same take-off: its health is fitted once, for the prediction and the band
        kw = ({"estimate": predictor.health_estimate(ci, cv, dt_s=sim.dt_s)}
              if isinstance(predictor, HealthFittingPredictor) else {})
        for a, b in zip(cuts[:-1], cuts[1:]):
            v = np.asarray(predictor.predict(ci, cv, sim.current_a[a:b], dt_s=sim.dt_s, **kw), dtype=float)
            parts.append(v.reshape(-1)[: b - a])
    except (InputError, ValueError, RuntimeError) as err:
        messages.append(f"Dynaformer prediction failed ({' '.join(str(err).split())}); "
                        "showing the physics model only")
        return None, None
    band = None
    if band_fn is not None:
        assert band_level is not None  # band_fn is only set with a band_level
        try:
            for a, b in zip(cuts[:-1], cuts[1:]):
                lo, _, hi = band_fn(ci, cv, sim.current_a[a:b], dt_s=sim.dt_s, level=band_level, **kw)
                lows.append(np.asarray(lo, dtype=float).reshape(-1)[: b - a])
                highs.append(np.asarray(hi, dtype=float).reshape(-1)[: b - a])
            band = (np.concatenate(lows), np.concatenate(highs)) if lows else None
        except Exception as err:  # the band is an extra: the plan and its prediction stand without it
            messages.append(f"Dynaformer band unavailable ({type(err).__name__}: {' '.join(str(err).split())})")
    return (np.concatenate(parts) if parts else np.zeros(0)), band


# ----------------------------------------------------------------------------- result


@dataclass(frozen=True)
class PlanResult(Mapping[str, Any]):
    """What :func:`plan_mission` returns: a plan checked on the physics model, with the Dynaformer's
    prediction. Read its fields (``res.route``); it also reads as a read-only mapping of the same
    names (``res["route"]``), and :meth:`to_dict` gives the plain-JSON dict the CLI prints.

    :param policy: who planned it.
    :param route: node names after the start at the vertiport (``"vertiport"`` = a landing that recharges).
    :param altitudes_m: cruise altitude (m) of each leg.
    :param charging_cycles: landings at the vertiport.
    :param reached: destinations reached on the physics model, in order.
    :param reached_priority: their total priority.
    :param predicted: the Dynaformer's voltage, ``{"time_s", "voltage_v"}`` (s, V), or None.
    :param band: the Dynaformer's pointwise voltage band, ``{"time_s", "low_v", "high_v", "level",
        "min_low_v", "min_high_v"}`` (s, V, coverage 0-1, V over every sample), or None.
    :param physics: the physics model's voltage, ``{"time_s", "voltage_v", "eod_s", "leg_start_s"}``
        (s, V, s or None, and the take-off time (s) of each leg that took off, in flying order).
    :param safe: the route stays at or above the cut-off.
    :param min_voltage_v: its lowest voltage (V), None for an empty route.
    :param exact: oracle: True for a proven optimum, False for the reference solver's plan; None for
        the other policies.
    :param messages: one line each.
    """

    policy: str
    route: list[str]
    altitudes_m: list[float]
    charging_cycles: int
    reached: list[str]
    reached_priority: int
    predicted: dict[str, Any] | None
    physics: dict[str, Any]
    safe: bool
    min_voltage_v: float | None
    exact: bool | None
    messages: list[str]
    band: dict[str, Any] | None = None

    def __getitem__(self, key: str) -> Any:
        if key not in _RESULT_FIELDS:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(_RESULT_FIELDS)

    def __len__(self) -> int:
        return len(_RESULT_FIELDS)

    def to_dict(self) -> dict[str, Any]:
        """The plain-JSON dict of the fields (series as lists)."""
        return {name: getattr(self, name) for name in _RESULT_FIELDS}


_RESULT_FIELDS = tuple(f.name for f in fields(PlanResult))
BAND_LEVEL = 0.9  # default coverage of the Dynaformer's voltage band along a plan

PLAN_CSV_COLUMNS = ("time_s", "leg", "to", "altitude_m", "physics_voltage_v", "dynaformer_voltage_v")


def plan_csv(plan: Mapping[str, Any]) -> str:
    """A plan's voltage series as CSV text (a :class:`PlanResult` or its :meth:`~PlanResult.to_dict`):
    time (s), the leg flown then (number, destination, altitude m), the physics model's voltage (V)
    and the Dynaformer's (V, empty without a prediction)."""
    phys = plan["physics"]
    pred = (plan.get("predicted") or {}).get("voltage_v") or []
    starts = list(phys.get("leg_start_s", []))
    route, alts = list(plan["route"]), list(plan["altitudes_m"])
    lines = [",".join(PLAN_CSV_COLUMNS)]
    for i, (t, v) in enumerate(zip(phys["time_s"], phys["voltage_v"])):
        k = int(np.searchsorted(starts, t, side="right"))  # legs that took off by t
        leg = (str(k), route[k - 1], f"{alts[k - 1]:g}") if 0 < k <= len(route) else ("", "", "")
        p = f"{pred[i]:.4f}" if i < len(pred) else ""
        lines.append(",".join((f"{t:g}", *leg, f"{v:.4f}", p)))
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- entry point


def plan_mission(
    mission: Mission | dict | str | os.PathLike[str],
    policy: str = "attention",
    q_max: float | None = None,
    r0: float | None = None,
    agent_path: str | os.PathLike[str] | None = None,
    predictor: VoltagePredictor | bool | None = None,
    lookahead: int = 0,
    band_level: float | None = BAND_LEVEL,
) -> PlanResult:
    """Plan ``mission`` with ``policy``, check it with the physics model, predict it with the Dynaformer.

    :param mission: a :class:`Mission`, a dict in the mission JSON format, or a path to a mission file.
    :param policy: ``"attention"`` (default), ``"dqn"`` (the paper's agent), ``"oracle"`` or ``"greedy"``.
    :param q_max: override the mission's q_max (C).
    :param r0: override the mission's r0 (ohm).
    :param agent_path: the agent: for ``"attention"`` a weights file (default: the bundled
        ``attention_planner.pt``), for ``"dqn"`` an agent zip (default: the bundled ``dqn_<scenario>.zip``,
        :func:`~uam_studio.planning.agents.dqn.rollout.bundled_agent_path`); a missing bundled agent raises InputError.
    :param predictor: a Dynaformer predictor (``predict(context_current_a, context_voltage_v, current_a,
        dt_s)``), None for the bundled one (its absence is a message), or False to skip the prediction.
    :param lookahead: dqn only: policy rollout over the agent's K best safe actions (and the greedy
        rule's action) per step, continued by the filtered agent and by the greedy rule
        (:func:`~uam_studio.planning.agents.dqn.rollout.rollout_agent`); 0 (default) for the filtered agent alone; 0-8.
    :param band_level: coverage (0.5-0.99) of the Dynaformer's voltage band along the route, computed
        in the same pass as the prediction (the predictor's ``voltage_band``); None for no band.
    :return: a :class:`PlanResult` (``to_dict()``: the plain-JSON form). Series are rounded to 4
        decimals and thinned to at most :data:`MAX_POINTS` samples (the lowest physics and predicted
        voltages are always kept).
    :raises InputError: bad input or a missing bundled agent (see the module docstring); never for a
        hard mission.
    """
    info = planner_info(policy)
    if isinstance(lookahead, bool) or not isinstance(lookahead, (int, np.integer)) or not 0 <= lookahead <= 8:
        raise InputError("lookahead", f"{lookahead!r} is out of range; allowed integers in [0, 8]")
    m = as_mission(mission)
    if q_max is not None or r0 is not None:
        m = m.with_battery(q_max, r0)
    if m.scenario not in SCENARIOS:  # pragma: no cover - Mission validates it
        raise InputError("scenario", f"{m.scenario!r} is not a scenario")
    if agent_path is None and info.learned:  # an install without it: an error, not an empty plan
        bundled = info.bundled_file(m.scenario)
        assert bundled is not None  # a learned policy has an agent file
        require_bundled(bundled, "agent", "agent",
                        "plan with the oracle or greedy policy, or give an agent file")
    if agent_path is not None and not info.learned:
        raise InputError("agent_path", f"only used with the {' and '.join(LEARNED_POLICIES)} policies (not {policy})")
    if lookahead and not info.lookahead:
        allowed = " and ".join(n for n, p in PLANNERS.items() if p.lookahead)
        raise InputError("lookahead", f"only used with the {allowed} policy (not {policy})")
    if band_level is not None:
        check_range("band_level", band_level, 0.5, 0.99)
    messages: list[str] = []

    pred_model = _load_predictor(predictor, messages)
    kwargs: dict[str, Any] = {}
    if info.learned:
        kwargs["agent_path"] = agent_path
    if info.reads_predictor:
        kwargs["predictor"] = pred_model
    if info.lookahead:
        kwargs["lookahead"] = int(lookahead)
    # the planner's answer, with its physics check where it made one
    plan = cast(Plan, info.plan_function()(m, **kwargs))
    route, alts = list(plan.route), list(plan.altitudes_m)
    messages.extend(plan.messages)
    exact = bool(plan.stats.get("exact", True)) if info.reports_exact else None

    check = plan.check if plan.check is not None else check_plan(m, route, alts)
    reached = list(check.sim.reached) if check.sim is not None else []
    if not check.safe:
        messages.append(check.message)
    prio = {d.name: d.priority for d in m.destinations}

    physics: dict[str, Any] = {"time_s": [], "voltage_v": [], "eod_s": None, "leg_start_s": []}
    predicted: dict[str, Any] | None = None
    band: dict[str, Any] | None = None
    if check.sim is not None:
        sim = check.sim
        v_pred, v_band = _predict(check, pred_model, messages, band_level) if pred_model is not None else (None, None)
        if v_pred is not None and v_pred.size != sim.voltage_v.size:
            messages.append(f"Dynaformer returned {v_pred.size} samples for {sim.voltage_v.size}; "
                            "showing the physics model only")
            v_pred, v_band = None, None
        keep = [int(np.argmin(sim.voltage_v))] + ([int(np.argmin(v_pred))] if v_pred is not None else [])
        idx = _sample_index(sim.time_s.size, keep)
        t = _round_list(sim.time_s[idx])
        physics = {"time_s": t, "voltage_v": _round_list(sim.voltage_v[idx]), "eod_s": _round_opt(sim.eod_s),
                   "leg_start_s": [round(float(leg.start_s), 1) for leg in sim.legs if leg.start_s is not None]}
        if v_pred is not None:
            predicted = {"time_s": list(t), "voltage_v": _round_list(v_pred[idx])}
        if v_band is not None and v_band[0].size == sim.voltage_v.size:
            assert band_level is not None  # a band is only made with a band_level
            low, high = v_band
            band = {"time_s": list(t), "low_v": _round_list(low[idx]), "high_v": _round_list(high[idx]),
                    "level": float(band_level), "min_low_v": float(low.min()), "min_high_v": float(high.min())}

    return PlanResult(
        policy=policy,
        route=[str(r) for r in route],
        altitudes_m=[float(a) for a in alts],
        charging_cycles=int(check.sim.charging_cycles) if check.sim is not None else 0,
        reached=reached,
        reached_priority=int(sum(prio[n] for n in reached)),
        predicted=predicted,
        physics=physics,
        safe=bool(check.safe),
        min_voltage_v=_round_opt(check.min_voltage_v),
        exact=exact,
        messages=_dedupe(messages),
        band=band,
    )

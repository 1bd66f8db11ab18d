"""The plans of all sessions: :class:`PlanRequest` (what a plan depends on) and :func:`compute_plan`
(the library's plan of a request, with the Dynaformer's band, the failed take-off and the cell's
health), cached for every session of the process.
"""

from __future__ import annotations

import collections
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uam_studio.app.services import agent_policy, health_estimate, one_line, predictor, predictor_or_error
from uam_studio.errors import InputError
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.planners import PLANNERS
from uam_studio.planning.safety import takeoff_attempt

__all__ = ["PLAN_CACHE_SIZE", "PlanRequest", "cached_plan", "compute_plan", "request_key"]

PLAN_CACHE_SIZE = 256  # plans kept for all sessions (compute_plan)


@dataclass(frozen=True)
class PlanRequest:
    """Everything a plan depends on (a snapshot, safe to hand to another thread)."""

    mission: Mission
    policy: str  # attention | dqn | oracle | greedy | agent:<path>


def _agent_stamp(req: PlanRequest) -> tuple[str, int, int] | None:
    """(path, mtime ns, size) of the agent file a learned plan uses (the bundled attention planner; a
    retrained DQN agent, or the bundled one for the mission's scenario), so a plan cached for another
    or an older file is never reused."""
    from uam_studio.bundled import bundled_path

    policy, agent_path = agent_policy(req.policy)
    bundled = PLANNERS[policy].bundled_file(req.mission.scenario) if policy in PLANNERS else None
    if agent_path is not None:
        path = Path(agent_path)
    elif bundled is not None:
        path = bundled_path(bundled)
    else:
        return None
    try:
        st = path.stat()
    except OSError:
        return str(path), -1, -1
    return str(path), st.st_mtime_ns, st.st_size


def request_key(req: PlanRequest) -> tuple:
    """The cache key of ``req``: the request and the stamp of the agent file it plans with."""
    return req, _agent_stamp(req)


_PLAN_CACHE: collections.OrderedDict[tuple, dict[str, Any]] = collections.OrderedDict()
_PLAN_CACHE_LOCK = threading.Lock()


def compute_plan(req: PlanRequest) -> dict[str, Any]:
    """Plan ``req`` with the library and estimate the cell's health. Never raises.

    Plans are deterministic in the request (mission, battery, cut-off, policy; a retrained agent's
    file stamp), so the last :data:`PLAN_CACHE_SIZE` results are shared by all sessions: a new
    session, an undo or a slider dragged back re-shows a plan at once. Unexpected failures
    ("planning failed: ...") are not cached.

    :return: ``{"plan": plan_mission's result as a dict (``PlanResult.to_dict()``) or None, "error":
        one line or None, "band": the Dynaformer's voltage band or None, "takeoff": the failed take-off
        or None, "health": (pc1, pc2) or None, "elapsed_s": float (s), "request": req, "cached": bool}``.
    """
    t0 = time.perf_counter()
    key = request_key(req)
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


def cached_plan(key: tuple) -> dict[str, Any] | None:
    """The cached :func:`compute_plan` result of a :func:`request_key`, or None; shared with the
    cache: read it, never change it."""
    with _PLAN_CACHE_LOCK:
        return _PLAN_CACHE.get(key)


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
    policy, agent_path = agent_policy(req.policy)
    try:
        out["plan"] = plan_mission(req.mission, policy, agent_path=agent_path,  # with the band, one pass
                                   predictor=pred if pred is not None else False).to_dict()  # JSON state
        if pred is None:
            out["plan"]["messages"].append(predictor_or_error()[1] or "no Dynaformer")
    except InputError as err:
        out["error"] = one_line(err)
    except Exception as err:  # never a traceback in the app; the server log keeps it
        traceback.print_exc()
        out["error"] = f"planning failed: {type(err).__name__}: {one_line(err)}"
    plan = out["plan"]
    out["band"], out["takeoff"] = (plan or {}).get("band"), None
    if plan is not None and not plan["route"]:
        try:
            out["takeoff"] = takeoff_attempt(req.mission)
        except Exception:  # the take-off trace is an extra: the plan stands without it
            traceback.print_exc()
    try:
        b = req.mission.battery
        out["health"] = health_estimate(float(b.q_max), float(b.r0))
    except Exception:  # the health view is optional
        traceback.print_exc()
    out["elapsed_s"] = time.perf_counter() - t0
    return out

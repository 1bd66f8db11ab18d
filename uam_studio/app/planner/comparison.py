"""The plan comparison: a mission planned by the agent, greedy and the oracle, apart from the plans.

- :func:`compare_row`: one planner's row (:func:`~uam_studio.planning.planner.plan_mission`, the
  CLI's call); :func:`cached_row` / :func:`store_row`: rows kept for all sessions, also read from
  the sessions' plan cache (:func:`~uam_studio.app.planner.plans.compute_plan`).
- :class:`ComparisonRunner` (:func:`comparison_runner`, one per mode and process): computes rows
  one at a time for all sessions, in a child process (the served app) or a thread.
- :func:`comparison_table`: the rows in display order with the gap to the oracle.
- :func:`compare_mode`: where this process computes comparisons.
"""

from __future__ import annotations

import collections
import multiprocessing
import os
import queue
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from uam_studio.app.planner.plans import PlanRequest, cached_plan, request_key
from uam_studio.app.services import agent_policy, one_line, predictor
from uam_studio.errors import InputError
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.planners import PAPER_PLANNER, PLANNERS, POLICIES, REFERENCE_PLANNER

if TYPE_CHECKING:
    from uam_studio.planning.planner import PlanResult

__all__ = [
    "COMPARE_DELAY_S",
    "COMPARE_LABELS",
    "COMPARE_MODES",
    "ORACLE_REFERENCE_LABEL",
    "ComparisonRunner",
    "cached_row",
    "cancel_comparisons",
    "compare_mode",
    "compare_row",
    "comparison_runner",
    "comparison_table",
    "prepare_worker",
    "store_row",
    "use_shared_workers",
]

COMPARE_ENV = "UAM_STUDIO_COMPARE"  # where comparison plans run: "process", "thread", "inline" or "off"
COMPARE_MODES = ("process", "thread", "inline", "off")
COMPARE_DELAY_S = 0.3  # a comparison starts once the shown plan has been stable this long (s; slider drags)
COMPARE_CACHE_SIZE = 512

COMPARE_ROWS = ("agent", "default", "paper", "greedy", "oracle")
DEFAULT_POLICY = POLICIES[0]  # the "default" row: the default planner, unless the agent row is it already
PAPER_POLICY = PAPER_PLANNER  # the "paper" row: the paper's method beside ours, unless the agent row is one already
COMPARE_LABELS = {DEFAULT_POLICY: "Attention (default)", PAPER_POLICY: "DQN (paper)"}
"""Short labels of the learned planners in the comparison table (its rows do not wrap)."""
ORACLE_REFERENCE_LABEL = "Oracle (reference)"
"""The comparison's oracle row where the oracle returned the reference solver's plan (9-20
destinations, not proven optimal)."""


def compare_mode(served: bool) -> str:
    """Where this process computes plan comparisons: ``$UAM_STUDIO_COMPARE`` if set to one of
    :data:`COMPARE_MODES`, else ``"process"`` for a server and ``"thread"`` elsewhere (Jupyter)."""
    env = os.environ.get(COMPARE_ENV, "").strip()
    return env if env in COMPARE_MODES else ("process" if served else "thread")


# ----------------------------------------------------------------------------- rows


def _row_from_plan(plan: PlanResult | dict[str, Any], mission: Mission) -> dict[str, Any]:
    """A comparison row from a :class:`~uam_studio.planning.planner.PlanResult` or its ``to_dict()``
    (the app's state keeps the dict)."""
    return {"status": "done", "error": None, "priority": int(plan["reached_priority"]),
            "reached": len(plan["reached"]), "of": len(mission.destinations),
            "cycles": int(plan["charging_cycles"]), "min_voltage_v": plan["min_voltage_v"],
            "safe": bool(plan["safe"]), "route": list(plan["route"]), "altitudes_m": list(plan["altitudes_m"]),
            "exact": plan["exact"]}


def _agent_reads_dynaformer(agent_path: str | None, scenario: str) -> bool:
    from uam_studio.planning.agents.dqn.rollout import bundled_agent_path, load_agent_cached

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
        "min_voltage_v", "safe", "route", "altitudes_m", "exact", "elapsed_s"}`` (V, m, s; ``exact``:
        the plan's, True or False for the oracle, None for the others).
    """
    from uam_studio.planning.planner import plan_mission

    t0 = time.perf_counter()
    name, agent_path = agent_policy(policy)
    try:
        pred: Any = False
        if PLANNERS[name].reads_predictor and _agent_reads_dynaformer(agent_path, mission.scenario):
            pred = predictor() or False
        row = _row_from_plan(plan_mission(mission, name, agent_path=agent_path, predictor=pred,
                                            band_level=None), mission)  # rows read no band
    except InputError as err:
        row = {"status": "error", "error": one_line(err)}
    except Exception as err:  # never a traceback in the app; the server log keeps it
        traceback.print_exc()
        row = {"status": "error", "error": f"planning failed: {type(err).__name__}: {one_line(err)}"}
    row["elapsed_s"] = time.perf_counter() - t0
    return row


_COMPARE_CACHE: collections.OrderedDict[tuple, dict[str, Any]] = collections.OrderedDict()
_COMPARE_CACHE_LOCK = threading.Lock()


def cached_row(req: PlanRequest) -> dict[str, Any] | None:
    """The comparison row of ``req`` if this process has it: computed for a comparison before, or
    from a plan the sessions computed (:func:`~uam_studio.app.planner.plans.compute_plan`'s cache; the same
    library call)."""
    key = request_key(req)
    with _COMPARE_CACHE_LOCK:
        row = _COMPARE_CACHE.get(key)
        if row is not None:
            _COMPARE_CACHE.move_to_end(key)
            return dict(row)
    res = cached_plan(key)
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
    key = request_key(req)
    with _COMPARE_CACHE_LOCK:
        _COMPARE_CACHE[key] = dict(row)
        while len(_COMPARE_CACHE) > COMPARE_CACHE_SIZE:
            _COMPARE_CACHE.popitem(last=False)


# ----------------------------------------------------------------------------- runner


def prepare_worker(nice: int) -> None:
    """A comparison process's start: ``nice`` lower CPU priority (where allowed) and one torch thread."""
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


def _runner_main(requests: Any, results: Any, parent_pid: int, nice: int) -> None:
    """The comparison child process: :func:`compare_row` for each request, until the parent is gone."""
    prepare_worker(nice)
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


_SHARED: tuple[Any, Any, int] | None = None  # (requests, this process's rows, its slot): use_shared_workers


def use_shared_workers(requests: Any, results: Any, slot: int) -> None:
    """This app process computes its comparisons in the front's shared workers
    (:class:`~uam_studio.app.planner.comparison_pool.SharedComparisons`): it sends ``(slot, mission,
    policy)`` on the pipe end ``requests`` and reads its rows from the pipe end ``results``, and starts no
    comparison process of its own."""
    global _SHARED
    _SHARED = (requests, results, slot)


@dataclass
class _Task:
    req: PlanRequest
    callback: Callable[[dict[str, Any]], None]


class ComparisonRunner:
    """Computes comparison rows one at a time for all sessions of a process, apart from their plans.

    ``mode="process"`` (the served app): in one ``spawn`` child process at a lower CPU priority
    (``nice``), with one torch thread, so that an exact oracle taking seconds shares neither the GIL
    nor a core's priority with the sessions' own replanning; behind a front (:func:`use_shared_workers`), in
    the front's shared workers instead of a child of its own. ``mode="thread"``: in a thread of this
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
        self._closed = False
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

    def close(self) -> None:
        """Stop for good (the server is stopping): drop every waiting task and start no child process
        again, so that none (with its queues' semaphores) starts while the process exits. A task already
        running ends with an error row once its child is gone; a task submitted later gets one at once;
        the child itself (a daemon) ends with this process."""
        with self._cv:
            self._closed = True
            self._pending.clear()
            self._cv.notify_all()

    def _ensure_process(self) -> None:
        if self._closed or _SHARED is not None or (self._proc is not None and self._proc.is_alive()):
            return

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
                    task.callback({"status": "error", "error": f"comparison failed: {one_line(err)}"})
                except Exception:
                    pass
            finally:
                with self._cv:
                    self.busy = False
                    self._cv.notify_all()

    def _run(self, req: PlanRequest) -> dict[str, Any]:
        if self.mode == "thread":
            return compare_row(req.mission, req.policy)
        with self._cv:
            if self._closed:
                return {"status": "error", "error": "comparison failed: the server is stopping"}
            self._ensure_process()
            proc, requests, results = self._proc, self._requests, self._results
        if _SHARED is not None:
            return self._run_shared(req, *_SHARED)
        requests.put((req.mission, req.policy))
        while True:
            try:
                return results.get(timeout=1.0)
            except queue.Empty:
                if not proc.is_alive():
                    return {"status": "error", "error": f"comparison failed: the worker process exited "
                                                        f"(code {proc.exitcode})"}

    @staticmethod
    def _run_shared(req: PlanRequest, requests: Any, results: Any, slot: int) -> dict[str, Any]:
        """One row from the front's shared workers (one request of this process in flight at a time, so
        the next row on ``results`` is its row)."""
        front = os.getppid()
        requests.send((slot, req.mission, req.policy))
        while not results.poll(1.0):
            if os.getppid() != front:
                return {"status": "error", "error": "comparison failed: the server is stopping"}
        row: dict[str, Any] = results.recv()
        return row

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until no task is waiting or running, at most ``timeout`` s (tests, benchmarks)."""
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


def close_comparisons() -> None:
    """Close every :class:`ComparisonRunner` this process has (:meth:`ComparisonRunner.close`): the
    server's last step, so that none starts a child process while the process exits."""
    with _RUNNERS_LOCK:
        runners = list(_RUNNERS.values())
    for runner in runners:
        runner.close()


def cancel_comparisons(mode: str, owner: Any) -> None:
    """Drop ``owner``'s waiting tasks in the runner of ``mode``, if this process has one (none is started)."""
    with _RUNNERS_LOCK:
        runner = _RUNNERS.get(mode)
    if runner is not None:
        runner.cancel(owner)


# ----------------------------------------------------------------------------- table


def comparison_table(comparison: dict[str, Any] | None) -> list[dict[str, Any]]:
    """The comparison's rows in display order, each with ``gap``: the difference to the oracle in
    the scenario's objective (priority reached; in multi charge also charging cycles), as text, ''
    while either is missing. Where the oracle's plan is the reference solver's (``exact`` False), its
    row is labelled :data:`ORACLE_REFERENCE_LABEL`."""
    if not comparison:
        return []
    rows = [dict(comparison["rows"][k], key=k) for k in COMPARE_ROWS if k in comparison["rows"]]
    oracle = comparison["rows"].get(REFERENCE_PLANNER, {})
    for r in rows:
        if r["key"] == REFERENCE_PLANNER and r.get("exact") is False:
            r["label"] = ORACLE_REFERENCE_LABEL
        r["gap"] = ""
        if r.get("status") != "done" or oracle.get("status") != "done":
            continue
        if r["key"] == REFERENCE_PLANNER:
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

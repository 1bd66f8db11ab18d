"""Process-wide services of the app, shared by every session and tab (no widgets, no plots).

- :data:`POOL`, the threads where background work runs (plans, battery-lab curves, flights), and
  :class:`LatestWorker`, one state's computation on it where the newest request wins.
- :data:`ACTIVITY` (:class:`PlanningActivity`): which sessions are planning, as an Event that
  retraining child processes watch to give way.
- :func:`predictor`, :func:`population`, :func:`health_estimate`: the bundled Dynaformer, the health
  population and a cell's health, loaded or computed once per process.
- :func:`registry` (:class:`AgentRegistry`): the retrained agents in the user folder;
  :func:`policy_options` and :func:`default_policy`: the planners a session can choose.
- :func:`one_line`: an error as one line, as every tab shows it.
- :data:`APP_Q_RANGE`, :data:`APP_R0_RANGE`, :data:`APP_EOD_RANGE`: the cell and cut-off ranges of
  the tabs' inputs.
"""

from __future__ import annotations

import functools
import multiprocessing
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import Executor, ThreadPoolExecutor
from typing import Any, Generic, TypeVar

import param

from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE
from uam_studio.planning.agents.attention import WEIGHTS_NAME
from uam_studio.planning.planners import LEARNED_POLICIES, PLANNERS, POLICIES

__all__ = [
    "ACTIVITY",
    "FLIGHT_POOL",
    "AGENT_PREFIX",
    "agent_policy",
    "APP_EOD_RANGE",
    "APP_Q_RANGE",
    "APP_R0_RANGE",
    "LEARNED_POLICIES",
    "POLICY_LABELS",
    "POOL",
    "AgentRegistry",
    "LatestWorker",
    "PlanningActivity",
    "default_policy",
    "health_estimate",
    "one_line",
    "policy_options",
    "population",
    "predictor",
    "registry",
]

APP_Q_RANGE = PAPER_Q_RANGE  # C: the tabs' q_max inputs span the paper's range
APP_R0_RANGE = PAPER_R0_RANGE  # ohm
APP_EOD_RANGE = (2.5, 3.5)  # V; the Dynaformer is trained down to 2.5 V
POPULATION_N = 300

POLICY_LABELS = {p.label: name for name, p in PLANNERS.items()}
AGENT_PREFIX = "agent:"  # policy value of a retrained agent: agent:<path>


def agent_policy(value: str) -> tuple[str, str | None]:
    """The library's ``(policy, agent_path)`` of a policy value: ``agent:<path>`` is a retrained DQN
    agent (``*.zip``) or attention planner (``*.pt``); any other value is a policy with its bundled agent."""
    if not value.startswith(AGENT_PREFIX):
        return value, None
    from uam_studio.planning.agents.retrain import agent_model

    path = value[len(AGENT_PREFIX):]
    return agent_model(path), path


def one_line(err: BaseException, limit: int | None = None) -> str:
    """``err``'s message on one line (its type's name if it has none), cut to ``limit`` characters."""
    return (" ".join(str(err).split()) or type(err).__name__)[:limit]


# ----------------------------------------------------------------------------- background work

POOL = ThreadPoolExecutor(max_workers=4, thread_name_prefix="uam-plan")
"""Background work of the served app: a few threads shared by all sessions, one job per
:class:`LatestWorker` (per session and tab) at a time."""

FLIGHT_POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="uam-fly")
"""The Fly tab's flights (seconds each): their own threads, so flights in some sessions never hold
the threads that plan for the others."""

Req = TypeVar("Req")
Res = TypeVar("Res")


def _call_now(callback: Callable[[], None]) -> None:
    callback()


class LatestWorker(Generic[Req, Res]):
    """A state's computation in the shared pool where the newest request wins.

    :meth:`submit` numbers a request and computes it in :data:`POOL`, one at a time: a request
    arriving while one is computed replaces any waiting one, so at most one computation per worker
    runs and only the newest request waits. When a computation ends and no newer request came in
    meanwhile, ``apply(result, latest)`` is handed to ``dispatch`` (the session's thread); a result
    older than one already applied is dropped, and ``latest`` says that no request was made since
    (the state clears its busy flag then). :meth:`run` computes and applies in the calling thread.

    :param compute: ``request -> result``; expected failures belong in the result. An exception is
        printed (the server log) and becomes ``on_error(request, err)``.
    :param apply: ``(result, latest) -> None``, called through ``dispatch``.
    :param on_error: the result of a computation that raised.
    :param dispatch: hands ``apply`` to the session's thread (default: called in the worker thread).
    :param pool: where to compute (default :data:`POOL`).
    """

    def __init__(self, compute: Callable[[Req], Res], apply: Callable[[Res, bool], None],
                 on_error: Callable[[Req, BaseException], Res],
                 dispatch: Callable[[Callable[[], None]], None] | None = None, pool: Executor | None = None) -> None:
        self._compute = compute
        self._apply = apply
        self._on_error = on_error
        self.dispatch = dispatch or _call_now
        self._pool = pool or POOL
        self._cv = threading.Condition()
        self._seq = 0  # requests numbered so far
        self._applied = 0  # the newest request whose result was applied
        self._latest: tuple[int, Req] | None = None
        self._running = False
        self._apply_lock = threading.RLock()

    @property
    def seq(self) -> int:
        """The number of the newest request (0 before any)."""
        return self._seq

    def submit(self, request: Req) -> int:
        """Compute ``request`` in the pool, replacing any waiting request. Returns its number."""
        with self._cv:
            self._seq += 1
            seq = self._seq
            self._latest = (seq, request)
            start = not self._running
            self._running = True
        if start:
            self._pool.submit(self._loop)
        return seq

    def run(self, request: Req) -> Res:
        """Compute ``request`` in this thread, apply the result here and return it (an exception of
        ``on_error`` or ``apply`` reaches the caller)."""
        with self._cv:
            self._seq += 1
            seq = self._seq
        try:
            res = self._compute(request)
        except Exception as err:
            traceback.print_exc()
            res = self._on_error(request, err)
        self._deliver(seq, res, background=False)
        return res

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the newest request's result is applied, at most ``timeout`` s (tests and
        benchmarks; not from the session's own thread when ``dispatch`` schedules on it)."""
        deadline = time.monotonic() + timeout
        with self._cv:
            while self._applied < self._seq:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(left)
        return True

    def _call(self, request: Req) -> Res | None:
        """``compute(request)``, or on an exception ``on_error(request, err)``; None (printed) if
        that raises too."""
        try:
            return self._compute(request)
        except BaseException as err:  # noqa: BLE001 - the loop must end with _running cleared
            traceback.print_exc()
            try:
                return self._on_error(request, err)
            except BaseException:  # noqa: BLE001
                traceback.print_exc()
                return None

    def _loop(self) -> None:
        handed_over = False  # _running cleared under the lock: a new loop may run from then on
        try:
            while True:
                with self._cv:
                    assert self._latest is not None
                    seq, request = self._latest
                res = self._call(request)
                with self._cv:
                    if self._latest is not None and self._latest[0] != seq:
                        continue  # a newer request came in meanwhile: compute that one instead
                    self._running = False
                    handed_over = True
                    if res is None:  # nothing to apply (on_error failed, printed): do not wait on it
                        self._applied = max(self._applied, seq)
                        self._cv.notify_all()
                if res is not None:
                    self.dispatch(functools.partial(self._deliver, seq, res))
                return
        except BaseException:  # noqa: BLE001 - printed: a pool future's exception is never read
            traceback.print_exc()
        finally:
            if not handed_over:
                with self._cv:
                    self._running = False
                    self._cv.notify_all()

    def _deliver(self, seq: int, res: Res, background: bool = True) -> None:
        # One result applied at a time, in order: where ``dispatch`` calls back in the worker thread
        # (no session), two loops may finish close together.
        with self._apply_lock:
            with self._cv:
                if seq < self._applied:
                    return
                latest = seq >= self._seq
            try:
                self._apply(res, latest)
            except BaseException:  # noqa: BLE001 - in the background a failed update is printed
                if not background:
                    raise
                traceback.print_exc()
            finally:
                with self._cv:
                    self._applied = max(self._applied, seq)
                    self._cv.notify_all()


class PlanningActivity:
    """Which sessions are planning right now, as a ``multiprocessing`` Event that retraining child
    processes watch: while any session plans (from the request to the views updated, plus
    :attr:`grace_s` for the server to send the changes and the browser to draw them), they pause
    between episodes (:class:`~uam_studio.planning.agents.retrain.RetrainProcess`)."""

    def __init__(self, grace_s: float = 1.0) -> None:
        """:param grace_s: how long (s) the Event stays set after the last session stopped planning."""
        self.grace_s = grace_s
        self._lock = threading.Lock()
        self._active: set[int] = set()
        self._event: Any = None
        self._timer: threading.Timer | None = None

    @property
    def event(self) -> Any:
        """The ``multiprocessing`` Event (``spawn`` context), created on first use."""
        with self._lock:
            if self._event is None:
                self._event = multiprocessing.get_context("spawn").Event()
                if self._active:
                    self._event.set()
            return self._event

    def mark(self, key: int, active: bool) -> None:
        """Mark the session ``key`` as planning (``active``) or not."""
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


# ----------------------------------------------------------------------------- Dynaformer, cached


@functools.lru_cache(maxsize=1)
def predictor_or_error() -> tuple[Any, str | None]:
    """``(the bundled Dynaformer, None)``, or ``(None, why it cannot be loaded)``; loaded once per process."""
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
    return predictor_or_error()[0]


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
    """The Dynaformer's (PC1, PC2) of a cell (q_max C, r0 ohm) from the first 20 s of its take-off
    on the physics model (:func:`~uam_studio.planning.env.takeoff_health`), None without a Dynaformer."""
    from uam_studio.planning.env import takeoff_health

    p = predictor()
    if p is None:
        return None
    return takeoff_health(p, q_max, r0)


# ----------------------------------------------------------------------------- agents and policies


class AgentRegistry(param.Parameterized):
    """Retrained agents in the user folder (:func:`uam_studio.planning.agents.retrain.agents_dir`), newest first.

    One instance per process (:func:`registry`); sessions watch :attr:`agents`.
    """

    agents = param.List(default=[], doc="AgentInfo of each agent found")

    def refresh(self) -> None:
        """Scan the agents folder again (``agents`` changes only if an agent was added, removed or rewritten)."""
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
        opts = {(f"{k.split(' (')[0]} (not installed)" if v == POLICIES[0] else k): v for k, v in opts.items()}
    for a in agents:
        opts[f"Retrained: {a.label}"] = f"{AGENT_PREFIX}{a.path}"
    return opts


def _bundled_exists(scenario: str) -> bool:
    from uam_studio.planning.agents.dqn.rollout import bundled_agent_path

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

"""Gymnasium environment of the paper's health-aware eVTOL mission planning (DQN training).

See :class:`UAMPlanningEnv` for the spaces, rewards and episode rules; its battery backends
(:class:`PhysicsBattery` / :class:`DynaformerBattery`) and the take-off health observation live in
:mod:`~uam_studio.planning.env.backends`, its queries that leave the episode unchanged (safety look-ahead,
greedy action, clone, plan, rendering) in :mod:`~uam_studio.planning.env.queries`.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from uam_studio.battery import rest_voltage
from uam_studio.errors import InputError, check_positive, check_range
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.env.backends import (
    CONTEXT_S,
    HEALTH_CLIP,
    BatteryBackend,
    DynaformerBattery,
    LegOutcome,
    PhysicsBattery,
    fallback_health,
    observe_takeoff,
    takeoff_context_current,
)
from uam_studio.planning.env.observation import (
    FEATURE_BOUND,
    FEATURE_NAMES,
    N_FEATURES,
    OBS_DIM,
    observe,
    static_features,
)
from uam_studio.planning.env.queries import EpisodeQueries
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import (
    ALTITUDES_M,
    DT_S,
    MIN_LEG_KM,
    N_ACTIONS,
    N_ALTITUDES,
    N_MAX,
    VERTIPORT_SLOT,
    LegTable,
)
from uam_studio.planning.missions.generate import (
    DEFAULT_Q_RANGE,
    DEFAULT_R0_RANGE,
    DEFAULT_RADIUS_KM,
    random_mission,
)
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO, check_scenario

MAX_EPISODE_STEPS = 2 * N_MAX + 2
REWARD_DEFAULTS = {"alpha": 1.0, "beta": 1.0, "gamma": 5.0}  # the paper's figures; the one home of these

# ----------------------------------------------------------------------------- environment


class UAMPlanningEnv(EpisodeQueries, gym.Env):
    """Health-aware eVTOL mission planning: pick the next node and the cruise altitude.

    An aircraft with one (equivalent) 18650 cell starts fully charged at the vertiport and serves
    up to ``N_MAX = 8`` destinations (priority 1-3). Each step flies one leg through the flight
    model and the battery backend (physics ground truth or the Dynaformer).

    ## Action space

    ``Discrete(36)``: ``a = target * 4 + altitude_index``; ``target`` 0-7 is a destination slot
    (``mission.destinations[target]``), 8 the vertiport; the altitude is
    ``ALTITUDES_M[altitude_index]`` = 500, 1000, 2000, 3000 m (:mod:`uam_studio.planning.legs`).
    An invalid action (see the mask) ends the episode with reward ``-gamma`` and
    ``info["invalid_action"] = True``; a masked agent never takes one.

    ## Observation space

    ``Box(float32)`` of shape (116,): 80 features (bounds +-10, clipped), then the 36-entry action
    mask (bounds [0, 1]; 1.0 valid, 0.0 invalid); :meth:`action_masks` returns the same mask as
    booleans. Names in :data:`FEATURE_NAMES`.

    | index | feature |
    |-------|---------|
    | 0-1   | health PC1, PC2: ``health_fn(current, voltage)`` of the 20 s take-off observation
    |       | (the Dynaformer's principal components), else :func:`fallback_health`; clipped to +-5 |
    | 2     | voltage now, ``(V - 3.6) / 0.5`` (at rest after a (re)charge) |
    | 3-4   | aircraft position ``(x, y)`` relative to the vertiport, / 100 km |
    | 5     | destinations reached / 8 |
    | 6     | charge drawn since the last (re)charge / 8000 C |
    | 7-62  | per slot k (7 values): present, dx, dy (relative to the aircraft, / 100 km), distance / 100 km, |
    |       | priority / 3, visited, wind on legs to it / 39 kt (negative = tailwind); zeros for empty slots |
    | 63-66 | vertiport: dx, dy, distance (/ 100 km), wind on legs to it / 39 kt |
    | 67-69 | scenario one-hot (single_flight, single_charge, multi_charge) |
    | 70    | EOD cut-off, ``(eod_v - 3.0) / 0.5`` (3.0 V: the default cut-off) |
    | 71-78 | per slot: charge of the round trip aircraft -> slot -> vertiport at the lowest feasible |
    |       | levels / 8000 C (0 for visited or empty slots): what the paper's tables say, no battery |
    | 79    | charge to fly home from here / 8000 C (0 at the vertiport) |
    | 80-115| action mask |

    Mask: invalid are empty slots, visited destinations, destinations that cannot be flown to
    and back at any level (closer than 6.1 km to the vertiport: every reachable destination must
    leave a way home), legs too short for an altitude (:func:`uam_studio.flight.min_leg_distance_km`),
    the vertiport while at the vertiport, and in single_flight everything except
    ``destinations[0]``. While the episode runs there is always at least one valid action; once it
    terminates the mask is all zeros (a truncated episode's last observation keeps its mask).

    ## Rewards (the paper's eq. "reward")

    * ``+alpha * priority`` for each destination reached with the voltage never below the cut-off;
    * ``-beta`` for each safe landing at the vertiport (a charging stop);
    * ``-gamma`` if the voltage falls below the cut-off (EOD) on a leg; the episode terminates.
      With ``safe_return``, also ``-gamma`` (and the end) for a leg that would leave no way home.

    Defaults ``alpha=1, beta=1, gamma=5`` as in the paper's figures.

    ## Starting state

    At the vertiport, fully charged. The episode's mission is ``mission`` (optionally with a random
    cell and winds, ``randomize_battery``/``randomize_wind``), ``options["mission"]`` of
    :meth:`reset`, or a fresh :func:`uam_studio.planning.missions.generate.random_mission` (1-8 destinations
    8-60 km out, priorities 1-3, winds U[-39, 39] kt, q_max U[5000, 8000] C, r0 U[0.017, 0.35] ohm).
    The health features come from the first 20 s of a take-off at 500 m simulated with the physics
    model for the episode's cell; ``health_fn`` is called once per episode.

    ## Episode end

    * single_flight: after the one leg to ``destinations[0]`` (reward ``alpha * priority`` or ``-gamma``);
    * single_charge: when the aircraft lands back at the vertiport, or at EOD;
    * multi_charge: landing at the vertiport recharges (``-beta``); ends when every reachable
      destination is visited and the aircraft is back at the vertiport, or at EOD;
    * with ``safe_return``, also at a leg that would strand the aircraft (not flown);
    * truncation after ``max_steps`` (default ``2 * N_MAX + 2 = 18``) steps.

    ``info`` (reset and every step): ``reached`` (names, cumulative), ``reached_priority``,
    ``charging_cycles``, ``eod``, ``invalid_action``, ``stranded``, ``leg_min_voltage_v`` (None before a leg),
    ``route`` and ``altitudes_m`` so far, ``health`` (the two health features).

    ## Arguments

    :param mission: a fixed :class:`Mission` (the paper's per-map training), or None for a random
        mission every episode.
    :param scenario: ``single_flight``, ``single_charge`` or ``multi_charge``; default: the mission's
        scenario, or ``single_charge`` for random missions.
    :param n_dest: destinations per random mission, int or inclusive ``(lo, hi)``.
    :param backend: ``"physics"``, ``"dynaformer"`` (needs ``predictor``) or a :class:`BatteryBackend`.
    :param predictor: the Dynaformer predictor (``predict`` and, optionally, ``health``).
    :param health_fn: ``f(context_current_a, context_voltage_v) -> [PC1, PC2]``; default
        ``predictor.health`` if the predictor has one, else :func:`fallback_health`.
    :param alpha: reward weight of a destination's priority (>= 0).
    :param beta: penalty of a charging stop at the vertiport (>= 0).
    :param gamma: penalty of an end of discharge (>= 0).
    :param randomize_battery: with a fixed mission, draw q_max and r0 from ``q_range``/``r0_range`` each episode.
    :param randomize_wind: with a fixed mission, draw every node's wind from U[-39, 39] kt each episode.
    :param r0_range: a random cell's R0 range (ohm; :mod:`uam_studio.planning.missions.generate` on the 0.35 default).
    :param q_range: range of a random cell's q_max (C).
    :param radius_km: how far from the vertiport a random mission's destinations lie (km).
    :param max_steps: truncation length.
    :param safe_return: off (default) is the paper's setting. On, a destination leg after which
        the battery (this env's backend) could not fly home at the least-charge level, a leg that
        strands the aircraft, is *not* flown: the episode ends with ``-gamma`` as if at EOD and
        ``info["stranded"] = True``. Training with it teaches the agent the same rule that the
        planner's safety filter (:meth:`lookahead_safe`) enforces, so the filter and the agent's
        Q-values agree.
    :param render_mode: None (default) or ``"ansi"``: :meth:`render` returns a text summary of the
        episode so far.

    Registered with gymnasium by ``import uam_studio`` as ``uam_studio/SingleFlight-v0``,
    ``uam_studio/SingleCharge-v0`` and ``uam_studio/MultiCharge-v0`` (:mod:`uam_studio.registration`).
    """

    metadata = {"render_modes": ["ansi"], "render_fps": 1}

    def __init__(
        self,
        mission: Mission | None = None,
        scenario: str | None = None,
        n_dest=(1, N_MAX),
        backend: str | BatteryBackend = "physics",
        predictor: Any = None,
        health_fn: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
        alpha: float = REWARD_DEFAULTS["alpha"],
        beta: float = REWARD_DEFAULTS["beta"],
        gamma: float = REWARD_DEFAULTS["gamma"],
        randomize_battery: bool = False,
        randomize_wind: bool = False,
        r0_range=DEFAULT_R0_RANGE,
        q_range=DEFAULT_Q_RANGE,
        radius_km=DEFAULT_RADIUS_KM,
        max_steps: int = MAX_EPISODE_STEPS,
        safe_return: bool = False,
        render_mode: str | None = None,
    ) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError("render_mode", f"{render_mode!r} is not a render mode; allowed: None, "
                                            f"{', '.join(self.metadata['render_modes'])}")
        self.render_mode = render_mode
        if mission is not None and not isinstance(mission, Mission):
            raise InputError("mission", f"expected a Mission or None, got {type(mission).__name__}")
        self.scenario = scenario = check_scenario(scenario or (mission.scenario if mission is not None
                                                               else DEFAULT_SCENARIO))
        if isinstance(backend, BatteryBackend):
            self.backend = backend
        elif backend == "physics":
            self.backend = PhysicsBattery()
        elif backend == "dynaformer":
            if predictor is None:
                raise InputError("predictor", "the dynaformer backend needs a predictor")
            self.backend = DynaformerBattery(predictor)
        else:
            raise InputError("backend", f"{backend!r} is not a backend; allowed: physics, dynaformer")
        if health_fn is None and predictor is not None and callable(getattr(predictor, "health", None)):
            health_fn = predictor.health
        self.health_fn = health_fn
        self.alpha = check_range("alpha", alpha, 0.0, 1e6)
        self.beta = check_range("beta", beta, 0.0, 1e6)
        self.gamma = check_range("gamma", gamma, 0.0, 1e6)
        self.max_steps = int(check_positive("max_steps", max_steps))
        self.safe_return = bool(safe_return)
        self.n_dest = n_dest
        self.randomize_battery = bool(randomize_battery)
        self.randomize_wind = bool(randomize_wind)
        # (lo, hi) ranges, drawn from with rng.uniform(*range)
        self.r0_range = cast(tuple[float, float], tuple(float(x) for x in r0_range))
        self.q_range = cast(tuple[float, float], tuple(float(x) for x in q_range))
        self.radius_km = tuple(float(x) for x in radius_km)
        self._fixed = mission
        if mission is not None:
            self._check_mission(mission)
        else:
            try:  # missions may have up to 20 destinations; the environment has N_MAX slots
                too_many = int(np.max(np.atleast_1d(n_dest))) > N_MAX
            except (TypeError, ValueError):
                too_many = False  # random_mission names what is wrong
            if too_many:
                raise InputError("n_dest", f"{n_dest!r} is out of range; allowed 1 <= lo <= hi <= {N_MAX} "
                                           "(the environment's destination slots)")
            random_mission(np.random.default_rng(0), n_dest, scenario, self.r0_range, self.q_range,
                           self.radius_km)  # validates n_dest and the ranges now

        low = np.full(OBS_DIM, -FEATURE_BOUND, dtype=np.float32)
        high = np.full(OBS_DIM, FEATURE_BOUND, dtype=np.float32)
        low[N_FEATURES:], high[N_FEATURES:] = 0.0, 1.0
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.mission: Mission | None = None
        self._mask = np.zeros(N_ACTIONS, dtype=bool)
        self._obs = np.zeros(OBS_DIM, dtype=np.float32)
        self._done = True

    # ------------------------------------------------------------------ mission checks

    def _check_mission(self, mission: Mission) -> Episode:
        """Refuse a mission the env cannot fly (one-line error naming the field); return its episode."""
        n = len(mission.destinations)
        if n == 0:
            raise InputError("mission.destinations", "is empty; the environment needs 1 to 8 destinations")
        if n > N_MAX:
            raise InputError("mission.destinations", f"has {n} destinations; the environment has {N_MAX} slots")
        legs = LegTable(mission)
        episode = Episode.of(legs, self.scenario)
        if not episode.servable.any():
            what = "destinations[0]" if episode.rules.one_leg else "every destination"
            raise InputError("mission.destinations", f"{what} is too close to the vertiport to fly to "
                                                     f"(a leg needs >= {MIN_LEG_KM[0]:.1f} km)")
        return episode

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        mission = (options or {}).get("mission")
        episode = None
        if mission is not None:
            if not isinstance(mission, Mission):
                raise InputError("options.mission", f"expected a Mission, got {type(mission).__name__}")
            episode = self._check_mission(mission)
        elif self._fixed is not None:
            mission = self._fixed
            if self.randomize_battery:
                mission = mission.with_battery(float(rng.uniform(*self.q_range)), float(rng.uniform(*self.r0_range)))
            if self.randomize_wind:
                lo, hi = WIND_RANGE_KTS
                mission = dataclasses.replace(
                    mission,
                    vertiport=dataclasses.replace(mission.vertiport, wind_kts=float(rng.uniform(lo, hi))),
                    destinations=tuple(dataclasses.replace(d, wind_kts=float(rng.uniform(lo, hi)))
                                       for d in mission.destinations))
        else:
            mission = random_mission(rng, self.n_dest, self.scenario, self.r0_range, self.q_range, self.radius_km)
        self.mission = mission
        # the rules (the env's battery is its backend)
        self._episode = episode if episode is not None else Episode.of(LegTable(mission), self.scenario)
        legs = self._legs = self._episode.legs
        q, r0, eod = mission.battery.q_max, mission.battery.r0, mission.eod_v
        ci, cv = observe_takeoff(q, r0)
        if self.health_fn is not None:
            health = np.asarray(self.health_fn(ci, cv), dtype=float).reshape(-1)[:2]
            health = np.clip(np.nan_to_num(health), -HEALTH_CLIP, HEALTH_CLIP)
        else:
            health = fallback_health(ci, cv)
        self._health = health
        self.backend.reset(mission.cell, ci, cv)
        self._v_rest = float(rest_voltage(q))

        # episode state
        self._node = VERTIPORT_SLOT
        self._visited = np.zeros(N_MAX, dtype=bool)
        self._voltage = self._v_rest
        self._charge = 0.0
        self._steps = 0
        self._cycles = 0
        self._route: list[str] = []
        self._alts: list[float] = []
        self._reached: list[str] = []
        self._reached_priority = 0
        self._return = 0.0
        self._eod = False
        self._invalid = False
        self._stranded = False
        self._leg_min_v: float | None = None
        self._done = False

        self._base, self._rel = static_features(legs, health, self.scenario, eod)
        self._update_mask()
        return self._observe(), self._info()

    def step(self, action):
        if self._done:
            raise RuntimeError("step() called after the episode ended; call reset()")
        a = int(action)
        self._steps += 1
        if not (0 <= a < N_ACTIONS and self._mask[a]):
            self._invalid = True
            return self._finish(-self.gamma, terminated=True)
        target, ai = divmod(a, N_ALTITUDES)
        legs = self._legs
        cur = legs.current(self._node, target, ai)
        if self.safe_return:
            probe = copy.copy(self.backend)
            out = probe.fly_leg(cur)
            if not out.eod and not self._home_reachable(probe, target):
                self._stranded = True
                return self._finish(-self.gamma, terminated=True)
            self.backend = probe
        else:
            out = self.backend.fly_leg(cur)
        self._route.append(legs.name(target))
        self._alts.append(ALTITUDES_M[ai])
        self._leg_min_v = out.min_voltage_v
        self._voltage = out.end_voltage_v
        if out.eod:
            self._eod = True
            return self._finish(-self.gamma, terminated=True)
        self._charge += float(cur.sum()) * DT_S
        self._node = target
        if target == VERTIPORT_SLOT:
            self._cycles += 1
            reward = -self.beta
            if self._episode.rules.recharges:
                self.backend.recharge()
                self._charge = 0.0
                self._voltage = self._v_rest
            terminated = self._episode.ends_after(target, self._visited)
        else:
            self._visited[target] = True
            name = legs.names[target]
            self._reached.append(name)
            prio = int(legs.priority[target])
            self._reached_priority += prio
            reward = self.alpha * prio
            terminated = self._episode.ends_after(target, self._visited)
        return self._finish(reward, terminated)

    def _finish(self, reward: float, terminated: bool):
        self._return += reward
        truncated = not terminated and self._steps >= self.max_steps
        self._done = bool(terminated or truncated)
        if terminated:
            self._mask[:] = False
        else:  # a truncated state keeps its mask: learners bootstrap from it
            self._update_mask()
        return self._observe(), float(reward), bool(terminated), bool(truncated), self._info()

    def _update_mask(self) -> None:
        self._mask = self._episode.moves(self._node, self._visited)[0].reshape(-1)

    def _observe(self) -> np.ndarray:
        return observe(self._base, self._rel, self._legs, self._node, self._voltage, len(self._reached),
                       self._charge, self._visited, self._episode.servable, self._mask, self._obs)

    def _info(self) -> dict[str, Any]:
        return {
            "reached": list(self._reached),
            "reached_priority": self._reached_priority,
            "charging_cycles": self._cycles,
            "eod": self._eod,
            "invalid_action": self._invalid,
            "stranded": self._stranded,
            "leg_min_voltage_v": self._leg_min_v,
            "route": list(self._route),
            "altitudes_m": list(self._alts),
            "health": self._health.copy(),
        }


def make_env(**kwargs: Any) -> Callable[[], UAMPlanningEnv]:
    """A no-argument factory of :class:`UAMPlanningEnv` (for ``make_vec_env`` / ``DummyVecEnv``).

    ``make_env(mission=m, scenario="multi_charge")()`` builds one environment; the vector-env
    helpers call it once per copy and seed each copy through ``reset(seed=...)``. A backend given
    as an instance is shallow-copied per environment (the predictor is shared, the state is not).
    """
    UAMPlanningEnv(**kwargs)  # fail early, in the caller, on bad arguments

    def _factory() -> UAMPlanningEnv:
        kw = dict(kwargs)
        if isinstance(kw.get("backend"), BatteryBackend):
            kw["backend"] = copy.copy(kw["backend"])  # each copy keeps its own battery state
        return UAMPlanningEnv(**kw)

    return _factory


__all__ = [
    "REWARD_DEFAULTS",
    "CONTEXT_S",
    "FEATURE_NAMES",
    "MAX_EPISODE_STEPS",
    "N_FEATURES",
    "OBS_DIM",
    "BatteryBackend",
    "DynaformerBattery",
    "LegOutcome",
    "PhysicsBattery",
    "UAMPlanningEnv",
    "fallback_health",
    "make_env",
    "observe_takeoff",
    "takeoff_context_current",
]

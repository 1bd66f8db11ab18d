"""The discrete action space shared by the environment, the DQN, the oracle and the baselines.

An action picks the next node and the cruise altitude of the leg to it::

    a = target * len(ALTITUDES_M) + altitude_index

``target`` 0..N_MAX-1 is a destination slot (``mission.destinations[target]``),
``target == N_MAX`` is the vertiport; ``altitude_index`` indexes
:data:`ALTITUDES_M`, the paper's four cruise levels (the flight model itself
accepts any altitude in [500, 3000] m). With ``N_MAX = 8`` there are
``(8 + 1) * 4 = 36`` actions.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from uam_studio.battery import SimulationResult
from uam_studio.battery.parameters import Cell
from uam_studio.battery.simulate import simulate_cell
from uam_studio.errors import InputError
from uam_studio.flight import leg_charges_c, leg_profile, min_leg_distance_km
from uam_studio.flight.profile import MAX_DISTANCE_KM
from uam_studio.planning.missions.mission import MAX_DESTINATIONS, PAPER_DESTINATIONS, Destination, Mission, Vertiport

N_MAX = PAPER_DESTINATIONS  # destination slots of the discrete action space (the paper's DQN, the exact oracle)
ALTITUDES_M = (500.0, 1000.0, 2000.0, 3000.0)  # the paper's cruise levels (m)
N_ALTITUDES = len(ALTITUDES_M)
VERTIPORT_SLOT = N_MAX  # target index of the vertiport
N_TARGETS = N_MAX + 1
N_ACTIONS = N_TARGETS * N_ALTITUDES  # 36
MIN_LEG_KM = tuple(min_leg_distance_km(h) for h in ALTITUDES_M)  # shortest leg per level (km)
DT_S = 1.0  # sample step of every leg current (s)


def encode_action(target: int, alt_idx: int) -> int:
    """Action index for ``target`` (0..N_MAX-1 destination slot, N_MAX vertiport) and altitude index."""
    if not 0 <= int(target) <= N_MAX:
        raise InputError("target", f"{target!r} is out of range; allowed [0, {N_MAX}] ({N_MAX} = vertiport)")
    if not 0 <= int(alt_idx) < N_ALTITUDES:
        raise InputError("alt_idx", f"{alt_idx!r} is out of range; allowed [0, {N_ALTITUDES - 1}]")
    return int(target) * N_ALTITUDES + int(alt_idx)


def decode_action(a: int) -> tuple[int, int]:
    """``(target, alt_idx)`` of action ``a`` (0..N_ACTIONS-1); target N_MAX is the vertiport."""
    a = int(a)
    if not 0 <= a < N_ACTIONS:
        raise InputError("action", f"{a!r} is out of range; allowed [0, {N_ACTIONS - 1}]")
    return a // N_ALTITUDES, a % N_ALTITUDES


@functools.cache
def takeoff_current() -> np.ndarray:
    """Per-cell current (A, 1 s samples) of the vertical take-off and climb to 500 m (about 101 s).

    Every leg starts like this (higher levels climb longer at about the same power), so a cell
    that cannot fly it above the cut-off cannot fly any leg.
    """
    p = leg_profile(MIN_LEG_KM[0] + 1.0, ALTITUDES_M[0], 0.0, DT_S)
    end = next(e for name, _, e, _ in p.phases if name == "climb")
    cur = np.array(p.current_a[: math.ceil(end / DT_S)])
    cur.setflags(write=False)
    return cur


def fly_takeoff(cell: Cell) -> SimulationResult:
    """A fresh ``cell`` (its parameter set, q_max C, R0 ohm and cut-off V) on the take-off and climb to 500 m
    (:func:`takeoff_current`, the least demanding start of any leg): the physics model's run. The one place a
    planner's take-off is simulated (the exact search's take-off check, the safety verdict's failed take-off, the
    environment's 20 s health observation)."""
    return simulate_cell(takeoff_current(), cell, DT_S)


class LegTable:
    """The legs of one mission over the discrete action space, with cached per-cell currents.

    Node index ``k < slots`` is ``mission.destinations[k]``, ``slots`` (:attr:`home`) the vertiport;
    ``slots`` defaults to ``N_MAX``, the discrete action space's slots, and may be up to
    :data:`MAX_DESTINATIONS` for planners that are not tied to it. ``feasible[i, j, a]`` is True if the leg i -> j
    exists (both nodes present, i != j) and its length fits altitude ``ALTITUDES_M[a]``
    (:func:`uam_studio.flight.min_leg_distance_km`, at most 500 km). :meth:`current` is the leg's per-cell current
    (A, 1 s samples) exactly as :func:`uam_studio.planning.missions.route.simulate_route` flies it: the wind and dwell
    of the node flown to. Profiles are computed on first use and cached.
    """

    def __init__(self, mission: Mission, slots: int = N_MAX) -> None:
        dests = mission.destinations
        if not 1 <= slots <= MAX_DESTINATIONS:
            raise InputError("slots", f"{slots!r} is out of range; allowed [1, {MAX_DESTINATIONS}]")
        if len(dests) > slots:
            raise InputError("mission.destinations", f"has {len(dests)} destinations; at most {slots} allowed")
        self.mission = mission
        self.slots = int(slots)
        self.home = self.slots  # node index of the vertiport
        n_nodes = self.slots + 1
        self.n = len(dests)
        self.names = tuple(d.name for d in dests) + ("vertiport",)
        nodes: list[Destination | Vertiport] = [*dests, mission.vertiport]
        idx = list(range(self.n)) + [self.home]
        self.index = idx  # node index of nodes[k]
        self.present = np.zeros(n_nodes, dtype=bool)
        self.present[idx] = True
        self.pos = np.zeros((n_nodes, 2))
        self.wind = np.zeros(n_nodes)
        self.dwell = np.zeros(n_nodes)
        self.priority = np.zeros(n_nodes, dtype=int)
        for k, node in zip(idx, nodes):
            self.pos[k] = (node.x_km, node.y_km)
            self.wind[k] = node.wind_kts
            self.dwell[k] = getattr(node, "dwell_s", 0.0)
            self.priority[k] = getattr(node, "priority", 0)
        self.dist = np.zeros((n_nodes, n_nodes))
        for i in idx:
            for j in idx:
                # math.hypot, as Mission.distance_km, so feasibility matches simulate_route exactly
                self.dist[i, j] = math.hypot(self.pos[i, 0] - self.pos[j, 0], self.pos[i, 1] - self.pos[j, 1])
        ok = self.present[:, None] & self.present[None, :] & ~np.eye(n_nodes, dtype=bool)
        ok &= self.dist <= MAX_DISTANCE_KM
        self.feasible = ok[:, :, None] & (self.dist[:, :, None] >= np.asarray(MIN_LEG_KM)[None, None, :])
        self._cache: dict[tuple[int, int, int], np.ndarray] = {}

    def current(self, i: int, j: int, a: int) -> np.ndarray:
        """Per-cell current (A) of leg i -> j at ``ALTITUDES_M[a]`` (read-only; must be feasible)."""
        key = (i, j, a)
        cur = self._cache.get(key)
        if cur is None:
            cur = leg_profile(self.dist[i, j], ALTITUDES_M[a], self.wind[j], DT_S, self.dwell[j]).current_a
            self._cache[key] = cur
        return cur

    @functools.cached_property
    def _charges(self) -> np.ndarray:
        """Charge (C) of every leg i -> j at every level a, shape [N_TARGETS, N_TARGETS, N_ALTITUDES];
        ``inf`` where the leg is not feasible. Equal, bit for bit, to ``leg_charge_c`` of each leg.
        Computed once per mission in one vectorised pass (an env observation needs most of them)."""
        dist = np.minimum(self.dist, MAX_DISTANCE_KM)  # longer legs are infeasible anyway
        table = leg_charges_c(dist, ALTITUDES_M, self.wind[None, :])  # wind of the node flown to
        return np.where(self.feasible, table, np.inf)

    @functools.cached_property
    def _cheapest(self) -> np.ndarray:
        """Charge (C) of each leg i -> j at its lowest feasible level, shape [N_TARGETS, N_TARGETS]
        (``inf`` where none is)."""
        first = np.argmax(self.feasible, axis=-1)  # lowest feasible level (0 where none: inf there)
        return np.take_along_axis(self._charges, first[..., None], -1)[..., 0]

    def charge(self, i: int, j: int, a: int) -> float:
        """Charge (C) one cell gives on leg i -> j at ``ALTITUDES_M[a]`` (``inf`` if not feasible)."""
        return float(self._charges[i, j, a])

    def cheapest_level(self, i: int, j: int) -> int | None:
        """Index of the feasible level of leg i -> j that uses the least charge, None if none is."""
        row = self._charges[i, j]
        a = int(np.argmin(row))
        return a if np.isfinite(row[a]) else None

    @property
    def cheapest_charges(self) -> np.ndarray:
        """:meth:`cheapest_charge` of every leg at once, shape [slots + 1, slots + 1] (C; ``inf`` where no
        level is feasible, the diagonal included). Do not modify."""
        return self._cheapest

    def cheapest_charge(self, i: int, j: int) -> float:
        """Charge (C) of leg i -> j at its lowest feasible level (the cheapest one in the paper's
        tables: climbing costs more than the cruise saves), ``inf`` if no level is feasible."""
        return float(self._cheapest[i, j])

    def greedy_order(self, node: int, slots: list[int]) -> list[int]:
        """``slots`` in the greedy rule's order from ``node``: best priority / distance first (ties keep
        their order). The one home of the rule of :func:`~uam_studio.planning.solvers.greedy.greedy_plan`
        and :meth:`~uam_studio.planning.env.UAMPlanningEnv.greedy_action`."""
        return sorted(slots, key=lambda k: -self.priority[k] / max(self.dist[node, k], 1e-9))

    def name(self, k: int) -> str:
        """Node name of index ``k`` (``"vertiport"`` for :attr:`home`)."""
        return self.names[-1] if k == self.home else self.names[k]

"""What the attention planner sees: the tokens of a mission and the features of one decision.

A mission of ``n`` destinations (1 to :data:`~uam_studio.planning.missions.mission.MAX_DESTINATIONS`) is ``n + 1``
tokens: token ``t < n`` is ``mission.destinations[t]``, token ``n`` the vertiport. Each token has
:data:`TOKEN_FEATURES` numbers, the node's own and the mission's (every token carries the cell's
health and the scenario, so the encoder sees them):

====  ==========================================================================================
0-1   position relative to the vertiport, x and y (km / 50)
2     distance from the vertiport (km / 50)
3     priority / 3 (0 for the vertiport)
4     wind on legs flown to the node (kt / 39; negative = tailwind)
5     dwell at the node (s / 300)
6-7   charge of the leg vertiport -> node and node -> vertiport at its lowest-charge level (C / q_max;
      1 where no level is feasible, 0 for the vertiport)
8     1 for the vertiport token
9     q_max (C / 8000)
10    R0 (ohm / 0.35)
11    1 for multi_charge
12    n / 20
====  ==========================================================================================

A decision is made at a node (a token) with a battery that has given ``used_c`` (C) since its last
charge. Its context has :data:`CONTEXT_FEATURES` numbers: ``used_c / q_max``, completed sorties / 5,
the fraction of destinations visited, 1 at the vertiport. Each candidate token has
:data:`CANDIDATE_FEATURES` numbers: the charge of the leg there, of the leg from there home (0 for
the vertiport candidate), the sortie's total charge after both (all C / q_max), the leg's length
(km / 50), priority per distance (priority / max(km, 2.5) * 10, the greedy rule's ratio as an
input) and 1 for the vertiport candidate (home, or stop when already there).

The candidate mask of :func:`step_features` is the *loose* one: unvisited destinations whose legs
there and home exist at some level (:class:`~uam_studio.planning.legs.LegTable` feasibility: length
only), and the vertiport. Whether the battery can fly them is the physics filter's question
(:mod:`~uam_studio.planning.agents.attention.decode`), not the mask's: the network has to learn when
the charge runs short.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.legs import LegTable
from uam_studio.planning.missions.generate import DEFAULT_R0_RANGE
from uam_studio.planning.missions.scenario import scenario_rules

TOKEN_FEATURES = 13
CONTEXT_FEATURES = 4
CANDIDATE_FEATURES = 6
KM_SCALE = 50.0  # km
Q_SCALE = 8000.0  # C
R0_SCALE = DEFAULT_R0_RANGE[1]  # ohm: the training generator's highest R0
WIND_SCALE = WIND_RANGE_KTS[1]  # kt
DWELL_SCALE = 300.0  # s
SORTIE_SCALE = 5.0
NO_LEG = 1.0  # charge feature (C / q_max) of a leg no level can fly

__all__ = [
    "CANDIDATE_FEATURES",
    "CONTEXT_FEATURES",
    "MissionTokens",
    "TOKEN_FEATURES",
    "mission_tokens",
    "step_features",
]


@dataclass(frozen=True)
class MissionTokens:
    """A mission in token space (see the module docstring).

    ``features`` [n+1, TOKEN_FEATURES]; ``leg_index`` [n+1]: each token's node index in ``legs``;
    ``charge`` [n+1, n+1]: the charge (C) of leg t -> u at its lowest-charge level (``inf`` if none is
    feasible); ``dist`` [n+1, n+1] (km); ``priority`` [n+1]; ``q_max`` (C); ``multi`` (bool).
    """

    legs: LegTable
    features: np.ndarray
    leg_index: np.ndarray
    charge: np.ndarray
    dist: np.ndarray
    priority: np.ndarray
    q_max: float
    multi: bool

    @property
    def n(self) -> int:
        """Number of destinations (the vertiport is token ``n``)."""
        return self.features.shape[0] - 1


def mission_tokens(legs: LegTable, scenario: str) -> MissionTokens:
    """The tokens of the mission of ``legs`` for ``scenario`` (see the module docstring)."""
    m = legs.mission
    n = legs.n
    idx = np.array(list(range(n)) + [legs.home])
    q = float(m.battery.q_max)
    charge = legs.cheapest_charges[np.ix_(idx, idx)]  # a copy; inf on the diagonal (no leg i -> i)
    dist = legs.dist[np.ix_(idx, idx)]
    pos = legs.pos[idx] - legs.pos[legs.home]
    prio = legs.priority[idx].astype(float)
    prio[n] = 0.0
    f = np.zeros((n + 1, TOKEN_FEATURES))
    f[:, 0:2] = pos / KM_SCALE
    f[:, 2] = dist[n] / KM_SCALE
    f[:, 3] = prio / 3.0
    f[:, 4] = legs.wind[idx] / WIND_SCALE
    f[:, 5] = legs.dwell[idx] / DWELL_SCALE
    f[:, 6] = np.where(np.isfinite(charge[n]), charge[n] / q, NO_LEG)
    f[:, 7] = np.where(np.isfinite(charge[:, n]), charge[:, n] / q, NO_LEG)
    f[n, 6:8] = 0.0
    f[n, 8] = 1.0
    f[:, 9] = q / Q_SCALE
    f[:, 10] = float(m.battery.r0) / R0_SCALE
    f[:, 11] = 1.0 if scenario_rules(scenario).recharges else 0.0
    f[:, 12] = n / 20.0
    return MissionTokens(legs, f.astype(np.float32), idx, charge, dist, prio, q, scenario_rules(scenario).recharges)


def step_features(tok: MissionTokens, at: int, visited: np.ndarray, used_c: float,
                  sorties: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Features of one decision at token ``at`` (see the module docstring).

    :param visited: bool [n], destinations already visited.
    :param used_c: charge (C) given since the last charge.
    :param sorties: completed sorties (returns to the vertiport).
    :return: ``(context [CONTEXT_FEATURES], candidates [n+1, CANDIDATE_FEATURES], mask [n+1])``.
    """
    n, q = tok.n, tok.q_max
    home = n
    go = tok.charge[at]
    back = tok.charge[:, home]
    mask = np.zeros(n + 1, dtype=bool)
    mask[:n] = ~visited & np.isfinite(go[:n]) & np.isfinite(back[:n])
    mask[home] = True
    go_f = np.where(np.isfinite(go), go / q, NO_LEG)
    back_f = np.where(np.isfinite(back), back / q, NO_LEG)
    back_f[home] = 0.0
    if at == home:
        go_f[home] = 0.0
    d = tok.dist[at]
    cand = np.zeros((n + 1, CANDIDATE_FEATURES), dtype=np.float32)
    cand[:, 0] = go_f
    cand[:, 1] = back_f
    cand[:, 2] = used_c / q + go_f + back_f
    cand[:, 3] = d / KM_SCALE
    cand[:n, 4] = tok.priority[:n] / np.maximum(d[:n], 2.5) * 10.0
    cand[home, 5] = 1.0
    ctx = np.array([used_c / q, min(sorties, 10) / SORTIE_SCALE, visited.mean() if n else 1.0,
                    1.0 if at == home else 0.0], dtype=np.float32)
    return ctx, cand, mask

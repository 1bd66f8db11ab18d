"""What a fleet's dispatcher knows and how it decides: each pack's belief, and three rules.

- :class:`AircraftView`: all a dispatcher is given about a free aircraft: its name and the belief its pack's logbook
  gives (:class:`~uam_studio.battery.health.belief.PackBelief`, the one belief value, on the fleet's declared
  configuration :func:`~uam_studio.battery.health.config.fleet_belief_config`).
  No true cell: the truth lives in :mod:`uam_studio.fleet.day`'s world.
- Rules (:data:`DISPATCHERS`): ``aware`` flies a request with an aircraft whose cautious belief
  (1.64 std to the weak side, winds 2.33 std to the head side) lands above the cut-off; ``blind``
  assumes every pack is the nominal new one (:data:`NOMINAL`) with a fixed voltage reserve on the forecast
  winds; ``hindsight`` knows each pack's truth and the actual winds (a reference, not a proven optimum:
  it assigns by the same rule; :mod:`uam_studio.fleet.hindsight` bounds what any rule could serve). Each assigns the
  waiting requests, most stars first, to the free aircraft with the least margin that still passes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from uam_studio.battery import DEFAULT_EOD_V
from uam_studio.battery.health.belief import PackBelief
from uam_studio.battery.health.config import NEW_PACK_Q_C, NEW_PACK_R0_OHM
from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE, CellParameters
from uam_studio.fleet.demand import Request
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning import Battery, Destination, Mission, Vertiport, simulate_route

__all__ = ["ALTITUDE_M", "BLIND_RESERVE_V", "DISPATCHERS", "NOMINAL", "AircraftView", "assign", "round_trip",
           "round_trip_margin"]

ALTITUDE_M = 500.0  # m: every leg's cruise
NOMINAL = (NEW_PACK_Q_C, NEW_PACK_R0_OHM)  # the nominal new pack (the fleet's declared one): q_max (C), R0 (ohm)
EOD_V = DEFAULT_EOD_V  # V: the cut-off
BLIND_RESERVE_V = 0.5  # V: the health-blind rule's reserve above the cut-off (tuned: RESULTS.md, "A fleet's life")
DISPATCHERS = ("aware", "blind", "hindsight")


@dataclass(frozen=True)
class AircraftView:
    """What a dispatcher sees of an aircraft: its ``name``, its ``belief`` and a ``key`` that changes
    whenever the belief does (for caching)."""

    name: str
    belief: PackBelief
    key: int


def round_trip(req: Request, q_max: float, r0: float, wind_out_kts: float, wind_home_kts: float,
               params: CellParameters | None = None):
    """The physics model's round trip vertiport -> request -> vertiport at :data:`ALTITUDE_M` on a
    cell of ``q_max`` (C), ``r0`` (ohm) and parameter set ``params`` (default: the cell type's), in the given winds
    (kt, + = headwind each way): a :class:`~uam_studio.planning.missions.route.RouteSimulation`."""
    lo, hi = WIND_RANGE_KTS
    (q_lo, q_hi), (r_lo, r_hi) = PAPER_Q_RANGE, PAPER_R0_RANGE  # the paper's health box
    mission = Mission(req.name, Vertiport(0.0, 0.0, float(min(max(wind_home_kts, lo), hi))),
                      (Destination(req.name, req.x_km, req.y_km, int(req.priority),
                                   float(min(max(wind_out_kts, lo), hi))),),
                      "single_charge", Battery(float(min(max(q_max, q_lo), q_hi)), float(min(max(r0, r_lo), r_hi))),
                      EOD_V)
    return simulate_route(mission, [req.name, "vertiport"], [ALTITUDE_M, ALTITUDE_M], params=params)


def round_trip_margin(req: Request, q_max: float, r0: float, wind_out_kts: float, wind_home_kts: float,
                      params: CellParameters | None = None) -> float:
    """Lowest voltage of :func:`round_trip` minus the cut-off (V); negative: it would breach."""
    return float(round_trip(req, q_max, r0, wind_out_kts, wind_home_kts, params).min_voltage_v) - EOD_V


def assign(waiting: Sequence[Request], free: Sequence[AircraftView],
           margin: Callable[[Request, AircraftView], float], required_v: float) -> list[tuple[Request, AircraftView]]:
    """Requests to aircraft: most stars first (then the earliest), each to the free aircraft with the
    least ``margin`` (V) that is still >= ``required_v``; a request no free aircraft passes waits."""
    left = list(free)
    out = []
    for req in sorted(waiting, key=lambda r: (-r.priority, r.t_s, r.name)):
        scored = [(m, a.name, a) for a in left if (m := margin(req, a)) >= required_v]
        if scored:
            _, _, best = min(scored, key=lambda t: (t[0], t[1]))
            out.append((req, best))
            left.remove(best)
    return out

"""What a fleet's dispatcher knows and how it decides: each pack's belief, and three rules.

- :class:`PackBelief`: an aircraft's own estimate of its pack (q_max C, R0 ohm, their std) and the
  charge it has delivered (C, from its current sensor), carried from flight to flight: aged by the
  aging law between flights (:meth:`PackBelief.aged`), sharpened by each flight's health fit
  (:meth:`PackBelief.update`).
- :class:`AircraftView`: all a dispatcher is given about a free aircraft: its name and its belief.
  No true cell: the truth lives in :mod:`uam_studio.fleet.day`'s world.
- Rules (:data:`DISPATCHERS`): ``aware`` flies a request with an aircraft whose cautious belief
  (1.64 std to the weak side, winds 2.33 std to the head side) lands above the cut-off; ``blind``
  assumes every pack is new (q_max 7600 C, R0 0.117 ohm) with a fixed voltage reserve on the forecast
  winds; ``hindsight`` knows each pack's truth and the actual winds (a reference, not a proven optimum:
  it assigns by the same rule; :mod:`uam_studio.fleet.hindsight` bounds what any rule could serve). Each assigns the
  waiting requests, most stars first, to the free aircraft with the least margin that still passes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from uam_studio.battery import DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE
from uam_studio.errors import InputError
from uam_studio.fleet.aging import AGING_LAW, AgingLaw
from uam_studio.fleet.demand import Request
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning import Battery, Destination, Mission, Vertiport, simulate_route

__all__ = ["ALTITUDE_M", "BLIND_RESERVE_V", "DISPATCHERS", "NOMINAL", "AircraftView", "PackBelief",
           "assign", "round_trip", "round_trip_margin"]

ALTITUDE_M = 500.0  # m: every leg's cruise
NOMINAL = (DEFAULT_Q_MAX, DEFAULT_R0)  # a new NASA pack: q_max (C), R0 (ohm)
EOD_V = DEFAULT_EOD_V  # V: the cut-off
BLIND_RESERVE_V = 0.5  # V: the health-blind rule's reserve above the cut-off (tuned: RESULTS.md)
DISPATCHERS = ("aware", "blind", "hindsight")


@dataclass(frozen=True)
class PackBelief:
    """An aircraft's estimate of its pack: ``q_max`` / ``q_max_sd`` (C), ``r0`` / ``r0_sd`` (ohm), and
    the charge it has delivered (``delivered_c``, C, measured), with the new pack's nominal q_max
    (``q_max_nominal``, C) as the aging clock's unit."""

    q_max: float
    q_max_sd: float
    r0: float
    r0_sd: float
    delivered_c: float = 0.0
    q_max_nominal: float = NOMINAL[0]

    @classmethod
    def new_pack(cls, delivered_c: float = 0.0, law: AgingLaw = AGING_LAW) -> PackBelief:
        """A pack known only by its logged throughput: the nominal new pack (q_max 7600 +- 300 C, R0
        0.117 +- 0.02 ohm), aged by ``law`` over ``delivered_c`` (C)."""
        return cls(NOMINAL[0], 300.0, NOMINAL[1], 0.02).aged(delivered_c, law)

    def aged(self, charge_c: float, law: AgingLaw = AGING_LAW, process_sd: float = 0.2) -> PackBelief:
        """After delivering ``charge_c`` (C) more: the estimate moves as ``law`` says, and its std grows
        by ``process_sd`` of the predicted change (the law is not exact)."""
        if not math.isfinite(charge_c) or charge_c < 0:
            raise InputError("charge_c", f"{charge_c!r}: allowed a finite charge >= 0 C")
        e0 = self.delivered_c / self.q_max_nominal
        e1 = (self.delivered_c + charge_c) / self.q_max_nominal
        fq = float(law.capacity_fraction(e1) / max(float(law.capacity_fraction(e0)), 1e-6))
        fr = float(law.resistance_ratio(e1) / law.resistance_ratio(e0))
        dq, dr = self.q_max * (1.0 - fq), self.r0 * (fr - 1.0)
        return replace(self, q_max=self.q_max - dq, r0=self.r0 + dr, delivered_c=self.delivered_c + charge_c,
                       q_max_sd=math.hypot(self.q_max_sd, process_sd * dq),
                       r0_sd=math.hypot(self.r0_sd, process_sd * dr))

    def update(self, q_max: float, q_max_sd: float, r0: float, r0_sd: float) -> PackBelief:
        """Combined with one flight's health fit (its estimate and std), parameter by parameter
        (precision-weighted)."""
        def comb(m0: float, s0: float, m1: float, s1: float) -> tuple[float, float]:
            w0, w1 = 1.0 / max(s0, 1e-9) ** 2, 1.0 / max(s1, 1e-9) ** 2
            return (w0 * m0 + w1 * m1) / (w0 + w1), math.sqrt(1.0 / (w0 + w1))

        q, qs = comb(self.q_max, self.q_max_sd, q_max, q_max_sd)
        r, rs = comb(self.r0, self.r0_sd, r0, r0_sd)
        return replace(self, q_max=q, q_max_sd=qs, r0=r, r0_sd=rs)


@dataclass(frozen=True)
class AircraftView:
    """What a dispatcher sees of an aircraft: its ``name``, its ``belief`` and a ``key`` that changes
    whenever the belief does (for caching)."""

    name: str
    belief: PackBelief
    key: int


def round_trip(req: Request, q_max: float, r0: float, wind_out_kts: float, wind_home_kts: float):
    """The physics model's round trip vertiport -> request -> vertiport at :data:`ALTITUDE_M` on a
    cell of ``q_max`` (C), ``r0`` (ohm), in the given winds (kt, + = headwind each way):
    a :class:`~uam_studio.planning.missions.route.RouteSimulation`."""
    lo, hi = WIND_RANGE_KTS
    (q_lo, q_hi), (r_lo, r_hi) = PAPER_Q_RANGE, PAPER_R0_RANGE  # the paper's health box
    mission = Mission(req.name, Vertiport(0.0, 0.0, float(min(max(wind_home_kts, lo), hi))),
                      (Destination(req.name, req.x_km, req.y_km, int(req.priority),
                                   float(min(max(wind_out_kts, lo), hi))),),
                      "single_charge", Battery(float(min(max(q_max, q_lo), q_hi)), float(min(max(r0, r_lo), r_hi))),
                      EOD_V)
    return simulate_route(mission, [req.name, "vertiport"], [ALTITUDE_M, ALTITUDE_M])


def round_trip_margin(req: Request, q_max: float, r0: float, wind_out_kts: float, wind_home_kts: float) -> float:
    """Lowest voltage of :func:`round_trip` minus the cut-off (V); negative: it would breach."""
    return float(round_trip(req, q_max, r0, wind_out_kts, wind_home_kts).min_voltage_v) - EOD_V


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

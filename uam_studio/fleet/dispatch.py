"""What a fleet's dispatcher knows and how it decides: each pack's belief, and three rules.

- :class:`PackBelief`: the dispatcher's view of an aircraft's health belief about its pack (q_max C, R0 ohm, their
  std; the one belief of :mod:`uam_studio.battery.health.belief`) and the charge it has delivered (C, from its
  current sensor), carried from flight to flight as its logbook grows: sharpened by each flight's whole-record
  fit (:meth:`PackBelief.update`), aged by the aging law (:meth:`PackBelief.aged`).
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
from dataclasses import dataclass

import numpy as np

from uam_studio.battery import DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.battery.health.belief import AGING_PROCESS_SD, BelievedHealth, aged_belief
from uam_studio.battery.health.logbook import FlightFit
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, combine
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
NEW_PACK_SD = (300.0, 0.02)  # the spread of new packs around it: q_max (C), R0 (ohm)
EOD_V = DEFAULT_EOD_V  # V: the cut-off
BLIND_RESERVE_V = 0.5  # V: the health-blind rule's reserve above the cut-off (tuned: RESULTS.md, "A fleet's life")
DISPATCHERS = ("aware", "blind", "hindsight")


@dataclass(frozen=True)
class PackBelief:
    """An aircraft's belief about its pack, as the dispatcher reads it: a thin view of the one health belief
    (:mod:`uam_studio.battery.health.belief`), the Gaussian in (w, R0) (w = 6500 C / q_max) with mean ``mean`` and
    covariance ``cov`` (row-major), the charge the pack has delivered (``delivered_c``, C, measured) and the new
    pack's nominal q_max (``q_max_nominal``, C), the aging clock's unit. ``q_max`` / ``q_max_sd`` (C) and ``r0`` /
    ``r0_sd`` (ohm) are its views. :meth:`update` multiplies in one flight's fit, :meth:`aged` ages it by the law:
    the same steps, in the same order, as :func:`~uam_studio.battery.health.belief.logbook_belief` over the pack's
    logbook."""

    mean: tuple[float, float]
    cov: tuple[float, float, float, float]
    delivered_c: float = 0.0
    q_max_nominal: float = NOMINAL[0]

    @classmethod
    def new_pack(cls, delivered_c: float = 0.0, law: AgingLaw = AGING_LAW) -> PackBelief:
        """A pack known only by its logged throughput: the nominal new pack (q_max 7600 +- 300 C, R0
        0.117 +- 0.02 ohm), aged by ``law`` over ``delivered_c`` (C)."""
        w = Q_REF_C / NOMINAL[0]
        sd_w = Q_REF_C * NEW_PACK_SD[0] / NOMINAL[0] ** 2
        return cls((w, NOMINAL[1]), (sd_w ** 2, 0.0, 0.0, NEW_PACK_SD[1] ** 2)).aged(delivered_c, law)

    @classmethod
    def of(cls, mean: np.ndarray, cov: np.ndarray, delivered_c: float, q_max_nominal: float = NOMINAL[0]
           ) -> PackBelief:
        """The view of a belief ``(mean [2], cov [2, 2])`` in (w, R0)."""
        c = np.asarray(cov, dtype=float)
        return cls((float(mean[0]), float(mean[1])), (float(c[0, 0]), float(c[0, 1]), float(c[1, 0]), float(c[1, 1])),
                   float(delivered_c), float(q_max_nominal))

    @property
    def health(self) -> BelievedHealth:
        """The belief's Gaussian (:class:`~uam_studio.battery.health.belief.BelievedHealth`)."""
        cov = np.array(self.cov).reshape(2, 2)
        return BelievedHealth(inverse_capacity=self.mean[0], inverse_capacity_sd=math.sqrt(cov[0, 0]),
                              r0_ohm=self.mean[1], r0_sd_ohm=math.sqrt(cov[1, 1]), cov_w=cov)

    @property
    def prior(self) -> HealthPrior:
        """The belief as a prior (the start of a logbook's belief)."""
        return HealthPrior(np.array(self.mean), np.array(self.cov).reshape(2, 2))

    @property
    def q_max(self) -> float:
        return self.health.q_max_c

    @property
    def q_max_sd(self) -> float:
        return self.health.q_max_sd_c

    @property
    def r0(self) -> float:
        return self.mean[1]

    @property
    def r0_sd(self) -> float:
        return self.health.r0_sd_ohm

    def aged(self, charge_c: float, law: AgingLaw = AGING_LAW, process_sd: float = AGING_PROCESS_SD) -> PackBelief:
        """After delivering ``charge_c`` (C) more: :func:`~uam_studio.battery.health.belief.aged_belief`."""
        if not math.isfinite(charge_c) or charge_c < 0:
            raise InputError("charge_c", f"{charge_c!r}: allowed a finite charge >= 0 C")
        mean, cov = aged_belief(np.array(self.mean), np.array(self.cov).reshape(2, 2), self.delivered_c, charge_c,
                                self.q_max_nominal, law, process_sd=process_sd)
        return PackBelief.of(mean, cov, self.delivered_c + charge_c, self.q_max_nominal)

    def update(self, fit: FlightFit | None) -> PackBelief:
        """Multiplied by one flight's fit (its likelihood, :class:`~uam_studio.battery.health.logbook.FlightFit`);
        unchanged for a flight too short to fit (None)."""
        if fit is None:
            return self
        mean, cov = combine([(np.array(self.mean), np.array(self.cov).reshape(2, 2)), (fit.mean, fit.cov)])
        return PackBelief.of(mean, cov, self.delivered_c, self.q_max_nominal)


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

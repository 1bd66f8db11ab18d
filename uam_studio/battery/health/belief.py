"""A pack's health belief: the one type for what an operator, a fleet's dispatcher or a real-cell evaluator
believes of a cell's health (q_max, R0) and how sure it is.

The belief is Gaussian in (w, R0), w = 6500 C / q_max (the health fits' coordinates, in which the voltage is close
to linear). It is built from

1. the fleet prior (:func:`~uam_studio.battery.health.prior.fleet_prior`: the cell type's health box);
2. the pack's logbook (:class:`~uam_studio.battery.health.logbook.Logbook`), a Kalman filter over its flights:
   each finished flight's whole-record fit (stored in the logbook) multiplied in by precision, and the belief
   aged between flights by the aging law (:mod:`uam_studio.battery.aging`: q_max times ``c(e1) / c(e0)``, R0
   times ``r(e1) / r(e0)`` on the pack's equivalent full cycles, its delivered charge over the logbook's
   ``q_nominal_c``), with a process noise of :data:`AGING_PROCESS_SD` of each predicted change (the law is not
   exact);
3. this flight's readings from take-off on: the fit of all readings since each full charge (the fits of the
   flight's earlier charges kept), fitted without the prior and multiplied in once.

It answers three questions: the believed cell (:meth:`HealthBelief.health`, a :class:`BelievedHealth`), a cautious
cell at a stated risk (:meth:`BelievedHealth.cautious_q_max_c`, :meth:`BelievedHealth.cautious_r0_ohm`, with a
level of :mod:`uam_studio.risk`), and the end-of-discharge interval of a planned load
(:meth:`HealthBelief.eod_interval`).

Public API: :class:`HealthBelief`, :class:`BelievedHealth`, :func:`logbook_belief`, :func:`aged_belief`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from uam_studio.battery.aging import NASA_AGING_LAW, T_REF_C, AgingLaw
from uam_studio.battery.health.estimate import MIN_CONTEXT_S, HealthEstimate, clip_to_box, cov_qr
from uam_studio.battery.health.fit import fit_health
from uam_studio.battery.health.intervals import EodInterval, eod_interval_s
from uam_studio.battery.health.logbook import Logbook
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, combine, fleet_prior, hold_to_fleet
from uam_studio.battery.health.quality import FLAG_MISFIT, FLAG_OUTSIDE_FLEET, FLEET_Z, fit_flags
from uam_studio.battery.parameters import DEFAULT_CELL, CellParameters
from uam_studio.errors import InputError

__all__ = ["AGING_PROCESS_SD", "MIN_FIT_SAMPLES", "SOURCE_LOGBOOK", "SOURCE_TAKEOFF", "BelievedHealth",
           "ChargeReadings", "HealthBelief", "aged_belief", "logbook_belief"]

AGING_PROCESS_SD = 0.2  # std of the aging law's error, as a share of each predicted change of q_max and R0
SOURCE_LOGBOOK = "logbook"  # a belief that started from the pack's logbook
SOURCE_TAKEOFF = "take-off"  # one that started from the fleet prior: the take-off's readings are all it has
MIN_FIT_SAMPLES = int(MIN_CONTEXT_S)  # readings (at 1 Hz) before a fit: the fit's shortest context


@dataclass(frozen=True, kw_only=True)
class BelievedHealth:
    """What a belief holds of a cell's health: a Gaussian on ``inverse_capacity`` (6500 C / q_max,
    the health fits' linear parameter, dimensionless) with std ``inverse_capacity_sd``, and on
    ``r0_ohm`` (ohm) with std ``r0_sd_ohm``."""

    inverse_capacity: float
    inverse_capacity_sd: float
    r0_ohm: float
    r0_sd_ohm: float
    cov_w: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def q_max_c(self) -> float:
        """The believed q_max (C)."""
        return Q_REF_C / self.inverse_capacity

    @property
    def q_max_sd_c(self) -> float:
        """Its std (C), to first order."""
        return Q_REF_C * self.inverse_capacity_sd / self.inverse_capacity ** 2

    def cautious_q_max_c(self, z: float) -> float:
        """q_max (C) ``z`` std to the weak side (in inverse capacity, where the belief is Gaussian)."""
        return Q_REF_C / max(self.inverse_capacity + z * self.inverse_capacity_sd, 1e-3)

    def cautious_r0_ohm(self, z: float) -> float:
        """R0 (ohm) ``z`` std to the weak side."""
        return self.r0_ohm + z * self.r0_sd_ohm

    def in_units(self) -> dict[str, float]:
        """q_max and its std (C), R0 and its std (ohm), by the names a decision records them under."""
        return {"q_max_c": self.q_max_c, "q_max_sd_c": self.q_max_sd_c, "r0_ohm": self.r0_ohm,
                "r0_sd_ohm": self.r0_sd_ohm}

    def as_estimate(self) -> HealthEstimate:
        """This belief as a :class:`~uam_studio.battery.health.estimate.HealthEstimate` (for the interval
        functions of :mod:`uam_studio.battery.health.intervals`); without a covariance, the two stds uncorrelated."""
        cov = self.cov_w if self.cov_w is not None else np.diag([self.inverse_capacity_sd ** 2, self.r0_sd_ohm ** 2])
        return HealthEstimate(q_max=self.q_max_c, r0=self.r0_ohm, cov=cov_qr(self.inverse_capacity, cov),
                              noise_v=0.0, n_samples=0, cov_w=np.array(cov, dtype=float))


@dataclass
class ChargeReadings:
    """Readings (A, V) since the last full charge."""

    current: list[np.ndarray] = field(default_factory=list)
    voltage: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(current A, voltage V), one array each; empty before any reading."""
        if not self.current:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(self.current), np.concatenate(self.voltage)


def aged_belief(mean: np.ndarray, cov: np.ndarray, delivered_c: float, charge_c: float, q_nominal_c: float,
                aging: AgingLaw = NASA_AGING_LAW, temperature_c: float = T_REF_C,
                process_sd: float = AGING_PROCESS_SD) -> tuple[np.ndarray, np.ndarray]:
    """A belief ``(mean [2], cov [2, 2])`` in (w, R0) aged by ``aging`` over ``charge_c`` (C) more delivered by a
    pack that had delivered ``delivered_c`` (C) (equivalent full cycles: charge over ``q_nominal_c``, C), at
    ``temperature_c`` (C): q_max times ``c(e1) / c(e0)`` (so w over it), R0 times ``r(e1) / r(e0)``; each component's
    variance grows by (``process_sd`` of its predicted change)^2."""
    e0, e1 = delivered_c / q_nominal_c, (delivered_c + max(charge_c, 0.0)) / q_nominal_c
    fq = float(aging.capacity_fraction(e1, temperature_c)) / max(float(aging.capacity_fraction(e0, temperature_c)),
                                                                  1e-6)
    fr = float(aging.resistance_ratio(e1) / aging.resistance_ratio(e0))
    a = np.diag([1.0 / max(fq, 1e-6), fr])
    new = a @ np.asarray(mean, dtype=float)
    step = process_sd * (new - np.asarray(mean, dtype=float))
    return new, a @ np.asarray(cov, dtype=float) @ a + np.diag(step ** 2)


def logbook_belief(logbook: Logbook, prior: HealthPrior | None = None, aging: AgingLaw = NASA_AGING_LAW,
                   process_sd: float = AGING_PROCESS_SD, scatter: float = 0.0,
                   walk: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The belief ``(mean [2], cov [2, 2])`` in (w, R0) at the next take-off of the pack whose logbook is
    ``logbook``: ``prior`` (default: the default cell's fleet) times each flight's stored fit, aged by ``aging`` over
    each flight's charge (at its ambient temperature where known). Reads the stored fits only: no refit.

    A real cell's health also moves from one discharge to the next by more than its fit's std (a rest gives some
    capacity back, a cold or hot run takes some): ``scatter`` (a share of the mean) is added to each fit's std in
    both components, and ``walk`` (a share of the mean) is a random walk per flight. Both are 0 for a simulated
    pack, which ages exactly by its law."""
    start = prior if prior is not None else fleet_prior()
    mean, cov = np.array(start.mean, dtype=float), np.array(start.cov, dtype=float)
    delivered = logbook.delivered_before_c
    for flight in logbook.flights:
        if flight.fit is not None:
            fit_cov = flight.fit.cov + np.diag((scatter * np.abs(flight.fit.mean)) ** 2)
            mean, cov = combine([(mean, cov), (flight.fit.mean, fit_cov)])
        temp = flight.ambient_c if math.isfinite(flight.ambient_c) else T_REF_C
        mean, cov = aged_belief(mean, cov, delivered, flight.charge_c, logbook.q_nominal_c, aging, temp, process_sd)
        cov = cov + np.diag((walk * np.abs(mean)) ** 2)
        delivered += flight.charge_c
    return mean, 0.5 * (cov + cov.T)


class HealthBelief:
    """The health belief of one pack over its logbook and this flight's charges (module docstring).

    :param noise_v: the voltage sensor's stated noise std (V), or None to estimate it from the residuals.
    :param eod_v: the cut-off (V).
    :param prior: the fleet's health box (default: the paper's, the default cell's fleet,
        :func:`~uam_studio.battery.health.prior.fleet_prior`): the start of a new pack's belief, and the box a
        belief is held to where readings put the cell beyond its optimistic edge.
    :param logbook: the pack's logbook (None or empty: a new pack, the belief starts from ``prior``).
    :param aging: the aging law between the logbook's flights.
    :param dt_s: the readings' step (s).
    :param cell: the parameter set this flight's readings are fitted, and its intervals simulated, on.
    :param scatter: :func:`logbook_belief`'s flight-to-flight scatter (a share of the mean; 0: a simulated pack).
    :param walk: :func:`logbook_belief`'s random walk per flight (a share of the mean).
    """

    def __init__(self, noise_v: float | None, eod_v: float, prior: HealthPrior | None = None,
                 logbook: Logbook | None = None, aging: AgingLaw = NASA_AGING_LAW, dt_s: float = 1.0,
                 cell: CellParameters = DEFAULT_CELL, scatter: float = 0.0, walk: float = 0.0) -> None:
        self.noise_v = noise_v
        self.eod_v = eod_v
        self.dt_s = float(dt_s)
        self.cell = cell
        self.prior = prior if prior is not None else fleet_prior()
        self.logbook = logbook if logbook is not None else Logbook()
        self.start = (HealthPrior(*logbook_belief(self.logbook, self.prior, aging, scatter=scatter, walk=walk))
                      if len(self.logbook) else self.prior)
        self.segment = ChargeReadings()
        self.charges: list[ChargeReadings] = []  # this flight's earlier charges, as read
        self.past: list[HealthEstimate] = []  # the fits of this flight's earlier charges
        self._fitted: tuple[ChargeReadings, int, HealthEstimate | None] | None = None  # this charge's fit, by length

    @property
    def source(self) -> str:
        """Where the belief started: :data:`SOURCE_LOGBOOK` (a logbook with a fitted flight) or
        :data:`SOURCE_TAKEOFF` (the fleet prior: this flight's readings are all it knows)."""
        return SOURCE_LOGBOOK if any(f.fit is not None for f in self.logbook.flights) else SOURCE_TAKEOFF

    def observe(self, current_a: np.ndarray, voltage_v: np.ndarray) -> None:
        """Readings (A, V) at the belief's step."""
        self.segment.current.append(np.asarray(current_a, dtype=float))
        self.segment.voltage.append(np.asarray(voltage_v, dtype=float))

    def recharged(self) -> None:
        """Landed at the vertiport and recharged: this charge's fit joins the earlier ones."""
        est = self.fit()
        if est is not None:
            self.past.append(est)
        self.charges.append(self.segment)
        self.segment = ChargeReadings()

    def flown(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """This flight's readings, one ``(current A, voltage V)`` per charge (the last one's so far): what the
        pack's logbook takes when the flight ends."""
        return [c.arrays() for c in [*self.charges, self.segment] if c.current]

    def fit(self) -> HealthEstimate | None:
        """The likelihood of this charge's readings (no prior: it is multiplied in once, by
        :meth:`health`); None below :data:`MIN_FIT_SAMPLES` readings. Fitted once per reading count: every
        query of the same readings (:meth:`health`, :meth:`flags`) reads the same fit."""
        cur, volt = self.segment.arrays()
        if self._fitted is not None and self._fitted[0] is self.segment and self._fitted[1] == cur.size:
            return self._fitted[2]
        est = None if cur.size * self.dt_s < MIN_FIT_SAMPLES else fit_health(
            cur, volt, self.dt_s, noise_v=self.noise_v, eod_v=self.eod_v, cell=self.cell, prior=False)
        self._fitted = (self.segment, cur.size, est)
        return est

    def health(self) -> BelievedHealth:
        """The belief from the logbook, all readings so far and the prior. Readings that put the cell beyond its
        prior's box on the optimistic side are held with caution
        (:func:`~uam_studio.battery.health.prior.hold_to_fleet`: a cell better than any of its fleet is planned as
        the fleet's best, with the difference in its std).

        :raises InputError: fewer than :data:`MIN_FIT_SAMPLES` readings in all and no logbook.
        """
        est = self.fit()
        fits = self.past + ([est] if est is not None else [])
        if not fits and self.source == SOURCE_TAKEOFF:
            raise InputError("readings", f"at least {MIN_FIT_SAMPLES} s of readings are needed before planning")
        parts = [(self.start.mean, self.start.cov)] + [(np.array([e.w, e.r0]), e.cov_w) for e in fits]
        mean, cov = combine(parts)
        if fits:  # readings that put the cell beyond the optimistic edge of its prior's box are held with caution
            lik_mean, lik_cov = combine([(np.array([e.w, e.r0]), e.cov_w / e.discrepancy_factor)
                                         for e in fits])  # face value
            mean, cov = hold_to_fleet(mean, cov, lik_mean, lik_cov, self.prior, FLEET_Z)
        # the Gaussian combination can put the mean a little outside the fit's box (a cell at its edge,
        # R0 = 0 say): the estimate the operator plans with stays inside it
        w, r0 = clip_to_box(mean)
        return BelievedHealth(inverse_capacity=float(w), inverse_capacity_sd=float(math.sqrt(cov[0, 0])),
                              r0_ohm=float(r0), r0_sd_ohm=float(math.sqrt(cov[1, 1])), cov_w=cov)

    def flags(self) -> tuple[str, ...]:
        """The flags of the fits behind the belief (this charge's readings so far and the earlier charges'), each
        once, in :func:`~uam_studio.battery.health.quality.fit_flags` order; the same whether or not
        :meth:`health` has run."""
        est = self.fit()
        fits = self.past + ([est] if est is not None else [])
        return fit_flags(any(FLAG_MISFIT in e.flags for e in fits), any(FLAG_OUTSIDE_FLEET in e.flags for e in fits))

    def prior_health(self) -> BelievedHealth:
        """The belief before this flight's readings: the fleet prior, or the logbook's belief."""
        mean, cov = self.start.mean, self.start.cov
        return BelievedHealth(inverse_capacity=float(mean[0]), inverse_capacity_sd=math.sqrt(cov[0, 0]),
                              r0_ohm=float(mean[1]), r0_sd_ohm=math.sqrt(cov[1, 1]), cov_w=np.array(cov))

    def eod_interval(self, current_a: np.ndarray, level: float = 0.9) -> EodInterval:
        """The ``level`` interval (s) of the end of discharge of a planned load ``current_a`` (A at the belief's step,
        from a full charge) on the believed cell (the physics model at the belief's sigma points)."""
        h = self.health() if (self.segment.current or self.past) else self.prior_health()
        return eod_interval_s(h.as_estimate(), current_a, self.dt_s, level, self.eod_v, cell=self.cell)

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

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from uam_studio.battery.aging import NASA_AGING_LAW, T_REF_C, AgingLaw
from uam_studio.battery.health.config import AGING_PROCESS_SD, PAPER_BELIEF, BeliefConfig
from uam_studio.battery.health.estimate import MIN_CONTEXT_S, HealthEstimate, clip_to_box, cov_qr
from uam_studio.battery.health.fit import fit_health
from uam_studio.battery.health.intervals import EodInterval, band_from_sigma_points, eod_interval_s, two_sided_z
from uam_studio.battery.health.logbook import Logbook, LoggedFlight
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, combine, hold_to_fleet
from uam_studio.battery.health.quality import FLAG_MISFIT, FLAG_OUTSIDE_FLEET, FLEET_Z, fit_flags
from uam_studio.battery.parameters import DEFAULT_Q_MAX, CellParameters
from uam_studio.battery.simulate import CURRENT_LIMIT_A, EOD_RANGE, simulate
from uam_studio.errors import InputError

__all__ = ["AGING_PROCESS_SD", "MIN_FIT_SAMPLES", "SOURCE_LOGBOOK", "SOURCE_TAKEOFF", "BelievedHealth",
           "ChargeReadings", "HealthBelief", "ModelError", "PackBelief", "aged_belief", "error_share",
           "flight_residual_sd_v", "logbook_belief", "model_error"]

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

    @classmethod
    def of(cls, mean: Sequence[float] | np.ndarray, cov: np.ndarray) -> BelievedHealth:
        """The belief of the Gaussian ``mean`` (w, R0 ohm) and ``cov`` (2x2, in (w, R0); copied)."""
        c = np.array(cov, dtype=float)
        return cls(inverse_capacity=float(mean[0]), inverse_capacity_sd=math.sqrt(c[0, 0]), r0_ohm=float(mean[1]),
                   r0_sd_ohm=math.sqrt(c[1, 1]), cov_w=c)

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


@dataclass(frozen=True)
class PackBelief:
    """What a pack's logbook says of its health at the next take-off: one immutable value, changed only by pure
    methods (:meth:`logged`: a flight's fit multiplied in, then aged over its charge). A Gaussian in (w, R0)
    (w = 6500 C / q_max) with mean ``mean`` and covariance ``cov`` (row-major, 4 floats), the charge the pack has
    delivered (``delivered_c``, C, measured), the aging clock's unit (``q_nominal_c``, C) and the cell type's
    declared ``config``. :meth:`of` builds it from a logbook; :attr:`health` is its
    :class:`BelievedHealth`. An in-flight :class:`HealthBelief` starts from it; a fleet's dispatcher reads it."""

    mean: tuple[float, float]
    cov: tuple[float, float, float, float]
    delivered_c: float
    q_nominal_c: float
    config: BeliefConfig = PAPER_BELIEF

    @classmethod
    def start(cls, config: BeliefConfig = PAPER_BELIEF, delivered_c: float = 0.0,
              q_nominal_c: float = DEFAULT_Q_MAX) -> PackBelief:
        """The belief of a pack with an empty logbook that has delivered ``delivered_c`` (C): the cell type's box
        (``config.prior``), or, where the config declares a new pack's prior (``config.new_pack``), that prior aged
        by the law over ``delivered_c``."""
        if config.new_pack is None:
            return cls._of(config.prior.mean, config.prior.cov, delivered_c, q_nominal_c, config)
        new = cls._of(config.new_pack.mean, config.new_pack.cov, 0.0, q_nominal_c, config)
        return new.aged(delivered_c)

    @classmethod
    def of(cls, logbook: Logbook, config: BeliefConfig = PAPER_BELIEF,
           since: tuple[Logbook, PackBelief] | None = None) -> PackBelief:
        """The belief at the next take-off of the pack whose logbook is ``logbook``: :meth:`start`, then
        :meth:`logged` for each flight. Reads the stored fits only: no refit. ``since``: an earlier logbook of the
        pack and its belief; where ``logbook`` only grew from it (the same flights first), the belief goes on from
        there (the same steps)."""
        belief, done = cls.start(config, logbook.delivered_before_c, logbook.q_nominal_c), 0
        if since is not None:
            old, known = since
            n = len(old)
            if known.config == config and old.delivered_before_c == logbook.delivered_before_c and len(logbook) >= n \
                    and (n == 0 or logbook.flights[n - 1] is old.flights[-1]):
                belief, done = known, n
        for flight in logbook.flights[done:]:
            belief = belief.logged(flight)
        return belief

    @classmethod
    def _of(cls, mean: np.ndarray, cov: np.ndarray, delivered_c: float, q_nominal_c: float,
            config: BeliefConfig) -> PackBelief:
        c = np.asarray(cov, dtype=float)
        return cls((float(mean[0]), float(mean[1])), (float(c[0, 0]), float(c[0, 1]), float(c[1, 0]), float(c[1, 1])),
                   float(delivered_c), float(q_nominal_c), config)

    @property
    def cov_matrix(self) -> np.ndarray:
        """The 2x2 covariance of (w, R0)."""
        return np.array(self.cov, dtype=float).reshape(2, 2)

    @property
    def health(self) -> BelievedHealth:
        """Its Gaussian as a :class:`BelievedHealth`."""
        return BelievedHealth.of(self.mean, self.cov_matrix)

    @property
    def prior(self) -> HealthPrior:
        """The belief as a prior (the start of a flight's :class:`HealthBelief`)."""
        return HealthPrior(np.array(self.mean), self.cov_matrix)

    def aged(self, charge_c: float, temperature_c: float = T_REF_C) -> PackBelief:
        """After delivering ``charge_c`` (C) more at ``temperature_c`` (C): :func:`aged_belief` by the config's law
        and process noise, then its random walk (``config.walk``, a share of the mean)."""
        if not math.isfinite(charge_c) or charge_c < 0:
            raise InputError("charge_c", f"{charge_c!r}: allowed a finite charge >= 0 C")
        cfg = self.config
        mean, cov = aged_belief(np.array(self.mean), self.cov_matrix, self.delivered_c, charge_c, self.q_nominal_c,
                                cfg.aging, temperature_c, cfg.process_sd)
        cov = cov + np.diag((cfg.walk * np.abs(mean)) ** 2)
        return PackBelief._of(mean, 0.5 * (cov + cov.T), self.delivered_c + charge_c, self.q_nominal_c, cfg)

    def logged(self, flight: LoggedFlight) -> PackBelief:
        """After one more logged flight: its fit multiplied in (its std widened by ``config.scatter``, a share of
        the mean; none for a flight too short to fit), then aged over its charge at its ambient temperature (25 C
        where unknown)."""
        belief = self
        if flight.fit is not None:
            fit_cov = flight.fit.cov + np.diag((self.config.scatter * np.abs(flight.fit.mean)) ** 2)
            mean, cov = combine([(np.array(self.mean), self.cov_matrix), (flight.fit.mean, fit_cov)])
            belief = PackBelief._of(mean, cov, self.delivered_c, self.q_nominal_c, self.config)
        temp = flight.ambient_c if math.isfinite(flight.ambient_c) else T_REF_C
        return belief.aged(flight.charge_c, temp)


def logbook_belief(logbook: Logbook, config: BeliefConfig = PAPER_BELIEF) -> tuple[np.ndarray, np.ndarray]:
    """``(mean [2], cov [2, 2])`` in (w, R0) of :meth:`PackBelief.of`."""
    b = PackBelief.of(logbook, config)
    return np.array(b.mean), b.cov_matrix


@dataclass(frozen=True)
class ModelError:
    """The belief's model-error term: ``sd_v`` (V), the std of the voltage its model cannot explain once the health
    is known, pooled from the cell type's prior ``prior_sd_v`` (V, worth ``prior_flights`` flights) and ``flights``
    logged flights' residuals (:func:`model_error`); ``low_sd_v`` (V), its std below the median where the error is
    skewed (a take-off's belief), 0 where it is not."""

    sd_v: float
    prior_sd_v: float
    prior_flights: float
    flights: int
    low_sd_v: float = 0.0

    @property
    def below_v(self) -> float:
        """The term's std below the median (V)."""
        return max(self.low_sd_v, self.sd_v)


def flight_residual_sd_v(flight: LoggedFlight, params: CellParameters) -> float | None:
    """The std (V) of what ``flight``'s own fit on ``params`` does not explain of its voltage, beyond the sensor's
    white noise: the residual's mean square less the white noise's (half the mean square of the residual's
    sample-to-sample change, which a slow model error hardly moves); None for a flight without a fit."""
    if flight.fit is None:
        return None
    cur = np.clip(np.asarray(flight.current_a, dtype=float), -CURRENT_LIMIT_A, CURRENT_LIMIT_A)
    model = simulate(cur, flight.dt_s, Q_REF_C / flight.fit.w, flight.fit.r0_ohm, eod_v=EOD_RANGE[0],
                     cell=params).voltage_v
    k = min(model.size, flight.voltage_v.size)
    if k < 3:
        return None
    r = np.asarray(flight.voltage_v[:k], dtype=float) - model[:k]
    white = 0.5 * float(np.mean(np.diff(r) ** 2))
    return math.sqrt(max(float(np.mean(r ** 2)) - white, 0.0))


def model_error(logbook: Logbook, config: BeliefConfig = PAPER_BELIEF) -> ModelError:
    """The model-error term of the pack whose logbook is ``logbook``: the prior's variance
    (``config.model_error_sd_v``, worth ``config.model_error_flights`` flights) pooled with each fitted flight's
    residual variance (:func:`flight_residual_sd_v`)."""
    sds = [s for f in logbook.flights if (s := flight_residual_sd_v(f, config.params)) is not None]
    k0 = config.model_error_flights
    var = (k0 * config.model_error_sd_v ** 2 + sum(s * s for s in sds)) / max(k0 + len(sds), 1e-12)
    return ModelError(math.sqrt(var), config.model_error_sd_v, k0, len(sds))


def error_share(interval: Sequence[float], error: ModelError, level: float = 0.9) -> float:
    """The share (0-1) of a ``level`` interval's variance (``interval``: low, median, high, V) that the model-error
    term ``error`` makes up, each side's (its std above and below the median) over that side's, averaged."""
    z = two_sided_z(level)
    shares = [min(e ** 2 / (w / z) ** 2, 1.0) if w > 0 else 0.0
              for e, w in ((error.below_v, interval[1] - interval[0]), (error.sd_v, interval[2] - interval[1]))]
    return float(sum(shares) / 2)


class HealthBelief:
    """The health belief of one pack over its logbook and this flight's charges (module docstring).

    :param noise_v: the voltage sensor's stated noise std (V), or None to estimate it from the residuals.
    :param eod_v: the cut-off (V).
    :param logbook: the pack's logbook (None or empty: a new pack, the belief starts from the cell type's prior).
    :param config: the cell type's declared configuration (:mod:`uam_studio.battery.health.config`): the parameter
        set this flight's readings are fitted, and its intervals simulated, on; the prior (the start of a new
        pack's belief, and the box a belief is held to where readings put the cell beyond its optimistic edge); the
        aging law and noise between the logbook's flights; the model-error prior.
    :param dt_s: the readings' step (s).
    """

    def __init__(self, noise_v: float | None, eod_v: float, logbook: Logbook | None = None,
                 config: BeliefConfig = PAPER_BELIEF, dt_s: float = 1.0) -> None:
        self.noise_v = noise_v
        self.eod_v = eod_v
        self.dt_s = float(dt_s)
        self.config = config
        self.cell = config.params
        self.prior = config.prior
        self.logbook = logbook if logbook is not None else Logbook()
        self.pack = PackBelief.of(self.logbook, config)  # what the logbook says at take-off
        self.start = self.pack.prior if len(self.logbook) else self.prior
        self._logged_error: ModelError | None = None  # from the logbook, on first use: fixed for this flight
        self.segment = ChargeReadings()
        self.charges: list[ChargeReadings] = []  # this flight's earlier charges, as read
        self.past: list[HealthEstimate] = []  # the fits of this flight's earlier charges
        self._fitted: tuple[ChargeReadings, int, HealthEstimate | None] | None = None  # this charge's fit, by length

    @property
    def logged_error(self) -> ModelError:
        """The logbook's model-error term (:func:`model_error`), computed once, on first use."""
        if self._logged_error is None:
            self._logged_error = model_error(self.logbook, self.config)
        return self._logged_error

    @property
    def model_error(self) -> ModelError:
        """The model-error term now: the logbook's (:func:`model_error`), or, for a belief that holds no logged
        flight and less than ``config.takeoff_span_s`` of readings, the take-off's
        (``config.takeoff_model_error_sd_v``, below the median ``config.takeoff_model_error_low_sd_v``)."""
        n = sum(c.size for c in self.segment.current) + sum(sum(x.size for x in c.current) for c in self.charges)
        if self.logged_error.flights == 0 and n * self.dt_s < self.config.takeoff_span_s:
            sd = max(self.config.takeoff_model_error_sd_v, self.logged_error.sd_v)
            return dataclasses.replace(self.logged_error, sd_v=sd, low_sd_v=self.config.takeoff_model_error_low_sd_v)
        return self.logged_error

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
        the fleet's best, with the difference in its std; a pack whose logbook already holds it beyond that edge is
        held at its logbook's belief instead).

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
            mean, cov = hold_to_fleet(mean, cov, lik_mean, lik_cov, self.prior, FLEET_Z,
                                      self.start.mean if self.source == SOURCE_LOGBOOK else None)
        # the Gaussian combination can put the mean a little outside the fit's box (a cell at its edge,
        # R0 = 0 say): the estimate the operator plans with stays inside it
        return BelievedHealth.of(clip_to_box(mean), cov)

    def flags(self) -> tuple[str, ...]:
        """The flags of the fits behind the belief (this charge's readings so far and the earlier charges'), each
        once, in :func:`~uam_studio.battery.health.quality.fit_flags` order; the same whether or not
        :meth:`health` has run."""
        est = self.fit()
        fits = self.past + ([est] if est is not None else [])
        return fit_flags(any(FLAG_MISFIT in e.flags for e in fits), any(FLAG_OUTSIDE_FLEET in e.flags for e in fits))

    def prior_health(self) -> BelievedHealth:
        """The belief before this flight's readings: the fleet prior, or the logbook's belief."""
        return BelievedHealth.of(self.start.mean, self.start.cov)

    def lowest_voltage(self, currents: Sequence[np.ndarray], after: int, level: float = 0.9
                       ) -> tuple[float, float, float]:
        """The ``level`` interval (low, median, high; V) of the lowest voltage after sample ``after`` of a planned
        load from a full charge (``currents[0]``, A at the belief's step, this charge's readings so far first), on
        the believed cell: the median at the believed health; the std from the health (the 5 sigma points in
        (w, R0)), from each pair ``currents[1:]`` (the same load under conditions one std either side, the wind's:
        half their difference) and from the model-error term (:attr:`model_error`; its own std below the median), in
        quadrature."""
        h = self.health() if (self.segment.current or self.past) else self.prior_health()
        pts = h.as_estimate().sigma_points()
        runs = [(c, q, r) for c, (q, r) in [(currents[0], p) for p in pts] + [(c, pts[0]) for c in currents[1:]]]
        lows = np.array([float(np.min(simulate(np.clip(c, -CURRENT_LIMIT_A, CURRENT_LIMIT_A), self.dt_s, q, r,
                                               eod_v=EOD_RANGE[0], cell=self.cell).voltage_v[after:], initial=5.0))
                         for c, q, r in runs])
        conditions = sum(((lows[k] - lows[k + 1]) / 2) ** 2 for k in range(5, lows.size - 1, 2))
        err = self.model_error
        _, med, hi = band_from_sigma_points(lows[:5, None], level, math.sqrt(err.sd_v ** 2 + conditions))
        lo = band_from_sigma_points(lows[:5, None], level, math.sqrt(err.below_v ** 2 + conditions))[0]
        return float(lo[0]), float(med[0]), float(hi[0])

    def model_error_share(self, current_a: np.ndarray, after: int) -> float:
        """The model-error term's share of the variance of the lowest voltage of a planned load
        (:func:`error_share` of :meth:`lowest_voltage`'s interval, without conditions)."""
        return error_share(self.lowest_voltage([current_a], after), self.model_error)

    def eod_interval(self, current_a: np.ndarray, level: float = 0.9) -> EodInterval:
        """The ``level`` interval (s) of the end of discharge of a planned load ``current_a`` (A at the belief's step,
        from a full charge) on the believed cell (the physics model at the belief's sigma points)."""
        h = self.health() if (self.segment.current or self.past) else self.prior_health()
        return eod_interval_s(h.as_estimate(), current_a, self.dt_s, level, self.eod_v, cell=self.cell)

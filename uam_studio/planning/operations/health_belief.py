"""What the operator believes about its cell's health: the fleet prior, times the health fit of every
charge flown so far (:func:`uam_studio.battery.health.fit.fit_health` of all readings since each full
charge, fitted without the prior and multiplied by it once).

Public API: :class:`HealthBelief` (``observe`` readings, ``recharged`` at the vertiport, ``health``: a
:class:`BelievedHealth`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from uam_studio.battery.health.estimate import MIN_CONTEXT_S, HealthEstimate, clip_to_box
from uam_studio.battery.health.fit import fit_health
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, combine, fleet_prior, hold_to_fleet
from uam_studio.battery.health.quality import FLAG_MISFIT, FLAG_OUTSIDE_FLEET, FLEET_Z, fit_flags
from uam_studio.errors import InputError
from uam_studio.planning.legs import DT_S

__all__ = ["MIN_FIT_SAMPLES", "BelievedHealth", "ChargeReadings", "HealthBelief"]

MIN_FIT_SAMPLES = int(MIN_CONTEXT_S)  # readings (1 Hz) before a fit: the fit's shortest context


@dataclass(frozen=True, kw_only=True)
class BelievedHealth:
    """What the operator believes of its cell's health: a Gaussian on ``inverse_capacity`` (6500 C / q_max,
    the health fits' linear parameter, dimensionless) with std ``inverse_capacity_sd``, and on
    ``r0_ohm`` (ohm) with std ``r0_sd_ohm``."""

    inverse_capacity: float
    inverse_capacity_sd: float
    r0_ohm: float
    r0_sd_ohm: float

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


@dataclass
class ChargeReadings:
    """Readings (A, V at 1 Hz) since the last full charge."""

    current: list[np.ndarray] = field(default_factory=list)
    voltage: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(current A, voltage V), one array each; empty before any reading."""
        if not self.current:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(self.current), np.concatenate(self.voltage)


class HealthBelief:
    """The health belief of one cell over its charges.

    :param noise_v: the voltage sensor's stated noise std (V), or None to estimate it from the residuals.
    :param eod_v: the cut-off (V).
    :param prior: what is known before any reading; default: the paper's health box (the fleet of the
        default cell, :func:`~uam_studio.battery.health.prior.fleet_prior`).
    """

    def __init__(self, noise_v: float | None, eod_v: float, prior: HealthPrior | None = None) -> None:
        self.noise_v = noise_v
        self.eod_v = eod_v
        self.prior = prior if prior is not None else fleet_prior()
        self.segment = ChargeReadings()
        self.past: list[HealthEstimate] = []  # the fits of earlier charges
        self.estimate: HealthEstimate | None = None  # the latest fit of this charge

    def observe(self, current_a: np.ndarray, voltage_v: np.ndarray) -> None:
        """ChargeReadings (A, V) at 1 Hz."""
        self.segment.current.append(np.asarray(current_a, dtype=float))
        self.segment.voltage.append(np.asarray(voltage_v, dtype=float))

    def recharged(self) -> None:
        """Landed at the vertiport and recharged: this charge's fit joins the earlier ones."""
        est = self.fit()
        if est is not None:
            self.past.append(est)
        self.segment = ChargeReadings()

    def fit(self) -> HealthEstimate | None:
        """The likelihood of this charge's readings (no prior: it is multiplied in once, by
        :meth:`health`); None below :data:`MIN_FIT_SAMPLES` readings."""
        cur, volt = self.segment.arrays()
        if cur.size < MIN_FIT_SAMPLES:
            return None
        return fit_health(cur, volt, DT_S, noise_v=self.noise_v, eod_v=self.eod_v, prior=False)

    def health(self) -> BelievedHealth:
        """The belief from all readings so far and the prior. Readings that put the cell beyond its prior's box on the
        optimistic side are held with caution (:func:`~uam_studio.battery.health.prior.hold_to_fleet`: a cell better
        than any of its fleet is planned as the fleet's best, with the difference in its std).

        :raises InputError: fewer than :data:`MIN_FIT_SAMPLES` readings in all.
        """
        est = self.fit()
        self.estimate = est if est is not None else self.estimate
        fits = self.past + ([est] if est is not None else [])
        if not fits:
            raise InputError("readings", f"at least {MIN_FIT_SAMPLES} s of readings are needed before planning")
        parts = [(self.prior.mean, self.prior.cov)] + [(np.array([e.w, e.r0]), e.cov_w) for e in fits]
        mean, cov = combine(parts)
        # readings that put the cell beyond the optimistic edge of its prior's box are held with caution
        lik_mean, lik_cov = combine([(np.array([e.w, e.r0]), e.cov_w / e.discrepancy_factor)
                                     for e in fits])  # face value
        mean, cov = hold_to_fleet(mean, cov, lik_mean, lik_cov, self.prior, FLEET_Z)
        # the Gaussian combination can put the mean a little outside the fit's box (a cell at its edge,
        # R0 = 0 say): the estimate the operator plans with stays inside it
        w, r0 = clip_to_box(mean)
        return BelievedHealth(inverse_capacity=float(w), inverse_capacity_sd=float(math.sqrt(cov[0, 0])),
                              r0_ohm=float(r0), r0_sd_ohm=float(math.sqrt(cov[1, 1])))

    def flags(self) -> tuple[str, ...]:
        """The flags of the fits behind the belief (this charge's latest and the earlier charges'), each
        once, in :func:`~uam_studio.battery.health.quality.fit_flags` order."""
        fits = self.past + ([self.estimate] if self.estimate is not None else [])
        return fit_flags(any(FLAG_MISFIT in e.flags for e in fits), any(FLAG_OUTSIDE_FLEET in e.flags for e in fits))

    def prior_health(self) -> BelievedHealth:
        """The prior alone."""
        mean, cov = self.prior.mean, self.prior.cov
        return BelievedHealth(inverse_capacity=float(mean[0]), inverse_capacity_sd=math.sqrt(cov[0, 0]),
                              r0_ohm=float(mean[1]), r0_sd_ohm=math.sqrt(cov[1, 1]))

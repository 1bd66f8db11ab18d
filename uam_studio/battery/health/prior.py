"""What is known of a cell's health before it is measured: the health range of its fleet, as a
Gaussian prior on (w, R0) with w = 6500 C / q_max (the coordinates of the health fit, in which the
voltage is close to linear).

Public API:

- :class:`HealthPrior`: mean (w, R0 ohm) and 2x2 covariance in (w, R0).
- :func:`fleet_prior`: the prior of a cell type, from its parameter set's ``fleet_q_range`` (C) and
  ``fleet_r0_range`` (ohm): the mean and std of a cell drawn uniformly from that box.
- :func:`combine`: Gaussians in (w, R0) multiplied by precision (a prior and independent fits).

A 20 s take-off says much about R0 and little about q_max; with a noisy sensor it says little about
either, and the fleet's range is then most of what is known. The health fit
(:func:`uam_studio.battery.health.fit.fit_health`) multiplies its likelihood's Gaussian by this prior by
default; the operator, which combines the fits of several charges, multiplies the prior in once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uam_studio.battery.parameters import DEFAULT_CELL, CellParameters

__all__ = ["Q_REF_C", "HealthPrior", "combine", "fleet_prior"]

Q_REF_C = 6500.0  # C: w = Q_REF_C / q_max


@dataclass(frozen=True, eq=False)
class HealthPrior:
    """A Gaussian belief on (w, R0), w = 6500 C / q_max.

    :param mean: (w, R0 ohm).
    :param cov: 2x2 covariance of (w, R0) (-, -ohm, ohm^2).
    """

    mean: np.ndarray
    cov: np.ndarray

    @classmethod
    def from_ranges(cls, q_range: tuple[float, float], r0_range: tuple[float, float]) -> HealthPrior:
        """The mean and covariance of a cell drawn uniformly from the box ``q_range`` (C) x
        ``r0_range`` (ohm), uniform in (w, R0)."""
        w = (Q_REF_C / q_range[1], Q_REF_C / q_range[0])
        mean = np.array([sum(w) / 2, sum(r0_range) / 2])
        sd = np.array([w[1] - w[0], r0_range[1] - r0_range[0]]) / math.sqrt(12.0)
        return cls(mean, np.diag(sd ** 2))

    @property
    def q_max(self) -> float:
        """q_max (C) at the prior's mean."""
        return Q_REF_C / float(self.mean[0])

    @property
    def half_width(self) -> np.ndarray:
        """Half the widths (w, R0 ohm) of the box the prior stands for: its mean +- sqrt(3) std (the
        uniform box :meth:`from_ranges` made it from)."""
        return math.sqrt(3.0) * np.sqrt(np.diag(self.cov))


def fleet_prior(cell: CellParameters = DEFAULT_CELL) -> HealthPrior:
    """The prior of a cell of type ``cell``: its fleet's health box (``cell.fleet_q_range`` C,
    ``cell.fleet_r0_range`` ohm) as a Gaussian (:meth:`HealthPrior.from_ranges`)."""
    return HealthPrior.from_ranges(cell.fleet_q_range, cell.fleet_r0_range)


def combine(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Gaussians ``(mean [2], cov [2, 2])`` in (w, R0) multiplied by precision: ``(mean, cov)``."""
    prec = np.zeros((2, 2))
    vec = np.zeros(2)
    for mean, cov in parts:
        cov = np.asarray(cov, dtype=float)
        p = np.linalg.inv(cov + np.diag(1e-9 * np.abs(np.diag(cov)) + 1e-300))  # relative jitter: never singular
        prec += p
        vec += p @ np.asarray(mean, dtype=float)
    cov = np.linalg.inv(prec)
    return cov @ vec, cov


def hold_to_fleet(mean: np.ndarray, cov: np.ndarray, likelihood_mean: np.ndarray, likelihood_cov: np.ndarray,
                  prior: HealthPrior, z: float, known: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A belief ``(mean [2], cov [2, 2])`` in (w, R0) held with caution where the readings alone
    (``likelihood_mean``, ``likelihood_cov``) put the cell more than ``z`` of their std beyond the
    optimistic edge of ``prior``'s box (w below it: q_max above every fleet cell's; R0 below every
    fleet cell's): in that component the mean is moved no further than the fleet's best cell, and the
    variance grows by the squared distance from the readings' value to that mean (so the belief still
    holds both). Components inside the box, or beyond its pessimistic edge, are left as they are; the
    correlation is kept. ``known`` (w, R0): what the pack's own logbook already holds; where it lies beyond the box's
    optimistic edge, the edge is moved out to it (readings that agree with the pack's history are not held)."""
    mean = np.asarray(mean, dtype=float).copy()
    cov = np.asarray(cov, dtype=float)
    lik = np.asarray(likelihood_mean, dtype=float)
    lik_sd = np.sqrt(np.maximum(np.diag(np.asarray(likelihood_cov, dtype=float)), 0.0))
    edge = prior.mean - prior.half_width  # the box's optimistic edge
    if known is not None:
        edge = np.minimum(edge, np.asarray(known, dtype=float))
    beyond = edge - lik > z * lik_sd
    if not beyond.any():
        return mean, cov
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov[0, 1] / max(sd[0] * sd[1], 1e-300)
    mean = np.where(beyond, np.maximum(mean, edge), mean)
    sd = np.where(beyond, np.sqrt(sd ** 2 + (mean - lik) ** 2), sd)
    off = corr * sd[0] * sd[1]
    return mean, np.array([[sd[0] ** 2, off], [off, sd[1] ** 2]])


def disagrees(mean: np.ndarray, cov: np.ndarray, prior: HealthPrior, z: float) -> np.ndarray:
    """Per component of (w, R0): whether ``mean`` lies more than ``z`` of its std (from ``cov``) outside
    the box that ``prior`` stands for (:attr:`HealthPrior.half_width`)."""
    sd = np.sqrt(np.maximum(np.diag(np.asarray(cov, dtype=float)), 0.0))
    return np.abs(np.asarray(mean, dtype=float) - prior.mean) - prior.half_width > z * sd

"""Health embeddings of a population of simulated cells (the "training population" view).

:func:`health_population` draws ``n`` cells uniformly over the Dynaformer's training ranges
(q_max 5000-8000 C, R0 0.017-0.45 ohm, :mod:`uam_studio.dynaformer.data`), flies each one through
the same observation window with the physics model, and returns the predictor's health principal
components for all of them in one batch. The app plots one cell's estimate against this cloud.

The observation window (current, A, on a 1 s grid) is an argument: the planner observes the
first 20 s of a take-off (:func:`uam_studio.planning.env.takeoff_context_current`), and this
module sits below ``planning`` in the layering, so it does not build that profile itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..battery import EOD_RANGE, simulate
from ..errors import InputError
from .data import TRAIN_Q_RANGE, TRAIN_R_RANGE

__all__ = ["HealthPopulation", "health_population"]

MAX_POPULATION = 5000


@dataclass(frozen=True)
class HealthPopulation:
    """``n`` cells: their health parameters and the predictor's two health PCs (arrays of shape [n])."""

    q_max: np.ndarray
    r0: np.ndarray
    pc1: np.ndarray
    pc2: np.ndarray

    def __len__(self) -> int:
        return int(self.q_max.shape[0])


def health_population(
    predictor,
    context_current_a,
    n: int = 300,
    seed: int = 0,
    q_range: tuple[float, float] = TRAIN_Q_RANGE,
    r0_range: tuple[float, float] = TRAIN_R_RANGE,
    dt_s: float = 1.0,
) -> HealthPopulation:
    """Health PCs of ``n`` random cells observed through ``context_current_a``.

    :param predictor: anything with ``health(context_current_a, context_voltage_v, dt_s) -> [B, 2]``
        (a :class:`~uam_studio.dynaformer.DynaformerPredictor`).
    :param context_current_a: the observed current (A), shape [L], sampled every ``dt_s``.
    :param n: number of cells, 1 to :data:`MAX_POPULATION`.
    :param seed: seed of ``numpy.random.default_rng`` (same seed, same population).
    :param q_range: uniform range of q_max (C).
    :param r0_range: uniform range of R0 (ohm).
    :raises InputError: for a bad ``n`` or context.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= int(n) <= MAX_POPULATION:
        raise InputError("n", f"{n!r} is out of range; allowed integers in [1, {MAX_POPULATION}]")
    ci = np.asarray(context_current_a, dtype=float)
    if ci.ndim != 1 or ci.size == 0:
        raise InputError("context_current_a", f"expected a 1-D profile with samples, got shape {ci.shape}")
    rng = np.random.default_rng(seed)
    q = rng.uniform(*q_range, int(n))
    r = rng.uniform(*r0_range, int(n))
    batch = np.tile(ci, (int(n), 1))
    # Simulated to the lowest allowed cut-off so that weak cells still give a full window.
    v = simulate(batch, dt_s, q, r, eod_v=EOD_RANGE[0]).voltage_v
    pcs = np.asarray(predictor.health(batch, v, dt_s=dt_s), dtype=float).reshape(int(n), -1)
    return HealthPopulation(q, r, pcs[:, 0].copy(), pcs[:, 1].copy())

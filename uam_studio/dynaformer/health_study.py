"""Studies of a Dynaformer against the physics model (the classroom notebooks use them).

Public API:

- :func:`compare_with_physics`: one load profile, one cell: the physics voltage next to the
  Dynaformer's prediction from a short observed context, with both EOD times
  (:class:`PhysicsComparison`).
- :func:`takeoff_context_current`: the first seconds of a take-off (the observation window).
- :func:`health_grid`: the two health principal components of cells on a q_max x R0 grid, each
  observed on the same take-off context (optionally with voltage noise).
- :func:`accuracy_table`: EOD timing error, voltage RMSE and health correlations on a held-out
  set, for several context lengths and sensor-noise levels.

The physics model is the ground truth here; the Dynaformer sees only current and voltage.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..battery import simulate
from ..battery.eod import first_below
from ..errors import InputError, check_range
from ..flight import leg_profile
from .evaluate import EOD_V, eod_metrics, health_correlations, physics_fit_eod, predict_set

__all__ = ["PhysicsComparison", "accuracy_table", "compare_with_physics", "health_grid",
           "takeoff_context_current"]

CURVE_CUTOFF_V = 2.5  # V: physics curves are drawn down to here (the Dynaformer's training cut-off)


@dataclass(frozen=True, eq=False)
class PhysicsComparison:
    """Physics and Dynaformer voltage for one profile and cell.

    :param time_s: sample times (s), sample k at (k + 1) s
    :param current_a: the load (A)
    :param physics_v: physics voltage (V); after it falls below 2.5 V it holds that value
    :param predicted_v: Dynaformer voltage (V) on the same grid
    :param context_s: seconds of (current, voltage) the Dynaformer observed
    :param eod_v: cut-off (V)
    :param eod_true_s: physics EOD (s), None if the profile ends first
    :param eod_pred_s: predicted EOD (s), None if the prediction stays above the cut-off
    :param rte: relative EOD time error ``|pred - true| / true``; None unless both EODs exist
    """

    time_s: np.ndarray
    current_a: np.ndarray
    physics_v: np.ndarray
    predicted_v: np.ndarray
    context_s: int
    eod_v: float
    eod_true_s: float | None
    eod_pred_s: float | None
    rte: float | None


def _first_below(v: np.ndarray, limit: float) -> int | None:
    k = int(first_below(v, limit))
    return k if k >= 0 else None


def compare_with_physics(predictor: Any, current_a, q_max: float, r0: float, context_s: int = 20,
                         eod_v: float = EOD_V, noise_mv: float = 0.0, seed: int = 0) -> PhysicsComparison:
    """Fly ``current_a`` (A, 1 s samples) on a cell (q_max C, r0 ohm) with the physics model, show the
    Dynaformer the first ``context_s`` seconds (voltage plus Gaussian noise of ``noise_mv``), and
    predict the whole profile.
    """
    cur = np.asarray(current_a, dtype=float).reshape(-1)
    n_ctx = int(check_range("context_s", context_s, 1, cur.size))
    noise = check_range("noise_mv", noise_mv, 0.0, 100.0, " mV") / 1000.0
    phys = simulate(cur, 1.0, q_max, r0, eod_v=CURVE_CUTOFF_V)
    v = np.asarray(phys.voltage_v, dtype=float)
    rng = np.random.default_rng(seed)
    ctx_v = np.clip(v[:n_ctx] + rng.normal(size=n_ctx) * noise, 0.0, 5.0)
    pred = np.asarray(predictor.predict(cur[:n_ctx], ctx_v, cur), dtype=float)
    k_true, k_pred = _first_below(v, eod_v), _first_below(pred, eod_v)
    t = np.array(phys.time_s)
    eod_true = float(t[k_true]) if k_true is not None else None
    eod_pred = float(t[k_pred]) if k_pred is not None else None
    rte = abs(eod_pred - eod_true) / eod_true if (eod_true and eod_pred is not None) else None
    return PhysicsComparison(t, cur, v, pred, n_ctx, float(eod_v), eod_true, eod_pred, rte)


def takeoff_context_current(context_s: int = 20) -> np.ndarray:
    """Per-cell current (A) of the first ``context_s`` seconds of a take-off (30 km leg at 500 m)."""
    n = int(check_range("context_s", context_s, 1, 100))
    return np.array(leg_profile(30.0, 500.0, 0.0).current_a[:n])


def health_grid(predictor: Any, q_values: Sequence[float], r0_values: Sequence[float], context_s: int = 20,
                noise_mv: float = 0.0, seed: int = 0) -> dict[str, np.ndarray]:
    """Health principal components of every cell of a q_max x R0 grid, each observed during the same
    take-off (:func:`takeoff_context_current`), voltage plus Gaussian noise of ``noise_mv``.

    :return: ``{"q_max": [Q], "r0": [R], "pc1": [R, Q], "pc2": [R, Q], "voltage_drop_v": [R, Q]}``;
        ``voltage_drop_v`` is the observed voltage drop over the window (first minus last sample),
        the plainest feature an engineer would read off the context.
    """
    noise = check_range("noise_mv", noise_mv, 0.0, 100.0, " mV") / 1000.0
    q_arr = np.asarray(q_values, dtype=float)
    r_arr = np.asarray(r0_values, dtype=float)
    if q_arr.ndim != 1 or r_arr.ndim != 1 or q_arr.size == 0 or r_arr.size == 0:
        raise InputError("q_values", "q_values and r0_values must be non-empty 1-D sequences")
    q, r = np.meshgrid(q_arr, r_arr)
    ci = takeoff_context_current(context_s)
    res = simulate(ci, 1.0, q.ravel(), r.ravel(), eod_v=CURVE_CUTOFF_V)
    rng = np.random.default_rng(seed)
    cv = np.clip(np.asarray(res.voltage_v) + rng.normal(size=res.voltage_v.shape) * noise, 0.0, 5.0)
    pcs = np.asarray(predictor.health(np.tile(ci, (q.size, 1)), cv), dtype=float)
    return {"q_max": q_arr, "r0": r_arr, "pc1": pcs[:, 0].reshape(q.shape), "pc2": pcs[:, 1].reshape(q.shape),
            "voltage_drop_v": (cv[:, 0] - cv[:, -1]).reshape(q.shape)}


def accuracy_table(predictor: Any, ds, contexts_s: Sequence[int] = (20, 60, 400),
                   noises_mv: Sequence[float] = (0.0, 5.0, 10.0), seed: int = 0) -> list[dict[str, Any]]:
    """EOD timing and health metrics of ``predictor`` on a held-out :class:`~uam_studio.dynaformer.data.DischargeSet`
    for every (context length, noise) pair.

    :return: one row per pair: ``context_s``, ``noise_mv``, ``median_rte``, ``median_rte_after_context``
        (EODs after the observed context only), ``p90_rte``, ``rmse_mv``,
        ``eod_agreement`` (see :func:`~uam_studio.dynaformer.evaluate.eod_metrics`), ``abs_r_r0`` and
        ``abs_r_q_max`` (\\|Pearson r\\| of the health components with R0 and q_max, over the ``n_health``
        discharges that last the context; None with fewer than 3), and the reference:
        ``physics_median_rte_after_context``, the physics model's maximum-likelihood fit of the same
        contexts (:func:`~uam_studio.dynaformer.evaluate.physics_fit_eod`).
    """
    rows = []
    for ctx in contexts_s:
        for noise in noises_mv:
            v = predict_set(predictor, ds, context_s=int(ctx), noise_v=float(noise) / 1000.0, seed=seed)
            m = eod_metrics(ds, v, context_s=int(ctx))
            h = health_correlations(predictor, ds, int(ctx), float(noise) / 1000.0, seed=seed)
            phys = eod_metrics(ds, physics_fit_eod(ds, int(ctx), float(noise) / 1000.0, seed=seed), context_s=int(ctx))
            rows.append({"context_s": int(ctx), "noise_mv": float(noise),
                         **{k: m[k] for k in ("median_rte", "median_rte_after_context", "p90_rte", "rmse_mv",
                                              "eod_agreement")},
                         "abs_r_r0": h["abs_r_r0"], "abs_r_q_max": h["abs_r_q_max"], "n_health": h["n"],
                         "physics_median_rte_after_context": phys["median_rte_after_context"]})
    return rows

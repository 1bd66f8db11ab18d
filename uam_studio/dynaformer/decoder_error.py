"""The Dynaformer decoder's own error, given the exact health: a band of lam * 0.01 V about the decoded
voltage and lam * 0.2% of the decoded EOD time (s), with lam calibrated split-conformally on synthetic
flights of the weights' cell type (stored for the bundled weights, keyed by their SHA-256), and its
combination with the health part of an interval (the two spreads add in quadrature).

``pred`` is a :class:`~uam_studio.dynaformer.predictor.DynaformerPredictor` (unannotated: the
predictor imports this module, not the other way).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import torch

from ..battery import DEFAULT_EOD_V
from ..battery.health.intervals import crossing_times

DECODER_CAL_SEED = 424242  # seed of the decoder-error calibration flights (disjoint from training and evaluation)
DECODER_CAL_N = 400  # flights
# The decoder's own error is a band of two parts scaled together by one factor lam: lam * 0.01 V
# about the decoded curve, and lam * 0.2% of the decoded EOD time (see :func:`decoder_error_scores`).
DECODER_ERROR_SHAPE = (0.01, 0.002)  # (V, -) per unit of lam
CAL_PROBS = (0.5, 0.6, 0.7, 0.75, 0.8, 0.85, 0.9, 0.925, 0.95, 0.975, 0.99, 0.999)
# Split-conformal quantiles of lam at CAL_PROBS for the bundled weights, keyed by the file's SHA-256
# (``decoder_error_scores(load_pretrained(cell))``: 400 discharges of the weights' cell type, seed 424242; 333
# of the VTC6's end after their 20 s context; for the held-out sets' weights, the count after the name).
# Other weights are calibrated on first use (200 flights, a few seconds).
BUNDLED_DECODER_LAMBDA: dict[str, tuple[float, ...]] = {
    "cfcb738ced4eb4fcae574d9e2a5d41f345dd4c83402510e9024a8197286c382b":  # pretrained/dynaformer.pt (715,909 bytes)
        (0.2195, 0.3189, 0.4386, 0.5187, 0.6423, 0.7908, 0.9728, 1.0764, 1.3455, 1.6256, 2.4252, 4.9844),
    "7a2522b588ac307d8a464ea3e8d506d97086885c60ebbc8d5326d4f7f346a8e8":  # pretrained/dynaformer_vtc6.pt (716,101 bytes)
        (0.1967, 0.3296, 0.4975, 0.6373, 0.7185, 0.8153, 1.0370, 1.1747, 1.5903, 2.3308, 3.4117, 5.0126),
    "f6387df88f86096d0fa80d123ecc1e7797ab1eff26bd942d457bcfc6633ec604":  # dynaformer_vtc6_landing_held_out.pt (317)
        (0.2444, 0.3600, 0.4903, 0.6427, 0.7960, 0.9551, 1.2151, 1.4663, 1.8587, 2.4561, 4.7815, 6.5148),
    "0918e1c24baa9e0e8e0de2879ceb0b3930e7efe17b6eeb6acf51c1131306481b":  # dynaformer_vtc6_cell_held_out.pt (317)
        (0.1958, 0.3169, 0.4212, 0.5042, 0.6002, 0.6926, 0.8935, 1.0941, 1.6163, 2.6821, 4.0625, 4.9153),
    "7c16aeb2107947f6dd6e5a778053029df981fc2fdc2d3bf6d6e42d2c0ba61e38":  # dynaformer_4a.pt (262; 30% flights)
        (0.5808, 0.8364, 1.2295, 1.5358, 1.7548, 2.5070, 3.7385, 4.1531, 5.3680, 11.7476, 20.8493, 22.3401),
}


def quantile_combine(med: np.ndarray, health_end: np.ndarray, decoder_end: np.ndarray, side: int) -> np.ndarray:
    """One end of an interval from a median and two independent spreads, added in quadrature
    (side -1: low, +1: high). Infinite times (no cut-off in the profile) stay conservative."""
    with np.errstate(invalid="ignore"):
        a, b = np.abs(health_end - med), np.abs(decoder_end - med)
        out = med + side * np.sqrt(a ** 2 + b ** 2)
    finite = np.isfinite(med) & np.isfinite(health_end) & np.isfinite(decoder_end)
    extreme = np.minimum(health_end, decoder_end) if side < 0 else np.maximum(health_end, decoder_end)
    extreme = np.minimum(extreme, med) if side < 0 else np.maximum(extreme, med)
    return np.where(finite, out, extreme)


def conformal_quantiles(scores: np.ndarray, probs) -> np.ndarray:
    """Split-conformal quantiles of ``scores``: the ceil((n + 1) p)-th smallest (the largest if beyond)."""
    s = np.sort(np.asarray(scores, float))
    k = np.minimum(np.ceil((s.size + 1) * np.asarray(probs)).astype(int), s.size) - 1
    return s[k]


def file_sha256(path) -> str:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return ""


@torch.no_grad()
def decoder_error_scores(pred, n: int = DECODER_CAL_N, seed: int = DECODER_CAL_SEED,
                         eod_v: float = DEFAULT_EOD_V) -> np.ndarray:
    """The decoder's own EOD error on ``n`` synthetic discharges of the weights' cell type (training ranges,
    ``seed``; the type's ``calibration_flights`` share of flights, the rest generic loads), given the
    exact health (read as in
    :meth:`~uam_studio.dynaformer.predictor.DynaformerPredictor._reobserved_latent`) and a 20 s
    observed context: per flight whose true EOD falls after the context, the smallest lam >= 0 such that
    [min(crossing of the curve - lam a, (1 - lam b) t_med), max(crossing of the curve + lam a,
    (1 + lam b) t_med)] holds the true EOD ((a, b) =
    :data:`DECODER_ERROR_SHAPE`; t_med: the decoded EOD). Closed form per side: the voltage part needs
    lam a > (min of the curve up to the true EOD) - eod_v (low side) or >= eod_v - (min before it)
    (high side); the time part lam b >= |t_med - t_true| / t_med on the side it is missing."""
    from .cells import dynaformer_cell
    from .data import make_dataset

    a, b = DECODER_ERROR_SHAPE
    kind = dynaformer_cell(pred.model.cfg.cell)
    ds = make_dataset(n, seed=seed, flight_fraction=kind.calibration_flights, cell=kind.key)
    t = np.arange(ds.voltage_v.shape[1])[None, :]
    true_t, _ = crossing_times(np.where(t < ds.length[:, None], ds.voltage_v, 5.0), 1.0, eod_v)
    keep = np.where(np.isfinite(true_t) & (true_t > 20))[0]
    scores = []
    for s in range(0, keep.size, 64):
        rows = keep[s:s + 64]
        part = ds.subset(rows)
        v = decode_given_health(pred, part)
        v[:, :20] = part.voltage_v[:, :20]
        med, _ = crossing_times(v, 1.0, eod_v)
        for r, i in enumerate(rows):
            k = int(true_t[i]) - 1  # index of the true first sample below
            t_true, t_med = float(true_t[i]), float(med[r])
            up_to, before = v[r, :k + 1].min(), (v[r, :k].min() if k > 0 else np.inf)
            rel = abs(t_med - t_true) / t_med if np.isfinite(t_med) else np.inf
            lo = min((up_to - eod_v) / a, rel / b if t_med > t_true else np.inf) if up_to >= eod_v else 0.0
            hi = min((eod_v - before) / a, rel / b) if before < eod_v else 0.0
            scores.append(max(lo, hi, 0.0))
    return np.asarray(scores)


@torch.no_grad()
def decode_given_health(pred, ds, batch: int = 64) -> np.ndarray:
    """The decoder's voltage (V) [N, T] along each discharge of the set ``ds`` (its whole current, A),
    given its exact health (q_max C, R0 ohm; latents as
    :meth:`~uam_studio.dynaformer.predictor.DynaformerPredictor._reobserved_latent` reads them), so
    only the decoder's own error remains; 5.0 V past each discharge's length (never read as a
    crossing of a cut-off)."""
    points = np.column_stack([ds.q_max, ds.r0])
    cur = ds.current_a.astype(np.float64)
    v = np.concatenate([pred._decode(None, cur[s:s + batch], skip_rest=True, points=points[s:s + batch])
                        for s in range(0, len(ds), batch)])
    t = np.arange(cur.shape[1])[None, :]
    return np.where(t < ds.length[:, None], v, 5.0)

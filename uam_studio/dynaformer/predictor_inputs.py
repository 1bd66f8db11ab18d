"""The Dynaformer predictor's inputs: checked arrays of current (A) and voltage (V) as [B, T], their
resampling onto the model's 1 s grid, a profile's leading rest (skipped by the decoder), and the
take-off decoder's latent for a cell's health (R0 in ohm, q_max in C).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..errors import InputError
from .model import takeoff_targets

MAX_PROFILE_S = 200_000.0  # s: longer profiles are refused (memory)
REST_CURRENT_A = 0.1  # A: leading samples below this, holding < REST_CHARGE_C in all, are rest
REST_CHARGE_C = 1.0  # C


def as_2d(field: str, arr) -> tuple[np.ndarray, bool]:
    try:
        a = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(field, "expected an array of numbers") from None
    if a.ndim not in (1, 2):
        raise InputError(field, f"expected shape [T] or [B, T], got {a.shape}")
    if a.shape[-1] == 0:
        raise InputError(field, "has no samples; at least 1 is needed")
    if not np.all(np.isfinite(a)):
        raise InputError(field, "contains NaN or inf; every sample must be finite")
    return np.atleast_2d(a), a.ndim == 1


def to_grid(values: np.ndarray, dt_s: float, hold: bool) -> np.ndarray:
    """Resample [B, T] samples at step dt_s onto the model's 1 s grid."""
    if dt_s == 1.0:
        return values
    t = values.shape[1]
    n = max(1, int(math.ceil(t * dt_s - 1e-9)))
    centers = np.arange(n) + 0.5
    if hold:  # piecewise-constant current: sample the step containing each 1 s midpoint
        idx = np.minimum((centers / dt_s).astype(int), t - 1)
        return values[:, idx]
    src_t = dt_s * np.arange(1, t + 1)
    return np.stack([np.interp(np.arange(1, n + 1), src_t, row) for row in values])


def clamped_latent(r0_ohm: np.ndarray, q_max_c: np.ndarray, cfg=None) -> torch.Tensor:
    """The take-off decoder's latent [B, 2] for (R0 ohm, q_max C), clamped like TakeoffHealth's output
    (``cfg``: the weights' :class:`~uam_studio.dynaformer.model.DynaformerConfig`, for its scales)."""
    h = takeoff_targets(np.asarray(r0_ohm, float), np.asarray(q_max_c, float), cfg)
    return torch.stack([h[:, 0].clamp(-1.5, 1.5), h[:, 1].clamp(-2.5, 4.0)], 1).float()


def leading_rest(grid: np.ndarray) -> np.ndarray:
    """Per row of a 1 s current grid [B, n] (A): leading samples at rest (|i| < REST_CURRENT_A, together
    under REST_CHARGE_C). A full, rested cell is unchanged by them, so the decoder skips them."""
    quiet = np.abs(grid) < REST_CURRENT_A
    small = np.abs(np.cumsum(grid, axis=1)) < REST_CHARGE_C
    ok = quiet & small
    return np.where(ok.all(axis=1), grid.shape[1], np.argmin(ok, axis=1))

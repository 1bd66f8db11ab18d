"""The public Dynaformer API: load weights, predict voltage, estimate health.

    from uam_studio.dynaformer import load_pretrained
    p = load_pretrained()
    v = p.predict(ctx_i, ctx_v, current_a)       # V on current_a's time grid
    pcs = p.health(ctx_i, ctx_v)                  # [..., 2] principal components
"""

from __future__ import annotations

import math
import os
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from ..errors import InputError, check_range
from .artifact import WeightsError, load_artifact

BUNDLED_WEIGHTS = Path(__file__).resolve().parents[2] / "pretrained" / "dynaformer.pt"
MAX_PROFILE_S = 200_000.0  # s: longer profiles are refused (memory)


def bundled_weights_path() -> Path:
    """The bundled weights: ``$UAM_STUDIO_DYNAFORMER`` if set, else ``pretrained/dynaformer.pt``."""
    return Path(os.environ.get("UAM_STUDIO_DYNAFORMER", BUNDLED_WEIGHTS))


def _as_2d(field: str, arr) -> tuple[np.ndarray, bool]:
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


def _to_grid(values: np.ndarray, dt_s: float, hold: bool) -> np.ndarray:
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


class DynaformerPredictor:
    """A loaded Dynaformer plus its health PCA. Thread-safe for inference."""

    def __init__(self, model, pca: dict, meta: dict, source: str) -> None:
        self.model = model.eval()
        self.pca = pca
        self.meta = meta
        self.source = source
        self.chunk = model.cfg.chunk
        self.max_context = model.cfg.max_context

    # ------------------------------------------------------------------ helpers
    def _context(self, context_current_a, context_voltage_v, dt_s: float, batch: int | None = None):
        ci, single_i = _as_2d("context_current_a", context_current_a)
        cv, _ = _as_2d("context_voltage_v", context_voltage_v)
        if ci.shape != cv.shape:
            raise InputError("context_voltage_v", f"shape {cv.shape} does not match context_current_a {ci.shape}")
        if np.any(np.abs(ci) > 50):
            raise InputError("context_current_a", "|current| must be <= 50 A")
        if np.any((cv < 0) | (cv > 5)):
            raise InputError("context_voltage_v", "voltages must be in [0, 5] V")
        ci = _to_grid(ci, dt_s, hold=True)
        cv = _to_grid(cv, dt_s, hold=False)
        if self.model.cfg.health == "takeoff":  # reads the take-off window from t = 0, nothing after it
            w = self.model.cfg.health_window
            if ci.shape[1] < w:
                raise InputError("context_current_a", f"needs at least {w} s of take-off (got {ci.shape[1]} s "
                                 "on the 1 s grid)")
            ci, cv = ci[:, :w], cv[:, :w]
        elif ci.shape[1] > self.max_context:  # whole history: stride down to the encoder's limit
            stride = int(math.ceil(ci.shape[1] / self.max_context))
            ci, cv = ci[:, ::stride], cv[:, ::stride]
        if batch is not None and ci.shape[0] not in (1, batch):
            raise InputError("context_current_a", f"batch {ci.shape[0]} does not match current_a batch {batch}")
        return torch.as_tensor(ci, dtype=torch.float32), torch.as_tensor(cv, dtype=torch.float32), single_i

    @torch.no_grad()
    def latent(self, context_current_a, context_voltage_v, dt_s: float = 1.0) -> np.ndarray:
        """Raw health latent [B, latent_dim] (for analysis)."""
        ci, cv, _ = self._context(context_current_a, context_voltage_v, dt_s)
        return self.model.encode(ci, cv).numpy()

    # ------------------------------------------------------------------ public API
    @torch.no_grad()
    def health(self, context_current_a, context_voltage_v, dt_s: float = 1.0) -> np.ndarray:
        """First two principal components of the health embedding, shape [..., 2] (standardised).

        :param context_current_a: observed current (A), [L] or [B, L].
        :param context_voltage_v: observed voltage (V), same shape.
        """
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        ci, cv, single = self._context(context_current_a, context_voltage_v, dt)
        z = self.model.health_head(self.model.encode(ci, cv))
        pcs = ((z - self.pca["mean"]) @ self.pca["components"].T) / self.pca["scale"]
        out = pcs.numpy().astype(np.float64)
        return out[0] if single else out

    @torch.no_grad()
    def predict(self, context_current_a, context_voltage_v, current_a, dt_s: float = 1.0) -> np.ndarray:
        """Predicted voltage (V) on ``current_a``'s time grid (sample k at (k+1) dt_s).

        :param context_current_a: observed current (A) from t = 0, [L] or [B, L].
        :param context_voltage_v: observed voltage (V), same shape.
        :param current_a: the whole planned per-cell current (A) from t = 0, context
            included, [T] or [B, T].
        :param dt_s: sample step of all inputs (s).
        """
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        cur, single = _as_2d("current_a", current_a)
        if np.any(np.abs(cur) > 50):
            raise InputError("current_a", "|current| must be <= 50 A")
        if cur.shape[1] * dt > MAX_PROFILE_S:
            raise InputError("current_a", f"profile longer than {MAX_PROFILE_S:g} s")
        ci, cv, single_ctx = self._context(context_current_a, context_voltage_v, dt, batch=cur.shape[0])
        grid = _to_grid(cur, dt, hold=True)
        b = max(grid.shape[0], ci.shape[0])
        n = grid.shape[1]
        padded = int(math.ceil(n / self.chunk) * self.chunk)
        g = np.zeros((b, padded), np.float32)
        g[:, :n] = grid
        latent = self.model.encode(ci, cv)
        if latent.shape[0] != b:
            latent = latent.expand(b, -1)
        v = self.model.decode(latent, torch.as_tensor(g)).numpy()[:, :n].astype(np.float64)
        if dt != 1.0:
            t_out = dt * np.arange(1, cur.shape[1] + 1)
            v = np.stack([np.interp(t_out, np.arange(1, n + 1), row) for row in v])
        v = np.clip(np.nan_to_num(v, nan=0.0, posinf=5.0, neginf=0.0), 0.0, 5.0)
        # The observed context is measured, not predicted: return it as observed (same dt_s grid
        # from t = 0), so an EOD already inside the observation is reported where it happened.
        obs = np.atleast_2d(np.asarray(context_voltage_v, dtype=np.float64))
        k = min(obs.shape[1], v.shape[1])
        v[:, :k] = obs[:, :k]
        return v[0] if (single and single_ctx) else v

    def predict_eod_s(self, context_current_a, context_voltage_v, current_a, dt_s: float = 1.0,
                      eod_v: float = 3.0):
        """Predicted EOD time (s): first sample below ``eod_v``; NaN if the profile ends first."""
        v = np.atleast_2d(self.predict(context_current_a, context_voltage_v, current_a, dt_s))
        below = v < eod_v
        eod = np.where(below.any(1), (np.argmax(below, 1) + 1) * dt_s, np.nan)
        return float(eod[0]) if np.ndim(current_a) == 1 else eod


def load_predictor(path=None) -> DynaformerPredictor:
    """Load weights from ``path`` (default: the bundled model). Raises :class:`WeightsError`."""
    p = bundled_weights_path() if path is None else Path(path)
    model, pca, meta = load_artifact(p)
    return DynaformerPredictor(model, pca, meta, str(p))


@lru_cache(maxsize=1)
def load_pretrained() -> DynaformerPredictor:
    """The bundled, pretrained Dynaformer (loaded once per process)."""
    return load_predictor(None)


def load_with_fallback(path) -> tuple[DynaformerPredictor, str | None]:
    """Load ``path``; on a bad file fall back to the bundled model. Returns (predictor, error or None)."""
    try:
        return load_predictor(path), None
    except WeightsError as err:
        return load_pretrained(), str(err)

"""The public Dynaformer API: load weights, estimate health, predict voltage, with uncertainty.

    from uam_studio.dynaformer import load_pretrained
    p = load_pretrained()
    est = p.health_estimate(ctx_i, ctx_v)         # physics fit of the whole context: q_max, R0, covariance
    v = p.predict(ctx_i, ctx_v, current_a)       # V on current_a's time grid
    lo, med, hi = p.eod_interval_s(ctx_i, ctx_v, current_a)   # s from the log's start, 90%
    v_lo, v_med, v_hi = p.voltage_band(ctx_i, ctx_v, current_a)
    pcs = p.health(ctx_i, ctx_v)                  # [..., 2] principal components

The context (current in A, voltage in V, from the log's first sample, at least 20 s) may be noisy,
start at rest or under load, and be as long as the flight so far. ``health_source="model"`` uses
the weights' own estimator instead (the take-off regression on the first 20 s).
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from scipy.ndimage import median_filter

from ..battery import DEFAULT_EOD_V, rest_voltage, simulate
from ..battery.eod import first_below
from ..battery.health.estimate import MIN_CONTEXT_S, HealthEstimate
from ..battery.health.fit import fit_health_batch
from ..battery.health.intervals import (
    EodInterval,
    band_from_sigma_points,
    crossing_times,
    interval_ends,
    two_sided_z,
    with_preroll,
)
from ..errors import InputError, check_range
from .artifact import WeightsError, bundled_weights_path, load_artifact
from .cells import dynaformer_cell
from .decoder_error import (
    BUNDLED_DECODER_LAMBDA,
    CAL_PROBS,
    DECODER_CAL_N,
    DECODER_ERROR_SHAPE,
    conformal_quantiles,
    decoder_error_scores,
    file_sha256,
    quantile_combine,
)
from .predictor_inputs import MAX_PROFILE_S, as_2d, clamped_latent, leading_rest, to_grid

HEALTH_SOURCES = ("fit", "model")
# One lock for every predictor's first calibration (rare): a predictor holds none, so it pickles (vector
# environments send it to their worker processes).
_CALIBRATION_LOCK = threading.Lock()


class DynaformerPredictor:
    """A loaded Dynaformer plus its health PCA. Thread-safe for inference.

    Health source (``health_source`` of every method): ``"fit"`` reads the whole context with the
    physics model's maximum-likelihood fit (:func:`uam_studio.battery.health.fit.fit_health`); the decoder
    then reads that cell as it was trained to: the take-off estimator's reading of the fitted cell's
    noise-free take-off, simulated along the profile's first 20 s (:meth:`_reobserved_latent`).
    ``"model"`` uses the weights' own estimator on the measured context (the take-off regression on
    the first 20 s, or the transformer encoder of older weights). Default (None): ``"fit"`` for
    weights whose decoder reads (R0, 1/q_max) (``health="takeoff"``), ``"model"`` otherwise. The
    health PCs (:meth:`health`) of the fit are those of its (R0, 1/q_max) in the decoder's units.
    """

    def __init__(self, model, pca: dict, meta: dict, source: str) -> None:
        self.model = model.eval()
        self.pca = pca
        self.meta = meta
        self.source = source
        self.cell_type = dynaformer_cell(model.cfg.cell)  # the cell the weights were trained for
        self.cell = self.cell_type.params  # its parameter set: the fit, the re-observed take-off, the rest
        self.chunk = model.cfg.chunk
        self.max_context = model.cfg.max_context
        self._decoder_quantiles: tuple[float, ...] | None = None

    # ------------------------------------------------------------------ helpers
    @property
    def reads_fitted_health(self) -> bool:
        """True when the decoder's latent is (R0, 1/q_max), so a physics fit can drive it."""
        return self.model.cfg.health == "takeoff"

    def _source(self, health_source) -> str:
        if health_source is None:
            return "fit" if self.reads_fitted_health else "model"
        if health_source == "fit":
            if not self.reads_fitted_health:
                raise InputError("health_source", "'fit' needs weights whose decoder reads (R0, 1/q_max) "
                                 f"(health='takeoff'); these use health={self.model.cfg.health!r}")
            return "fit"
        if health_source in ("model", self.model.cfg.health):
            return "model"
        raise InputError("health_source", f"{health_source!r} is not allowed; use None, 'fit' or 'model' "
                         f"(these weights' own estimator: {self.model.cfg.health!r})")

    def _raw_context(self, context_current_a, context_voltage_v, batch: int | None = None):
        """Validated context arrays [B, L] (A, V) on their own grid, and whether the input was 1-D."""
        ci, single_i = as_2d("context_current_a", context_current_a)
        cv, _ = as_2d("context_voltage_v", context_voltage_v)
        if ci.shape != cv.shape:
            raise InputError("context_voltage_v", f"shape {cv.shape} does not match context_current_a {ci.shape}")
        if np.any(np.abs(ci) > 50):
            raise InputError("context_current_a", "|current| must be <= 50 A")
        if np.any((cv < 0) | (cv > 5)):
            raise InputError("context_voltage_v", "voltages must be in [0, 5] V")
        if batch is not None and batch != 1 and ci.shape[0] not in (1, batch):
            raise InputError("context_current_a", f"batch {ci.shape[0]} does not match current_a batch {batch}")
        return ci, cv, single_i

    def _context(self, context_current_a, context_voltage_v, dt_s: float, batch: int | None = None):
        """The weights' own estimator's input: context tensors on the 1 s grid (A, V)."""
        ci, cv, single_i = self._raw_context(context_current_a, context_voltage_v, batch)
        ci = to_grid(ci, dt_s, hold=True)
        cv = to_grid(cv, dt_s, hold=False)
        if self.model.cfg.health == "takeoff":  # reads the take-off window from t = 0, nothing after it
            w = self.model.cfg.health_window
            if ci.shape[1] < w:
                raise InputError("context_current_a", f"needs at least {w} s of take-off (got {ci.shape[1]} s "
                                 "on the 1 s grid)")
            ci, cv = ci[:, :w], cv[:, :w]
        elif ci.shape[1] > self.max_context:  # whole history: stride down to the encoder's limit
            stride = int(math.ceil(ci.shape[1] / self.max_context))
            ci, cv = ci[:, ::stride], cv[:, ::stride]
        return torch.as_tensor(ci, dtype=torch.float32), torch.as_tensor(cv, dtype=torch.float32), single_i

    def _estimates(self, ci: np.ndarray, cv: np.ndarray, dt: float, noise_v, estimate) -> list[HealthEstimate]:
        """Health estimates of the rows of a validated context [B, L] (fitted unless given)."""
        if estimate is not None:
            ests = [estimate] if isinstance(estimate, HealthEstimate) else list(estimate)
            if not ests or not all(isinstance(e, HealthEstimate) for e in ests):
                raise InputError("estimate", "expected a HealthEstimate or a sequence of them (from health_estimate)")
            if len(ests) not in (1, ci.shape[0]):
                raise InputError("estimate", f"{len(ests)} estimates for a context batch of {ci.shape[0]}")
            return ests * ci.shape[0] if len(ests) == 1 else ests
        if ci.shape[1] * dt < MIN_CONTEXT_S - 1e-9:
            raise InputError("context_current_a", f"needs at least {MIN_CONTEXT_S:g} s of context, got "
                             f"{ci.shape[1] * dt:g} s ({ci.shape[1]} samples at {dt:g} s)")
        if noise_v is not None:
            check_range("noise_v", noise_v, 0.0, 1.0, " V")
        return fit_health_batch(ci, cv, dt, noise_v, cell=self.cell)

    def _latent(self, source: str, context_current_a, context_voltage_v, dt: float, batch: int | None,
                noise_v, estimate):
        """(latent [B, d], estimates or None, raw context voltage [B, L], whether the context was 1-D)."""
        if source == "fit":
            ci, cv, single = self._raw_context(context_current_a, context_voltage_v, batch)
            ests = self._estimates(ci, cv, dt, noise_v, estimate)
            lat = clamped_latent(np.array([e.r0 for e in ests]), np.array([e.q_max for e in ests]), self.model.cfg)
            return lat, ests, cv, single
        ci_t, cv_t, single = self._context(context_current_a, context_voltage_v, dt, batch)
        _, cv, _ = self._raw_context(context_current_a, context_voltage_v, batch)
        return self.model.encode(ci_t, cv_t), None, cv, single

    def _profile(self, current_a, dt: float) -> tuple[np.ndarray, bool]:
        cur, single = as_2d("current_a", current_a)
        if np.any(np.abs(cur) > 50):
            raise InputError("current_a", "|current| must be <= 50 A")
        if cur.shape[1] * dt > MAX_PROFILE_S:
            raise InputError("current_a", f"profile longer than {MAX_PROFILE_S:g} s")
        return cur, single

    @torch.no_grad()
    def _decode(self, latent: torch.Tensor | None, grid: np.ndarray, skip_rest: bool,
                estimates: list[HealthEstimate] | None = None, points: np.ndarray | None = None) -> np.ndarray:
        """Decoded voltage (V) [B, n] for latents [B, d] and a 1 s current grid [B, n] (A). With
        ``skip_rest``, each row's leading rest (:func:`leading_rest`) is cut before decoding and
        filled with the rested full cell's voltage. With ``estimates`` (one per row), each row's
        pre-roll (:func:`uam_studio.battery.health.intervals.with_preroll`) is decoded before it and dropped.
        With ``points`` [B, 2] (q_max C, r0 ohm) instead of latents: :meth:`_reobserved_latent`."""
        n_out = grid.shape[1]
        grid, k_pre = with_preroll(estimates, grid, 1.0) if estimates is not None else (grid, 0)
        b, n = grid.shape
        k0 = leading_rest(grid) if skip_rest else np.zeros(b, int)
        padded = int(math.ceil(max(1, n) / self.chunk) * self.chunk)
        g = np.zeros((b, padded), np.float32)
        for r in range(b):
            g[r, :n - k0[r]] = grid[r, k0[r]:]
        if points is not None:
            latent = self._reobserved_latent(points, g)
        v = self.model.decode(latent, torch.as_tensor(g)).numpy()[:, :n].astype(np.float64)
        if skip_rest and k0.any():
            out = np.full((b, n), float(rest_voltage(self.cell_type.cell.q_max, self.cell)))
            for r in range(b):
                out[r, k0[r]:] = v[r, :n - k0[r]]
            v = out
        return v[:, k_pre:k_pre + n_out]

    def _reobserved_latent(self, points: np.ndarray, grid: np.ndarray) -> torch.Tensor:
        """The decoder's latent [B, 2] for cells (q_max C, r0 ohm) ``points`` [B, 2] about to be decoded
        along ``grid`` [B, n] (A, 1 s): the take-off estimator's reading of each cell's noise-free
        first ``health_window`` s of that grid, simulated with the physics model. The decoder was
        trained on exactly these readings (of noise-free take-offs), whose small systematic errors
        on some loads it has learned to expect; feeding it (R0, 1/q_max) directly
        (:func:`clamped_latent`) costs accuracy on generic loads. The reading is sensitive to current
        noise (20 mA moves it by about 1% of q_max), so the window's current is median-filtered over 9
        samples first (no change to a noise-free take-off; about half the noise's effect)."""
        w = self.model.cfg.health_window
        if grid.shape[1] < w:
            return clamped_latent(points[:, 1], points[:, 0], self.model.cfg)
        first = median_filter(np.asarray(grid[:, :w], np.float64), size=(1, 9), mode="nearest")
        volt = simulate(first, 1.0, np.clip(points[:, 0], 1.0, None), np.clip(points[:, 1], 0.0, None),
                        eod_v=2.5, cell=self.cell).voltage_v  # held below 2.5 V, as in the training data
        return self.model.takeoff(torch.as_tensor(first, dtype=torch.float32),
                                  torch.as_tensor(volt, dtype=torch.float32))

    def _finish(self, v: np.ndarray, cur: np.ndarray, dt: float, n: int, obs: np.ndarray) -> np.ndarray:
        """1 s grid -> current_a's grid, clipped to [0, 5] V, the observed context written back."""
        if dt != 1.0:
            t_out = dt * np.arange(1, cur.shape[1] + 1)
            v = np.stack([np.interp(t_out, np.arange(1, n + 1), row) for row in v])
        v = np.clip(np.nan_to_num(v, nan=0.0, posinf=5.0, neginf=0.0), 0.0, 5.0)
        # The observed context is measured, not predicted: return it as observed (same dt_s grid
        # from t = 0), so an EOD already inside the observation is reported where it happened.
        k = min(obs.shape[1], v.shape[1])
        v[:, :k] = obs[:, :k] if obs.shape[0] == v.shape[0] else obs[:1, :k]
        return v

    @torch.no_grad()
    def latent(self, context_current_a, context_voltage_v, dt_s: float = 1.0, health_source: str | None = None,
               noise_v: float | None = None) -> np.ndarray:
        """Health latent [B, latent_dim] (for analysis): the model's own estimate, or for the fit its
        (R0, 1/q_max) in the decoder's scaled units."""
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        lat, *_ = self._latent(self._source(health_source), context_current_a, context_voltage_v, dt, None,
                               noise_v, None)
        return lat.numpy()

    # ------------------------------------------------------------------ public API
    def health_estimate(self, context_current_a, context_voltage_v, dt_s: float = 1.0,
                        noise_v: float | None = None) -> HealthEstimate | list[HealthEstimate]:
        """The physics fit of the context (:func:`uam_studio.battery.health.fit.fit_health`): q_max (C), R0
        (ohm), covariance. One :class:`HealthEstimate` for a 1-D context, a list for [B, L]. Pass it
        back as ``estimate=`` to :meth:`predict`, :meth:`eod_interval_s`, :meth:`voltage_band` to skip
        refitting.

        :param context_current_a: measured current (A) from the log's first sample, [L] or [B, L],
            at least 20 s.
        :param context_voltage_v: measured voltage (V), same shape.
        :param noise_v: voltage-noise std (V); None: estimated from the residuals.
        """
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        ci, cv, single = self._raw_context(context_current_a, context_voltage_v)
        ests = self._estimates(ci, cv, dt, noise_v, None)
        return ests[0] if single else ests

    @torch.no_grad()
    def health(self, context_current_a, context_voltage_v, dt_s: float = 1.0, health_source: str | None = None,
               noise_v: float | None = None, estimate=None) -> np.ndarray:
        """First two principal components of the health embedding, shape [..., 2] (standardised).
        With the physics fit, the embedding is the fitted (R0, 1/q_max) in the decoder's scaled units.

        :param context_current_a: observed current (A), [L] or [B, L].
        :param context_voltage_v: observed voltage (V), same shape.
        :param health_source: None, ``"fit"`` or ``"model"`` (see the class).
        :param noise_v: voltage-noise std (V) for the fit; None: estimated.
        :param estimate: a :class:`HealthEstimate` (or one per row) to use instead of fitting.
        """
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        lat, _, _, single = self._latent(self._source(health_source), context_current_a, context_voltage_v, dt,
                                         None, noise_v, estimate)
        z = self.model.health_head(lat)
        pcs = ((z - self.pca["mean"]) @ self.pca["components"].T) / self.pca["scale"]
        out = pcs.numpy().astype(np.float64)
        return out[0] if single else out

    @torch.no_grad()
    def predict(self, context_current_a, context_voltage_v, current_a, dt_s: float = 1.0,
                health_source: str | None = None, noise_v: float | None = None, estimate=None) -> np.ndarray:
        """Predicted voltage (V) on ``current_a``'s time grid (sample k at (k+1) dt_s).

        :param context_current_a: observed current (A) from t = 0, [L] or [B, L]; at least 20 s for
            the physics fit.
        :param context_voltage_v: observed voltage (V), same shape.
        :param current_a: the whole planned per-cell current (A) from t = 0, context
            included, [T] or [B, T].
        :param dt_s: sample step of all inputs (s).
        :param health_source: None, ``"fit"`` or ``"model"`` (see the class).
        :param noise_v: voltage-noise std (V) for the fit; None: estimated.
        :param estimate: a :class:`HealthEstimate` (or one per row) to use instead of fitting.
        """
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        cur, single = self._profile(current_a, dt)
        source = self._source(health_source)
        latent, ests, obs, single_ctx = self._latent(source, context_current_a, context_voltage_v, dt,
                                                     cur.shape[0], noise_v, estimate)
        grid = to_grid(cur, dt, hold=True)
        b = max(grid.shape[0], latent.shape[0])
        grid = np.broadcast_to(grid, (b, grid.shape[1]))
        if latent.shape[0] != b:
            latent = latent.expand(b, -1)
        if ests is not None and len(ests) != b:
            ests = ests * b
        points = np.array([[e.q_max, e.r0] for e in ests]) if ests is not None else None
        v = self._decode(latent, grid, skip_rest=source == "fit", estimates=ests, points=points)
        v = self._finish(v, cur, dt, grid.shape[1], obs)
        return v[0] if (single and single_ctx) else v

    def predict_eod_s(self, context_current_a, context_voltage_v, current_a, dt_s: float = 1.0,
                      eod_v: float = DEFAULT_EOD_V, health_source: str | None = None, noise_v: float | None = None,
                      estimate=None):
        """Predicted EOD time (s): first sample below ``eod_v``; NaN if the profile ends first."""
        v = np.atleast_2d(self.predict(context_current_a, context_voltage_v, current_a, dt_s,
                                       health_source=health_source, noise_v=noise_v, estimate=estimate))
        k = first_below(v, eod_v)
        eod = np.where(k >= 0, (k + 1) * dt_s, np.nan)
        return float(eod[0]) if np.ndim(current_a) == 1 else eod

    # ------------------------------------------------------------------ uncertainty
    def decoder_error(self, level: float = 0.9) -> tuple[float, float]:
        """The decoder's own error at ``level``, given the exact health: (h_v in V, h_t relative). The
        decoder's part of an EOD interval is [min(crossing of the curve - h_v, (1 - h_t) median),
        max(crossing of the curve + h_v, (1 + h_t) median)]; ``level`` of held-out flights fall inside
        (split-conformal, :func:`decoder_error_scores`). Bundled weights: stored; others: measured on
        first use."""
        lv = check_range("level", level, 0.5, 0.999)
        with _CALIBRATION_LOCK:
            if self._decoder_quantiles is None:
                known = BUNDLED_DECODER_LAMBDA.get(file_sha256(self.source))
                if known is None:
                    scores = decoder_error_scores(self, n=DECODER_CAL_N // 2)
                    known = tuple(float(x) for x in conformal_quantiles(scores, CAL_PROBS))
                self._decoder_quantiles = known
        lam = float(np.interp(lv, CAL_PROBS, self._decoder_quantiles))
        return lam * DECODER_ERROR_SHAPE[0], lam * DECODER_ERROR_SHAPE[1]

    def _interval_inputs(self, context_current_a, context_voltage_v, current_a, dt_s, level, noise_v, estimate,
                         health_source):
        dt = check_range("dt_s", dt_s, 1e-3, 60.0, " s")
        lv = check_range("level", level, 0.5, 0.999)
        cur, single = self._profile(current_a, dt)
        if self._source(health_source) != "fit":
            raise InputError("health_source", "intervals and bands need the physics fit ('fit')")
        ci, cv, single_ctx = self._raw_context(context_current_a, context_voltage_v, cur.shape[0])
        ests = self._estimates(ci, cv, dt, noise_v, estimate)
        b = max(cur.shape[0], len(ests))
        cur = np.broadcast_to(cur, (b, cur.shape[1]))
        ests = ests * b if len(ests) == 1 else ests
        return dt, lv, cur, ests, cv, single and single_ctx

    @torch.no_grad()
    def eod_interval_s(self, context_current_a, context_voltage_v, current_a, dt_s: float = 1.0,
                       level: float = 0.9, eod_v: float = DEFAULT_EOD_V, noise_v: float | None = None, estimate=None,
                       health_source: str | None = None):
        """``level`` interval (low, median, high) of the time (s) from the log's first sample to the
        first sample below ``eod_v`` along ``current_a`` (the same time as :meth:`predict_eod_s`).

        median: the Dynaformer at the fitted health. The health part of the spread: the health at the
        two ends of the physics model's first-order EOD interval
        (:func:`uam_studio.battery.health.intervals.interval_points`), decoded. The decoder's own error: the
        band of :meth:`decoder_error` about the median. The two spreads add in quadrature. One physics
        call (5 trajectories per row) and one decoder call (3 per row).

        :return: for a 1-D input an :class:`~uam_studio.battery.health.intervals.EodInterval` (an end the
            profile does not reach censored at its length); else three arrays [B], ``math.inf`` there.
        """
        dt, lv, cur, ests, obs, single = self._interval_inputs(context_current_a, context_voltage_v, current_a,
                                                               dt_s, level, noise_v, estimate, health_source)
        eod = check_range("eod_v", eod_v, 2.5, 4.0, " V")
        b = cur.shape[0]
        ends = interval_ends(ests, np.ascontiguousarray(cur), dt, lv, eod, cell=self.cell)  # [b, 2, 2] (q_max, r0)
        pts = np.concatenate([np.array([[e.q_max, e.r0] for e in ests])[:, None], ends], axis=1)  # [b, 3, 2]
        grid = to_grid(cur, dt, hold=True)
        v = self._decode(None, np.repeat(grid, 3, axis=0), skip_rest=True,
                         estimates=[e for e in ests for _ in range(3)], points=pts.reshape(-1, 2)).reshape(b, 3, -1)
        h_v, h_t = self.decoder_error(lv)
        curves = np.concatenate([v, (v[:, 0] - h_v)[:, None], (v[:, 0] + h_v)[:, None]], axis=1)  # [b, 5, n]
        curves = np.stack([self._finish(curves[:, k], cur, dt, grid.shape[1], obs) for k in range(5)], axis=1)
        times, _ = crossing_times(curves.reshape(b * 5, -1), dt, eod)
        times = times.reshape(b, 5)
        med = times[:, 0]
        h_lo, h_hi = np.minimum(times[:, 1], times[:, 2]), np.maximum(times[:, 1], times[:, 2])
        d_lo = np.minimum(times[:, 3], np.where(np.isfinite(med), med * (1.0 - h_t), np.inf))
        d_hi = np.maximum(times[:, 4], med * (1.0 + h_t))
        low = quantile_combine(med, np.minimum(h_lo, med), np.minimum(d_lo, med), -1)
        high = quantile_combine(med, np.maximum(h_hi, med), np.maximum(d_hi, med), +1)
        low = np.where(np.isfinite(low), np.maximum(np.ceil(low / dt - 1e-9) * dt, dt), low)
        high = np.where(np.isfinite(high), np.ceil(high / dt - 1e-9) * dt, high)
        if single:
            return EodInterval.from_times(low[0], med[0], high[0], cur.shape[1] * dt)
        return low, med, high

    @torch.no_grad()
    def voltage_band(self, context_current_a, context_voltage_v, current_a, dt_s: float = 1.0,
                     level: float = 0.9, noise_v: float | None = None, estimate=None,
                     health_source: str | None = None):
        """Pointwise ``level`` band (low, median, high) of the predicted voltage (V) on ``current_a``'s
        grid, a band to draw. median = :meth:`predict`. Spread: the 5 health sigma points
        (:meth:`~uam_studio.battery.health.estimate.HealthEstimate.sigma_points`) decoded, linearised per sample,
        plus the decoder's own error (:meth:`decoder_error`: -+ h_v, and the median curve stretched
        in time by -+ h_t) in quadrature. The observed context is returned as observed in all three.

        :return: three arrays, [T] for a 1-D input, else [B, T].
        """
        dt, lv, cur, ests, obs, single = self._interval_inputs(context_current_a, context_voltage_v, current_a,
                                                               dt_s, level, noise_v, estimate, health_source)
        b = cur.shape[0]
        pts = np.stack([e.sigma_points() for e in ests])  # [b, 5, 2]
        grid = to_grid(cur, dt, hold=True)
        v = self._decode(None, np.repeat(grid, 5, axis=0), skip_rest=True,
                         estimates=[e for e in ests for _ in range(5)], points=pts.reshape(-1, 2)).reshape(b, 5, -1)
        h_v, h_t = self.decoder_error(lv)
        z = two_sided_z(lv)
        low, med, high = (np.empty((b, v.shape[2])) for _ in range(3))
        t = np.arange(1, v.shape[2] + 1, dtype=float)
        for r in range(b):
            c = v[r, 0]
            early = np.interp(t * (1.0 + h_t), t, c)  # the curve reaching each voltage earlier
            late = np.interp(t / (1.0 + h_t), t, c)
            d_lo = np.maximum(h_v, c - early)
            d_hi = np.maximum(h_v, late - c)
            _, _, hi_h = band_from_sigma_points(v[r], lv)
            s_h = (hi_h - c) / z  # the health part's std per sample
            low[r] = c - np.sqrt((z * s_h) ** 2 + d_lo ** 2)
            high[r] = c + np.sqrt((z * s_h) ** 2 + d_hi ** 2)
            med[r] = c
        out = [self._finish(np.clip(x, 0.0, 5.0), cur, dt, grid.shape[1], obs) for x in (low, med, high)]
        return tuple(o[0] for o in out) if single else tuple(out)


def load_predictor(path=None) -> DynaformerPredictor:
    """Load weights from ``path`` (default: the bundled model). Raises :class:`WeightsError`."""
    p = bundled_weights_path() if path is None else Path(path)
    model, pca, meta = load_artifact(p)
    return DynaformerPredictor(model, pca, meta, str(p))


@lru_cache(maxsize=4)
def load_pretrained(cell: str = "nasa18650") -> DynaformerPredictor:
    """The bundled, pretrained Dynaformer for the cell type ``cell`` (``"nasa18650"``, the paper's cell;
    ``"nasa18650_4a"``, the same cell at the NASA PCoE data set's loads, up to 4.5 A; ``"vtc6"``, fine-tuned
    on the identified VTC6; ``"vtc6_landing_held_out"`` and ``"vtc6_cell_held_out"``,
    on the VTC6 sets that never read VAH01's landing), loaded once per process."""
    return load_predictor(bundled_weights_path(cell))


def load_with_fallback(path) -> tuple[DynaformerPredictor, str | None]:
    """Load ``path``; on a bad file fall back to the bundled model. Returns (predictor, error or None)."""
    try:
        return load_predictor(path), None
    except WeightsError as err:
        return load_pretrained(), str(err)

"""The bundled NASA Dynaformer scored zero-shot on real NASA PCoE discharges, under the online protocol of
:mod:`uam_studio.battery.real.nasa_predict`.

What it reads: only a :class:`~uam_studio.battery.real.nasa_predict.KnownDischarge` per prediction, i.e. the
discharge's samples (times s from its start, current A with + = discharge, voltage V) up to ``context_s`` s
after the first loaded sample, and the load planned after it
(:func:`~uam_studio.battery.real.nasa_predict.planned_load`: the context's load continued). The measured
discharge (all its voltage) is read only by :func:`score_dynaformer`, for the true time to the cut-off.

How (:func:`dynaformer_eod_s`): the context and the planned current are put on the predictor's 1 s grid
(sample k covers [k, k + 1) s from the log's start; its current is the sample held there, its voltage is
the one at k + 1 s), and :meth:`~uam_studio.dynaformer.predictor.DynaformerPredictor.eod_interval_s` gives a
90% interval of the time to the cut-off. The current is held between the ~10 s samples (the 4 A
square-wave cells alternate 4 A / 0 A sample to sample); the voltage is interpolated linearly between two
samples at the same load and held where the load changes between them (it belongs to the held current).

The planned current is the context's load continued to :data:`HORIZON_S` (a constant load goes on, a
square wave keeps its phase): a NASA record's load drops to 0 A when the cell reaches the rig's own, lower
cut-off (2.0-2.7 V), and that end is never read. By default the log
starts at the rest sample before the load (``start_at_rest``); starting at the first loaded sample instead
(the fit then looks for a pre-roll) scored worse on these cells (median error 27% against 21%).

The cell's history (:func:`score_dynaformer`'s ``history``, default ``'health'``): the protocol lets a
method read the cell's finished discharges, and the physics method and the history predictor do. Two
readings: the Dynaformer's times divided by one plus the median of its relative errors on the cell's last
ten finished discharges at the same load and ambient (:func:`own_error_factor`, as the physics method's
are), and the health it decodes with taken from the cell's latest such discharge, fitted on its whole
record (:func:`finished_health`: a 300 s context says little about capacity, a whole discharge says it; its
q_max moved so that the model reaches the cut-off when that discharge did, as the physics method's is),
chosen over the context's fit where that has done better on the cell so far at that condition.

Fine-tuning (:func:`training_example`, :func:`history_examples`, :func:`finetune_dynaformer`): the decoder
trained further on real discharges, read exactly as at inference, with their whole measured voltage as the
target: at the context's health, or (:func:`history_examples`) at the previous discharge's whole-record
health, as ``history='health'`` decodes. Only training cells' discharges may go in; the result stays in
memory (nothing is written).

The weights: by default the bundled ones trained for these loads (:data:`NASA_DATA_CELL`,
``dynaformer_4a.pt``, currents up to 4.5 A); the aircraft's ``dynaformer.pt`` stops at 3 A.

All times are in s from the first loaded sample, currents in A, voltages in V.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import cast

import numpy as np
import torch

from uam_studio.battery.health.estimate import HealthEstimate
from uam_studio.battery.health.intervals import with_preroll
from uam_studio.battery.real.nasa_data import LOADED_A, NasaCell, NasaDischarge, RunConditions, same_conditions
from uam_studio.battery.real.nasa_predict import (
    HORIZON_S,
    OWN_ERROR_WINDOW,
    KnownDischarge,
    known_before,
    own_error_factor,
    planned_load,
)
from uam_studio.dynaformer.model import Dynaformer
from uam_studio.dynaformer.predictor import DynaformerPredictor, load_pretrained
from uam_studio.dynaformer.predictor_inputs import leading_rest
from uam_studio.errors import InputError

__all__ = ["COVER", "HISTORY", "HORIZON_S", "MATCH_STEPS", "MATCH_TOL_S", "MIN_OWN_ERRORS", "NASA_DATA_CELL",
           "Example", "dynaformer_eod_s", "finetune_dynaformer", "finished_health", "history_examples",
           "score_dynaformer", "summarise_dynaformer", "training_example", "with_dynaformer"]

NASA_DATA_CELL = "nasa18650_4a"  # the bundled weights for these discharges: trained up to 4.5 A (cells.py)


def _grid_voltage(t: np.ndarray, i: np.ndarray, v: np.ndarray, at: np.ndarray, first: int) -> np.ndarray:
    """Voltage (V) at the times ``at`` (s, each the end of a 1 s grid step) from samples ``first``.. of
    (``t`` s, ``i`` A, ``v`` V): linear between two samples at the same load, else the earlier sample's
    (held with its current, as the grid holds the current)."""
    j = np.clip(np.searchsorted(t, at - 0.5, side="right") - 1, first, t.size - 2)
    frac = np.clip((at - t[j]) / (t[j + 1] - t[j]), 0.0, 1.0)
    same = np.abs(i[j + 1] - i[j]) <= LOADED_A
    return np.where(same, v[j] + frac * (v[j + 1] - v[j]), v[j])


def _context_voltage(known: KnownDischarge, start: int, n_grid: int) -> np.ndarray:
    """The context voltage (V) at 1, 2, ..., ``n_grid`` s after sample ``start``, from the known samples only."""
    n = known.voltage_v.size
    at = known.time_s[start] + np.arange(1, n_grid + 1, dtype=float)
    return _grid_voltage(known.time_s[:n], known.current_a[:n], known.voltage_v, at, start)


def dynaformer_eod_s(predictor: DynaformerPredictor, known: KnownDischarge, cutoff_v: float = 3.0, *,
                     start_at_rest: bool = True,
                     estimate: HealthEstimate | None = None) -> tuple[float, float, float] | None:
    """(low, median, high) of the 90% interval of the time (s, from the first loaded sample) to the first
    predicted voltage below ``cutoff_v`` (V), from ``known`` only; None where the median never crosses
    within the profile (a high end beyond it is ``math.inf``). ``estimate``: the health to decode with
    (e.g. :func:`finished_health` of the cell's previous discharge) instead of the context's fit.

    :param start_at_rest: start the log at the rest sample before the load (0 A held until the first
        loaded sample); else at the first loaded sample (the fit then looks for a pre-roll).
    """
    start = known.load_start - 1 if start_at_rest else known.load_start
    t0 = float(known.time_s[start])
    n_ctx = int(math.floor(float(known.time_s[known.voltage_v.size - 1]) - t0 + 1e-9))
    times, current = planned_load(known, start, HORIZON_S)
    n_grid = int(HORIZON_S)
    if n_ctx < 20 or n_grid <= n_ctx:
        return None
    held = np.clip(np.searchsorted(times, t0 + np.arange(n_grid) + 0.5, side="right") - 1, 0, times.size - 1)
    grid_i = current[held]
    ctx_v = _context_voltage(known, start, n_ctx)
    iv = predictor.eod_interval_s(grid_i[:n_ctx], ctx_v, grid_i, dt_s=1.0, level=0.9, eod_v=cutoff_v, estimate=estimate)
    if iv.censored[1]:
        return None
    shift = float(known.time_s[known.load_start]) - t0
    return iv.low_s - shift, iv.median_s - shift, (math.inf if iv.censored[2] else iv.high_s - shift)


HISTORY = ("health", "bias", "off")
"""What of the cell's history :func:`score_dynaformer` reads (module docstring)."""
COVER = 0.9  # the share of a method's own errors its interval must hold (the 90% interval)
MATCH_STEPS = 6  # tries of finished_health's q_max towards the discharge's own end
MATCH_TOL_S = 1.0  # s: a try ending this close to the discharge's own end is kept (the predictor's grid step)
MIN_OWN_ERRORS = 9  # errors at a condition before the previous discharge's health may be chosen: with n of
# them, the ceil(0.9 (n + 1))-th smallest |error| holds 90% (split conformal), which needs n >= 9


def finished_health(predictor: DynaformerPredictor, d: NasaDischarge, context_s: float = 300.0, cutoff_v: float = 3.0,
                    **options) -> HealthEstimate:
    """What the cell's health was on its finished discharge ``d``: the physics fit (q_max C, R0 ohm) of its
    whole record up to its last loaded sample, read as :func:`dynaformer_eod_s` reads a context (log from the
    rest sample, 1 s grid), with q_max then moved so that the Dynaformer, reading ``d``'s first ``context_s``
    s and its planned current as :func:`dynaformer_eod_s` does (``options``), reaches ``cutoff_v`` (V) when
    ``d`` did (as the physics method moves its q_max): at most :data:`MATCH_STEPS` tries (:func:`_next_q`),
    stopping within :data:`MATCH_TOL_S`, the closest kept. Unmoved where ``d`` did not reach the cut-off
    after its context or the model never does."""
    start, t0, last = _record_start(d)
    cur = _record_current(d, t0, last)
    volt = _grid_voltage(d.time_s, d.current_a, d.voltage_v, t0 + np.arange(1, cur.size + 1, dtype=float), start)
    est = cast(HealthEstimate, predictor.health_estimate(cur, volt))
    true_s = d.time_to_cutoff_s(cutoff_v)
    if true_s is None or true_s <= context_s:
        return est
    known = known_before(d, context_s)
    q, tried = est.q_max, []  # (|miss| s, q_max C, predicted end s)
    for _ in range(MATCH_STEPS):
        pred = dynaformer_eod_s(predictor, known, cutoff_v, estimate=replace(est, q_max=q), **options)
        if pred is None or not 0.0 < pred[1] < math.inf:
            break
        tried.append((abs(pred[1] - true_s), q, pred[1]))
        if tried[-1][0] < MATCH_TOL_S:
            break
        q = float(np.clip(_next_q(tried, true_s), 0.5 * est.q_max, 2.0 * est.q_max))
    return replace(est, q_max=min(tried)[1]) if tried else est


def _next_q(tried: list[tuple[float, float, float]], true_s: float) -> float:
    """The next q_max (C) to try: the secant through the two closest tries (miss s, q_max C, end s) where
    their ends differ and rise with q_max, else a proportional step from the latest."""
    _, q, end = tried[-1]
    if len(tried) >= 2:
        (_, qa, ea), (_, qb, eb) = sorted(tried)[:2]
        if qa != qb and (eb - ea) / (qb - qa) > 0.0:
            return qa + (true_s - ea) * (qb - qa) / (eb - ea)
    return q * true_s / end


def _record_start(d: NasaDischarge) -> tuple[int, float, int]:
    """(the rest sample before the load, its time s, the last loaded sample) of a whole record."""
    start = d.load_start - 1
    return start, float(d.time_s[start]), int(np.flatnonzero(d.current_a > LOADED_A)[-1])


def _record_current(d: NasaDischarge, t0: float, last: int) -> np.ndarray:
    """The record's current (A) on the 1 s grid from ``t0`` (s) to its sample ``last``, each sample held."""
    n = int(math.floor(float(d.time_s[last]) - t0 + 1e-9))
    return d.current_a[np.searchsorted(d.time_s, t0 + np.arange(n) + 0.5, side="right") - 1]


class _Method:
    """One way of predicting a cell's discharges, with its record on the cell: raw relative errors (for
    :func:`own_error_factor`) and |errors| after that correction (to choose between methods)."""

    def __init__(self) -> None:
        self.raw: list[tuple[NasaDischarge, float | None]] = []
        self.corrected: list[tuple[NasaDischarge, float]] = []

    def skill(self, d: RunConditions) -> tuple[int, float, float]:
        """(how many, median, conformal 90% bound) of its latest ten corrected |errors| (-) at ``d``'s load
        and ambient; the bound is infinite below :data:`MIN_OWN_ERRORS` errors."""
        e = np.sort([x for q, x in self.corrected if same_conditions(q, d)][-OWN_ERROR_WINDOW:])
        k = math.ceil(COVER * (e.size + 1))
        return e.size, float(np.median(e)) if e.size else math.inf, float(e[k - 1]) if k <= e.size else math.inf

    def record(self, d: NasaDischarge, raw: float | None, corrected: float | None, true_s: float) -> None:
        self.raw.append((d, None if raw is None else raw / true_s - 1.0))
        if corrected is not None:
            self.corrected.append((d, abs(corrected / true_s - 1.0)))


def score_dynaformer(cells: list[NasaCell], context_s: float = 300.0, cutoff_v: float = 3.0, every: int = 1,
                     predictor: DynaformerPredictor | None = None, history: str = "health",
                     **options) -> list[dict]:
    """One row per scored discharge (every ``every``-th of each cell, from its first) whose true time to
    ``cutoff_v`` (V) is after ``context_s`` (s): cell, discharge, ambient_c (C), context_s, true_s,
    median_s, low_s, high_s (s from the first loaded sample; None where the Dynaformer gives no crossing),
    raw_median_s (the Dynaformer at the context's health, uncorrected) and health_from ('context' or
    'previous discharge').

    ``history`` (:data:`HISTORY`), what of the cell's finished discharges it reads (module docstring):
    'off', nothing; 'bias', each method's times divided by :func:`own_error_factor` of its own errors on
    the cell; 'health' (default), also a second prediction decoded at :func:`finished_health` of the
    cell's latest scored discharge at the same load and ambient, chosen over the context's when its
    corrected errors at that condition (at least :data:`MIN_OWN_ERRORS`) have the smaller median.
    ``options`` go to :func:`dynaformer_eod_s`; ``predictor`` defaults to the bundled weights trained for
    the data set's loads (:data:`NASA_DATA_CELL`)."""
    if history not in HISTORY:
        raise InputError("history", f"must be one of {', '.join(HISTORY)}, got {history!r}")
    predictor = predictor or load_pretrained(NASA_DATA_CELL)
    rows = []
    for cell in cells:
        context, previous = _Method(), _Method()
        latest: list[tuple[NasaDischarge, HealthEstimate]] = []  # scored discharges and their whole-record health
        for d in cell.discharges[::every]:
            true_s = d.time_to_cutoff_s(cutoff_v)
            if true_s is None or true_s <= context_s:
                continue
            known = known_before(d, context_s)
            preds = {"context": dynaformer_eod_s(predictor, known, cutoff_v, **options)}
            est = _latest_health(latest, known)
            if history == "health" and est is not None:
                preds["previous discharge"] = dynaformer_eod_s(predictor, known, cutoff_v, estimate=est, **options)
            methods = (("context", context), ("previous discharge", previous))
            out: dict[str, tuple[float, float, float] | None] = {}
            for name, method in methods:
                pred = preds.get(name)
                f = own_error_factor(method.raw, known) if history != "off" else 1.0
                out[name] = None if pred is None else (pred[0] / f, pred[1] / f, pred[2] / f)
            pick = "context"
            chosen = out.get("previous discharge")
            if chosen is not None:
                (n_p, m_p, bound), (_, m_c, _) = previous.skill(known), context.skill(known)
                if n_p >= MIN_OWN_ERRORS and m_p < m_c:
                    pick = "previous discharge"  # its interval also holds its own errors on this cell
                    out[pick] = (min(chosen[0], chosen[1] / (1.0 + bound)), chosen[1],
                                 max(chosen[2], chosen[1] / max(1.0 - bound, 1e-3)))
            low, med, high = out[pick] or (None, None, None)
            raw = preds["context"]
            rows.append({"cell": cell.name, "discharge": d.index, "ambient_c": d.ambient_c, "context_s": context_s,
                         "true_s": true_s, "median_s": med, "low_s": low, "high_s": high,
                         "raw_median_s": None if raw is None else raw[1], "health_from": pick})
            for name, method in methods:  # the discharge has finished: its errors are history now
                pred, corrected = preds.get(name), out.get(name)
                method.record(d, None if pred is None else pred[1], None if corrected is None else corrected[1],
                              true_s)
            if history == "health":
                # finished: its whole record is history now
                latest.append((d, finished_health(predictor, d, context_s, cutoff_v, **options)))
    return rows


def with_dynaformer(rows: list, cells: list[NasaCell], context_s: float = 300.0, cutoff_v: float = 3.0,
                    every: int = 1) -> list:
    """``rows`` (``nasa_eval.ScoredDischarge``) with ``dynaformer_s`` set to :func:`score_dynaformer`'s
    median (its default history method) on the same discharge; None where it never crosses."""
    dyn = {(r["cell"], r["discharge"]): r["median_s"] for r in score_dynaformer(cells, context_s, cutoff_v, every)}
    return [replace(r, dynaformer_s=dyn.get((r.cell, r.discharge))) for r in rows]


def _latest_health(latest: list[tuple[NasaDischarge, HealthEstimate]], d: RunConditions) -> HealthEstimate | None:
    """The whole-record health of the latest of ``latest`` (a cell's finished discharges, oldest first) run at
    ``d``'s load and ambient; None where there is none."""
    return next((e for q, e in reversed(latest) if same_conditions(q, d)), None)


def summarise_dynaformer(rows: list[dict]) -> dict:
    """n, predictions with no crossing (``none``), and over the rest: median and 95th percentile of
    |median_s - true_s| / (true_s - context_s) (%), its median signed value (bias, %) and the 90%
    interval's coverage (-)."""
    ok = [r for r in rows if r["median_s"] is not None]
    out: dict = {"n": len(rows), "none": len(rows) - len(ok)}
    if ok:
        err = np.array([(r["median_s"] - r["true_s"]) / (r["true_s"] - r["context_s"]) for r in ok])
        out.update(median_pct=float(100 * np.median(np.abs(err))), p95_pct=float(100 * np.percentile(np.abs(err), 95)),
                   bias_pct=float(100 * np.median(err)),
                   coverage90=float(np.mean([r["low_s"] <= r["true_s"] <= r["high_s"] for r in ok])))
    return out


# ------------------------------------------------------------------ fine-tuning on real discharges
Example = tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""A training discharge: (cell name, decoder latent [2], decoder current [n] (A, 1 s grid), measured
voltage [n] (V) at the end of each step, loss weight [n] (0 where nothing was measured under load))."""


def training_example(predictor: DynaformerPredictor, d: NasaDischarge, context_s: float = 300.0,
                     estimate: HealthEstimate | None = None) -> Example | None:
    """``d`` as the decoder reads it at inference (:func:`dynaformer_eod_s`, log from the rest sample): the
    latent of the physics fit of its first ``context_s`` s, or of ``estimate`` where given (e.g. the
    :func:`finished_health` of the cell's previous discharge, as ``history='health'`` decodes), re-observed
    as in ``_decode``, its current
    up to the last loaded sample on the grid (the fit's pre-roll before it, its leading rest cut), and the
    measured voltage there as the target (the whole record: training cells only). Loss weight 4x between
    2.8 and 3.3 V (as :mod:`uam_studio.dynaformer.train`). None where the context is too short."""
    known = known_before(d, context_s)
    start, t0, last = _record_start(d)
    n_ctx = int(math.floor(float(known.time_s[known.voltage_v.size - 1]) - t0 + 1e-9))
    cur = _record_current(d, t0, last)
    if n_ctx < 20 or cur.size <= n_ctx:
        return None
    est = estimate or cast(HealthEstimate,  # a 1-D context: one estimate
                           predictor.health_estimate(cur[:n_ctx], _context_voltage(known, start, n_ctx)))
    grid, k_pre = with_preroll([est], cur[None], 1.0)
    k0 = int(leading_rest(grid)[0])
    grid = grid[:, k0:]
    latent = predictor._reobserved_latent(np.array([[est.q_max, est.r0]]), grid)[0].numpy()
    at = t0 + k0 + 1 - k_pre + np.arange(grid.shape[1], dtype=float)
    volt = _grid_voltage(d.time_s, d.current_a, d.voltage_v, at, start)
    weight = ((at >= d.load_time_s) & (at <= d.time_s[last])) * (1.0 + 3.0 * ((volt > 2.8) & (volt < 3.3)))
    return d.cell, latent, grid[0], volt, weight


def history_examples(predictor: DynaformerPredictor, cell: NasaCell, context_s: float = 300.0) -> list[Example]:
    """The :func:`training_example` of each of ``cell``'s discharges decoded at the :func:`finished_health` of
    the cell's latest earlier discharge at the same load and ambient, as ``score_dynaformer(history='health')``
    decodes it (discharges with no such earlier one are left out): the decoder fine-tuned where it is used.
    Training cells only."""
    out: list[Example] = []
    latest: list[tuple[NasaDischarge, HealthEstimate]] = []
    for d in cell.discharges:
        est = _latest_health(latest, known_before(d, context_s))
        if est is not None and (e := training_example(predictor, d, context_s, estimate=est)) is not None:
            out.append(e)
        latest.append((d, finished_health(predictor, d, context_s)))
    return out


def finetune_dynaformer(examples: list[Example], base: DynaformerPredictor | None = None, steps: int = 3000,
                        batch: int = 16, lr: float = 3e-4, seed: int = 0) -> DynaformerPredictor:
    """The ``base`` Dynaformer (default: the bundled weights of :data:`NASA_DATA_CELL`) with its decoder
    fine-tuned on ``examples`` (:func:`training_example`): AdamW, weighted MSE (V^2), ``steps`` batches of
    ``batch`` discharges of similar length, linear warm-up over 100 steps then cosine decay, gradients clipped
    at 1. Kept in memory, never written.
    Its intervals reuse the base weights' decoder-error calibration (``source``)."""
    base = base or load_pretrained(NASA_DATA_CELL)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = Dynaformer(base.model.cfg)
    model.load_state_dict(base.model.state_dict())
    model.train()
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: min(1.0, (s + 1) / 100) * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(s, steps) / steps))))
    order = np.argsort([e[2].size for e in examples], kind="stable")
    buckets = [b for b in np.array_split(order, max(1, len(examples) // (4 * batch))) if b.size]
    chunk = model.cfg.chunk
    for _ in range(steps):
        bucket = buckets[int(rng.integers(len(buckets)))]
        rows = [examples[k] for k in rng.choice(bucket, min(batch, bucket.size), replace=False)]
        t = int(math.ceil(max(r[2].size for r in rows) / chunk) * chunk)
        cur, volt, w = (np.zeros((len(rows), t), np.float32) for _ in range(3))
        for k, r in enumerate(rows):
            cur[k, :r[2].size], volt[k, :r[2].size], w[k, :r[2].size] = r[2], r[3], r[4]
        w_t = torch.as_tensor(w)
        pred = model.decode(torch.as_tensor(np.stack([r[1] for r in rows])), torch.as_tensor(cur))
        loss = (w_t * (pred - torch.as_tensor(volt)) ** 2).sum() / w_t.sum().clamp_min(1.0)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        sched.step()
    model.eval()
    meta = {**base.meta, "finetuned_on": sorted({e[0] for e in examples}), "finetune_steps": steps}
    return DynaformerPredictor(model, base.pca, meta, base.source)

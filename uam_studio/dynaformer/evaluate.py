"""Held-out evaluation of a Dynaformer: EOD timing (RTE), voltage RMSE, health correlations.

RTE = |t_EOD,pred - t_EOD,true| / t_EOD,true with EOD at 3.0 V, on profiles whose
true EOD falls inside the profile. RMSE is over the true-valid samples (above 3.0 V).
The predictor returns the observed context as observed, so an EOD inside the context
(cells whose voltage drops below 3.0 V during the take-off) scores RTE 0; the
``*_after_context`` figures count only EODs after the context: the predictions proper.
"""

from __future__ import annotations

import numpy as np

from .data import make_dataset
from .predictor import DynaformerPredictor

EOD_V = 3.0
SETS = {
    "interpolation_flight": dict(band="train", flight_fraction=1.0),
    "interpolation_generic": dict(band="train", flight_fraction=0.0),
    "extrapolation_flight": dict(band="extra", flight_fraction=1.0),
    "extrapolation_generic": dict(band="extra", flight_fraction=0.0),
}


def _first_below(v: np.ndarray, limit: np.ndarray, eod_v: float) -> np.ndarray:
    """Index of the first sample below eod_v before ``limit`` per row; -1 if none."""
    t = v.shape[1]
    below = (v < eod_v) & (np.arange(t)[None, :] < limit[:, None])
    return np.where(below.any(1), np.argmax(below, 1), -1)


def predict_set(pred: DynaformerPredictor, ds, context_s: int = 20, noise_v: float = 0.0,
                seed: int = 0, batch: int = 64) -> np.ndarray:
    """Predicted voltage [N, T] for a DischargeSet, contexts of ``context_s`` with voltage noise (V)."""
    rng = np.random.default_rng(seed)
    out = np.zeros(ds.voltage_v.shape, np.float64)
    order = np.argsort(ds.length)
    for s in range(0, len(ds), batch):
        idx = order[s:s + batch]
        t = int(ds.length[idx].max())
        ci = ds.current_a[idx, :context_s].astype(float)
        cv = ds.voltage_v[idx, :context_s].astype(float) + rng.normal(size=(idx.size, context_s)) * noise_v
        out[idx, :t] = pred.predict(ci, np.clip(cv, 0.0, 5.0), ds.current_a[idx, :t].astype(float))
    return out


def eod_metrics(ds, v_pred: np.ndarray, context_s: int = 20) -> dict:
    true_k = _first_below(ds.voltage_v, ds.length, EOD_V)
    pred_k = _first_below(v_pred, ds.length, EOD_V)
    has = true_k >= 0
    rte = np.abs(pred_k[has] - true_k[has]).astype(float) / (true_k[has] + 1.0)
    rte = np.where(pred_k[has] < 0, np.abs(ds.length[has] - true_k[has]) / (true_k[has] + 1.0), rte)
    # RMSE over samples where the true voltage is valid (above the 3.0 V EOD and before it).
    t = np.arange(ds.voltage_v.shape[1])[None, :]
    stop = np.where(has, true_k, ds.length)
    mask = (t < stop[:, None]) & ds.valid
    err = (v_pred - ds.voltage_v)[mask]
    agree = float(np.mean((pred_k >= 0) == has))
    later = rte[true_k[has] >= context_s]
    return {
        "n": int(len(ds)), "n_eod": int(has.sum()),
        "n_eod_after_context": int(later.size),
        "median_rte_after_context": float(np.median(later)) if later.size else None,
        "median_rte": float(np.median(rte)) if rte.size else None,
        "mean_rte": float(np.mean(rte)) if rte.size else None,
        "p90_rte": float(np.quantile(rte, 0.9)) if rte.size else None,
        "rmse_mv": float(1000 * np.sqrt(np.mean(err ** 2))),
        "eod_agreement": agree,
    }


def health_correlations(pred: DynaformerPredictor, ds, context_s: int, noise_v: float, seed: int = 0) -> dict:
    """|Pearson r| between the PCs and (r0, q_max); the PC assignment with the larger sum is reported."""
    rng = np.random.default_rng(seed)
    n = min(context_s, int(ds.valid.sum(1).min()))
    ci = ds.current_a[:, :n].astype(float)
    cv = np.clip(ds.voltage_v[:, :n] + rng.normal(size=(len(ds), n)) * noise_v, 0.0, 5.0)
    pcs = pred.health(ci, cv)
    c = np.corrcoef(np.column_stack([pcs, ds.r0, ds.q_max]).T)
    r_pc1_r0, r_pc1_q, r_pc2_r0, r_pc2_q = abs(c[0, 2]), abs(c[0, 3]), abs(c[1, 2]), abs(c[1, 3])
    if r_pc1_r0 + r_pc2_q >= r_pc2_r0 + r_pc1_q:
        return {"r0_pc": 1, "abs_r_r0": float(r_pc1_r0), "q_max_pc": 2, "abs_r_q_max": float(r_pc2_q)}
    return {"r0_pc": 2, "abs_r_r0": float(r_pc2_r0), "q_max_pc": 1, "abs_r_q_max": float(r_pc1_q)}


def evaluate(pred: DynaformerPredictor, n: int = 400, seed: int = 12345,
             contexts=(20, 60, 400), noises_mv=(0, 5, 10)) -> dict:
    """All held-out metrics as a JSON-ready dict (sets drawn with seeds disjoint from training)."""
    out: dict = {"weights": pred.source, "sets": {}, "health": []}
    datasets = {}
    for k, (name, kw) in enumerate(SETS.items()):
        ds = make_dataset(n, seed=seed + 1000 * (k + 1), **kw)
        datasets[name] = ds
        out["sets"][name] = eod_metrics(ds, predict_set(pred, ds))
    flight = datasets["interpolation_flight"]
    for ctx in contexts:
        for noise in noises_mv:
            row = {"context_s": ctx, "noise_mv": noise}
            row.update(health_correlations(pred, flight, ctx, noise / 1000.0, seed=seed))
            out["health"].append(row)
    return out


def format_report(m: dict) -> str:
    lines = [f"weights: {m['weights']}",
             "set                      n   n_eod  median RTE  p90 RTE  RMSE mV  EOD agree  "
             "| EOD after context: n  median RTE"]
    for name, s in m["sets"].items():
        med, p90, later = (("-" if s.get(k) is None else f"{s[k]:.4f}")
                           for k in ("median_rte", "p90_rte", "median_rte_after_context"))
        lines.append(f"{name:22s} {s['n']:4d} {s['n_eod']:6d}  {med:>10s} {p90:>8s} {s['rmse_mv']:8.1f} "
                     f"{s['eod_agreement']:9.3f}  | {s.get('n_eod_after_context', 0):20d}  {later:>10s}")
    lines.append("health (interpolation flight contexts): context s, noise mV -> |r| with r0, |r| with q_max")
    for h in m["health"]:
        lines.append(f"  {h['context_s']:4d} s {h['noise_mv']:3d} mV   r0~PC{h['r0_pc']}: {h['abs_r_r0']:.3f}   "
                     f"q_max~PC{h['q_max_pc']}: {h['abs_r_q_max']:.3f}")
    return "\n".join(lines)

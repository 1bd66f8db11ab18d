"""Every NASA discharge's end predicted online (:mod:`uam_studio.battery.real.nasa_predict`), scored against what
happened, beside the persistence baseline and progpy's default model with no health estimate.

- :func:`fit_nasa_model`: the cross-cell numbers of a :class:`NasaEodModel` from training cells.
- :func:`score_cell`: one cell's life run through the online protocol: one :class:`ScoredDischarge`
  per discharge that ends after the context.
- :func:`evaluate_nasa`: a folder of cells; a cell among the bundled model's training cells is scored by a
  model refitted without it (leave one cell out) when the other training cells are in the folder, else
  by the bundled model, and its rows say which (``fit``: 'loco', 'bundled' or 'in-sample').
- :func:`summarise`: the table per cell and per condition.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import least_squares

from uam_studio.battery.parameters import DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.battery.real.nasa_data import (
    LOADED_A,
    NasaCell,
    NasaDischarge,
    persistence_s,
)
from uam_studio.battery.real.nasa_predict import (
    EARLY_ERRORS,
    N0_SLOPE,
    RISKS,
    Z_LEVELS,
    CellBelief,
    NasaEodModel,
    ambient_band,
    charge_to_cutoff_ah,
    context_voltage_v,
    history_log_change,
    known_before,
    rest_feature,
)
from uam_studio.battery.simulate import simulate

__all__ = ["BUNDLED_SETTINGS", "FitCache", "ScoredDischarge", "condition_of", "conservative_quantile",
           "evaluate_nasa", "fit_bundled", "fit_nasa_model", "format_table", "models_literal", "progpy_default_curve",
           "progpy_default_s", "score_cell", "skipped_summary", "summarise"]

YOUNG = 5  # a cell's first this many discharges at a condition give its "young" charge
MIN_BAND = 100  # an ambient band with fewer training errors takes the pooled quantiles
EARLY = EARLY_ERRORS  # a cell's first history predictions, whose errors set the 'early' prior scale


@dataclass(frozen=True)
class ScoredDischarge:
    """One discharge predicted at ``context_s`` (s) and what happened; times (s) from the first loaded
    sample. ``persistence_s`` and ``progpy_s`` are the baselines (None where there is none);
    ``dynaformer_s`` the bundled NASA Dynaformer's median on the same discharge, where it was asked for
    and crosses the cut-off."""

    cell: str
    discharge: int
    ambient_c: float
    condition: str
    context_s: float
    true_s: float
    median_s: float
    low_s: float
    high_s: float
    bound95_s: float
    bound99_s: float
    persistence_s: float | None
    progpy_s: float | None
    method: str
    flag: str | None
    fit: str
    dynaformer_s: float | None = None

    def as_dict(self) -> dict:
        """The row as plain JSON types."""
        return asdict(self)


def condition_of(d) -> str:
    """A discharge's test condition: ambient (C), mean load (A), and 'square wave' where the load is on
    for less than 80% of the samples after it starts."""
    on = d.current_a[d.load_start:] > LOADED_A
    on = on[:np.flatnonzero(on)[-1] + 1]
    pulsed = " square wave" if on.mean() < 0.8 else ""
    return f"{round(d.ambient_c):d} C, {d.mean_load_a():.0f} A{pulsed}"


def progpy_default_curve(d: NasaDischarge, cutoff_v: float = 2.5) -> tuple[np.ndarray, np.ndarray, float | None]:
    """progpy's default cell (q_max 7600 C, R0 0.117 ohm, no health estimate) along ``d``'s measured
    current, held between samples at 1 s steps and carried on at its last load past the record (up to 3x
    its length): (time s from the first loaded sample, voltage V, time s to ``cutoff_v`` V or None)."""
    t = d.time_s[d.load_start:] - d.load_time_s
    grid = np.arange(0.0, 3.0 * t[-1] + 1.0, 1.0)
    idx = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.size - 1)
    cur = np.clip(d.current_a[d.load_start:][idx], 0.0, None)
    on = d.current_a[d.load_start:] > LOADED_A
    cur[grid > t[-1]] = float(d.current_a[d.load_start:][on][-1])
    r = simulate(cur, 1.0, DEFAULT_Q_MAX, DEFAULT_R0, cutoff_v)
    keep = np.asarray(r.valid)
    eod = None if math.isnan(float(r.eod_s)) else float(r.eod_s) - 1.0
    return (np.r_[0.0, np.asarray(r.time_s)[keep]],
            np.r_[float(np.asarray(r.voltage_v)[0]), np.asarray(r.voltage_v)[keep]], eod)


def progpy_default_s(d: NasaDischarge, cutoff_v: float) -> float | None:
    """:func:`progpy_default_curve`'s time (s, from the first loaded sample) to ``cutoff_v`` (V); None if it
    never gets there within 3x the record."""
    return progpy_default_curve(d, cutoff_v)[2]


def _robust_slope(x: np.ndarray, y: np.ndarray) -> float:
    """The slope of ``y`` on ``x`` through the origin, fitted with a soft L1 loss (scale 0.05)."""
    return float(least_squares(lambda p: p[0] * x - y, [0.0], loss="soft_l1", f_scale=0.05).x[0])


def _cell_charges(c: NasaCell, cutoff_v: float, context_s: float) -> list[tuple[tuple[float, float], float, float,
                                                                                  bool]]:
    """(condition key, charge to the cut-off Ah, context voltage V, whether among the cell's first
    :data:`YOUNG` at that condition) of each of ``c``'s discharges that ends after the context."""
    out = []
    seen: dict[tuple[float, float], int] = {}
    for d in c.discharges:
        q = charge_to_cutoff_ah(d, cutoff_v)
        t = d.time_to_cutoff_s(cutoff_v)
        if q is None or t is None or t <= context_s:
            continue
        key = (round(d.mean_load_a() * 2) / 2, float(round(d.ambient_c)))
        out.append((key, q, context_voltage_v(known_before(d, context_s)), seen.get(key, 0) < YOUNG))
        seen[key] = seen.get(key, 0) + 1
    return out


def _charge_table(charges: list[tuple[tuple[float, float], float, float, bool]]) -> tuple[tuple[float, ...], ...]:
    """Per condition of ``charges`` (:func:`_cell_charges` of the training cells): (load A, ambient C,
    median charge to the cut-off Ah, that of each cell's first :data:`YOUNG`, median context voltage V,
    d log charge / d context voltage 1/V fitted robustly)."""
    groups: dict[tuple[float, float], tuple[list[float], list[float], list[float]]] = {}
    for key, q, v, young in charges:
        every, first, volts = groups.setdefault(key, ([], [], []))
        every.append(q)
        volts.append(v)
        if young:
            first.append(q)
    out = []
    for k, (e, y, vs) in sorted(groups.items()):
        logq, volt = np.log(e), np.array(vs)
        v0, slope = float(np.median(volt)), 0.0
        if len(e) >= 10 and np.ptp(volt) > 1e-3:
            slope = _robust_slope(volt - v0, logq - np.median(logq))
        out.append((k[0], k[1], float(np.median(e)), float(np.median(y)) if y else float(np.median(e)), v0, slope))
    return tuple(out)


def _cell_pairs(c: NasaCell, context_s: float, cutoff_v: float) -> list[tuple[float, float, float, str, str]]:
    """(log change of the time to the cut-off, context shift V, rest-feature change, ambient band, that or
    'early' for the cell's first :data:`EARLY`) of each of ``c``'s discharges against the reference
    :meth:`CellBelief.previous` picks for it."""
    probe = NasaEodModel(context_s, cutoff_v, 0.0, 0.0, {"room": 1.0}, {"all": (0.0,) * len(Z_LEVELS)},
                         ((2.0, 24.0, 1.0, 1.0),), (0.0,) * len(RISKS))  # its predictions are not read
    belief = CellBelief(probe)
    out: list[tuple[float, float, float, str, str]] = []
    for _, d, known, _, t in belief.walk(c.discharges):
        p = belief.previous(known)
        if p is None:
            continue
        t_p = p.time_to_cutoff_s(cutoff_v)
        assert t_p is not None  # p was picked for reaching it
        band = ambient_band(d.ambient_c)
        out.append((math.log(t / t_p), belief.shift_v(known, p), rest_feature(known.rest_s) - rest_feature(p.rest_s),
                    band, "early" if len(out) < EARLY else band))
    return out


class FitCache:
    """Each cell's share of a fit (:func:`_cell_pairs`, :func:`_cell_charges`), computed once per (cell,
    context s, cut-off V) and reused by every leave-one-out fit that reads the cell."""

    def __init__(self) -> None:
        self._pairs: dict[tuple[str, float, float], list] = {}
        self._charges: dict[tuple[str, float, float], list] = {}

    def pairs(self, c: NasaCell, context_s: float, cutoff_v: float) -> list:
        key = (c.path, context_s, cutoff_v)
        if key not in self._pairs:
            self._pairs[key] = _cell_pairs(c, context_s, cutoff_v)
        return self._pairs[key]

    def charges(self, c: NasaCell, context_s: float, cutoff_v: float) -> list:
        key = (c.path, context_s, cutoff_v)
        if key not in self._charges:
            self._charges[key] = _cell_charges(c, cutoff_v, context_s)
        return self._charges[key]


def conservative_quantile(x: np.ndarray, risk: float) -> float:
    """The ``risk`` quantile of ``x``, taken one order statistic further out (split-conformal style)."""
    x = np.sort(x)
    n = x.size
    if risk < 0.5:
        return float(x[max(0, math.floor(risk * (n + 1)) - 1)])
    if risk > 0.5:
        return float(x[min(n - 1, math.ceil(risk * (n + 1)) - 1)])
    return float(np.median(x))


def _slopes(y: np.ndarray, dv: np.ndarray, dr: np.ndarray) -> np.ndarray:
    """(a, b, c) of ``y = a + b dv + c dr``, fitted robustly (soft L1) and shrunk towards 0 by
    :data:`N0_SLOPE` pairs."""
    if y.size < 3:
        return np.zeros(3)
    fit = least_squares(lambda p: p[0] + p[1] * dv + p[2] * dr - y, np.zeros(3), loss="soft_l1", f_scale=0.01).x
    return fit * y.size / (y.size + N0_SLOPE)


def fit_nasa_model(cells: list[NasaCell], context_s: float = 300.0, cutoff_v: float = 3.0,
                   cache: FitCache | None = None) -> NasaEodModel:
    """Fit the cross-cell numbers on ``cells`` (every discharge of each, online in order); ``cache`` keeps
    each cell's share for the next fit that reads it."""
    cache = cache or FitCache()
    rows = [r for c in cells for r in cache.pairs(c, context_s, cutoff_v)]
    y, dv, dr = (np.array([r[k] for r in rows], dtype=float).reshape(-1) for k in range(3))
    bands, kind = [r[3] for r in rows], [r[4] for r in rows]
    a, b, _ = _slopes(y, dv, np.zeros_like(dr))
    slope: dict[str, tuple[float, float, float]] = {}
    for name in ("cold", "room", "hot"):
        m = np.array([n == name for n in bands], dtype=bool)
        if m.any():
            sa, sb, sc = (float(x) for x in _slopes(y[m], dv[m], dr[m]))
            slope[name] = (sa, sb, sc)
    coefficients = [slope.get(n, (float(a), float(b), 0.0)) for n in bands]  # NasaEodModel.coefficients
    res = y - np.array([history_log_change(c, v, r) for c, v, r in zip(coefficients, dv, dr)])
    scale = {}
    for name in ("cold", "room", "hot", "early"):
        r = res[[k for k, n in enumerate(kind) if n == name]]
        if r.size >= 5:
            scale[name] = float(1.4826 * np.median(np.abs(r - np.median(r))))
    if not scale:
        scale["room"] = float(1.4826 * np.median(np.abs(res - np.median(res)))) if res.size else 0.01
    charge = _charge_table([x for c in cells for x in cache.charges(c, context_s, cutoff_v)])
    draft = NasaEodModel(context_s, cutoff_v, float(a), float(b), scale, {"all": (0.0,) * len(Z_LEVELS)}, charge,
                         (0.0,) * len(RISKS), tuple(c.name for c in cells), slope)
    studentized: dict[str, list[float]] = {"all": []}
    logs = []
    for c in cells:
        belief = CellBelief(draft)
        for _, d, known, pred, t in belief.walk(c.discharges):
            p = belief.previous(known)
            if p is not None:
                e = (math.log(t / belief.centre_s(known, p)) - belief.bias()) / belief.spread(known, p)
                studentized["all"].append(e)
                studentized.setdefault(ambient_band(d.ambient_c), []).append(e)
                if len(belief.errors) < EARLY_ERRORS:
                    studentized.setdefault("early", []).append(e)
            else:
                logs.append(math.log(t / pred.median_s))
    z = {band: tuple(conservative_quantile(np.array(e), r) for r in Z_LEVELS) for band, e in studentized.items()
         if band == "all" or len(e) >= MIN_BAND}
    prior_log = (tuple(conservative_quantile(np.array(logs), r) for r in RISKS) if len(logs) >= 5
                 else (-1.0, -0.5, 0.0, 0.5))
    return NasaEodModel(context_s, cutoff_v, float(a), float(b), scale, z, draft.charge, prior_log,
                        tuple(c.name for c in cells), slope)


def score_cell(cell: NasaCell, model: NasaEodModel, fit: str = "bundled", progpy: bool = True,
               every: int = 1) -> list[ScoredDischarge]:
    """Run ``cell``'s life through the online protocol with ``model``; one row per ``every``-th discharge
    whose cut-off comes after the context (those that end within it need no prediction). The belief
    predicts and takes in every discharge, whether or not its row is kept."""
    out = []
    for k, d, _, pred, t in CellBelief(model).walk(cell.discharges):
        if k % every:
            continue
        out.append(ScoredDischarge(
            cell.name, d.index, d.ambient_c, condition_of(d), model.context_s, t, pred.median_s, pred.low_s,
            pred.high_s, pred.bound95_s, pred.bound99_s, persistence_s(cell, k, model.cutoff_v),
            progpy_default_s(d, model.cutoff_v) if progpy else None, pred.method, pred.flag, fit))
    return out


def evaluate_nasa(cells: list[NasaCell], bundled: NasaEodModel, training: list[NasaCell] | None = None,
                  progpy: bool = True, every: int = 1) -> list[ScoredDischarge]:
    """Score every cell. A cell the bundled model trained on is scored by a model fitted on ``training``
    (default: the other cells given that the bundled model trained on) without it, if that leaves at least
    half the bundled model's training cells; else by the bundled model, labelled 'in-sample'."""
    pool = training if training is not None else [c for c in cells if c.name in bundled.trained_on]
    cache = FitCache()
    rows = []
    for c in cells:
        if c.name in bundled.trained_on:
            others = [o for o in pool if o.name != c.name]
            if len(others) >= len(bundled.trained_on) / 2:
                model, fit = fit_nasa_model(others, bundled.context_s, bundled.cutoff_v, cache), "loco"
            else:
                model, fit = bundled, "in-sample"
        else:
            model, fit = bundled, "bundled"
        rows += score_cell(c, model, fit, progpy, every)
    return rows


def skipped_summary(cells: list[NasaCell], context_s: float) -> str:
    """Why ``cells`` hold nothing to score, in one line: runs skipped per reason, and runs that end within
    the context (the first cell's first reason quoted)."""
    reasons = [why for c in cells for _, why in c.skipped]
    ended = sum(ended_in_context(c, context_s) for c in cells)
    runs = sum(len(c.discharges) + len(c.skipped) for c in cells)
    out = f"{len(cells)} cell(s), {runs} run(s): {len(reasons)} skipped"
    if reasons:
        out += f" (e.g. {reasons[0]})"
    return out + f", {ended} reach the cut-off within the {context_s:g} s context"


def ended_in_context(cell: NasaCell, context_s: float) -> int:
    """How many of ``cell``'s discharges reach its cut-off within ``context_s`` (s): nothing to predict."""
    return sum(1 for d in cell.discharges if (t := d.time_to_cutoff_s(cell.cutoff_v)) is not None and t <= context_s)


def _stats(rows: list[ScoredDischarge]) -> dict:
    t = np.array([r.true_s for r in rows])
    left = t - np.array([r.context_s for r in rows])
    med = np.array([r.median_s for r in rows])
    err = (med - t) / left
    pers = [(r.persistence_s - r.true_s) / (r.true_s - r.context_s) for r in rows if r.persistence_s is not None]
    prog = [(r.progpy_s - r.true_s) / (r.true_s - r.context_s) for r in rows if r.progpy_s is not None]
    dyn = [(d - r.true_s) / (r.true_s - r.context_s) for r in rows
           if (d := getattr(r, "dynaformer_s", None)) is not None]

    def pct(x, q):
        return float(100 * np.percentile(np.abs(x), q)) if len(x) else None

    return {"n": len(rows), "median_pct": pct(err, 50), "p95_pct": pct(err, 95),
            "bias_pct": float(100 * np.median(err)),
            "coverage90": float(np.mean([(r.low_s <= r.true_s <= r.high_s) for r in rows])),
            "miss95": float(np.mean([r.true_s < r.bound95_s for r in rows])),
            "miss99": float(np.mean([r.true_s < r.bound99_s for r in rows])),
            "width_pct": float(100 * np.median([(r.high_s - r.low_s) / (r.true_s - r.context_s) for r in rows])),
            "flagged": sum(r.flag is not None for r in rows),
            "persistence_n": len(pers), "persistence_median_pct": pct(pers, 50), "persistence_p95_pct": pct(pers, 95),
            "progpy_median_pct": pct(prog, 50), "progpy_p95_pct": pct(prog, 95),
            "dynaformer_n": len(dyn), "dynaformer_median_pct": pct(dyn, 50), "dynaformer_p95_pct": pct(dyn, 95)}


def summarise(rows: list[ScoredDischarge], key: str = "cell") -> dict[str, dict]:
    """Statistics per ``key`` ('cell', 'condition' or 'method'), and 'all'."""
    out: dict[str, dict] = {}
    for name in sorted({getattr(r, key) for r in rows}):
        out[name] = _stats([r for r in rows if getattr(r, key) == name])
    if rows:
        out["all"] = _stats(rows)
    return out


BUNDLED_SETTINGS = ((300.0, 3.0), (60.0, 3.0), (300.0, 3.2), (60.0, 3.2))
"""(context s, cut-off V) of the bundled models; another setting takes the nearest (nasa_model.bundled_model)."""


def fit_bundled(cells: list[NasaCell]) -> list[NasaEodModel]:
    """One model per :data:`BUNDLED_SETTINGS`, each fitted on every cell given (each loaded at its cut-off)."""
    from uam_studio.battery.real.nasa_data import load_nasa_cell

    out = []
    for context_s, cutoff_v in BUNDLED_SETTINGS:
        at = [c if c.cutoff_v == cutoff_v else load_nasa_cell(c.path, cutoff_v) for c in cells]
        out.append(fit_nasa_model(at, context_s, cutoff_v))
    return out


def _r(x: float) -> str:
    return f"{x:.6g}"


def models_literal(models: list[NasaEodModel]) -> str:
    """Python source of ``BUNDLED = (...)`` for :mod:`uam_studio.battery.real.nasa_model`."""
    lines = ["BUNDLED = ("]
    for m in models:
        z = ", ".join(f"{b!r}: ({', '.join(_r(v) for v in q)})" for b, q in m.z.items())
        scale = ", ".join(f"{b!r}: {_r(v)}" for b, v in m.scale.items())
        charge = ", ".join(f"({', '.join(_r(v) for v in row)})" for row in m.charge)
        slope_items = ", ".join(f"{k!r}: ({', '.join(_r(v) for v in c)})" for k, c in m.slope.items())
        lines += [
            "    NasaEodModel(",
            f"        context_s={_r(m.context_s)}, cutoff_v={_r(m.cutoff_v)}, a={_r(m.a)}, b={_r(m.b)},",
            f"        scale={{{scale}}},",
            f"        z={{{z}}},",
            f"        charge=({charge},),",
            f"        prior_log=({', '.join(_r(v) for v in m.prior_log)}),",
            f"        trained_on={m.trained_on!r},",
            f"        slope={{{slope_items}}},",
            "    ),"]
    lines.append(")")
    return "\n".join(wrapped for line in lines for wrapped in _wrap(line))


def _wrap(line: str, width: int = 120) -> list[str]:
    """``line`` (inside the literal's brackets) broken after commas into lines of at most ``width``
    characters, each continuation indented four spaces more."""
    indent = " " * (len(line) - len(line.lstrip()) + 4)
    out: list[str] = []
    while len(line) > width:
        cut = line.rfind(", ", 0, width - 1)
        if cut <= len(indent):
            break
        out.append(line[:cut + 1])
        line = indent + line[cut + 2:]
    return out + [line]


COLUMNS = ("scored", "skipped", "med %", "p95 %", "bias %", "cov90", "miss95", "miss99", "width %", "flagged",
           "| pers med %", "pers p95 %", "progpy med %", "progpy p95 %", "dyn med %", "dyn p95 %")


def _fmt(x, pct: bool = True) -> str:
    if x is None:
        return "-"
    return f"{x:.2f}" if pct else f"{x:.3f}"


def format_table(rows: list[ScoredDischarge], cells: list[NasaCell], context_s: float) -> str:
    """The table per cell, per condition and over all: errors in % of the true time left at the prediction
    instant, beside persistence, progpy's default model and (where asked for) the Dynaformer on the same
    discharges."""
    skipped = {c.name: len(c.skipped) + ended_in_context(c, context_s) for c in cells}
    fits = {r.cell: r.fit for r in rows}
    head = f"{'':26s}" + " ".join(f"{c:>9s}" for c in COLUMNS)
    out = [head]
    for title, key in (("cell", "cell"), ("condition", "condition")):
        out.append(f"-- per {title}")
        for name, st in summarise(rows, key).items():
            skip = skipped.get(name, sum(skipped.values()) if name == "all" else None)
            label = f"{name} ({fits[name]})" if key == "cell" and name in fits else name
            vals = [str(st["n"]), "-" if skip is None else str(skip), _fmt(st["median_pct"]), _fmt(st["p95_pct"]),
                    f"{st['bias_pct']:+.2f}", _fmt(st["coverage90"], False), _fmt(st["miss95"], False),
                    _fmt(st["miss99"], False), _fmt(st["width_pct"]), str(st["flagged"]),
                    _fmt(st["persistence_median_pct"]), _fmt(st["persistence_p95_pct"]),
                    _fmt(st["progpy_median_pct"]), _fmt(st["progpy_p95_pct"]),
                    _fmt(st["dynaformer_median_pct"]), _fmt(st["dynaformer_p95_pct"])]
            out.append(f"{label[:26]:26s}" + " ".join(f"{v:>9s}" for v in vals))
    return "\n".join(out)

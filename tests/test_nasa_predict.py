"""The NASA end-of-discharge predictor: the online protocol never reads a discharge's voltage after its
context, its bounds miss at their declared risk on synthetic lives with a known truth (held out of the
fit), and on the real lives it beats persistence where the data sit beside the checkout."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nasa_synthetic import synthetic_cell, synthetic_rows, write_cell

from uam_studio.battery.real.nasa_data import NasaCell
from uam_studio.battery.real.nasa_eval import evaluate_nasa, fit_nasa_model, score_cell, summarise
from uam_studio.battery.real.nasa_model import BUNDLED, bundled_model
from uam_studio.battery.real.nasa_predict import (
    EARLY_ERRORS,
    HORIZON_S,
    CellBelief,
    as_prediction,
    high_cap_s,
    known_before,
    min_width_s,
    seen_s,
)
from uam_studio.cli import main

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nasa_pcoe"


@pytest.fixture(scope="module")
def lives(tmp_path_factory) -> list[NasaCell]:
    tmp = tmp_path_factory.mktemp("lives")
    return [synthetic_cell(tmp, seed) for seed in range(8)]



def test_known_before_cuts_the_record_at_the_context(lives):
    d = lives[0].discharges[3]
    known = known_before(d, 300.0)
    n = known.voltage_v.size
    assert n < d.voltage_v.size and known.time_s.size == known.current_a.size == n
    assert known.time_s[-1] <= d.load_time_s + 300.0 < d.time_s[n]
    assert np.array_equal(known.current_a, d.current_a[:n])


def _after_context(d, how: str, rng: np.random.Generator):
    """``d`` with its record after the context changed: cut just after it, extended by 2000 s more of load,
    or its voltage and current there replaced by noise."""
    end = known_before(d, 300.0).voltage_v.size
    if how == "cut":
        keep = slice(0, end + 1)
        return replace(d, time_s=d.time_s[keep], voltage_v=d.voltage_v[keep], current_a=d.current_a[keep],
                       temperature_c=d.temperature_c[keep])
    if how == "extend":
        extra = d.time_s[-1] + 10.0 * np.arange(1, 201)
        return replace(d, time_s=np.r_[d.time_s, extra], voltage_v=np.r_[d.voltage_v, np.full(200, 2.5)],
                       current_a=np.r_[d.current_a, np.full(200, 3.0)],
                       temperature_c=np.r_[d.temperature_c, np.full(200, d.temperature_c[-1])])
    n = d.time_s.size - end
    return replace(d, voltage_v=np.r_[d.voltage_v[:end], rng.uniform(0.0, 4.2, n)],
                   current_a=np.r_[d.current_a[:end], rng.uniform(0.0, 5.0, n)])


@pytest.mark.parametrize("how", ["cut", "extend", "noise"])
def test_a_prediction_never_reads_the_record_after_the_context(lives, how):
    """Cut, extend or replace discharge k's record (voltage and current) after its context: its own
    prediction must not change in any field (the next ones may: once finished, the discharge is read
    whole). The record's end, which on these lives is where the rig stopped the load, is not known when
    the prediction is made."""
    model = fit_nasa_model(lives[1:], 300.0, 3.0)
    cell = lives[0]
    before = {r.discharge: r for r in score_cell(cell, model, progpy=False)}
    rng = np.random.default_rng(3)
    for k in (0, 1, 5, 20):
        changed = replace(cell, discharges=cell.discharges[:k] + (_after_context(cell.discharges[k], how, rng),)
                          + cell.discharges[k + 1:])
        belief = CellBelief(model)
        for _ in belief.walk(changed.discharges[:k]):  # the earlier discharges, predicted and taken in
            pass
        pred = belief.predict(known_before(changed.discharges[k], 300.0))
        row = before[k]
        assert (pred.median_s, pred.low_s, pred.high_s, pred.bound95_s, pred.bound99_s, pred.method) == \
            (row.median_s, row.low_s, row.high_s, row.bound95_s, row.bound99_s, row.method)


def test_the_bounds_miss_at_their_risk_on_held_out_synthetic_lives(lives, tmp_path):
    """Fit on 8 lives, score 8 others never read: the 95% bound misses at most a binomial margin over 5%,
    the 90% interval covers 80-99%, and the median is near the truth."""
    model = fit_nasa_model(lives, 300.0, 3.0)
    held = [synthetic_cell(tmp_path, seed) for seed in range(100, 108)]
    rows = [r for c in held for r in score_cell(c, model, progpy=False)]
    st = summarise(rows)["all"]
    assert st["n"] == 8 * 40
    assert st["miss95"] <= 0.05 + 2.5 * np.sqrt(0.05 * 0.95 / st["n"]), st
    assert st["miss99"] <= 0.01 + 2.5 * np.sqrt(0.01 * 0.99 / st["n"]), st
    assert 0.80 <= st["coverage90"] <= 0.99, st
    assert st["median_pct"] < 2.0, st


def test_a_cells_first_history_predictions_take_the_early_quantiles(lives):
    """Until a cell has EARLY_ERRORS errors of its own, its interval reads the training cells' 'early'
    studentized quantiles (their first predictions' tails), then its ambient band's; without an 'early'
    table (too few training errors: 8 synthetic lives) the band's throughout."""
    model = fit_nasa_model(lives[1:], 300.0, 3.0)
    assert "early" not in model.z
    table = model.z.get("room", model.z["all"])
    wide = replace(model, z={**model.z, "early": tuple(3.0 * v for v in table)})
    plain, early = (score_cell(lives[0], m, progpy=False) for m in (model, wide))
    history = [k for k, r in enumerate(plain) if r.method == "history"]
    for k in history[:EARLY_ERRORS]:
        assert early[k].high_s - early[k].low_s > 2.0 * (plain[k].high_s - plain[k].low_s)
    for k in history[EARLY_ERRORS + 1:]:  # later predictions: the band's table (the levels move alike)
        assert early[k].median_s == pytest.approx(plain[k].median_s)


def test_a_first_discharge_is_a_prior_prediction_with_a_wide_interval(lives):
    model = fit_nasa_model(lives[1:], 300.0, 3.0)
    belief = CellBelief(model)
    first, second = lives[0].discharges[:2]
    pred = belief.predict(known_before(first, 300.0))
    assert pred.method == "prior"
    assert pred.bound99_s <= pred.bound95_s <= pred.median_s <= pred.high_s
    assert pred.low_s <= first.time_to_cutoff_s() <= pred.high_s
    belief.observe(first, pred, known_before(first, 300.0))
    then = belief.predict(known_before(second, 300.0))
    assert then.method == "history" and then.high_s - then.low_s < 0.5 * (pred.high_s - pred.low_s)


def test_a_condition_no_training_cell_ran_is_flagged_and_widened(lives, tmp_path):
    model = fit_nasa_model(lives, 300.0, 3.0)
    odd = synthetic_cell(tmp_path, 50, n=1, load_a=1.0, ambient_c=24.0)
    pred = CellBelief(model).predict(known_before(odd.discharges[0], 300.0))
    assert pred.flag is not None and "no training discharge near 1.0 A" in pred.flag
    cold = synthetic_cell(tmp_path, 51, n=2, ambient_c=4.0)
    belief = CellBelief(model)
    belief.observe(cold.discharges[0])
    assert belief.predict(known_before(cold.discharges[1], 300.0)).flag.startswith("cold (4 C")


def test_a_cell_of_the_bundled_training_set_is_scored_leave_one_cell_out(lives):
    model = replace(fit_nasa_model(lives, 300.0, 3.0), trained_on=tuple(c.name for c in lives))
    rows = evaluate_nasa(lives[:2], model, training=lives, progpy=False, every=10)
    assert {r.fit for r in rows} == {"loco"} and {r.discharge for r in rows} == {0, 10, 20, 30}
    assert {r.fit for r in evaluate_nasa(lives[:1], model, training=lives[:1], progpy=False)} == {"in-sample"}


def test_the_bundled_models_cover_their_settings():
    assert {(m.context_s, m.cutoff_v) for m in BUNDLED} == {(300.0, 3.0), (60.0, 3.0), (300.0, 3.2), (60.0, 3.2)}
    assert len(BUNDLED[0].trained_on) == 26
    m = bundled_model(120.0, 3.1)
    assert (m.context_s, m.cutoff_v) == (120.0, 3.1)


def test_the_cli_scores_a_folder_of_cells_it_never_saw_as_json(tmp_path, capsys):
    for seed in (200, 201):
        write_cell(tmp_path / f"B{seed:04d}.csv.gz", synthetic_rows(seed, n=6))
    assert main(["evaluate", "nasa", "--data", str(tmp_path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["context_s"] == 300.0 and out["cutoff_v"] == 3.0 and len(out["discharges"]) == 12
    row = out["discharges"][0]
    for key in ("cell", "discharge", "ambient_c", "context_s", "true_s", "median_s", "low_s", "high_s",
                "bound95_s", "bound99_s", "persistence_s", "flag"):
        assert key in row
    assert row["persistence_s"] is None and out["discharges"][1]["persistence_s"] is not None
    assert {r["fit"] for r in out["discharges"]} == {"bundled"}
    assert main(["evaluate", "nasa", "--data", str(tmp_path), "--cell", "B0200", "--every", "2"]) == 0
    text = capsys.readouterr().out
    assert "B0200 (bundled)" in text and "B0201" not in text


@pytest.mark.parametrize("case", ["missing", "truncated", "nan", "time", "empty"])
def test_the_cli_refuses_bad_data_in_one_line_with_exit_code_2(tmp_path, capsys, case):
    path = tmp_path / "B0300.csv.gz"
    rows = synthetic_rows(300, n=2)
    if case == "truncated":
        write_cell(path, rows)
        path.write_bytes(path.read_bytes()[:-60])
    elif case == "nan":
        rows[7][4] = float("nan")
        write_cell(path, rows)
    elif case == "time":
        rows[8][3] = rows[7][3]
        write_cell(path, rows)
    elif case == "empty":
        write_cell(path, [])
    folder = tmp_path / "nowhere" if case == "missing" else tmp_path
    assert main(["evaluate", "nasa", "--data", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    expected = {"missing": "nowhere: data: no such folder", "truncated": "B0300.csv.gz: file:",
                "nan": "B0300.csv.gz: voltage_V:", "time": "B0300.csv.gz: time_s:", "empty": "B0300.csv.gz: discharge:"}
    assert expected[case] in err, err


def test_a_folder_with_nothing_to_score_says_why_in_one_line(tmp_path, capsys):
    """Every run reaches the cut-off within a 3600 s context (longer than every synthetic discharge): no
    empty table, but one line that says why, and exit 2."""
    write_cell(tmp_path / "B0301.csv.gz", synthetic_rows(301, n=3))
    assert main(["evaluate", "nasa", "--data", str(tmp_path), "--context-s", "3600"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no discharge to score" in err and "3 reach the cut-off within the 3600 s" in err, err


def test_the_rest_before_each_run_is_read_from_the_folders_start_times(tmp_path):
    """discharges.csv beside the cell gives each run's start (MATLAB date vector): the rest is the time from
    the previous run's last sample to this start; without the table it is unknown (NaN)."""
    from uam_studio.battery.real.nasa_data import load_nasa_cell

    path = write_cell(tmp_path / "B0302.csv.gz", synthetic_rows(302, n=3))
    assert all(np.isnan(d.rest_s) for d in load_nasa_cell(path).discharges)
    starts = ["[2008. 4. 2. 15. 25. 41.5]", "[2008. 4. 2. 19. 43. 48.4]", "[2008. 4. 5. 1. 0. 0.]"]
    (tmp_path / "discharges.csv").write_text("battery_id,discharge,uid,start_time\n" + "".join(
        f"B0302,{k},{k},{t}\n" for k, t in enumerate(starts)))
    cell = load_nasa_cell(path)
    d0, d1, d2 = cell.discharges
    assert np.isnan(d0.rest_s)
    assert d1.rest_s == pytest.approx((4 * 3600 + 18 * 60 + 6.9) - d0.time_s[-1], abs=1e-6)
    assert d2.rest_s == pytest.approx((2 * 86400 + 5 * 3600 + 16 * 60 + 11.6) - d1.time_s[-1], abs=1e-6)
    assert known_before(d2, 300.0).rest_s == d2.rest_s


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_on_real_2a_lives_left_out_it_beats_persistence_and_its_bounds_hold():
    from uam_studio.battery.real.nasa_data import load_nasa_folder

    cells = load_nasa_folder(DATA, ["B0005", "B0007", "B0018", "B0036", "B0029", "B0030"])
    rows = score_cell(cells[0], fit_nasa_model(cells[1:]), "loco", progpy=False)  # B0005 never read by the fit
    st = summarise(rows)["all"]
    assert st["median_pct"] <= 1.0 and st["p95_pct"] <= 3.0, st
    assert st["median_pct"] < st["persistence_median_pct"], st
    assert st["miss95"] <= 0.08 and 0.82 <= st["coverage90"] <= 0.98, st
    assert all(np.isfinite(r.high_s) and r.low_s < r.high_s <= 3 * r.median_s for r in rows)


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_the_bundled_default_model_is_what_identify_nasa_prints():
    from uam_studio.battery.real.nasa_data import load_nasa_folder
    from uam_studio.battery.real.nasa_eval import models_literal

    refit = fit_nasa_model(load_nasa_folder(DATA), 300.0, 3.0)
    assert models_literal([refit]) == models_literal([BUNDLED[0]])


_ANY = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e40, 1e40))


@settings(max_examples=300, deadline=None)
@given(q=st.lists(_ANY, min_size=4, max_size=4), k=st.integers(0, 39), context=st.sampled_from([60.0, 300.0]))
def test_every_interval_is_finite_wide_and_capped(lives, q, k, context):
    """Whatever quantiles a method produces (NaN, infinite, negative, 1e40, all equal), the prediction is an
    interval: finite, low < high, none before the context's end, high at most the stated cap, bounds at
    or below the low end and the median inside."""
    known = known_before(lives[0].discharges[k], context)
    p = as_prediction(known, np.array(q), "history", None)
    vals = (p.bound99_s, p.bound95_s, p.low_s, p.median_s, p.high_s)
    assert all(np.isfinite(vals))
    assert seen_s(known) <= p.bound99_s <= p.bound95_s <= p.low_s <= p.median_s <= p.high_s
    assert p.high_s - p.low_s >= min_width_s(known) - 1e-9 > 0
    assert p.high_s <= high_cap_s(known, p.median_s) + 1e-9
    assert high_cap_s(known, p.median_s) <= HORIZON_S + seen_s(known) + min_width_s(known)

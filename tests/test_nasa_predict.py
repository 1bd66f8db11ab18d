"""The NASA end-of-discharge predictor: the online protocol never reads a discharge's voltage after its
context, its bounds miss at their declared risk on synthetic lives with a known truth (held out of the
fit), and on the real lives it beats persistence where the data sit beside the checkout."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from nasa_synthetic import synthetic_cell, synthetic_rows, write_cell

from uam_studio.battery.real.nasa_data import NasaCell
from uam_studio.battery.real.nasa_eval import evaluate_nasa, fit_nasa_model, score_cell, summarise
from uam_studio.battery.real.nasa_model import BUNDLED, bundled_model
from uam_studio.battery.real.nasa_predict import EARLY_ERRORS, CellBelief, known_before
from uam_studio.cli import main

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nasa_pcoe"


@pytest.fixture(scope="module")
def lives(tmp_path_factory) -> list[NasaCell]:
    tmp = tmp_path_factory.mktemp("lives")
    return [synthetic_cell(tmp, seed) for seed in range(8)]



def test_known_before_cuts_the_voltage_at_the_context(lives):
    d = lives[0].discharges[3]
    known = known_before(d, 300.0)
    assert known.voltage_v.size < d.voltage_v.size
    assert known.time_s[known.voltage_v.size - 1] <= d.load_time_s + 300.0 < known.time_s[known.voltage_v.size]
    assert np.array_equal(known.current_a, d.current_a)


def test_a_prediction_never_reads_the_voltage_after_the_context(lives):
    """Poison discharge k's voltage after its context: its own prediction must not change (the next ones
    may: once finished, the discharge is read whole)."""
    model = fit_nasa_model(lives[1:], 300.0, 3.0)
    cell = lives[0]
    before = score_cell(cell, model, progpy=False)
    for k in (0, 5, 20):
        d = cell.discharges[k]
        end = known_before(d, 300.0).voltage_v.size
        poisoned = d.voltage_v.copy()
        poisoned[end:] = np.linspace(4.2, 0.0, poisoned.size - end)  # a cheat would read a different end
        cheat = replace(cell, discharges=cell.discharges[:k] + (replace(d, voltage_v=poisoned),)
                        + cell.discharges[k + 1:])
        after = score_cell(cheat, model, progpy=False)
        row_before = next(r for r in before if r.discharge == k)
        row_after = next(r for r in after if r.discharge == k)
        assert (row_after.median_s, row_after.low_s, row_after.bound99_s) == \
            (row_before.median_s, row_before.low_s, row_before.bound99_s)


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


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_on_real_2a_lives_left_out_it_beats_persistence_and_its_bounds_hold():
    from uam_studio.battery.real.nasa_data import load_nasa_folder

    cells = load_nasa_folder(DATA, ["B0005", "B0007", "B0018", "B0036", "B0029", "B0030"])
    rows = score_cell(cells[0], fit_nasa_model(cells[1:]), "loco", progpy=False)  # B0005 never read by the fit
    st = summarise(rows)["all"]
    assert st["median_pct"] <= 1.0 and st["p95_pct"] <= 3.0, st
    assert st["median_pct"] < st["persistence_median_pct"], st
    assert st["miss95"] <= 0.08 and 0.82 <= st["coverage90"] <= 0.98, st


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_the_bundled_default_model_is_what_identify_nasa_prints():
    from uam_studio.battery.real.nasa_data import load_nasa_folder
    from uam_studio.battery.real.nasa_eval import models_literal

    refit = fit_nasa_model(load_nasa_folder(DATA), 300.0, 3.0)
    assert models_literal([refit]) == models_literal([BUNDLED[0]])

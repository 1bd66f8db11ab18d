"""The bundled Dynaformer on real NASA PCoE discharges (uam_studio.dynaformer.nasa_discharges): finite, positive
predictions, and predictions that never read the voltage after the context. Skipped where the data
(``../shared/data/nasa_pcoe`` or ``$UAM_STUDIO_NASA_DATA``) is not present."""

from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from uam_studio.battery.real.nasa_data import load_nasa_folder
from uam_studio.battery.real.nasa_predict import known_before
from uam_studio.dynaformer.nasa_discharges import (
    MIN_OWN_ERRORS,
    NASA_DATA_CELL,
    dynaformer_eod_s,
    finetune_dynaformer,
    finished_health,
    history_examples,
    score_dynaformer,
    summarise_dynaformer,
    training_example,
)
from uam_studio.dynaformer.predictor import load_pretrained


def _data() -> Path | None:
    for p in (os.environ.get("UAM_STUDIO_NASA_DATA"),
              Path(__file__).resolve().parents[2] / "shared" / "data" / "nasa_pcoe"):
        if p and Path(p, "B0005.csv.gz").is_file():
            return Path(p)
    return None


DATA = _data()
needs_data = pytest.mark.skipif(DATA is None, reason="no NASA PCoE data (../shared/data/nasa_pcoe or "
                                                     "$UAM_STUDIO_NASA_DATA)")


@pytest.fixture(scope="module")
def b0005():
    return load_nasa_folder(DATA, ["B0005"])[0]


@needs_data
def test_three_b0005_discharges_score_finite_and_positive(b0005):
    cell = replace(b0005, discharges=b0005.discharges[:3])
    rows = score_dynaformer([cell], context_s=300.0, cutoff_v=3.0)
    assert [r["discharge"] for r in rows] == [0, 1, 2]
    for r in rows:
        low, med, high = r["low_s"], r["median_s"], r["high_s"]
        assert all(x is not None and math.isfinite(x) and x > 0 for x in (low, med, high, r["true_s"]))
        assert low <= med <= high
        assert med > 300.0 - 20.0  # the cut-off is not seen within the context
    s = summarise_dynaformer(rows)
    assert s["n"] == 3 and s["none"] == 0 and math.isfinite(s["median_pct"])


@needs_data
@pytest.mark.parametrize("k", [0, 100])
def test_prediction_never_reads_the_voltage_after_the_context(b0005, k):
    d = b0005.discharges[k]
    end = known_before(d, 300.0).voltage_v.size
    hidden = replace(d, voltage_v=np.r_[d.voltage_v[:end], np.full(d.voltage_v.size - end, np.nan)])
    predictor = load_pretrained(NASA_DATA_CELL)
    for rest in (True, False):
        a = dynaformer_eod_s(predictor, known_before(d, 300.0), 3.0, start_at_rest=rest)
        b = dynaformer_eod_s(predictor, known_before(hidden, 300.0), 3.0, start_at_rest=rest)
        assert a is not None and a == b


@needs_data
@pytest.mark.parametrize("history", ["bias", "health"])
def test_the_cells_history_corrects_later_predictions_never_the_one_it_came_from(b0005, history):
    """Discharge 1 ends earlier after its context: its own row is unchanged, and the next (same load and
    ambient; its correction the mean of discharges 0 and 1's errors, too few for the previous discharge's
    health to be chosen) is earlier by what discharge 1's error became; with history off, every median is
    the Dynaformer's own."""
    cell = replace(b0005, discharges=b0005.discharges[:3])
    d = cell.discharges[1]
    end = known_before(d, 300.0).voltage_v.size
    shorter = replace(d, voltage_v=np.r_[d.voltage_v[:end], d.voltage_v[end:] - 0.08])
    moved = replace(cell, discharges=(cell.discharges[0], shorter, cell.discharges[2]))
    predictor = load_pretrained(NASA_DATA_CELL)
    a, b = (score_dynaformer([c], predictor=predictor, history=history) for c in (cell, moved))
    assert b[1]["true_s"] < a[1]["true_s"]
    assert b[1]["median_s"] == a[1]["median_s"] and b[1]["raw_median_s"] == a[1]["raw_median_s"]
    assert b[2]["raw_median_s"] == a[2]["raw_median_s"] and b[2]["median_s"] < a[2]["median_s"]
    assert {r["health_from"] for r in a + b} == {"context"}
    errors = [r["raw_median_s"] / r["true_s"] - 1.0 for r in b[:2]]
    assert b[2]["median_s"] == pytest.approx(b[2]["raw_median_s"] / (1.0 + np.mean(errors)))
    assert a[0]["median_s"] == a[0]["raw_median_s"]  # a first discharge: no history to correct by
    plain = score_dynaformer([moved], predictor=predictor, history="off")
    assert [r["median_s"] for r in plain] == [r["raw_median_s"] for r in b]


@needs_data
def test_the_previous_discharges_health_is_chosen_where_it_has_done_better_and_never_reads_ahead(b0005):
    """On B0005 (one load and ambient) the whole-record health of the previous discharge predicts better
    than a 300 s context: once it has MIN_OWN_ERRORS errors of its own it is chosen, and its rows are
    within 1% of the truth. Poisoning a discharge after its context changes no row up to its own."""
    cell = replace(b0005, discharges=b0005.discharges[:MIN_OWN_ERRORS + 5])
    predictor = load_pretrained(NASA_DATA_CELL)
    rows = score_dynaformer([cell], predictor=predictor)
    chosen = [r for r in rows if r["health_from"] == "previous discharge"]
    assert [r["discharge"] for r in rows[:MIN_OWN_ERRORS + 2]] == list(range(MIN_OWN_ERRORS + 2))
    assert all(r["health_from"] == "context" for r in rows[:MIN_OWN_ERRORS + 1])  # d0: no history; then too few
    assert len(chosen) >= 3
    assert all(abs(r["median_s"] / r["true_s"] - 1.0) < 0.01 for r in chosen)
    assert all(r["low_s"] <= r["median_s"] <= r["high_s"] for r in rows)
    k = MIN_OWN_ERRORS + 2
    d = cell.discharges[k]
    end = known_before(d, 300.0).voltage_v.size
    poisoned = replace(d, voltage_v=np.r_[d.voltage_v[:end], np.linspace(4.2, 2.0, d.voltage_v.size - end)])
    cheat = replace(cell, discharges=cell.discharges[:k] + (poisoned,) + cell.discharges[k + 1:])
    again = score_dynaformer([cheat], predictor=predictor)
    keys = ("median_s", "low_s", "high_s", "raw_median_s", "health_from")
    assert again[k]["true_s"] != rows[k]["true_s"]
    assert [[r[c] for c in keys] for r in again[:k + 1]] == [[r[c] for c in keys] for r in rows[:k + 1]]


@needs_data
def test_the_finished_health_reaches_the_cut_off_when_its_discharge_did(b0005, monkeypatch):
    """``finished_health`` moves the whole-record fit's q_max until the Dynaformer ends the discharge when it
    ended; with no steps allowed the fit is returned as it is."""
    import uam_studio.dynaformer.nasa_discharges as nd

    base = load_pretrained(NASA_DATA_CELL)
    for d in b0005.discharges[3:6]:
        true_s = d.time_to_cutoff_s(3.0)
        moved = finished_health(base, d)
        monkeypatch.setattr(nd, "MATCH_STEPS", 0)
        fit = finished_health(base, d)
        monkeypatch.undo()
        assert moved.r0 == fit.r0
        err = [abs(dynaformer_eod_s(base, known_before(d, 300.0), estimate=e)[1] - true_s) for e in (moved, fit)]
        assert err[0] <= err[1] and err[0] <= 0.01 * true_s


@needs_data
@pytest.mark.parametrize("k", [0, 14])
def test_a_4a_discharge_at_43c_is_matched_to_its_end_by_the_default_weights(k):
    """B0029 (4 A, 43 C): the default weights (trained up to 4.5 A) end the discharge within 1% at its
    matched health; the aircraft's weights (trained up to 3 A) cannot, even at twice the fitted q_max."""
    d = load_nasa_folder(DATA, ["B0029"])[0].discharges[k]
    true_s = d.time_to_cutoff_s(3.0)
    miss = {}
    for key in (NASA_DATA_CELL, "nasa18650"):
        pred = load_pretrained(key)
        est = finished_health(pred, d)
        miss[key] = abs(dynaformer_eod_s(pred, known_before(d, 300.0), estimate=est)[1] - true_s) / true_s
    assert miss[NASA_DATA_CELL] <= 0.01 and miss["nasa18650"] >= 0.10, miss


@needs_data
def test_history_examples_decode_at_the_previous_discharges_whole_record_health(b0005):
    base = load_pretrained(NASA_DATA_CELL)
    cell = replace(b0005, discharges=b0005.discharges[:3])
    examples = history_examples(base, cell)
    assert len(examples) == 2  # the first discharge has no earlier one
    for k, e in zip((1, 2), examples):
        want = training_example(base, cell.discharges[k], estimate=finished_health(base, cell.discharges[k - 1]))
        assert want is not None and np.allclose(e[1], want[1]) and np.array_equal(e[3], want[3])
        own = training_example(base, cell.discharges[k])
        assert own is not None and not np.allclose(e[1], own[1])  # not the context's health


@needs_data
def test_a_short_fine_tune_runs_and_leaves_the_bundled_weights_alone(b0005):
    base = load_pretrained(NASA_DATA_CELL)
    before = {k: v.clone() for k, v in base.model.state_dict().items()}
    examples = [training_example(base, d) for d in b0005.discharges[:2]]
    name, latent, cur, volt, weight = examples[0]
    assert name == "B0005" and latent.shape == (2,) and cur.shape == volt.shape == weight.shape
    assert np.all(np.isfinite(volt)) and weight.min() > 0
    tuned = finetune_dynaformer(examples, base, steps=2, batch=2)
    assert tuned.meta["finetuned_on"] == ["B0005"]
    assert all((base.model.state_dict()[k] == v).all() for k, v in before.items())
    pred = dynaformer_eod_s(tuned, known_before(b0005.discharges[2], 300.0))
    assert pred is not None and all(math.isfinite(x) and x > 0 for x in pred)

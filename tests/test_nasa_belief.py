"""The one health belief on NASA-format lives (``evaluate nasa --method belief``): synthetic lives with a known truth
(the physics cell itself, fading with noise), the online protocol (nothing after the context is read), the
leave-one-cell-out rows and the CLI."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.nasa_synthetic import synthetic_cell
from uam_studio.battery.parameters import NASA_18650
from uam_studio.battery.real.nasa_belief import belief_life, evaluate_belief
from uam_studio.cli import main


@pytest.fixture(scope="module")
def cells(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("nasa")
    return [synthetic_cell(tmp, seed, n=10) for seed in (11, 12, 13)]


def test_the_belief_predicts_a_synthetic_life_within_a_percent_and_follows_its_fade(cells):
    preds = belief_life(cells[0], NASA_18650)
    assert len(preds) == 10 and preds[0].early and not preds[-1].early
    errs = [abs(p.median_s - p.true_s) / p.true_s for p in preds[1:]]
    assert np.all(np.isfinite(errs)) and np.median(errs) < 0.01
    # the belief sharpens as the logbook grows, and its q_max follows the life's discharges
    assert preds[-1].q_max_sd < 0.5 * preds[0].q_max_sd
    assert np.corrcoef([p.q_max for p in preds[2:]], [p.true_s for p in preds[1:-1]])[0, 1] > 0.5


def test_a_prediction_never_reads_its_discharges_voltage_after_the_context(cells):
    cell = cells[1]
    last = cell.discharges[-1]
    after = last.time_s - last.load_time_s > 300.0
    changed = replace(last, voltage_v=np.where(after, last.voltage_v - 0.3, last.voltage_v))
    other = replace(cell, discharges=(*cell.discharges[:-1], changed))
    assert belief_life(other, NASA_18650)[-1].median_s == belief_life(cell, NASA_18650)[-1].median_s


def test_rows_are_the_history_methods_and_scored_leave_one_cell_out(cells):
    rows = evaluate_belief(cells, progpy=False)
    assert {r.fit for r in rows} == {"loco"} and {r.method for r in rows} == {"belief"}
    for r in rows:
        assert r.bound99_s <= r.bound95_s <= r.median_s <= r.high_s and r.low_s <= r.median_s
        assert all(np.isfinite([r.median_s, r.low_s, r.high_s, r.bound95_s, r.bound99_s]))
    json.dumps([r.as_dict() for r in rows], allow_nan=False)


def test_cli_evaluate_nasa_method_belief(cells, capsys):
    folder = Path(cells[0].path).parent
    assert main(["evaluate", "nasa", "--data", str(folder), "--method", "belief", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {d["method"] for d in out["discharges"]} == {"belief"} and len(out["discharges"]) >= 20
    assert main(["evaluate", "lives", "--method", "belief"]) == 2
    assert "--method" in capsys.readouterr().err

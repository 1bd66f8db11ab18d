"""The one health belief on NASA-format lives (``evaluate nasa --method belief``): synthetic lives with a known truth
(the physics cell itself, fading with noise), the online protocol (nothing after the context is read), the
leave-one-cell-out rows and the CLI."""

from __future__ import annotations

import json
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
    """The life is the physics cell itself (at 19 C; the belief runs it at the logged 24 C), so the model's time at
    the belief's health along the planned load is near the truth before any correction for the cell's past
    errors: within 3% once the logbook holds a discharge (a plan as long as the context, whose time to the
    cut-off is its own length, is 50% short), and the corrected median within 1%."""
    preds = belief_life(cells[0], NASA_18650)
    assert len(preds) == 10 and preds[0].early and not preds[-1].early
    raw = [abs(p.raw_s - p.true_s) / p.true_s for p in preds[1:]]
    assert np.all(np.isfinite(raw)) and max(raw) < 0.03
    errs = [abs(p.median_s - p.true_s) / p.true_s for p in preds[1:]]
    assert np.all(np.isfinite(errs)) and np.median(errs) < 0.01
    # the belief sharpens as the logbook grows, and its q_max follows the life's discharges
    assert preds[-1].q_max_sd < 0.5 * preds[0].q_max_sd
    assert np.corrcoef([p.q_max for p in preds[2:]], [p.true_s for p in preds[1:-1]])[0, 1] > 0.5


def test_rows_are_the_history_methods_and_scored_leave_one_cell_out(cells):
    rows = evaluate_belief(cells, progpy=False)
    assert {r.fit for r in rows} == {"loco"} and {r.method for r in rows} == {"belief"}
    for r in rows:
        assert r.bound99_s <= r.bound95_s <= r.median_s <= r.high_s and r.low_s <= r.median_s
        assert all(np.isfinite([r.median_s, r.low_s, r.high_s, r.bound95_s, r.bound99_s]))
    json.dumps([r.as_dict() for r in rows], allow_nan=False)


def test_no_high_end_passes_the_history_methods_cap(cells, monkeypatch):
    """A group whose training errors run wild (a crashed run among them) still gives an interval as the history
    method's: ordered, of some width, none of it past ``high_cap_s``. Its quantiles are made wild here."""
    import uam_studio.battery.real.nasa_belief as nb
    from uam_studio.battery.real.nasa_predict import high_cap_s, known_before

    monkeypatch.setattr(nb, "_quantiles", lambda errors: (-1.0, -0.5, 0.0, 3.0))
    rows = nb.evaluate_belief(cells, progpy=False)
    by_index = {(c.name, d.index): d for c in cells for d in c.discharges}
    for r in rows:
        cap = high_cap_s(known_before(by_index[r.cell, r.discharge], r.context_s), r.median_s)
        assert r.bound99_s <= r.bound95_s <= r.low_s <= r.median_s <= r.high_s <= cap + 1e-9 and r.low_s < r.high_s


def test_cli_evaluate_nasa_method_belief(cells, capsys):
    folder = Path(cells[0].path).parent
    assert main(["evaluate", "nasa", "--data", str(folder), "--method", "belief", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {d["method"] for d in out["discharges"]} == {"belief"} and len(out["discharges"]) >= 20
    assert main(["evaluate", "lives", "--method", "belief"]) == 2
    assert "--method" in capsys.readouterr().err

"""The NASA 18650 identified as a cell type of its own, and the physics method that predicts a life online
(``uam_studio.battery.real.nasa_physics``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.nasa_synthetic import synthetic_cell
from uam_studio.battery.parameters import NASA_18650, NASA_IDENTIFIED
from uam_studio.battery.real import nasa_physics
from uam_studio.battery.real.nasa_data import NasaDischarge, load_nasa_cell, nasa_folder
from uam_studio.battery.real.nasa_physics import discharge_health, predict_life
from uam_studio.battery.simulate import simulate


def _have_data() -> bool:
    try:
        return all((nasa_folder() / f"{c}.csv.gz").is_file() for c in ("B0005", "B0007"))  # not the sample alone
    except Exception:
        return False


needs_data = pytest.mark.skipif(not _have_data(), reason="the NASA PCoE cells B0005 and B0007 are not found "
                                "($UAM_STUDIO_NASA_DATA, or beside the checkout; the bundled sample has B0005 only)")


def _discharge(q_max: float, r0: float, load_a: float, params) -> NasaDischarge:
    """A discharge of ``params`` at (q_max C, R0 ohm) under ``load_a`` (A), sampled every 10 s to 2.7 V."""
    res = simulate(np.full(12000, load_a), 1.0, q_max, r0, 2.7, cell=replace(params, t_ambient_k=297.15))
    v = res.voltage_v[res.valid][9::10]
    t = np.r_[0.0, 10.0 * np.arange(1, v.size + 1)]
    return NasaDischarge("B9999", 0, 0, 24.0, t, np.r_[4.19, v], np.r_[0.0, np.full(v.size, load_a)],
                         np.full(t.size, 24.0), 1)


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(q=st.floats(4000.0, 7600.0), r0=st.floats(0.005, 0.05), load=st.sampled_from([1.0, 2.0, 4.0]))
def test_a_finished_discharges_health_reaches_the_cutoff_when_the_cell_did(q, r0, load):
    d = _discharge(q, r0, load, NASA_IDENTIFIED.params)
    q_fit, r0_fit = discharge_health(d, NASA_IDENTIFIED.params, (NASA_IDENTIFIED.q_max, NASA_IDENTIFIED.r0))
    # the samples are 10 s apart: the cell's cut-off time, and so its charge, is known to one sample
    t_true = d.time_to_cutoff_s(3.0)
    assert t_true is not None
    assert q_fit == pytest.approx(q, rel=0.005 + 10.0 / t_true)
    assert np.isfinite(r0_fit) and r0_fit > 0


def test_the_physics_method_predicts_a_synthetic_life_within_a_percent(tmp_path):
    cell = synthetic_cell(tmp_path, 3, n=12)
    preds = predict_life(cell, NASA_18650)
    assert preds[0].median_s is None  # no history: the first discharge is not predicted
    errs = [abs(p.median_s - p.true_s) / p.true_s for p in preds[1:]]
    assert len(errs) == 11 and np.all(np.isfinite(errs))
    assert np.median(errs) < 0.01
    # the health it carries is the last finished discharge's: its q_max follows that discharge's length
    q = [p.q_max for p in preds[1:]]
    t = [p.true_s for p in preds[:-1]]
    assert np.corrcoef(q, t)[0, 1] > 0.9


@needs_data
def test_the_identification_reads_only_its_cell_and_prints_the_bundled_set(monkeypatch, capsys):
    """``uam-studio identify nasa-cell``: the printed source, run, gives the bundled set; only B0005 is read."""
    from uam_studio.battery import parameters
    from uam_studio.cli import main

    read = []

    def recording(path, *a, **k):
        read.append(path.name)
        return load_nasa_cell(path, *a, **k)

    monkeypatch.setattr(nasa_physics, "load_nasa_cell", recording)
    assert main(["identify", "nasa-cell", "--data", str(nasa_folder())]) == 0
    assert read == ["B0005.csv.gz"]
    scope = {"replace": replace, "DEFAULT_CELL": parameters.DEFAULT_CELL, "Cell": parameters.Cell,
             "NASA_ID_FLEET_Q_RANGE": parameters.NASA_ID_FLEET_Q_RANGE,
             "NASA_ID_FLEET_R0_RANGE": parameters.NASA_ID_FLEET_R0_RANGE}
    exec(capsys.readouterr().out, scope)
    cell = scope["NASA_IDENTIFIED"]
    assert cell.q_max == pytest.approx(NASA_IDENTIFIED.q_max, rel=0.01)
    assert cell.params.u0p == pytest.approx(NASA_IDENTIFIED.params.u0p, abs=0.01)
    assert cell.params.fleet_q_range == NASA_IDENTIFIED.params.fleet_q_range


def test_identifying_from_a_folder_without_the_cell_is_one_line_naming_the_folder(tmp_path, capsys):
    from uam_studio.cli import main

    assert main(["identify", "nasa-cell", "--data", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "data" in err and str(tmp_path) in err and "B0005" in err, err


@needs_data
def test_on_a_held_out_life_the_identified_cell_beats_progpys_set():
    d = load_nasa_cell(nasa_folder() / "B0007.csv.gz").discharges[0]
    seg = nasa_physics.fit_segment(d)
    rms = {}
    for cell in (NASA_IDENTIFIED, NASA_18650):
        q, r0 = discharge_health(d, cell.params, (cell.q_max, cell.r0))
        v = simulate(seg.current_a, 1.0, q, r0, 2.5, cell=replace(cell.params, t_ambient_k=seg.t_ambient_k)).voltage_v
        keep = seg.observed < v.size
        rms[cell.name] = float(np.sqrt(np.mean((v[seg.observed[keep]] - seg.voltage_v[keep]) ** 2)))
    assert rms[NASA_IDENTIFIED.name] < 0.5 * rms[NASA_18650.name]


def test_the_battery_lab_flies_the_identified_cell_inside_its_health_box():
    from uam_studio.app.battery_lab.state import HEALTH_BOX, NASA_ID_NAME, BatteryLabState

    lab = BatteryLabState(cell=NASA_ID_NAME)
    lab.cell = NASA_ID_NAME
    (q_lo, q_hi), (r_lo, r_hi) = HEALTH_BOX[NASA_ID_NAME]
    assert (lab.q_max, lab.r0) == (NASA_IDENTIFIED.q_max, NASA_IDENTIFIED.r0)
    assert q_lo <= lab.q_max <= q_hi and r_lo <= lab.r0 <= r_hi
    for vary in ("q_max", "R0"):
        lab.vary = vary
        res = lab.result
        assert res["error"] == "" and len(res["family"]) == 4
        assert all(np.all(np.isfinite(m["voltage_v"])) for m in res["family"])
        assert all(m["eod_s"] is not None for m in res["family"])  # every member of the family ends its legs

"""The Battery lab's real NASA cell: its state replays a discharge (or says in one line where the data
go), and the replay's sentence says what happened; the browser test draws it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from nasa_synthetic import synthetic_rows, write_cell

from uam_studio.app.battery_lab.nasa import NasaLabState, NasaLabView, nasa_figure
from uam_studio.battery.real.nasa_data import load_nasa_cell
from uam_studio.battery.real.nasa_eval import fit_nasa_model
from uam_studio.battery.real.nasa_replay import replay_discharge
from uam_studio.errors import InputError


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("nasa")
    for seed in (301, 302, 303):
        write_cell(tmp / f"B{seed:04d}.csv.gz", synthetic_rows(seed, n=12))
    return tmp


def test_without_data_the_lab_says_where_to_put_it_in_one_line(tmp_path):
    state = NasaLabState(folder=str(tmp_path / "nowhere"))
    assert state.result is None and "\n" not in state.missing
    assert "No NASA PCoE data" in state.missing and "UAM_STUDIO_NASA_DATA" in state.missing
    view = NasaLabView(state)
    assert "No NASA PCoE data" in view.__panel__()[1].object


def test_the_lab_replays_a_cell_it_never_saw_and_clamps_the_discharge(folder):
    state = NasaLabState(folder=str(folder))
    assert state.cell == "B0301" and state.discharges == 12
    assert state.position == 11  # the first position asked for (mid-life of B0005) is past this short life
    r = state.result["replay"]
    assert r.fit == "bundled" and r.discharge == 11 and r.prediction.method == "history"
    assert r.sentence().startswith("predicted ") and f"real {r.true_s:,.0f} s" in r.sentence()
    state.position = 0
    assert state.result["replay"].prediction.method == "prior" and state.result["replay"].persistence_s is None
    view = NasaLabView(state)
    assert "B0301" in view.text.object and "nan" not in view.text.object
    assert len(nasa_figure(state.result["replay"])) >= 6


def test_the_figure_builds_whatever_backend_another_pane_left_current(folder, monkeypatch):
    import holoviews as hv

    state = NasaLabState(folder=str(folder))
    monkeypatch.setattr(hv.Store, "current_backend", "matplotlib")  # a fresh process's default, never loaded here
    overlay = nasa_figure(state.result["replay"])  # before hv.renderer, which makes its backend current
    fig = hv.renderer("bokeh").get_plot(overlay).state
    assert fig.title.text.startswith("B0301, discharge 11") and len(fig.renderers) >= 6


def test_a_replay_reads_no_voltage_after_the_context_and_refuses_a_bad_position(folder):
    cell = load_nasa_cell(folder / "B0302.csv.gz")
    model = fit_nasa_model([load_nasa_cell(folder / "B0301.csv.gz"), load_nasa_cell(folder / "B0303.csv.gz")])
    a = replay_discharge(cell, 5, model=model)
    assert a.fit == "given" and np.isfinite([a.prediction.median_s, a.prediction.bound95_s]).all()
    with pytest.raises(InputError, match="discharge: 12 is out of range; allowed \\[0, 11\\]"):
        replay_discharge(cell, 12, model=model)


def test_views_build_after_the_bokeh_backend_was_only_imported():
    """``import holoviews.plotting.bokeh`` (the classroom's plots do it) makes bokeh HoloViews' current backend
    without building ``hv.opts``' builders; a view built after that still gets them (a fresh interpreter:
    the state is global)."""
    import subprocess
    import sys

    code = ("import holoviews.plotting.bokeh, holoviews as hv\n"
            "from uam_studio.app.session import ensure_bokeh_backend\n"
            "ensure_bokeh_backend()\n"
            "print(type(hv.opts.Overlay(responsive=True)).__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "Options", out.stderr[-2000:]

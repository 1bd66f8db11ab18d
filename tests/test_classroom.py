"""Classroom helpers: the fast-mode switch, asset paths and the shared figures."""

from __future__ import annotations

import pytest

from uam_studio.classroom import FAST_ENV_VAR, asset_path, fast_mode, pick
from uam_studio.errors import InputError


@pytest.mark.parametrize("value,expected", [("1", True), ("true", True), (" YES ", True), ("on", True),
                                            ("", False), ("0", False), ("false", False), ("off", False)])
def test_fast_mode_values(monkeypatch, value, expected):
    monkeypatch.setenv(FAST_ENV_VAR, value)
    assert fast_mode() is expected
    assert pick(fast="f", full="F") == ("f" if expected else "F")


def test_fast_mode_unset_and_typo(monkeypatch):
    monkeypatch.delenv(FAST_ENV_VAR, raising=False)
    assert fast_mode() is False
    monkeypatch.setenv(FAST_ENV_VAR, "fats")
    with pytest.raises(InputError, match="UAM_FAST"):
        fast_mode()


def test_asset_path_points_at_the_bundled_missions():
    assert asset_path("example_mission.json").is_file()
    assert asset_path("classroom_single_charge.json").is_file()
    assert asset_path("classroom_multi_charge.json").is_file()


def test_mission_map_and_sorties():
    hv = pytest.importorskip("holoviews")
    from uam_studio.classroom.plots import curves, mission_map, sorties
    from uam_studio.planning import load_mission

    assert sorties(["A", "B", "vertiport", "C"]) == [["vertiport", "A", "B", "vertiport"], ["vertiport", "C"]]
    assert sorties([]) == []
    m = load_mission(asset_path("classroom_multi_charge.json"))
    fig = mission_map(m, ["D3", "D2", "vertiport", "D7", "vertiport"])
    assert isinstance(fig, hv.Overlay)
    assert sum(isinstance(el, hv.Curve) for el in fig) == 2  # one line per charging cycle
    ov = curves({"a": ([0, 1], [3.5, 3.2]), "b": ([0, 1], [3.6, 3.1])}, "t", "V", hline=3.0)
    assert len(ov) == 3


def test_notebook_figures_draw_on_canvas_by_default(monkeypatch):
    """Importing the classroom helpers makes HoloViews draw on the canvas: with its default (WebGL), a
    student's browser without a GPU draws no line."""
    import importlib

    hv = pytest.importorskip("holoviews")
    import uam_studio.classroom.plots as plots

    monkeypatch.setattr(type(hv.renderer("bokeh")), "webgl", True)  # HoloViews' own default
    webgl = hv.renderer("bokeh").get_plot(hv.Curve([(0, 1), (1, 2)])).state.output_backend
    plots = importlib.reload(plots)  # what a notebook's import does
    ov = plots.curves({"a": ([0, 1], [3.5, 3.2])}, "t", "V", hline=3.0)
    assert (webgl, hv.renderer("bokeh").get_plot(ov).state.output_backend) == ("webgl", "canvas")


def test_the_price_of_safety_figure_draws_each_levels_rate_interval_and_priority():
    import holoviews as hv

    from uam_studio.classroom.plots import price_of_safety_figure
    from uam_studio.planning.operations.safety_price import RiskFlight, risk_levels

    flights = [RiskFlight(r, "single_charge", 5, 4, 8, k < n, False) for r, n in ((0.01, 0), (0.2, 3))
               for k in range(10)]
    levels = risk_levels(flights)
    fig = price_of_safety_figure(levels)
    rates, served = fig
    bars = next(e for e in rates if isinstance(e, hv.ErrorBars))
    assert list(bars.dimension_values(0)) == [0.01, 0.2]
    assert list(bars.dimension_values(1)) == [1e-3, 0.3]  # a rate of 0 drawn at the floor of the log axis
    assert bars.dimension_values(3)[1] == pytest.approx(levels[1].rate_high - 0.3)
    operator = next(e for e in served if isinstance(e, hv.Curve) and e.label == "operator")
    assert list(operator.dimension_values(1)) == [0.625, 0.625]

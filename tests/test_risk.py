"""The declared risk: one number a flight's cautions follow from (uam_studio.risk), its bad values, its home."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.classroom import asset_path
from uam_studio.cli import main
from uam_studio.errors import InputError
from uam_studio.planning import load_mission
from uam_studio.planning.operations import fly_mission
from uam_studio.risk import (
    DEFAULT_RISK,
    HEALTH_Z,
    RISK_RANGE,
    WEATHER_RESERVE_KT,
    WIND_Z,
    caution,
    check_risk,
    risk_z,
)

ROOT = Path(__file__).resolve().parents[1] / "uam_studio"


def test_the_default_risk_is_the_caution_the_operator_flies():
    """5%: the health and wind bounds 1.64 std and the 25 kt reserve, the numbers every benchmark was flown at."""
    c = caution()
    assert (c.risk, c.health_z, c.wind_z, c.reserve_kt) == (DEFAULT_RISK, 1.64, 1.64, 25.0)
    assert (HEALTH_Z, WIND_Z, WEATHER_RESERVE_KT) == (c.health_z, c.wind_z, c.reserve_kt)
    assert risk_z(0.01) == 2.33
    assert caution(0.01).reserve_kt == pytest.approx(25.0 * 2.33 / 1.64, abs=1e-5)  # the envelope's 1% quantile


@settings(max_examples=60, deadline=None)
@given(a=st.floats(RISK_RANGE[0], 0.4999), b=st.floats(RISK_RANGE[0], 0.4999))
def test_a_smaller_risk_is_never_less_cautious(a, b):
    lo, hi = sorted((a, b))
    c_lo, c_hi = caution(lo), caution(hi)
    assert c_lo.health_z >= c_hi.health_z >= 0 and c_lo.reserve_kt >= c_hi.reserve_kt >= 0
    assert (c_lo.reserve_kt > c_hi.reserve_kt) == (c_lo.health_z > c_hi.health_z)  # the reserve moves with the z
    assert c_lo.reserve_kt <= 60.0  # within the operator's reserve range at the smallest declared risk


@pytest.mark.parametrize("bad", [0, 0.0, -0.1, 0.5, 0.7, math.nan, math.inf, True, "5%", None, 1e-5])
def test_a_bad_risk_is_one_line_naming_the_field(bad):
    with pytest.raises(InputError) as err:
        check_risk(bad)
    assert err.value.field == "risk" and "\n" not in str(err.value)


@pytest.mark.parametrize("arg", ["0", "-0.01", "0.5", "nan"])
def test_fly_with_a_bad_risk_exits_2_in_one_line(capsys, arg):
    assert main(["fly", str(asset_path("example_mission.json")), "--risk", arg]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: risk: ") and "\n" not in err


def test_a_flight_takes_the_cautions_of_its_declared_risk():
    """``fly_mission(risk=)``: every decision keeps the reserve that follows from the risk, and the record says the
    risk; a less cautious risk serves no less on the README mission; cautions set by hand record no risk."""
    mission = load_mission(asset_path("example_mission.json"))
    careful, bold = (fly_mission(mission, seed=0, risk=r, references=False) for r in (0.01, 0.2))
    assert careful.risk == 0.01 and all(d.reserve_kt == caution(0.01).reserve_kt for d in careful.events)
    assert bold.risk == 0.2 and all(d.reserve_kt == caution(0.2).reserve_kt for d in bold.events)
    assert bold.reached_priority >= careful.reached_priority
    assert fly_mission(mission, seed=0, references=False).risk == DEFAULT_RISK
    assert fly_mission(mission, seed=0, references=False, reserve_kt=10.0).risk is None
    json.dumps(careful.to_dict(series=False), allow_nan=False)


# reserves bound to a number outside uam_studio/risk.py, each with what it is (not a flight's declared caution)
NOT_RISK_RESERVES = {
    ("fleet/dispatch.py", "BLIND_RESERVE_V"),  # the health-blind reference dispatcher's voltage reserve (tuned)
}


def test_no_reserve_is_written_outside_the_risks_home():
    """A *_RESERVE_* name is bound to a number only in uam_studio/risk.py (or is named above with what it is)."""
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Assign):
                for t in node.targets:
                    if (isinstance(t, ast.Name) and "_RESERVE" in t.id and isinstance(node.value, ast.Constant)
                            and rel != "risk.py" and (rel, t.id) not in NOT_RISK_RESERVES):
                        offenders.append(f"{rel}: {t.id}")
    assert offenders == [], offenders


# --------------------------------------------------------------------------- the fleet's declared risk


def test_the_fleet_dispatcher_takes_its_margins_from_the_declared_risk():
    """The default risk is the dispatcher's tuned margins (health 1.64 std, each leg's wind 2.33 std); a smaller risk
    never passes a round trip that a larger one refuses (its margin is smaller for every aircraft and request)."""
    from uam_studio.fleet.day import Fleet, OperatingDay
    from uam_studio.fleet.demand import poisson_demand
    from uam_studio.fleet.dispatch import AircraftView
    from uam_studio.risk import DISPATCH_WIND_Z

    assert (caution().health_z, caution().dispatch_wind_z) == (HEALTH_Z, DISPATCH_WIND_Z) == (1.64, 2.33)
    demand = poisson_demand(3, rate_per_h=4.0, day_s=3 * 3600.0)
    fleet = Fleet.new(3, seed=4)
    margins = {}
    for risk in (0.01, 0.05, 0.2):
        day = OperatingDay(fleet, demand, "aware", 1, [2], risk)
        margins[risk] = [day.margin(r, AircraftView(str(i), fleet.belief(i), 0)) for r in demand for i in range(3)]
    assert all(a < b < c for a, b, c in zip(margins[0.01], margins[0.05], margins[0.2]))


@pytest.mark.parametrize("arg", ["0", "0.5", "nan"])
def test_fleet_with_a_bad_risk_exits_2_in_one_line(capsys, arg):
    assert main(["fleet", "--risk", arg]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: risk: ") and "\n" not in err


def _check_winds(monkeypatch, reserve_kt: float, sigma_kt: float) -> list[float]:
    """The winds (kt) the take-off's safety check flies each leg in, for the example mission (winds as forecast)."""
    from uam_studio.planning.operations.operator import Operator

    mission = load_mission(asset_path("example_mission.json"))
    op = Operator(mission, forecast_sigma_kt=sigma_kt, reserve_kt=reserve_kt, planner="oracle")
    seen: list[float] = []
    real = Operator.leg_current

    def spy(self, frm, to, altitude_m, wind_kts):
        seen.append(wind_kts - self.winds.predict(to)[0])  # the check's wind above the belief's mean
        return real(self, frm, to, altitude_m, wind_kts)

    monkeypatch.setattr(Operator, "leg_current", spy)
    op.observe(np.arange(20.0), np.full(20, 20.0), np.full(20, 3.9))
    op.decide()
    return seen


def test_the_check_holds_the_weather_change_jointly_with_the_forecasts_error(monkeypatch):
    """The take-off check's winds: with a perfect forecast each leg gets the whole reserve (the change is common to
    both legs; the belief keeps a small std of its own); with no reserve, the forecast's joint bound alone; with
    both, more than either and less than their sum (the two are independent: their quantiles do not add)."""
    only_change = _check_winds(monkeypatch, 25.0, 0.0)
    assert only_change and all(25.0 <= w < 26.0 for w in only_change)
    monkeypatch.undo()
    only_forecast = _check_winds(monkeypatch, 0.0, 13.0)
    monkeypatch.undo()
    both = _check_winds(monkeypatch, 25.0, 13.0)
    assert len(both) == len(only_forecast) and max(only_forecast) > 1.0
    for a, b in zip(only_forecast, both):
        assert max(a, 25.0 * 0.5) < b < a + 25.0

"""The Fleet tab's state model (no browser): days flown for three dispatchers on the same demand and
packs, the tables the view draws, settings that start new fleets."""

from __future__ import annotations

import holoviews as hv
from bokeh.document import Document

from uam_studio.app.fleet.state import FleetState
from uam_studio.app.fleet.view import FleetView
from uam_studio.fleet.day import simulate_life


def test_a_day_at_a_time_matches_the_library_life_and_the_view_draws_it():
    s = FleetState(aircraft=3, rate_per_h=2.0, seed=4)
    view = FleetView(s)
    view.__panel__().get_root(Document())
    for _ in range(2):
        s.next_day()
    assert [row["day"] for row in s.days] == [1, 2] and not s.running and s.error == ""
    # the same numbers as the library's life of the same settings (what `uam-studio fleet` prints)
    life = simulate_life(3, 2, 4, "aware", rate_per_h=2.0)
    assert [row["aware"] for row in s.days] == life["days"]
    stars = s.per_day()
    assert set(stars) == {"aware", "blind", "hindsight", "bound"}
    assert stars["aware"] == ([1, 2], [d["priority"] for d in life["days"]])
    hindsight = simulate_life(3, 2, 4, "hindsight", rate_per_h=2.0)  # the dotted line: hindsight's bounds
    assert stars["bound"] == ([1, 2], [d["bound"] for d in hindsight["days"]])
    assert all(b >= max(stars[d][1][k] for d in ("aware", "blind", "hindsight"))
               for k, b in enumerate(stars["bound"][1]))
    flights = s.timeline("aware")
    assert flights and all(0 <= f["start_h"] < f["end_h"] <= 18 for f in flights)
    assert len(flights) == s.last["aware"].flights
    packs = s.packs("aware")
    assert len(packs) == 3 and all(p["low"] <= p["belief_q_max"] <= p["high"] for p in packs)
    for fig in (view._timeline(), view._packs(), view._days()):
        assert hv.render(fig).toolbar.active_scroll is None
    s.aircraft = 2  # a new setting: new fleets, no day flown
    assert s.days == [] and len(s.packs("blind")) == 2 and "2 aircraft ready" in s.status


def test_vertiports_in_the_tab_fly_the_library_day_and_too_many_is_one_line():
    s = FleetState(aircraft=4, vertiports=2, rate_per_h=3.0, seed=6)
    s.next_day()
    assert s.error == "" and "at 2 vertiports" not in s.status  # the status now names the day flown
    life = simulate_life(4, 1, 6, "blind", rate_per_h=3.0, vertiports=2)
    assert [row["blind"] for row in s.days] == life["days"]
    s.param.update(aircraft=2, vertiports=3)  # more vertiports than aircraft: no fleet, one line
    assert s.error.startswith("vertiports: ") and "\n" not in s.error and s.days == []
    s.next_day()  # nothing to fly: no crash, no day
    assert s.days == [] and not s.running
    s.vertiports = 2
    assert s.error == "" and "2 aircraft at 2 vertiports ready" in s.status

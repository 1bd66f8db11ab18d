"""A fleet's day (uam_studio.fleet): demand files, the dispatchers' view, the SimPy day, the CLI."""

from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery.health import Logbook
from uam_studio.battery.health.belief import PackBelief, logbook_belief
from uam_studio.battery.health.config import fleet_belief_config
from uam_studio.battery.health.logbook import FlightFit, LoggedFlight
from uam_studio.cli import main
from uam_studio.errors import InputError
from uam_studio.fleet.aging import PackHealth
from uam_studio.fleet.day import Fleet, simulate_day
from uam_studio.fleet.demand import Request, load_demand, poisson_demand
from uam_studio.fleet.dispatch import AircraftView, assign

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def day_demand():
    return poisson_demand(5, rate_per_h=3.0, day_s=4 * 3600.0)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**63 - 1), rate=st.floats(0.0, 60.0), far=st.floats(8.0, 100.0))
def test_a_poisson_day_is_valid_anywhere_in_its_documented_range(seed, rate, far):
    reqs = poisson_demand(seed, rate_per_h=rate, max_km=far)
    assert all(8.0 <= r.distance_km <= max(far, 8.1) for r in reqs)
    assert [r.t_s for r in reqs] == sorted(r.t_s for r in reqs) and len({r.name for r in reqs}) == len(reqs)


def test_a_day_is_seeded_serves_within_the_fleet_and_ages_the_packs(day_demand):
    runs = []
    for _ in range(2):
        fleet = Fleet.new(3, seed=2)
        before = [t.delivered_c for t in fleet.truth]
        runs.append((simulate_day(fleet, day_demand, "aware", seed=9), fleet, before))
    (a, fleet, before), (b, _, _) = runs
    assert a == b  # the same inputs, the same day
    assert a.served + a.breaches + a.refused == len(day_demand) and a.flights == a.served + a.breaches
    assert a.priority == sum(r.priority for r in day_demand if r.name in {entry[2] for entry in a.log}) or a.breaches
    flown = {entry[1] for entry in a.log}
    for i, t in enumerate(fleet.truth):  # the packs that flew delivered charge and aged
        assert (t.delivered_c > before[i]) == (i in flown)
    assert all(b.delivered_c >= 0 for b in fleet.beliefs)
    json.dumps(a.to_dict(), allow_nan=False)
    # each aircraft's belief is its pack's logbook's, on the fleet's declared configuration: the one belief value,
    # from the flights its sensors logged (the belief the day read as its logbook grew, and one read from scratch)
    for i, (b, book) in enumerate(zip(fleet.beliefs, fleet.logbooks)):
        assert len(book) == sum(1 for entry in a.log if entry[1] == i)
        fresh = PackBelief.of(book, fleet_belief_config(fleet.law))
        assert b == fresh and b.config.new_pack is not None and b.config.aging is fleet.aging_law
        mean, cov = logbook_belief(book, fleet_belief_config(fleet.law))
        assert np.allclose(b.mean, mean, rtol=1e-12) and np.allclose(b.cov_matrix, cov, rtol=1e-12)


def test_the_dispatcher_never_reads_the_true_cell(day_demand):
    """Swap test: two fleets with the same beliefs and very different true packs get the same
    assignments from the health-aware and the health-blind rules (only hindsight may differ)."""
    strong = [PackHealth(7900.0, 0.10) for _ in range(3)]
    weak = [PackHealth(6200.0, 0.30) for _ in range(3)]
    books = [Logbook(delivered_before_c=k * 50 * 7600.0, noise_v=0.005) for k in range(3)]
    for rule in ("aware", "blind"):
        days = [simulate_day(Fleet(truth, logbooks=list(books)), day_demand[:3], rule, seed=1)
                for truth in (strong, weak)]
        first = [entry[:3] for entry in days[0].log][:3]
        second = [entry[:3] for entry in days[1].log][:3]
        assert first == second, rule
    # and statically: the dispatch module has no way to the world's truth
    src = (ROOT / "uam_studio" / "fleet" / "dispatch.py").read_text()
    names = {n.id for n in ast.walk(ast.parse(src)) if isinstance(n, ast.Name)}
    assert "PackHealth" not in names and "truth" not in src.split('"""', 2)[2]
    assert {f.name for f in dataclasses.fields(AircraftView)} == {"name", "belief", "key"}


def test_assign_gives_most_stars_first_to_the_tightest_aircraft_that_passes():
    reqs = [Request(0.0, "low", 20.0, 0.0, 1), Request(5.0, "high", 0.0, 20.0, 3)]
    new = PackBelief.start(fleet_belief_config())
    views = [AircraftView("0", new, 0), AircraftView("1", new, 0)]
    margins = {("high", "0"): 0.3, ("high", "1"): 0.1, ("low", "0"): 0.2, ("low", "1"): -0.1}
    out = assign(reqs, views, lambda r, a: margins[(r.name, a.name)], 0.0)
    assert [(r.name, a.name) for r, a in out] == [("high", "1"), ("low", "0")]
    assert assign(reqs, views[1:], lambda r, a: margins[(r.name, a.name)], 0.0) == [(reqs[1], views[1])]


def test_the_belief_ages_with_charge_and_learns_from_a_fit():
    """The fleet's belief value: a new pack's (the factory's 7600 +- 300 C) aged by 200 cycles is weaker and no
    surer; a logged flight's fit pulls it to the fit; a flight too short to fit (and no charge) leaves it."""
    b = PackBelief.start(fleet_belief_config())
    assert b.health.q_max_c == pytest.approx(7600.0) and b.health.q_max_sd_c == pytest.approx(300.0)
    old = b.aged(7600.0 * 200)
    h, h0 = old.health, b.health
    assert h.q_max_c < h0.q_max_c and h.r0_ohm > h0.r0_ohm and h.q_max_sd_c >= h0.q_max_sd_c
    w, sd_w = 6500.0 / 6500.0, 6500.0 * 50.0 / 6500.0 ** 2  # a fit of q_max 6500 +- 50 C, R0 0.15 +- 0.005 ohm
    idle = np.zeros(30)
    learned = old.logged(LoggedFlight(idle, idle + 3.7, fit=FlightFit(w, 0.15, (sd_w ** 2, 0.0, 0.0, 0.005 ** 2))))
    assert abs(learned.health.q_max_c - 6500.0) < abs(h.q_max_c - 6500.0) and learned.health.q_max_sd_c < 50.0
    assert old.logged(LoggedFlight(idle, idle + 3.7)) == old
    with pytest.raises(InputError, match="^charge_c: "):
        b.aged(-1.0)


@pytest.mark.parametrize("text, field", [
    ("t_s,name,x_km,y_km,priority\n100,A,10,10,5\n", "priority"),
    ("t_s,name,x_km,y_km,priority\n100,A,1,1,2\n", "x_km"),
    ("t_s,name,x_km,y_km,priority\n-5,A,10,10,2\n", "t_s"),
    ("t_s,name,x_km,y_km\n100,A,10,10\n", "priority"),
    ("t_s,name,x_km,y_km,priority\nabc,A,10,10,2\n", "demand"),
    ("t_s,name,x_km,y_km,priority,wind_kts\n100,A,10,10,2,nan\n", "wind_kts"),
    ("t_s,name,x_km,y_km,priority\n100,A,10,10,2\n200,A,12,12,1\n", "name"),
    ("t_s,name,x_km,y_km,priority,vertiport\n100,A,10,10,2,x\n", "vertiport"),
    ("t_s,name,x_km,y_km,priority,vertiport\n100,A,10,10,2,10\n", "vertiport"),
])
def test_bad_demand_files_are_one_line_naming_the_field(tmp_path, capsys, text, field):
    path = tmp_path / "day.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=f"^{field}: "):
        load_demand(path)
    assert main(["fleet", "--demand", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {field}: ") and "\n" not in err


def test_a_demand_file_round_trips_and_the_cli_flies_it(tmp_path, capsys):
    from uam_studio.fleet.demand import demand_rows

    reqs = poisson_demand(3, rate_per_h=2.0, day_s=2 * 3600.0)
    path = tmp_path / "day.json"
    path.write_text(json.dumps(demand_rows(reqs)))
    assert load_demand(path) == reqs
    table = tmp_path / "days.csv"
    assert main(["fleet", "--demand", str(path), "--aircraft", "2", "--json", "--dispatcher", "aware",
                 "--csv", str(table)]) == 0
    out = json.loads(capsys.readouterr().out)
    day = out["aware"]["days"][0]
    assert day["served"] + day["refused"] + day["breaches"] == len(reqs)
    import csv

    rows = list(csv.DictReader(table.read_text().splitlines()))  # the same day as the JSON
    assert rows == [{"dispatcher": "aware", "seed": "0", "day": "1",
                     **{k: str(day[k]) for k in ("priority", "served", "refused", "breaches")}, "bound": ""}]


def test_a_life_as_csv_has_a_row_per_dispatcher_seed_and_day_as_the_json(tmp_path, capsys):
    import csv

    table = tmp_path / "life.csv"
    assert main(["fleet", "--aircraft", "2", "--days", "2", "--seeds", "2", "--rate", "2", "--workers", "0",
                 "--dispatcher", "aware", "--dispatcher", "blind", "--json", "--csv", str(table)]) == 0
    lives = json.loads(capsys.readouterr().out)["lives"]
    rows = list(csv.DictReader(table.read_text().splitlines()))
    assert [(r["dispatcher"], r["seed"], r["day"]) for r in rows] == [
        (d, str(s), str(k)) for s in (0, 1) for d in ("aware", "blind") for k in (1, 2)]
    for r in rows:
        life = next(x for x in lives if x["dispatcher"] == r["dispatcher"] and x["seed"] == int(r["seed"]))
        assert int(r["priority"]) == life["priority"][int(r["day"]) - 1]
        assert int(r["breaches"]) == life["breaches"][int(r["day"]) - 1]


@pytest.mark.parametrize("args, flag", [(["--aircraft", "0"], "--aircraft"), (["--days", "0"], "--days"),
                                        (["--rate", "nan"], "--rate"), (["--chargers", "99"], "--chargers"),
                                        (["--aircraft", "2", "--vertiports", "3"], "--vertiports"),
                                        (["--csv", "/nonexistent-folder/day.csv"], "--csv")])
def test_cli_bad_settings_are_one_line(capsys, args, flag):
    assert main(["fleet", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {flag}: ") and "\n" not in err


# --------------------------------------------------------------------------- several vertiports


def test_each_aircraft_serves_its_own_vertiport_and_charges_on_its_chargers():
    """Two vertiports, aircraft based alternately: every flight is flown by an aircraft of the request's
    vertiport; two aircraft landing together at different vertiports of one charger each do not wait,
    at the same vertiport they queue."""
    far = [Request(0.0, "A", 20.0, 0.0, 2), Request(0.0, "B", 0.0, 20.0, 3, vertiport=1),
           Request(7200.0, "C", -15.0, 5.0, 1, vertiport=1)]
    apart = simulate_day(Fleet.new(4, seed=1, vertiports=2), far, "aware", seed=4, chargers=[1, 1])
    by_name = {r.name: r for r in far}
    assert apart.served == 3 and {entry[2] for entry in apart.log} == {"A", "B", "C"}
    assert all(i % 2 == by_name[name].vertiport for _, i, name, _, _ in apart.log)  # base of aircraft i: i % 2
    assert apart.charger_wait_s == 0.0
    together = [dataclasses.replace(r, vertiport=0) for r in far[:2]]
    queued = simulate_day(Fleet.new(4, seed=1, vertiports=2), together, "aware", seed=4, chargers=[1, 1])
    assert queued.served == 2 and all(i % 2 == 0 for _, i, _, _, _ in queued.log) and queued.charger_wait_s > 0.0
    with pytest.raises(InputError, match="^vertiport: "):
        simulate_day(Fleet.new(4, seed=1, vertiports=2), [Request(0.0, "Z", 20.0, 0.0, 1, vertiport=2)], "aware", 4)
    with pytest.raises(InputError, match="^chargers: "):
        simulate_day(Fleet.new(4, seed=1, vertiports=2), far, "aware", 4, chargers=[1, 1, 1])


def test_a_poisson_day_at_several_vertiports_draws_the_same_requests_spread_over_them():
    one, three = poisson_demand(8, rate_per_h=10.0), poisson_demand(8, rate_per_h=10.0, vertiports=3)
    assert [dataclasses.replace(r, vertiport=0) for r in three] == one and {r.vertiport for r in one} == {0}
    assert {r.vertiport for r in three} == {0, 1, 2}


# --------------------------------------------------------------------------- many lives on Dask


def test_lives_on_a_two_worker_local_cluster_equal_the_same_lives_run_here():
    """The engine: each life seeded by its task, so 2 Dask workers give what one process gives."""
    from uam_studio.fleet.study import fleet_study, summarize

    kw = dict(aircraft=(2,), days=1, seeds=(0, 1), dispatchers=("aware", "blind"), rate_per_h=3.0)
    here = fleet_study(**kw, workers=0)
    seen = []
    on_dask = fleet_study(**kw, workers=2, progress=lambda done, n: seen.append((done, n)))
    assert on_dask == here and seen[-1] == (4, 4)
    rows = summarize(here)
    assert [(r["aircraft"], r["dispatcher"], r["lives"]) for r in rows] == [(2, "aware", 2), (2, "blind", 2)]
    assert all(r["p5"] <= r["priority_per_day"] <= r["p95"] for r in rows)


def test_lives_on_a_running_scheduler_by_its_address(capsys):
    """--address: the CLI sends the lives to a scheduler it did not start (a local one here)."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=40) as cluster:
        assert main(["fleet", "--aircraft", "2", "--rate", "2", "--dispatcher", "aware", "--seeds", "2",
                     "--address", cluster.scheduler_address, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [r["seed"] for r in out["lives"]] == [0, 1] and out["summary"][0]["lives"] == 2
    assert main(["fleet", "--aircraft", "2", "--rate", "2", "--dispatcher", "aware", "--seeds", "2",
                 "--workers", "0", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["lives"] == out["lives"]  # the same lives, run here

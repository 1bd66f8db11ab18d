"""Hostile input to the library and the CLI: seeds, events and cell capacities anywhere in (and outside)
their documented ranges give one line naming the field and its range, never a traceback, NaN or hang.

The CLI cases run in-process through ``uam_studio.cli.main`` (the same parser and checks as the
console script); the mission-file cases are in ``tests/test_mission_files.py``."""

from __future__ import annotations

import math
from pathlib import Path

import hypothesis
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery import Q_MAX_RANGE, full_charge, simulate
from uam_studio.cli import main
from uam_studio.errors import MAX_SEED, InputError, check_seed
from uam_studio.planning import load_mission
from uam_studio.planning.operations import fly_mission
from uam_studio.planning.operations.world import MAX_EVENTS, World, parse_event

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"


@pytest.fixture(scope="module")
def example():
    return load_mission(EXAMPLE)


# --------------------------------------------------------------------------- seeds


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.one_of(st.integers(min_value=-2**70, max_value=2**70), st.floats(allow_nan=True), st.booleans(),
                 st.text(max_size=5), st.none()))
def test_check_seed_accepts_exactly_the_integers_in_range(value):
    ok = isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_SEED
    if ok:
        assert check_seed("seed", value) == value
    else:
        with pytest.raises(InputError) as err:
            check_seed("seed", value)
        assert err.value.field == "seed" and f"[0, {MAX_SEED}]" in str(err.value)
        assert len(str(err.value).splitlines()) == 1


@pytest.mark.parametrize("argv", [
    ["fly", str(EXAMPLE), "--seed", "-1"],
    ["fly", str(EXAMPLE), "--seed", str(MAX_SEED + 1)],
    ["fly", str(EXAMPLE), "--seed", "1.5"],
    ["train", "dqn", "--seed", "-1"],
    ["train", "attention", "--seed", "-1"],
    ["evaluate", "dynaformer", "--seed", "-1"],
])
def test_cli_seeds_are_checked_before_anything_runs(argv, tmp_path, capsys):
    out = tmp_path / "run"
    if argv[0] == "train":
        argv = [*argv, "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: argument --seed: ") and f"[0, {MAX_SEED}]" in err, err
    assert len(err.strip().splitlines()) == 1
    assert not out.exists()  # nothing written


def test_library_seed_is_named(example):
    with pytest.raises(InputError, match=rf"^seed: -1 is out of range; a seed is an integer in \[0, {MAX_SEED}\]$"):
        fly_mission(example, seed=-1)
    with pytest.raises(InputError, match="^seed: expected an integer"):
        World(example, seed=1.5)


# --------------------------------------------------------------------------- events


@pytest.mark.parametrize("events", [["wind+30@1200"], [None], [parse_event("wind+5@10"), "wind+5@20"]])
def test_events_that_are_not_wind_events_are_named(example, events):
    with pytest.raises(InputError) as err:
        fly_mission(example, events=events)
    assert err.value.field == "event" and "WindEvent" in str(err.value)


def test_events_are_capped(example, capsys):
    many = [parse_event(f"wind+1@{60 * k}") for k in range(MAX_EVENTS + 1)]
    with pytest.raises(InputError, match=rf"^event: {MAX_EVENTS + 1} events; at most {MAX_EVENTS} allowed"):
        World(example, events=many)
    World(example, events=many[:MAX_EVENTS])  # the cap itself is allowed
    argv = ["fly", str(EXAMPLE)] + [a for k in range(MAX_EVENTS + 1) for a in ("--event", f"wind+1@{60 * k}")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: event: {MAX_EVENTS + 1} events; at most {MAX_EVENTS}"), err


@pytest.mark.parametrize("text", ["wind+\u0663\u0660@1200", "wind+30@\u0661\u0662\u0660\u0660", "wind+３０@1200"])
def test_event_digits_are_ascii(text):
    with pytest.raises(InputError, match="^event: .* is not an event"):
        parse_event(text)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.text(max_size=30))
def test_any_event_text_parses_or_is_one_line(text):
    try:
        ev = parse_event(text)
    except InputError as err:
        assert err.field == "event" and len(str(err).splitlines()) == 1
        return
    assert math.isfinite(ev.start_s) and math.isfinite(ev.delta_kts) and ev.start_s >= 0


# --------------------------------------------------------------------------- cell capacity


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.floats(allow_nan=True, allow_infinity=True))
@hypothesis.example(1.0786158809173895e308)  # once overflowed the state to inf
def test_full_charge_refuses_what_is_not_a_capacity(q):
    if Q_MAX_RANGE[0] <= q <= Q_MAX_RANGE[1]:
        state = full_charge(q)
        assert all(np.all(np.isfinite(getattr(state, f))) for f in ("tb", "qnb", "qns", "qpb", "qps"))
    else:
        with pytest.raises(InputError, match=r"^q_max: \S+ is out of range; allowed \[1, 20000\] C$"):
            full_charge(q)


def test_no_cell_is_an_error_not_an_empty_result():
    with pytest.raises(InputError, match="^q_max: is empty"):
        simulate(np.ones(10), q_max=np.array([]))
    with pytest.raises(InputError, match=r"^q_max: .*nan.* is out of range"):
        simulate(np.ones(10), q_max=np.array([7000.0, np.nan]))


@pytest.mark.parametrize("option", [["--alpha", "nan"], ["--gamma", "-1"], ["--steps", "100000000000000000000"],
                                    ["--beta", "inf"]])
def test_train_dqn_checks_every_option_before_making_the_folder(option, tmp_path, capsys):
    out = tmp_path / "deep" / "run"
    assert main(["train", "dqn", *option, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "deep").exists()


def test_a_cell_at_the_edge_of_the_health_box_flies(example):
    """R0 = 0 is a valid mission (the file format's range starts at 0): the operator's estimate may land a
    little outside the fit's box, and it plans with the estimate kept inside it, instead of failing on
    its own internal number."""
    rec = fly_mission(example.with_battery(7600.0, 0.0), seed=0, references=False)
    assert rec.route and rec.route[-1] == "vertiport" and not rec.breached
    assert all(0.0 <= e.r0_ohm for e in rec.events)


def test_a_very_long_route_names_the_route(example):
    from uam_studio.planning import simulate_route
    from uam_studio.planning.missions.route import MAX_ROUTE_LEGS

    route = ["Richmond", "vertiport"] * 5000
    with pytest.raises(InputError, match=rf"^route: 10000 legs; at most {MAX_ROUTE_LEGS} allowed in one route$"):
        simulate_route(example, route, [500.0] * len(route))


# --------------------------------------------------------------------- health fit on readings that are not a cell's
@settings(max_examples=25, deadline=None, derandomize=True)
@given(volt=st.floats(0.0, 1.5), n=st.integers(20, 200))
def test_readings_no_cell_state_explains_are_refused(volt, n):
    """0-1.5 V throughout under load: no state of the cell model is near it. One line naming the
    voltage and the residual, instead of a confident-looking fleet prior."""
    from uam_studio.battery import fit_health

    with pytest.raises(InputError, match=r"^voltage_v: the cell model cannot explain these readings: RMS residual "
                                         r"[0-9.]+ V, at most 0.5 V; check the units \(V, A\) and the cell type$"):
        fit_health(np.full(n, 1.0), np.full(n, volt))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(current=st.floats(-30.0, -1e-3), n=st.integers(20, 200))
def test_a_context_that_charges_a_full_cell_is_refused(current, n):
    from uam_studio.battery import fit_health

    with pytest.raises(InputError, match=r"^current_a: the context charges the cell \(net -[0-9.e+-]+ C\); the fit "
                                         r"reads a discharge from a full cell \(\+ = discharge\)$"):
        fit_health(np.full(n, current), np.full(n, 3.8))

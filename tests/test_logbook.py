"""A pack's logbook and its one health belief: the file (round trip, damaged files refused in one line and left
untouched, no refit on reading), the belief's aging, the operator starting from a logbook, and the CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uam_studio.battery import simulate
from uam_studio.battery.aging import NASA_AGING_LAW
from uam_studio.battery.health import HealthBelief, Logbook, LogbookError
from uam_studio.battery.health import belief as belief_module
from uam_studio.battery.health import logbook as logbook_module
from uam_studio.battery.health.belief import aged_belief, logbook_belief
from uam_studio.battery.health.config import PAPER_BELIEF
from uam_studio.battery.health.prior import Q_REF_C, fleet_prior
from uam_studio.cli import main
from uam_studio.planning import load_mission
from uam_studio.planning.operations import fly_mission
from uam_studio.planning.operations.pack_history import simulate_logbook
from uam_studio.risk import INTERVAL_Z

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "assets" / "example_mission.json"


def _flight(q_max: float, r0: float, amps: float, seconds: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A constant-current discharge from full, read by a 5 mV / 20 mA sensor (A, V at 1 Hz)."""
    cur = np.full(seconds, amps)
    volt = simulate(cur, 1.0, q_max, r0).voltage_v[:seconds]
    rng = np.random.default_rng(seed)
    return cur[:volt.size] + rng.normal(0, 0.02, volt.size), volt + rng.normal(0, 0.005, volt.size)


@pytest.fixture(scope="module")
def book() -> Logbook:
    out = Logbook(noise_v=0.005)
    for k in range(3):
        out = out.appended(*_flight(7000.0, 0.15, 2.0, 1500, k), rest_s=3600.0 * k)
    return out


@pytest.fixture(scope="module")
def example():
    return load_mission(EXAMPLE)


@pytest.fixture(scope="module")
def example_book(example):
    return simulate_logbook(example, 3, seed=0, world="model")  # the pack its model: its q_max is the mission's


# --------------------------------------------------------------------------- the file


def test_round_trip_keeps_flights_fits_and_belief(book, tmp_path):
    path = tmp_path / "pack.json"
    book.save(path)
    back = Logbook.load(path)
    assert len(back) == 3 and back.noise_v == book.noise_v and back.eod_v == book.eod_v
    for a, b in zip(book.flights, back.flights):
        assert np.allclose(a.current_a, b.current_a, atol=1e-5) and np.allclose(a.voltage_v, b.voltage_v, atol=1e-5)
        assert a.fit == b.fit and a.rest_s == b.rest_s and math.isnan(b.ambient_c)
    assert np.allclose(logbook_belief(back)[0], logbook_belief(book)[0])
    assert json.loads(path.read_text())["version"] == 1


def test_reading_a_logbook_refits_nothing(book, tmp_path, monkeypatch):
    path = tmp_path / "pack.json"
    book.save(path)

    def refuse(*a, **k):
        raise AssertionError("refitted")

    monkeypatch.setattr(logbook_module, "fit_health", refuse)
    monkeypatch.setattr(belief_module, "fit_health", refuse)
    belief = HealthBelief(0.005, 3.0, logbook=Logbook.load(path))
    assert belief.source == "logbook" and belief.prior_health().q_max_c > 0


def _damaged(text: str) -> list[tuple[str, str]]:
    doc = json.loads(text)
    foreign = dict(doc, format="something.else")
    newer = dict(doc, version=2)
    nan_volt = json.loads(text)
    nan_volt["flights"][0]["voltage_v"][3] = 99.0
    short = json.loads(text)
    short["flights"][1]["current_a"] = short["flights"][1]["current_a"][:-5]
    bad_fit = json.loads(text)
    bad_fit["flights"][2]["fit"]["cov_w"] = [0.0, 0.0, 0.0, 0.0]
    return [("truncated", text[: len(text) // 2]), ("empty", ""), ("foreign", json.dumps(foreign)),
            ("newer", json.dumps(newer)), ("out of range", json.dumps(nan_volt)), ("lengths", json.dumps(short)),
            ("bad fit", json.dumps(bad_fit)), ("not json", "\x00\x01binary"), ("a list", "[1, 2, 3]")]


def test_damaged_files_get_one_line_and_stay_as_they_were(book, tmp_path):
    good = tmp_path / "pack.json"
    book.save(good)
    for name, text in _damaged(good.read_text()):
        path = tmp_path / f"{name}.json"
        path.write_text(text)
        before = path.read_bytes()
        with pytest.raises(LogbookError) as err:
            Logbook.load(path)
        msg = str(err.value)
        assert "\n" not in msg and msg.startswith(f"logbook: {path}"), (name, msg)
        assert path.read_bytes() == before


def test_cli_refuses_a_damaged_logbook_with_exit_2_and_leaves_it(book, tmp_path, capsys):
    path = tmp_path / "pack.json"
    book.save(path)
    text = path.read_text()[:-200]
    path.write_text(text)
    for argv in (["fly", str(EXAMPLE), "--logbook", str(path), "--save-logbook", str(path)],
                 ["logbook", "show", str(path)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "logbook:" in err and str(path) in err, err
        assert path.read_text() == text


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, 10_000), byte=st.integers(0, 255))
def test_any_corruption_is_a_logbook_error_or_a_valid_logbook(book, tmp_path, cut, byte):
    """A byte changed anywhere: the load either refuses it in one line or reads a logbook whose belief is finite."""
    raw = bytearray(json.dumps(book.to_dict()).encode())
    raw[cut % len(raw)] = byte
    path = tmp_path / "corrupt.json"
    path.write_bytes(bytes(raw))
    try:
        back = Logbook.load(path)
    except LogbookError as err:
        assert "\n" not in str(err)
        return
    mean, cov = logbook_belief(back)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))


def _bad_documents(doc: dict) -> list[tuple[str, str, str]]:
    """(name, JSON text, a word the one-line error must hold): values no logbook can hold."""
    def edited(change):
        d = json.loads(json.dumps(doc))
        change(d)
        return json.dumps(d)

    fit0 = doc["flights"][0]["fit"]
    v_w, v_r = fit0["cov_w"][0], fit0["cov_w"][3]
    return [
        ("nested 100,000 deep", "[" * 100_000 + "]" * 100_000, "not a logbook"),
        ("a logbook nested 100,000 deep", json.dumps(doc)[:-1] + ', "pack": ' + "[" * 100_000 + "]" * 100_000 + "}",
         "nested"),
        ("nested past the depth", edited(lambda d: d.update(pack=[[[[[["x"]]]]]])), "levels"),
        ("covariance not positive definite", edited(lambda d: d["flights"][0]["fit"].update(
            cov_w=[v_w, 2.0 * (v_w * v_r) ** 0.5, 2.0 * (v_w * v_r) ** 0.5, v_r])), "positive-definite"),
        ("covariance not symmetric", edited(lambda d: d["flights"][0]["fit"].update(cov_w=[v_w, 0.0, 1e-3, v_r])),
         "symmetric"),
        ("1e12 C delivered before", edited(lambda d: d.update(delivered_before_c=1e12)), "delivered_before_c"),
        ("a rest of 300 years", edited(lambda d: d["flights"][0].update(rest_s=1e10)), "rest_s"),
        ("R0 of 8 ohm", edited(lambda d: d["flights"][0]["fit"].update(r0_ohm=8.0)), "r0_ohm"),
        ("an unknown key", edited(lambda d: d.update(health_override=1)), "health_override"),
        ("an unknown flight key", edited(lambda d: d["flights"][0].update(true_q_max=7600)), "true_q_max"),
        ("an unknown fit key", edited(lambda d: d["flights"][0]["fit"].update(q_max=7600)), "q_max"),
    ]


def test_values_no_logbook_can_hold_get_one_line_naming_the_field_and_its_range(book, tmp_path, capsys):
    """Nesting past the depth (100,000 levels included), a covariance that is not positive definite, a charge or
    a rest outside the physical range, unknown keys at any level: one line naming the field and what is allowed,
    exit 2 from the CLI, the file untouched."""
    for name, text, word in _bad_documents(book.to_dict()):
        path = tmp_path / "bad.json"
        path.write_text(text)
        before = path.read_bytes()
        with pytest.raises(LogbookError) as err:
            Logbook.load(path)
        msg = str(err.value)
        assert "\n" not in msg and word in msg and "allowed" in msg, (name, msg)
        assert main(["logbook", "show", str(path)]) == 2, name
        out = capsys.readouterr().err.strip()
        assert out.count("\n") == 0 and word in out, (name, out)
        assert path.read_bytes() == before


_ANY_VALUE = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10**15, 10**15)
    | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=12)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(level=st.sampled_from(["doc", "flight", "fit"]), key=st.sampled_from(
    ["delivered_before_c", "q_nominal_c", "noise_v", "eod_v", "dt_s", "rest_s", "ambient_c", "w", "r0_ohm",
     "cov_w", "discrepancy_factor", "current_a", "flags", "unexpected"]), value=_ANY_VALUE)
def test_any_field_set_to_any_value_is_refused_in_one_line_or_read_whole(book, level, key, value):
    """A field of the document (or a key it does not know) set to any JSON value: refused in one line, or a
    logbook whose belief is finite."""
    doc = json.loads(json.dumps(book.to_dict()))
    target = {"doc": doc, "flight": doc["flights"][0], "fit": doc["flights"][0]["fit"]}[level]
    target[key] = value
    try:
        back = Logbook.from_dict(json.loads(json.dumps(doc)))
    except LogbookError as err:
        assert "\n" not in str(err)
        return
    mean, cov = logbook_belief(back)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))
    assert np.all(np.linalg.eigvalsh(cov) > 0)


# --------------------------------------------------------------------------- the belief


def test_aging_moves_the_belief_as_the_law_and_widens_it():
    prior = fleet_prior()
    mean, cov = aged_belief(prior.mean, np.diag([1e-6, 1e-8]), 20 * 7600.0, 7600.0, 7600.0)
    fq = NASA_AGING_LAW.capacity_fraction(21.0) / NASA_AGING_LAW.capacity_fraction(20.0)
    fr = NASA_AGING_LAW.resistance_ratio(21.0) / NASA_AGING_LAW.resistance_ratio(20.0)
    assert Q_REF_C / mean[0] == pytest.approx(Q_REF_C / prior.mean[0] * fq)
    assert mean[1] == pytest.approx(prior.mean[1] * fr)
    assert cov[0, 0] > 1e-6 / fq ** 2 and cov[1, 1] > 1e-8 * fr ** 2
    same, same_cov = aged_belief(prior.mean, prior.cov, 0.0, 0.0, 7600.0)  # no charge: no change
    assert np.allclose(same, prior.mean) and np.allclose(same_cov, prior.cov)


def test_an_empty_logbook_is_a_new_pack(book):
    new, empty = HealthBelief(0.005, 3.0), HealthBelief(0.005, 3.0, logbook=Logbook())
    assert new.source == empty.source == "take-off"
    cur, volt = _flight(7000.0, 0.15, 2.0, 300, 9)
    for b in (new, empty):
        b.observe(cur, volt)
    assert new.health() == empty.health()
    with_book = HealthBelief(0.005, 3.0, logbook=book)
    with_book.observe(cur, volt)
    assert with_book.source == "logbook" and with_book.health().q_max_sd_c < 0.5 * new.health().q_max_sd_c


def test_the_logbook_belief_holds_the_true_cell_and_answers_three_questions(book):
    belief = HealthBelief(0.005, 3.0, logbook=book)
    h = belief.prior_health()
    # the truth at the next take-off: the pack aged by the law over the logged charge (the test's cell did not
    # age, so the interval has to hold 7000 C within the aging law's few tens of coulombs)
    assert abs(h.q_max_c - 7000.0) < 3 * INTERVAL_Z * h.q_max_sd_c + 60.0
    assert h.cautious_q_max_c(INTERVAL_Z) < h.q_max_c < Q_REF_C / (h.inverse_capacity - INTERVAL_Z
                                                                   * h.inverse_capacity_sd)
    assert h.cautious_r0_ohm(INTERVAL_Z) > h.r0_ohm
    low, median, high = belief.eod_interval(np.full(6000, 2.0))
    assert low <= median <= high and 0 < low


# --------------------------------------------------------------------------- the operator and the CLI


def test_the_operator_starts_from_the_logbook(example, example_book):
    rec = fly_mission(example, seed=0, logbook=example_book, references=False, world="model")
    tb = rec.takeoff_belief
    assert tb["source"] == "logbook" and tb["flights"] == 3
    w, sd = Q_REF_C / tb["q_max_c"], Q_REF_C * tb["q_max_sd_c"] / tb["q_max_c"] ** 2
    assert abs(Q_REF_C / example.battery.q_max - w) <= INTERVAL_Z * sd  # the README mission's cell, in its 90%
    new = fly_mission(example, seed=0, references=False)
    assert new.takeoff_belief["source"] == "take-off" and new.takeoff_belief["flights"] == 0
    assert tb["q_max_sd_c"] < 0.1 * new.takeoff_belief["q_max_sd_c"]
    after = rec.logbook_after()
    assert len(after) == 3 + len(rec.flown_charges) and after.flights[:3] == example_book.flights


def test_the_logbook_holds_readings_not_the_truth(example, example_book):
    """What the logbook keeps is what the sensors read: noisy, never the world's true series."""
    for f in example_book.flights:
        resid = np.diff(f.voltage_v, 2)
        assert 0.005 < np.std(resid) < 0.05  # the 5 mV sensor's noise is in it (a true curve is smooth)


def test_cli_new_fly_and_save(tmp_path, capsys):
    path = tmp_path / "pack.json"
    assert main(["logbook", "new", str(EXAMPLE), "--flights", "2", "--seed", "3", "--out", str(path)]) == 0
    assert "2 flights" in capsys.readouterr().out
    out = subprocess.run([sys.executable, "-m", "uam_studio.cli", "fly", str(EXAMPLE), "--logbook", str(path),
                          "--save-logbook", str(path), "--json"], capture_output=True, text=True, check=True).stdout
    rec = json.loads(out)
    assert rec["takeoff_belief"]["source"] == "logbook" and rec["takeoff_belief"]["flights"] == 2
    assert len(Logbook.load(path)) > 2


def test_a_real_cells_scatter_and_walk_widen_the_logbooks_belief(book):
    """A simulated pack's logbook (scatter and walk 0) against a real cell's: the flight-to-flight scatter and the
    random walk per flight only widen the belief, each in both components."""
    mean0, cov0 = logbook_belief(book)
    mean1, cov1 = logbook_belief(book, replace(PAPER_BELIEF, scatter=0.015))
    mean2, cov2 = logbook_belief(book, replace(PAPER_BELIEF, scatter=0.015, walk=0.0045))
    assert np.all(np.diag(cov1) > np.diag(cov0)) and np.all(np.diag(cov2) > np.diag(cov1))
    assert np.allclose(mean0, mean1, rtol=0.05) and np.all(np.isfinite(mean2))


def test_a_beliefs_flags_and_health_read_one_fit_whichever_runs_first(monkeypatch):
    """flags() before health() gives what it gives after; the readings are fitted once however often either runs,
    and again only when new readings arrive."""
    calls = []
    real = belief_module.fit_health
    monkeypatch.setattr(belief_module, "fit_health", lambda *a, **k: calls.append(1) or real(*a, **k))
    cur, volt = _flight(4000.0, 0.4, 3.0, 400, 7)  # a cell beyond the fleet's box: its fit is flagged
    first, second = HealthBelief(0.005, 3.0), HealthBelief(0.005, 3.0)
    for b in (first, second):
        b.observe(cur, volt)
    flags_before = first.flags()
    assert first.health().q_max_c == first.health().q_max_c and len(calls) == 1
    second.health()
    assert second.flags() == flags_before and flags_before  # the same flags, and some
    assert len(calls) == 2
    first.observe(cur[:60], volt[:60])
    first.flags()
    assert len(calls) == 3


def test_extended_keeps_each_flights_ambient_and_fits_on_the_cell_given(book):
    from uam_studio.battery.parameters import NASA_IDENTIFIED_PARAMS

    records = [_flight(6500.0, 0.05, 2.0, 900, k) for k in range(2)]
    out = Logbook(noise_v=0.005).extended(records, 1.0, rest_s=60.0, ambient_c=31.0, cell=NASA_IDENTIFIED_PARAMS)
    assert [f.ambient_c for f in out.flights] == [31.0, 31.0] and [f.rest_s for f in out.flights] == [60.0, 0.0]
    one = Logbook(noise_v=0.005).appended(*records[0], 1.0, 60.0, 31.0, NASA_IDENTIFIED_PARAMS)
    assert out.flights[0].fit == one.flights[0].fit
    assert Logbook(noise_v=0.005).extended(records[:1]).flights[0].fit != one.flights[0].fit

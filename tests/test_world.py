"""The world unlike the model: a pack's own parameter set, drifting sensors, and the belief's model-error term."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery import simulate
from uam_studio.battery.health import HealthBelief, Logbook
from uam_studio.battery.health.belief import flight_residual_sd_v, model_error
from uam_studio.battery.health.config import PAPER_BELIEF
from uam_studio.battery.pack_variation import OCV_SHIFT_SD_V, PACK_SPREAD, SPREAD_CLIP, pack_params
from uam_studio.battery.parameters import DEFAULT_CELL
from uam_studio.classroom import asset_path
from uam_studio.cli import main
from uam_studio.errors import MAX_SEED, InputError
from uam_studio.flight import leg_profile
from uam_studio.planning import load_mission
from uam_studio.planning.operations import World, fly_mission
from uam_studio.planning.operations.world import DEFAULT_WORLD, DRIFT_SD_MV, WORLDS


@pytest.fixture(scope="module")
def example():
    return load_mission(asset_path("example_mission.json"))


def test_the_default_world_is_not_the_model(example):
    """By default the world's pack has its own parameter set, the same for the same pack number; the model world
    flies the cell type's own set."""
    assert DEFAULT_WORLD == "varied" and set(WORLDS) == {"varied", "model"}
    varied, model = World(example, seed=3), World(example, seed=3, world="model")
    assert model.cell.params == DEFAULT_CELL and varied.cell.params != DEFAULT_CELL
    assert World(example, seed=9, pack=3).cell.params == varied.cell.params  # the pack, not the flight, sets it
    assert World(example, seed=3, pack=4).cell.params != varied.cell.params
    assert (varied.cell.q_max, varied.cell.r0) == (model.cell.q_max, model.cell.r0)  # the health is the mission's


@settings(max_examples=40, deadline=None)
@given(pack=st.integers(0, MAX_SEED))
def test_every_pack_lies_within_its_declared_spread_and_flies(pack):
    """Any pack number: each varied parameter within SPREAD_CLIP std of the type's (in log), the open-circuit
    curve within its shift, the rest untouched; a 2 A discharge on it is finite and reaches the cut-off."""
    p = pack_params(DEFAULT_CELL, pack)
    for name, sd in PACK_SPREAD.items():
        base = getattr(DEFAULT_CELL, name)
        if base == 0.0:
            assert getattr(p, name) == 0.0
            continue
        assert abs(math.log(getattr(p, name) / base)) <= SPREAD_CLIP * sd + 1e-12, name
    assert abs(p.u0p - DEFAULT_CELL.u0p) <= SPREAD_CLIP * OCV_SHIFT_SD_V + 1e-12
    assert (p.xn_max, p.sn, p.vol, p.ap) == (DEFAULT_CELL.xn_max, DEFAULT_CELL.sn, DEFAULT_CELL.vol, DEFAULT_CELL.ap)
    res = simulate(np.full(5000, 2.0), 1.0, 7600.0, 0.117, cell=p)
    assert np.all(np.isfinite(res.voltage_v)) and res.eod_reached


@pytest.mark.parametrize("pack", [-1, 1.5, "a", True, MAX_SEED + 1])
def test_a_bad_pack_or_world_is_one_line(example, pack):
    with pytest.raises(InputError) as err:
        World(example, pack=pack)
    assert err.value.field == "pack"
    with pytest.raises(InputError) as err:
        fly_mission(example, world="real")
    assert err.value.field == "world" and "varied, model" in str(err.value)


def test_the_sensors_drift_in_the_varied_world_only(example):
    """The readings' error (measured - true) over a whole first leg: white in the model world (its mean within 4 std
    of white noise's), a slow offset beside it in the varied world (a low-frequency part of the declared size,
    across seeds)."""
    cur = np.asarray(leg_profile(40.0, 500.0, 0.0).current_a, dtype=float)
    first = example.destinations[0].name
    sizes = []

    def offsets(world: str) -> np.ndarray:
        out = []
        for seed in range(12):
            w = World(example, seed=seed, world=world)
            w.takeoff_check(cur)
            r = w.fly_leg(first, 500.0)
            sizes.append(r.voltage_v.size)
            out.append(float(np.mean(r.voltage_v - w.last_true_voltage_v)))
        return np.array(out)

    model, varied = offsets("model"), offsets("varied")
    white = 5e-3 / math.sqrt(min(sizes))
    assert min(sizes) > 500 and np.all(np.abs(model) < 4 * white)
    assert 0.4 * DRIFT_SD_MV * 1e-3 < np.std(varied) < 2.5 * DRIFT_SD_MV * 1e-3


def test_the_model_error_is_learned_from_the_logbook(example):
    """A logged flight of the model world leaves no residual beyond the white noise (its pooled term falls below the
    prior); a flight of a varied pack leaves one (its term exceeds the model world's); a new pack takes the
    take-off's term until it has read a flight's worth."""
    model_rec = fly_mission(example, seed=2, world="model", references=False)
    varied_rec = fly_mission(example, seed=2, references=False)
    model_book = Logbook(noise_v=0.005).extended(model_rec.flown_charges, 1.0)
    varied_book = Logbook(noise_v=0.005).extended(varied_rec.flown_charges, 1.0)
    m_sd = [flight_residual_sd_v(f, DEFAULT_CELL) for f in model_book.flights]
    v_sd = [flight_residual_sd_v(f, DEFAULT_CELL) for f in varied_book.flights]
    assert max(m_sd) < 2e-3 < max(v_sd), (m_sd, v_sd)
    assert model_error(model_book).sd_v < PAPER_BELIEF.model_error_sd_v
    assert model_error(varied_book).sd_v > model_error(model_book).sd_v
    new = HealthBelief(0.005, 3.0)
    assert new.model_error.sd_v == PAPER_BELIEF.takeoff_model_error_sd_v
    assert new.model_error.below_v == PAPER_BELIEF.takeoff_model_error_low_sd_v > new.model_error.sd_v  # skewed
    cur, volt = varied_rec.flown_charges[0]
    new.observe(cur, volt)
    assert new.model_error.sd_v == new.model_error.below_v == PAPER_BELIEF.model_error_sd_v  # a flight's worth read
    assert HealthBelief(0.005, 3.0, logbook=varied_book).model_error.flights == len(varied_book)


def test_the_record_holds_the_first_legs_interval_and_what_the_world_gave(example):
    """``takeoff_belief`` carries the 90% interval of the first leg's lowest voltage (low < median < high) and the
    model-error term; ``first_leg_min_voltage_v`` is the world's; JSON has finite numbers only."""
    rec = fly_mission(example, seed=1, references=False)
    tb = rec.takeoff_belief
    lo, hi = tb["first_leg_min_voltage_90_v"]
    med = tb["first_leg_min_voltage_median_v"]
    assert lo < med < hi and tb["model_error_v"] > 0 and 0 < tb["model_error_share"] <= 1
    # a new pack's take-off belief: the term's skew (the world gives far less more often) widens the low side
    assert tb["model_error_low_v"] == PAPER_BELIEF.takeoff_model_error_low_sd_v and med - lo > 2 * (hi - med)
    assert rec.first_leg_min_voltage_v == pytest.approx(min(rec.true_voltage_v[:int(rec.leg_end_s[0])]), abs=1e-9)
    d = rec.to_dict(series=False)
    assert d["world"] == "varied" and d["pack"] == 1
    json.dumps(d, allow_nan=False)


def test_the_hindsight_reference_knows_the_packs_own_parameters(example, monkeypatch):
    """Hindsight plans on the world's cell, the pack's own set (it breaches no more than the operator could)."""
    from uam_studio.planning.operations import references as fly_module

    seen = []
    real = fly_module.oracle_plan

    def spy(*args, **kwargs):
        seen.append(kwargs.get("params"))
        return real(*args, **kwargs)

    monkeypatch.setattr(fly_module, "oracle_plan", spy)
    fly_mission(example, seed=4, pack=7)
    assert seen and all(p == pack_params(DEFAULT_CELL, 7) for p in seen)


def test_fly_and_logbook_new_name_the_world_and_the_pack(tmp_path, capsys):
    book = tmp_path / "b.json"
    mission = str(asset_path("example_mission.json"))
    assert main(["logbook", "new", mission, "--flights", "1", "--pack", "5", "--out", str(book)]) == 0
    assert "model error" in capsys.readouterr().out
    assert main(["fly", mission, "--logbook", str(book), "--pack", "5", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["world"] == "varied" and d["pack"] == 5 and "first_leg_min_voltage_90_v" in d["takeoff_belief"]
    assert main(["fly", mission, "--world", "model"]) == 0
    out = capsys.readouterr().out
    assert "world model" in out and "first leg's lowest voltage: believed" in out
    assert main(["fly", mission, "--world", "real"]) == 2
    assert "--world: invalid choice: 'real'" in capsys.readouterr().err


def test_the_model_world_flies_what_it_flew_before_the_varied_world(example):
    """``world="model"`` is the world that was the only one: the same readings as a World built without drift or
    varied parameters (the drift's own random stream leaves the sensor noise's untouched)."""
    w = World(example, seed=5, world="model")
    r = w.takeoff_check(np.asarray(leg_profile(20.0, 500.0, 0.0).current_a, dtype=float))
    rng = np.random.default_rng([5, 0x5E45])
    cur_noise = rng.normal(0.0, 20e-3, r.current_a.size)
    volt_noise = rng.normal(0.0, 5e-3, r.current_a.size)
    np.testing.assert_allclose(r.voltage_v - w.last_true_voltage_v, volt_noise, atol=1e-12)
    np.testing.assert_allclose(r.current_a - w.last_true_current_a, cur_noise, atol=1e-12)
    assert dataclasses.replace(w.cell, name="x").params == DEFAULT_CELL


def test_a_sweep_of_one_cell_flies_the_default_world_and_formats_its_row():
    """``studies.flying.sweep`` (forecast error x sensor noise) in the default world: one mission, one cell, its
    row in the plain-text table."""
    from uam_studio.studies.flying import format_rows, sweep

    rows = sweep(sigmas_kt=(0.0,), noises_mv=(5.0,), n=1, n_dest=(4, 4))
    assert len(rows) == 1 and rows[0]["n"] == 1 and rows[0]["breaches"] == 0
    table = format_rows(rows).splitlines()
    assert len(table) == 2 and table[0].split()[:2] == ["sigma", "kt"] and table[1].split()[:2] == ["0", "5"]


def test_the_clis_world_choices_are_the_librarys():
    """The CLI writes the worlds down so that parsing imports no model: the same worlds, the default first."""
    from uam_studio.cli.common import WORLD_CHOICES

    assert WORLD_CHOICES == WORLDS and WORLD_CHOICES[0] == DEFAULT_WORLD

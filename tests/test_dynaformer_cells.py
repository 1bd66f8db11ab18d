"""Dynaformers per cell type: the VTC6's synthetic data, fine-tuning from the NASA weights, a predictor
that fits, re-observes and rests on its own cell, and the bundled VTC6 weights on held-out data."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import example, given, settings
from hypothesis import strategies as st

from uam_studio.battery import rest_voltage, simulate, simulate_constant_power
from uam_studio.battery.parameters import DEFAULT_CELL, VTC6, VTC6_FLEET_Q_RANGE, VTC6_FLEET_R0_RANGE
from uam_studio.dynaformer import load_predictor
from uam_studio.dynaformer.artifact import bundled_weights_path
from uam_studio.dynaformer.cells import DYNAFORMER_CELLS, VTC6_TRAINING, dynaformer_cell
from uam_studio.dynaformer.data import make_dataset, power_mission_profile
from uam_studio.dynaformer.model import Dynaformer, DynaformerConfig
from uam_studio.errors import InputError

HAS_NASA = bundled_weights_path().is_file()
HAS_VTC6 = bundled_weights_path("vtc6").is_file()
TINY = dict(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32)


def test_nasa_config_is_the_old_default_and_unknown_cells_are_refused():
    """Weights saved before cell types (no 'cell' in the config) read as the NASA cell, with its scales."""
    assert DynaformerConfig.for_cell("nasa18650") == DynaformerConfig()
    v = DynaformerConfig.for_cell("vtc6")
    assert (v.cell, v.i_scale) == ("vtc6", 15.0)
    assert v.r0_mid - v.r0_half == pytest.approx(0.012) and v.r0_mid + v.r0_half == pytest.approx(0.06)
    for bad in ("lipo", None, 3):
        with pytest.raises(InputError) as err:
            dynaformer_cell(bad)
        assert str(err.value).startswith("cell")
    with pytest.raises(InputError):
        Dynaformer(DynaformerConfig(cell="lipo"))


def test_vtc6_training_box_covers_the_fleet_prior():
    """The fine-tuned decoder must have seen every cell the operator's prior can propose."""
    kind = DYNAFORMER_CELLS["vtc6"]
    assert kind.q_range[0] < VTC6_FLEET_Q_RANGE[0] and kind.q_range[1] > VTC6_FLEET_Q_RANGE[1]
    assert kind.r0_range[0] < VTC6_FLEET_R0_RANGE[0] and kind.r0_range[1] > VTC6_FLEET_R0_RANGE[1]
    assert kind.q_range[0] <= VTC6.q_max <= kind.q_range[1] and kind.r0_range[0] <= VTC6.r0 <= kind.r0_range[1]


@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_power_missions_have_the_dataset_shape(seed):
    p = power_mission_profile(np.random.default_rng(seed), 5120)
    assert 1 <= p.size <= 5120 and np.all(np.isfinite(p))
    flying = p[p > 0]
    assert flying.min() >= 8.0 and flying.max() <= 65.0  # W per cell: cruise 8-30, take-off/landing 40-65
    assert p[0] >= 40.0  # every mission starts with a take-off


def test_vtc6_set_is_the_physics_of_its_own_current_on_the_vtc6():
    """The flights are flown by power; the stored current is what the cell drew: the VTC6 model driven by
    that current reproduces the stored voltage, and P = I V holds at the power levels of the protocol."""
    ds = make_dataset(12, seed=4242, cell="vtc6", flight_fraction=0.5)
    assert set(np.unique(ds.kind)) == {0, 1}
    assert np.all((ds.q_max >= 8000) & (ds.q_max <= 12500) & (ds.r0 >= 0.012) & (ds.r0 <= 0.06))
    res = simulate(ds.current_a.astype(float), 1.0, ds.q_max, ds.r0, eod_v=2.5, cell=VTC6.params)
    both = ds.valid & res.valid
    assert both.sum() > 0.95 * ds.valid.sum()
    assert np.max(np.abs(res.voltage_v[both] - ds.voltage_v[both])) < 2e-3  # V (float32 storage)
    flights = np.flatnonzero(ds.kind == 0)
    k = flights[0]
    power = ds.current_a[k, 1:50].astype(float) * ds.voltage_v[k, :49]  # P / V(start of the step)
    assert 39.5 < np.median(power) < 65.5
    generic = ds.current_a[ds.kind == 1]
    assert generic.max() <= 18.0 + 1e-5 and generic[generic > 0].min() >= 0.5 - 1e-5


def test_vtc6_held_out_and_train_sets_differ_by_seed_and_nasa_set_is_its_own():
    a = make_dataset(4, seed=1, cell="vtc6", max_len=600)
    b = make_dataset(4, seed=2, cell="vtc6", max_len=600)
    n = make_dataset(4, seed=1, max_len=600)
    assert not np.array_equal(a.q_max, b.q_max)
    assert n.q_max.max() <= 8000 and a.q_max.min() >= 8000


def test_fine_tune_from_nasa_weights_makes_a_vtc6_predictor(tmp_path):
    """Fine-tuning starts from the given weights, refits the take-off estimator on VTC6 take-offs, and the
    predictor fits health, re-observes the take-off and fills a leading rest on the VTC6 set."""
    import uam_studio.dynaformer.train as train_mod
    from uam_studio.dynaformer.artifact import save_artifact

    torch.manual_seed(0)
    base = Dynaformer(DynaformerConfig(**TINY))
    pca = {"mean": torch.zeros(2), "components": torch.eye(2), "scale": torch.ones(2), "explained": torch.ones(2)}
    init = tmp_path / "nasa.pt"
    save_artifact(init, base, pca, {})
    cfg = train_mod.TrainConfig(n_train=64, n_context=400, steps=2, batch=8, max_len=512, checkpoint_every=2,
                                device="cpu", threads=1, cell="vtc6", init=str(init), lr=1e-12)
    weights = train_mod.train(cfg, tmp_path / "run", resume=False, model_cfg=DynaformerConfig.for_cell("vtc6", **TINY))
    pred = load_predictor(weights)
    assert pred.model.cfg.cell == "vtc6" and pred.cell is VTC6.params
    final = pred.model.state_dict()
    start = base.state_dict()
    dec = [k for k in final if k.startswith("decoder.")]
    assert all(torch.allclose(final[k], start[k], atol=1e-6) for k in dec)  # lr ~ 0: the decoder is the init's
    assert not torch.equal(final["takeoff.weight"], start["takeoff.weight"])  # refitted on the VTC6
    # A log that starts at rest: the rest is filled with the VTC6's rested full-cell voltage, not the NASA's.
    cur = np.r_[np.zeros(30), np.full(300, 14.0)]
    v_rest = float(rest_voltage(VTC6.q_max, VTC6.params))
    ctx_v = np.r_[np.full(30, v_rest), simulate(cur[30:60], 1.0, VTC6.q_max, VTC6.r0, eod_v=2.5,
                                                   cell=VTC6.params).voltage_v]
    est = pred.health_estimate(cur[:60], ctx_v)
    assert VTC6_FLEET_Q_RANGE[0] * 0.8 < est.q_max < VTC6_FLEET_Q_RANGE[1] * 1.2
    assert abs(est.r0 - VTC6.r0) < 0.01
    v = pred.predict(cur[:60], ctx_v, np.r_[np.zeros(30), cur])  # a profile with a longer rest first
    assert np.allclose(v[:30], v_rest) and abs(v_rest - float(rest_voltage())) > 0.01
    with pytest.raises(InputError) as err:  # another architecture: refused, one line naming the field
        bad_cfg = train_mod.TrainConfig(n_train=64, n_context=400, steps=1, batch=8, max_len=512, device="cpu",
                                        cell="vtc6", init=str(init))
        train_mod.train(bad_cfg, tmp_path / "run2", resume=False)
    assert str(err.value).startswith("init") and "architecture" in str(err.value)
    with pytest.raises(InputError) as err:
        bad = train_mod.TrainConfig(n_train=64, n_context=400, steps=1, cell="vtc6",
                                    init=str(tmp_path / "missing.pt"))
        train_mod.train(bad, tmp_path / "run3", resume=False, model_cfg=DynaformerConfig.for_cell("vtc6", **TINY))
    assert str(err.value).startswith("init")


def test_cli_cell_option_is_for_the_dynaformer_only(capsys):
    from uam_studio.cli import main

    assert main(["train", "dqn", "--cell", "vtc6", "--steps", "10"]) != 0
    assert "--cell" in capsys.readouterr().err


VTC6_KEYS = ("vtc6", "vtc6_landing_held_out", "vtc6_cell_held_out")


def test_held_out_cell_types_are_the_vtc6_recipe_on_the_held_out_sets():
    """The Dynaformers of the held-out rows differ from the VTC6's only in the parameter set they were
    trained on (and their file): the same box, loads, scales and lengths; and the CLI offers every type."""
    from dataclasses import fields

    from uam_studio.battery.parameters import VTC6_CELL_HELD_OUT, VTC6_LANDING_HELD_OUT
    from uam_studio.cli.train import DYNAFORMER_CELL_KEYS

    assert DYNAFORMER_CELL_KEYS == list(DYNAFORMER_CELLS)
    for key, cell in (("vtc6_landing_held_out", VTC6_LANDING_HELD_OUT), ("vtc6_cell_held_out", VTC6_CELL_HELD_OUT)):
        kind = dynaformer_cell(key)
        assert kind.cell is cell and kind.params is cell.params and kind.weights_file == f"dynaformer_{key}.pt"
        same = [f.name for f in fields(kind) if f.name not in ("key", "cell", "weights_file")]
        assert [getattr(kind, n) for n in same] == [getattr(VTC6_TRAINING, n) for n in same]
        cfg = DynaformerConfig.for_cell(key)
        assert cfg.cell == key and cfg == replace(DynaformerConfig.for_cell("vtc6"), cell=key)
        # every cell its fleet prior can propose was in training (the set's own nominal R0 need not be:
        # VAH07's identified 0.008 ohm is below every fitted mission of the fleet, 0.015-0.052 ohm)
        (q_lo, q_hi), (r_lo, r_hi) = cell.params.fleet_q_range, cell.params.fleet_r0_range
        assert kind.q_range[0] < q_lo < q_hi < kind.q_range[1] and kind.r0_range[0] < r_lo < r_hi < kind.r0_range[1]


@pytest.mark.parametrize("key", VTC6_KEYS)
def test_bundled_vtc6_weights_predict_held_out_vtc6_flights(key):
    """On flights of the weights' own VTC6 parameter set drawn with a seed training never saw, given the
    exact health, the fine-tuned decoder follows the physics (RMSE before the 2.5 V floor) and times the
    3.0 V EOD; the NASA weights, on the same flights, do not (the reference that shows the fine-tuning
    mattered)."""
    from uam_studio.dynaformer.evaluate import decoder_errors

    if not bundled_weights_path(key).is_file():
        pytest.skip(f"bundled {key} weights not present")
    ds = make_dataset(48, seed=777_001, cell=key, flight_fraction=1.0)
    errors = {cell: decoder_errors(load_predictor(bundled_weights_path(cell)), ds) for cell in (key, "nasa18650")}
    assert load_predictor(bundled_weights_path(key)).cell_type is dynaformer_cell(key)
    assert errors[key]["rmse_mv"] < 20, errors
    assert errors[key]["median_rte"] < 0.02, errors
    assert errors["nasa18650"]["rmse_mv"] > 3 * errors[key]["rmse_mv"], errors


@pytest.mark.skipif(not (HAS_VTC6 and HAS_NASA), reason="bundled weights not present")
def test_bundled_vtc6_weights_are_a_vtc6_model_and_the_nasa_ones_unchanged():
    from uam_studio.dynaformer import load_pretrained

    assert load_pretrained().cell_type.key == "nasa18650" and load_pretrained().cell is DEFAULT_CELL
    v = load_pretrained("vtc6")
    assert v.cell_type is VTC6_TRAINING and v.model.cfg.i_scale == 15.0
    assert Path(v.source).name == "dynaformer_vtc6.pt"
    with pytest.raises(InputError):
        load_pretrained("lipo")


def test_flights_by_power_draw_more_current_as_the_voltage_sags():
    """The data's power flights are constant-power loads (sanity of the generator's physics)."""
    res = simulate_constant_power(np.full(300, 54.0), 1.0, VTC6.q_max, VTC6.r0, eod_v=2.5, cell=VTC6.params)
    assert res.valid.all()
    assert res.current_a[-1] > res.current_a[0] > 12.0
    np.testing.assert_allclose(res.current_a[1:] * res.voltage_v[:-1], 54.0, rtol=1e-9)


@pytest.mark.parametrize("key", (*VTC6_KEYS, "nasa18650_4a"))
def test_stored_decoder_calibration_of_the_fine_tuned_weights_is_what_calibration_gives(key):
    """The stored split-conformal quantiles are recomputed from their documented seed and count."""
    from uam_studio.dynaformer.decoder_error import (
        BUNDLED_DECODER_LAMBDA,
        CAL_PROBS,
        conformal_quantiles,
        decoder_error_scores,
        file_sha256,
    )

    if not bundled_weights_path(key).is_file():
        pytest.skip(f"bundled {key} weights not present")
    pred = load_predictor(bundled_weights_path(key))
    stored = BUNDLED_DECODER_LAMBDA[file_sha256(pred.source)]
    np.testing.assert_allclose(conformal_quantiles(decoder_error_scores(pred), CAL_PROBS), stored, atol=6e-5)


@settings(max_examples=15, deadline=None, derandomize=True)
@given(q_max=st.floats(8000.0, 12500.0), r0=st.floats(0.012, 0.06), current=st.floats(5.0, 18.0),
       rest=st.integers(0, 30), load_s=st.integers(20, 120))
@example(q_max=VTC6.q_max, r0=VTC6.r0, current=14.0, rest=30, load_s=30)
def test_health_fit_recovers_a_vtc6_at_high_current(q_max, r0, current, rest, load_s):
    """The fit's coarse start is scaled to the cell type's fleet: noise-free VTC6 data at 5-18 A, after a rest
    or from the first sample, give back the cell (the NASA start, 0.1-0.3 ohm, put the VTC6 under the cut-off
    and ended in q_max 3510 C for a 10943 C cell)."""
    from uam_studio.battery import fit_health

    cur = np.r_[np.zeros(rest), np.full(load_s, current)]
    volt = simulate(cur, 1.0, q_max, r0, eod_v=2.5, cell=VTC6.params).voltage_v
    est = fit_health(cur, volt, cell=VTC6.params, prior=False)
    assert abs(est.q_max - q_max) / q_max < 0.01, est
    assert abs(est.r0 - r0) < 1e-3, est


@pytest.mark.skipif(not HAS_VTC6, reason="bundled VTC6 weights not present")
def test_health_correlations_read_only_discharges_that_last_the_context():
    """A context of 400 s is read from the discharges that last 400 s, never from a shorter one's padding
    (a VTC6 set holds discharges of 35 s); too few such discharges give no correlation, not a number."""
    from uam_studio.dynaformer import load_pretrained
    from uam_studio.dynaformer.evaluate import format_report, health_correlations

    pred = load_pretrained("vtc6")
    ds = make_dataset(24, seed=13_345, cell="vtc6", flight_fraction=1.0)
    lasting = ds.valid.sum(1)
    assert lasting.min() < 400 <= lasting.max()
    long = np.flatnonzero(lasting >= 400)
    row = health_correlations(pred, ds, 400, 0.0)
    assert row["n"] == long.size
    assert row == health_correlations(pred, ds.subset(long), 400, 0.0)
    shortest = health_correlations(pred, ds.subset(np.argsort(lasting)[:2]), 400, 0.0)
    assert shortest["n"] < 3 and shortest["abs_r_r0"] is None
    text = format_report({"weights": "w", "sets": {}, "health": [{"context_s": 400, "noise_mv": 0, **shortest},
                                                                 {"context_s": 400, "noise_mv": 0, **row}]})
    assert "too few discharges last the context" in text and f"n {long.size:4d}" in text


HAS_NASA_4A = bundled_weights_path("nasa18650_4a").is_file()


@pytest.mark.skipif(not (HAS_NASA_4A and HAS_NASA), reason="bundled weights not present")
@settings(max_examples=6, deadline=None, derandomize=True)
@given(q_max=st.floats(5000.0, 8000.0), r0=st.floats(0.02, 0.13), current=st.floats(3.8, 4.5))
@example(q_max=6400.0, r0=0.13, current=4.0)
def test_the_4a_weights_follow_the_physics_above_3a_where_the_aircrafts_do_not(q_max, r0, current):
    """At a constant 3.8-4.5 A (the data set's 4 A loads) the weights trained for the PCoE loads end the
    discharge within 2% of the physics model at the exact health; the aircraft's weights (trained up to
    3 A) at least 5% off. (Above about 0.15 ohm at 4 A the model's voltage lies along 3.0 V for minutes, so
    a few mV move its end by several %: the 4a weights miss by up to 5% there, measured; not asserted.)"""
    from uam_studio.dynaformer.data import DischargeSet
    from uam_studio.dynaformer.decoder_error import decode_given_health

    n = 8000
    cur = np.full(n, current)
    res = simulate(cur, 1.0, q_max, r0, eod_v=2.5)
    ds = DischargeSet(cur[None, :].astype(np.float32), res.voltage_v[None, :].astype(np.float32),
                      res.valid[None, :], np.array([n]), np.array([q_max]), np.array([r0]), np.array([1], np.int8))
    true_s = int(np.argmax(res.voltage_v < 3.0))
    assert 0 < true_s < int(res.valid.sum())
    miss = {}
    for key in ("nasa18650_4a", "nasa18650"):
        v = decode_given_health(load_predictor(bundled_weights_path(key)), ds)[0]
        miss[key] = abs(int(np.argmax(v < 3.0)) - true_s) / true_s
    assert miss["nasa18650_4a"] <= 0.02, miss
    assert miss["nasa18650"] >= 0.05, miss


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), max_len=st.integers(600, 10240))
def test_square_waves_are_the_4a_types_own_and_look_like_the_pcoe_load(seed, max_len):
    """``nasa18650_4a``'s square waves hold one level of 1-4.5 A for 5-20 s, then 0 A as long; the types
    without a ``square_wave_share`` draw none (their data sets are unchanged)."""
    from uam_studio.dynaformer.cells import NASA_4A_TRAINING, NASA_TRAINING
    from uam_studio.dynaformer.data import generic_profile, square_wave_profile

    p = square_wave_profile(np.random.default_rng(seed), max_len, NASA_4A_TRAINING)
    assert min(600, max_len) <= p.size <= max_len
    level = p.max()
    assert 1.0 <= level <= 4.5 and set(np.unique(p)) == {0.0, level}
    runs = np.diff(np.flatnonzero(np.diff(p) != 0))
    assert runs.size and runs.min() == runs.max() and 5 <= runs[0] <= 20
    assert NASA_TRAINING.square_wave_share == 0.0
    q = generic_profile(np.random.default_rng(seed), max_len, NASA_TRAINING)
    assert np.count_nonzero(np.diff(q)) <= 6

"""Dynaformer API: shapes, time grids, bad input, corrupted weights, and the bundled model's accuracy."""

import numpy as np
import pytest
import torch

from uam_studio.battery import simulate
from uam_studio.dynaformer import WeightsError, load_predictor, load_with_fallback
from uam_studio.dynaformer.artifact import save_artifact
from uam_studio.dynaformer.data import make_dataset
from uam_studio.dynaformer.model import Dynaformer, DynaformerConfig
from uam_studio.dynaformer.predictor import bundled_weights_path
from uam_studio.errors import InputError
from uam_studio.flight import leg_current

HAS_BUNDLED = bundled_weights_path().is_file()


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    torch.manual_seed(0)
    cfg = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32, latent_dim=4)
    pca = {"mean": torch.zeros(4), "components": torch.eye(4)[:2], "scale": torch.ones(2), "explained": torch.ones(2)}
    path = tmp_path_factory.mktemp("w") / "tiny.pt"
    save_artifact(path, Dynaformer(cfg), pca, {"note": "test"})
    return load_predictor(path), path


def _ctx():
    cur = leg_current(40.0, 1000, 0.0)
    v = simulate(cur[:20]).voltage_v
    return cur, cur[:20], v


def test_shapes_single_and_batch(tiny):
    p, _ = tiny
    cur, ci, cv = _ctx()
    v = p.predict(ci, cv, cur)
    assert v.shape == cur.shape and np.all(np.isfinite(v))
    vb = p.predict(np.stack([ci, ci]), np.stack([cv, cv]), np.stack([cur, cur]))
    assert vb.shape == (2, cur.size)
    np.testing.assert_allclose(vb[0], v, atol=1e-5)
    assert p.health(ci, cv).shape == (2,)
    assert p.health(np.stack([ci] * 3), np.stack([cv] * 3)).shape == (3, 2)


def test_prediction_is_causal(tiny):
    """Changing the future current must not change the past prediction (beyond the current chunk)."""
    p, _ = tiny
    cur, ci, cv = _ctx()
    other = cur.copy()
    other[640:] = 0.1
    a, b = p.predict(ci, cv, cur), p.predict(ci, cv, other)
    np.testing.assert_allclose(a[:640], b[:640], atol=1e-5)


def test_other_time_grid(tiny):
    p, _ = tiny
    cur, ci, cv = _ctx()
    v2 = p.predict(ci[::2], cv[1::2], cur[::2], dt_s=2.0)
    assert v2.shape == cur[::2].shape and np.all(np.isfinite(v2))


@pytest.mark.parametrize(
    "args,field",
    [
        (([], [], [1.0]), "context_current_a"),
        (([1.0, np.nan], [4.0, 4.0], [1.0]), "context_current_a"),
        (([1.0, 1.0], [4.0, np.inf], [1.0]), "context_voltage_v"),
        (([1.0, 1.0], [4.0], [1.0]), "context_voltage_v"),
        (([1.0], [4.0], [np.nan]), "current_a"),
        (([1.0], [4.0], []), "current_a"),
    ],
)
def test_bad_input(tiny, args, field):
    p, _ = tiny
    with pytest.raises(InputError) as err:
        p.predict(*args)
    assert str(err.value).startswith(field) and "\n" not in str(err.value)


def test_corrupted_and_incompatible_weights(tiny, tmp_path):
    _, good = tiny
    bad = tmp_path / "bad.pt"
    bad.write_bytes(good.read_bytes()[:1000])
    with pytest.raises(WeightsError) as err:
        load_predictor(bad)
    assert str(err.value).startswith("weights")
    other = tmp_path / "other.pt"
    torch.save({"format": "something-else"}, other)
    with pytest.raises(WeightsError):
        load_predictor(other)
    with pytest.raises(WeightsError):
        load_predictor(tmp_path / "missing.pt")


@pytest.mark.skipif(not HAS_BUNDLED, reason="no bundled weights")
def test_fallback_to_bundled(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a model")
    pred, err = load_with_fallback(bad)
    assert err is not None and "weights" in err
    assert pred.source == str(bundled_weights_path())


@pytest.mark.skipif(not HAS_BUNDLED, reason="no bundled weights")
@pytest.mark.xfail(strict=True, reason="the bundled model misses the accuracy goal (RMSE 56 mV, median RTE 0.084): "
                   "its health latent does not capture q_max; see pretrained/DYNAFORMER_CARD.md and issue #3")
def test_bundled_model_tracks_physics_on_held_out_missions():
    """A small held-out check of the bundled model (the full evaluation is `uam-studio evaluate dynaformer`)."""
    from uam_studio.dynaformer import load_pretrained
    from uam_studio.dynaformer.evaluate import eod_metrics, predict_set

    ds = make_dataset(60, seed=987654, flight_fraction=1.0)
    m = eod_metrics(ds, predict_set(load_pretrained(), ds))
    assert m["rmse_mv"] < 40.0
    assert m["median_rte"] < 0.05

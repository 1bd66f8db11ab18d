"""Dynaformer API: shapes, time grids, bad input, corrupted weights, and the bundled model's accuracy."""

import numpy as np
import pytest
import torch

from uam_studio.battery import simulate
from uam_studio.dynaformer import WeightsError, load_predictor, load_with_fallback
from uam_studio.dynaformer.artifact import bundled_weights_path, save_artifact
from uam_studio.dynaformer.data import make_dataset
from uam_studio.dynaformer.model import Dynaformer, DynaformerConfig
from uam_studio.errors import InputError
from uam_studio.flight import leg_current

HAS_BUNDLED = bundled_weights_path().is_file()


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    torch.manual_seed(0)
    cfg = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32, latent_dim=4)
    pca = {"mean": torch.zeros(2), "components": torch.eye(2), "scale": torch.ones(2), "explained": torch.ones(2)}
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


def test_observed_context_is_returned_as_observed(tiny):
    """The first samples are the measured context, not a prediction; an EOD inside it is kept."""
    p, _ = tiny
    cur, ci, cv = _ctx()
    low = cv.copy()
    low[5:] = 2.9  # the observation already fell below the 3.0 V cut-off
    v = p.predict(ci, low, cur)
    np.testing.assert_array_equal(v[:20], low)
    assert p.predict_eod_s(ci, low, cur) == 6.0


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


@pytest.fixture(scope="module")
def held_out_metrics():
    from uam_studio.dynaformer import load_pretrained
    from uam_studio.dynaformer.evaluate import eod_metrics, predict_set

    ds = make_dataset(60, seed=987654, flight_fraction=1.0)
    return eod_metrics(ds, predict_set(load_pretrained(), ds))


@pytest.mark.skipif(not HAS_BUNDLED, reason="no bundled weights")
def test_bundled_model_times_eod_on_held_out_missions(held_out_metrics):
    """A small held-out check (the full evaluation is `uam-studio evaluate dynaformer`): the issue's
    median-RTE goal of 0.02 holds on these 60 flight missions (0.0035 on the 400-mission evaluation)."""
    assert held_out_metrics["median_rte"] <= 0.02
    assert held_out_metrics["eod_agreement"] >= 0.9


@pytest.mark.skipif(not HAS_BUNDLED, reason="no bundled weights")
def test_bundled_model_voltage_rmse_goal(held_out_metrics):
    """The issue's 20 mV voltage-RMSE goal on these 60 held-out flight missions (16.3 mV on the
    400-mission evaluation)."""
    assert held_out_metrics["rmse_mv"] <= 20.0


@pytest.mark.skipif(not HAS_BUNDLED, reason="no bundled weights")
def test_bundled_health_pcs_follow_r0_and_q_max_from_20_s():
    """Noise-free 20 s take-off contexts: PC1 follows R0 and PC2 q_max (the issue asks 0.95 and 0.9)."""
    from uam_studio.dynaformer import load_pretrained

    ds = make_dataset(300, seed=4242, max_len=64, flight_fraction=1.0)
    pcs = load_pretrained().health(ds.current_a[:, :20].astype(float), ds.voltage_v[:, :20].astype(float))
    assert abs(np.corrcoef(pcs[:, 0], ds.r0)[0, 1]) >= 0.95
    assert abs(np.corrcoef(pcs[:, 1], ds.q_max)[0, 1]) >= 0.9


def test_two_stage_training_freezes_the_encoder_and_writes_weights(tmp_path, monkeypatch):
    """Stage 1 fits the health head; stage 2 trains only the decoder; the export loads and predicts."""
    import uam_studio.dynaformer.train as train_mod

    snap = {}
    original = train_mod.pretrain_encoder

    def spy(model, *args):
        before = {k: v.clone() for k, v in model.state_dict().items()}
        mse = original(model, *args)
        snap.update(before=before, after={k: v.clone() for k, v in model.state_dict().items()}, mse=mse)
        return mse

    monkeypatch.setattr(train_mod, "pretrain_encoder", spy)
    cfg = train_mod.TrainConfig(n_train=64, n_context=256, context_batch=32, encoder_steps=30, steps=6, batch=8,
                                max_len=512, checkpoint_every=3, device="cpu", threads=1)
    tiny_cfg = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32, latent_dim=4,
                                health="transformer")
    weights = train_mod.train(cfg, tmp_path / "run", resume=False, model_cfg=tiny_cfg)
    pred = load_predictor(weights)
    final = pred.model.state_dict()
    moved = lambda k, a, b: not torch.equal(a[k], b[k])  # noqa: E731
    enc = [k for k in final if k.split(".")[0] in train_mod.ENCODER_PARTS]
    dec = [k for k in final if k not in enc]
    assert any(moved(k, snap["before"], snap["after"]) for k in enc)  # stage 1 trains the encoder
    assert not any(moved(k, snap["before"], snap["after"]) for k in dec)  # ... and only the encoder
    assert not any(moved(k, snap["after"], final) for k in enc)  # stage 2 leaves it frozen
    assert any(moved(k, snap["after"], final) for k in dec)
    cur, ci, cv = _ctx()
    v = pred.predict(ci, cv, cur)
    assert v.shape == cur.shape and np.all(np.isfinite(v))
    assert pred.meta["encoder_stage_health_mse"] == pytest.approx(snap["mse"])


def test_takeoff_training_fits_the_health_and_trains_only_the_decoder(tmp_path):
    """Default health estimator: the closed-form take-off fit recovers R0 and q_max on held-out
    noise-free flights; the decoder trains; the export loads, predicts and refuses a short context."""
    import uam_studio.dynaformer.train as train_mod
    from uam_studio.dynaformer.model import takeoff_to_health

    cfg = train_mod.TrainConfig(n_train=64, n_context=3000, steps=6, batch=8, max_len=512, checkpoint_every=3,
                                device="cpu", threads=1)
    tiny_cfg = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32)
    untrained = Dynaformer(tiny_cfg).state_dict()
    weights = train_mod.train(cfg, tmp_path / "run", resume=False, model_cfg=tiny_cfg)
    pred = load_predictor(weights)
    final = pred.model.state_dict()
    assert any(not torch.equal(untrained[k], final[k]) for k in final if k.startswith("latent_to_query"))
    ds = make_dataset(200, seed=31337, max_len=64, flight_fraction=1.0)
    with torch.no_grad():
        h = pred.model.encode(torch.as_tensor(ds.current_a[:, :20]), torch.as_tensor(ds.voltage_v[:, :20]))
    r0, q_max = (t.numpy() for t in takeoff_to_health(h.double()))
    assert np.corrcoef(r0, ds.r0)[0, 1] > 0.99
    assert np.median(np.abs(q_max - ds.q_max)) < 300.0  # C, from 3000 fitting cells
    cur, ci, cv = _ctx()
    assert np.all(np.isfinite(pred.predict(ci, cv, cur)))
    with pytest.raises(InputError) as err:
        pred.predict(ci[:10], cv[:10], cur)
    assert str(err.value).startswith("context_current_a") and "20 s" in str(err.value)


def test_format_2_weights_still_load_as_the_transformer_encoder(tmp_path):
    """Weights saved before the take-off estimator (format 2, no 'health' in the config) load as before."""

    cfg = DynaformerConfig(d_model=16, n_heads=2, enc_layers=1, dec_layers=1, ff_dim=32, latent_dim=4,
                           health="transformer")
    model = Dynaformer(cfg)
    config = cfg.to_dict()
    del config["health"], config["health_window"]
    pca = {"mean": torch.zeros(2), "components": torch.eye(2), "scale": torch.ones(2), "explained": torch.ones(2)}
    path = tmp_path / "old.pt"
    torch.save({"format": "uam_studio.dynaformer/2", "config": config, "state_dict": model.state_dict(),
                "pca": pca, "meta": {}}, path)
    pred = load_predictor(path)
    assert pred.model.cfg.health == "transformer"
    cur, ci, cv = _ctx()
    assert np.all(np.isfinite(pred.predict(ci[:5], cv[:5], cur)))  # the encoder takes any context length


def test_the_predictor_pickles_for_worker_processes_and_predicts_the_same():
    """Vector environments (SubprocVecEnv, GroupedSubprocVecEnv) pickle the env factories, the predictor in them."""
    import pickle

    from uam_studio.dynaformer import load_pretrained

    pred = load_pretrained()
    back = pickle.loads(pickle.dumps(pred))
    cur = np.full(600, 2.0)
    ctx_i, ctx_v = np.full(20, 2.9), np.linspace(4.1, 3.95, 20)
    np.testing.assert_array_equal(back.predict(ctx_i, ctx_v, cur), pred.predict(ctx_i, ctx_v, cur))

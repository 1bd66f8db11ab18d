"""The NASA aging law and a pack's capacity belief: on a synthetic life with a known law, and on the real
NASA lives (held out of the law's fit) where they sit beside the checkout."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.fleet.aging import AGING_LAW, AgingLaw, LifePoints
from uam_studio.fleet.nasa_aging import (
    NASA_AGING_LAW,
    CapacityBelief,
    RestRecovery,
    fit_nasa_law,
    fit_rest_recovery,
    forecast_score,
    law_floor_rms,
    nasa_leave_one_cell_out,
    nasa_life_points,
)

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nasa_pcoe"


def _life(name: str, law: AgingLaw, c0: float, n: int, seed: int, noise: float = 0.01) -> LifePoints:
    rng = np.random.default_rng(seed)
    efc = np.arange(n, dtype=float)
    cap = c0 * law.capacity_fraction(efc, 24.0) + rng.normal(0, noise, n)
    return LifePoints(name, efc, cap, np.arange(n), 24.0, efc[::10], 0.2 * (1 + 0.002 * efc[::10]))


@settings(max_examples=12, deadline=None)
@given(a=st.floats(0.002, 0.05), b=st.floats(0.3, 2.0), noise=st.floats(0.002, 0.03), n=st.integers(20, 200),
       seed=st.integers(0, 10_000))
def test_the_law_floor_is_the_scatter_and_no_law_of_the_form_beats_it(a, b, noise, n, seed):
    """A life of the law's form plus scatter: the floor leaves at least most of the scatter (two parameters
    fitted to the life itself), and the law it was drawn from, or the fleet's, scored on it as the
    leave-one-out table scores a law (from the life's noisy reference), is never below the floor."""
    scale = 0.5 / (a * (n - 1) ** b)  # at most half the capacity gone by the life's end
    truth = AgingLaw(a=a * min(scale, 1.0), b=b, ea_k=0.0, k_r=0.0)
    lf = _life("S", truth, 1.8, n, seed, noise)
    floor = law_floor_rms(lf)
    assert 0.6 * noise <= floor
    for law in (truth, NASA_AGING_LAW):
        err = np.median(lf.capacity_ah[:5]) * law.capacity_fraction(lf.efc, 24.0) - lf.capacity_ah
        assert floor <= np.sqrt(np.mean(err[1:] ** 2)) + 1e-9


def test_the_law_is_recovered_from_synthetic_lives_and_the_belief_band_covers():
    truth = AgingLaw(a=0.02, b=0.5, ea_k=0.0, k_r=0.002)
    lives = [_life(f"S{i}", truth, 1.8 + 0.05 * i, 150, i) for i in range(4)]
    law = fit_nasa_law(lives)
    assert law.capacity_fraction(100.0, 24.0) == pytest.approx(truth.capacity_fraction(100.0, 24.0), abs=0.01)
    assert law.k_r == pytest.approx(0.002, rel=0.05)
    scores = forecast_score(lives)
    assert all(s["rms_ah"] < 0.03 for s in scores), scores
    assert all(0.8 <= s["coverage90"] <= 1.0 for s in scores), scores


def test_a_belief_moves_towards_what_it_measures():
    b = CapacityBelief.start(NASA_AGING_LAW, 1.85, 24.0, 0.02)
    before, lo0, hi0 = (float(x[0]) for x in b.forecast(np.array([60.0])))
    for e in range(1, 60):
        b.observe(float(e), 1.85 * 0.9)  # a cell that holds 90% while the law fades it faster
    after, lo, hi = (float(x[0]) for x in b.forecast(np.array([60.0])))
    assert abs(after - 1.85 * 0.9) < 0.03 < abs(before - 1.85 * 0.9)
    assert lo < after < hi and hi - lo < 0.5 * (hi0 - lo0)


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_on_the_2a_lives_the_nasa_law_beats_the_vtc6_law_held_out():
    lives = nasa_life_points(DATA)
    rows = {r["cell"]: r for r in nasa_leave_one_cell_out(lives)}
    for cell in ("B0005", "B0007", "B0018"):
        assert rows[cell]["rms_ah"] < 0.7 * rows[cell]["vtc6_rms_ah"], rows[cell]
    assert AGING_LAW != NASA_AGING_LAW
    with_rests = forecast_score(lives, cells=["B0005"])[0]
    without = forecast_score(lives, cells=["B0005"], rests=False)[0]
    assert 0.85 <= without["coverage90"] <= 0.97 and without["rms_ah"] < 0.06, without
    # the rests before each discharge (the table's start_time) explain the recoveries: held out, the next-20
    # error falls by a third (0.048 -> 0.030 Ah) and the band still holds
    assert with_rests["rms_ah"] < 0.8 * without["rms_ah"] and with_rests["coverage90"] >= 0.85, with_rests
    life = next(lf for lf in lives if lf.cell == "B0005")
    assert life.rest_h is not None and np.isnan(life.rest_h[0]) and np.nanmax(life.rest_h) > 100.0


def _rested_life(name: str, law: AgingLaw, rec: RestRecovery, c0: float, seed: int) -> LifePoints:
    """150 discharges 4 h apart, a rest of 50-300 h before every 25th; capacity = the law's fade + what the
    rests give back + 5 mAh noise."""
    rng = np.random.default_rng(seed)
    n = 150
    rest = np.full(n, 4.0)
    rest[25::25] = rng.uniform(50.0, 300.0, rest[25::25].size)
    rest[0] = np.nan
    efc = np.arange(n, dtype=float)
    life = LifePoints(name, efc, np.zeros(n), np.arange(n), 24.0, efc[::10], 0.2 * (1 + 0.002 * efc[::10]), rest)
    cap = c0 * law.capacity_fraction(efc, 24.0) + rec.series(life, c0) + rng.normal(0, 0.005, n)
    return LifePoints(name, efc, cap, np.arange(n), 24.0, efc[::10], life.ir_ohm, rest)


def test_the_rests_recovery_is_recovered_and_sharpens_the_forecasts():
    truth, rec = AgingLaw(a=0.02, b=0.5, ea_k=0.0, k_r=0.002), RestRecovery(rho=0.85, beta=0.015)
    lives = [_rested_life(f"R{i}", truth, rec, 1.8 + 0.05 * i, 10 + i) for i in range(4)]
    fitted = fit_rest_recovery(truth, lives)
    assert fitted.rho == pytest.approx(0.85, abs=0.04) and fitted.beta == pytest.approx(0.015, rel=0.25), fitted
    assert fit_rest_recovery(truth, [_life("S", truth, 1.8, 50, 0)]) == RestRecovery()  # undated: nothing
    life = lives[0]

    def rms(recovery: RestRecovery) -> float:  # the next 20 forecast just after each rest, on the true law
        b = CapacityBelief.start(truth, 1.8, 24.0, 0.005, recovery=recovery)
        errs = []
        for k in range(1, life.efc.size - 1):
            if life.rest_h[k - 1] > 8.0:
                errs += list(b.forecast(life.efc[k:k + 20])[0] - life.capacity_ah[k:k + 20])
            b.observe(float(life.efc[k]), float(life.capacity_ah[k]), float(life.rest_h[k]))
        return float(np.sqrt(np.mean(np.square(errs))))

    assert rms(fitted) < 0.7 * rms(RestRecovery()), (rms(fitted), rms(RestRecovery()))


@settings(max_examples=40, deadline=None)
@given(rests=st.lists(st.one_of(st.floats(0.0, 2000.0), st.just(float("nan"))), min_size=1, max_size=30),
       caps=st.lists(st.floats(0.05, 3.0), min_size=30, max_size=30),
       rho=st.floats(0.0, 0.99), beta=st.floats(0.0, 0.1))
def test_a_belief_with_rests_stays_finite_and_ordered(rests, caps, rho, beta):
    b = CapacityBelief.start(NASA_AGING_LAW, 1.85, 24.0, 0.02, recovery=RestRecovery(rho, beta))
    for k, h in enumerate(rests):
        b.observe(float(k + 1), caps[k], h)
    mean, lo, hi = b.forecast(np.arange(len(rests) + 1, len(rests) + 21, dtype=float))
    assert np.all(np.isfinite(mean)) and np.all(lo < mean) and np.all(mean < hi)


@pytest.mark.skipif(not DATA.is_dir(), reason="the NASA PCoE lives are not beside the checkout")
def test_b0018s_next_20_error_is_above_0_03_ah_even_with_its_own_rests_and_noise():
    """The belief's form, given B0018's own rests and noise (in-sample, a reference), still forecasts its next
    20 capacities with an RMS error above 0.03 Ah: what its rests give back is not known ahead. The held-out
    score is no better than that reference by more than 0.002 Ah."""
    lives = nasa_life_points(DATA)
    held = forecast_score(lives, cells=["B0018"])[0]
    own = forecast_score(lives, cells=["B0018"], in_sample=True)[0]
    assert own["rms_ah"] > 0.03 and held["rms_ah"] > own["rms_ah"] - 0.002, (held, own)

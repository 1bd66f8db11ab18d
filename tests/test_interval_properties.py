"""Property-based tests of the health intervals (hypothesis): the physics fit's and the Dynaformer's 90%
end-of-discharge interval on flights of mixed legs, any context of at least 20 s, sensor noise 0-20 mV,
logs aligned with the take-off or starting at rest, any cell of the paper's health box.

Each planned flight draws more charge than any cell a fit can return holds (legs are added until then),
so every EOD time of the interval exists; it must be finite and ordered: lower <= median <= upper. Coverage is a
benchmark's question (``uam-studio evaluate dynaformer --table noise``), not this test's.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from uam_studio.battery import eod_interval_s, fit_health, simulate
from uam_studio.battery.health.estimate import FIT_Q_RANGE
from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE
from uam_studio.flight import leg_profile
from uam_studio.flight.profile import leg_feasible
from uam_studio.flight.tables import WIND_RANGE_KTS

SCALE = int(os.environ.get("UAM_PROPERTY_SCALE", "1"))
_SETTINGS = dict(deadline=None, derandomize=SCALE == 1, suppress_health_check=[HealthCheck.too_slow])
EMPTIES_ANY_CELL_C = 1.1 * FIT_Q_RANGE[1]  # C drawn by a flight: more than the largest q_max a fit returns


@st.composite
def flights(draw):
    """(current A [T], true voltage V [T], true EOD s, context length s, noise V, rest s before the take-off)."""
    q = draw(st.floats(*PAPER_Q_RANGE))
    r0 = draw(st.floats(PAPER_R0_RANGE[0], 0.3))  # above ~0.3 ohm the cell cannot finish a climb
    rest = draw(st.sampled_from((0, 0, 30, 120)))
    parts = [np.zeros(rest)]
    charge = 0.0
    while charge < EMPTIES_ANY_CELL_C:  # any cell the fit's box holds is empty before the flight ends
        alt = draw(st.sampled_from((500.0, 1000.0, 2000.0, 3000.0)))
        dist = draw(st.floats(5.0, 120.0))
        if not leg_feasible(dist, alt):
            alt = 500.0
            dist = max(dist, 7.0)
        prof = leg_profile(dist, alt, draw(st.floats(*WIND_RANGE_KTS)))
        parts.append(np.asarray(prof.current_a))
        charge += float(np.sum(prof.current_a))
    cur = np.concatenate(parts)
    sim = simulate(cur, 1.0, q, r0)
    if not sim.eod_reached or sim.eod_s < rest + 20:
        return None
    ctx = draw(st.integers(20, int(min(600, sim.eod_s - rest - 1)))) + rest
    noise = draw(st.sampled_from((0.0, 0.001, 0.005, 0.01, 0.02)))
    return cur, sim.voltage_v, float(sim.eod_s), ctx, noise


def _noisy(v: np.ndarray, noise: float, seed: int) -> np.ndarray:
    return v + np.random.default_rng(seed).normal(0.0, noise, v.shape) if noise else v


def _ordered_and_finite(lo: float, med: float, hi: float, what: str) -> None:
    assert all(math.isfinite(x) for x in (lo, med, hi)), (what, lo, med, hi)
    assert lo <= med <= hi, (what, lo, med, hi)


@settings(max_examples=30 * SCALE, **_SETTINGS)
@given(flights(), st.integers(0, 2**31 - 1))
def test_physics_fit_interval_is_finite_and_ordered(flight, seed):
    assume(flight is not None)
    cur, volt, _eod, ctx, noise = flight
    v = _noisy(volt[:ctx], noise, seed)
    est = fit_health(cur[:ctx], v, 1.0)
    assert all(math.isfinite(x) for x in (est.q_max, est.r0, est.noise_v))
    _ordered_and_finite(*eod_interval_s(est, cur, 1.0), "physics fit")


@pytest.fixture(scope="module")
def predictor():
    from uam_studio.dynaformer import load_pretrained

    return load_pretrained()


@settings(max_examples=20 * SCALE, **_SETTINGS)
@given(flight=flights(), seed=st.integers(0, 2**31 - 1))
def test_dynaformer_interval_is_finite_and_ordered(predictor, flight, seed):
    assume(flight is not None)
    cur, volt, _eod, ctx, noise = flight
    v = _noisy(volt[:ctx], noise, seed)
    _ordered_and_finite(*predictor.eod_interval_s(cur[:ctx], v, cur), "Dynaformer")


@settings(max_examples=20 * SCALE, **_SETTINGS)
@given(flight=flights(), seed=st.integers(0, 2**31 - 1), keep=st.floats(0.05, 1.0))
def test_a_profile_cut_short_gives_censored_bounds_never_inf(predictor, flight, seed, keep):
    """Any profile, cut anywhere after the context: every end is finite, at most the profile's length,
    and flagged censored exactly where it sits at that length because the cut-off was not reached."""
    assume(flight is not None)
    cur, volt, _eod, ctx, noise = flight
    n = max(ctx + 1, int(keep * cur.size))
    v = _noisy(volt[:ctx], noise, seed)
    est = fit_health(cur[:ctx], v, 1.0)
    for what, interval in (("physics fit", eod_interval_s(est, cur[:n], 1.0)),
                           ("Dynaformer", predictor.eod_interval_s(cur[:ctx], v, cur[:n], estimate=est))):
        _ordered_and_finite(*interval, what)
        assert interval.horizon_s == n and all(x <= n for x in interval), (what, interval)
        for x, c in zip(interval, interval.censored):
            assert not c or x == n, (what, interval)

"""The fleet prior of a health fit: what is known of a cell before it is measured, multiplied in once."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery import simulate
from uam_studio.battery.health.estimate import FIT_Q_RANGE, FIT_R0_RANGE
from uam_studio.battery.health.fit import fit_health, fit_health_batch
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, combine, fleet_prior
from uam_studio.battery.parameters import DEFAULT_CELL, PAPER_Q_RANGE, PAPER_R0_RANGE, VTC6_PARAMS
from uam_studio.errors import InputError
from uam_studio.flight import leg_profile

Q, R0 = 6200.0, 0.16  # C, ohm


@pytest.fixture(scope="module")
def flight():
    cur = np.concatenate([leg_profile(60.0, 1000.0, 0.0).current_a] * 2)
    return cur, simulate(cur, 1.0, Q, R0, eod_v=2.5).voltage_v


def test_fleet_prior_is_the_cell_types_box():
    nasa, vtc6 = fleet_prior(), fleet_prior(VTC6_PARAMS)
    assert fleet_prior(DEFAULT_CELL).q_max == nasa.q_max
    w_lo, w_hi = Q_REF_C / PAPER_Q_RANGE[1], Q_REF_C / PAPER_Q_RANGE[0]
    assert nasa.mean[0] == pytest.approx((w_lo + w_hi) / 2) and nasa.mean[1] == pytest.approx(sum(PAPER_R0_RANGE) / 2)
    assert np.sqrt(nasa.cov[0, 0]) == pytest.approx((w_hi - w_lo) / np.sqrt(12))
    lo, hi = VTC6_PARAMS.fleet_q_range
    assert lo < vtc6.q_max < hi and vtc6.q_max > PAPER_Q_RANGE[1]  # the VTC6 fleet is not the NASA cell's


@settings(max_examples=60, deadline=None)
@given(st.floats(0.2, 4.0), st.floats(0.0, 1.0), st.floats(1e-3, 1.0), st.floats(1e-4, 0.3),
       st.floats(0.2, 4.0), st.floats(0.0, 1.0), st.floats(1e-3, 1.0), st.floats(1e-4, 0.3))
def test_combine_lies_between_and_is_sharper(w1, r1, sw1, sr1, w2, r2, sw2, sr2):
    """Two independent Gaussians (diagonal): the product's mean lies between theirs, its variance below each."""
    mean, cov = combine([(np.array([w1, r1]), np.diag([sw1 ** 2, sr1 ** 2])),
                         (np.array([w2, r2]), np.diag([sw2 ** 2, sr2 ** 2]))])
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))
    for k, (a, b) in enumerate(((w1, w2), (r1, r2))):
        assert min(a, b) - 1e-9 <= mean[k] <= max(a, b) + 1e-9
    assert cov[0, 0] <= min(sw1, sw2) ** 2 * (1 + 1e-6) and cov[1, 1] <= min(sr1, sr2) ** 2 * (1 + 1e-6)


def test_default_fit_is_the_likelihood_times_the_fleet_prior(flight):
    cur, volt = flight
    rng = np.random.default_rng(3)
    ci, cv = cur[:20] + rng.normal(0, 0.04, 20), volt[:20] + rng.normal(0, 0.02, 20)  # 20 s at 20 mV
    post, lik = fit_health(ci, cv), fit_health(ci, cv, prior=False)
    same = lik.with_prior(fleet_prior())
    assert (post.q_max, post.r0) == pytest.approx((same.q_max, same.r0)) and np.allclose(post.cov_w, same.cov_w)
    prior = fleet_prior()
    # the prior decides where the context says little: the estimate moves towards the fleet's mean ...
    assert abs(post.w - prior.mean[0]) < abs(lik.w - prior.mean[0])
    assert post.cov_w[0, 0] < min(lik.cov_w[0, 0], prior.cov[0, 0])
    # ... and a batch of one agrees with the single fit; an explicit prior is used as given
    assert fit_health_batch(ci[None], cv[None])[0].q_max == pytest.approx(post.q_max)
    own = HealthPrior.from_ranges((9000.0, 9500.0), (0.1, 0.2))
    assert abs(fit_health(ci, cv, prior=own).q_max - 9250) < abs(post.q_max - 9250)


def test_prior_barely_moves_an_informative_context(flight):
    cur, volt = flight
    post, lik = fit_health(cur[:600], volt[:600]), fit_health(cur[:600], volt[:600], prior=False)
    assert abs(post.q_max - lik.q_max) < 1e-3 * Q and abs(post.r0 - lik.r0) < 1e-4
    assert abs(post.q_max - Q) < 5.0


def test_context_at_rest_returns_the_fleet_prior():
    """A log with no load holds no information on health: the estimate is the fleet's, inside the box."""
    est = fit_health(np.zeros(30), np.full(30, simulate(np.zeros(1), 1.0, Q, R0).voltage_v[0]), cell=VTC6_PARAMS)
    prior = fleet_prior(VTC6_PARAMS)
    assert est.q_max == pytest.approx(prior.q_max, rel=1e-3)
    assert FIT_Q_RANGE[0] <= est.q_max <= FIT_Q_RANGE[1] and FIT_R0_RANGE[0] <= est.r0 <= FIT_R0_RANGE[1]


def test_bad_prior_names_the_field(flight):
    cur, volt = flight
    with pytest.raises(InputError) as err:
        fit_health(cur[:30], volt[:30], prior="fleet")
    assert str(err.value).startswith("prior") and "\n" not in str(err.value)

"""The health fit's model-discrepancy terms and flags (uam_studio.battery.health.quality): unchanged where the
context is the model plus white noise, wider and flagged where it is not (issue 38)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2  # the reference for the library's chi-square quantile

from uam_studio.battery import simulate
from uam_studio.battery.health.belief import HealthBelief
from uam_studio.battery.health.config import PAPER_BELIEF
from uam_studio.battery.health.fit import fit_health
from uam_studio.battery.health.prior import combine, disagrees, fleet_prior, hold_to_fleet
from uam_studio.battery.health.quality import (
    FLAG_MISFIT,
    FLAG_OUTSIDE_FLEET,
    andrews_bandwidth,
    current_noise_a,
    describe_flags,
    excess_factor,
    hac_covariance,
    not_white,
    residual_autocorrelation,
)
from uam_studio.battery.parameters import DEFAULT_CELL
from uam_studio.flight import leg_profile
from uam_studio.glossary import GLOSSARY

CUR = np.concatenate([leg_profile(40.0, 600.0, 0.0).current_a] * 2)[:240]  # A: a take-off and cruise


def _flight(q: float, r0: float, n: int, cell=DEFAULT_CELL) -> np.ndarray:
    return simulate(CUR[:n], 1.0, q, r0, eod_v=2.5, cell=cell).voltage_v


@settings(max_examples=40, deadline=None)
@given(rho=st.floats(-0.9, 0.97), n=st.integers(200, 2000), seed=st.integers(0, 2 ** 32 - 1))
def test_autocorrelation_recovers_an_ar1_series(rho, n, seed):
    rng = np.random.default_rng(seed)
    e = rng.normal(size=n)
    x = np.empty(n)
    x[0] = e[0]
    for k in range(1, n):
        x[k] = rho * x[k - 1] + np.sqrt(1 - rho ** 2) * e[k]
    est = residual_autocorrelation(x[None])[0]
    assert abs(est - rho) < 5.0 / np.sqrt(n) + 0.02


def test_autocorrelation_skips_uncounted_samples_and_short_rows():
    x = np.r_[np.ones(10), -np.ones(10)] + np.arange(20) * 0.0
    mask = np.ones(20, bool)
    mask[5:15] = False  # the uncounted middle is skipped, not read as zeros
    assert residual_autocorrelation(x[None], mask[None])[0] == pytest.approx(
        residual_autocorrelation(np.r_[np.ones(5), -np.ones(5)][None])[0])
    assert residual_autocorrelation(np.ones((1, 2)))[0] == 0.0
    assert residual_autocorrelation(np.ones((1, 10)))[0] == 0.0  # no variance


@given(rho=st.floats(-1.0, 1.0), n=st.integers(1, 100000))
def test_white_noise_test_is_a_one_sided_test_of_rho(rho, n):
    assert bool(not_white(rho, n)) == (rho * np.sqrt(n) > 2.33)


@given(ratio=st.floats(0.01, 100.0), dof=st.integers(1, 5000), noise=st.floats(1e-4, 0.05))
def test_residuals_above_a_stated_noise_are_not_white(ratio, dof, noise):
    flagged = bool(not_white(0.0, dof, ratio * dof * noise ** 2, dof, noise))
    assert flagged == (ratio * dof * noise ** 2 / noise ** 2 > chi2.ppf(0.99, dof))  # a 1% chi-square test
    if ratio <= 1.0:
        assert not flagged
    if ratio >= 1.0 + 3.3 * np.sqrt(2.0 / dof) + 6.0 / dof:  # above the 99% quantile for any dof
        assert flagged


@given(rho=st.floats(-1.0, 1.0), n=st.integers(1, 100000))
def test_bandwidth_is_a_valid_lag_and_grows_with_rho(rho, n):
    lag = andrews_bandwidth(rho, n)
    assert 1 <= lag <= max(n - 1, 1)
    assert andrews_bandwidth(min(max(rho, 0.0) + 0.1, 0.99), n) >= lag


@pytest.mark.parametrize("rho, n, lag", [(0.5, 1000, 14), (0.3, 50, 4), (0.7, 2000, 29), (0.9, 300, 35),
                                         (0.0, 500, 1), (-0.4, 500, 1), (0.99, 10, 9), (0.999, 10, 9),
                                         (0.99, 2, 1)])
def test_bandwidth_is_andrews_ar1_plug_in(rho, n, lag):
    """Andrews (1991), Bartlett kernel: ceil(1.1447 (alpha n)^(1/3)), alpha = 4 rho^2 / ((1 - rho)^2
    (1 + rho)^2), at least 1 and at most n - 1 (the lags worked out by hand: rho 0.5, n 1000: alpha
    1.778, (1778)^(1/3) 12.11, x 1.1447 = 13.87 -> 14)."""
    assert andrews_bandwidth(rho, n) == lag


def _newey_west(jac: np.ndarray, r: np.ndarray, lags: int) -> np.ndarray:
    """Newey-West's covariance by its definition, one product at a time (the reference)."""
    n, p = jac.shape
    s = np.zeros((p, p))
    for t in range(n):
        s += r[t] ** 2 * np.outer(jac[t], jac[t])
        for k in range(1, min(lags, t) + 1):
            w = 1.0 - k / (lags + 1.0)
            s += w * r[t] * r[t - k] * (np.outer(jac[t], jac[t - k]) + np.outer(jac[t - k], jac[t]))
    a_inv = np.linalg.inv(jac.T @ jac)
    return a_inv @ s @ a_inv


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), n=st.integers(4, 40), rho=st.floats(0.0, 0.99))
def test_hac_covariance_is_newey_west_over_the_counted_samples(seed, n, rho):
    rng = np.random.default_rng(seed)
    jac = np.column_stack([np.ones(n), rng.normal(size=n)])
    r = rng.normal(size=n)
    mask = rng.random(n) < 0.8
    mask[:3] = True  # at least three counted samples for two parameters
    got = hac_covariance(jac, r, mask, rho)
    want = _newey_west(jac[mask], r[mask], andrews_bandwidth(rho, int(mask.sum())))
    assert got is not None and np.allclose(got, want, rtol=1e-9, atol=0.0)
    assert np.array_equal(got, got.T)


def test_hac_covariance_is_none_where_the_samples_do_not_determine_the_fit():
    jac = np.column_stack([np.ones(3), np.arange(3.0)])
    assert hac_covariance(jac[:2], np.ones(2), np.ones(2, bool), 0.5) is None  # 2 samples, 2 parameters
    assert hac_covariance(jac, np.ones(3), np.array([True, True, False]), 0.5) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused before any arithmetic: no overflow warning either
        assert hac_covariance(jac, np.array([1.0, np.inf, 1.0]), np.ones(3, bool), 0.5) is None
        assert hac_covariance(np.where(jac == 2.0, np.nan, jac), np.ones(3), np.ones(3, bool), 0.5) is None
    assert hac_covariance(jac, np.array([1.0, -1.0, 0.5]), np.ones(3, bool), 0.5) is not None


def test_excess_factor_is_scale_free_and_one_where_it_cannot_be_judged():
    """The largest ratio in any direction, the same at the scale of R0's variance (1e-8 ohm^2) as of
    q_max's (1e4 C^2); 1 where the other covariance is missing, smaller, or not a number."""
    for scale in (1e-20, 1e-8, 1.0, 1e4):
        ref = scale * np.diag([1.0, 4.0])
        assert excess_factor(ref, scale * np.diag([3.0, 4.0])) == pytest.approx(3.0, rel=1e-9)
    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    assert excess_factor(np.eye(2), rot @ np.diag([5.0, 0.1]) @ rot.T) == pytest.approx(5.0, rel=1e-9)
    assert excess_factor(np.eye(2), np.array([[np.nan, 0.0], [0.0, 1.0]])) == 1.0


def test_flags_are_described_one_sentence_each():
    both = describe_flags((FLAG_MISFIT, FLAG_OUTSIDE_FLEET))
    assert both == describe_flags((FLAG_MISFIT,)) + " " + describe_flags((FLAG_OUTSIDE_FLEET,))
    assert both.count(". ") == 1 and both.endswith(".") and describe_flags(()) == ""


def test_hac_covariance_holds_the_spread_of_a_fit_with_correlated_errors():
    """A straight-line fit with AR(1) errors (rho 0.8): the classical covariance is several times too
    small; the HAC one from each sample's own residuals is within a factor 2 of the Monte-Carlo spread."""
    rng = np.random.default_rng(1)
    n, rho = 300, 0.8
    x = np.column_stack([np.ones(n), np.linspace(-1, 1, n)])
    slopes, hac_var, classical_var = [], [], []
    for _ in range(200):
        e = np.empty(n)
        e[0] = rng.normal()
        for k in range(1, n):
            e[k] = rho * e[k - 1] + np.sqrt(1 - rho ** 2) * rng.normal()
        beta, *_ = np.linalg.lstsq(x, e, rcond=None)
        r = e - x @ beta
        slopes.append(beta[1])
        cov = hac_covariance(x, r, np.ones(n, bool), residual_autocorrelation(r[None])[0])
        hac_var.append(cov[1, 1])
        classical_var.append(np.var(r) * np.linalg.inv(x.T @ x)[1, 1])
    spread = np.var(slopes)
    assert np.median(classical_var) < spread / 3
    assert spread / 2 < np.median(hac_var) < 2 * spread
    assert excess_factor(np.median(classical_var) * np.eye(1), np.median(hac_var) * np.eye(1)) > 3
    assert excess_factor(np.eye(2), None) == 1.0 and excess_factor(np.eye(2), 0.5 * np.eye(2)) == 1.0


def test_current_noise_is_read_off_the_current():
    rng = np.random.default_rng(2)
    steps = np.repeat([2.0, 3.0, 1.0, 2.5], 100)
    assert current_noise_a(steps) == 0.0 and current_noise_a(np.ones(2)) == 0.0
    assert current_noise_a(steps + rng.normal(0, 0.02, steps.size)) == pytest.approx(0.02, rel=0.15)


@pytest.mark.parametrize("current_noise_a_", [0.005, 0.02])
def test_the_fit_holds_what_current_noise_does_to_it(current_noise_a_):
    """Current-sensor noise (the model's input) under 1 mV of voltage noise: over 24 draws the spread of
    q_max is within 0.7-1.5x of the std each fit reports (without the current-noise term it was half)."""
    volt = _flight(7700.0, 0.2, 60)
    rng = np.random.default_rng(5)
    qs, sds = [], []
    for _ in range(24):
        e = fit_health(CUR[:60] + rng.normal(0, current_noise_a_, 60), volt + rng.normal(0, 1e-3, 60), prior=False)
        qs.append(e.q_max)
        sds.append(e.std[0])
    assert 0.7 < np.median(sds) / np.std(qs) < 1.5


@pytest.mark.parametrize("noise_mv", [1.0, 5.0])
def test_model_plus_white_noise_is_rarely_flagged(noise_mv):
    """The fit's own model with white voltage noise at the stated level: the misfit tests are 1%
    tests; over 40 contexts they fire at most a few times."""
    rng = np.random.default_rng(7)
    volt = _flight(6500.0, 0.1, 120)
    flagged = 0
    for _ in range(40):
        e = fit_health(CUR[:120], volt + rng.normal(size=120) * noise_mv * 1e-3, noise_v=noise_mv * 1e-3)
        flagged += FLAG_MISFIT in e.flags
        assert FLAG_OUTSIDE_FLEET not in e.flags
    assert flagged <= 4


@settings(max_examples=15, deadline=None, derandomize=True)
@given(amp_mv=st.floats(8.0, 40.0), period_s=st.floats(60.0, 400.0), q=st.floats(5000.0, 8000.0),
       r0=st.floats(0.02, 0.4))
def test_a_context_the_model_does_not_explain_widens_and_is_flagged(amp_mv, period_s, q, r0):
    """A smooth voltage error the model has no term for (a slow wave of 8-40 mV on a 120 s context over the
    paper's whole health box): the fit is flagged, its covariance widened by the factor it reports,
    and its q_max std wider than the same context's without the wave."""
    volt = _flight(q, r0, 120)
    rng = np.random.default_rng(0)
    noise = rng.normal(size=120) * 1e-3
    wave = amp_mv * 1e-3 * np.sin(2 * np.pi * np.arange(120) / period_s)
    clean = fit_health(CUR[:120], volt + noise, noise_v=1e-3, prior=False)
    bent = fit_health(CUR[:120], volt + noise + wave, noise_v=1e-3, prior=False)
    assert FLAG_MISFIT in bent.flags and bent.discrepancy_factor > 1.0
    assert bent.std[1] > clean.std[1]


def test_a_cell_better_than_its_fleet_is_flagged_and_planned_as_the_fleets_best():
    """A cell with 7500 C where its fleet holds 3000-4000 C: the readings say so and are flagged; the default
    posterior (with the fleet prior) is no more optimistic than the fleet's best cell, and its std
    grows to hold the readings' value too."""
    cell = replace(DEFAULT_CELL, fleet_q_range=(3000.0, 4000.0))
    q_true = 7500.0
    rng = np.random.default_rng(3)
    volt = _flight(q_true, 0.1, 240, cell) + rng.normal(size=240) * 1e-3
    lik = fit_health(CUR, volt, noise_v=1e-3, cell=cell, prior=False)
    assert FLAG_OUTSIDE_FLEET in lik.flags and lik.q_max == pytest.approx(q_true, rel=0.05)
    post = fit_health(CUR, volt, noise_v=1e-3, cell=cell)
    plain = replace(lik, flags=()).with_prior(fleet_prior(cell))
    assert post.q_max <= 4000.0 + 1e-6 < plain.q_max
    assert post.std[0] > plain.std[0]
    assert abs(post.w - lik.w) <= np.sqrt(post.cov_w[0, 0]) * 1.01  # the readings' value within one std
    assert "outside" in describe_flags(post.flags) and "Flag: outside fleet range" in GLOSSARY


def test_a_cell_worse_than_its_fleet_is_flagged_and_believed():
    """4000 C where the fleet holds 7000-8000 C: flagged, and planned with the plain posterior (the
    readings' side is the cautious one)."""
    cell = replace(DEFAULT_CELL, fleet_q_range=(7000.0, 8000.0))
    rng = np.random.default_rng(3)
    volt = _flight(4000.0, 0.1, 240, cell) + rng.normal(size=240) * 1e-3
    lik = fit_health(CUR, volt, noise_v=1e-3, cell=cell, prior=False)
    post = fit_health(CUR, volt, noise_v=1e-3, cell=cell)
    plain = replace(lik, flags=()).with_prior(fleet_prior(cell))
    assert FLAG_OUTSIDE_FLEET in post.flags and post.q_max == pytest.approx(plain.q_max)


def test_operator_belief_holds_a_flagged_fit_with_caution():
    cell = replace(DEFAULT_CELL, fleet_q_range=(3000.0, 4000.0))
    rng = np.random.default_rng(4)
    volt = _flight(7500.0, 0.1, 240, cell) + rng.normal(size=240) * 1e-3
    belief = HealthBelief(1e-3, 3.0, config=replace(PAPER_BELIEF, params=cell))
    belief.observe(CUR, volt)
    health = belief.health()
    est = belief.fit()
    assert est.q_max > 7000.0  # the readings alone: a cell beyond its fleet
    assert health.q_max_c <= 4000.0 + 1e-6  # planned as the fleet's best cell
    trusting = np.linalg.inv(np.linalg.inv(fleet_prior(cell).cov) + np.linalg.inv(est.cov_w))
    assert health.inverse_capacity_sd > np.sqrt(trusting[0, 0])  # and wider than trusting the fit over the fleet


@given(lik=st.tuples(st.floats(0.2, 2.0), st.floats(0.0, 0.6)),
       sd=st.tuples(st.floats(1e-4, 0.2), st.floats(1e-4, 0.1)), corr=st.floats(-0.9, 0.9))
def test_hold_to_fleet_is_never_more_optimistic_than_the_fleets_best_and_holds_the_readings(lik, sd, corr):
    prior = fleet_prior(DEFAULT_CELL)
    cov = np.array([[sd[0] ** 2, corr * sd[0] * sd[1]], [corr * sd[0] * sd[1], sd[1] ** 2]])
    post_mean, post_cov = combine([(np.array(lik), cov), (prior.mean, prior.cov)])
    mean, held = hold_to_fleet(post_mean, post_cov, np.array(lik), cov, prior, 2.0)
    edge = prior.mean - np.sqrt(3.0) * np.sqrt(np.diag(prior.cov))
    beyond = edge - np.array(lik) > 2.0 * np.array(sd)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(held))
    for i in range(2):
        if beyond[i]:
            assert mean[i] >= edge[i] - 1e-12
            assert abs(mean[i] - lik[i]) <= np.sqrt(held[i, i]) + 1e-9
        else:
            assert mean[i] == post_mean[i] and held[i, i] == pytest.approx(post_cov[i, i])
    assert np.linalg.eigvalsh(held).min() >= -1e-12


@given(lik=st.tuples(st.floats(0.2, 2.0), st.floats(0.0, 0.6)),
       known=st.tuples(st.floats(0.2, 2.0), st.floats(0.0, 0.6)),
       sd=st.tuples(st.floats(1e-4, 0.2), st.floats(1e-4, 0.1)))
def test_a_logbook_that_holds_the_pack_beyond_its_fleet_moves_the_edge_out_to_it(lik, known, sd):
    """Readings held with a logbook's belief ``known``: never more optimistic than the more optimistic of the fleet's
    best cell and the logbook's; readings no more optimistic than the logbook are taken as they are."""
    prior = fleet_prior(DEFAULT_CELL)
    cov = np.diag(np.square(sd))
    post_mean, post_cov = combine([(np.array(lik), cov), (np.array(known), cov)])
    mean, held = hold_to_fleet(post_mean, post_cov, np.array(lik), cov, prior, 2.0, known=np.array(known))
    edge = np.minimum(prior.mean - np.sqrt(3.0) * np.sqrt(np.diag(prior.cov)), known)
    for i in range(2):
        if edge[i] - lik[i] > 2.0 * sd[i]:
            assert mean[i] >= edge[i] - 1e-12
        else:
            assert mean[i] == post_mean[i] and held[i, i] == pytest.approx(post_cov[i, i])
    # the logbook beyond the fleet's edge: readings that agree with it are not held back to the fleet's best
    far = prior.mean - 3.0 * np.sqrt(3.0) * np.sqrt(np.diag(prior.cov))
    tight = np.diag([1e-8, 1e-10])
    assert np.allclose(hold_to_fleet(far, tight, far, tight, prior, 2.0, known=far)[0], far)
    assert not np.allclose(hold_to_fleet(far, tight, far, tight, prior, 2.0)[0], far)


def test_disagrees_is_per_component():
    prior = fleet_prior(DEFAULT_CELL)
    inside = prior.mean
    assert not disagrees(inside, np.diag([1e-6, 1e-8]), prior, 2.0).any()
    far_w = inside + np.array([1.0, 0.0])
    assert disagrees(far_w, np.diag([1e-6, 1e-8]), prior, 2.0).tolist() == [True, False]
    assert not disagrees(far_w, np.diag([1.0, 1e-8]), prior, 2.0).any()  # within 2 std of its own


def test_the_operators_decisions_carry_the_fits_flags():
    from uam_studio.planning.operations.decision import Decision

    cell = replace(DEFAULT_CELL, fleet_q_range=(3000.0, 4000.0))
    volt = _flight(7500.0, 0.1, 240, cell) + np.random.default_rng(4).normal(size=240) * 1e-3
    belief = HealthBelief(1e-3, 3.0, config=replace(PAPER_BELIEF, params=cell))
    assert belief.flags() == ()
    belief.observe(CUR, volt + 0.02 * np.sin(np.arange(240) / 20.0))  # a wave the model has no term for
    belief.health()
    assert FLAG_MISFIT in belief.flags()
    d = Decision(time_s=0.0, node="vertiport", kind="plan", reason="", **belief.health().in_units(),
                 plan_q_max_c=1.0, plan_r0_ohm=0.1, wind_shift_kts=0.0, wind_shift_sd_kts=1.0, route=(),
                 altitudes_m=(), next_to=None, next_altitude_m=None, health_flags=belief.flags())
    assert d.to_dict()["health_flags"] == list(belief.flags())

"""Uncertainty: the reported standard deviations against the spread of Monte Carlo estimates.

FIGAROH-style: fit many noisy copies of one problem (paper 1 set-up: full pose, 42
parameters, 15 poses, Gaussian noise, fixed seeds) and compare the sample standard deviation
of each estimate with the reported one (a-priori covariance (J̃ᵀJ̃)⁻¹ for the weighted fit,
the sandwich for the unweighted fit).

The bands follow from the sampling distributions, for a family-wise probability of a false
failure below helpers.FALSE_FAILURE = 1e-6 with any seeds (Bonferroni over the 42
parameters): with 200 trials (s/σ)² ~ χ²₁₉₉/199, so s/σ ∈ [0.733, 1.290]; the mean's error
over its sample standard error is Student-t with 199 degrees of freedom (|t| < 5.82); the
mean of 200 reduced χ² with ν = 48 is χ²₉₆₀₀/9600 (in [0.931, 1.072]); jointly, the mean
squared Mahalanobis distance of the estimates under the reported covariance is χ²₈₄₀₀/8400
(helpers.assert_covariance_matches_monte_carlo). The seeds are fixed as well, so the suite is
reproducible.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import FALSE_FAILURE, assert_covariance_matches_monte_carlo, mc_mean_bound, mc_std_ratio_band
from scipy.stats import chi2 as chi2_dist

from pkmcal.identification.engine import identify
from pkmcal.identification.uncertainty import correlation, embed, parameter_uncertainty
from pkmcal.mechanisms import builtin_machine
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor

N_TRIALS = 200
HALF = np.array([25.0, 25.0, 12.0, *np.deg2rad([10.0, 10.0, 10.0])])


@pytest.fixture(scope="module")
def campaign():
    nominal = builtin_machine("stewart-prototype")
    real = builtin_machine("stewart-prototype-real")
    setup = MeasurementSetup(FullPoseSensor(), NoiseModel(
        reading_std=np.array([0.01] * 3 + [5e-5] * 3), actuator_std=np.full(6, 0.005)))
    rng = np.random.default_rng(11)
    cmd = nominal.home_pose + rng.uniform(-1.0, 1.0, (15, 6)) * HALF
    q = nominal.ik(cmd)
    x = real.fk(q, guess=cmd).poses
    y = setup.sensor.predict(real.frame(x))
    exact = identify(real, setup, q=q, y=y, method="ik-residual")
    estimates = {True: [], False: []}
    chi2 = []
    for k in range(N_TRIALS):
        e_y, e_q = setup.noise.sample(np.random.default_rng(1000 + k), y.shape, q.shape)
        for w in (True, False):
            # start from the real machine: same minimum, fewer iterations (keeps the test fast)
            res = identify(real, setup, q=q + e_q, y=y + e_y, method="ik-residual", weighted=w)
            estimates[w].append(res.estimate[:42])
            if w:
                chi2.append(res.uncertainty.reduced_chi2)
    return real, setup, q, y, exact, {w: np.array(v) for w, v in estimates.items()}, np.array(chi2)


def test_weighted_std_matches_monte_carlo(campaign):
    real, setup, q, y, exact, est, _ = campaign
    spread = est[True].std(axis=0, ddof=1)
    reported = exact.uncertainty.std_prior
    ratio = spread / reported
    lo, hi = mc_std_ratio_band(N_TRIALS, 42)
    assert np.all((lo < ratio) & (ratio < hi)), ratio
    # unbiased to within the Monte Carlo error of the mean
    bias = est[True].mean(axis=0) - real.params[:42]  # the 42 estimated (the gains held)
    assert np.all(np.abs(bias) < mc_mean_bound(N_TRIALS, 42) * spread / np.sqrt(N_TRIALS))
    # jointly: the whole reported covariance (correlations too) against the spread
    assert_covariance_matches_monte_carlo(est[True], real.params[:42], exact.uncertainty.covariance_prior)


def test_unweighted_sandwich_std_matches_monte_carlo(campaign):
    real, setup, q, y, _, est, _ = campaign
    exact_u = identify(real, setup, q=q, y=y, method="ik-residual", weighted=False)
    ratio = est[False].std(axis=0, ddof=1) / exact_u.uncertainty.std_prior
    lo, hi = mc_std_ratio_band(N_TRIALS, 42)
    assert np.all((lo < ratio) & (ratio < hi)), ratio
    assert_covariance_matches_monte_carlo(est[False], real.params[:42], exact_u.uncertainty.covariance_prior)


def test_reduced_chi2_is_one_on_average(campaign):
    *_, chi2 = campaign
    # reduced χ² with ν = 90 − 42 = 48 per trial: 200 ν·χ²_red ~ χ²₉₆₀₀ (sd of the mean 1.4 %)
    dof = 48 * N_TRIALS
    lo, hi = chi2_dist.ppf([FALSE_FAILURE / 2, 1.0 - FALSE_FAILURE / 2], dof) / dof
    assert lo < chi2.mean() < hi


def test_covariance_helpers():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(10, 2, 3))
    r = rng.normal(size=(10, 2))
    u = parameter_uncertainty(("a", "b", "c"), J, r, weighted=True)
    Jf = J.reshape(20, 3)
    np.testing.assert_allclose(u.covariance_prior, np.linalg.inv(Jf.T @ Jf), rtol=1e-10)
    assert u.dof == 17
    np.testing.assert_allclose(u.covariance_posterior, u.covariance_prior * np.sum(r**2) / 17)
    C = correlation(u.covariance_prior)
    np.testing.assert_allclose(np.diag(C), 1.0)
    assert np.all(np.abs(C) <= 1 + 1e-12)
    full = embed(u.covariance_prior, np.array([4, 0, 2]), 5)
    assert full.shape == (5, 5) and full[4, 4] == u.covariance_prior[0, 0] and np.all(full[1] == 0)
    # unweighted with identity noise: sandwich == (JᵀJ)⁻¹
    eye = np.broadcast_to(np.eye(2), (10, 2, 2))
    uu = parameter_uncertainty(("a", "b", "c"), J, r, weighted=False, cov_rows=eye, W=eye)
    np.testing.assert_allclose(uu.covariance_prior, u.covariance_prior, rtol=1e-10)


def test_calibrated_machine_file_round_trip(campaign, tmp_path):
    """The identified machine with its covariance survives save_machine/load_machine."""
    io = pytest.importorskip("pkmcal.io.machine_file")
    res = campaign[4]
    path = tmp_path / "calibrated.yaml"
    io.save_machine(res.mechanism, path)
    back = io.load_machine(str(path))
    np.testing.assert_allclose(back.covariance, res.mechanism.covariance, rtol=1e-12, atol=0)
    np.testing.assert_allclose(back.params, res.mechanism.params, rtol=0, atol=0)

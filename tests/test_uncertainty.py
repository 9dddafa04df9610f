"""Uncertainty: the reported standard deviations against the spread of Monte Carlo estimates.

FIGAROH-style: fit many noisy copies of one problem (paper 1 set-up: full pose, 42
parameters, 15 poses, Gaussian noise, fixed seed) and compare the sample standard deviation
of each estimate with the reported one (a-priori covariance (J̃ᵀJ̃)⁻¹ for the weighted fit,
the sandwich for the unweighted fit). With 200 trials the sample std has a relative
standard error of 1/√400 = 5 %, so 15 % is a 3σ band.
"""

from __future__ import annotations

import numpy as np
import pytest

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
    y = setup.sensor.predict(x)
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
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio
    # unbiased to within the Monte Carlo error of the mean
    bias = est[True].mean(axis=0) - real.params
    assert np.all(np.abs(bias) < 4 * reported / np.sqrt(N_TRIALS))


def test_unweighted_sandwich_std_matches_monte_carlo(campaign):
    real, setup, q, y, _, est, _ = campaign
    exact_u = identify(real, setup, q=q, y=y, method="ik-residual", weighted=False)
    ratio = est[False].std(axis=0, ddof=1) / exact_u.uncertainty.std_prior
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio


def test_reduced_chi2_is_one_on_average(campaign):
    *_, chi2 = campaign
    # mean of χ²_ν over 200 trials, ν = 90 − 42 = 48: sd of the mean √(2/48/200) ≈ 1.4 %
    assert abs(chi2.mean() - 1.0) < 0.06


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

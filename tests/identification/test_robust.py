"""Robust identification (pkmcal.identification.robust): screening, losses, rejection.

* The must-show case of issue 11: a 5 mm outlier among 100 full-pose measurements is flagged
  with its pose number, and ``reject`` restores the clean fit within its σ (while the plain
  fit with the outlier is many σ off: the check has teeth).
* A robust loss without outliers gives the least-squares answer: with f_scale → ∞ to
  O(z_max²/f²) σ (deterministic), and with the default f_scale within the Hausman band of
  an inefficient against an efficient estimator.
* soft_l1 bounds the outlier's influence: 5 mm and 50 mm outliers move it alike.
* The losses against scipy's own, and the 95 % efficiency constants against the textbook
  (Huber 1.345 in closed form, Cauchy 2.385).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_user_error, random_poses
from scipy.stats import norm

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.robust import DEFAULT_F_SCALE, LOSSES, efficiency, masked_loss, rho, screen
from pkmcal.mechanisms import builtin_machine
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor

NOISE_FULL = NoiseModel(reading_std=np.array([0.01] * 3 + [1e-4] * 3), actuator_std=np.full(6, 0.005))
BAD_POSE = 41   # 0-based: pose number 42
OUTLIER_MM = 5.0


@pytest.fixture(scope="module")
def data():
    nominal, real = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype-real")
    cmd = random_poses(nominal, 100, 3)
    q = nominal.ik(cmd)
    fk = real.fk(q, guess=cmd)
    assert fk.all_converged
    y = FullPoseSensor().predict(real.frame(fk.poses))
    e_y, e_q = NOISE_FULL.sample(np.random.default_rng(5), y.shape, q.shape)
    setup = MeasurementSetup(FullPoseSensor(), NOISE_FULL)
    clean = identify(nominal, setup, q=q + e_q, y=y + e_y)
    return nominal, setup, q + e_q, y + e_y, clean


def with_outlier(y, size=OUTLIER_MM):
    bad = y.copy()
    bad[BAD_POSE, 0] += size
    return bad


def test_outlier_flagged_and_rejected(data):
    nominal, setup, q, y, clean = data
    assert clean.screening is not None and not clean.screening.outliers   # clean data: nothing beyond 3 σ
    plain = identify(nominal, setup, q=q, y=with_outlier(y))
    out = plain.screening.outliers
    assert out[0].pose == BAD_POSE + 1 and out[0].sigma > 50 and not out[0].dropped
    assert any(w.startswith("warning:") and "pose 42 " in w for w in plain.warnings)
    assert np.max(np.abs(plain.x - clean.x) / clean.std) > 3      # the outlier spoils the plain fit
    rej = identify(nominal, setup, q=q, y=with_outlier(y), reject=3.0)
    assert [(o.pose, o.dropped, o.round) for o in rej.screening.outliers] == [(BAD_POSE + 1, True, 1)]
    assert rej.screening.rounds == 2 and BAD_POSE not in rej.used_poses and len(rej.used_poses) == 99
    assert not len(rej.dropped)              # rejected, not "dropped as unsolvable"
    assert np.max(np.abs(rej.x - clean.x) / clean.std) < 1.0      # the contract: within its σ
    # χ² over the poses kept, dof counted right
    u = rej.uncertainty
    assert u.dof == 99 * 6 - len(rej.free)
    assert u.chi2 == pytest.approx(np.sum(rej.residuals_weighted**2), rel=1e-12)
    d = rej.to_dict()
    assert d["outliers"] == [{"pose": 42, "sigma": out[0].sigma, "reading": out[0].reading,
                              "reading_sigma": out[0].reading_sigma, "dropped": True, "round": 1}] \
        or d["outliers"][0]["pose"] == 42 and d["outliers"][0]["dropped"] is True
    assert d["normalised_residuals"]["pose"] == [int(i) + 1 for i in rej.used_poses]


def test_robust_loss_without_outliers_is_least_squares(data):
    """f_scale = 1e3 σ: soft_l1 differs from the quadratic by a relative z²/(2f²) in each row's
    influence, so the estimates differ by at most ~max z²/f² of their σ."""
    nominal, setup, q, y, clean = data
    f = 1e3
    rob = identify(nominal, setup, q=q, y=y, loss="soft_l1", f_scale=f)
    zmax = np.max(np.abs(clean.residuals_weighted))
    assert np.max(np.abs(rob.x - clean.x) / clean.std) < 2 * zmax**2 / f**2 + 1e-6
    np.testing.assert_allclose(rob.std, clean.std, rtol=2 * zmax**2 / f**2 + 1e-6)
    assert rob.uncertainty.kind == "robust" and "soft_l1" in rob.uncertainty.description


@pytest.mark.parametrize("loss", ["soft_l1", "huber", "cauchy"])
def test_default_robust_fit_within_its_efficiency_band(data, loss):
    """At the default f_scale (95 % efficiency) the robust and the least-squares estimates
    differ by an amount of covariance C_robust − C_ls (an efficient estimator against an
    inefficient one, Hausman 1978): within 5.5 σ of it for every parameter (false failure
    < 42·4e-8 for these fixed data)."""
    nominal, setup, q, y, clean = data
    rob = identify(nominal, setup, q=q, y=y, loss=loss)
    a, b = efficiency(loss, DEFAULT_F_SCALE[loss])
    assert a * a / b == pytest.approx(0.95, abs=1e-3)
    # C_robust = (b/a²)·C_ls on the same poses, up to the Jacobian moving with the estimate
    np.testing.assert_allclose(rob.uncertainty.std_prior, clean.uncertainty.std_prior * np.sqrt(b) / a, rtol=0.01)
    band = np.sqrt(np.diag(rob.uncertainty.covariance_prior - clean.uncertainty.covariance_prior))
    assert np.all(np.abs(rob.x - clean.x) < 5.5 * band)


def test_soft_l1_bounds_the_outlier_influence(data):
    """fk-residual (the pose from the actuators, so the outlier's Jacobian rows do not move
    with it): soft_l1's influence ψ(z) → f saturates, a 5 mm and a 20 mm outlier move the
    estimate alike and by less than its σ; least squares moves with the outlier."""
    nominal, setup, q, y, _ = data
    clean = identify(nominal, setup, q=q, y=y, method="fk-residual")
    r5 = identify(nominal, setup, q=q, y=with_outlier(y, 5.0), loss="soft_l1", method="fk-residual")
    r20 = identify(nominal, setup, q=q, y=with_outlier(y, 20.0), loss="soft_l1", method="fk-residual")
    p5 = identify(nominal, setup, q=q, y=with_outlier(y, 5.0), method="fk-residual")
    shift5, shift20 = (r5.x - clean.x) / clean.std, (r20.x - clean.x) / clean.std
    assert np.max(np.abs(shift5)) < 1.0 and np.max(np.abs(shift20)) < 1.0      # bounded
    # nearly saturated: 4x the outlier moves the estimate by < 0.1 σ more (the whitening spreads
    # the outlier over the pose's rows, W = L⁻¹ lower triangular, and the rows it reaches with a
    # small coefficient are not yet in the loss's linear tail), where least squares moves 4x
    assert np.max(np.abs(shift20 - shift5)) < 0.1
    assert np.max(np.abs((p5.x - clean.x) / clean.std)) > 10 * np.max(np.abs(shift5))
    assert [o.pose for o in r5.screening.flagged] == [BAD_POSE + 1]
    # the covariance is that of the inliers: the flagged pose carries no information
    assert r5.uncertainty.dof == 99 * 6 - len(r5.free)


def test_losses_are_scipys():
    """rho() and masked_loss() against scipy's string losses on a small nonlinear problem, and
    ρ', ρ'' against central differences of ρ."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(0)
    t = np.linspace(0, 3, 40)
    obs = 2.0 * np.exp(-0.7 * t) + 0.01 * rng.standard_normal(40)
    obs[7] += 1.0
    fun = lambda p: p[0] * np.exp(-p[1] * t) - obs  # noqa: E731
    for loss in LOSSES[1:]:
        ref = least_squares(fun, [1.0, 1.0], loss=loss, f_scale=0.05, xtol=1e-14, ftol=1e-14, gtol=1e-14)
        ours = least_squares(fun, [1.0, 1.0], loss=masked_loss(loss, 40), f_scale=0.05, xtol=1e-14, ftol=1e-14,
                             gtol=1e-14)
        # the cost is flat to rounding at its minimum: x is determined to about sqrt(eps)
        np.testing.assert_allclose(ours.x, ref.x, rtol=1e-7)
        u = np.array([0.3, 0.9, 1.5, 4.0, 30.0])
        h = 1e-6 * u
        r0, rp, rm = rho(loss, u), rho(loss, u + h), rho(loss, u - h)
        np.testing.assert_allclose((rp[0] - rm[0]) / (2 * h), r0[1], rtol=1e-8)
        np.testing.assert_allclose((rp[1] - rm[1]) / (2 * h), r0[2], rtol=1e-6)


def test_efficiency_against_the_textbook():
    """Huber: E[ψ'] = 2Φ(c) − 1, E[ψ²] = 2Φ(c) − 1 − 2cφ(c) + 2c²(1 − Φ(c)); c = 1.345 gives
    95 %. Cauchy c = 2.385 gives 95 % (the published constant, 4 digits)."""
    c = 1.345
    a, b = efficiency("huber", c)
    assert a == pytest.approx(2 * norm.cdf(c) - 1, rel=1e-10)
    assert b == pytest.approx(2 * norm.cdf(c) - 1 - 2 * c * norm.pdf(c) + 2 * c * c * norm.sf(c), rel=1e-10)
    assert a * a / b == pytest.approx(0.95, abs=5e-5)
    a, b = efficiency("cauchy", 2.385)
    assert a * a / b == pytest.approx(0.95, abs=5e-5)
    for loss, f in DEFAULT_F_SCALE.items():
        a, b = efficiency(loss, f)
        assert a * a / b == pytest.approx(0.95, abs=5e-4), loss
    assert efficiency("soft_l1", 1e4)[0] == pytest.approx(1.0, abs=1e-7)


def test_screen_numbers_and_threshold():
    z = np.array([[0.5, -0.5], [3.0, 4.0], [0.1, 0.0]])
    sc = screen(z, np.array([0, 4, 7]), ("u", "v"), 3.0)
    np.testing.assert_allclose(sc.sigma, [0.5, np.sqrt(12.5), np.sqrt(0.005)])
    assert [o.pose for o in sc.outliers] == [5] and sc.outliers[0].reading == "v"
    assert sc.outliers[0].reading_sigma == 4.0 and sc.inliers.tolist() == [True, False, True]


def test_errors(data):
    nominal, setup, q, y, clean = data
    with pytest.raises(PkmcalError, match="noise-weighted"):
        identify(nominal, setup, q=q, y=y, loss="huber", weighted=False)
    with pytest.raises(PkmcalError, match="unknown loss"):
        identify(nominal, setup, q=q, y=y, loss="l1")
    with pytest.raises(PkmcalError, match="solver 'lm'"):
        identify(nominal, setup, q=q, y=y, loss="huber", solver="lm")
    with pytest.raises(PkmcalError, match="noise model that is too optimistic"):
        tight = MeasurementSetup(FullPoseSensor(), NoiseModel(NOISE_FULL.reading_std / 30, NOISE_FULL.actuator_std / 30))
        identify(nominal, tight, q=q, y=y, reject=3.0)


def test_cli_outliers_json_and_report(tmp_path, data):
    """The pose number in the JSON is the data row of the file; --reject drops it in round 1;
    the warning names the file and line; the report has the Outliers section."""
    from pkmcal.io.tables import write_table

    nominal, setup, q, y, clean = data
    bad = with_outlier(y)
    cols = {**{f"lambda{i + 1}": q[:, i] for i in range(6)},
            **{k: (np.rad2deg(bad[:, i]) if i >= 3 else bad[:, i]) for i, k in enumerate("xyzabc")}}
    write_table(tmp_path / "meas.csv", cols)
    (tmp_path / "setup.yaml").write_text("sensor: full-pose\nnoise: {position: 0.01, orientation_deg: "
                                         f"{float(np.rad2deg(1e-4))!r}, actuator: 0.005}}\n")
    run = CliRunner().invoke
    base = ["identify", "stewart-prototype", str(tmp_path / "meas.csv"), "--setup", str(tmp_path / "setup.yaml")]
    # least squares with the outlier kept: refused (issue 24), the outlier named first with the remedy
    res = run(cli, base + ["-o", str(tmp_path / "a.yaml")])
    assert res.exit_code == 2 and "pose(s) (42," in res.stderr and "--reject" in res.stderr, res.output
    res = run(cli, base + ["-o", str(tmp_path / "a.yaml"), "--accept-bad-fit"])
    assert res.exit_code == 0, res.output
    # the outlier first (it also drags the fit, so that others follow it beyond 3 σ), with its line:
    # data row 42 under the header line
    assert "pose(s) beyond 3 sigma" in res.output and "whitened with the noise model): pose 42 (" in res.output
    assert "meas.csv, line 43]" in res.output
    res = run(cli, base + ["-o", str(tmp_path / "b.yaml"), "--reject", "3", "--loss", "soft_l1", "--json",
                           "--report", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert [(o["pose"], o["dropped"], o["round"]) for o in d["outliers"]] == [(42, True, 1)]
    assert d["loss"] == "soft_l1" and d["covariance_kind"] == "robust" and d["n_poses"] == 99
    assert d["normalised_residuals"]["reject_sigma"] == 3.0 and 42 not in d["normalised_residuals"]["pose"]
    assert "outliers" in d["units"]
    html = (tmp_path / "rep" / "report.html").read_text()
    assert 'id="outliers"' in html and "dropped" in html
    assert "rejected_poses:\n  - 42\n" in (tmp_path / "b.yaml").read_text()
    bad_cmd = run(cli, base + ["-o", str(tmp_path / "c.yaml"), "--loss", "huber", "--unweighted"])
    assert_user_error(bad_cmd, "noise-weighted", "--unweighted")


def test_outliers_keep_their_file_numbers_when_clipped_poses_are_left_out(tmp_path, data):
    """A clipped reading drops pose 5 before the fit (identify --clipped drop); the outlier
    is still reported as data row 42, and --reject drops that row, not its neighbour."""
    from pkmcal.io.tables import write_table

    nominal, setup, q, y, clean = data
    bad = with_outlier(y)
    q = q.copy()
    q[4, 0] = nominal.stroke[0, 1]          # pose 5's leg 1 at its stroke end: clipped
    cols = {**{f"lambda{i + 1}": q[:, i] for i in range(6)},
            **{k: (np.rad2deg(bad[:, i]) if i >= 3 else bad[:, i]) for i, k in enumerate("xyzabc")}}
    write_table(tmp_path / "meas.csv", cols)
    (tmp_path / "setup.yaml").write_text("sensor: full-pose\nnoise: {position: 0.01, orientation_deg: "
                                         f"{float(np.rad2deg(1e-4))!r}, actuator: 0.005}}\n")
    res = CliRunner().invoke(cli, ["identify", "stewart-prototype", str(tmp_path / "meas.csv"), "--setup",
                                   str(tmp_path / "setup.yaml"), "-o", str(tmp_path / "c.yaml"), "--reject", "3",
                                   "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.output[res.output.index("{"):])
    assert [o["pose"] for o in d["outliers"] if o["dropped"]] == [42]
    assert 5 not in d["normalised_residuals"]["pose"] and 42 not in d["normalised_residuals"]["pose"]
    assert len(d["normalised_residuals"]["pose"]) == 98

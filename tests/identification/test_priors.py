"""Gaussian priors (maximum a posteriori, pkmcal.identification.priors).

* The linear Gaussian case against its closed form: with a full-pose (identity) sensor and
  only the leg offsets free, the ik-residual r_j = q_j − (L(x̂_j) − L0) is linear in L0 with
  Jacobian I and a covariance Σ_j = σ_q² I + A_j Σ_y A_jᵀ (A_j = ∂λ/∂x at x̂_j) that does not
  depend on L0, so the MAP estimate is L0̂ = (Σ_j Σ_j⁻¹ + P)⁻¹ (Σ_j Σ_j⁻¹ d_j + P μ),
  d_j = L(x̂_j) − q_j, and the posterior covariance is (Σ_j Σ_j⁻¹ + P)⁻¹, computed here from
  the machine's leg lengths and its analytic pose Jacobian (tested against finite
  differences in tests/mechanisms/test_hexapod.py), independently of the engine's residuals.
* Noise-free data with priors at the true values: the truth is the exact minimiser.
* A prior on a gauge parameter pins the direction the data cannot see: the automatic gauge
  does not fix it, and its estimate and posterior σ are exactly the prior's.
* Parsing, setup files, errors, CLI and JSON.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_user_error, random_poses

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import TOLERANCE, identify
from pkmcal.identification.priors import Prior, parse_prior
from pkmcal.mechanisms import builtin_machine
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor
from pkmcal.sensors.indicators import IndicatorSensor

NOISE_FULL = NoiseModel(reading_std=np.array([0.01] * 3 + [1e-4] * 3), actuator_std=np.full(6, 0.005))
NOISE_3 = NoiseModel(reading_std=np.full(3, 0.01), actuator_std=np.full(6, 0.005))
INDICATOR_XY = np.array([[40.0, 0.0], [-20.0, 34.64], [-20.0, -34.64]])


@pytest.fixture(scope="module")
def nominal():
    return builtin_machine("stewart-prototype")


@pytest.fixture(scope="module")
def real():
    return builtin_machine("stewart-prototype-real")


def measure(nominal, real, sensor, n, noise=None, seed=1):
    cmd = random_poses(nominal, n, seed)
    q = nominal.ik(cmd)
    fk = real.fk(q, guess=cmd)
    assert fk.all_converged
    y = sensor.predict(real.frame(fk.poses))
    if noise is not None:
        e_y, e_q = noise.sample(np.random.default_rng(seed + 1), y.shape, q.shape)
        y, q = y + e_y, q + e_q
    return q, y


def test_parse_prior_forms():
    assert parse_prior("L0_*=640±0.5") == Prior("L0_*", 640.0, 0.5, "--prior 'L0_*=640±0.5'")
    assert parse_prior("L0_1 = 640 +- 0.5").mean == 640.0 and parse_prior("L0_1=640+/-5e-1").std == 0.5
    p = parse_prior("b1.z=±0.2")
    assert p.mean is None and p.std == 0.2
    for bad in ("L0_1", "L0_1=640", "=1±2", "L0_1=a±1", "L0_1=1±0", "L0_1=1±-2"):
        with pytest.raises(PkmcalError):
            parse_prior(bad)


def test_linear_gaussian_closed_form(nominal, real):
    """MAP estimate and posterior covariance of the L0-only ik-residual fit = the closed form."""
    setup = MeasurementSetup(FullPoseSensor(), NOISE_FULL)
    q, y = measure(nominal, real, FullPoseSensor(), 30, NOISE_FULL)
    mu = np.array([306.0, 304.0, 305.5])          # priors on legs 1, 2, 4; mm
    sd = np.array([0.002, 0.01, 0.5])
    priors = [f"L0_1={mu[0]}±{sd[0]}", f"L0_2={mu[1]}+-{sd[1]}", f"L0_4={mu[2]}±{sd[2]}"]
    res = identify(nominal, setup, q=q, y=y, method="ik-residual", free=["L0_*"], priors=priors)
    assert res.uncertainty.kind == "map"
    # closed form
    d = nominal.leg_lengths(y) - q                               # = L0 + noise, (N, 6)
    A = nominal.actuator_pose_jacobian(y)                        # ∂λ/∂x at the measured poses
    S = np.diag(NOISE_FULL.actuator_std**2) + A @ np.diag(NOISE_FULL.reading_std**2) @ np.swapaxes(A, 1, 2)
    Si = np.linalg.inv(S)
    P = np.zeros((6, 6))
    pm = np.zeros(6)
    for k, leg in enumerate((0, 1, 3)):
        P[leg, leg] = 1.0 / sd[k] ** 2
        pm[leg] = mu[k] / sd[k] ** 2
    H = Si.sum(axis=0) + P
    cov = np.linalg.inv(H)
    est = cov @ (np.einsum("nij,nj->i", Si, d) + pm)
    got = res.estimate[[res.names.index(f"L0_{i}") for i in range(1, 7)]]
    # the solver stops at a relative step of xtol: 10·xtol·|θ| bounds what is left
    assert np.max(np.abs(got - est)) < 10 * TOLERANCE * np.max(np.abs(est))
    # the priors moved the estimate by far more than that: the check has teeth
    plain = identify(nominal, setup, q=q, y=y, method="ik-residual", free=["L0_*"])
    assert np.abs(plain.x[0] - got[0]) > 1e3 * 10 * TOLERANCE * 306
    np.testing.assert_allclose(res.uncertainty.covariance_prior, cov, rtol=1e-9, atol=1e-9 * np.max(np.abs(cov)))
    # chi2 counts the prior rows; dof = M + K - p
    r_prior = (got[[0, 1, 3]] - mu) / sd
    assert res.uncertainty.dof == 30 * 6 + 3 - 6
    assert res.uncertainty.chi2 == pytest.approx(np.sum(res.residuals_weighted**2) + np.sum(r_prior**2), rel=1e-9)
    # the JSON names the priors, the estimate and the posterior std in file units
    d = res.to_dict()
    assert d["covariance_kind"] == "map" and "posterior" in d["covariance_in_file"]
    first = d["priors"][0]
    assert first["parameter"] == "L0_1" and first["mean"] == mu[0] and first["std"] == sd[0]
    assert first["posterior_std"] == pytest.approx(np.sqrt(cov[0, 0] * res.uncertainty.inflation), rel=1e-9)


def test_noise_free_priors_at_the_truth(nominal, real):
    """Noise-free data, priors at the true values: the truth is the exact minimiser."""
    setup = MeasurementSetup(FullPoseSensor(), NOISE_FULL)
    q, y = measure(nominal, real, FullPoseSensor(), 20)
    names = real.param_names
    truth = np.asarray(real.params)
    priors = [f"{n}={float(truth[i])!r}±0.3" for i, n in enumerate(names) if n.startswith(("L0_", "b3."))]
    res = identify(nominal, setup, q=q, y=y, method="ik-residual", priors=priors)
    assert len(res.priors) == 9 and not res.gauge
    assert np.max(np.abs(res.estimate[:len(names)] - truth)) < 10 * TOLERANCE * np.max(np.abs(truth))


def test_prior_pins_a_gauge_direction(nominal, real):
    """Indicators leave 3 directions unseen; the gauge fixes a1.x, a1.y, a2.x. A prior on a1.x
    keeps it free: a1.x is then estimated as its prior mean with the prior's σ, exactly (the
    data see nothing along its direction), and the gauge fixes the other two only."""
    sensor = IndicatorSensor(positions=INDICATOR_XY, plane_offset=10.0)
    setup = MeasurementSetup(sensor, NOISE_3)
    q, y = measure(nominal, real, sensor, 40, NOISE_3)
    base = identify(nominal, setup, q=q, y=y)
    assert "a1.x" in base.gauge
    res = identify(nominal, setup, q=q, y=y, priors=["a1.x=-60.5±0.1"])
    assert "a1.x" not in res.gauge and len(res.gauge) == len(base.gauge) - 1
    k = res.free.index("a1.x")
    assert res.x[k] == pytest.approx(-60.5, abs=1e-9)
    assert np.sqrt(res.uncertainty.covariance_prior[k, k]) == pytest.approx(0.1, rel=1e-6)
    assert res.identifiability.rank == base.identifiability.rank + 1


def test_prior_errors(nominal, real):
    setup = MeasurementSetup(FullPoseSensor(), NOISE_FULL)
    q, y = measure(nominal, real, FullPoseSensor(), 12, NOISE_FULL)
    with pytest.raises(PkmcalError, match="no parameter has this name.*did you mean L0_"):
        identify(nominal, setup, q=q, y=y, priors=["L0_l=305±1"])
    with pytest.raises(PkmcalError, match="b1.x is held fixed"):
        identify(nominal, setup, q=q, y=y, fix=["b1.x"], priors=["b1.x=±1"])
    with pytest.raises(PkmcalError, match="world.x is held fixed"):
        identify(nominal, setup, q=q, y=y, priors=["world.x=±1"])
    with pytest.raises(PkmcalError, match="lengths .mm. and angles"):
        free_world = FullPoseSensor(free=("world.x", "world.y", "world.z", "world.a", "world.b", "world.c"))
        identify(nominal, MeasurementSetup(free_world, NOISE_FULL), q=q, y=y, priors=["world.*=±1"])
    with pytest.raises(PkmcalError, match="two priors"):
        identify(nominal, setup, q=q, y=y, priors=["L0_*=±1", "L0_1=±2"])
    with pytest.raises(PkmcalError, match="noise-weighted"):
        identify(nominal, setup, q=q, y=y, priors=["L0_1=±1"], weighted=False)


def test_angle_prior_in_degrees(nominal, real):
    """world.c=0±0.05 is degrees in files and on the command line: σ = 0.05° in radians inside."""
    sensor = FullPoseSensor(free=("world.x", "world.y", "world.z", "world.a", "world.b", "world.c"))
    setup = MeasurementSetup(sensor, NOISE_FULL)
    q, y = measure(nominal, real, FullPoseSensor(), 15, NOISE_FULL)
    res = identify(nominal, setup, q=q, y=y, priors=["world.c=0.01±0.05"])
    pr = res.priors
    assert pr.names == ("world.c",) and pr.std[0] == pytest.approx(np.deg2rad(0.05), rel=1e-15)
    assert pr.mean[0] == pytest.approx(np.deg2rad(0.01), rel=1e-15)
    e = res.to_dict()["priors"][0]
    assert e["unit"] == "deg" and e["std"] == pytest.approx(0.05, rel=1e-12)


SETUP_WITH_PRIOR = """\
sensor: indicators
indicators: [[40, 0], [-20, 34.64], [-20, -34.64]]
plane_offset: 10.0
noise: {reading: 0.01, actuator: 0.005}
prior:
  a1.x: [-60.622, 0.1]
  L0_*: "± 2"
"""


def test_setup_file_priors_cli_and_json(tmp_path, nominal, real):
    """The setup's prior: and --prior together (the command line replaces the setup's prior of
    the same parameter), in the text summary, the JSON and the report; errors name the file
    and line."""
    from pkmcal.io.setup_file import load_setup, setup_to_yaml
    from pkmcal.io.tables import write_table

    (tmp_path / "setup.yaml").write_text(SETUP_WITH_PRIOR)
    setup = load_setup(tmp_path / "setup.yaml")
    assert [(p.pattern, p.mean, p.std) for p in setup.priors] == [("a1.x", -60.622, 0.1), ("L0_*", None, 2.0)]
    assert "line 6" in setup.priors[0].source
    (tmp_path / "again.yaml").write_text(setup_to_yaml(setup))
    assert [(p.pattern, p.mean, p.std) for p in load_setup(tmp_path / "again.yaml").priors] == \
        [(p.pattern, p.mean, p.std) for p in setup.priors]
    q, y = measure(nominal, real, setup.sensor, 40, setup.noise)
    write_table(tmp_path / "meas.csv", {**{f"lambda{i + 1}": q[:, i] for i in range(6)},
                                         **{f"d{k + 1}": y[:, k] for k in range(3)}})
    run = CliRunner().invoke
    res = run(cli, ["identify", "stewart-prototype", str(tmp_path / "meas.csv"), "--setup", str(tmp_path / "setup.yaml"),
                    "-o", str(tmp_path / "cal.yaml"), "--prior", "L0_1=305+-0.5", "--json",
                    "--report", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    by = {e["parameter"]: e for e in d["priors"]}
    assert set(by) == {"a1.x", "L0_1", "L0_2", "L0_3", "L0_4", "L0_5", "L0_6"}
    assert by["L0_1"]["std"] == 0.5 and by["L0_1"]["source"].startswith("--prior")
    assert by["L0_2"]["std"] == 2.0 and "setup.yaml, line 7" in by["L0_2"]["source"]
    assert "a1.x" not in d["gauge"] and d["covariance_kind"] == "map"
    html = (tmp_path / "rep" / "report.html").read_text()
    assert 'id="priors"' in html and "posterior σ" in html
    text = run(cli, ["identify", "stewart-prototype", str(tmp_path / "meas.csv"), "--setup",
                     str(tmp_path / "setup.yaml"), "-o", str(tmp_path / "cal2.yaml")])
    assert text.exit_code == 0 and "priors (maximum a posteriori" in text.output
    assert "L0_3: prior 305 ± 2 mm" in text.output
    bad = run(cli, ["identify", "stewart-prototype", str(tmp_path / "meas.csv"), "--setup",
                    str(tmp_path / "setup.yaml"), "-o", str(tmp_path / "cal3.yaml"), "--prior", "L9=1±1"])
    assert_user_error(bad, "prior 'L9'", "no parameter has this name")
    assert not (tmp_path / "cal3.yaml").exists()
    (tmp_path / "bad.yaml").write_text(SETUP_WITH_PRIOR.replace('"± 2"', '"2 pm 1"'))
    bad = run(cli, ["identify", "stewart-prototype", str(tmp_path / "meas.csv"), "--setup",
                    str(tmp_path / "bad.yaml"), "-o", str(tmp_path / "cal3.yaml")])
    assert_user_error(bad, "bad.yaml, line 7", "prior.L0_*", "MEAN±STD")

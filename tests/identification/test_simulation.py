"""Campaign simulation: exact readings without noise, noise statistics, seeded
reproducibility, dropped unreachable poses, random real machines."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import perturb_machine, simulate_campaign
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real
from pkmcal.sensors import FullPoseSensor, IndicatorSensor, MeasurementSetup, NoiseModel, PositionSensor

NOMINAL = stewart_prototype()
REAL = stewart_prototype_real()


def _poses(n, seed=0, span=15.0, ang=0.08):
    rng = np.random.default_rng(seed)
    p = np.tile(NOMINAL.home, (n, 1))
    p[:, :3] += rng.uniform(-span, span, (n, 3))
    p[:, 3:] += rng.uniform(-ang, ang, (n, 3))
    return p


def _quiet(sensor):
    return MeasurementSetup(sensor, NoiseModel(np.zeros(sensor.n_readings), np.zeros(6)))


SENSORS = [
    FullPoseSensor(tool=[1.0, 2.0, 30.0, 0.01, -0.02, 0.03]),
    PositionSensor(target=[10.0, -5.0, 20.0]),
    IndicatorSensor(positions=[[40, 0], [-20, 34.641], [-20, -34.641]], plane_offset=10.0),
]


@pytest.mark.parametrize("sensor", SENSORS, ids=lambda s: s.kind)
def test_real_equal_nominal_without_noise_reads_the_prediction(sensor):
    poses = _poses(40)
    res = simulate_campaign(NOMINAL, NOMINAL, _quiet(sensor), poses, rng=1)
    assert len(res.kept) == 40 and res.dropped == {}
    np.testing.assert_allclose(res.real_poses, poses, atol=1e-8)
    np.testing.assert_allclose(res.sensor_readings, sensor.predict(NOMINAL.frame(poses)), atol=1e-8)
    np.testing.assert_allclose(res.actuator_readings, NOMINAL.ik(poses), atol=0)


def test_real_machine_pose_satisfies_its_own_ik():
    poses = _poses(30)
    res = simulate_campaign(NOMINAL, REAL, _quiet(SENSORS[0]), poses, rng=1)
    assert len(res.kept) > 20
    # the real machine, driven by the nominal commands, is away from the commanded pose ...
    assert np.min(np.linalg.norm(res.real_poses[:, :3] - poses[res.kept, :3], axis=1)) > 0.5
    # ... and where its own inverse kinematics give back the commands
    np.testing.assert_allclose(REAL.ik(res.real_poses), NOMINAL.ik(poses[res.kept]), atol=1e-8)


@pytest.mark.parametrize("distribution", ["gaussian", "uniform"])
def test_noise_statistics(distribution):
    std_y = np.array([0.01, 0.02, 0.03, 0.001, 0.002, 0.003])
    setup = MeasurementSetup(FullPoseSensor(), NoiseModel(std_y, np.full(6, 0.005), distribution))
    poses = np.tile(NOMINAL.home, (20000, 1))
    res = simulate_campaign(NOMINAL, NOMINAL, setup, poses, rng=7)
    e_y = res.sensor_readings - res.sensor_true
    e_q = res.actuator_readings - res.actuator_true
    n = len(poses)
    # 12 means within 5.6 standard errors (normal by the CLT; two-sided 2e-8 each), 12 stds
    # within 4 % (20000 draws: relative se of a std √((κ − 1)/4n) = 0.5 % Gaussian (κ = 3),
    # 0.32 % uniform (κ = 1.8), so 4 % is ≥ 8 se): false failure below 1e-6 (FALSE_FAILURE)
    assert np.all(np.abs(e_y.mean(axis=0)) < 5.6 * std_y / np.sqrt(n))
    assert np.all(np.abs(e_q.mean(axis=0)) < 5.6 * 0.005 / np.sqrt(n))
    np.testing.assert_allclose(e_y.std(axis=0), std_y, rtol=0.04)
    np.testing.assert_allclose(e_q.std(axis=0), 0.005, rtol=0.04)
    if distribution == "uniform":
        h = std_y * np.sqrt(3.0)
        assert np.all(np.abs(e_y) <= h * (1 + 1e-12))
        assert np.all(np.abs(e_y).max(axis=0) > 0.99 * h)   # the half-width is reached (misses: 0.99ⁿ = e⁻²⁰⁰)
    else:
        assert np.all(np.abs(e_y).max(axis=0) > 3 * std_y)  # tails beyond a uniform's (misses: 0.9973ⁿ = e⁻⁵⁴)


def test_paper1_setup_is_uniform_with_the_papers_half_widths():
    setup = load_setup("full-pose-paper1")
    res = simulate_campaign(NOMINAL, NOMINAL, setup, np.tile(NOMINAL.home, (5000, 1)), rng=3)
    e_y = np.abs(res.sensor_readings - res.sensor_true)
    e_q = np.abs(res.actuator_readings - res.actuator_true)
    # the half-widths are bounds, and reached: no draw of 15000 (30000) beyond 99.6 % (99.9 %)
    # of its half-width has probability 0.996¹⁵⁰⁰⁰ = e⁻⁶⁰, 0.999¹⁵⁰⁰⁰ = 3e-7, 0.999³⁰⁰⁰⁰ = e⁻³⁰
    assert e_y[:, :3].max() <= 0.025 and e_y[:, :3].max() > 0.0249
    assert e_y[:, 3:].max() <= 0.001 and e_y[:, 3:].max() > 0.000999
    assert e_q.max() <= 0.01 and e_q.max() > 0.00999


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_same_seed_same_bits(seed):
    setup = load_setup("indicators-prototype")
    poses = _poses(10, seed=seed % 1000)
    a = simulate_campaign(NOMINAL, REAL, setup, poses, rng=seed)
    b = simulate_campaign(NOMINAL, REAL, setup, poses, rng=seed)
    assert a.sensor_readings.tobytes() == b.sensor_readings.tobytes()
    assert a.actuator_readings.tobytes() == b.actuator_readings.tobytes()
    c = simulate_campaign(NOMINAL, REAL, setup, poses, rng=seed + 1)
    assert not np.array_equal(a.sensor_readings, c.sensor_readings)


def test_unreachable_poses_are_dropped_with_reasons():
    poses = _poses(6)
    poses[1, 2] += 200.0            # far beyond the stroke
    poses[3, 3] = 0.6               # 34° roll: beyond the S-joint tilt limit
    res = simulate_campaign(NOMINAL, REAL, load_setup("laser-tracker"), poses, rng=0)
    assert 1 in res.dropped and 3 in res.dropped
    assert "stroke" in res.dropped[1] or "fk" in res.dropped[1]
    assert res.dropped[3].startswith("real-limits")
    assert list(res.kept) == [0, 2, 4, 5]
    assert res.sensor_readings.shape == (4, 3) and res.measurements.commanded.shape == (4, 6)
    np.testing.assert_array_equal(res.measurements.commanded, poses[[0, 2, 4, 5]])
    assert "4 of 6 poses measured, 2 dropped" in res.summary()


def test_noise_of_kept_poses_does_not_depend_on_dropped_ones():
    setup = load_setup("laser-tracker")
    poses = _poses(6)
    a = simulate_campaign(NOMINAL, REAL, setup, poses, rng=5)
    poses[2, 2] += 500.0
    b = simulate_campaign(NOMINAL, REAL, setup, poses, rng=5)
    keep = [0, 1, 3, 4, 5]
    np.testing.assert_array_equal(b.sensor_readings - b.sensor_true,
                                  (a.sensor_readings - a.sensor_true)[keep])


def test_perturb_machine_uniform_bounds_and_reproducibility():
    m = perturb_machine(NOMINAL, 5.0, rng=11)
    d = m.params - NOMINAL.params
    assert np.all(np.abs(d) <= 5.0) and np.abs(d).max() > 4.0
    assert np.array_equal(perturb_machine(NOMINAL, 5.0, rng=11).params, m.params)
    np.testing.assert_array_equal(m.home, NOMINAL.home)
    g = perturb_machine(NOMINAL, 1.0, rng=11, distribution="gaussian")
    assert np.abs(g.params - NOMINAL.params).max() > 1.0  # 42 normal draws: max |z| > 1 (p ≈ 1e-7 otherwise)
    with pytest.raises(PkmcalError, match="unknown error distribution"):
        perturb_machine(NOMINAL, 1.0, distribution="triangular")


def test_ignore_limits_keeps_colliding_perturbed_machines():
    real = perturb_machine(NOMINAL, 5.0, rng=0)
    poses = _poses(20)
    strict = simulate_campaign(NOMINAL, real, load_setup("laser-tracker"), poses, rng=0)
    loose = simulate_campaign(NOMINAL, real, load_setup("laser-tracker"), poses, rng=0,
                              ignore_limits=("leg_collision",))
    assert len(loose.kept) >= len(strict.kept)
    assert not any("leg_collision" in why for why in loose.dropped.values())
    with pytest.raises(PkmcalError, match="no limit"):
        simulate_campaign(NOMINAL, real, load_setup("laser-tracker"), poses, ignore_limits=("bogus",))


# -- command line ------------------------------------------------------------------------


def _pose_file(path, poses):
    from pkmcal.conventions import poses_to_file_units

    rows = poses_to_file_units(poses)
    path.write_text("x,y,z,a,b,c\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))
    return path


def test_cli_simulate_same_seed_same_bytes_and_readable(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.measurements import load_measurements

    poses = _poses(12)
    poses[3, 2] += 300.0
    pf = _pose_file(tmp_path / "poses.csv", poses)
    runner = CliRunner()
    args = ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
            "--poses", str(pf), "--seed", "4"]
    r1 = runner.invoke(cli, args + ["-o", str(tmp_path / "a.csv")])
    r2 = runner.invoke(cli, args + ["-o", str(tmp_path / "b.csv")])
    assert r1.exit_code == 0 and r2.exit_code == 0, r1.output
    assert "11 of 12 poses measured, 1 dropped" in r1.output and "stroke" in r1.output
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    meas = load_measurements(tmp_path / "a.csv", NOMINAL, load_setup("indicators-prototype"))
    direct = simulate_campaign(NOMINAL, REAL, load_setup("indicators-prototype"), poses, rng=4)
    np.testing.assert_array_equal(meas.actuators, direct.actuator_readings)
    np.testing.assert_array_equal(meas.readings, direct.sensor_readings)
    np.testing.assert_allclose(meas.commanded, poses[direct.kept], rtol=1e-15)


def test_cli_simulate_random_errors_saves_the_real_machine(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.machine_file import load_machine

    pf = _pose_file(tmp_path / "poses.csv", _poses(8))
    r = CliRunner().invoke(cli, ["simulate", "stewart-prototype", "--random-errors", "2", "--save-real",
                                 str(tmp_path / "real.yaml"), "--setup", "laser-tracker", "--poses", str(pf),
                                 "--seed", "9", "--ignore-limit", "leg_collision", "-o", str(tmp_path / "m.csv")])
    assert r.exit_code == 0, r.output
    real = load_machine(str(tmp_path / "real.yaml"))
    expected = perturb_machine(NOMINAL, 2.0, np.random.default_rng(9))
    np.testing.assert_array_equal(real.params, expected.params)


def test_cli_simulate_errors_exit_2_and_write_nothing(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    pf = _pose_file(tmp_path / "poses.csv", _poses(3))
    out = tmp_path / "m.csv"
    bad_setup = tmp_path / "s.yaml"
    bad_setup.write_text("sensor: position\nnoise: {reading: 0.01}\n")
    cases = [
        (["--setup", "laser-tracker"], "give the real machine with --real"),
        (["--real", "stewart-prototype-real", "--setup", str(bad_setup)], "noise.actuator': is missing"),
        (["--real", "stewart-prototype-real", "--setup", "laser-tracker", "--save-real", "x.yaml"], "--save-real"),
    ]
    for extra, msg in cases:
        r = CliRunner().invoke(cli, ["simulate", "stewart-prototype", "--poses", str(pf), "-o", str(out)] + extra)
        assert r.exit_code == 2, r.output
        assert msg in r.output and "Traceback" not in r.output
        assert not out.exists()
    far = _pose_file(tmp_path / "far.csv", _poses(3) + [0, 0, 400, 0, 0, 0])
    r = CliRunner().invoke(cli, ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                                 "laser-tracker", "--poses", str(far), "-o", str(out)])
    assert r.exit_code == 2 and "reaches none of the 3 poses" in r.output and not out.exists()

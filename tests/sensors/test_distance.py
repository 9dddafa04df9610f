"""Distance sensor (ballbar, string potentiometer, interferometer to a fixed point):
readings against the distance computed independently (homogeneous transforms with scipy),
analytic pose and parameter Jacobians against central finite differences, the setup file
round trip, and what the identifiability analysis says it sees on a hexapod."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd, frames_of, hexapod_pose_jacobian
from scipy.spatial.transform import Rotation

from pkmcal.errors import PkmcalError
from pkmcal.sensors.distance import DistanceSensor

PIVOTS = np.array([[0.0, 0.0, 0.0], [300.0, -50.0, 20.0], [-120.0, 260.0, -40.0]])
BALL = np.array([10.0, -5.0, 40.0])


def _poses(n=12, seed=0):
    rng = np.random.default_rng(seed)
    lo = np.array([-60, -60, 250, -0.3, -0.3, -0.5])
    hi = np.array([60, 60, 350, 0.3, 0.3, 0.5])
    return lo + rng.uniform(size=(n, 6)) * (hi - lo)


def _sensor(**kw):
    return DistanceSensor(pivots=PIVOTS, ball=BALL, lengths=np.array([250.0, 0.0, 10.0]), **kw)


def test_readings_are_distances_less_the_reference_lengths():
    poses = _poses()
    s = _sensor()
    # independent: the ball in the base frame by scipy's rotation of the same convention
    R = Rotation.from_euler("ZYX", poses[:, [5, 4, 3]]).as_matrix()   # R = Rz(c) Ry(b) Rx(a)
    ball_base = poses[:, :3] + np.einsum("nij,j->ni", R, BALL)
    expected = np.linalg.norm(ball_base[:, None, :] - PIVOTS[None], axis=2) - [250.0, 0.0, 10.0]
    np.testing.assert_allclose(s.predict(frames_of(poses)), expected, rtol=0, atol=1e-9)
    assert s.reading_names == ("dist1", "dist2", "dist3")
    assert s.param_names[:4] == ("ball.x", "ball.y", "ball.z", "pivot1.x")
    assert s.param_names[-3:] == ("length1", "length2", "length3")


def test_pose_jacobian_matches_finite_differences():
    """Through the engine's composition ∂r/∂x = frame_jacobian · T. Curvature of a distance
    is 1/d (d ≥ ~200 mm here), so the length scale is 200 mm; angles 1 rad."""
    poses = _poses()
    s = _sensor()
    J = hexapod_pose_jacobian(s, poses)
    assert_jacobian_matches_fd(lambda x: s.predict(frames_of(x)), poses, J,
                               scale=np.array([200.0] * 3 + [1.0] * 3))


def test_param_jacobian_matches_finite_differences():
    poses = _poses()
    s = _sensor()
    frame = frames_of(poses)
    J = s.param_jacobian(frame)
    assert J.shape == (len(poses), 3, 3 + 4 * 3)
    assert_jacobian_matches_fd(lambda th: s.predict(frame, params=th), s.params, J, scale=200.0,
                               names=s.param_names)


def test_one_pivot_flat_params_and_errors():
    s = DistanceSensor(pivots=[1.0, 2.0, 3.0])
    assert s.n_pivots == 1 and s.reading_names == ("dist1",)
    t = s.with_params(np.arange(7.0))
    np.testing.assert_array_equal(t.pivots, [3.0, 4.0, 5.0])
    assert t.lengths[0] == 6.0 and t == s.with_params(np.arange(7.0)) and t != s
    with pytest.raises(PkmcalError, match="pivot"):
        DistanceSensor()
    with pytest.raises(PkmcalError, match="pivots must be"):
        DistanceSensor(pivots=[[1.0, 2.0]])


def test_unreadable_when_the_ball_sits_on_a_pivot():
    s = DistanceSensor(pivots=[[0.0, 0.0, 300.0]])
    ok, why = s.readable(frames_of(np.array([[0, 0, 300, 0, 0, 0], [0, 0, 310, 0, 0, 0.0]])))
    assert ok.tolist() == [False, True] and "pivot" in why


SETUP = """sensor: distance
pivots: [[0, 0, 0], [300, -50, 20], [-120, 260, -40], [80, 90, 500]]   # mm, base frame
ball: {x: 10, y: -5, z: 40}
lengths: [250, 0, 10, 0]
free: [ball.x, ball.y, ball.z]
noise: {reading: 0.001, actuator: 0.005}
"""


def test_setup_file_reads_and_round_trips(tmp_path):
    from pkmcal.io.setup_file import load_setup, save_setup

    path = tmp_path / "ballbar.yaml"
    path.write_text(SETUP)
    setup = load_setup(path)
    s = setup.sensor
    assert s.kind == "distance" and s.n_pivots == 4 and s.free == ("ball.x", "ball.y", "ball.z")
    np.testing.assert_array_equal(s.ball, [10, -5, 40])
    np.testing.assert_array_equal(setup.noise.reading_std, [0.001] * 4)
    save_setup(setup, tmp_path / "again.yaml")
    back = load_setup(tmp_path / "again.yaml")
    assert back.sensor == s
    np.testing.assert_array_equal(back.noise.reading_std, setup.noise.reading_std)


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: t.replace("pivots: [[0, 0, 0], [300, -50, 20], [-120, 260, -40], [80, 90, 500]]   # mm, base frame\n", ""),
     "pivots"),
    (lambda t: t.replace("lengths: [250, 0, 10, 0]", "lengths: [250, 0]"), "one reference length per pivot"),
    (lambda t: t + "plane_offset: 3\n", "does not apply to sensor 'distance'"),
    (lambda t: t.replace("free: [ball.x, ball.y, ball.z]", "free: [ball.w]"), "ball.w"),
])
def test_setup_file_errors_name_the_key(tmp_path, edit, fragment):
    from pkmcal.errors import InputFileError
    from pkmcal.io.setup_file import load_setup

    path = tmp_path / "bad.yaml"
    path.write_text(edit(SETUP))
    with pytest.raises(InputFileError, match=fragment):
        load_setup(path)


def test_noise_free_identification_of_a_hexapod_from_distances():
    """Four pivots (multilateration) on the stewart prototype: from noise-free readings the
    fit leaves residuals below 1e-9 mm and the calibrated machine with its identified ball
    predicts held-out readings of the real one to 1e-9 mm (a gauge-free check); the ball
    offset, 0.3 mm off at the start, is estimated with it."""
    import dataclasses

    from helpers import random_poses

    from pkmcal.identification.engine import identify
    from pkmcal.identification.simulation import simulate_campaign
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.sensors.base import MeasurementSetup, NoiseModel

    nominal = builtin_machine("stewart-prototype")
    real = builtin_machine("stewart-prototype-real")
    pivots = np.array([[0.0, 0.0, 0.0], [300.0, -50.0, 20.0], [-120.0, 260.0, -40.0], [80.0, 90.0, 500.0]])
    truth = DistanceSensor(pivots=pivots, ball=np.array([10.3, -4.8, 40.2]), free=("ball.x", "ball.y", "ball.z"))
    noise = NoiseModel(reading_std=np.zeros(4), actuator_std=np.array(0.0))
    sim = simulate_campaign(nominal, real, MeasurementSetup(truth, noise), random_poses(nominal, 80, seed=4),
                            rng=4, ignore_limits=("leg_collision",))
    assert len(sim.kept) >= 70
    start = dataclasses.replace(truth, ball=np.array([10.0, -5.0, 40.0]))
    weights = NoiseModel(reading_std=np.full(4, 0.001), actuator_std=np.array(0.005))
    fit = identify(nominal, MeasurementSetup(start, weights), sim.measurements, method="fk-residual",
                   xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert fit.success and fit.rms_residual < 1e-9
    q = nominal.ik(random_poses(nominal, 40, seed=5))
    real_fk, cal_fk = real.fk(q), fit.mechanism.fk(q)
    ok = real_fk.ok & cal_fk.ok
    assert ok.mean() > 0.9
    np.testing.assert_allclose(fit.sensor.predict(fit.mechanism.frame(cal_fk.poses[ok])),
                               truth.predict(real.frame(real_fk.poses[ok])), rtol=0, atol=1e-9)


def test_identifiability_of_one_ballbar_on_a_hexapod():
    """What distances cannot see, structurally: one ball is one point, so the three
    rotations of the platform joints about the ball change no distance (4 pivots: rank
    42 − 3); with a single pivot the three rotations of the base joints about the pivot
    are unseen as well (rank 42 − 6)."""
    from helpers import random_poses

    from pkmcal.identification.identifiability import identifiability
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.sensors.base import MeasurementSetup, NoiseModel

    nominal = builtin_machine("stewart-prototype")
    poses = random_poses(nominal, 120, seed=6)
    ranks = {}
    for k in (1, 4):
        piv = np.array([[0.0, 0.0, 0.0], [300.0, -50.0, 20.0], [-120.0, 260.0, -40.0], [80.0, 90.0, 500.0]])[:k]
        setup = MeasurementSetup(DistanceSensor(pivots=piv, ball=np.array([0.0, 0.0, 40.0])),
                                 NoiseModel(reading_std=np.full(k, 0.001), actuator_std=np.array(0.005)))
        ranks[k] = identifiability(nominal, setup, poses)
    assert ranks[4].rank == 39 and ranks[1].rank == 36
    base_only = [d for d in ranks[1].null_space if all(n.startswith("b") for n in d)]
    assert len(base_only) >= 1


@pytest.mark.parametrize("plane", ["xy", "yz", "zx"])
def test_circle_frames_put_the_ball_on_the_circle(plane):
    """Every circle-test frame puts the ball at the bar length from pivot 1 (the reading is
    0: the bar at its reference length), in the plane through the pivot, the platform at its
    home orientation; the angles are equally spaced."""
    s = DistanceSensor(pivots=[[5.0, -3.0, 310.0]], ball=BALL, lengths=[60.0])
    home = frames_of(np.array([1.0, 2.0, 300.0, 0.05, -0.02, 0.1]))
    frames = s.circle_frames(24, home, plane)
    np.testing.assert_allclose(s.predict(frames), 0.0, atol=1e-12)
    np.testing.assert_allclose(frames.R, np.broadcast_to(home.R[0], (24, 3, 3)), atol=0)
    ball = frames.p + frames.R @ BALL
    normal = "xyz".index(next(a for a in "xyz" if a not in plane))
    np.testing.assert_allclose(ball[:, normal], [5.0, -3.0, 310.0][normal], atol=1e-12)
    i, j = DistanceSensor.CIRCLE_PLANES[plane]
    angles = np.arctan2(ball[:, j] - [5.0, -3.0, 310.0][j], ball[:, i] - [5.0, -3.0, 310.0][i])
    np.testing.assert_allclose(np.diff(np.unwrap(angles)), 2 * np.pi / 24, atol=1e-12)


def test_circle_radius_defaults_to_the_home_distance_and_errors():
    home = frames_of(np.array([0.0, 0.0, 300.0, 0.0, 0.0, 0.0]))
    s = DistanceSensor(pivots=[[0.0, 40.0, 300.0]])            # ball at the platform origin
    np.testing.assert_allclose(s.predict(s.circle_frames(8, home)), 40.0, atol=1e-12)
    with pytest.raises(PkmcalError, match="circle plane"):
        s.circle_frames(8, home, "xx")
    with pytest.raises(PkmcalError, match="no radius"):
        DistanceSensor(pivots=[[0.0, 0.0, 300.0]]).circle_frames(8, home)


def test_plan_circle_command(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.tables import read_table

    setup = tmp_path / "ballbar.yaml"
    setup.write_text("sensor: distance\npivots: [[0, 0, 315]]\nball: {x: 0, y: 0, z: 0}\nlengths: [30]\n"
                     "noise: {reading: 0.001, actuator: 0.005}\n")
    out = tmp_path / "circle.csv"
    run = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", str(setup), "--algorithm", "circle",
                                   "--n-poses", "36", "-o", str(out)])
    assert run.exit_code == 0, run.output
    table = read_table(out, ("x", "y", "z"))
    xy = np.stack([table["x"], table["y"]], axis=1)
    np.testing.assert_allclose(np.hypot(*xy.T), 30.0, atol=1e-9)
    np.testing.assert_allclose(table["z"], 315.0, atol=1e-9)
    bad = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", "laser-tracker", "--algorithm", "circle",
                                   "--n-poses", "36", "-o", str(tmp_path / "x.csv")])
    assert bad.exit_code == 2 and "ballbar circle test" in bad.output
    far = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", str(setup), "--algorithm", "circle",
                                   "--n-poses", "36", "--circle-plane", "yz", "-o", str(tmp_path / "y.csv")])
    assert far.exit_code == 2 and "circle-test poses" in far.output and "cannot be measured" in far.output

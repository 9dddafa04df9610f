"""The indicator plate as its own frame (paper 2 §2.3, Fig. 2; issue 15 item 2).

Checks: with the identity plate the readings and the pose Jacobian are bit-identical to
paper 2's eq. 6 as implemented before the plate existed (copied below); the analytic pose
and parameter Jacobians against central differences; a rigid motion of plate and platform
together changes no reading (closed form); readings of a tilted plate equal those of a
level plate seen from the plate frame; the setup file's ``plate:`` key round-trips; and the
identification: parallel frames absorb the plate, a surveyed plate leaves the machine in
the base frame, a free plate is recovered against a surveyed base.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import frames_of, hexapod_pose_jacobian
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.conventions import (
    euler_pose_jacobian,
    euler_to_matrix,
    matrix_to_euler,
    rotation_vector_to_matrix,
)
from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io.setup_file import load_setup, setup_to_yaml
from pkmcal.mechanisms import builtin_machine
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.indicators import PLATE_PARAM_NAMES, IndicatorSensor, plane_normals
from pkmcal.sensors.library import PROTOTYPE_INDICATORS

HOME = np.array([0.0, 0.0, 320.0, 0.0, 0.0, 0.0])
SPAN = np.array([20.0, 20.0, 10.0, 0.12, 0.12, 0.4])


def _poses(seed, n=8):
    return HOME + np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 6)) * SPAN


def _plate(seed):
    rng = np.random.default_rng(seed)
    return np.r_[rng.uniform(-5, 5, 3), rng.uniform(-0.05, 0.05, 2), rng.uniform(-0.5, 0.5)]


def _reference(s: IndicatorSensor, poses):
    """Eq. 6 and its pose Jacobian exactly as implemented before the plate frame (same NumPy
    operations), for the bit-identity check."""
    n = plane_normals(poses[:, 3:6])
    num = (np.einsum("nk,nk->n", n, poses[:, 0:3]) - s.plane_offset)[:, None] - n[:, 0:2] @ s.positions.T
    y = num / n[:, 2:3] - s.zero
    inz = 1.0 / n[:, 2:3]
    gx = (poses[:, 0:1] - s.positions[:, 0]) * inz
    gy = (poses[:, 1:2] - s.positions[:, 1]) * inz
    gz = (poses[:, 2:3] - num * inz) * inz
    nx, ny, nz = n[:, 0:1], n[:, 1:2], n[:, 2:3]
    Jt = np.empty(num.shape + (6,))
    Jt[..., 0:3] = (n * inz)[:, None, :]
    Jt[..., 3] = ny * gz - nz * gy
    Jt[..., 4] = nz * gx - nx * gz
    Jt[..., 5] = nx * gy - ny * gx
    return y, euler_pose_jacobian(Jt, poses)


def test_identity_plate_is_bit_identical_to_eq6():
    s = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, zero=[0.1, -0.2, 0.3])
    assert s.plate_is_identity and s.param_names[3:] == PLATE_PARAM_NAMES
    P = _poses(1, 50)
    y, J = _reference(s, P)
    assert np.array_equal(s.predict(frames_of(P)), y)
    assert np.array_equal(hexapod_pose_jacobian(s, P), J)
    explicit = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, zero=[0.1, -0.2, 0.3], plate=np.zeros(6))
    assert explicit == s and np.array_equal(explicit.predict(frames_of(P)), y)


@pytest.mark.parametrize("seed", range(4))
def test_jacobians_against_central_differences(seed):
    """Step h = 1e-6 (mm, rad): truncation ~h²·|z'''| ≈ 1e-10, rounding ~ε|z|/h ≈ 300·2e-16/1e-6
    = 6e-8 mm per unit; tolerance 5e-7."""
    s = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, zero=[0.1, 0.2, 0.3], plate=_plate(seed))
    P = _poses(10 + seed)
    h = 1e-6
    J = hexapod_pose_jacobian(s, P)
    Jfd = np.stack([(s.predict(frames_of(P + h * e)) - s.predict(frames_of(P - h * e))) / (2 * h) for e in np.eye(6)], axis=-1)
    np.testing.assert_allclose(J, Jfd, atol=5e-7, rtol=0)
    th = s.params
    Jp = s.param_jacobian(frames_of(P))
    Jpfd = np.stack([(s.with_params(th + h * e).predict(frames_of(P)) - s.with_params(th - h * e).predict(frames_of(P))) / (2 * h)
                     for e in np.eye(th.size)], axis=-1)
    np.testing.assert_allclose(Jp, Jpfd, atol=5e-7, rtol=0)
    assert np.abs(Jp[:, :, 6:]).max() > 1.0          # the plate angles matter (lever ~ the platform height)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000))
def test_rigid_motion_of_plate_and_platform_changes_no_reading(seed):
    """Moving the plate and the platform by the same rigid motion (rotation Q about the origin
    then translation t) leaves every reading as it was."""
    rng = np.random.default_rng(seed)
    plate = _plate(seed)
    P = _poses(seed, 5)
    Q = rotation_vector_to_matrix(rng.uniform(-0.05, 0.05, 3))
    t = rng.uniform(-3, 3, 3)

    def move(pose6):
        R = euler_to_matrix(pose6[:, 3:6])
        return np.concatenate([pose6[:, 0:3] @ Q.T + t, matrix_to_euler(Q @ R)], axis=1)

    s0 = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, plate=plate)
    s1 = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, plate=move(plate[None])[0])
    np.testing.assert_allclose(s1.predict(frames_of(move(P))), s0.predict(frames_of(P)), atol=1e-9)


def test_tilted_plate_reads_the_plate_frame_pose():
    """A plate at (p_W, R_W) reads what a level, centred plate reads for the platform's pose
    in plate coordinates (R_Wᵀ(p − p_W), R_Wᵀ R)."""
    plate = _plate(7)
    P = _poses(8)
    Rw = euler_to_matrix(plate[3:6])
    local = np.concatenate([(P[:, 0:3] - plate[0:3]) @ Rw, matrix_to_euler(Rw.T @ euler_to_matrix(P[:, 3:6]))], 1)
    tilted = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, plate=plate)
    level = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0)
    np.testing.assert_allclose(tilted.predict(frames_of(P)), level.predict(frames_of(local)), atol=1e-10)
    # the touch points lie on the platform's lower plane and on the indicator axes
    pts = tilted.touch_points(frames_of(P))
    n = plane_normals(P[:, 3:6])
    x0 = P[:, 0:3] - 10.0 * n
    np.testing.assert_allclose(np.einsum("nkj,nj->nk", pts - x0[:, None, :], n), 0.0, atol=1e-9)
    local_pts = (pts - plate[0:3]) @ Rw
    np.testing.assert_allclose(local_pts[..., 0:2], np.broadcast_to(PROTOTYPE_INDICATORS, local_pts[..., 0:2].shape),
                               atol=1e-9)


def test_setup_file_plate_round_trip(tmp_path):
    path = tmp_path / "ind.yaml"
    path.write_text("sensor: indicators\nindicators: [[40, 0], [-20, 34.641], [-20, -34.641]]\nplane_offset: 10\n"
                    "plate: {x: 1.5, z: -2, a: 0.5, c: 30}\nfree: [plate.a, plate.b]\n"
                    "noise: {reading: 0.01, actuator: 0.005}\n")
    s = load_setup(path)
    np.testing.assert_allclose(s.sensor.plate, [1.5, 0, -2, np.deg2rad(0.5), 0, np.deg2rad(30)], rtol=0, atol=1e-15)
    assert s.sensor.free == ("plate.a", "plate.b")
    again = tmp_path / "again.yaml"
    again.write_text(setup_to_yaml(s))
    back = load_setup(again)
    assert back.sensor == s.sensor
    level = dataclasses.replace(s, sensor=s.sensor.with_params(np.zeros(9)))
    assert "plate:" not in setup_to_yaml(level)      # the identity plate is not written


def test_identification_with_and_without_the_plate():
    """Noise-free data from Table 4's machine over a tilted plate: every model fits the
    readings; parallel frames assumed move the base joints by the plate's rigid motion; the
    surveyed plate leaves only the 3-parameter platform gauge; a free plate against a
    surveyed base comes out exact."""
    nominal, real = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype-real")
    plate = np.array([1.0, -0.5, 2.0, *np.deg2rad([0.5, -0.3, 1.0])])
    noise = NoiseModel(np.full(3, 0.01), np.array(0.005))
    sensor = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0, plate=plate)
    rng = np.random.default_rng(0)
    cmd = nominal.home_pose + rng.uniform(-1, 1, (200, 6)) * np.array([20, 20, 10, *np.deg2rad([8, 8, 8])])
    sim = simulate_campaign(nominal, real, MeasurementSetup(sensor, noise), cmd, rng,
                            ignore_limits=("leg_collision",)).subset(slice(100))
    kw = dict(q=sim.actuator_true, y=sim.sensor_true, commanded=sim.commanded[sim.kept], method="fk-residual",
              weighted=False)
    level = IndicatorSensor(PROTOTYPE_INDICATORS, 10.0)
    parallel = identify(nominal, MeasurementSetup(level, noise), **kw)
    surveyed = identify(nominal, MeasurementSetup(sensor, noise), **kw)
    for r in (parallel, surveyed):
        assert r.rms_residual < 1e-9 and r.gauge == ("a1.x", "a1.y", "a2.x")
    err = lambda r: np.abs(r.estimate[:42] - real.params[:42])  # noqa: E731  (the gains held)
    assert err(parallel).max() > 2.0                    # base joints moved by the plate's pose
    assert err(surveyed).max() < 1.5                    # only the platform gauge (Table 4 moves a2.x)
    base = ("b1.x", "b1.y", "b1.z", "b2.x", "b2.z", "b3.z")
    pinned = nominal.with_params(np.where(np.isin(nominal.param_names, base), real.params, nominal.params))
    free_plate = dataclasses.replace(level, free=PLATE_PARAM_NAMES)
    r = identify(pinned, MeasurementSetup(free_plate, noise), fix=base + ("a1.x", "a1.y", "a2.x"), **kw)
    est = r.estimate[[r.names.index(n) for n in PLATE_PARAM_NAMES]]
    np.testing.assert_allclose(est, plate, atol=1e-7)
    # freed with the automatic gauge: the engine names the rigid motion of base and plate
    auto = identify(nominal, MeasurementSetup(free_plate, noise), **kw)
    assert len(auto.gauge) == 9 and {"a1.x", "a1.y", "a2.x"} <= set(auto.gauge)

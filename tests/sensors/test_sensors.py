"""Sensor models: analytic Jacobians vs central finite differences, and the readings vs
independent constructions (homogeneous transforms with scipy; plane through three
transformed platform points intersected with each indicator's vertical line); the
position sensor against the position part of the full-pose sensor; the angle flags of
the parameters against 2π-periodicity of the readings; value equality of every sensor."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import assert_jacobian_matches_fd, frames_of, hexapod_pose_jacobian
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from pkmcal.workflow.text import _angle_names
from pkmcal.conventions import euler_to_matrix
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.hexapod import HEXAPOD_PARAM_NAMES
from pkmcal.mechanisms.library import builtin_machine
from pkmcal.sensors import SENSOR_KINDS, FullPoseSensor, IndicatorSensor, PlanarToolSensor, PositionSensor
from pkmcal.sensors.library import PROTOTYPE_INDICATORS

def _floats(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def _pose_array(n):
    lo = np.array([-60, -60, 200, -0.5, -0.5, -1.0])
    hi = np.array([60, 60, 400, 0.5, 0.5, 1.0])
    return arrays(float, (n, 6), elements=_floats(0, 1)).map(lambda u: lo + u * (hi - lo))


def _transform(lo_t, hi_t, ang):
    return st.tuples(*([_floats(lo_t, hi_t)] * 3 + [_floats(-ang, ang)] * 3)).map(np.array)


#: Length scale ℓ of every coordinate in mm here (the setups drawn span ~1 m: world offsets
#: ≤ 520 mm, poses ≤ 400 mm); the readings are linear in every mm coordinate, so ℓ only sets
#: the step. Angles: 1 rad, or less near a singularity (gimbal lock, a vertical plane).
LENGTH_SCALE = 1000.0


def _wrap_angles(is_angle):
    """diff(a, b) of readings: a − b, the angle readings wrapped to (−π, π]."""
    ang = np.asarray(is_angle, dtype=bool)

    def diff(a, b):
        d = a - b
        d[..., ang] = (d[..., ang] + np.pi) % (2 * np.pi) - np.pi
        return d

    return diff


def _euler_levers(abc, v):
    """Levers (3,) of the Euler angles (a, b, c) of R = Rz(c) Ry(b) Rx(a) acting on vectors v
    (N, 3), largest over the rows: a turns v about x, b turns Rx v about y, c turns Ry Rx v
    about z, and every derivative of a turn about a fixed unit axis k has norm |k × v|."""
    abc, v = np.broadcast_arrays(np.atleast_2d(abc), np.atleast_2d(v))
    ca, sa, cb, sb = np.cos(abc[:, 0]), np.sin(abc[:, 0]), np.cos(abc[:, 1]), np.sin(abc[:, 1])
    vx = np.stack([v[:, 0], ca * v[:, 1] - sa * v[:, 2], sa * v[:, 1] + ca * v[:, 2]], axis=1)
    vy = np.stack([cb * vx[:, 0] + sb * vx[:, 2], vx[:, 1], -sb * vx[:, 0] + cb * vx[:, 2]], axis=1)
    return np.array([np.hypot(v[:, 1], v[:, 2]).max(), np.hypot(vx[:, 0], vx[:, 2]).max(),
                     np.hypot(vy[:, 0], vy[:, 1]).max()])


def _fd_model(is_angle, angle_scale, mm_slope, angle_slope):
    """dict(scale, slope) of helpers.assert_jacobian_matches_fd for mm / angle columns."""
    ang = np.asarray(is_angle, dtype=bool)
    slope = np.full(ang.shape, float(mm_slope))
    slope[ang] = angle_slope  # one for all angle columns, or one each
    return dict(scale=np.where(ang, angle_scale, LENGTH_SCALE), slope=slope)


def _assert_pose_fd(sensor, poses, **model):
    assert_jacobian_matches_fd(lambda x: sensor.predict(frames_of(x)), poses, hexapod_pose_jacobian(sensor, poses), **_fd_model(ANG, **model),
                               diff=_wrap_angles(sensor.reading_is_angle), names=list("xyzabc"))


def _assert_param_fd(sensor, poses, **model):
    assert_jacobian_matches_fd(lambda theta: sensor.with_params(theta).predict(frames_of(poses)), sensor.params,
                               sensor.param_jacobian(frames_of(poses)), **_fd_model(sensor.param_is_angle, **model),
                               diff=_wrap_angles(sensor.reading_is_angle), names=sensor.param_names)


def _homogeneous(pose):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", pose[3:]).as_matrix()
    T[:3, 3] = pose[:3]
    return T


ANG = np.array([False, False, False, True, True, True])


# -- full pose ---------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(poses=_pose_array(4), world=_transform(-300, 300, 0.6), tool=_transform(-80, 80, 0.6))
def test_full_pose_jacobians_match_finite_differences(poses, world, tool):
    s = FullPoseSensor(world=world, tool=tool)
    y = s.predict(frames_of(poses))
    # stay away from gimbal lock of the measured angles, where E⁻¹ blows up
    b_max = np.max(np.abs(y[:, 4]))
    assume(b_max < np.deg2rad(75))
    # The reading's Euler angles are analytic up to gimbal lock: angle scale half the distance
    # to it. Slopes: position readings 1 per mm, the lever per rad (tool point: ‖t‖; world:
    # the reading's distance from the world origin); Euler readings ‖E⁻¹‖‖E‖ ≤ 4/cos b, twice
    # that within half the distance to the lock.
    angle_scale = min(1.0, (np.pi / 2 - b_max) / 2)
    euler = 8.0 / np.cos(b_max)
    _assert_pose_fd(s, poses, angle_scale=angle_scale, mm_slope=1.0,
                    angle_slope=max(np.linalg.norm(tool[:3]), euler))
    _assert_param_fd(s, poses, angle_scale=angle_scale, mm_slope=1.0,
                     angle_slope=max(np.linalg.norm(y[:, :3] - world[:3], axis=1).max(), euler))


@settings(max_examples=40, deadline=None)
@given(poses=_pose_array(3), world=_transform(-300, 300, 1.0), tool=_transform(-80, 80, 1.0))
def test_full_pose_reading_is_world_base_platform_tool_composition(poses, world, tool):
    s = FullPoseSensor(world=world, tool=tool)
    y = s.predict(frames_of(poses))
    for k, pose in enumerate(poses):
        T = _homogeneous(world) @ _homogeneous(pose) @ _homogeneous(tool)
        np.testing.assert_allclose(y[k, :3], T[:3, 3], atol=1e-9)
        R_read = Rotation.from_euler("xyz", y[k, 3:]).as_matrix()
        np.testing.assert_allclose(R_read, T[:3, :3], atol=1e-12)


def test_full_pose_identity_reads_the_pose():
    poses = np.array([[1.0, -2.0, 300.0, 0.1, -0.2, 0.3], [0, 0, 250, 0, 0, 0]])
    s = FullPoseSensor()
    np.testing.assert_allclose(s.predict(frames_of(poses)), poses, atol=1e-12)
    np.testing.assert_allclose(hexapod_pose_jacobian(s, poses), np.broadcast_to(np.eye(6), (2, 6, 6)), atol=1e-12)
    assert s.reading_is_angle == (False, False, False, True, True, True)
    assert s.default_free == ()
    assert FullPoseSensor(free=("world.x",)).default_free == ("world.x",)


# -- position ----------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(poses=_pose_array(4), target=_transform(-80, 80, 0).map(lambda v: v[:3]), world=_transform(-300, 300, 1.0))
def test_position_jacobians_match_finite_differences(poses, target, world):
    s = PositionSensor(target=target, world=world)
    # p_w + R_w (p + R t): linear in every mm coordinate (slope 1); an Euler angle turns a
    # lever about a fixed axis (_euler_levers: of t for the pose's angles, of p + R t for the
    # world's): ℓ = 1 rad
    R = euler_to_matrix(poses[:, 3:])
    _assert_pose_fd(s, poses, angle_scale=1.0, mm_slope=1.0, angle_slope=_euler_levers(poses[:, 3:], target))
    _assert_param_fd(s, poses, angle_scale=1.0, mm_slope=1.0,
                     angle_slope=_euler_levers(world[3:], poses[:, :3] + R @ target))
    for k, pose in enumerate(poses):
        expected = (_homogeneous(world) @ _homogeneous(pose) @ np.r_[target, 1.0])[:3]
        np.testing.assert_allclose(s.predict(frames_of(poses))[k], expected, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(poses=_pose_array(4), target=_transform(-80, 80, 0).map(lambda v: v[:3]), world=_transform(-300, 300, 1.0),
       tool_abc=_transform(0, 0, 3.0).map(lambda v: v[3:]))
def test_position_is_the_position_part_of_full_pose(poses, target, world, tool_abc):
    """Same frames (world; target = tool origin, any tool rotation): the readings, the pose
    Jacobian and the derivatives w.r.t. the shared parameters are the full-pose sensor's
    position rows."""
    pos = PositionSensor(target=target, world=world)
    full = FullPoseSensor(world=world, tool=np.r_[target, tool_abc])
    np.testing.assert_allclose(pos.predict(frames_of(poses)), full.predict(frames_of(poses))[:, 0:3], rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(hexapod_pose_jacobian(pos, poses), hexapod_pose_jacobian(full, poses)[:, 0:3], rtol=1e-14, atol=1e-12)
    Jp, Jf = pos.param_jacobian(frames_of(poses)), full.param_jacobian(frames_of(poses))
    col = {n: k for k, n in enumerate(full.param_names)}
    for k, name in enumerate(pos.param_names):
        other = col[name.replace("target.", "tool.")]
        np.testing.assert_allclose(Jp[:, :, k], Jf[:, 0:3, other], rtol=1e-14, atol=1e-12)


def test_position_defaults():
    s = PositionSensor(target=[1.0, 2.0, 3.0])
    assert s.reading_names == ("px", "py", "pz")
    assert s.default_free == ("target.x", "target.y", "target.z")
    np.testing.assert_allclose(s.predict(frames_of([10, 20, 300, 0, 0, 0])), [[11, 22, 303]])


# -- indicators --------------------------------------------------------------------------


def _indicator_positions(k):
    return arrays(float, (k, 2), elements=_floats(-70, 70))


def _plane_construction(positions, plane_offset, pose):
    """Independent geometry: three points of the lower plane z_P = −d_off mapped to {F};
    intersect each indicator's vertical line x = x_k, y = y_k with the plane through them."""
    T = _homogeneous(pose)
    pts = (T @ np.array([[0, 0, -plane_offset, 1], [50, 0, -plane_offset, 1], [0, 50, -plane_offset, 1]]).T).T[:, :3]
    u, v = pts[1] - pts[0], pts[2] - pts[0]
    out = []
    for xk, yk in positions:
        # pts0 + s u + t v has (x, y) = (x_k, y_k): a 2×2 system for s, t.
        s, t = np.linalg.solve(np.array([[u[0], v[0]], [u[1], v[1]]]), [xk - pts[0, 0], yk - pts[0, 1]])
        out.append(pts[0, 2] + s * u[2] + t * v[2])
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(poses=_pose_array(3), k=st.integers(3, 6), data=st.data(), d_off=_floats(-20, 40))
def test_indicator_model_matches_plane_construction_and_fd(poses, k, data, d_off):
    positions = data.draw(_indicator_positions(k))
    zero = data.draw(arrays(float, (k,), elements=_floats(-5, 5)))
    s = IndicatorSensor(positions=positions, plane_offset=d_off, zero=zero)
    y = s.predict(frames_of(poses))
    assert y.shape == (3, k)
    for j, pose in enumerate(poses):
        np.testing.assert_allclose(y[j] + zero, _plane_construction(positions, d_off, pose), atol=1e-8)
    # z_k = c_z − (n_x (x_k − c_x) + n_y (y_k − c_y)) / n_z, c = p + R (0, 0, −d_off), n = R e_z:
    # linear in p (slope ≤ 1/n_z), analytic in the angles until the plane turns vertical
    # (n_z = 0; the drawn tilts keep it ≥ π/2 − 0.71 rad away): angle scale half that, slope
    # ≤ r/n_z² with r the indicators' reach from c, twice that within the scale; the zeros:
    # linear, slope 1
    n_z = np.min(np.cos(poses[:, 3]) * np.cos(poses[:, 4]))
    reach = np.max(np.linalg.norm(positions[None] - poses[:, None, :2], axis=2)) + abs(d_off)
    _assert_pose_fd(s, poses, angle_scale=(np.pi / 2 - np.arccos(n_z)) / 2, mm_slope=1.0 / n_z,
                    angle_slope=2.0 * reach / n_z**2)
    # θ: the zeros (linear, slope 1), the plate translation (linear, slope ≤ 1/n_z) and the
    # plate angles at the identity plate, which turn c' = R_Wᵀ c (lever |c| ≤ |p| + |d_off|)
    # and n' as the platform's angles turn n: the same singularity distance, slope ≤
    # (|c| + reach)/n_z², twice that within the scale
    lever = np.max(np.linalg.norm(poses[:, :3], axis=1)) + abs(d_off)
    _assert_param_fd(s, poses, angle_scale=(np.pi / 2 - np.arccos(n_z)) / 2, mm_slope=1.0 / n_z,
                     angle_slope=2.0 * (lever + reach) / n_z**2)


def test_indicator_level_platform_reads_height_minus_offset():
    s = IndicatorSensor(positions=[[40, 0], [-20, 34.641], [-20, -34.641]], plane_offset=10.0, zero=[1, 2, 3])
    np.testing.assert_allclose(s.predict(frames_of([5, -3, 300, 0, 0, 0])), [[289, 288, 287]])
    assert s.reading_names == ("d1", "d2", "d3")
    assert s.param_names == ("zero1", "zero2", "zero3", "plate.x", "plate.y", "plate.z", "plate.a", "plate.b", "plate.c")
    assert s.default_free == ()


def test_indicator_vertical_plane_names_the_pose():
    s = IndicatorSensor(positions=[[40, 0], [-20, 34.641], [-20, -34.641]], plane_offset=10.0)
    poses = np.array([[0, 0, 300, 0, 0, 0], [0, 0, 300, np.pi / 2, 0, 0]])
    with pytest.raises(PkmcalError, match=r"pose 1 .*near vertical"):
        s.predict(frames_of(poses))


def test_indicator_needs_three():
    with pytest.raises(PkmcalError, match="at least 3"):
        IndicatorSensor(positions=[[0, 0], [1, 1]])


# -- common ------------------------------------------------------------------------------


def test_param_names_do_not_collide_with_hexapod():
    sensors = [FullPoseSensor(), PositionSensor(), IndicatorSensor(positions=np.zeros((4, 2)))]
    for s in sensors:
        assert not set(s.param_names) & set(HEXAPOD_PARAM_NAMES)
        assert len(set(s.param_names)) == len(s.param_names)
        assert s.with_params(s.params) == s
        assert SENSOR_KINDS[s.kind] is type(s)


def test_unknown_free_parameter_is_rejected():
    with pytest.raises(PkmcalError, match="no parameter 'world.q'"):
        FullPoseSensor(free=("world.q",))


def test_with_params_checks_length():
    with pytest.raises(PkmcalError, match="12 parameters"):
        FullPoseSensor().with_params(np.zeros(3))


def _all_sensors():
    return [
        FullPoseSensor(world=[5, -3, 2, 0.1, -0.2, 0.3], tool=[1, 2, 30, 0.2, 0.1, -0.1]),
        PositionSensor(target=[10, -5, 20], world=[3, 4, -5, 0.05, 0.1, -0.2]),
        IndicatorSensor(positions=[[40, 0], [-20, 34.641], [-20, -34.641], [0, 10]], plane_offset=7.0, zero=[1, 2, 3, 4]),
        PlanarToolSensor(n_pose=2, target=[3, -4], world=[10, -20, 0.3]),
        PlanarToolSensor(n_pose=3, target=[3, -4], world=[10, -20, 0.3]),
    ]


def _frames_for(sensor):
    """Two platform frames the sensor can read: of a hexapod, or of a planar machine."""
    poses = np.array([[10.0, -5.0, 300.0, 0.1, -0.2, 0.3], [-20.0, 15.0, 280.0, -0.15, 0.1, -0.4]])
    if "tool-point" in sensor.abilities:
        m = builtin_machine("planar-2dof-3act" if sensor.n_pose == 2 else "planar-3dof-4act")
        return m.frame(poses[:, :sensor.n_pose])
    return frames_of(poses)


EXPECTED_ANGLES = {
    "full-pose": {"world.a", "world.b", "world.c", "tool.a", "tool.b", "tool.c"},
    "position": {"world.a", "world.b", "world.c"},
    "indicators": {"plate.a", "plate.b", "plate.c"},
    "planar-tool": {"world.c"},
}


@pytest.mark.parametrize("sensor", _all_sensors(), ids=lambda s: f"{s.kind}")
def test_param_is_angle_flags_the_2pi_periodic_parameters(sensor):
    """An angle parameter moved by 2π leaves every reading unchanged (up to wrapping of angle
    readings); a length moved by 2π mm changes some reading."""
    flags = sensor.param_is_angle
    assert len(flags) == len(sensor.param_names) and all(isinstance(a, bool) for a in flags)
    assert {n for n, a in zip(sensor.param_names, flags) if a} == EXPECTED_ANGLES[sensor.kind]
    frames = _frames_for(sensor)
    y0 = sensor.predict(frames)
    for k, is_angle in enumerate(flags):
        theta = sensor.params
        theta[k] += 2 * np.pi
        change = np.max(np.abs(sensor.reading_residual(sensor.with_params(theta).predict(frames), y0)))
        if is_angle:
            assert change < 1e-9, sensor.param_names[k]
        else:
            assert change > 1e-3, sensor.param_names[k]


@pytest.mark.parametrize("k", range(len(_all_sensors())))
def test_sensors_are_equal_by_value(k):
    sensor = _all_sensors()[k]
    # a fresh construction with the same values is equal; every other sensor is not
    assert [sensor == other for other in _all_sensors()] == [j == k for j in range(len(_all_sensors()))]
    theta = sensor.params
    assert sensor.with_params(theta) == sensor and sensor.with_params(theta) is not sensor
    moved = theta.copy()
    moved[-1] += 1e-9
    assert sensor.with_params(moved) != sensor
    assert dataclasses.replace(sensor, free=sensor.param_names[:1]) != dataclasses.replace(sensor, free=())
    with pytest.raises(TypeError):
        hash(sensor)


def test_equality_compares_geometry_and_kind():
    ind = IndicatorSensor(positions=[[40, 0], [-20, 34.6], [-20, -34.6]], plane_offset=7.0)
    assert ind == IndicatorSensor(positions=[[40, 0], [-20, 34.6], [-20, -34.6]], plane_offset=7.0)
    assert ind != IndicatorSensor(positions=[[40, 0], [-20, 34.6], [-20, -34.6]], plane_offset=7.5)
    assert ind != IndicatorSensor(positions=[[40, 0], [-20, 34.6], [-20, -34.7]], plane_offset=7.0)
    assert ind != IndicatorSensor(positions=[[40, 0], [-20, 34.6], [-20, -34.6], [0, 0]], plane_offset=7.0)
    assert PlanarToolSensor(n_pose=2, target=[1, 2]) == PlanarToolSensor(n_pose=2, target=[1.0, 2.0])
    assert PlanarToolSensor(n_pose=2, target=[1, 2]) != PlanarToolSensor(n_pose=3, target=[1, 2])
    # same parameter values, different kinds
    assert FullPoseSensor() != PositionSensor() and PositionSensor() != FullPoseSensor()
    assert FullPoseSensor() != "full-pose"


def test_identify_table_angles_come_from_the_flags():
    hexapod = builtin_machine("stewart-prototype")
    planar = builtin_machine("planar-3dof-4act")
    for sensor in _all_sensors():
        result = SimpleNamespace(sensor=sensor, mechanism=hexapod)
        assert _angle_names(result) == EXPECTED_ANGLES[sensor.kind]
    planar_angles = {n for n, a in zip(planar.param_names, planar.param_is_angle) if a}
    assert planar_angles  # the way directions α_i
    result = SimpleNamespace(sensor=PlanarToolSensor(n_pose=3), mechanism=planar)
    assert _angle_names(result) == planar_angles | {"world.c"}


# -- the sensor contract: frames in, explicit parameters, declared abilities -------------------

PROTOTYPE_POSITIONS = PROTOTYPE_INDICATORS
PLATE = np.array([3.0, -2.0, 1.0, 0.02, -0.01, 0.3])


@pytest.mark.parametrize("sensor", _all_sensors() + [IndicatorSensor(PROTOTYPE_POSITIONS, 5.0, plate=PLATE)],
                         ids=lambda s: f"{s.kind}")
def test_explicit_params_equal_with_params_to_the_bit(sensor):
    frames = _frames_for(sensor)
    theta = sensor.params + 0.01 * (1 + np.arange(len(sensor.params)))
    other = sensor.with_params(theta)
    for f in ("predict", "frame_jacobian", "param_jacobian"):
        np.testing.assert_array_equal(getattr(sensor, f)(frames, theta), getattr(other, f)(frames), err_msg=f)
        np.testing.assert_array_equal(getattr(sensor, f)(frames), getattr(sensor, f)(frames, sensor.params))
    assert sensor.frame_jacobian(frames).shape == (len(frames), sensor.n_readings, 6)


@pytest.mark.parametrize("sensor", _all_sensors(), ids=lambda s: f"{s.kind}")
def test_frame_jacobian_matches_twists_of_the_frame(sensor):
    """∂y/∂(δp, δω) against central differences of y(frame moved by a twist) (Frame.moved):
    the readings are smooth in the twist on the scale of the setup (1 m for δp, 1 rad for δω)."""
    frames = _frames_for(sensor)[:1]
    J = sensor.frame_jacobian(frames)
    planar = "tool-point" in sensor.abilities
    rows = [0, 1, 5] if planar else list(range(6))     # a planar frame turns about z only
    assert_jacobian_matches_fd(lambda t: sensor.predict(frames.moved(_twist(t, rows))), np.zeros((1, len(rows))),
                               J[..., rows], scale=np.where(np.array(rows) >= 3, 1.0, 1000.0),
                               magnitude=1000.0, diff=_wrap_angles(sensor.reading_is_angle),
                               names=[("dpx", "dpy", "dpz", "dwx", "dwy", "dwz")[k] for k in rows])


def _twist(t, rows):
    full = np.zeros((np.shape(t)[0], 6))
    full[:, rows] = t
    return full


def test_readable_and_works_with_are_declared():
    hexapod, planar = builtin_machine("stewart-prototype"), builtin_machine("planar-3dof-4act")
    s = IndicatorSensor(PROTOTYPE_POSITIONS, 5.0)
    ok, why = s.readable(frames_of(np.array([[0, 0, 300, 0, 0, 0], [0, 0, 300, np.pi / 2, 0, 0]])))
    assert ok.tolist() == [True, False] and "vertical" in why
    assert FullPoseSensor().readable(frames_of(np.zeros(6)))[0].all()
    assert s.works_with(hexapod) is None and "planar-tool" in s.works_with(planar)
    assert PlanarToolSensor(n_pose=3).works_with(planar) is None
    assert FullPoseSensor().invertible and not PositionSensor().invertible
    with pytest.raises(PkmcalError, match="do not determine"):
        PositionSensor().invert(np.zeros((1, 3)))

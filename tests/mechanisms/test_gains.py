"""Hexapod leg gains: L_i = L0_i + g_i λ_i, readings in the instrument's unit (issue 11 item 1b).

Checked against independent references:

* the analytic Jacobians ∂λ/∂x and ∂λ/∂ρ (48 columns, the gains' included) at non-unit gains
  against central differences (helpers.assert_jacobian_matches_fd), and against the
  unit-gain Jacobians scaled by hand (∂λ/∂· = ∂L/∂· / g, ∂λ_i/∂g_i = −λ_i / g_i);
* IK/FK round trips with gains, and λ = (L − L0)/g against the leg lengths;
* noise-free recovery of 1 % gain errors with the geometry (L0 and joints) from full-pose
  measurements, to 1e-9 mm, in Python and through the command line (``--free``);
* the gains are held unless freed by name; with unit gains every number is the papers';
* machine-file round trips (exact, with gains and ``actuator_unit``) and the file errors;
* the LinuxCNC INI values against a hand computation.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_jacobian_matches_fd, assert_user_error
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.conventions import POSE_COLUMNS
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.residuals import default_fixed_parameters
from pkmcal.identification.simulation import perturb_machine, simulate_campaign
from pkmcal.io.export_linuxcnc import (
    joint_settings,
    leg_gains,
    linuxcnc_hal,
    linuxcnc_ini,
)
from pkmcal.io.machine_file import (
    load_machine,
    machine_from_text,
    machine_to_text,
    save_machine,
)
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import builtin_setup
from pkmcal.io.tables import format_table
from pkmcal.mechanisms import builtin_machine
from pkmcal.mechanisms.hexapod import GAIN_NAMES, HEXAPOD_PARAM_NAMES

PROTOTYPE = builtin_machine("stewart-prototype")
#: Poses around home: x, y ±15 mm, z ±10 mm, roll/pitch ±4°, yaw ±8° (all reachable).
HALF = np.array([15.0, 15.0, 10.0, *np.deg2rad([4.0, 4.0, 8.0])])
#: A ball-screw hexapod read in motor revolutions: 5 mm of leg per revolution, ±1 %.
LEAD = 5.0
#: The prototype's legs nearly touch: a few 0.1 mm of joint error bring the modelled legs into
#: contact (simulate_campaign's docstring), so the simulations do not check that limit.
COLLISION = ("leg_collision",)


def poses_near_home(machine, n, seed):
    return machine.home_pose + np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 6)) * HALF


def with_gains(machine, gains, unit="mm"):
    """``machine`` with leg gains ``gains`` and its stroke in the readings' unit (the same leg
    length range)."""
    gains = np.asarray(gains, dtype=float)
    return replace(machine, gains=gains, actuator_unit=unit, stroke=machine.stroke / gains[:, None],
                   home=machine.home_pose)


def real_with_gain_errors(nominal, seed, geometry_mm=0.5, gain_rel=0.01):
    """The real machine: the geometry (joints and L0) off by U(±geometry_mm), each gain by
    U(±gain_rel) relative."""
    rng = np.random.default_rng(seed)
    real = perturb_machine(nominal, geometry_mm, rng)
    rho = real.params
    assert np.array_equal(rho[42:], nominal.gains)  # perturb_machine leaves the gains alone
    rho[42:] *= 1.0 + rng.uniform(-gain_rel, gain_rel, 6)
    return real.with_params(rho, name=f"{nominal.name}-real")


gains_strategy = st.lists(st.floats(0.2, 10.0), min_size=6, max_size=6).map(np.array)


# -- the model and its Jacobians -------------------------------------------------------------


def test_parameters_are_the_papers_42_then_the_gains_held_by_default():
    assert HEXAPOD_PARAM_NAMES[:42] == tuple(s.format(i=i) for i in range(1, 7) for s in (
        "b{i}.x", "b{i}.y", "b{i}.z", "a{i}.x", "a{i}.y", "a{i}.z", "L0_{i}"))
    assert HEXAPOD_PARAM_NAMES[42:] == GAIN_NAMES == tuple(f"gain_{i}" for i in range(1, 7))
    assert PROTOTYPE.param_names == HEXAPOD_PARAM_NAMES and len(PROTOTYPE.params) == 48
    np.testing.assert_array_equal(PROTOTYPE.params[42:], 1.0)
    assert default_fixed_parameters(PROTOTYPE) == GAIN_NAMES
    assert PROTOTYPE.param_units == ("mm",) * 42 + ("1",) * 6
    assert with_gains(PROTOTYPE, np.full(6, LEAD), "rev").param_units[42:] == ("mm/rev",) * 6


@settings(max_examples=25, deadline=None)
@given(gains=gains_strategy, seed=st.integers(0, 2**32 - 1))
def test_readings_are_lengths_minus_offsets_over_gains_and_fk_inverts_them(gains, seed):
    m = with_gains(PROTOTYPE, gains, "rev")
    poses = poses_near_home(m, 80, seed)  # ≥ 64: the compiled IK; the first 5 alone: NumPy
    L = m.leg_lengths(poses)
    for x, lengths in ((poses, L), (poses[:5], L[:5])):
        lam = m.ik(x)
        np.testing.assert_allclose(lam * gains, lengths - m.offset, rtol=0, atol=1e-12 * lengths.max())
        np.testing.assert_allclose(m.lengths_from_readings(lam), lengths, rtol=0, atol=1e-12 * lengths.max())
        np.testing.assert_allclose(m.readings_from_lengths(lengths), lam, rtol=0, atol=1e-12 * np.abs(lam).max())
    fk = m.fk(m.ik(poses))
    assert fk.ok.all()
    # FK stops at leg errors ≤ 1e-9 mm; at these well-conditioned poses that is < 1e-7 mm, rad
    np.testing.assert_allclose(fk.poses, poses, rtol=0, atol=1e-7)
    q = m.ik_and_jacobians(poses)[0]
    np.testing.assert_allclose(q, m.ik(poses), rtol=0, atol=1e-12 * np.abs(q).max())


@settings(max_examples=15, deadline=None)
@given(gains=gains_strategy, seed=st.integers(0, 2**32 - 1))
def test_jacobians_are_the_unit_gain_ones_divided_by_the_gains(gains, seed):
    """∂λ/∂x = ∂L/∂x / g, ∂λ/∂(b, a, L0) = (unit-gain columns) / g, ∂λ_i/∂g_i = −λ_i/g_i."""
    m = with_gains(PROTOTYPE, gains)
    poses = poses_near_home(m, 7, seed)
    q, A, B = m.ik_and_jacobians(poses)
    _, A1, B1 = PROTOTYPE.ik_and_jacobians(poses)
    g = gains[None, :, None]
    np.testing.assert_allclose(A, A1 / g, rtol=1e-15, atol=0)
    np.testing.assert_allclose(B[..., :42], B1[..., :42] / g, rtol=1e-15, atol=0)
    expected = np.zeros((len(poses), 6, 6))
    expected[:, np.arange(6), np.arange(6)] = -q / gains
    np.testing.assert_allclose(B[..., 42:], expected, rtol=1e-15, atol=0)
    # the leg lengths do not depend on L0 or the gains
    JL = m.length_param_jacobian(poses)
    assert np.all(JL[..., 6:42:7] == 0.0) and np.all(JL[..., 42:] == 0.0)
    np.testing.assert_allclose(JL[..., :42], B1[..., :42] * np.where(np.arange(42) % 7 == 6, 0.0, 1.0),
                               rtol=1e-15, atol=0)


@settings(max_examples=15, deadline=None)
@given(gains=gains_strategy, seed=st.integers(0, 2**32 - 1))
def test_jacobians_against_finite_differences_with_gains(gains, seed):
    """Central differences of λ(x) and λ(ρ) at non-unit gains (error model of helpers: slope
    G and scale ℓ per column). Against ρ: b_i, a_i move leg i's vector along a unit direction
    (slope 1/g, scale ℓ = the shortest leg), L0_i is linear (slope 1/g); λ_i(g_i) =
    (L_i − L0_i)/g_i has slope |λ_i|/g_i and third derivative 6|λ_i|/g_i³ = 2G/ℓ² with
    ℓ = g_i/√3. Against x: slopes 1/g (mm) and r/g (angles, lever r), scales ℓ and 1 rad."""
    m = with_gains(PROTOTYPE, gains, "rev")
    poses = poses_near_home(m, 3, seed)
    L = m.leg_lengths(poses)
    lam = m.ik(poses)
    g_min = gains.min()
    ell = L.min()
    M = max(L.max(), np.abs(m.base).max(), np.abs(poses[:, :3]).max()) / g_min
    gain_col = np.arange(48) >= 42
    scale = np.where(gain_col, np.r_[np.ones(42), gains] / np.sqrt(3.0), ell)
    slope = np.where(gain_col, np.r_[np.ones(42), np.abs(lam).max(axis=0) / gains] + 1e-3, 1.0 / g_min)
    J = m.actuator_param_jacobian(poses)
    assert J.shape == (3, 6, 48)
    assert_jacobian_matches_fd(lambda rho: m.with_params(rho).ik(poses), m.params, J, scale=scale, slope=slope,
                               magnitude=M, names=HEXAPOD_PARAM_NAMES)
    r = np.max(np.linalg.norm(m.platform, axis=1))
    for pose in poses:
        A = m.actuator_pose_jacobian(pose)[0]
        assert_jacobian_matches_fd(lambda x: m.ik(x)[0], pose, A, scale=[ell] * 3 + [1.0] * 3,
                                   slope=[1.0 / g_min] * 3 + [r / g_min] * 3, magnitude=M, names=POSE_COLUMNS)


def test_squared_ik_residual_with_gains_against_finite_differences():
    """The squared ik-residual L_q² − L² with L_q = L0 + g q (paper 1 eq. 3 with gains): its
    gain columns are 2 L_q q_i, its L0 columns 2 L_q (by hand), and every machine column
    against central differences (helpers' error model: r is a polynomial of degree 2 in
    L0 and g, smooth on the scale of a leg length in the joints; slope twice the column)."""
    from pkmcal.identification.residuals import Model, make_method

    setup = builtin_setup("full-pose-paper1")
    nominal = with_gains(PROTOTYPE, LEAD * np.array([1.0, 1.01, 0.99, 1.0, 1.005, 0.995]), "rev")
    real = real_with_gain_errors(nominal, 2, geometry_mm=0.3)
    sim = simulate_campaign(nominal, real, setup, poses_near_home(nominal, 8, 3), 4, ignore_limits=COLLISION)
    q = sim.actuator_readings
    model = Model(nominal, setup.sensor, setup.noise, q, sim.sensor_readings, sim.commanded[sim.kept])
    meth = make_method("ik-residual", model, form="squared")
    theta = model.theta0.copy()
    n = model.n_mech
    ev = meth.evaluate(theta)
    Lq = nominal.lengths_from_readings(q)
    legs = np.arange(6)
    np.testing.assert_allclose(ev.J[:, legs, 42 + legs], 2.0 * Lq * q, rtol=1e-13, atol=0)
    np.testing.assert_allclose(ev.J[:, legs, 6 + 7 * legs], 2.0 * Lq, rtol=1e-13, atol=0)
    L = nominal.leg_lengths(ev.poses)
    J = ev.J[..., :n]
    size = np.max(np.abs(J).reshape(-1, n), axis=0)
    assert_jacobian_matches_fd(lambda t: meth.evaluate(np.r_[t, theta[n:]], jac=False, cov=False).r, theta[:n], J,
                               scale=np.r_[np.full(42, L.min()), nominal.gains], slope=2.0 * size,
                               magnitude=Lq.max() ** 2, names=model.names[:n])


# -- identification ----------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["ik-residual", "fk-residual"])
def test_noise_free_recovery_of_gains_and_geometry(method):
    """A machine read in motor revolutions whose leads are 1 % off and whose joints and L0 are
    off by up to 0.5 mm: a noise-free full-pose campaign with every parameter free gives them
    back to 1e-9 mm (geometry; gains × the largest reading, their effect on a leg length)."""
    setup = builtin_setup("full-pose-paper1")
    nominal = with_gains(PROTOTYPE, np.full(6, LEAD), "rev")
    real = real_with_gain_errors(nominal, 7)
    assert np.all(np.abs(real.gains / LEAD - 1.0) > 1e-4)
    sim = simulate_campaign(nominal, real, setup, poses_near_home(nominal, 60, 8), 9, ignore_limits=COLLISION)
    assert len(sim.kept) == 60
    res = identify(nominal, setup, q=sim.actuator_true, y=sim.sensor_true, commanded=sim.commanded,
                   method=method, free=list(HEXAPOD_PARAM_NAMES))
    assert res.gauge == () and res.identifiability.rank == 48
    est = res.mechanism.params
    np.testing.assert_allclose(est[:42], real.params[:42], rtol=0, atol=1e-9)
    reach = np.abs(sim.actuator_true).max()
    assert np.max(np.abs(est[42:] - real.gains)) * reach < 1e-9
    # and the uncertainty names the gains (identified: a finite, positive σ)
    std = res.uncertainty.std[42:48]
    assert np.all(np.isfinite(std)) and np.all(std > 0)


def test_gains_are_held_unless_freed_and_unit_gains_change_nothing():
    """Without --free the gains are held (42 free): the fit is the papers' one, the same
    numbers as a 42-parameter fit of the same data, and the held gains stay at 1."""
    setup = builtin_setup("full-pose-paper1")
    real = perturb_machine(PROTOTYPE, 1.0, np.random.default_rng(5))
    sim = simulate_campaign(PROTOTYPE, real, setup, poses_near_home(PROTOTYPE, 20, 6), 7, ignore_limits=COLLISION)
    res = identify(PROTOTYPE, setup, q=sim.actuator_readings, y=sim.sensor_readings, commanded=sim.commanded)
    assert [n for n in res.free if n.startswith("gain_")] == []
    assert len(res.free) == 42
    np.testing.assert_array_equal(res.mechanism.gains, 1.0)
    explicit = identify(PROTOTYPE, setup, q=sim.actuator_readings, y=sim.sensor_readings, commanded=sim.commanded,
                        free=list(HEXAPOD_PARAM_NAMES[:42]))
    np.testing.assert_array_equal(explicit.estimate, res.estimate)
    # freed by name: the gains are estimated (noisy data: near 1, not exactly 1)
    freed = identify(PROTOTYPE, setup, q=sim.actuator_readings, y=sim.sensor_readings, commanded=sim.commanded,
                     free=list(HEXAPOD_PARAM_NAMES[:42]) + ["gain_*"])
    assert set(GAIN_NAMES) <= set(freed.free) and len(freed.free) == 48
    assert np.all(freed.mechanism.gains != 1.0) and np.all(np.abs(freed.mechanism.gains - 1.0) < 0.01)


# -- files -------------------------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(gains=st.lists(st.one_of(st.just(1.0), st.floats(1e-6, 1e4)), min_size=6, max_size=6),
       unit=st.sampled_from(["mm", "rev", "count", "deg", "motor rev"]))
def test_machine_file_round_trip_is_exact_with_gains_and_unit(tmp_path_factory, gains, unit):
    m = replace(PROTOTYPE, gains=gains, actuator_unit=unit)
    cov = np.zeros((48, 48))
    cov[40:, 40:] = np.diag(np.linspace(1e-4, 1e-3, 8)) + 1e-5  # L0_6 and the gains, correlated
    m = replace(m, covariance=cov)
    text = machine_to_text(m)
    assert ("actuator_unit: " + unit in text) == (unit != "mm")
    assert text.count("  gain: ") == sum(g != 1.0 for g in gains)
    back = machine_from_text(text, "m.yaml")
    assert back == m and back.actuator_unit == unit
    np.testing.assert_array_equal(back.gains, gains)
    np.testing.assert_array_equal(back.covariance, m.covariance)
    assert machine_to_text(back) == text
    path = tmp_path_factory.mktemp("rt") / "m.yaml"
    save_machine(m, path)
    assert load_machine(path) == m


def test_unit_gains_write_the_same_file_as_before():
    text = machine_to_text(PROTOTYPE)
    assert "gain" not in text and "actuator_unit" not in text


@pytest.mark.parametrize("value, message", [
    ("0", "0.0 is not a leg gain: give the mm of leg length per reading unit, a number > 0"),
    ("-5.0", "-5.0 is not a leg gain"),
    (".nan", "expected a finite number, got nan"),
    (".inf", "expected a finite number"),
    ("'5'", "expected a number, got '5'"),
    ("1e9", "1000000000.0 mm per reading unit is beyond"),
])
def test_bad_gain_is_an_error_with_file_line_and_leg(tmp_path, value, message):
    text = machine_to_text(with_gains(PROTOTYPE, np.full(6, LEAD), "rev"))
    lines = text.splitlines()
    k = [i for i, line in enumerate(lines) if line.strip() == "gain: 5.0"][2]  # leg 3
    lines[k] = lines[k].replace("5.0", value)
    path = tmp_path / "bad.yaml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputFileError) as err:
        load_machine(path)
    assert f"line {k + 1}" in str(err.value) and "legs[2].gain (leg 3)" in str(err.value)
    assert message in str(err.value)
    res = CliRunner().invoke(cli, ["info", str(path)])
    assert_user_error(res, "bad.yaml", f"line {k + 1}", "legs[2].gain (leg 3)")


@pytest.mark.parametrize("value", ["''", "3", "' rev'", "[rev]"])
def test_bad_actuator_unit_is_an_error_with_its_line(value):
    text = machine_to_text(with_gains(PROTOTYPE, np.full(6, LEAD), "rev")).replace("actuator_unit: rev",
                                                                                   f"actuator_unit: {value}")
    line = text.splitlines().index(f"actuator_unit: {value}") + 1
    with pytest.raises(InputFileError, match=rf"m.yaml, line {line}: actuator_unit: "):
        machine_from_text(text, "m.yaml")


def test_bad_gain_in_the_api_is_refused():
    with pytest.raises(PkmcalError, match="leg 2 gain -1.0 is not a positive finite number"):
        replace(PROTOTYPE, gains=[1, -1, 1, 1, 1, 1])
    with pytest.raises(PkmcalError, match="leg 1 gain"):
        PROTOTYPE.with_params(np.r_[PROTOTYPE.params[:42], 0.0, np.ones(5)])


def test_leg_length_columns_convert_with_offsets_and_gains(tmp_path):
    m = with_gains(PROTOTYPE, LEAD * np.array([1.0, 1.01, 0.99, 1.02, 0.98, 1.0]), "rev")
    poses = poses_near_home(m, 5, 1)
    L = m.leg_lengths(poses)
    cols = {f"l{i + 1}": L[:, i] for i in range(6)}
    cols.update({n: np.rad2deg(poses[:, k]) if k >= 3 else poses[:, k] for k, n in enumerate(POSE_COLUMNS)})
    path = tmp_path / "legs.csv"
    path.write_text(format_table(cols))
    meas = load_measurements(path, m, builtin_setup("full-pose-paper1"))
    np.testing.assert_allclose(meas.actuators, (L - m.offset) / m.gains, rtol=0, atol=1e-12)
    assert any("(l_i - L0_i) / gain_i (rev)" in n for n in meas.notes)


def test_readings_in_another_unit_are_not_converted_by_a_length_units_line(tmp_path):
    """A '# units: length=m' line converts lengths; readings in rev are no lengths."""
    m = with_gains(PROTOTYPE, np.full(6, LEAD), "rev")
    cols = {f"lambda{i + 1}": [1.5] for i in range(6)}
    cols.update({"x": [0.0], "y": [0.0], "z": [0.3], "a": [0.0], "b": [0.0], "c": [0.0]})
    path = tmp_path / "m.csv"
    path.write_text("# units: length=m, angle=deg\n" + format_table(cols))
    meas = load_measurements(path, m, builtin_setup("full-pose-paper1"))
    np.testing.assert_array_equal(meas.actuators, 1.5)
    np.testing.assert_array_equal(meas.readings[0, :3], [0.0, 0.0, 300.0])  # the pose: metres → mm


def test_stroke_is_in_reading_units_and_its_margin_in_mm():
    """A stroke [0, 10] rev at 5 mm/rev is the 50 mm of the prototype's legs: the same verdicts
    and the same margins (mm of leg length), in the compiled kernel (≥ 64 poses) and NumPy."""
    m = with_gains(PROTOTYPE, np.full(6, LEAD), "rev")
    np.testing.assert_array_equal(m.reading_range(), PROTOTYPE.stroke / LEAD)
    poses = PROTOTYPE.home_pose + np.random.default_rng(2).uniform(-1, 1, (200, 6)) * HALF * 3.0
    for x in (poses, poses[:10]):
        a, b = m.check_limits(x), PROTOTYPE.check_limits(x)
        assert a.verdicts() == b.verdicts() and 0 < sum(a.ok) < len(x)
        np.testing.assert_allclose(a.margins["stroke"], b.margins["stroke"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.home_pose, PROTOTYPE.home_pose, rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.workspace_box(), PROTOTYPE.workspace_box(), rtol=0, atol=1e-12)


# -- LinuxCNC ----------------------------------------------------------------------------------


def test_linuxcnc_ini_values_against_a_hand_computation():
    """Leg 2 of the prototype read in rev at 5.05 mm/rev, stroke [0, 9.9] rev, home switch at
    reading 0: MIN_LIMIT = 305 + 5.05·0 = 305, MAX_LIMIT = 305 + 5.05·9.9 = 354.995,
    HOME_OFFSET = L0 = 305, HOME = the strut length at home (unchanged by gains)."""
    gains = np.array([5.0, 5.05, 4.95, 5.0, 5.0, 5.0])
    m = replace(PROTOTYPE, gains=gains, actuator_unit="rev", stroke=np.tile([0.0, 9.9], (6, 1)),
                home=PROTOTYPE.home_pose)
    np.testing.assert_array_equal(leg_gains(m), gains)
    ini = linuxcnc_ini(m, stroke_margin=0.0)         # the limits at the stroke's ends (no margin)
    section = ini.split("[JOINT_1]")[1].split("[JOINT_2]")[0]
    values = dict(line.split(" = ") for line in section.strip().splitlines())
    assert float(values["MIN_LIMIT"]) == 305.0
    assert float(values["MAX_LIMIT"]) == 305.0 + 5.05 * 9.9 == pytest.approx(354.995, abs=1e-12)
    assert float(values["HOME_OFFSET"]) == 305.0
    # the strut length at home rounded to 1 nm (export_linuxcnc.LINUXCNC_DECIMALS): half a unit of its 6th decimal
    assert float(values["HOME"]) == pytest.approx(PROTOTYPE.leg_lengths(PROTOTYPE.home_pose)[0, 1],
                                                  abs=0.5e-6 + np.spacing(1e3))
    assert "#   joint 1: gain 5.05 mm/rev" in ini and "(encoder/step counts per rev) / gain" in ini
    s = joint_settings(m, stroke_margin=0.0)
    np.testing.assert_array_equal(s["MAX_LIMIT"], 305.0 + gains * 9.9)
    # the default margin is 1 % of each joint's stroke in mm of strut: 0.01·5.05·9.9 for leg 2
    np.testing.assert_allclose(joint_settings(m)["MIN_LIMIT"][1], 305.0 + 0.01 * 5.05 * 9.9, rtol=0, atol=1e-12)
    hal = linuxcnc_hal(m, stroke_margin=0.0)
    assert "# pkmcal.joint.1 leg=2 L0=305.0 MIN_LIMIT=305.0 MAX_LIMIT=354.995" in hal and "gain=5.05" in hal
    # and a machine without gains writes exactly what it wrote before (no gain lines)
    assert "Leg gains" not in linuxcnc_ini(PROTOTYPE) and "gain=" not in linuxcnc_hal(PROTOTYPE)
    assert "Readings in" not in linuxcnc_hal(PROTOTYPE)


def test_linuxcnc_import_keeps_unit_gains_and_the_same_strut_lengths(tmp_path):
    from pkmcal.io.import_linuxcnc import machine_from_linuxcnc

    m = replace(PROTOTYPE, gains=[5.0, 5.05, 4.95, 5.0, 5.0, 5.0], actuator_unit="rev",
                stroke=np.tile([0.0, 9.9], (6, 1)), home=PROTOTYPE.home_pose)
    (tmp_path / "k.hal").write_text(linuxcnc_hal(m))
    (tmp_path / "k.ini").write_text(linuxcnc_ini(m))
    back = machine_from_linuxcnc(tmp_path / "k.hal", tmp_path / "k.ini").machine
    np.testing.assert_array_equal(back.gains, 1.0)
    assert back.actuator_unit == "mm"
    np.testing.assert_allclose(back.stroke, m.gains[:, None] * m.stroke, rtol=0, atol=1e-12)
    x = poses_near_home(m, 5, 3)
    np.testing.assert_allclose(back.lengths_from_readings(back.ik(x)), m.lengths_from_readings(m.ik(x)), atol=1e-9)


def test_json_export_lists_the_gains_and_the_unit(tmp_path):
    m = replace(PROTOTYPE, gains=[5.0, 5.05, 4.95, 5.0, 5.0, 5.0], actuator_unit="rev",
                stroke=np.tile([0.0, 9.9], (6, 1)), home=PROTOTYPE.home_pose)
    save_machine(m, tmp_path / "m.yaml")
    res = CliRunner().invoke(cli, ["export", str(tmp_path / "m.yaml"), "--format", "json"])
    assert res.exit_code == 0, res.output
    j = json.loads(res.output)
    gains = {p["name"]: p for p in j["parameters"] if p["name"].startswith("gain_")}
    assert [gains[f"gain_{i}"]["value"] for i in range(1, 7)] == list(m.gains)
    assert {p["unit"] for p in gains.values()} == {"mm/rev"}
    assert j["actuator_units"] == {f"lambda{i}": "rev" for i in range(1, 7)}


# -- the command line, end to end ----------------------------------------------------------------


def test_cli_identify_frees_the_gains_by_name(tmp_path):
    """simulate (a real machine in rev with 1 % lead errors) → identify --free '*' … 'gain_*'
    → the calibrated file has the real gains (to the data's 1e-12 noise) with their σ, and its
    unit; without --free the gains are held and the summary says so."""
    run = lambda *a: CliRunner().invoke(cli, [str(v) for v in a])
    nominal = with_gains(PROTOTYPE, np.full(6, LEAD), "rev")
    nominal = replace(nominal, limits=replace(nominal.limits, leg_diameter=None))  # see COLLISION
    real = real_with_gain_errors(nominal, 11)
    save_machine(nominal, tmp_path / "nominal.yaml")
    save_machine(real, tmp_path / "real.yaml")
    (tmp_path / "setup.yaml").write_text("sensor: full-pose\nnoise: {position: 1.0e-12, orientation_deg: 1.0e-12, "
                                         "actuator: 1.0e-12}\n")
    poses = poses_near_home(nominal, 60, 12)
    cols = {n: np.rad2deg(poses[:, k]) if k >= 3 else poses[:, k] for k, n in enumerate(POSE_COLUMNS)}
    (tmp_path / "poses.csv").write_text(format_table(cols))
    res = run("simulate", tmp_path / "nominal.yaml", "--real", tmp_path / "real.yaml", "--setup",
              tmp_path / "setup.yaml", "--poses", tmp_path / "poses.csv", "--seed", "1", "-o", tmp_path / "m.csv")
    assert res.exit_code == 0, res.output
    free = ["--free", "b*", "--free", "a*", "--free", "L0_*", "--free", "gain_*"]
    res = run("identify", tmp_path / "nominal.yaml", tmp_path / "m.csv", "--setup", tmp_path / "setup.yaml",
              "--method", "ik-residual", *free, "-o", tmp_path / "cal.yaml", "--report", tmp_path / "rep")
    assert res.exit_code == 0, res.output
    assert "rms" in res.output and " rev over lambda1, lambda2" in res.output  # the readings' residuals in rev
    # the report: residual rows in rev, the gains in mm/rev (not mm)
    html = next((tmp_path / "rep").glob("*.html")).read_text()
    assert 'gain_1</td><td class="l">mm/rev</td>' in html
    assert 'lambda1</td><td class="l">rev</td>' in html
    cal = load_machine(tmp_path / "cal.yaml")
    assert cal.actuator_unit == "rev"
    np.testing.assert_allclose(cal.params[:42], real.params[:42], rtol=0, atol=1e-8)
    assert np.max(np.abs(cal.gains - real.gains)) * 10.0 < 1e-8
    text = (tmp_path / "cal.yaml").read_text()
    assert "actuator_unit: rev" in text and "gain_1:" in text.split("uncertainty:")[1]
    info = run("info", tmp_path / "cal.yaml")
    assert info.exit_code == 0 and "mm/rev" in info.output and "stroke 0..10 rev" in info.output
    # the gains held, the real 1 % lead errors leave residuals 1e9 times the setup's 1e-12 noise: refused
    # (issue 24), the noise named; written with --accept-bad-fit
    held = run("identify", tmp_path / "nominal.yaml", tmp_path / "m.csv", "--setup", tmp_path / "setup.yaml",
               "--method", "ik-residual", "-o", tmp_path / "cal42.yaml")
    assert held.exit_code == 2 and "refused" in held.stderr and "noise far too small" in held.stderr, held.output
    held = run("identify", tmp_path / "nominal.yaml", tmp_path / "m.csv", "--setup", tmp_path / "setup.yaml",
               "--method", "ik-residual", "-o", tmp_path / "cal42.yaml", "--accept-bad-fit")
    assert held.exit_code == 0, held.output
    assert "gain_1, gain_2, gain_3, gain_4, gain_5, gain_6, which the machine holds unless freed by name" \
        in held.output
    np.testing.assert_array_equal(load_machine(tmp_path / "cal42.yaml").gains, LEAD)



def test_clipped_readings_are_reported_in_the_readings_unit(tmp_path):
    """A reading at the end of a stroke in rev is named with its unit, in text and JSON."""
    from pkmcal.io.measurements import Measurements, clipped_readings

    m = with_gains(PROTOTYPE, np.full(6, LEAD), "rev")
    lam = m.ik(poses_near_home(m, 3, 2))
    lam[1, 2] = m.stroke[2, 1]  # stuck at the top of its stroke
    meas = Measurements(actuators=lam, readings=np.zeros((3, 6)))
    (found,) = clipped_readings(meas, m)
    assert found.actuator == "lambda3" and found.kind == "at-end" and found.pose == 2
    assert found.describe("rev").endswith("[0.0, 10.0] rev")
    d = found.to_dict("rev")
    assert d["reading"] == 10.0 and d["stroke"] == [0.0, 10.0] and d["units"]["reading"] == "rev"
    assert "reading_mm" in found.to_dict("mm")


def test_residual_units_of_readings_in_their_own_unit():
    """Actuator residual rows carry the readings' unit; a label that reads like an angle unit
    ("deg" of a motor, never converted) is marked as a reading unit, so the report does not
    treat it as an angle."""
    from pkmcal.report.from_results import residual_units

    setup = builtin_setup("full-pose-paper1")
    names = ("lambda1", "x", "a")
    assert residual_units(names, setup, PROTOTYPE) == ("mm", "mm", "rad")
    assert residual_units(names, setup, with_gains(PROTOTYPE, np.full(6, LEAD), "rev")) == ("rev", "mm", "rad")
    assert residual_units(names, setup, with_gains(PROTOTYPE, np.full(6, 0.01), "deg"))[0] == "deg (reading)"

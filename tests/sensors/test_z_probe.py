"""The z-probe sensor (issue 13, item 3): a delta printer's probe reading its height above a
bed plane, its setup file, Klipper's probe output read as measurements, and what Z-probe
campaigns identify on the built-in ``kossel-mini``.

Checks: the readings against closed forms (a level bed: p_z − o_z − z_b; a point of the
tilted plane reads 0; the reading is the vertical distance); the analytic twist and
parameter Jacobians against central differences on rotated frames and tilted beds; the
declared ``readable``/``works_with``; the setup file's keys, errors and exact round trip;
the gauge (probe z offset and bed height one direction, named by the identifiability
report); Klipper's log lines (both formats) and the ``#*#`` stable positions back to the
carriage positions they came from; and simulated probing campaigns (the probe descends
the firmware's vertical line until the real probe point meets the real bed): noise-free
recovery to 1e-9 of what is identifiable, the common arm/radius scale reported as not
determined by Z heights alone, and a fit with priors on the arms recovering the truth
within its σ.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_jacobian_matches_fd, probe_triggers
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.conventions import euler_to_matrix, rotation_vector_to_matrix
from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.identifiability import identifiability
from pkmcal.identification.priors import Prior
from pkmcal.io.klipper_probe import read_klipper_probe
from pkmcal.io.machine_file import load_machine
from pkmcal.io.measurements import Measurements, load_measurements
from pkmcal.io.setup_file import load_setup, setup_to_yaml
from pkmcal.mechanisms.frame import Frame
from pkmcal.mechanisms.linear_delta import PARAM_NAMES
from pkmcal.sensors.base import NoiseModel
from pkmcal.sensors.z_probe import ZProbeSensor

KLIPPER_SET = tuple(f"{p}_{t}" for p in ("angle", "radius", "arm", "endstop") for t in "abc")
#: A gauge of the Klipper set on a level bed: tower c's position and tower b's radius pin the
#: rotation about z and the horizontal translation, which no height sees.
GAUGE = ("angle_c", "radius_b", "radius_c")


def _disc(n, radius, rng):
    r = radius * np.sqrt(rng.uniform(size=n))
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(t), r * np.sin(t)]


def _real(nominal, rng, free, mm=0.5, deg=0.3):
    rho = nominal.params.copy()
    for name in free:
        rho[PARAM_NAMES.index(name)] += rng.standard_normal() * (np.deg2rad(deg) if "angle" in name else mm)
    return nominal.with_params(rho, name="real")


def _frames(rng, n, tilt=0.4):
    p = rng.uniform(-80, 80, (n, 3))
    return Frame(p=p, R=euler_to_matrix(rng.uniform(-tilt, tilt, (n, 3))))


def _sensor(rng):
    return ZProbeSensor(probe_offset=rng.uniform(-30, 30, 3), bed=np.r_[rng.uniform(-2, 2), rng.uniform(-0.1, 0.1, 2)])


# -- the model -----------------------------------------------------------------------------


def test_level_bed_reading_is_the_probe_point_height():
    s = ZProbeSensor(probe_offset=[12.0, -7.0, 1.5], bed=[0.25, 0.0, 0.0])
    p = np.array([[10.0, 20.0, 3.0], [-40.0, 5.0, 0.0]])
    y = s.predict(Frame(p=p, R=np.broadcast_to(np.eye(3), (2, 3, 3)).copy()))
    np.testing.assert_allclose(y[:, 0], p[:, 2] - 1.5 - 0.25, rtol=0, atol=1e-14)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_a_point_of_the_bed_reads_zero_and_height_is_vertical(seed):
    rng = np.random.default_rng(seed)
    s = _sensor(rng)
    zb, a, b = s.bed
    n = euler_to_matrix(np.array([a, b, 0.0])) @ np.array([0.0, 0.0, 1.0])
    frames = _frames(rng, 6)
    t = frames.R @ np.array([s.probe_offset[0], s.probe_offset[1], -s.probe_offset[2]])
    # move each frame onto the plane along z: the probe point on the bed reads 0
    P = frames.p + t
    z_on = zb - (n[0] * P[:, 0] + n[1] * P[:, 1]) / n[2]
    on_bed = Frame(p=frames.p + np.c_[np.zeros((6, 2)), z_on - P[:, 2]], R=frames.R)
    np.testing.assert_allclose(s.predict(on_bed)[:, 0], 0.0, rtol=0, atol=1e-12)
    # raised by h along z, it reads h (the vertical distance, not the normal one)
    h = rng.uniform(-5, 5, 6)
    raised = Frame(p=on_bed.p + np.c_[np.zeros((6, 2)), h], R=frames.R)
    np.testing.assert_allclose(s.predict(raised)[:, 0], h, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_twist_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    s, frames = _sensor(rng), _frames(rng, 7)
    J = s.frame_jacobian(frames)

    def f(tw):
        R = rotation_vector_to_matrix(tw[:, 3:6]) @ frames.R
        return s.predict(Frame(p=frames.p + tw[:, 0:3], R=R))

    assert_jacobian_matches_fd(f, np.zeros((7, 6)), J, scale=[100.0] * 3 + [1.0] * 3, magnitude=300.0,
                               names=["dpx", "dpy", "dpz", "dwx", "dwy", "dwz"])


@pytest.mark.parametrize("seed", range(4))
def test_parameter_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(10 + seed)
    s, frames = _sensor(rng), _frames(rng, 7)
    J = s.param_jacobian(frames)
    # θ is shared by every frame: f maps θ (6,) to the readings (N, 1)
    assert_jacobian_matches_fd(lambda th: s.predict(frames, params=th), s.params, J,
                               scale=[100.0, 100.0, 10.0, 10.0, 1.0, 1.0], magnitude=300.0, names=s.param_names)
    assert np.all(J[:, 0, 3] == -1.0)


def test_explicit_params_equal_with_params():
    rng = np.random.default_rng(4)
    s, frames = _sensor(rng), _frames(rng, 5)
    theta = s.params + rng.uniform(-0.01, 0.01, 6)
    other = s.with_params(theta)
    for method in ("predict", "frame_jacobian", "param_jacobian"):
        np.testing.assert_array_equal(getattr(s, method)(frames, params=theta), getattr(other, method)(frames))


def test_readable_and_works_with_are_declared():
    s = ZProbeSensor()
    level = Frame(p=np.zeros((2, 3)), R=np.broadcast_to(np.eye(3), (2, 3, 3)).copy())
    ok, _ = s.readable(level)
    assert ok.all()
    tilted = Frame(p=np.zeros((2, 3)), R=euler_to_matrix(np.array([[0.0, np.deg2rad(44), 0.0],
                                                                   [np.deg2rad(46), 0.0, 0.0]])))
    ok, why = s.readable(tilted)
    assert ok.tolist() == [True, False] and "probe axis" in why
    assert s.works_with(load_machine("kossel-mini")) is None
    assert "planar" in s.works_with(load_machine("planar-2dof-3act"))


# -- the setup file ------------------------------------------------------------------------


def test_setup_file_reads_the_documented_keys_and_round_trips(tmp_path):
    path = tmp_path / "probe.yaml"
    path.write_text("sensor: z-probe\nprobe_offset: [12.5, -3, 1.25]\nbed: {z: 0.1, a: 0.3, b: -0.2}\n"
                    "free: [bed.a, bed.b]\nnoise: {reading: 0.005, actuator: 0.0036}\n")
    setup = load_setup(path)
    s = setup.sensor
    assert s.kind == "z-probe" and s.reading_names == ("probe_z",)
    np.testing.assert_array_equal(s.probe_offset, [12.5, -3.0, 1.25])
    assert s.bed[0] == 0.1 and s.bed[1] == pytest.approx(np.deg2rad(0.3), rel=1e-15)
    assert s.default_free == ("bed.a", "bed.b")
    again = tmp_path / "again.yaml"
    again.write_text(setup_to_yaml(setup))
    assert load_setup(again) == setup


@pytest.mark.parametrize("text, fragments", [
    ("sensor: z-probe\nbed: {z: 0, a: 60}\nnoise: {reading: 0.005, actuator: 0.004}\n", ("line 2", "bed.a", "45")),
    ("sensor: z-probe\nnoise: {actuator: 0.004}\n", ("noise.reading", "is missing", "PROBE_ACCURACY")),
    ("sensor: z-probe\nprobe_offset: [1, 2]\nnoise: {reading: 0.005, actuator: 0.004}\n", ("probe_offset",)),
    ("sensor: z-probe\ntarget: {x: 1}\nnoise: {reading: 0.005, actuator: 0.004}\n", ("target", "probe_offset, bed")),
    ("sensor: z-probe\nfree: [probe.w]\nnoise: {reading: 0.005, actuator: 0.004}\n", ("probe.w", "probe.x")),
])
def test_setup_file_errors_name_the_key(tmp_path, text, fragments):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(PkmcalError) as err:
        load_setup(path)
    for fragment in fragments:
        assert fragment in str(err.value), str(err.value)


def test_builtin_setup():
    setup = load_setup("z-probe-klipper", load_machine("kossel-mini"))
    assert setup.sensor == ZProbeSensor() and setup.sensor.default_free == ()
    assert setup.noise.reading_std.tolist() == [0.005]
    assert float(setup.noise.actuator_std) == pytest.approx(0.0125 / math.sqrt(12), rel=1e-15)


# -- the gauge -----------------------------------------------------------------------------


def test_probe_z_offset_and_bed_height_are_one_direction():
    """Freed, the bed height adds one unseen direction (with a common shift of the endstops)
    and the probe's z offset another: probe.z − bed.z, named as such by the report."""
    nominal = load_machine("kossel-mini")
    setup = load_setup("z-probe-klipper", nominal)
    poses = np.c_[_disc(40, 80, np.random.default_rng(0)), np.zeros(40)]
    deficit = {}
    for extra in ((), ("bed.z",), ("bed.z", "probe.z")):
        rep = identifiability(nominal, setup, poses, free=list(KLIPPER_SET) + list(extra))
        deficit[extra] = rep.n_params - rep.rank
    assert list(deficit.values()) == [3, 4, 5]
    named = [{k: round(v, 9) for k, v in d.items()} for d in rep.null_space]
    assert {"probe.z": 1.0, "bed.z": -1.0} in named, named


# -- Klipper's output ----------------------------------------------------------------------


def test_probe_lines_give_back_the_carriage_positions(tmp_path):
    """Both of Klipper's line formats: λ = IK(nozzle) of the firmware's machine; the newer
    format's probe point is shifted back by the setup's offset."""
    m = load_machine("kossel-mini")
    nozzle = np.array([[0.0, 0.0, 0.123456], [-61.5, 35.25, -0.04], [12.0, -70.125, 0.5]])
    offset = np.array([5.0, -12.5, 1.75])
    old = "\n".join(f"Recv: // probe at {x:.3f},{y:.3f} is z={z:.6f}" for x, y, z in nozzle)
    new = "\n".join(f"// probe: at {x + offset[0]:.3f},{y + offset[1]:.3f} bed will contact at z={z - offset[2]:.6f}"
                    for x, y, z in nozzle)
    for text in (old, new):
        path = tmp_path / "console.log"
        path.write_text("PROBE_ACCURACY at X:0.000 Y:0.000 Z:10.000\n" + text + "\n// Result is z=0.123456\n")
        got = read_klipper_probe(path, m, offset).measurements
        np.testing.assert_allclose(got.actuators, m.ik(nozzle), rtol=0, atol=1e-9)
        np.testing.assert_array_equal(got.readings[:3], np.zeros((3, 1)))
        np.testing.assert_allclose(got.commanded, nozzle, rtol=0, atol=1e-9)
        assert got.lines.tolist() == [2, 3, 4]


def test_saved_block_stable_positions_give_back_the_carriage_positions(tmp_path):
    """#*# heightN_pos are steps below each endstop (Klipper's calc_stable_position:
    (abs_endstop − stepper position)/step distance); λ = H^fw − steps·step distance."""
    from pkmcal.io.delta_firmware import read_klipper

    nozzle = np.array([[0.0, 0.0, 1.25], [0.0, 76.0, 1.25], [-62.3538, -36.0, 1.25]])
    base = ("[printer]\nkinematics: delta\ndelta_radius: 105.2\n\n"
            "[stepper_a]\nrotation_distance: 40\nmicrosteps: 16\narm_length: 215\nposition_endstop: 250\n\n"
            "[stepper_b]\nrotation_distance: 40\nmicrosteps: 16\n\n"
            "[stepper_c]\nstep_distance: 0.0125\n\n")
    path = tmp_path / "printer.cfg"
    path.write_text(base)
    m = read_klipper(str(path)).machine("p")
    sd = 40.0 / (200 * 16)
    steps = (m.reading_reference[None, :] - m.ik(nozzle)) / sd
    # the header Klipper's SAVE_CONFIG writes (klippy/configfile.py AUTOSAVE_HEADER): a block
    # under its first line only is not read by Klipper, nor now by pkmcal
    block = ["#*# <---------------------- SAVE_CONFIG ---------------------->",
             "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.", "#*#", "#*# [delta_calibrate]"]
    for k, row in enumerate(steps):
        block += [f"#*# height{k} = 1.25", f"#*# height{k}_pos = " + ",".join(f"{v:.3f}" for v in row)]
    block += ["#*# manual_height0 = 0.1", "#*# manual_height0_pos = 1.0,2.0,3.0"]
    path.write_text(base + "\n".join(block) + "\n")
    res = read_klipper_probe(path, m, (0.0, 0.0, 1.25))
    got = res.measurements
    # the manual height (DELTA_ANALYZE MANUAL_HEIGHT: the nozzle measured 0.1 above the bed) is
    # read after the probe heights: its carriages from its steps, probe_z = 0.1 - z_offset
    manual_steps = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(got.actuators[3], m.reading_reference - manual_steps * np.array([sd, sd, 0.0125]),
                               rtol=0, atol=1e-9)
    assert got.readings[3, 0] == pytest.approx(0.1 - 1.25, abs=1e-12)
    assert any("1 manual height(s)" in n for n in res.notes)
    # %.3f steps: within 0.0005 step
    np.testing.assert_allclose(got.actuators[:3], m.ik(nozzle), rtol=0, atol=0.0005 * sd * 1.000001)
    np.testing.assert_array_equal(got.readings[:3], np.zeros((3, 1)))
    np.testing.assert_allclose(got.commanded[:3], nozzle, rtol=0, atol=1e-3)
    # the gear ratio divides the step; a missing microsteps is named
    path.write_text(base.replace("microsteps: 16\narm", "microsteps: 16\ngear_ratio: 2:1\narm") + "\n".join(block))
    lam_a = read_klipper_probe(path, m, (0.0, 0.0, 1.25)).measurements.actuators[:3, 0]
    np.testing.assert_allclose(m.reading_reference[0] - lam_a, steps[:, 0] * sd / 2, rtol=1e-6, atol=1e-9)
    path.write_text(base.replace("microsteps: 16\n\n[stepper_c]", "\n[stepper_c]") + "\n".join(block))
    with pytest.raises(PkmcalError, match=r"\[stepper_b\] has rotation_distance but no microsteps"):
        read_klipper_probe(path, m)
    # the printer's [probe] offsets against the setup's: x, y must agree, a z difference is noted
    path.write_text(base + "[probe]\npin: ^PA1\nx_offset: 0\ny_offset: 18\nz_offset: 1.0\n" + "\n".join(block) + "\n")
    with pytest.raises(PkmcalError, match=r"\[probe\] x_offset, y_offset are 0, 18 mm but the setup's probe_offset has "
                                          r"0, 0.*--setup-output"):
        read_klipper_probe(path, m, (0.0, 0.0, 1.25))
    # a manual height is the nozzle's: not read as a probe with an x, y offset
    with pytest.raises(PkmcalError, match=r"manual_height0: a manual height is the nozzle's"):
        read_klipper_probe(path, m, (0.0, 18.0, 1.25))
    path.write_text(path.read_text().replace("#*# manual_height0 = 0.1\n#*# manual_height0_pos = 1.0,2.0,3.0\n", ""))
    res = read_klipper_probe(path, m, (0.0, 18.0, 1.25))
    assert any("z_offset 1 mm, the setup's 1.25 mm" in n for n in res.notes)


def test_files_without_probe_results_are_refused(tmp_path):
    path = tmp_path / "empty.log"
    path.write_text("Starting Klippy...\n// probe: open\n")
    with pytest.raises(PkmcalError, match="no probe results found"):
        read_klipper_probe(path, load_machine("kossel-mini"))
    path.write_text("// probe at 900.000,0.000 is z=0.000000\n")
    with pytest.raises(PkmcalError, match=r"line 1: .*out of the reach"):
        read_klipper_probe(path, load_machine("kossel-mini"))


def test_import_command_writes_a_measurement_file_that_loads(tmp_path):
    out = tmp_path / "meas.csv"
    res = CliRunner().invoke(cli, ["import", "klipper-probe", "examples/klipper/probe-console.log", "--machine",
                                   "kossel-mini", "-o", str(out)])
    assert res.exit_code == 0, res.output
    m = load_machine("kossel-mini")
    setup = load_setup("z-probe-klipper", m)
    meas = load_measurements(out, m, setup)
    assert len(meas) == 31 and np.all(meas.readings == 0.0)
    assert out.read_text().splitlines()[0] == "lambda1,lambda2,lambda3,probe_z,cmd_x,cmd_y,cmd_z"
    bad = CliRunner().invoke(cli, ["import", "klipper-probe", "examples/klipper/probe-console.log", "--machine",
                                   "kossel-mini", "--setup", "laser-tracker"])
    assert bad.exit_code == 2 and "sensor: z-probe" in bad.output


# -- campaigns on the kossel-mini ------------------------------------------------------------


def _noise_free(setup):
    return dataclasses.replace(setup, noise=NoiseModel(reading_std=np.zeros(1), actuator_std=np.array(0.0)))


def _campaign(seed, n, noisy):
    """A probing campaign on a kossel-mini whose Klipper parameters (but the gauge) are off by
    ~0.5 mm / 0.3°: n points on the bed, with the setup's trigger and carriage noise if
    ``noisy``. Returns (nominal, setup, free names, real machine, measurements, rng)."""
    nominal = load_machine("kossel-mini")
    setup = load_setup("z-probe-klipper", nominal)
    rng = np.random.default_rng(seed)
    free = [name for name in KLIPPER_SET if name not in GAUGE]
    real = _real(nominal, rng, free)
    lam, cmd = probe_triggers(nominal, real, setup.sensor, _disc(n, 80, rng), noise=0.005 if noisy else 0.0, rng=rng)
    if noisy:
        lam = lam + rng.standard_normal(lam.shape) * float(setup.noise.actuator_std)
    meas = Measurements(actuators=lam, readings=np.zeros((n, 1)), commanded=cmd)
    return nominal, setup, free, real, meas, rng


def test_noise_free_probing_recovers_the_identifiable_parameters():
    nominal, setup, free, real, meas, rng = _campaign(21, 60, noisy=False)
    fit = identify(nominal, _noise_free(setup), meas, free=free, weighted=False, xtol=1e-15, ftol=1e-15,
                   gtol=1e-15)
    assert fit.success and fit.rms_residual < 1e-9
    idx = [PARAM_NAMES.index(n) for n in free]
    np.testing.assert_allclose(fit.mechanism.params[idx], real.params[idx], rtol=0, atol=1e-9)
    # held out: where the real probe triggers, the calibrated model says the probe touches
    lam2, _ = probe_triggers(nominal, real, setup.sensor, _disc(30, 85, rng))
    cal = fit.mechanism
    y = setup.sensor.predict(cal.frame(cal.fk(lam2).poses))
    np.testing.assert_allclose(y, 0.0, rtol=0, atol=1e-9)


def test_z_heights_alone_do_not_determine_the_arm_scale(tmp_path):
    """The common scale of arms and radius is named (not determined, with its σ and the fix);
    the Klipper parameters a probe sees are identified, the rotation about z is not."""
    nominal = load_machine("kossel-mini")
    setup = load_setup("z-probe-klipper", nominal)
    xy = _disc(60, 80, np.random.default_rng(7))
    poses = tmp_path / "P.csv"
    poses.write_text("x,y,z\n" + "\n".join(f"{float(x)!r},{float(y)!r},0.0" for x, y in xy) + "\n")
    rep = identifiability(nominal, setup, np.c_[xy, np.zeros(60)])
    scale, shift_x, shift_y = rep.named
    assert scale["meaning"] == "a common scale of the arm lengths and the radius"
    # the towers' slide on the bed: unseen, said so with its unbounded sigma (issue 25 item 2)
    assert shift_x["status"] == shift_y["status"] == "unidentifiable" and shift_x["placement"]
    assert scale["status"] == "not determined" and scale["sigma"] > 5e-3
    # the rotation about z (the three tower angles together) is in the unseen span
    N = np.array([[d.get(n, 0.0) for n in rep.names] for d in rep.null_space]).T
    rot = np.array([1.0 if n.startswith("angle_") else 0.0 for n in rep.names])
    coef = np.linalg.lstsq(N, rot, rcond=None)[0]
    np.testing.assert_allclose(N @ coef, rot, rtol=0, atol=1e-6)
    res = CliRunner().invoke(cli, ["identifiability", "kossel-mini", "--setup", "z-probe-klipper", "--poses",
                                   str(poses)])
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.splitlines() if ln.startswith("a common scale"))
    assert "not determined by these measurements" in line and "--prior 'arm_*=215±0.1'" in line
    # a tracker sees lengths: the same poses determine the scale
    tracker = identifiability(nominal, load_setup("laser-tracker", nominal), np.c_[xy, np.full(60, 50.0)])
    assert tracker.named[0]["status"] == "identified"
    # and, its frame being the machine's, where the towers stand
    assert [e["status"] for e in tracker.named[1:]] == ["identified"] * 2
    # with the Klipper parameters only, the gauge held, the probe identifies every one of them
    klip = identifiability(nominal, setup, np.c_[xy, np.zeros(60)], free=[n for n in KLIPPER_SET if n not in GAUGE])
    assert klip.identifiable


def test_priors_on_the_arms_give_a_fit_within_its_sigma():
    nominal, setup, free, real, meas, rng = _campaign(5, 80, noisy=True)
    arms = real.params[[PARAM_NAMES.index(f"arm_{t}") for t in "abc"]]
    measured = arms + 0.1 * rng.standard_normal(3)           # rods measured to ±0.1 mm
    priors = tuple(Prior(f"arm_{t}", float(v), 0.1) for t, v in zip("abc", measured))
    fit = identify(nominal, setup, meas, free=free, priors=priors)
    assert fit.success
    idx = [PARAM_NAMES.index(n) for n in fit.free]
    z = (fit.mechanism.params[idx] - real.params[idx]) / fit.std
    assert np.all(np.abs(z) < 4.0), dict(zip(fit.free, z))
    # the prior narrows the arms: below the probe-only σ
    alone = identify(nominal, setup, meas, free=free)
    arm_pos = [fit.free.index(f"arm_{t}") for t in "abc"]
    assert np.all(fit.std[arm_pos] < alone.std[arm_pos])


def test_named_direction_sigma_is_the_covariance_of_its_amount():
    """Independent check of the named-direction verdict: on a full-rank whitened J with
    unit-norm scaling D = diag(1/‖J_:,i‖), the amount of d in θ is the coordinate along d in
    the scaled columns, ε = cᵀθ with c = D⁻²d/‖D⁻¹d‖², so σ_ε² = cᵀ(JᵀJ)⁻¹c; a direction in
    the null space is unidentifiable; one only partly a gauge change is judged on the rest."""
    from pkmcal.identification.identifiability import describe_named, named_directions_report
    from pkmcal.mechanisms.base import NamedDirection

    rng = np.random.default_rng(3)
    J = rng.standard_normal((40, 5)) * np.array([1.0, 10.0, 0.1, 3.0, 1.0])
    d = {"p0": 2.0, "p1": -0.5, "p3": 1.0}
    nd = NamedDirection("a test direction", d, "1", 1e-6, "test", "measure more")
    (entry,) = named_directions_report(J, ["p0", "p1", "p2", "p3", "p4"], [nd])
    dv = np.array([2.0, -0.5, 0.0, 1.0, 0.0])
    D2 = np.sum(J**2, axis=0)                                  # D⁻² (D = diag(1/‖J_:,i‖))
    c = D2 * dv / (dv @ (D2 * dv))
    expected = np.sqrt(c @ np.linalg.inv(J.T @ J) @ c)
    assert entry["sigma"] == pytest.approx(expected, rel=1e-10)
    assert entry["status"] == "not determined" and "measure more" in describe_named(entry)
    # a direction along which no reading changes
    Jn = J.copy()
    Jn[:, 4] = Jn[:, 0] * 2.0 - Jn[:, 1] * 0.5 + Jn[:, 3]            # p4 ≡ d: d − p4 is a gauge change
    null_dir = NamedDirection("null", {"p0": 2.0, "p1": -0.5, "p3": 1.0, "p4": -1.0}, "1", 1.0, "t", "r")
    entries = named_directions_report(Jn, ["p0", "p1", "p2", "p3", "p4"], [null_dir, nd])
    assert entries[0]["status"] == "unidentifiable" and entries[0]["sigma"] == float("inf")
    # d itself equals a change of p4 alone (modulo the gauge): judged as that change
    only = named_directions_report(Jn[:, [0, 1, 2, 3]], ["p0", "p1", "p2", "p3"], [nd])[0]
    assert entries[1]["sigma"] < 10 * only["sigma"] and np.isfinite(entries[1]["sigma"])
    # a direction with a parameter that is not a candidate is left out
    assert named_directions_report(J[:, :3], ["p0", "p1", "p2"], [nd]) == []

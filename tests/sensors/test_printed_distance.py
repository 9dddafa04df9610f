"""Printed-object distances (issue 13, item 3): Klipper's DELTA_ANALYZE read as two-pose
measurements (``sensors/printed_distance.py`` on ``mechanisms/pose_pairs.py``), its files
(``io/klipper_analyze.py``, ``pkmcal import klipper-analyze``) and what the distances add.

Checks: readings against their closed forms (a distance row reads ‖p_1 − p_2‖, a height row
the Z probe's reading); the sensor's twist Jacobian against central differences on distance
rows and equal to the Z probe's on height rows; the pair machine's IK, A, B, T and FK
against the single machine's and against finite differences; the engine's composed
fk-residual Jacobian of pair rows against finite differences of its residual; Klipper's
object points against the numbers of ``delta_calibrate.py``; the #*# block and the
DELTA_ANALYZE console lines back to the carriage positions; the setup file round trip; and
simulated Klipper campaigns: Z heights alone leave the arm/radius scale undetermined, Z
heights with the printed distances determine it, and a noise-free fit recovers Klipper's
ten numbers (through the exact firmware rewrite; the rotation about z, which nothing here
sees, compared as angle differences) to 1e-9.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_jacobian_matches_fd

from pkmcal.cli.main import cli
from pkmcal.conventions import euler_to_matrix
from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.identifiability import identifiability
from pkmcal.identification.residuals import Model, make_method
from pkmcal.io.delta_firmware import firmware_subset
from pkmcal.io.klipper_analyze import corrected_distances, object_point_pairs, read_klipper_analyze
from pkmcal.io.measurements import Measurements, load_measurements
from pkmcal.io.setup_file import load_setup, setup_to_yaml
from pkmcal.mechanisms.frame import Frame
from pkmcal.mechanisms.linear_delta import klipper_delta
from pkmcal.mechanisms.pose_pairs import PairFrame, PosePairs
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.library import builtin_setup
from pkmcal.sensors.printed_distance import PrintedDistanceSensor
from pkmcal.sensors.z_probe import ZProbeSensor

KLIPPER_SET = tuple(f"{p}_{t}" for p in ("angle", "radius", "arm", "endstop") for t in "abc")
FIRMWARE = klipper_delta("firmware", 105.0, 215.0, 250.0)
#: The real printer, its carriage readings those of the firmware's configuration (homed at
#: the real switches, which the firmware believes at its own switch readings).
REAL = FIRMWARE.with_params(klipper_delta("real", 105.3, (215.4, 214.8, 215.2), (250.3, 249.7, 250.9),
                                          (210.2, 329.6, 90.0)).params, name="real")


def _pair_frames(rng, n, tilt=0.3) -> PairFrame:
    f1 = Frame(p=rng.uniform(-80, 80, (n, 3)), R=euler_to_matrix(rng.uniform(-tilt, tilt, (n, 3))))
    f2 = Frame(p=rng.uniform(-80, 80, (n, 3)), R=euler_to_matrix(rng.uniform(-tilt, tilt, (n, 3))))
    same = np.arange(n) % 3 == 0                              # every third row a height row
    f2.p[same], f2.R[same] = f1.p[same], f1.R[same]
    return PairFrame(f1, f2), same


def _sensor(rng) -> PrintedDistanceSensor:
    return PrintedDistanceSensor(probe_offset=rng.uniform(-20, 20, 3),
                                 bed=np.r_[rng.uniform(-1, 1), rng.uniform(-0.05, 0.05, 2)])


def probed(xy) -> tuple[np.ndarray, np.ndarray]:
    """Klipper's probing of ``REAL`` under ``FIRMWARE`` (probe at the nozzle, level bed z = 0):
    the firmware lowers its nozzle at (x, y) until the real nozzle touches the bed. Returns
    the carriage positions and the firmware's nozzle positions at the triggers."""
    xy = np.asarray(xy, dtype=float)
    z = np.zeros(len(xy))
    for _ in range(8):          # z ← z − h: the real height moves 1:1 with the firmware's z to first order
        lam = FIRMWARE.ik(np.c_[xy, z])
        z = z - REAL.fk(lam).poses[:, 2]
    lam = FIRMWARE.ik(np.c_[xy, z])
    assert np.max(np.abs(REAL.fk(lam).poses[:, 2])) < 1e-12
    return lam, np.c_[xy, z]


def klipper_points(n_extra: int = 0) -> np.ndarray:
    """DELTA_CALIBRATE's probe points (centre and six at 95…70 % of radius 80 mm) and
    ``n_extra`` more on a ring of 60 mm."""
    r = np.deg2rad(90.0 + 60.0 * np.arange(6))
    dist = 80.0 * np.array([0.95, 0.90, 0.85, 0.70, 0.75, 0.80])
    extra = 2 * np.pi * np.arange(n_extra) / max(n_extra, 1)
    return np.r_[[[0.0, 0.0]], np.c_[np.cos(r) * dist, np.sin(r) * dist], np.c_[60 * np.cos(extra), 60 * np.sin(extra)]]


def campaign(n_extra: int = 0) -> Measurements:
    """Heights at Klipper's probe points and the 12 printed distances of Klipper's object,
    printed by ``FIRMWARE`` on ``REAL``, as pair rows."""
    lam_h, cmd_h = probed(klipper_points(n_extra))
    p1, p2 = object_point_pairs()
    l1, l2 = FIRMWARE.ik(p1), FIRMWARE.ik(p2)
    d = np.linalg.norm(REAL.fk(l1).poses - REAL.fk(l2).poses, axis=1)
    n = len(lam_h)
    return Measurements(actuators=np.r_[np.c_[lam_h, lam_h], np.c_[l1, l2]],
                        readings=np.r_[np.zeros((n, 2)), np.c_[np.zeros(12), d]],
                        commanded=np.r_[np.c_[cmd_h, cmd_h], np.c_[p1, p2]])


def _noise_free(setup):
    return MeasurementSetup(setup.sensor, NoiseModel(np.ones(2), np.ones(1)))


# -- the sensor ------------------------------------------------------------------------------


def test_readings_are_the_distance_or_the_probe_height():
    rng = np.random.default_rng(3)
    frame, same = _pair_frames(rng, 12)
    s = _sensor(rng)
    y = s.predict(frame)
    probe = ZProbeSensor(probe_offset=s.probe_offset, bed=s.bed).predict(frame.first)[:, 0]
    np.testing.assert_array_equal(y[same, 0], probe[same])
    np.testing.assert_array_equal(y[same, 1], 0.0)
    np.testing.assert_array_equal(y[~same, 0], 0.0)
    np.testing.assert_allclose(y[~same, 1], np.linalg.norm(frame.p - frame.second.p, axis=1)[~same], rtol=1e-15)
    ok, _ = s.readable(frame)
    assert ok[~same].all()


def test_twist_jacobian_matches_finite_differences_and_the_probe():
    rng = np.random.default_rng(4)
    frame, same = _pair_frames(rng, 9)
    s = _sensor(rng)
    J = s.frame_jacobian(frame)
    far = ~same

    def f(tw):
        return s.predict(frame[far].moved(tw))

    assert_jacobian_matches_fd(f, np.zeros((int(far.sum()), 12)), J[far], scale=[100.0] * 3 + [1.0] * 3 + [100.0] * 3
                               + [1.0] * 3, magnitude=300.0)
    probe = ZProbeSensor(probe_offset=s.probe_offset, bed=s.bed)
    np.testing.assert_array_equal(J[same, 0, 0:6], probe.frame_jacobian(frame.first[same])[:, 0])
    assert not J[same, 0, 6:].any() and not J[same, 1].any()
    # the parameter Jacobian is the probe's on height rows, zero on distance rows
    G = s.param_jacobian(frame)
    np.testing.assert_array_equal(G[same, 0], probe.param_jacobian(frame.first[same])[:, 0])
    assert not G[far].any() and not G[:, 1].any()


def test_works_only_on_pose_pairs():
    s = PrintedDistanceSensor()
    assert "pose pairs" in s.works_with(FIRMWARE)
    assert s.works_with(PosePairs(FIRMWARE)) is None
    with pytest.raises(PkmcalError, match="reads pairs of poses"):
        builtin_setup("printed-distance-klipper", FIRMWARE)


# -- the pair machine ------------------------------------------------------------------------


def test_pair_machine_is_the_machine_twice_with_exact_jacobians():
    rng = np.random.default_rng(5)
    pairs = PosePairs(REAL)
    x1 = np.c_[rng.uniform(-50, 50, (6, 2)), rng.uniform(0, 80, 6)]
    x2 = np.c_[rng.uniform(-50, 50, (6, 2)), rng.uniform(0, 80, 6)]
    X = np.c_[x1, x2]
    q, A, B = pairs.ik_and_jacobians(X)
    np.testing.assert_array_equal(q, np.c_[REAL.ik(x1), REAL.ik(x2)])
    assert_jacobian_matches_fd(pairs.ik, X, A, scale=100.0)
    assert_jacobian_matches_fd(lambda r: np.stack([pairs.ik(X, params=ri) for ri in r]), REAL.params[None, :],
                               B[None], scale=[1.0 if a else 100.0 for a in REAL.param_is_angle])
    fk = pairs.fk(q)
    assert fk.converged.all()
    np.testing.assert_allclose(fk.poses, X, rtol=0, atol=1e-10)
    T, Tr = pairs.frame_jacobians(X)
    assert Tr is None and T.shape == (6, 12, 6)
    J = rng.standard_normal((6, 2, 12))
    np.testing.assert_array_equal(pairs.pose_jacobian_from_twist(J, X), J @ T)
    np.testing.assert_array_equal(pairs.poses_from_frame(pairs.frame(X)), X)
    assert pairs.param_names == REAL.param_names and pairs.with_params(FIRMWARE.params).single == \
        REAL.with_params(FIRMWARE.params)
    assert pairs.actuator_names[3:] == ("lambda1_2", "lambda2_2", "lambda3_2")


def test_fk_residual_jacobian_of_pair_rows_matches_finite_differences():
    """The engine, unchanged, differentiates a distance through both poses' FK."""
    meas = campaign()
    setup = builtin_setup("printed-distance-klipper", PosePairs(FIRMWARE))
    sensor = PrintedDistanceSensor(probe_offset=[1.0, -2.0, 0.5], bed=[0.1, 0.002, -0.003])
    model = Model(PosePairs(FIRMWARE), sensor, setup.noise, meas.actuators, meas.readings, meas.commanded)
    meth = make_method("fk-residual", model, weighted=False)
    theta = model.theta0
    J = meth.evaluate(theta).J
    scale = [1.0 if a else 100.0 for a in model.param_is_angle]
    assert_jacobian_matches_fd(lambda t: np.stack([make_method("fk-residual", model, weighted=False).evaluate(
        ti, jac=False, cov=False).r for ti in t]), theta[None, :], J[None], scale=scale, magnitude=300.0,
        names=model.names)
    assert np.abs(J[-12:, 1, :]).max() > 0.1        # the distances see the machine


# -- what the distances add ------------------------------------------------------------------


def test_heights_alone_leave_the_scale_open_and_the_distances_fix_it():
    meas = campaign(n_extra=12)
    heights = meas.commanded[:-12, :3]
    free = list(KLIPPER_SET)
    z_only = identifiability(FIRMWARE, builtin_setup("z-probe-klipper", FIRMWARE), heights, free=free)
    scale = z_only.named[0]
    assert scale["status"] == "not determined"
    pairs = PosePairs(FIRMWARE)
    both = identifiability(pairs, builtin_setup("printed-distance-klipper", pairs), meas.commanded, free=free)
    scale2 = both.named[0]
    assert scale2["status"] == "identified", scale2
    # distances do not see where the towers stand on the bed either
    assert [e["status"] for e in both.named[1:]] == ["unidentifiable"] * 2
    assert scale2["sigma"] < scale2["tolerance"] < scale["sigma"]
    # the heights see the scale only weakly (numerically of full rank); what neither sees is the rotation
    # about z and the sideways slide of the towers
    assert both.rank == z_only.rank == len(free) - 3


def test_noise_free_campaign_recovers_klippers_parameters():
    """Z heights at Klipper's 7 probe points and the 12 printed distances: the fit (per-tower
    model, its gauge held automatically) is Klipper's ten numbers after the exact firmware
    rewrite, to 1e-9 (angles relative to tower c: the rotation about z is a gauge)."""
    meas = campaign()
    pairs = PosePairs(FIRMWARE)
    setup = _noise_free(builtin_setup("printed-distance-klipper", pairs))
    fit = identify(pairs, setup, meas, free=list(KLIPPER_SET), fix="auto", weighted=False, xtol=1e-15, ftol=1e-15,
                   gtol=1e-15)
    assert fit.success and fit.rms_residual < 1e-10
    fw, dropped = firmware_subset(fit.mechanism.single)
    truth, _ = firmware_subset(REAL)
    assert dropped == [] and truth.origin == (0.0, 0.0)
    assert abs(fw.radius - truth.radius) < 1e-9
    np.testing.assert_allclose(fw.arms, truth.arms, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fw.endstops, truth.endstops, rtol=0, atol=1e-9)
    rel = np.subtract(fw.angles_deg, fw.angles_deg[2]) - np.subtract(truth.angles_deg, truth.angles_deg[2])
    np.testing.assert_allclose(rel, 0.0, rtol=0, atol=1e-9)


# -- files -----------------------------------------------------------------------------------


def test_object_points_are_klippers():
    """delta_calibrate.py: centre pair k from 4.5 e_k to 69.5 e_k; outer pair k from 65 e_k +
    4.5 e_{k+2} to 65 e_k + 69.5 e_{k+2}; distances less the pillar widths."""
    p1, p2 = object_point_pairs(2.0)
    a = np.deg2rad([210.0, 270.0, 330.0, 30.0, 90.0, 150.0])
    e = np.c_[np.cos(a), np.sin(a), np.zeros(6)]
    np.testing.assert_allclose(p1[:6], 9.0 * e, atol=1e-12)
    np.testing.assert_allclose(p2[:6], 139.0 * e, atol=1e-12)
    np.testing.assert_allclose(p1[6], 130.0 * e[0] + 9.0 * e[2], atol=1e-12)
    np.testing.assert_allclose(p2[11], 130.0 * e[5] + 139.0 * e[1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(p1 - p2, axis=1), 130.0, rtol=1e-14)
    d = corrected_distances({"CENTER_DISTS": [75.0] * 6, "CENTER_PILLAR_WIDTHS": [9.0, 9.1, 9.2],
                             "OUTER_DISTS": [76.0] * 6, "OUTER_PILLAR_WIDTHS": [10.0 + k for k in range(6)]})
    np.testing.assert_allclose(d, [66.0, 65.8, 65.9, 66.0, 65.8, 65.9] + [66.0 - k for k in range(6)], atol=1e-12)


def _printer_cfg(tmp_path, meas):
    """A printer.cfg of FIRMWARE with a #*# block of the campaign's stable positions (%.3f)."""
    step = 40.0 / (200 * 16)
    ref = FIRMWARE.reading_reference
    lines = ["[printer]", "kinematics: delta", "delta_radius: 105", ""]
    for t in "abc":
        lines += [f"[stepper_{t}]", "rotation_distance: 40", "microsteps: 16", "arm_length: 215",
                  "position_endstop: 250", ""]
    # the whole header Klipper writes (klippy/configfile.py AUTOSAVE_HEADER): Klipper, and now
    # pkmcal, read no block under its first line only
    lines += ["#*# <---------------------- SAVE_CONFIG ---------------------->",
              "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.", "#*#", "#*# [delta_calibrate]"]
    steps = (ref[None, :] - meas.actuators[:, :3]) / step, (ref[None, :] - meas.actuators[:, 3:]) / step
    n_h = int(np.sum(meas.readings[:, 1] == 0))
    for i in range(n_h):
        lines += [f"#*# height{i} = 0.0", f"#*# height{i}_pos = " + ",".join(f"{v:.3f}" for v in steps[0][i])]
    for i in range(len(meas) - n_h):
        k = n_h + i
        lines += [f"#*# distance{i} = {meas.readings[k, 1]:.6f}",
                  f"#*# distance{i}_pos1 = " + ",".join(f"{v:.3f}" for v in steps[0][k]),
                  f"#*# distance{i}_pos2 = " + ",".join(f"{v:.3f}" for v in steps[1][k])]
    path = tmp_path / "printer.cfg"
    path.write_text("\n".join(lines) + "\n")
    return path, step


def test_saved_block_gives_back_the_pairs(tmp_path):
    meas = campaign()
    path, step = _printer_cfg(tmp_path, meas)
    got = read_klipper_analyze(path, FIRMWARE).measurements
    np.testing.assert_allclose(got.actuators, meas.actuators, rtol=0, atol=0.0005 * step + 1e-12)
    np.testing.assert_allclose(got.readings, meas.readings, rtol=0, atol=5e-7)
    # the heights' rows repeat their point; the distances' rows do not
    n_h = 7
    np.testing.assert_array_equal(got.actuators[:n_h, :3], got.actuators[:n_h, 3:])
    res = CliRunner().invoke(cli, ["import", "klipper-analyze", str(path), "--machine", "kossel-mini", "-o",
                                   str(tmp_path / "pairs.csv")])
    assert res.exit_code == 0, res.output
    pairs = PosePairs(klipper_delta("kossel-mini", 105.2, 215.0, 250.0))
    back = load_measurements(tmp_path / "pairs.csv", pairs, builtin_setup("printed-distance-klipper", pairs))
    assert back.actuators.shape == (19, 6) and back.readings.shape == (19, 2)


def test_console_lines_give_the_object_pairs(tmp_path):
    log = tmp_path / "console.log"
    log.write_text("// probe at 0.000,0.000 is z=0.012500\n"
                   "DELTA_ANALYZE CENTER_DISTS=74,74,74,74,74,74 CENTER_PILLAR_WIDTHS=9,9,9\n"
                   "Recv: // ok\nDELTA_ANALYZE OUTER_DISTS=74,74,74,74,74,74 OUTER_PILLAR_WIDTHS=9,9,9,9,9,9\n")
    got = read_klipper_analyze(log, FIRMWARE, object_machine=FIRMWARE)   # printed with the probe's config
    m = got.measurements
    assert len(m) == 13
    p1, p2 = object_point_pairs()
    np.testing.assert_array_equal(m.actuators[1:], np.c_[FIRMWARE.ik(p1), FIRMWARE.ik(p2)])
    np.testing.assert_array_equal(m.readings[1:, 1], 65.0)
    assert m.readings[0, 1] == 0.0
    bad = tmp_path / "bad.log"
    bad.write_text("DELTA_ANALYZE CENTER_DISTS=74,74\n")
    with pytest.raises(PkmcalError, match="line 1: DELTA_ANALYZE CENTER_DISTS must have 6"):
        read_klipper_analyze(bad, FIRMWARE)
    with pytest.raises(PkmcalError, match="no complete DELTA_ANALYZE"):
        read_klipper_analyze(_only_probe(tmp_path), FIRMWARE)


def _only_probe(tmp_path):
    p = tmp_path / "probe.log"
    p.write_text("// probe at 0.000,0.000 is z=0.012500\n")
    return p


def test_setup_file_round_trips(tmp_path):
    pairs = PosePairs(FIRMWARE)
    path = tmp_path / "s.yaml"
    path.write_text("sensor: printed-distance\nprobe_offset: [1.0, 2.0, 0.5]\nbed: {z: 0.1, a: 0.2, b: -0.1}\n"
                    "noise: {reading: [0.005, 0.02], actuator: 0.0036}\n")
    s = load_setup(str(path), pairs)
    assert s.sensor.kind == "printed-distance" and s.sensor.reading_names == ("probe_z", "distance")
    np.testing.assert_array_equal(s.noise.reading_std, [0.005, 0.02])
    again = tmp_path / "again.yaml"
    again.write_text(setup_to_yaml(s))
    assert load_setup(str(again), pairs).sensor == s.sensor


#: The printer behind examples/klipper/delta-analyze.log: kossel-mini's config, but rods
#: 215.12/214.93/215.06 mm, radius 104.8 mm, endstops 250.62/249.71/250.38 mm, towers a and b
#: 0.35° and −0.25° off.
EXAMPLE_TRUTH = dict(radius=104.8, arms=(215.12, 214.93, 215.06), endstops=(250.62, 249.71, 250.38),
                     angles=(210.35, 329.75, 90.0))
EXAMPLE_LOG = Path(__file__).resolve().parents[2] / "examples" / "klipper" / "delta-analyze.log"


def delta_analyze_log() -> str:
    """The console of DELTA_CALIBRATE (Klipper's 7 points, probe at the nozzle) and of the
    DELTA_ANALYZE commands (calipers to 0.01 mm, pillar widths about 9 mm) on that printer."""
    from pkmcal.io.machine_file import load_machine

    fw = load_machine("kossel-mini")
    t = EXAMPLE_TRUTH
    real = fw.with_params(klipper_delta("r", t["radius"], t["arms"], t["endstops"], t["angles"]).params)
    xy = klipper_points()
    z = np.zeros(len(xy))
    for _ in range(8):
        z = z - real.fk(fw.ik(np.c_[xy, z])).poses[:, 2]
    p1, p2 = object_point_pairs()
    d = np.linalg.norm(real.fk(fw.ik(p1)).poses - real.fk(fw.ik(p2)).poses, axis=1)
    rng = np.random.default_rng(13)
    cw = np.round(9.0 + rng.uniform(-0.05, 0.05, 3), 2)
    ow = np.round(9.0 + rng.uniform(-0.05, 0.05, 6), 2)
    meas = np.round(d + np.r_[cw[[0, 2, 1, 0, 2, 1]], ow], 2)

    def values(v):
        return ",".join(f"{x:.2f}" for x in v)

    lines = ["// Klipper console of a Kossel Mini (z_offset 0): DELTA_CALIBRATE, then Klipper's calibrate_size.stl",
             "// printed and measured with calipers (0.01 mm); a simulated printer (see tests/sensors/test_printed_distance.py)",
             "// that printed the object with the config it probed with (nothing saved in between): --object-machine "
             "kossel-mini",
             "DELTA_CALIBRATE"]
    lines += [f"// probe at {x:.3f},{y:.3f} is z={zz:.6f}" for (x, y), zz in zip(xy, z)]
    lines += [f"DELTA_ANALYZE CENTER_DISTS={values(meas[:6])}", f"DELTA_ANALYZE CENTER_PILLAR_WIDTHS={values(cw)}",
              f"DELTA_ANALYZE OUTER_DISTS={values(meas[6:])}", f"DELTA_ANALYZE OUTER_PILLAR_WIDTHS={values(ow)}",
              "DELTA_ANALYZE CALIBRATE=extended"]
    return "\n".join(lines) + "\n"


def test_example_log_is_its_simulation():
    assert EXAMPLE_LOG.read_text() == delta_analyze_log()


def test_cli_fits_the_printed_distances_and_exports_klippers_numbers(tmp_path):
    """import klipper-analyze → identify (the machine read as pose pairs) → export klipper:
    the truth to the calipers' 0.01 mm (angles relative to tower a)."""
    from pkmcal.io.delta_firmware import read_klipper

    run = CliRunner()
    pairs, cal, cfg = tmp_path / "pairs.csv", tmp_path / "cal.yaml", tmp_path / "saved.cfg"
    res = run.invoke(cli, ["import", "klipper-analyze", str(EXAMPLE_LOG), "--machine", "kossel-mini",
                           "--object-machine", "kossel-mini", "-o", str(pairs)])   # the example saved nothing between
    assert res.exit_code == 0, res.output
    res = run.invoke(cli, ["identify", "kossel-mini", str(pairs), "--setup", "printed-distance-klipper", "--free",
                           "angle_*,radius_*,arm_*,endstop_*", "--fix", "auto", "-o", str(cal), "--held-out", str(pairs)])
    assert res.exit_code == 0, res.output
    assert "reading residual rms (mm)" in res.output          # the held-out table reads pairs too
    for setup in (str(cal), "printed-distance-klipper"):   # verify reads pair files as identify does
        res = run.invoke(cli, ["verify", str(cal), "--held-out", str(pairs), "--setup", setup, "--json"])
        assert res.exit_code == 0, res.output
        rep = json.loads(res.output)
        assert rep["n_poses"] == 19 and rep["sensor"] == "printed-distance"
        assert rep["after"]["reading_rms_mm"] < 0.01 < rep["before"]["reading_rms_mm"]
    res = run.invoke(cli, ["export", str(cal), "--format", "klipper", "-o", str(cfg)])
    assert res.exit_code == 0, res.output
    assert "written about their circle's centre" in res.output
    cfg.write_text("[printer]\nkinematics: delta\n" + cfg.read_text().replace("[printer]\n", "", 1))
    got = read_klipper(str(cfg))
    t = EXAMPLE_TRUTH
    assert abs(got.radius - t["radius"]) < 0.02
    np.testing.assert_allclose(got.arms, t["arms"], rtol=0, atol=0.03)
    np.testing.assert_allclose(got.endstops, t["endstops"], rtol=0, atol=0.03)
    np.testing.assert_allclose(np.subtract(got.angles_deg, got.angles_deg[0]),
                               np.subtract(t["angles"], t["angles"][0]), rtol=0, atol=0.02)


def test_pairs_of_a_rotating_platform_compose_like_the_machine():
    """On a hexapod (frames that rotate) the pair's J·T is the machine's per pose, and a
    distance's pose Jacobian matches central differences of the readings over both poses."""
    from pkmcal.io.machine_file import load_machine

    hexa = load_machine("stewart-prototype")
    pairs = PosePairs(hexa)
    rng = np.random.default_rng(8)
    home = hexa.home_pose
    X = np.c_[home + rng.uniform(-5, 5, (5, 6)) * [1, 1, 1, 0.02, 0.02, 0.02],
              home + rng.uniform(-5, 5, (5, 6)) * [1, 1, 1, 0.02, 0.02, 0.02]]
    J = rng.standard_normal((5, 2, 12))
    T, _ = pairs.frame_jacobians(X)
    np.testing.assert_allclose(pairs.pose_jacobian_from_twist(J, X), J @ T, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(pairs.pose_jacobian_from_twist(J, X)[..., 6:],
                                  hexa.pose_jacobian_from_twist(J[..., 6:], X[:, 6:]))
    s = PrintedDistanceSensor()
    H = pairs.pose_jacobian_from_twist(s.frame_jacobian(pairs.frame(X)), X)
    d = float(np.min(np.linalg.norm(X[:, :3] - X[:, 6:9], axis=1)))    # the distance's curvature scale
    assert_jacobian_matches_fd(lambda x: s.predict(pairs.frame(x)), X, H,
                               scale=[d] * 3 + [1.0] * 3 + [d] * 3 + [1.0] * 3, magnitude=1000.0)


def test_chi2_of_pair_fits_counts_only_the_readings_each_row_takes():
    """A printed-object campaign (probe heights and Klipper's 12 distances, as pair rows that
    each measure one of their two readings) simulated with the setup's own noise: χ² of the
    weighted fit follows χ²(dof) with dof = measured readings − free parameters, so its mean
    over fits is dof (the old count, every row's two readings, made it about a third). With
    n fits the mean's relative spread is √(2 / (dof n)); the tolerance is 4 of those. The
    screening's per-pose sigma and the rms count the measured readings too."""
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.mechanisms.pose_pairs import PosePairs
    from pkmcal.study import printed

    nominal = builtin_machine("kossel-mini")
    setup = builtin_setup("printed-distance-klipper")
    rng = np.random.default_rng(11)
    angle = rng.uniform(0, 2 * np.pi, 15)
    radius = 70 * np.sqrt(rng.uniform(0, 1, 15))
    probe_points = np.c_[radius * np.cos(angle), radius * np.sin(angle), rng.uniform(0, 5, 15)]
    free = ["angle_*", "radius_*", "arm_*", "endstop_*"]
    chi2, dofs = [], set()
    for seed in range(40):
        sim = printed.simulate(nominal, nominal, setup, probe_points, 1.0, np.random.default_rng(seed))
        res = identify(PosePairs(nominal), setup, sim.measurements, free=free, fix="auto")
        u = res.uncertainty
        chi2.append(u.chi2)
        dofs.add(u.dof)
        assert res.measured is not None and int(res.measured.sum()) == 15 + 12
    (dof,) = dofs
    assert dof == 15 + 12 - len(res.free)
    mean = float(np.mean(chi2))
    assert abs(mean / dof - 1) < 4 * np.sqrt(2 / (dof * len(chi2))), (mean, dof)
    r = res.residuals_weighted
    np.testing.assert_allclose(res.rms_whitened, np.sqrt(np.sum(r**2) / 27), rtol=1e-12)
    np.testing.assert_allclose(res.screening.sigma, np.linalg.norm(r, axis=1), rtol=1e-12)   # one reading a row


def test_held_out_reading_statistics_count_the_readings_each_row_takes():
    """Held-out errors of Klipper's example log (7 heights, 12 distances) on the nominal
    machine: the reading mean and rms are over the 19 readings measured, not over the 38
    entries of which 19 are recorded 0 and predicted 0."""
    from pkmcal.identification.heldout import predict
    from pkmcal.mechanisms.library import builtin_machine

    machine = builtin_machine("kossel-mini")
    meas = read_klipper_analyze(EXAMPLE_LOG, machine, object_machine=machine).measurements
    sensor = builtin_setup("printed-distance-klipper").sensor
    pred = predict(PosePairs(machine), sensor, meas, "nominal")
    assert pred.measured is not None and int(pred.measured.sum()) == 19
    taken = pred.residuals[pred.measured]
    out = pred.summary(np.ones(len(meas.readings), dtype=bool))
    assert out["reading_rms_mm"] == pytest.approx(float(np.sqrt(np.mean(taken**2))), rel=1e-12)
    assert out["reading_mean_mm"] == pytest.approx(float(np.mean(np.abs(taken))), rel=1e-12)
    assert out["reading_max_mm"] == pytest.approx(float(np.max(np.abs(pred.residuals))), rel=1e-12)
    assert np.all(pred.residuals[~pred.measured] == 0)


def test_cli_identifiability_reads_pose_pairs_and_refuses_what_pairs_cannot_do(tmp_path):
    """`pkmcal identifiability` judges a printed-object campaign from its pose pairs (x, y, z,
    x_2, y_2, z_2) as the library does on the machine read as pose pairs; `--suggest`, `plan`
    and `simulate` refuse it with what to do instead (exit 2, no traceback)."""
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.mechanisms.library import builtin_machine

    machine = builtin_machine("kossel-mini")
    meas = read_klipper_analyze(EXAMPLE_LOG, machine, object_machine=machine).measurements
    poses = tmp_path / "pairs.csv"
    cols = ("x", "y", "z", "x_2", "y_2", "z_2")
    poses.write_text(",".join(cols) + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in meas.commanded)
                     + "\n")
    run = CliRunner()
    res = run.invoke(cli, ["identifiability", "kossel-mini", "--setup", "printed-distance-klipper", "--poses", str(poses),
                           "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    setup = builtin_setup("printed-distance-klipper", PosePairs(machine))
    want = identifiability(PosePairs(machine), setup, meas.commanded)
    assert (got["rank"], got["n_params"]) == (want.rank, want.n_params) == (15, 18)
    np.testing.assert_allclose(got["singular_values"], want.singular_values, rtol=1e-12)
    for args, hint in ((["identifiability", "kossel-mini", "--setup", "printed-distance-klipper", "--poses", str(poses),
                         "--suggest"], "probe heights alone"),
                       (["plan", "kossel-mini", "--setup", "printed-distance-klipper", "--n-poses", "15", "-o",
                         str(tmp_path / "p.csv")], "z-probe-klipper"),
                       (["simulate", "kossel-mini", "--real", "kossel-mini", "--setup", "printed-distance-klipper",
                         "--poses", str(poses), "-o", str(tmp_path / "m.csv")], "z-probe-klipper")):
        res = run.invoke(cli, args)
        assert res.exit_code == 2 and hint in res.output and "Traceback" not in res.output, (args, res.output)

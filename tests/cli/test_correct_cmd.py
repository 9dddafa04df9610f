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
    r = run("compensate", d / "cal.yaml", d / "meas.csv", "--heldout", d / "held.csv", "-o", d / "corr.yaml",
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
    r = run("compensate", tmp_path / "cal.yaml", tmp_path / "meas.csv", "--heldout", tmp_path / "held.csv", "-o",
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

"""LinuxCNC genhexkins in both directions (issue 11 item 9): ``pkmcal import linuxcnc HAL
[INI]`` (:mod:`pkmcal.io.import_linuxcnc`), the INI sections of ``pkmcal export --format
linuxcnc --ini`` (:func:`pkmcal.io.export_linuxcnc.linuxcnc_ini`) and L0 = 0.

Checks: the round trip machine → HAL + INI → machine over hypothesis-drawn machines (joints,
offsets and home pose exact, stroke to 1e-9 mm); the imported machine's leg lengths against
genhexkins' inverse kinematics written out here from its source (strut = ‖p + R a − b‖ with
``pmRpyMatConvert``'s columns and the spindle offset added to both joints' z), in the file's
units; halcmd's and LinuxCNC's INI syntax; every bad input a one-line error naming the file
and line.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.export_linuxcnc import check_home, joint_settings, linuxcnc_hal, linuxcnc_ini, rounded_machine
from pkmcal.io.import_linuxcnc import machine_from_linuxcnc, read_hal_genhexkins, read_ini
from pkmcal.io.machine_file import load_machine, machine_from_text, machine_to_text
from pkmcal.mechanisms.hexapod import Hexapod
from pkmcal.mechanisms.library import builtin_machine

STROKE_TOL_MM = 1e-9


def genhexkins_struts(base, platform, pose_deg, spindle=0.0):
    """genhexkins' inverse kinematics (genhexkins.c, posemath pmRpyMatConvert), in the
    units of its inputs: joint_N = |p + R a_N - b_N| with the spindle offset on both z."""
    x, y, z, A, B, C = pose_deg
    r, p, yw = np.deg2rad([A, B, C])
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(yw), np.sin(yw)
    mx = np.array([cy * cp, sy * cp, -sp])
    my = np.array([cy * sp * sr - sy * cr, sy * sp * sr + cy * cr, cp * sr])
    mz = np.array([cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr])
    a = np.array(platform, dtype=float) + [0, 0, spindle]
    b = np.array(base, dtype=float) + [0, 0, spindle]
    Ra = np.outer(a[:, 0], mx) + np.outer(a[:, 1], my) + np.outer(a[:, 2], mz)
    return np.linalg.norm(np.array([x, y, z]) + Ra - b, axis=1)


def export_files(tmp_path, machine, stem="m"):
    hal, ini = tmp_path / f"{stem}.hal", tmp_path / f"{stem}.ini"
    hal.write_text(linuxcnc_hal(machine))
    ini.write_text(linuxcnc_ini(machine))
    return hal, ini


#: Half a unit of the 6th decimal of the exported lengths (1 nm: export_linuxcnc
#: LINUXCNC_DECIMALS) and of the 7th of the exported degrees (ANGLE_DECIMALS), in mm and rad,
#: plus the decimal conversion's round-off of numbers below 1e3.
HALF_NM = 0.5e-6 + np.spacing(1e3)
HALF_ANGLE = np.deg2rad(0.5e-7) + np.spacing(np.pi)


def assert_same_kinematics(back, machine, stroke_tol=STROKE_TOL_MM):
    """``back`` (imported from ``machine``'s export) is the machine as exported, exactly
    (export_linuxcnc.rounded_machine), and each number within half a unit of the last
    decimal written of ``machine``'s."""
    exported = rounded_machine(machine)
    np.testing.assert_array_equal(back.base, exported.base)
    np.testing.assert_array_equal(back.platform, exported.platform)
    np.testing.assert_array_equal(back.offset, exported.offset)
    for got, want in ((back.base, machine.base), (back.platform, machine.platform), (back.offset, machine.offset)):
        np.testing.assert_allclose(got, want, rtol=0, atol=HALF_NM)
    np.testing.assert_allclose(back.stroke, machine.stroke, rtol=0, atol=stroke_tol + 3 * HALF_NM)
    np.testing.assert_allclose(back.home_pose[:3], machine.home_pose[:3], rtol=0, atol=HALF_NM)
    np.testing.assert_allclose(back.home_pose[3:], machine.home_pose[3:], rtol=0, atol=HALF_ANGLE)


@st.composite
def machines(draw):
    nominal = builtin_machine("stewart-prototype")
    f = st.floats(-5.0, 5.0, allow_nan=False)
    base = nominal.base + np.array(draw(st.lists(f, min_size=18, max_size=18))).reshape(6, 3)
    platform = nominal.platform + np.array(draw(st.lists(f, min_size=18, max_size=18))).reshape(6, 3)
    zero = draw(st.booleans())
    offset = np.zeros(6) if zero else np.array(draw(st.lists(st.floats(250.0, 320.0), min_size=6, max_size=6)))
    lo = np.array(draw(st.lists(st.floats(-10.0, 10.0), min_size=6, max_size=6)))
    width = np.array(draw(st.lists(st.floats(20.0, 80.0), min_size=6, max_size=6)))
    if zero:
        lo = lo + 300.0                                  # readings are strut lengths
    stroke = np.stack([lo, lo + width], axis=1)
    m = Hexapod(name="drawn", base=base, platform=platform, offset=offset, stroke=stroke)
    if draw(st.booleans()):
        dx = np.array(draw(st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6)))
        m = Hexapod(name="drawn", base=base, platform=platform, offset=offset, stroke=stroke,
                    home=m.home_pose + dx * [1, 1, 1, 0.01, 0.01, 0.01])
    return m


@settings(max_examples=60, deadline=None)
@given(machines())
def test_round_trip_machine_hal_ini_machine(tmp_path_factory, machine):
    d = tmp_path_factory.mktemp("rt")
    try:
        check_home(machine, joint_settings(machine))
    except PkmcalError:                 # a home LinuxCNC cannot home to: the INI is refused
        with pytest.raises(PkmcalError, match="home pose"):
            linuxcnc_ini(machine)
        return
    hal, ini = export_files(d, machine)
    back = machine_from_linuxcnc(hal, ini).machine
    assert_same_kinematics(back, machine)
    # and the imported machine file loads back to itself (as save_machine checks)
    assert machine_from_text(machine_to_text(back)) == back
    # exporting the imported machine gives the same setp lines
    setp = [line for line in linuxcnc_hal(machine).splitlines() if line.startswith("setp")]
    assert [line for line in linuxcnc_hal(back).splitlines() if line.startswith("setp")] == setp


def test_round_trip_in_genhexkins_convention_keeps_the_home_switch(tmp_path):
    """--offsets zero: L0 = 0, readings = joint values; the home-switch reading is kept, so
    that the export writes the same HOME_OFFSET again."""
    m = builtin_machine("stewart-prototype")
    hal, ini = export_files(tmp_path, m)
    zero = machine_from_linuxcnc(hal, ini, offsets="zero").machine
    np.testing.assert_array_equal(zero.offset, np.zeros(6))
    np.testing.assert_array_equal(zero.stroke, m.offset[:, None] + m.stroke)
    assert zero.metadata["linuxcnc"]["home_switch_reading"] == [305.0] * 6
    assert linuxcnc_ini(zero).split("[TRAJ]")[1] == linuxcnc_ini(m).split("[TRAJ]")[1]
    np.testing.assert_allclose(zero.leg_lengths(m.home_pose), m.leg_lengths(m.home_pose), rtol=0, atol=0)
    # an identified L0 correction moves HOME_OFFSET by it: HOME_OFFSET = L0 + reading at the switch
    shifted = zero.with_params(zero.params + np.r_[np.tile([0, 0, 0, 0, 0, 0, 0.25], 6), np.zeros(6)])
    np.testing.assert_array_equal(joint_settings(shifted)["HOME_OFFSET"], 305.25)
    z2 = tmp_path / "z"
    z2.mkdir()
    back = machine_from_linuxcnc(*export_files(z2, zero), offsets="zero").machine
    assert_same_kinematics(back, zero, stroke_tol=0.0)


def test_leg_lengths_are_genhexkins_struts_in_an_inch_configuration(tmp_path):
    """A configuration written as LinuxCNC's hexapod-sim is (inch, HOME_OFFSET= without a
    blank, rounded HOME values): the imported machine (mm) gives 25.4 × genhexkins' struts."""
    base = [[-22.95, 13.25, 0], [22.95, 13.25, 0], [22.95, 13.25, 0], [0, -26.5, 0], [0, -26.5, 0],
            [-22.95, 13.25, 0]]
    plat = [[-1.0, 11.5, 0], [1.0, 11.5, 0], [10.459, -4.884, 0], [9.459, -6.616, 0], [-9.459, -6.616, 0],
            [-10.459, -4.884, 0]]
    lines = ["# base and platform joints (inch)"]
    for part, pts in (("base", base), ("platform", plat)):
        for n, p in enumerate(pts):
            lines += [f"setp genhexkins.{part}.{n}.{ax} {v:8.3f}" for ax, v in zip("xyz", p)]
    (tmp_path / "kinematics.hal").write_text("\n".join(lines) + "\n")
    home_len = genhexkins_struts(base, plat, [0, 0, 20, 0, 0, 0])
    joints = "".join(f"[JOINT_{n}]\nTYPE = LINEAR\nMIN_LIMIT = 20.0\nMAX_LIMIT = 40.0\nHOME_OFFSET= {h:.4f}\n"
                     f"HOME = {h:.4f}\nHOME_SEQUENCE = 0\n" for n, h in enumerate(home_len))
    (tmp_path / "hexapod.ini").write_text(
        "[EMC]\nMACHINE = hexapod (switchkins)\n[TRAJ]\nHOME = 0 0 20 0 0 0\nLINEAR_UNITS = inch\n"
        "ANGULAR_UNITS = degree\n[KINS]\nKINEMATICS = genhexkins\nJOINTS = 6\n" + joints)
    res = machine_from_linuxcnc(tmp_path / "kinematics.hal", tmp_path / "hexapod.ini")
    m = res.machine
    assert m.name == "hexapod (switchkins)"
    np.testing.assert_allclose(m.home_pose, [0, 0, 508.0, 0, 0, 0], rtol=1e-15)
    np.testing.assert_allclose(m.offset, 25.4 * np.round(home_len, 4), rtol=1e-15)
    rng = np.random.default_rng(0)
    for _ in range(5):
        pose_in = np.array([*rng.uniform(-1, 1, 2), rng.uniform(18, 22), *rng.uniform(-5, 5, 3)])
        pose_mm = np.concatenate([pose_in[:3] * 25.4, np.deg2rad(pose_in[3:])])
        np.testing.assert_allclose(m.leg_lengths(pose_mm)[0], 25.4 * genhexkins_struts(base, plat, pose_in),
                                   rtol=1e-13)
    # the 4-decimal HOME values are ~1e-3 mm from the struts at [TRAJ] HOME: a note, not an error
    assert any("[JOINT_N] HOME differ" in n for n in res.notes)
    np.testing.assert_allclose(m.offset + m.stroke[:, 0], 20 * 25.4, rtol=1e-15)


def test_hal_syntax_as_halcmd_reads_it(tmp_path, monkeypatch):
    m = builtin_machine("stewart-prototype")
    setp = [line for line in linuxcnc_hal(m).splitlines() if line.startswith("setp")]
    ini = tmp_path / "h.ini"
    ini.write_text("[HEXAPOD]\nBASE_0_X = -152.5\n[TRAJ]\nLINEAR_UNITS = mm\n")
    monkeypatch.setenv("PKMCAL_TEST_B1Y", "0.0")
    lines = ["loadrt genhexkins", "net x-pos joint.0.motor-pos-cmd => genhexkins.gui.x  # a net: ignored"]
    for k, line in enumerate(setp):
        name, value = line.split()[1:]
        if name == "genhexkins.base.0.x":
            lines.append(f"setp {name} [HEXAPOD]BASE_0_X   # from the INI file")
        elif name == "genhexkins.base.0.y":
            lines.append(f"setp {name} $(PKMCAL_TEST_B1Y)")
        elif k % 3 == 0:
            lines.append(f"{name} = {value}")
        elif k % 3 == 1:
            lines += [f"setp {name} \\", f"   {value}"]
        else:
            lines += [f"setp {name} 999", f"setp {name} {value}"]     # the last setp wins
    (tmp_path / "h.hal").write_text("\n".join(lines) + "\n")
    back = machine_from_linuxcnc(tmp_path / "h.hal", ini, joint_limits=(305.0, 355.0)).machine
    np.testing.assert_array_equal(back.base, m.base)
    np.testing.assert_array_equal(back.platform, m.platform)
    values = read_hal_genhexkins(tmp_path / "h.hal", read_ini(ini))
    assert values["base.0.x"][0] == -152.5 and len(values) == 36


def _hal_with(tmp_path, replace: dict[str, str | None], extra=()):
    m = builtin_machine("stewart-prototype")
    out = []
    for line in linuxcnc_hal(m).splitlines():
        if line.startswith("setp") and line.split()[1] in replace:
            if replace[line.split()[1]] is not None:
                out.append(replace[line.split()[1]])
            continue
        out.append(line)
    path = tmp_path / "bad.hal"
    path.write_text("\n".join(list(out) + list(extra)) + "\n")
    return path


@pytest.mark.parametrize("replace, extra, fragment", [
    ({"genhexkins.base.3.y": None}, (), "sets 35 of the 36 genhexkins joint coordinates; missing genhexkins.base.3.y"),
    ({"genhexkins.base.3.y": "setp genhexkins.base.3.y abc"}, (), "genhexkins.base.3.y: 'abc' is not a number"),
    ({"genhexkins.base.3.y": "setp genhexkins.base.3.y nan"}, (), "is not a finite number"),
    ({}, ("setp genhexkins.platfrom.0.x 1.0",), "'genhexkins.platfrom.0.x' is not a genhexkins input "
                                                "(halcmd would refuse it); did you mean 'genhexkins.platform.0.x'?"),
    ({}, ("setp genhexkins.screw-lead 5.0",), "genhexkins.screw-lead = 5.0: the strut-length correction"),
    ({}, ("setp genhexkins.base.0.z [TRAJ]HOME",), "uses the INI value [TRAJ]HOME; give the INI file too"),
    ({}, ("setp genhexkins.base.0.z $PKMCAL_SURELY_UNSET",), "environment variable $PKMCAL_SURELY_UNSET"),
])
def test_bad_hal_files_are_errors_naming_file_and_line(tmp_path, replace, extra, fragment):
    hal = _hal_with(tmp_path, replace, extra)
    with pytest.raises(PkmcalError) as info:
        machine_from_linuxcnc(hal, joint_limits=(305.0, 355.0))
    msg = str(info.value)
    assert msg.startswith(str(hal)) and fragment in msg, msg
    if extra:
        n_lines = len(hal.read_text().splitlines())
        assert msg.startswith(f"{hal}, line {n_lines}:"), msg


def test_spindle_and_tool_offsets_are_folded_into_the_joints(tmp_path):
    m = builtin_machine("stewart-prototype")
    hal = _hal_with(tmp_path, {}, ("setp genhexkins.spindle-offset 2.5", "setp genhexkins.tool-offset 1.5"))
    res = machine_from_linuxcnc(hal, joint_limits=(305.0, 355.0))
    pose = np.array([3.0, -2.0, 318.0, 4.0, -3.0, 10.0])
    expected = genhexkins_struts(m.base, m.platform, pose, spindle=4.0)
    got = res.machine.leg_lengths(np.concatenate([pose[:3], np.deg2rad(pose[3:])]))[0]
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    assert any("spindle-offset + tool-offset = 4.0 mm" in n for n in res.notes)


def test_ini_syntax_include_first_key_continuation(tmp_path):
    m = builtin_machine("stewart-prototype")
    hal, ini = export_files(tmp_path, m)
    text = ini.read_text()
    joints = text[text.index("[JOINT_0]"):]
    (tmp_path / "joints.inc").write_text(joints)
    main = text[:text.index("[JOINT_0]")].replace("HOME = ", "HOME = \\\n")    # a continued value
    main = main.replace("[KINS]", "[KINS]\n; a comment\n# another\nKINEMATICS = genhexkins\nJOINTS = 6")
    (tmp_path / "main.ini").write_text(main + "#INCLUDE joints.inc\n[JOINT_0]\nMIN_LIMIT = 1.0\n")
    back = machine_from_linuxcnc(hal, tmp_path / "main.ini").machine
    assert_same_kinematics(back, m)                       # the later MIN_LIMIT = 1.0 is not used
    parsed = read_ini(tmp_path / "main.ini")
    value, file, line = parsed.get("joint_0", "min_limit")
    assert value == "305.5" and file.endswith("joints.inc") and line == 3    # the stroke 0.5 mm inside


@pytest.mark.parametrize("edit, fragment", [
    (("KINEMATICS = genhexkins", "KINEMATICS = trivkins"), "[KINS] KINEMATICS = trivkins: not genhexkins"),
    (("JOINTS = 6", "JOINTS = 9"), "[KINS] JOINTS = 9: genhexkins has 6 joints"),
    (("LINEAR_UNITS = mm", "LINEAR_UNITS = furlong"), "[TRAJ] LINEAR_UNITS = 'furlong': unknown unit"),
    (("[JOINT_2]\nTYPE = LINEAR", "[JOINT_2]\nTYPE = ANGULAR"), "[JOINT_2] TYPE = ANGULAR"),
    (("MAX_LIMIT = 354.5\nHOME_OFFSET = 305.0\nHOME = 330.0\n\n[JOINT_3]",
      "MAX_LIMIT = abc\nHOME_OFFSET = 305.0\nHOME = 330.0\n\n[JOINT_3]"),
     "[JOINT_2] MAX_LIMIT = 'abc' is not a number"),
])
def test_bad_ini_files_are_errors_naming_file_and_line(tmp_path, edit, fragment):
    hal, ini = export_files(tmp_path, builtin_machine("stewart-prototype"))
    text = ini.read_text()
    assert edit[0] in text
    ini.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputFileError) as info:
        machine_from_linuxcnc(hal, ini)
    assert str(info.value).startswith(f"{ini}, line ") and fragment in str(info.value), str(info.value)


def test_missing_limits_need_an_ini_or_the_option(tmp_path):
    hal, ini = export_files(tmp_path, builtin_machine("stewart-prototype"))
    with pytest.raises(PkmcalError, match=r"no INI file gives the joint limits; give the INI file or --joint-limits"):
        machine_from_linuxcnc(hal)
    ini.write_text(ini.read_text().replace("MIN_LIMIT = 305.5\n", "", 1))
    with pytest.raises(PkmcalError, match=r"has no \[JOINT_N\] MIN_LIMIT/MAX_LIMIT for joints 0"):
        machine_from_linuxcnc(hal, ini)


def test_gains_enter_the_joint_limits_and_home_offset():
    """HOME_OFFSET = L0 + g·λ_switch and the limits L0 + g·stroke, with the gains of
    export_linuxcnc.leg_gains (the one place the export reads them: the machine's
    legs[i].gain, all 1 for the built-in hexapods)."""
    from dataclasses import replace

    from pkmcal.io import export_linuxcnc

    plain = builtin_machine("stewart-prototype")
    np.testing.assert_array_equal(export_linuxcnc.leg_gains(plain), np.ones(6))
    assert "Leg gains" not in linuxcnc_ini(plain)
    g = np.array([1.0, 1.01, 0.99, 1.0, 1.02, 0.98])
    m = replace(plain, gains=g)
    np.testing.assert_array_equal(export_linuxcnc.leg_gains(m), g)
    s = joint_settings(m)
    np.testing.assert_array_equal(s["margin"], 0.01 * (g * 50.0))        # 1 % of each joint's stroke in mm
    np.testing.assert_array_equal(s["MIN_LIMIT"], m.offset + g * m.stroke[:, 0] + s["margin"])
    np.testing.assert_array_equal(s["MAX_LIMIT"], m.offset + g * m.stroke[:, 1] - s["margin"])
    ini = linuxcnc_ini(m)
    assert "i.e. divide the scale that made the readings by the gain" in ini and "#   joint 2: gain 0.99 mm/mm" in ini


def test_leg_offset_zero_is_a_valid_machine_file_and_negative_is_not():
    text = machine_to_text(builtin_machine("stewart-prototype"))
    zero = text.replace("offset: 305.0", "offset: 0.0").replace("stroke: [0.0, 50.0]", "stroke: [305.0, 355.0]")
    m = machine_from_text(zero, "zero.yaml")
    np.testing.assert_array_equal(m.offset, 0.0)
    ref = builtin_machine("stewart-prototype")
    np.testing.assert_allclose(m.fk(ref.ik(ref.home_pose) + 305.0).poses, ref.home_pose[None], atol=1e-9)
    with pytest.raises(InputFileError, match=r"legs\[0\].offset \(leg 1\): -1.0 mm is not a leg offset"):
        machine_from_text(text.replace("offset: 305.0", "offset: -1.0", 1), "neg.yaml")


def test_cli_export_ini_and_import_round_trip(tmp_path):
    runner = CliRunner()
    hal, ini, out = tmp_path / "k.hal", tmp_path / "j.ini", tmp_path / "back.yaml"
    res = runner.invoke(cli, ["export", "stewart-prototype", "--format", "linuxcnc", "-o", str(hal), "--ini", str(ini)])
    assert res.exit_code == 0, res.output
    assert "[JOINT_5]" in ini.read_text() and ini.read_text().count("HOME_OFFSET = 305.0") == 6
    res = runner.invoke(cli, ["import", "linuxcnc", str(hal), str(ini), "-o", str(out), "--name", "back"])
    assert res.exit_code == 0, res.output
    assert f"wrote {out}" in res.stderr
    m, back = builtin_machine("stewart-prototype"), load_machine(str(out))
    assert back.name == "back"
    assert_same_kinematics(back, m)
    for args, fragment in [
        (["export", "stewart-prototype", "--format", "json", "--ini", str(tmp_path / "x.ini")], "--format linuxcnc"),
        (["export", "stewart-prototype", "--format", "linuxcnc", "-o", str(hal), "--ini", str(hal)], "same file"),
        (["import", "linuxcnc", str(hal), str(ini), "-o", str(hal)], "input"),
        (["import", "linuxcnc", str(hal)], "--joint-limits"),
        (["import", "linuxcnc", str(hal), "--joint-limits", "3,x"], "--joint-limits '3,x'"),
    ]:
        res = runner.invoke(cli, args)
        assert res.exit_code == 2 and fragment in res.stderr and "Traceback" not in res.output, (args, res.output)


def test_linuxcnc_sample_joint_limits_are_reported_as_too_loose(tmp_path):
    """LinuxCNC's hexapod sample lets every strut run from -1000 to 1000 inch on struts of
    29.75 inch at home: the import writes the stroke as the file says and its note names the
    limit, the range the geometry allows (L_h / 2 .. 2 L_h) and that genhexkins refuses
    struts <= 0. A configuration with a real strut range has no such note."""
    from helpers import write_linuxcnc_hexapod_sample

    hal, ini = write_linuxcnc_hexapod_sample(tmp_path / "sample")
    got = machine_from_linuxcnc(hal, ini)
    np.testing.assert_allclose(got.machine.offset[:, None] + got.machine.stroke, [[-25400.0, 25400.0]] * 6,
                               rtol=1e-12)
    loose = [n for n in got.notes if "strut range" in n]
    assert len(loose) == 1
    assert f"(-25400 to 25400 mm, [JOINT_N] MIN_LIMIT/MAX_LIMIT of {ini})" in loose[0]
    assert "(377.8 to 1511 mm)" in loose[0] and "genhexkins refuses struts of length 0 or less" in loose[0]
    res = CliRunner().invoke(cli, ["import", "linuxcnc", str(hal), "--joint-limits", "-100,2000", "-o",
                                   str(tmp_path / "m.yaml")])
    assert res.exit_code == 0, res.output
    assert "(-100 to 2000 mm, --joint-limits)" in res.output and "refuses" in res.output
    hal2, ini2 = export_files(tmp_path, builtin_machine("stewart-prototype"))
    assert not [n for n in machine_from_linuxcnc(hal2, ini2).notes if "strut range" in n]


def test_axis_soft_limits_are_the_workspace_within_the_euler_range(tmp_path):
    """[AXIS_X..C] MIN_LIMIT/MAX_LIMIT (LinuxCNC's soft limits in world coordinates, [TRAJ]
    units) become the machine's workspace; angles beyond A, C ±180° and B ±90° are clipped
    with a note naming the section; an axis without limits (LinuxCNC: ±1e99) gives no
    workspace, with a note; MAX < MIN is an error naming the file and line."""
    from helpers import write_linuxcnc_hexapod_sample

    hal, ini = write_linuxcnc_hexapod_sample(tmp_path / "sample")
    got = machine_from_linuxcnc(hal, ini)
    box = got.machine.workspace
    np.testing.assert_allclose(box[:3], [[-25400.0, 25400.0]] * 3, rtol=1e-12)
    np.testing.assert_array_equal(box[3:], [[-np.pi, np.pi], [-np.pi / 2, np.pi / 2], [-np.pi, np.pi]])
    clipped = [n for n in got.notes if "[AXIS_A]" in n]
    assert len(clipped) == 1 and "[AXIS_B] MIN_LIMIT/MAX_LIMIT = -1000/1000 deg" in clipped[0]
    text = machine_to_text(got.machine)
    assert "a: [-180.0, 180.0]" in text and "b: [-90.0, 90.0]" in text
    assert machine_from_text(text).workspace is not None

    small = ini.read_text().replace("[AXIS_A]\nMIN_LIMIT = -1000.0\nMAX_LIMIT = 1000.0",
                                    "[AXIS_A]\nMIN_LIMIT = -10\nMAX_LIMIT = 20")
    assert small != ini.read_text()
    ini.write_text(small)
    got = machine_from_linuxcnc(hal, ini)
    np.testing.assert_allclose(np.rad2deg(got.machine.workspace[3]), [-10.0, 20.0], rtol=1e-12)
    assert not [n for n in got.notes if "[AXIS_A]" in n]

    ini.write_text(small.replace("[AXIS_Y]\nMIN_LIMIT = -1000.0\n", "[AXIS_Y]\n"))
    got = machine_from_linuxcnc(hal, ini)
    assert got.machine.workspace is None
    assert any("no [AXIS_Y] MIN_LIMIT/MAX_LIMIT" in n and "no 'workspace:' imported" in n for n in got.notes)

    ini.write_text(small.replace("[AXIS_Z]\nMIN_LIMIT = -1000.0\nMAX_LIMIT = 1000.0",
                                 "[AXIS_Z]\nMIN_LIMIT = 10\nMAX_LIMIT = 5"))
    with pytest.raises(InputFileError, match=r"\[AXIS_Z\] MAX_LIMIT < MIN_LIMIT") as exc:
        machine_from_linuxcnc(hal, ini)
    assert str(ini) in str(exc.value) and "line" in str(exc.value)


def test_home_angles_beyond_180_are_wrapped_with_a_note(tmp_path):
    """[TRAJ] HOME = 0 0 20 370 0 -190 (degrees): the same orientation as 10, 0, 170, which
    the machine file's home gets, with a note; the home strut lengths are unchanged."""
    from helpers import write_linuxcnc_hexapod_sample

    hal, ini = write_linuxcnc_hexapod_sample(tmp_path)
    text = ini.read_text()
    assert "HOME = 0 0 20 0 0 0" in text
    ini.write_text(text.replace("HOME = 0 0 20 0 0 0", "HOME = 0 0 20 10 0 170"))
    plain = machine_from_linuxcnc(hal, ini)
    ini.write_text(text.replace("HOME = 0 0 20 0 0 0", "HOME = 0 0 20 370 0 -190"))
    turned = machine_from_linuxcnc(hal, ini)
    np.testing.assert_allclose(np.rad2deg(turned.machine.home_pose[3:]), [10.0, 0.0, 170.0], rtol=0, atol=1e-12)
    assert any("[TRAJ] HOME = 0 0 20 370 0 -190" in n for n in turned.notes)
    assert not any("[TRAJ] HOME =" in n for n in plain.notes)
    np.testing.assert_allclose(turned.machine.leg_lengths(turned.machine.home_pose),
                               plain.machine.leg_lengths(plain.machine.home_pose), rtol=1e-12)

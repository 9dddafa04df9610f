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
the output may not be the input file. The command checks its options, calls
:func:`pkmcal.workflow.export.export_machine` (which makes the texts and the refit, and whose
notes it prints on standard error as they come) and writes.
"""

from __future__ import annotations

import json
import os

import click

from pkmcal.cli.options import check_output, emit, examples, option, output_option, quiet_accepted, to_stdout
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.errors import PkmcalError
from pkmcal.workflow.export import export_machine

@click.command("export", epilog=examples(
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal",
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal --ini joints.ini",
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal --update-ini joints.ini --ini machine.ini",
    "pkmcal export calibrated.yaml --format json -o calibrated.json",
    "pkmcal export stewart-prototype --format linuxcnc",
    "pkmcal export kossel-mini --format klipper",
    "pkmcal export kossel-mini --format marlin",
    "pkmcal export kossel-mini --format marlin --marlin-version 1.1.8",
    "pkmcal export kossel-mini --format marlin --marlin-version 2.0.5.3 --steps-per-mm 80",
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
@click.option("--marlin-version", "marlin_version", metavar="VERSION", default="2.1.x", show_default=True,
              help="marlin: the Marlin the settings are for, as M115 prints it (e.g. 1.1.8, 2.0.9.3, 2.1.2; or "
                   "2.1.x): M665's letters and homing differ (1.1.x and 2.0.0-2.0.5.x have no rod trims in M665; "
                   "1.1.0-1.1.5 hold tower C at 90 deg).")
@click.option("--steps-per-mm", "steps_per_mm", type=FiniteFloat(min=0.0, min_open=True), metavar="STEPS",
              help="marlin, --marlin-version 1.1.9 to 2.0.5.x: the towers' steps per mm (M92), for their homing's "
                   "extra MIN_STEPS_PER_SEGMENT + 1 steps.")
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
        raise PkmcalError("--setup, --held-out and --json belong to the firmware-limited refit: give --calibration-measurements "
                          "MEAS.csv too")
    if fmt == "marlin":                            # the version's error before any work
        from pkmcal.io.marlin_settings import marlin_dialect

        marlin_dialect(marlin_version)
    if (no_refit or accept_undetermined) and fmt not in ("klipper", "marlin"):
        raise PkmcalError(f"--no-refit and --accept-undetermined are for --format klipper or marlin, not {fmt}")
    if no_refit and measurements is not None:
        raise PkmcalError("--no-refit exports without the refit that --calibration-measurements asks for: give one of them")
    if measurements is not None and fmt not in ("klipper", "marlin"):
        raise PkmcalError(f"--calibration-measurements refits a linear delta for its firmware: use it with --format klipper or "
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
    done = export_machine(calibrated, fmt, ini=ini is not None, update_ini=update_ini, stroke_margin=stroke_margin,
                          measurements=measurements, setup=setup_spec, heldout=heldout, klipper_config=klipper_config,
                          marlin_version=marlin_version, steps_per_mm=steps_per_mm, refit=not no_refit,
                          accept_undetermined=accept_undetermined, output=output,
                          note=lambda line: click.echo(line, err=True))
    text, ini_text, refit = done.text, done.ini_text, done.refit
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


__all__ = ["export_cmd"]

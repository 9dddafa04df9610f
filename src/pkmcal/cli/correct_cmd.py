"""``pkmcal compensate`` and ``pkmcal correct``: a correction of what the calibrated model
leaves, kept only when held-out data show it helps (:mod:`pkmcal.compensation.fit`), its
Klipper bed mesh profile (:mod:`pkmcal.compensation.files`), and programs filtered through
the calibrated model plus the correction for a controller that runs its nominal kinematics
(:mod:`pkmcal.compensation.apply`, :mod:`pkmcal.compensation.gcode`).

Why a command of its own rather than ``identify --compensate``: the correction is fitted to
what a calibration leaves, so it comes after one (and after its held-out check), may be
refitted from new held-out probing without recalibrating, and writes files for other
programs (Klipper's block) that identify has no business writing.
"""

from __future__ import annotations

import json
import os

import click
import numpy as np

from pkmcal.cli.import_options import import_options
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.cli.options import (check_output, emit, examples, option, output_option, quiet_accepted, quiet_option,
                                summary_echo, to_stdout)
from pkmcal.errors import PkmcalError, PkmcalWarning


def _counts(text: str | None, what: str, low: int, high: int) -> tuple[int, ...] | None:
    if text is None:
        return None
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise PkmcalError(f"--{what} '{text}': give integers separated by commas, e.g. 3,5,7") from None
    bad = [v for v in values if not low <= v <= high]
    if bad or not values:
        raise PkmcalError(f"--{what} '{text}': each must be within {low}..{high}")
    return values


@click.command("compensate", epilog=examples(
    "pkmcal identify kossel-mini examples/compensation/warped-bed-meas.csv --setup z-probe-klipper --accept-bad-fit "
    "-o warped-cal.yaml",
    "pkmcal compensate warped-cal.yaml examples/compensation/warped-bed-meas.csv --held-out "
    "examples/compensation/warped-bed-heldout.csv -o bed-correction.yaml --klipper-mesh bed-mesh.cfg",
    "pkmcal compensate warped-cal.yaml examples/compensation/warped-bed-meas.csv --held-out "
    "examples/compensation/warped-bed-heldout.csv --json -o bed-correction-2.yaml"))
@click.argument("calibrated")
@click.argument("measurements")
@option("--held-out", "heldout_path", old=("--heldout",), required=True, metavar="HELDOUT.csv",
              help="Held-out measurements (as MEAS.csv, not used by the calibration): the correction is kept only "
                   "when it lowers their error significantly.")
@click.option("--setup", "setup_spec", metavar="SETUP.yaml",
              help="The measurement setup (default: the sensor identified in CALIBRATED's setup:).")
@click.option("--field", type=click.Choice(["auto", "bed-mesh", "pose"]), default="auto", show_default=True,
              help="bed-mesh: a Klipper mesh of the bed's heights (a Z probe); pose: a polynomial field over the "
                   "pose; auto: bed-mesh for a Z probe, else pose.")
@click.option("--counts", metavar="N,N,...", help="Mesh sizes tried, nodes a side (default 3,4,5,6,7).")
@click.option("--degrees", metavar="D,D,...", help="Polynomial degrees tried (default 0,1,2,3).")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Seed of the cross-validation's folds.")
@click.option("--klipper-mesh", "mesh_out", metavar="FILE",
              help="Also write the bed mesh as Klipper's SAVE_CONFIG block ([bed_mesh PROFILE]); with --config "
                   "the whole printer.cfg with the block updated.")
@option("--config", "printer_cfg", old=("--printer-cfg",), metavar="PRINTER.cfg",
              help="With --klipper-mesh: the printer.cfg whose SAVE_CONFIG block receives the profile (it is read, "
                   "never overwritten).")
@click.option("--profile", default="default", show_default=True, help="Klipper's profile name.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@output_option("CORRECTION.yaml", "The correction file (written only when the correction is kept)")
@quiet_option
@import_options
def compensate_cmd(calibrated, measurements, heldout_path, setup_spec, field, counts, degrees, seed, mesh_out,
                   printer_cfg, profile, as_json, output, quiet, mapping) -> None:
    """Fit what CALIBRATED leaves on MEAS.csv, keep it only if HELDOUT.csv confirms it.

    The residuals the calibrated model leaves on its calibration data are fitted by a smooth
    field: for a Z probe a Klipper bed mesh (the bed's heights, interpolated as Klipper's
    bed_mesh does), otherwise a polynomial displacement over the pose. Its size (mesh
    nodes, polynomial degree) is chosen by 5-fold cross-validation over the poses (the
    simplest within one standard error of the best, or none). The chosen field is kept only
    when it lowers the held-out error by more than 2 standard errors; the report gives the
    candidates' scores, the held-out RMS before and after, and the decision. A kept
    correction is written to -o (for 'pkmcal correct --correction') and, with
    --klipper-mesh, as Klipper's bed_mesh profile. Nothing is written when it is rejected
    (exit code 0: a rejection is an answer).
    """
    from pkmcal.workflow.inputs import machine_and_setup
    from pkmcal.compensation.files import klipper_block, klipper_profile, save_correction
    from pkmcal.compensation.fit import compensate
    from pkmcal.io.atomic import atomic_write_text, check_output_path
    from pkmcal.io.measurements import load_measurements

    inputs = [calibrated, measurements, heldout_path, setup_spec, printer_cfg]
    check_output(output, inputs)
    if mesh_out is not None:
        check_output_path(mesh_out, inputs + [output])
    elif printer_cfg is not None:
        raise PkmcalError("--config is the printer.cfg the --klipper-mesh output updates; give --klipper-mesh")
    if as_json and to_stdout(output):
        raise PkmcalError("--json prints the report on standard output: write the correction to a file with -o")
    machine, setup = machine_and_setup(calibrated, setup_spec or calibrated)
    kind = {"auto": None, "bed-mesh": "bed-mesh", "pose": "pose-field"}[field]
    if mesh_out is not None and kind == "pose-field":
        raise PkmcalError("--klipper-mesh writes a bed mesh; leave out --field pose")
    options = {}
    if (c := _counts(counts, "counts", 3, 15)) is not None:
        options["counts"] = c
    if (d := _counts(degrees, "degrees", 0, 4)) is not None:
        options["degrees"] = d
    meas = load_measurements(measurements, machine, setup, mapping)
    held = load_measurements(heldout_path, machine, setup, mapping)
    report = compensate(machine, setup, meas, held, kind, seed=seed, **options)
    if mesh_out is not None and report.kind != "bed-mesh":
        raise PkmcalError(f"--klipper-mesh writes a bed mesh; {calibrated} was calibrated with a "
                          f"'{setup.sensor.kind}' sensor, whose correction is a pose field")
    say = summary_echo(output) if not as_json else (lambda m="": click.echo(m, err=True))
    if as_json:
        from pkmcal.io.json_out import finite_or_null

        click.echo(json.dumps(finite_or_null(report.to_dict()), indent=2, allow_nan=False))
    else:
        for line in report.lines():
            say(line)
    if not report.accepted:
        say("nothing written" + (f" ({output} and {mesh_out} left as they were)" if mesh_out and output else ""))
        return
    text = save_correction(None, report.field, machine, report.to_dict())
    if mesh_out is not None:
        if printer_cfg is not None:
            from pkmcal.io.klipper_config import save_config_text

            atomic_write_text(mesh_out, save_config_text(printer_cfg, klipper_profile(report.field, profile)))
        else:
            atomic_write_text(mesh_out, klipper_block(report.field, profile))
        say(f"Klipper bed mesh profile '{profile}' written to {mesh_out} (needs a [bed_mesh] section; "
            f"BED_MESH_PROFILE LOAD={profile} applies it)")
    emit(text, output)


def _is_pose_file(path: str) -> bool:
    return os.path.splitext(path)[1].lower() in (".csv", ".tsv", ".txt")


@click.command("correct", epilog=examples(
    "pkmcal correct examples/compensation/part.gcode -m warped-cal.yaml --correction bed-correction.yaml "
    "-o part-corrected.gcode",
    "pkmcal correct examples/compensation/part.gcode -m warped-cal.yaml --correction bed-correction.yaml "
    "--segment 5 -o part-split.gcode",
    "pkmcal correct examples/compensation/targets.csv -m warped-cal.yaml --correction bed-correction.yaml "
    "-o commanded.csv",
    "pkmcal correct examples/compensation/hexapod.ngc -m calibrated.yaml --nominal stewart-prototype "
    "--ignore-limit leg_collision -o hexapod-corrected.ngc"))
@click.argument("program")
@click.option("-m", "--calibrated", "calibrated", required=True, metavar="CALIBRATED",
              help="The calibrated machine (pkmcal identify's output).")
@click.option("--nominal", metavar="NOMINAL",
              help="The kinematics the controller runs (default: the nominal machine the calibration record names).")
@click.option("--correction", "correction_path", metavar="FILE",
              help="A correction kept by 'pkmcal compensate' (default: the calibrated model alone).")
@click.option("--ignore-limit", "ignore_limits", multiple=True, metavar="NAME",
              help="A limit of the calibrated machine not to check (e.g. leg_collision); repeatable.")
@click.option("--segment", type=FiniteFloat(min=0.1), metavar="MM",
              help="G-code: split moves longer than MM (in x, y, z) into equal pieces, each corrected, the "
                   "extrusion shared (as Klipper's bed mesh splits moves every 5 mm). Default: end points only.")
@output_option("OUT", "The corrected program or pose file")
@import_options
@quiet_accepted
def correct_cmd(program, calibrated, nominal, correction_path, ignore_limits, segment, output, mapping) -> None:
    """Filter PROGRAM through the calibrated model (plus a correction) for a nominal controller.

    A controller that runs the machine's nominal kinematics (a printer whose config was not
    updated, LinuxCNC's genhexkins with the drawing's numbers) goes where the calibrated
    model plus the correction says it should when commanded the filtered program: each
    target is reached by the calibrated model at x with x + correction(x) = target, its
    actuators there are IK(x), and the command is the pose whose nominal IK gives them. A bed
    mesh adds the bed's height under the nozzle to z (targets relative to the bed).
    PROGRAM is G-code (G0/G1 X Y Z [A B C] moves replaced, every other byte kept; G91, G20,
    arcs and G92 with axes refused with their line; --segment MM splits long moves so that the
    correction is applied along them, not only at their ends) or a pose CSV (.csv: the machine's pose
    columns, written back in mm and degrees). A target the calibrated machine cannot reach
    is refused with its line.
    """
    from pkmcal.workflow.verify import nominal_from_record
    from pkmcal.compensation.apply import commands_for
    from pkmcal.compensation.files import load_correction
    from pkmcal.io.atomic import atomic_write_bytes
    from pkmcal.io.lookup import load_machine

    check_output(output, [program, calibrated, nominal, correction_path])
    cal = load_machine(calibrated)
    if nominal is not None:
        nom = load_machine(nominal)
    else:
        nom, why = nominal_from_record(cal)
        if nom is None:
            raise PkmcalError(f"the controller's kinematics: {why}")
    fld = None if correction_path is None else load_correction(correction_path, cal)
    if _is_pose_file(program):
        from pkmcal.io.tables import column_kinds, format_table, from_file_units, read_table, to_file_units

        table = read_table(program, cal.pose_names, kinds=column_kinds(cal.pose_names, cal.pose_is_angle),
                           mapping=mapping)
        targets = from_file_units(table.values, cal.pose_is_angle)
        lines = [int(v) for v in table.lines]
        result = commands_for(cal, nom, fld, targets, tuple(ignore_limits))
        _refuse(program, lines, result)
        out = to_file_units(result.commands, cal.pose_is_angle)
        text = format_table({n: out[:, k] for k, n in enumerate(cal.pose_names)})
        emit(text, output)
        summary_echo(output)(f"{len(targets)} poses filtered for the controller's kinematics ('{nom.name}')")
        return
    from pkmcal.compensation.gcode import parse_moves, rewrite

    try:
        with open(program, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise PkmcalError(f"{program}: cannot read the program ({exc.strerror})") from None
    text = raw.decode("utf-8", errors="surrogateescape")
    src_lines = text.splitlines(keepends=True)
    axes = tuple(n.upper() for n in cal.pose_names)
    if any(len(a) != 1 for a in axes):
        raise PkmcalError(f"machine '{cal.name}' has pose coordinates {', '.join(cal.pose_names)}, which are no "
                          "G-code axis letters; give its targets as a pose CSV")
    moves, skipped = parse_moves(src_lines, axes, program, segment)
    targets = np.vstack([mv.targets for mv in moves] or [np.zeros((0, len(axes)))])
    from pkmcal.io.tables import from_file_units, to_file_units

    result = commands_for(cal, nom, fld, from_file_units(targets, cal.pose_is_angle), tuple(ignore_limits))
    _refuse(program, [mv.line + 1 for mv in moves for _ in range(len(mv.targets))], result)
    new = rewrite(src_lines, moves, to_file_units(result.commands, cal.pose_is_angle), axes)
    data = "".join(new).encode("utf-8", errors="surrogateescape")
    if to_stdout(output):
        click.echo(data, nl=False)
    else:
        atomic_write_bytes(output, data)
    say = summary_echo(output)
    say(f"{len(moves)} moves filtered for the controller's kinematics ('{nom.name}')"
        + (f", split into {len(targets)} pieces of at most {segment:g} mm" if segment else "")
        + ("" if fld is None else f" with the {fld.kind} correction of {correction_path}"))
    if skipped:
        import warnings

        shown = ", ".join(map(str, skipped[:10])) + (", ..." if len(skipped) > 10 else "")
        warnings.warn(f"{program}: {len(skipped)} move(s) before every coordinate was known (after the start or "
                      f"G28) left as they are, uncorrected: line(s) {shown}", PkmcalWarning, stacklevel=1)


def _refuse(src: str, lines: list[int], result) -> None:
    bad = np.flatnonzero(~result.ok)
    if len(bad):
        k = int(bad[0])
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise PkmcalError(f"{src}:{lines[k]}: the target cannot be reached: {result.reasons[k]}{more}; keep the "
                          "program inside the machine's workspace")


__all__ = ["compensate_cmd", "correct_cmd"]

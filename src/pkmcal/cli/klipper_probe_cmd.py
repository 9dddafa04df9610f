"""``pkmcal import klipper-probe``: Klipper's Z-probe results as a measurement file.

``pkmcal import klipper-probe LOG_OR_CFG --machine DELTA.yaml -o MEAS.csv`` reads the probe
lines of a Klipper console log or the ``#*#`` DELTA_CALIBRATE block of a printer.cfg
(:mod:`pkmcal.io.klipper_probe`) and writes the measurement CSV that ``pkmcal identify
DELTA.yaml MEAS.csv --setup PROBE.yaml`` fits: ``lambda1..3`` (carriage positions),
``probe_z`` and the firmware's pose ``cmd_x..cmd_z``. Registered in the ``import`` group.

``pkmcal import marlin-probe LOG --machine DELTA.yaml -o MEAS.csv`` reads Marlin's G30 lines
(:mod:`pkmcal.io.marlin_probe`) into the same measurement file. No output may name an input:
the log or printer.cfg, any file it ``[include]``s, the machine and setup files.

``pkmcal import klipper-analyze CFG_OR_LOG --machine DELTA.yaml -o PAIRS.csv`` reads
Klipper's DELTA_ANALYZE printed-object distances and the probe heights
(:mod:`pkmcal.io.klipper_analyze`) as measurements of pose pairs (``lambda1..3``,
``lambda1_2..lambda3_2``, ``probe_z``, ``distance``, ``cmd_*``), for a ``printed-distance``
setup.
"""

from __future__ import annotations

import contextlib

import click

from pkmcal.cli.options import check_output, examples, output_option, to_stdout
from pkmcal.workflow.inputs import klipper_analyze_pairs, setup_of_kind


@click.command("klipper-probe", epilog=examples(
    "pkmcal import klipper-probe examples/klipper/probe-console.log --machine kossel-mini -o probe-meas.csv",
    "pkmcal import klipper-probe examples/klipper/probe-console.log --machine kossel-mini --setup z-probe-klipper"))
@click.argument("source", metavar="LOG_OR_CFG")
@click.option("--machine", "machine_spec", required=True, metavar="DELTA.yaml",
              help="The printer's machine file (from 'pkmcal import klipper printer.cfg'), or a built-in name: its "
                   "parameters are the firmware configuration the probe ran with.")
@click.option("--setup", "setup_spec", default="z-probe-klipper", show_default=True, metavar="PROBE.yaml",
              help="The z-probe setup: its probe_offset is Klipper's [probe] x_offset, y_offset, z_offset.")
@output_option("MEAS.csv", "Measurement file to write")
def klipper_probe_cmd(source: str, machine_spec: str, setup_spec: str, output: str | None) -> None:
    """Read Klipper's Z-probe results as a pkmcal measurement file (z-probe sensor).

    LOG_OR_CFG: a console or klippy log with 'probe at X,Y is z=Z' lines (older Klipper:
    the nozzle position) or 'probe: at X,Y bed will contact at z=Z' lines (later Klipper:
    the probe point; the setup's probe offset is added back), from PROBE, PROBE_ACCURACY,
    DELTA_CALIBRATE or BED_MESH_CALIBRATE; or a printer.cfg whose SAVE_CONFIG (#*#) block
    holds DELTA_CALIBRATE's [delta_calibrate] heightN and heightN_pos (steps below the
    endstops, converted with each stepper's rotation_distance, microsteps,
    full_steps_per_rotation and gear_ratio). The carriage positions are those of MACHINE
    at the logged positions; probe_z is 0 at every trigger (the probe point on the bed).
    Manual probing is read too (with a setup whose probe x, y offset is 0): MANUAL_PROBE's
    'Z position is Z' (at the x, y of the last G1 X Y) and DELTA_ANALYZE MANUAL_HEIGHT's
    'Adding manual height: X,Y,Z is actually z=H'. A value that is not finite or beyond any
    printer is refused with its line; lines that mention a probe result but cannot be read
    are counted in a note.
    """
    check_output(output, input_files(source, machine_spec, setup_spec))
    from pkmcal.io.klipper_probe import read_klipper_probe, require_linear_delta
    from pkmcal.io.lookup import load_machine

    machine = load_machine(machine_spec)
    require_linear_delta(machine, "Klipper's probe results", f"--machine {machine_spec}")
    setup = setup_of_kind(setup_spec, machine, "z-probe", "Klipper's probe results")
    result = read_klipper_probe(source, machine, setup.sensor.probe_offset)
    _write(result, machine, setup, output, f"from Klipper probe results {source}", "pose(s)")


@click.command("marlin-probe", epilog=examples(
    "pkmcal import marlin-probe examples/marlin/g30-terminal.log --machine kossel-mini -o marlin-probe.csv"))
@click.argument("source", metavar="LOG")
@click.option("--machine", "machine_spec", required=True, metavar="DELTA.yaml",
              help="The printer's machine file (from 'pkmcal import marlin M503.txt'), or a built-in name: its "
                   "parameters are the firmware configuration the probe ran with.")
@click.option("--setup", "setup_spec", default="z-probe-klipper", show_default=True, metavar="PROBE.yaml",
              help="The z-probe setup: its probe_offset is Marlin's M851 X, Y and minus its Z (Klipper's sign: "
                   "z_offset the nozzle's height above the bed when the probe triggers).")
@output_option("MEAS.csv", "Measurement file to write")
def marlin_probe_cmd(source: str, machine_spec: str, setup_spec: str, output: str | None) -> None:
    """Read Marlin's G30 probe results as a pkmcal measurement file (z-probe sensor).

    LOG: a terminal log (Pronterface, OctoPrint, a serial console) with Marlin's G30 lines
    'Bed X: x Y: y Z: z' (x, y the probe's position; z the nozzle height at the trigger plus
    the M851 z offset), e.g. of the G-code 'pkmcal plan --format gcode' writes. The nozzle was
    at the probe's position less the setup's probe x, y offset; the carriage positions are
    those of MACHINE there; probe_z is 0 at every trigger.
    """
    check_output(output, input_files(source, machine_spec, setup_spec))
    from pkmcal.io.klipper_probe import require_linear_delta
    from pkmcal.io.lookup import load_machine
    from pkmcal.io.marlin_probe import read_marlin_probe

    machine = load_machine(machine_spec)
    require_linear_delta(machine, "Marlin's probe results", f"--machine {machine_spec}")
    setup = setup_of_kind(setup_spec, machine, "z-probe", "Marlin's probe results")
    result = read_marlin_probe(source, machine, setup.sensor.probe_offset)
    _write(result, machine, setup, output, f"from Marlin G30 probe results {source}", "pose(s)")


def input_files(source: str, *specs: str | None) -> list[str]:
    """Every file an import reads, none of which its output may name: ``source`` and, when
    it is a Klipper config, every file it ``[include]``s (:func:`pkmcal.io.klipper_config.read_config`),
    and the machine and setup files given (built-in names are not files)."""
    from pkmcal.errors import PkmcalError
    from pkmcal.io.klipper_config import read_config

    files = [source]
    # not a config (a console log), or one whose errors the import reports: the source alone
    with contextlib.suppress(PkmcalError, OSError, ValueError):
        files += [f for f in read_config(source).files if f not in files]
    return files + [s for s in specs if s is not None]


def _write(result, machine, setup, output: str | None, comment: str, rows: str) -> None:
    """The imported measurements to ``output`` (or standard output) and the notes on stderr."""
    from pkmcal.io.measurements import measurement_columns, save_measurements
    from pkmcal.io.tables import format_table

    if to_stdout(output):
        click.echo(format_table(measurement_columns(result.measurements, machine, setup)), nl=False)
    else:
        save_measurements(output, result.measurements, machine, setup, comments=(comment,))
    for note in result.notes:
        click.echo(f"note: {note}", err=True)
    if not to_stdout(output):
        click.echo(f"wrote {output}: {len(result.measurements)} {rows}", err=True)


@click.command("klipper-analyze", epilog=examples(
    "pkmcal import klipper-analyze examples/klipper/delta-analyze.log --machine kossel-mini --object-machine "
    "kossel-mini -o pairs.csv"))
@click.argument("source", metavar="CFG_OR_LOG")
@click.option("--machine", "machine_spec", required=True, metavar="DELTA.yaml",
              help="The printer's machine file (its firmware configuration), or a built-in name.")
@click.option("--setup", "setup_spec", default="printed-distance-klipper", show_default=True, metavar="SETUP.yaml",
              help="The printed-distance setup: its probe_offset is Klipper's [probe] x_offset, y_offset, z_offset.")
@click.option("--object-machine", "object_spec", metavar="OBJECT.yaml",
              help="A console log: the machine file of the config the object was printed with (Klipper's procedure "
                   "saves DELTA_CALIBRATE's result with SAVE_CONFIG before printing it: 'pkmcal import klipper' of "
                   "that printer.cfg); --machine is the config the probe ran with. The same file as --machine if "
                   "nothing was saved in between. Needed when the log has both.")
@output_option("PAIRS.csv", "Measurement file to write")
def klipper_analyze_cmd(source: str, machine_spec: str, setup_spec: str, output: str | None,
                        object_spec: str | None = None) -> None:
    """Read Klipper's DELTA_ANALYZE distances and probe heights as pose-pair measurements.

    CFG_OR_LOG: a printer.cfg whose SAVE_CONFIG (#*#) block holds [delta_calibrate]
    distanceN with distanceN_pos1/_pos2 and heightN with heightN_pos (steps below the
    endstops); or a console log with the DELTA_ANALYZE CENTER_DISTS=... CENTER_PILLAR_WIDTHS=...
    OUTER_DISTS=... OUTER_PILLAR_WIDTHS=... [SCALE=...] commands and the probe result lines.
    Each row is two points: a distance row holds the carriage positions of both printed points
    and 'distance'; a height row holds one probed point twice and 'probe_z'. In a console
    log the probe ran with one config (--machine) and the object was printed with the one
    SAVE_CONFIG wrote after DELTA_CALIBRATE (--object-machine); the carriage positions are
    all written in --machine's (identify with it). A distance far from the object's nominal
    is refused as a likely typo.
    """
    check_output(output, input_files(source, machine_spec, setup_spec, object_spec))
    result, pairs, setup = klipper_analyze_pairs(source, machine_spec, setup_spec, object_spec)
    _write(result, pairs, setup, output, f"from Klipper DELTA_ANALYZE results {source}; each row a pair of poses",
           "row(s)")


__all__ = ["input_files", "klipper_analyze_cmd", "klipper_probe_cmd", "marlin_probe_cmd"]

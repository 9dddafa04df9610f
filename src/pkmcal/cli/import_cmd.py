"""``pkmcal import``: a machine file from a controller's configuration.

``pkmcal import klipper printer.cfg -o DELTA.yaml`` and ``pkmcal import marlin M503.txt -o
DELTA.yaml`` read a linear delta printer's firmware settings
(:mod:`pkmcal.io.delta_firmware`); the inverses of ``pkmcal export --format klipper|marlin``.

``pkmcal import linuxcnc HAL [INI] -o MACHINE.yaml`` reads LinuxCNC's genhexkins joints
(``setp genhexkins.base.N.*`` / ``platform.N.*``) and the INI file's units, home pose and
joint limits (:func:`pkmcal.io.import_linuxcnc.machine_from_linuxcnc`); the inverse of
``pkmcal export --format linuxcnc --ini``. The machine file is written atomically and
checked to load back to the same machine (:func:`pkmcal.io.machine_file.save_machine`).
"""

from __future__ import annotations

import os

import click

from pkmcal.cli.options import check_output, examples, output_option, to_stdout
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.errors import PkmcalError

_OFFSET_HELP = ("home-offset (default): L0 = [JOINT_N] HOME_OFFSET, readings zero at the home switch (as pkmcal "
                "exports); zero: L0 = 0, readings = LinuxCNC joint values (strut lengths), genhexkins' convention.")


@click.group("import", epilog=examples(
    "pkmcal import linuxcnc examples/linuxcnc/hexapod.hal examples/linuxcnc/hexapod.ini -o imported.yaml",
    "pkmcal import linuxcnc examples/linuxcnc/hexapod.hal examples/linuxcnc/hexapod.ini --offsets zero",
    "pkmcal import klipper examples/klipper/printer.cfg -o delta.yaml",
    "pkmcal import marlin examples/marlin/m503.txt"))
def import_group() -> None:
    """Make a machine file from a controller's configuration (LinuxCNC, Klipper, Marlin).

    linuxcnc: genhexkins HAL and INI (hexapods); klipper: printer.cfg of a delta printer;
    marlin: its M665/M666 settings. Run 'pkmcal import NAME --help' for what each reads.
    """


def _parse_limits(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise PkmcalError(f"--joint-limits '{text}': give MIN,MAX (strut lengths, mm), e.g. 280,380") from None
    if not (abs(lo) < 1e6 and abs(hi) < 1e6) or hi < lo:
        raise PkmcalError(f"--joint-limits '{text}': give finite MIN <= MAX (mm)")
    return lo, hi


@import_group.command("linuxcnc", epilog=examples(
    "pkmcal import linuxcnc examples/linuxcnc/hexapod.hal examples/linuxcnc/hexapod.ini -o imported.yaml",
    "pkmcal import linuxcnc kinematics.hal joints.ini -o round-trip.yaml",
    "pkmcal import linuxcnc examples/linuxcnc/hexapod.hal --joint-limits 300,360 --name my-hexapod"))
@click.argument("hal", metavar="HAL")
@click.argument("ini", metavar="[INI]", required=False)
@output_option("MACHINE.yaml", "Machine file to write")
@click.option("--offsets", type=click.Choice(["home-offset", "zero"]), default="home-offset", show_default=True,
              help=_OFFSET_HELP)
@click.option("--joint-limits", metavar="MIN,MAX",
              help="Strut length limits (mm) of every joint, instead of the INI's [JOINT_N] MIN_LIMIT/MAX_LIMIT "
                   "(needed without an INI file).")
@click.option("--length-unit", type=click.Choice(["mm", "cm", "inch"]), default=None,
              help="Unit of the HAL and INI lengths, instead of [TRAJ] LINEAR_UNITS (default mm).")
@click.option("--name", metavar="NAME", help="Machine name (default: [EMC] MACHINE, else the HAL file's name).")
def linuxcnc_cmd(hal: str, ini: str | None, output: str | None, offsets: str, joint_limits: str | None,
                 length_unit: str | None, name: str | None) -> None:
    """Read a LinuxCNC genhexkins configuration as a pkmcal hexapod machine file.

    HAL: the file with 'setp genhexkins.base.N.x|y|z' and 'setp genhexkins.platform.N.x|y|z'
    (N = 0..5 = leg N+1; also 'NAME = VALUE', [SECTION]KEY from the INI file, '\\'
    continuations, as halcmd reads them). INI (optional): [TRAJ] LINEAR_UNITS and HOME (the
    home pose), [KINS], and per joint [JOINT_N] MIN_LIMIT, MAX_LIMIT (the stroke),
    HOME_OFFSET (the leg offset, see --offsets) and HOME. genhexkins' joint is the strut
    length L = L0 + reading. The inverse of 'pkmcal export --format linuxcnc --ini'.
    """
    check_output(output, [hal] + ([ini] if ini else []))
    from pkmcal.io.import_linuxcnc import machine_from_linuxcnc
    from pkmcal.io.machine_file import machine_to_text, save_machine

    result = machine_from_linuxcnc(hal, ini, offsets=offsets, joint_limits=_parse_limits(joint_limits),
                                   length_unit=length_unit, name=name)
    m = result.machine
    if to_stdout(output):
        click.echo(machine_to_text(m), nl=False)
    else:
        save_machine(m, output)
    for note in result.notes:
        click.echo(f"note: {note}", err=True)
    L0 = ", ".join(f"{v:.6g}" for v in m.offset)
    click.echo(f"machine '{m.name}': 6 legs, L0 = [{L0}] mm ({offsets}); stroke "
               f"[{m.stroke[:, 0].min():.6g}, {m.stroke[:, 1].max():.6g}] mm", err=True)
    if not to_stdout(output):
        click.echo(f"wrote {output}", err=True)


def _write_delta(machine, output: str | None, source: str, kind: str = "linear delta") -> None:
    from pkmcal.io.machine_file import machine_to_text, save_machine

    if to_stdout(output):
        click.echo(machine_to_text(machine), nl=False)
    else:
        save_machine(machine, output)
    click.echo(f"machine '{machine.name}': {kind} from {source}", err=True)
    if not to_stdout(output):
        click.echo(f"wrote {output}", err=True)


def _delta_name(path: str, name: str | None) -> str:
    from pathlib import Path

    from pkmcal.errors import one_line

    return name if name is not None else one_line(Path(path).stem)


@import_group.command("klipper", epilog=examples(
    "pkmcal import klipper examples/klipper/printer.cfg -o delta.yaml",
    "pkmcal import klipper examples/klipper/printer.cfg -o kossel.yaml --setup-output probe.yaml",
    "pkmcal import klipper examples/klipper/printer.cfg --name my-kossel"))
@click.argument("config", metavar="PRINTER.cfg")
@output_option("DELTA.yaml", "Machine file to write")
@click.option("--name", metavar="NAME", help="Machine name (default: the config file's name).")
@click.option("--setup-output", "setup_output", metavar="PROBE.yaml",
              help="Also write the z-probe setup of this printer: its [probe] or [bltouch] x_offset, y_offset, "
                   "z_offset, with the noise of the built-in z-probe-klipper (give it to plan, simulate, import "
                   "klipper-probe and identify with --setup).")
def klipper_cmd(config: str, output: str | None, name: str | None, setup_output: str | None) -> None:
    """Read a Klipper delta printer's printer.cfg as a pkmcal machine file, as Klipper reads it.

    kinematics: delta — [printer] delta_radius, print_radius, minimum_z_position and, per
    [stepper_a|b|c], angle (default 210, 330, 90), arm_length and position_endstop (b and c
    default to a's); the rail travel and build radius are those Klipper's kinematics allow.
    kinematics: rotary_delta — [printer] shoulder_radius, shoulder_height and per stepper
    angle (default 30, 150, 270), upper_arm_length, lower_arm_length, position_endstop.
    As Klipper: [include] files are read where they stand (globs, relative to the including
    file; later values win); an option of the SAVE_CONFIG (#*#) block that the main file
    also sets is overridden by the main file's, and the whole block is ignored when anything
    follows it (a note says so). [probe] / [bltouch] offsets are printed, and written as a
    setup with --setup-output. The inverse of 'pkmcal export --format klipper'.
    """
    check_output(output, [config])
    if setup_output is not None:
        check_output(setup_output, [config])
        if output is not None and os.path.abspath(setup_output) == os.path.abspath(output):
            raise PkmcalError("-o and --setup-output name the same file; choose two paths")
    from pkmcal.io.delta_firmware import RotaryFirmware, read_klipper_printer

    printer = read_klipper_printer(config)
    for out in (output, setup_output):             # nor any file printer.cfg includes
        if out is not None:
            check_output(out, list(printer.files))
    if setup_output is not None and printer.probe_offset is None:
        raise PkmcalError(f"{config} has no [probe] or [bltouch] section: there is no probe offset to write; "
                          "drop --setup-output or add the probe's section")
    for note in printer.notes:
        click.echo(f"note: {note}", err=True)
    kind = "rotary delta" if isinstance(printer.firmware, RotaryFirmware) else "linear delta"
    _write_delta(printer.machine(_delta_name(config, name)), output, f"Klipper config {config}", kind)
    if printer.probe_offset is not None:
        x, y, z = printer.probe_offset
        click.echo(f"probe: [{printer.probe_section}] x_offset {x:g}, y_offset {y:g}, z_offset {z:g} mm"
                   + ("" if setup_output else " (write them as a setup with --setup-output PROBE.yaml, or give them "
                      "as probe_offset in your setup file)"), err=True)
    if setup_output is not None:
        from pkmcal.io.setup_file import save_setup
        from pkmcal.workflow.inputs import klipper_probe_setup

        save_setup(klipper_probe_setup(printer.probe_offset), setup_output)
        click.echo(f"wrote {setup_output} (z-probe setup with the probe offset of {config})", err=True)


@import_group.command("marlin", epilog=examples(
    "pkmcal import marlin examples/marlin/m503.txt -o delta.yaml",
    "pkmcal import marlin examples/marlin/m503.txt --marlin-version 2.1.x --missing zero"))
@click.argument("settings", metavar="M503.txt")
@output_option("DELTA.yaml", "Machine file to write")
@click.option("--name", metavar="NAME", help="Machine name (default: the file's name).")
@click.option("--marlin-version", "version", metavar="VERSION",
              help="The Marlin that printed the settings, as M115 prints it (e.g. 1.1.8, 2.0.5.3, 2.0.9.3, 2.1.2; "
                   "1.1.0-RC8; or 2.1.x): M665's letters and homing differ between releases. Needed unless the text "
                   "tells (I J K, or A C without H: a 1.1.0 release candidate; A C with H: 2.0.6 to 2.1.x).")
@click.option("--missing", type=click.Choice(["error", "zero"]), default="error", show_default=True,
              help="A trim or M666 adjustment the version prints but the file lacks: an error, or 0 (noted).")
@click.option("--height", type=FiniteFloat(), metavar="MM",
              help="Marlin 1.1.0 release candidates only (their M665 has no H): the nozzle height at home, "
                   "MANUAL_Z_HOME_POS plus M206 Z.")
def marlin_cmd(settings: str, output: str | None, name: str | None, version: str | None, missing: str,
               height: float | None) -> None:
    """Read a Marlin delta printer's M665/M666 settings as a pkmcal linear-delta machine file.

    A text file with the printer's M665 and M666 lines (the output of M503, 'echo:' and ';'
    comments allowed, or a G-code file), read as the stated Marlin release runs them: 1.1.0
    release candidates M665 L R S A B C (rod trims) [I J K] (no H: --height); 1.1.0-1.1.9
    M665 L R H S B X Y Z (B the calibration radius, not geometry; up to 1.1.5 M665 Z turns
    towers A and B); 2.0.0-2.0.5.x M665 L R H S X Y Z; 2.0.6-2.1.x M665 L R H S X Y Z A B C;
    M666 X Y Z endstop adjustments (<= 0), with each release's homing (1.1.2-1.1.8 move 0.1
    mm further, 1.1.9-2.0.5.x 7 steps further, needing M92; 2.0.6 on skip adjustments of 6
    steps or fewer) and, on 2.x, the M851 Z probe offset in the home height. The inverse of
    'pkmcal export --format marlin'.
    """
    check_output(output, [settings])
    from pkmcal.io.marlin_settings import read_marlin_settings

    result = read_marlin_settings(settings, version, missing=missing, height=height)
    for note in result.notes:
        click.echo(f"note: {note}", err=True)
    _write_delta(result.firmware.machine(_delta_name(settings, name)), output,
                 f"Marlin {result.version} settings {settings}")


from pkmcal.cli.klipper_probe_cmd import klipper_analyze_cmd, klipper_probe_cmd, marlin_probe_cmd  # noqa: E402

import_group.add_command(klipper_probe_cmd)
import_group.add_command(klipper_analyze_cmd)
import_group.add_command(marlin_probe_cmd)

__all__ = ["import_group", "klipper_cmd", "linuxcnc_cmd", "marlin_cmd"]

"""``pkmcal import``: a machine file from a controller's configuration.

``pkmcal import linuxcnc HAL [INI] -o MACHINE.yaml`` reads LinuxCNC's genhexkins joints
(``setp genhexkins.base.N.*`` / ``platform.N.*``) and the INI file's units, home pose and
joint limits (:func:`pkmcal.io.import_linuxcnc.machine_from_linuxcnc`); the inverse of
``pkmcal export --format linuxcnc --ini``. The machine file is written atomically and
checked to load back to the same machine (:func:`pkmcal.io.machine_file.save_machine`).
"""

from __future__ import annotations

import click

from pkmcal.cli.options import check_output, examples, output_option, to_stdout
from pkmcal.errors import PkmcalError

_OFFSET_HELP = ("home-offset (default): L0 = [JOINT_N] HOME_OFFSET, readings zero at the home switch (as pkmcal "
                "exports); zero: L0 = 0, readings = LinuxCNC joint values (strut lengths), genhexkins' convention.")


@click.group("import", epilog=examples(
    "pkmcal import linuxcnc examples/linuxcnc/hexapod.hal examples/linuxcnc/hexapod.ini -o imported.yaml",
    "pkmcal import linuxcnc examples/linuxcnc/hexapod.hal examples/linuxcnc/hexapod.ini --offsets zero"))
def import_group() -> None:
    """Make a machine file from a controller's configuration (LinuxCNC genhexkins HAL and INI).

    Run 'pkmcal import linuxcnc --help' for the files it reads and how.
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


__all__ = ["import_group", "linuxcnc_cmd"]

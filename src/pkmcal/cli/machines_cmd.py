"""``pkmcal machines``: list the built-in machines."""

from __future__ import annotations

import click

from pkmcal.cli.options import examples
from pkmcal.mechanisms.library import BUILTIN_MACHINES, SYMMETRIC_PREFIX


@click.command("machines", epilog=examples(
    "pkmcal machines",
    "pkmcal info symmetric:base_radius=200,platform_radius=100"))
def machines() -> None:
    """List the built-in machines (usable by name wherever a machine file is accepted).

    The default machine (used when a command's MACHINE is left out) says so in its line.
    """
    width = max(len(n) for n in BUILTIN_MACHINES)
    for name, (_, text) in BUILTIN_MACHINES.items():
        click.echo(f"{name:<{width}}  {text}")
    click.echo(
        f"{SYMMETRIC_PREFIX}KEY=VALUE,...  symmetric 6-6/3-6 hexapod generator; keys: base_radius, "
        "platform_radius, base_separation, platform_separation (deg), phase (deg), offset, stroke, "
        "u_joint_tilt, s_joint_tilt (deg), leg_diameter"
    )

"""``pkmcal machines``: list the built-in machines."""

from __future__ import annotations

import click

from pkmcal.mechanisms.library import BUILTIN_MACHINES, DEFAULT_MACHINE, SYMMETRIC_PREFIX


@click.command("machines")
def machines() -> None:
    """List the built-in machines (usable by name wherever a machine file is accepted)."""
    width = max(len(n) for n in BUILTIN_MACHINES)
    for name, (_, text) in BUILTIN_MACHINES.items():
        mark = "  (default)" if name == DEFAULT_MACHINE else ""
        click.echo(f"{name:<{width}}  {text}{mark}")
    click.echo(
        f"{SYMMETRIC_PREFIX}KEY=VALUE,...  symmetric 6-6/3-6 hexapod generator; keys: base_radius, "
        "platform_radius, base_separation, platform_separation (deg), phase (deg), offset, stroke, "
        "u_joint_tilt, s_joint_tilt (deg), leg_diameter"
    )

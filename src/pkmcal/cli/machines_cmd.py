"""``pkmcal machines``: list the built-in machines."""

from __future__ import annotations

import click

from pkmcal.cli.options import examples
from pkmcal.mechanisms.catalogue import BUILTIN_CATALOGUE, SYMMETRIC_DESCRIPTION, SYMMETRIC_KIND, SYMMETRIC_PREFIX


@click.command("machines", epilog=examples(
    "pkmcal machines",
    "pkmcal info symmetric:base_radius=200,platform_radius=100"))
def machines() -> None:
    """List the built-in machines with their kinds (usable by name wherever a machine file is accepted).

    The default machine (used when a command's MACHINE is left out) says so in its line.
    """
    rows = [(name, kind, text) for name, (kind, text) in BUILTIN_CATALOGUE.items()]
    rows.append((f"{SYMMETRIC_PREFIX}KEY=VALUE,...", SYMMETRIC_KIND, SYMMETRIC_DESCRIPTION))
    width = max(len(n) for n, _, _ in rows[:-1])
    kind_width = max(len(k) for _, k, _ in rows)
    for name, kind, text in rows:
        click.echo(f"{name:<{width}}  {kind:<{kind_width}}  {text}")

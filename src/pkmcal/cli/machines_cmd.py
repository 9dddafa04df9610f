"""``pkmcal machines``: list the built-in machines."""

from __future__ import annotations

import click

from pkmcal.cli.options import examples
from pkmcal.workflow.vocabulary import builtin_machines


@click.command("machines", epilog=examples(
    "pkmcal machines",
    "pkmcal info symmetric:base_radius=200,platform_radius=100"))
def machines() -> None:
    """List the built-in machines with their kinds (usable by name wherever a machine file is accepted).

    The default machine (used when a command's MACHINE is left out) says so in its line.
    """
    rows = builtin_machines()
    width = max(len(n) for n, _, _ in rows[:-1])
    kind_width = max(len(k) for _, k, _ in rows)
    for name, kind, text in rows:
        click.echo(f"{name:<{width}}  {kind:<{kind_width}}  {text}")

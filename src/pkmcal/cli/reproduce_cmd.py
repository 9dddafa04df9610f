"""``pkmcal reproduce NAME``: regenerate a paper's table, ours beside the paper's
(:mod:`pkmcal.reproduce`)."""

from __future__ import annotations

import json

import click

from pkmcal.cli.option_types import SEED
from pkmcal.errors import PkmcalError


@click.command("reproduce")
@click.argument("name", required=False, metavar="NAME")
@click.option("--list", "list_", is_flag=True, help="List the reproductions and exit.")
@click.option("--quick", is_flag=True, help="Few Monte Carlo runs (seconds; for tests and a first look).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same numbers).")
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON instead of text.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True), default=None, metavar="FILE",
              help="Also write the output (text, or JSON with --json) to FILE (atomically).")
def reproduce(name, list_, quick, seed, as_json, output) -> None:
    """Regenerate paper table NAME with our numbers beside the published ones.

    Each reproduction states its setup (machine, noise, poses, seeds, Monte Carlo count)
    and explains every difference in its notes. Run with --list to see the names.
    """
    from pkmcal.reproduce import REPRODUCTIONS, run_reproduction

    if list_:
        for key, (_, text) in REPRODUCTIONS.items():
            click.echo(f"{key:<18}{text}")
        return
    if not name:
        raise PkmcalError(f"give a reproduction NAME ({', '.join(REPRODUCTIONS)}) or --list")
    if output is not None:
        from pkmcal.io.atomic import check_output_path

        check_output_path(output)   # before the run: '' or an unwritable folder is refused at once
    result = run_reproduction(name, seed=seed, quick=quick)
    text = json.dumps(result.to_dict(), indent=2) if as_json else result.format()
    click.echo(text)
    if output is not None:
        from pkmcal.io.atomic import atomic_write_text

        atomic_write_text(output, text + "\n")   # a failed write is a PkmcalError

"""``pkmcal reproduce NAME``: regenerate a paper's table, ours beside the paper's
(:mod:`pkmcal.reproduce`)."""

from __future__ import annotations

import json

import click

from pkmcal.errors import PkmcalError


@click.command("reproduce")
@click.argument("name", required=False, metavar="NAME")
@click.option("--list", "list_", is_flag=True, help="List the reproductions and exit.")
@click.option("--quick", is_flag=True, help="Few Monte Carlo runs (seconds; for tests and a first look).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed (same seed, same numbers).")
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON instead of text.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True), default=None, metavar="FILE",
              help="Also write the output (text, or JSON with --json) to FILE (atomically).")
@click.option("--figures", "figures", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Also draw the reproduction's figures (the paper's figures as we redraw them) into DIR "
                   "as SVG and PNG.")
def reproduce(name, list_, quick, seed, as_json, output, figures) -> None:
    """Regenerate paper table NAME with our numbers beside the published ones.

    Each reproduction states its setup (machine, noise, poses, seeds, Monte Carlo count)
    and explains every difference in its notes. Run with --list to see the names and every
    table and figure of the three papers, each reproduced or listed with the reason it is not.
    """
    from pkmcal.reproduce import REPRODUCTIONS, format_catalogue, run_reproduction

    if list_:
        click.echo(format_catalogue(REPRODUCTIONS))
        return
    if not name:
        raise PkmcalError(f"give a reproduction NAME ({', '.join(REPRODUCTIONS)}) or --list")
    result = run_reproduction(name, seed=seed, quick=quick)
    text = json.dumps(result.to_dict(), indent=2) if as_json else result.format()
    click.echo(text)
    if output:
        from pkmcal.io.atomic import atomic_write_text

        atomic_write_text(output, text + "\n")   # a failed write is a PkmcalError
    if figures:
        for path in result.write_figures(figures):
            click.echo(f"wrote {path}", err=True)
        if not result.figures:
            click.echo(f"{name} draws no figures", err=True)

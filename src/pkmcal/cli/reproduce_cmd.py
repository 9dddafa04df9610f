"""``pkmcal reproduce NAME``: regenerate a paper's table, ours beside the paper's
(:mod:`pkmcal.reproduce`), with a progress bar over its Monte Carlo runs on a terminal."""

from __future__ import annotations

import json

import click

from pkmcal.cli.options import check_output, emit, examples, output_option, quiet_option, to_stdout
from pkmcal.cli.option_types import SEED
from pkmcal.errors import PkmcalError


@click.command("reproduce", epilog=examples(
    "pkmcal reproduce --list",
    "pkmcal reproduce paper3-case2 --quick",
    "pkmcal reproduce paper3-case1 --quick --json -o case1.json",
    "pkmcal reproduce paper1-table1 --quick --seed 1 -o paper1-table1.txt"))
@click.argument("name", required=False, metavar="NAME")
@click.option("--list", "list_", is_flag=True, help="List the reproductions and exit.")
@click.option("--quick", is_flag=True, help="Few Monte Carlo runs (seconds; for tests and a first look).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same numbers).")
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON instead of text.")
@output_option("FILE", "Write the table (text, or JSON with --json) to FILE")
@click.option("--figures", "figures", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Also draw the reproduction's figures (the paper's figures as we redraw them) into DIR "
                   "as SVG and PNG.")
@quiet_option
def reproduce(name, list_, quick, seed, as_json, output, figures, quiet) -> None:
    """Regenerate paper table NAME with our numbers beside the published ones.

    Each reproduction states its setup (machine, noise, poses, seeds, Monte Carlo count)
    and explains every difference in its notes. Run with --list to see the names and every
    table and figure of the three papers, each reproduced or listed with the reason it is not.
    """
    from pkmcal.progress import ProgressBar
    from pkmcal.reproduce import REPRODUCTIONS, format_catalogue, run_reproduction

    if list_:
        click.echo(format_catalogue(REPRODUCTIONS))
        return
    if not name:
        raise PkmcalError(f"give a reproduction NAME ({', '.join(REPRODUCTIONS)}) or --list")
    check_output(output, [])
    with ProgressBar(f"reproduce {name}", quiet=quiet, unit="runs") as bar:
        result = run_reproduction(name, seed=seed, quick=quick, progress=bar)
    text = json.dumps(result.to_dict(), indent=2) if as_json else result.format()
    emit(text + "\n", output)   # a failed write is a PkmcalError
    if not to_stdout(output):
        click.echo(f"wrote {output}")
    if figures:
        for path in result.write_figures(figures):
            click.echo(f"wrote {path}", err=True)
        if not result.figures:
            click.echo(f"{name} draws no figures", err=True)

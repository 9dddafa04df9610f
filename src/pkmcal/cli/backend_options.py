"""``--workers N`` and ``--dask ADDRESS|local``: where a command's chunks of work run (the
backends of :mod:`pkmcal.study.backends`). Used by ``pkmcal plan``; ``pkmcal study`` spells
the same two options."""

from __future__ import annotations

import click

from pkmcal.errors import PkmcalError


def backend_options(default_workers: str):
    """Decorator adding ``workers`` and ``dask_address``; ``default_workers`` says in the
    help what no ``--workers`` means for this command."""

    def decorate(f):
        f = click.option("--dask", "dask_address", default=None, metavar="ADDRESS|local",
                         help="Run on a Dask cluster: a scheduler address (tcp://host:8786) or 'local' for a "
                              "LocalCluster (needs pip install 'pkmcal[dask]').")(f)
        return click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
                            help=f"Local worker processes (1 = in this process; default: {default_workers}); "
                                 "with --dask local, the LocalCluster's workers.")(f)

    return decorate


def check_backend(workers: int | None, dask_address: str | None) -> None:
    """--workers applies to local runs and to --dask local only."""
    if workers is not None and dask_address not in (None, "local"):
        raise PkmcalError("--workers applies to local runs and to --dask local; a Dask scheduler's workers are "
                          "started with 'dask worker'")

"""The options ``--columns``, ``--length-unit`` and ``--angle-unit`` of every command that reads
a pose or measurement CSV: how to read a file written by another tool
(:mod:`pkmcal.io.import_mapping`).

``@import_options`` adds the three options to a click command and hands the command one
keyword argument ``mapping`` (an :class:`~pkmcal.io.import_mapping.ImportMapping`, or None
when no option is given).
"""

from __future__ import annotations

import functools

import click

from pkmcal.io.import_mapping import ANGLE_UNIT_CHOICES, LENGTH_UNIT_CHOICES, make_mapping


def import_options(command):
    """Decorator: add the import-mapping options to a click command (below its other options)."""

    @functools.wraps(command)
    def wrapper(*args, columns=None, length_unit=None, angle_unit=None, **kwargs):
        return command(*args, mapping=make_mapping(columns, length_unit, angle_unit), **kwargs)

    wrapper = click.option(
        "--angle-unit", type=click.Choice(ANGLE_UNIT_CHOICES), default=None,
        help="Angles of the input CSV are in this unit (overrides its '# units:' line; without both: deg).")(wrapper)
    wrapper = click.option(
        "--length-unit", type=click.Choice(LENGTH_UNIT_CHOICES), default=None,
        help="Lengths of the input CSV are in this unit (overrides its '# units:' line; without both: mm).")(wrapper)
    wrapper = click.option(
        "--columns", default=None, metavar="OLD=NEW,...",
        help="Rename columns of the input CSV (e.g. 'X [mm]=x,Leg 1=lambda1'); names are case-insensitive.")(wrapper)
    return wrapper


__all__ = ["import_options"]

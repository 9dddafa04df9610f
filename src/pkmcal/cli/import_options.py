"""The options ``--columns``, ``--length-unit``, ``--angle-unit`` and ``--quaternion-order`` of
every command that reads a pose or measurement CSV: how to read a file written by another
tool (:mod:`pkmcal.io.import_mapping`; orientations as quaternions or rotation vectors:
:mod:`pkmcal.io.orientation`).

``@import_options`` adds the four options to a click command and hands the command one
keyword argument ``mapping`` (an :class:`~pkmcal.io.import_mapping.ImportMapping`, or None
when no option is given).
"""

from __future__ import annotations

import functools

import click

from pkmcal.io.import_mapping import ANGLE_UNIT_CHOICES, LENGTH_UNIT_CHOICES, QUATERNION_ORDERS, make_mapping


def import_options(command):
    """Decorator: add the import-mapping options to a click command (below its other options)."""

    @functools.wraps(command)
    def wrapper(*args, columns=None, length_unit=None, angle_unit=None, quaternion_order=None, **kwargs):
        return command(*args, mapping=make_mapping(columns, length_unit, angle_unit, quaternion_order), **kwargs)

    wrapper = click.option(
        "--quaternion-order", type=click.Choice(QUATERNION_ORDERS), default=None,
        help="Order of quaternion columns q1..q4 given instead of a,b,c: xyzw (default, scalar last as scipy and "
             "ROS) or wxyz. Columns qx,qy,qz,qw are read by name; rx,ry,rz are a rotation vector.")(wrapper)
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

"""Reading CSV files written by other tools: column renaming and unit overrides.

A measurement or pose file from another program (a CMM export, a spreadsheet, a laser
tracker's log) usually has its own column names, its own column order and its own units.
An :class:`ImportMapping` says how to read it, without editing the file:

* ``rename``: header cell (as written, matched case-insensitively after stripping) → pkmcal
  column name (``X_mm=x,Leg1=lambda1``); column order never matters;
* ``quaternion_order``: the order of positional quaternion columns ``q1..q4``, ``xyzw``
  (default, scalar last) or ``wxyz`` (:mod:`pkmcal.io.orientation`);
* ``length_unit`` / ``angle_unit``: the units of the file's length / angle columns, replacing
  what its ``# units:`` line says (or the default mm, deg). Values are converted to mm and
  degrees on reading: v_mm = f · v (f = 1000 for m, 25.4 for in, ...), v_deg = v · 180/π for
  rad.

The command line builds one from ``--columns``, ``--length-unit``, ``--angle-unit`` and
``--quaternion-order``
(:func:`pkmcal.cli.import_options.import_options`); :func:`pkmcal.io.tables.read_table`
applies it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

from pkmcal.errors import PkmcalError
from pkmcal.io.orientation import QUATERNION_ORDERS

#: Length units accepted on the command line (the ``# units:`` line also accepts ``inch``, ``µm``).
LENGTH_UNIT_CHOICES = ("mm", "m", "cm", "um", "in")
ANGLE_UNIT_CHOICES = ("deg", "rad")


@dataclass(frozen=True)
class ImportMapping:
    """How to read a CSV file from another tool.

    ``rename`` maps lower-case, stripped header cells to pkmcal column names; ``length_unit``
    and ``angle_unit`` (or None) replace the units of the file's ``# units:`` line.
    """

    rename: Mapping[str, str] = field(default_factory=dict)
    length_unit: str | None = None
    angle_unit: str | None = None
    quaternion_order: str | None = None

    @property
    def units(self) -> dict[str, str]:
        """The unit overrides, quantity → unit (only those given)."""
        out = {}
        if self.length_unit is not None:
            out["length"] = self.length_unit
        if self.angle_unit is not None:
            out["angle"] = self.angle_unit
        return out

    def __bool__(self) -> bool:
        return (bool(self.rename) or self.length_unit is not None or self.angle_unit is not None
                or self.quaternion_order is not None)

    def describe(self) -> str:
        """One line for logs and file comments, e.g. ``columns X_mm=x; length unit m``."""
        parts = []
        if self.rename:
            parts.append("columns " + ",".join(f"{k}={v}" for k, v in self.rename.items()))
        if self.length_unit is not None:
            parts.append(f"length unit {self.length_unit}")
        if self.angle_unit is not None:
            parts.append(f"angle unit {self.angle_unit}")
        if self.quaternion_order is not None:
            parts.append(f"quaternion order {self.quaternion_order}")
        return "; ".join(parts) or "no mapping"


def parse_column_mapping(text: str | None, option: str = "--columns") -> dict[str, str]:
    """``'OLD=NEW,OLD2=NEW2'`` → ``{'old': 'new', 'old2': 'new2'}`` (stripped, lower case).

    Raises :class:`PkmcalError` naming the option and the bad item for an item without
    ``=``, an empty name, an OLD given twice, or two OLDs mapped to the same NEW.
    """
    if text is None or not text.strip():
        return {}
    out: dict[str, str] = {}
    for item in text.split(","):
        old, sep, new = item.partition("=")
        old, new = old.strip().lower(), new.strip().lower()
        if not sep or not old or not new:
            raise PkmcalError(f"{option} '{text}': item '{item.strip()}' is not OLD=NEW (the file's column name, "
                              f"'=', the pkmcal column name), e.g. {option} 'X [mm]=x,Leg 1=lambda1'")
        if old in out:
            raise PkmcalError(f"{option} '{text}': column '{old}' is mapped twice; map each column once")
        out[old] = new
    targets = list(out.values())
    dup = sorted({t for t in targets if targets.count(t) > 1})
    if dup:
        raise PkmcalError(f"{option} '{text}': several columns are mapped to '{dup[0]}'; map one column to each name")
    return out


def make_mapping(columns: str | None, length_unit: str | None, angle_unit: str | None,
                 quaternion_order: str | None = None) -> ImportMapping | None:
    """The mapping of the command-line options (None when none is given)."""
    for name, value, choices in (("--length-unit", length_unit, LENGTH_UNIT_CHOICES),
                                 ("--angle-unit", angle_unit, ANGLE_UNIT_CHOICES),
                                 ("--quaternion-order", quaternion_order, QUATERNION_ORDERS)):
        if value is not None and value not in choices:
            raise PkmcalError(f"{name} '{value}': unknown value; choose one of {', '.join(choices)}")
    mapping = ImportMapping(rename=parse_column_mapping(columns), length_unit=length_unit, angle_unit=angle_unit,
                            quaternion_order=quaternion_order)
    return mapping if mapping else None


__all__ = ["ANGLE_UNIT_CHOICES", "ImportMapping", "LENGTH_UNIT_CHOICES", "QUATERNION_ORDERS", "make_mapping",
           "parse_column_mapping"]

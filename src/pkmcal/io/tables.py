"""Numeric CSV tables with named columns: the pose, reading and measurement files of pkmcal.

Format (``docs/file-formats.md``): comma-separated, UTF-8, one header row naming the
columns, one row per pose. Lines starting with ``#`` are comments; a comment before the
header of the form ``# units: length=mm, angle=deg`` states the units of the file. Header
names are matched case-insensitively, through aliases (``λ1``, ``lambda_1`` → ``lambda1``);
columns a command does not need are ignored. Every cell of a needed column must be a finite
number. Errors name the file, the 1-based line (as an editor shows it) and the column.

Values are returned in pkmcal's file units (mm, degrees): a table in other units (m, µm,
inch; rad) is converted on reading for the columns whose ``kinds`` are given.
:func:`format_table` writes the reverse: header, every float as its shortest round-trip
``repr``, ``\\n`` line ends, so equal data give identical bytes, and no comment line unless
asked (``units_comment``), so that ``pandas.read_csv`` and ``csv.DictReader`` read every
file pkmcal writes with their defaults; :func:`write_table` writes it atomically.
"""

from __future__ import annotations

import codecs
import csv
import io
import os
import re
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError, PkmcalWarning, one_line
from pkmcal.io.atomic import atomic_write_text
from pkmcal.io.inputs import has_nul, not_utf8, open_input
from pkmcal.io.limits import MAX_MAGNITUDE, magnitude_problem

if TYPE_CHECKING:
    from pkmcal.io.import_mapping import ImportMapping

#: Conversion factors to pkmcal's file units, by quantity.
LENGTH_UNITS: dict[str, float] = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "um": 1e-3, "µm": 1e-3, "in": 25.4, "inch": 25.4}
ANGLE_UNITS: dict[str, float] = {"deg": 1.0, "rad": float(np.rad2deg(1.0))}
UNITS: dict[str, dict[str, float]] = {"length": LENGTH_UNITS, "angle": ANGLE_UNITS}
#: The units line pkmcal writes (and assumes when a file has none).
FILE_UNITS = {"length": "mm", "angle": "deg"}

POSE_KINDS: dict[str, str] = {"x": "length", "y": "length", "z": "length", "a": "angle", "b": "angle", "c": "angle"}
LENGTH_COLUMNS = tuple(f"l{i}" for i in range(1, 7))
READING_COLUMNS = tuple(f"lambda{i}" for i in range(1, 7))


def _default_aliases() -> dict[str, str]:
    out: dict[str, str] = {}
    for i in range(1, 13):
        # Not q1..: planar machines name their actuators q1..qn.
        for alias in (f"λ{i}", f"lambda_{i}", f"λ_{i}"):
            out[alias] = f"lambda{i}"
        for alias in (f"l_{i}", f"length{i}", f"length_{i}"):
            out[alias] = f"l{i}"
    return out


#: Alternative header names (lower case) → canonical column names.
DEFAULT_ALIASES: dict[str, str] = _default_aliases()
_UNITS_LINE = re.compile(r"^#\s*units\s*:(.*)$", re.IGNORECASE)


@dataclass(frozen=True)
class Table:
    """Numeric columns read from a CSV file.

    ``columns`` are the canonical names of the columns read (in the order asked for),
    ``values`` (N, k) their numbers in file units (mm, degrees), ``lines`` (N,) the 1-based
    line of each row in the file, ``header`` the file's column names as written, ``units``
    the file's units line (quantity → unit).
    """

    path: str
    columns: tuple[str, ...]
    values: np.ndarray
    lines: np.ndarray
    header: tuple[str, ...] = ()
    units: dict[str, str] = field(default_factory=dict)
    #: Conventions that look wrong (radians read as degrees, a scalar-first quaternion read
    #: scalar-last: :mod:`pkmcal.io.orientation`), one line each, also issued as warnings.
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        return self.values.shape[0]

    def __getitem__(self, names: str | Sequence[str]) -> np.ndarray:
        """One column (N,) by name, or several (N, k) by a list of names."""
        if isinstance(names, str):
            return self.values[:, self._index(names)]
        return self.values[:, [self._index(n) for n in names]]

    def _index(self, name: str) -> int:
        try:
            return self.columns.index(name)
        except ValueError:
            raise KeyError(f"table {self.path} has no column '{name}' (it has {', '.join(self.columns)})") from None


def canonical_name(header_cell: str, aliases: Mapping[str, str] = DEFAULT_ALIASES) -> str:
    """The canonical column name of a header cell (stripped, lower case, aliases applied)."""
    key = header_cell.strip().lower()
    return aliases.get(key, key)


def mapped_name(header_cell: str, mapping: "ImportMapping | None" = None,
                aliases: Mapping[str, str] = DEFAULT_ALIASES) -> str:
    """The canonical column name of a header cell after ``mapping``'s renaming (if any)."""
    if mapping is not None and mapping.rename:
        header_cell = mapping.rename.get(header_cell.strip().lower(), header_cell)
    return canonical_name(header_cell, aliases)


def _check_renamed(src: str, header: Sequence[str], mapping: "ImportMapping", line: int) -> None:
    have = {h.strip().lower() for h in header}
    missing = [old for old in mapping.rename if old not in have]
    if missing:
        found = ", ".join(repr(h) for h in header)
        raise InputFileError(src, f"--columns renames {', '.join(repr(m) for m in missing)}, but the header has no "
                                  f"such column (it has {found}); use the file's column names on the left of '='",
                             line=line)


def _split(line: str) -> list[str]:
    if '"' in line:
        return [c.strip() for c in next(csv.reader([line]))]
    return [c.strip() for c in line.split(",")]


def _parse_units(path: str, text: str, line: int) -> dict[str, str]:
    units: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        quantity, sep, unit = (s.strip().lower() for s in item.partition("="))
        if not sep or quantity not in UNITS:
            raise InputFileError(path, f"units line: '{item}' is not QUANTITY=UNIT with QUANTITY one of "
                                       f"{', '.join(UNITS)} (e.g. '# units: length=mm, angle=deg')", line=line)
        if unit not in UNITS[quantity]:
            raise InputFileError(path, f"units line: unknown {quantity} unit '{unit}'; known: "
                                       f"{', '.join(UNITS[quantity])}", line=line)
        units[quantity] = unit
    return units


def _describe_columns(names: Sequence[str]) -> str:
    names = list(names)
    m = re.fullmatch(r"([a-z_]+)1", names[0]) if names else None
    if m and len(names) > 2 and names == [f"{m.group(1)}{i}" for i in range(1, len(names) + 1)]:
        return f"{names[0]}..{names[-1]}"
    return ",".join(names)


def _looks_numeric(cells: Sequence[str]) -> bool:
    try:
        [float(c) for c in cells]
    except ValueError:
        return False
    return True


def read_table(
    path: str | os.PathLike,
    columns: Sequence[str] = (),
    *,
    either: Sequence[Sequence[str]] = (),
    kinds: Mapping[str, str] | None = None,
    aliases: Mapping[str, str] = DEFAULT_ALIASES,
    text: str | None = None,
    mapping: "ImportMapping | None" = None,
    small_angle_deg: float | None = None,
) -> Table:
    """Read the numeric ``columns`` of the CSV file ``path``.

    Parameters
    ----------
    columns : canonical names of the columns that must be present.
    either : groups of columns of which the first group fully present is read too (e.g.
        ``[READING_COLUMNS, LENGTH_COLUMNS]``); the chosen group follows ``columns`` in
        :attr:`Table.columns`.
    kinds : quantity (``"length"`` or ``"angle"``) of columns to convert from the file's
        units line to mm/degrees; default :data:`POSE_KINDS`. A units line other than
        mm/deg naming a quantity no column has is accepted (nothing to convert).
    aliases : lower-case alternative header names → canonical names.
    text : the file's contents, if already read (``path`` then only names it in errors).
    mapping : an :class:`~pkmcal.io.import_mapping.ImportMapping` for files from other tools:
        header cells renamed before the aliases apply (every renamed column must exist), and
        units that replace the file's units line.
    small_angle_deg : below this largest |angle| (degrees) an orientation read in degrees
        looks like radians (:func:`pkmcal.io.orientation.small_angle_note`); default
        :data:`~pkmcal.io.orientation.SMALL_ANGLE_DEG`, readers that know the machine give
        :func:`~pkmcal.io.orientation.small_angle_limit`.

    The file is read line by line and its rows are parsed in blocks of :data:`_BLOCK_ROWS`,
    so the memory it takes is that of the numbers it holds, not of its text. Problems are
    reported in file order (the first bad row).

    Raises :class:`InputFileError` naming file, line and column for every malformed input.
    """
    src = os.fspath(path)
    kinds = POSE_KINDS if kinds is None else kinds
    units: dict[str, str] = {}
    header: list[str] | None = None
    header_line = 0
    chosen: list[str] = []
    idx: list[int] = []
    rows: list[list[str]] = []
    row_lines: list[int] = []
    blocks: list[np.ndarray] = []
    all_lines: list[np.ndarray] = []
    wanted_hint = _describe_columns(list(columns) + (list(either[0]) if either else []))
    for number, line in enumerate(_text_lines(src, text), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            m = _UNITS_LINE.match(stripped)
            if m and header is None:
                units.update(_parse_units(src, m.group(1), number))
            continue
        try:
            cells = _split(line)
        except csv.Error as exc:
            raise InputFileError(src, f"not a CSV row: {exc}", line=number) from None
        if header is None:
            header, header_line = cells, number
            if mapping is not None:
                _check_renamed(src, header, mapping, header_line)
                units.update(mapping.units)
            chosen, idx, sources = _choose_columns(src, header, header_line, columns, either, aliases, mapping,
                                                   wanted_hint)
            continue
        rows.append(cells)
        row_lines.append(number)
        if len(rows) == _BLOCK_ROWS:
            blocks.append(_block_values(src, header, idx, rows, row_lines))
            all_lines.append(np.array(row_lines, dtype=int))
            rows, row_lines = [], []
    if header is None:
        raise InputFileError(src, f"the file is empty: expected a header row naming the columns "
                                  f"(e.g. {wanted_hint}) and one row per pose")
    if rows:
        blocks.append(_block_values(src, header, idx, rows, row_lines))
        all_lines.append(np.array(row_lines, dtype=int))
    if not blocks:
        raise InputFileError(src, "no data rows after the header; add one row per pose", line=header_line)
    values = blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
    lines = all_lines[0] if len(all_lines) == 1 else np.concatenate(all_lines)
    rotvec_kinds = {c: "angle" for o in sources if o.kind == "rotvec" for c in o.columns}
    for k, name in enumerate(chosen):
        quantity = kinds.get(name) or rotvec_kinds.get(name)
        if quantity is not None and quantity in units:
            factor = UNITS[quantity][units[quantity]]
            if factor != 1.0:
                given = values[:, k].copy()
                with np.errstate(over="ignore"):
                    values[:, k] = np.rad2deg(given) if units[quantity] == "rad" else given * factor
                over = np.isfinite(given) & ~np.isfinite(values[:, k])
                if over.any():
                    i = int(np.argmax(over))
                    raise InputFileError(src, f"column '{name}': {float(given[i])!r} {units[quantity]} is beyond any "
                                              f"{quantity} a number can hold in pkmcal's units; check the value and "
                                              "the unit", line=int(lines[i]))
    notes: list[str] = []
    if sources:
        chosen, values = _euler_from_sources(src, header, idx, chosen, values, lines, sources, notes)
    notes += _small_angle_notes(src, chosen, values, units, kinds, sources, small_angle_deg)
    for note in notes:
        warnings.warn(note, PkmcalWarning, stacklevel=2)
    return Table(path=src, columns=tuple(chosen), values=values, lines=lines, header=tuple(header), units=units,
                 notes=tuple(notes))


def _small_angle_notes(src, chosen, values, units, kinds, sources, limit) -> list[str]:
    """:func:`pkmcal.io.orientation.small_angle_note` of each orientation read in degrees:
    Euler triples read as such, and rotation vectors (here already turned into Euler angles,
    whose magnitudes are as small as the vector's)."""
    from pkmcal.io.orientation import euler_triples, small_angle_note

    if units.get("angle", "deg") != "deg":
        return []
    by_euler = {o.euler: o for o in sources}
    out = []
    for triple in euler_triples(chosen):
        if any(kinds.get(n) != "angle" for n in triple):
            continue
        o = by_euler.get(triple)
        if o is not None and o.kind != "rotvec":
            continue
        cols, what = (o.columns, "rotation vectors") if o is not None else (triple, "angles")
        note = small_angle_note(src, cols, values[:, [chosen.index(n) for n in triple]], what, limit)
        if note is not None:
            out.append(note)
    return out


def _euler_from_sources(src, header, idx, chosen, values, lines, sources, notes):
    """``(names, values)`` with each orientation source's columns replaced, where the triple
    was asked for, by its a, b, c in degrees (:mod:`pkmcal.io.orientation`); a quaternion
    that looks scalar-first adds its note to ``notes``."""
    from pkmcal.io.orientation import euler_from_quaternions, euler_from_rotvecs, quaternion_order_note

    names, parts = [], []
    by_first = {o.columns[0]: o for o in sources}
    skip = {c for o in sources for c in o.columns[1:]}
    for k, name in enumerate(chosen):
        if name in skip:
            continue
        o = by_first.get(name)
        if o is None:
            names.append(name)
            parts.append(values[:, k:k + 1])
            continue
        cols = [chosen.index(c) for c in o.columns]
        if o.kind == "quaternion":
            cells = [header[idx[j]] for j in cols]
            euler = euler_from_quaternions(values[:, cols], src, lines, o.columns, cells)
            note = quaternion_order_note(src, values[:, cols], cells, [idx[j] for j in cols],
                                         positional=not o.columns[0].endswith("qx"))
            if note is not None:
                notes.append(note)
        else:
            euler = euler_from_rotvecs(values[:, cols])
        names.extend(o.euler)
        parts.append(euler)
    return names, np.concatenate(parts, axis=1)


#: Rows parsed at a time by :func:`read_table`.
_BLOCK_ROWS = 65_536


def _text_lines(src: str, text: str | None):
    """The lines of ``text``, or of the file ``src``, split exactly as ``str.splitlines``
    splits the whole text. A file is first checked to be UTF-8 text without NUL bytes (one
    pass in 1 MB pieces, so that these errors come first as for a text read whole), then
    read one line at a time (BOM dropped)."""
    if text is not None:
        if "\x00" in text:
            raise InputFileError(src, "contains NUL bytes: not a text CSV file")
        yield from text.splitlines()
        return
    fix = "save the table as UTF-8 CSV"
    try:
        with open_input(src, "table") as fh:
            decoder, offset, newlines, nul = codecs.getincrementaldecoder("utf-8")(), 0, 0, None
            while piece := fh.read(1 << 20):
                pending = decoder.getstate()[0]        # the start of a character cut by the last piece
                try:
                    decoder.decode(piece)
                except UnicodeDecodeError as exc:
                    buf = pending + piece
                    raise not_utf8(src, buf[exc.start], offset - len(pending) + exc.start,
                                   newlines + buf.count(b"\n", 0, exc.start) + 1, fix) from None
                if nul is None and (k := piece.find(b"\x00")) >= 0:
                    nul = (offset + k, newlines + piece.count(b"\n", 0, k) + 1)
                offset += len(piece)
                newlines += piece.count(b"\n")
            pending = decoder.getstate()[0]
            try:
                decoder.decode(b"", final=True)
            except UnicodeDecodeError as exc:
                raise not_utf8(src, pending[exc.start], offset - len(pending) + exc.start, newlines + 1, fix) from None
            if nul is not None:
                raise has_nul(src, *nul, "table")
            fh.seek(0)
            for k, raw in enumerate(fh):  # split at b"\n": no byte of a multi-byte UTF-8 character is 0x0A
                line = raw.decode("utf-8")
                yield from (line.removeprefix("\ufeff") if k == 0 else line).splitlines()
    except OSError as exc:
        raise InputFileError(src, f"cannot read the table: {exc.strerror or exc}") from None


def _choose_columns(src, header, header_line, columns, either, aliases, mapping, wanted_hint):
    """``(chosen, idx, sources)``: the canonical names read, their cells' indices in the
    header, and the orientations read from quaternion or rotation-vector columns instead of
    Euler angles (:func:`pkmcal.io.orientation.find_sources`; their columns are read in
    place of the triple, in x, y, z(, w) order)."""
    from pkmcal.io.orientation import alternatives_hint, euler_triples, find_sources

    canon = [mapped_name(h, mapping, aliases) for h in header]
    present: dict[str, int] = {}
    for i, name in enumerate(canon):
        if name in present and name:
            first = header[present[name]]
            raise InputFileError(src, f"columns '{first}' and '{header[i]}' both name '{name}'; keep one",
                                 line=header_line, column=header[i])
        present[name] = i

    def missing_message(missing: Sequence[str], needed: str) -> str:
        found = ", ".join(repr(h) for h in header) if header != [""] else "none"
        msg = f"missing column{'s' if len(missing) > 1 else ''} {', '.join(missing)} (needs {needed}); the header has {found}"
        if _looks_numeric(header):
            msg += f"; the first row is numbers, not names: add a header row '{wanted_hint}'"
        elif len(header) == 1 and any(sep in header[0] for sep in (";", "\t", " ")):
            msg += "; separate the columns with commas"
        return msg

    order = (mapping.quaternion_order if mapping is not None else None) or "xyzw"
    sources = find_sources(src, header, present, columns, order, header_line)
    read: list[str] = []
    for c in columns:
        source = next((o for o in sources if c in o.euler), None)
        if source is None:
            read.append(c)
        elif c == source.euler[0]:
            read.extend(source.columns)
    missing = [c for c in read if c not in present]
    if missing:
        msg = missing_message(missing, _describe_columns(columns))
        hints = [alternatives_hint(t, order) for t in euler_triples(columns) if any(c in missing for c in t)]
        raise InputFileError(src, "; ".join([msg] + hints), line=header_line)
    chosen: list[str] = read
    if either:
        group = next((g for g in either if all(c in present for c in g)), None)
        if group is None:
            best = min(either, key=lambda g: sum(c not in present for c in g))
            options = " or ".join(_describe_columns(g) for g in either)
            raise InputFileError(src, missing_message([c for c in best if c not in present], options),
                                 line=header_line)
        chosen += list(group)
    return chosen, [present[c] for c in chosen], sources


def _block_values(src: str, header: Sequence[str], idx: Sequence[int], rows: list[list[str]],
                  row_lines: list[int]) -> np.ndarray:
    """The numbers (n, len(idx)) of a block of rows; :class:`InputFileError` for the first
    row (in file order) that has the wrong number of cells or a cell that is not a finite
    number."""
    width = len(header)
    ragged = next((k for k, r in enumerate(rows) if len(r) != width), None)
    limit = len(rows) if ragged is None else ragged
    values = np.empty((limit, len(idx)))
    bad: tuple[int, int, str] | None = None
    for k, j in enumerate(idx):
        cells = [r[j] for r in rows[:limit]]
        try:
            col = np.array(cells, dtype=float)
        except ValueError:
            parsed = []
            for n, cell in enumerate(cells):
                try:
                    parsed.append(float(cell))
                except ValueError:
                    if bad is None or n < bad[0]:
                        bad = (n, j, "empty" if cell == "" else f"'{cell[:40]}' is not a number")
                    break
            if len(parsed) < len(cells):
                continue
            col = np.array(parsed)
        finite = np.isfinite(col)
        if not finite.all():
            n = int(np.argmin(finite))
            if bad is None or n < bad[0]:
                bad = (n, j, f"'{cells[n]}' is not a finite number")
        values[:, k] = col
    if bad is not None:
        n, j, what = bad
        raise InputFileError(src, f"{what}; every cell of column '{header[j]}' must be a finite number",
                             line=row_lines[n], column=header[j])
    if ragged is not None:
        raise InputFileError(src, f"{len(rows[ragged])} cells, but the header has {width} columns; every row needs "
                                  f"one cell per column", line=row_lines[ragged])
    return values


def _cells(name: str, data) -> list[str]:
    arr = np.asarray(data)
    if arr.ndim != 1:
        raise ValueError(f"column '{name}' must be one-dimensional, got shape {arr.shape}")
    if arr.dtype.kind == "f":
        return [repr(v) for v in arr.tolist()]
    if arr.dtype.kind in "iub":
        return [str(int(v)) for v in arr.tolist()]
    return [_text_cell(str(v)) for v in arr.tolist()]


def _text_cell(text: str) -> str:
    """A text cell on one line (control characters escaped, :func:`pkmcal.errors.one_line`),
    quoted only when it must be."""
    s = one_line(text)
    if any(ch in s for ch in ',"') or s != s.strip():
        buf = io.StringIO()
        csv.writer(buf, lineterminator="").writerow([s])
        s = buf.getvalue()
    return s


def format_table(columns: Mapping[str, Sequence], *, units_comment: bool = False,
                 units: Mapping[str, str] | None = FILE_UNITS, comments: Sequence[str] = (),
                 head: bool = True) -> str:
    """CSV text of named columns (all the same length): a header, then rows; with
    ``units_comment``, first a ``# units:`` line (of ``units``) and the ``comments``.

    Without ``units_comment`` (the default) the text is a plain CSV that ``pandas.read_csv``
    and ``csv.DictReader`` read with their default arguments into the named columns (a
    leading comment line would become their header); the units are those of the
    documentation (mm, degrees; ``docs/file-formats.md``). Floats are written as ``repr``
    (shortest exact, so reading gives the same doubles), integers and booleans as integers,
    anything else as text (quoted only when it must be). Every comment, header name and text
    cell is one line (control characters escaped), so no value can add a line.
    ``head=False`` gives the rows only: the text of a table written in pieces is the
    ``head=True`` text of its first rows followed by the others'."""
    names = list(columns)
    if not names:
        raise ValueError("a table needs at least one column")
    cols = [_cells(n, columns[n]) for n in names]
    n_rows = {len(c) for c in cols}
    if len(n_rows) != 1:
        raise ValueError(f"columns have different lengths: {sorted(n_rows)}")
    lines = []
    if head:
        if units_comment:
            if units:
                lines.append("# units: " + ", ".join(f"{q}={u}" for q, u in units.items()))
            lines.extend(f"# {one_line(c)}" for c in comments)
        lines.append(",".join(_text_cell(n) for n in names))
    lines.extend(",".join(row) for row in zip(*cols))
    return "\n".join(lines) + "\n" if lines else ""


def column_kinds(names: Sequence[str], is_angle: Sequence[bool]) -> dict[str, str]:
    """``{column: "angle" | "length"}`` for the ``kinds`` of :func:`read_table`."""
    return {n: ("angle" if a else "length") for n, a in zip(names, is_angle)}


def from_file_units(values, is_angle: Sequence[bool]) -> np.ndarray:
    """A copy of ``values`` (..., K) with the angle columns (``is_angle``, K) converted from
    file units (degrees) to internal units (radians); lengths (mm) unchanged."""
    out = np.array(values, dtype=float)
    ang = np.asarray(is_angle, dtype=bool)
    out[..., ang] = np.deg2rad(out[..., ang])
    return out


def to_file_units(values, is_angle: Sequence[bool]) -> np.ndarray:
    """The inverse of :func:`from_file_units`: radians → degrees in the angle columns."""
    out = np.array(values, dtype=float)
    ang = np.asarray(is_angle, dtype=bool)
    out[..., ang] = np.rad2deg(out[..., ang])
    return out


def check_magnitudes(table: Table, kinds: Mapping[str, str]) -> None:
    """:class:`InputFileError` at the first cell (file order) beyond ±:data:`MAX_MAGNITUDE`
    (mm or degrees, after unit conversion; :mod:`pkmcal.io.limits`): no pose or measurement
    of a machine is that large, and one such value would overflow the computations (a
    squared 1e308 is infinite) into results that look like answers."""
    big = np.abs(table.values) > MAX_MAGNITUDE
    if not big.any():
        return
    row = int(np.argmax(big.any(axis=1)))
    k = int(np.argmax(big[row]))
    name = table.columns[k]
    unit = "deg" if kinds.get(name) == "angle" else "mm"
    raise InputFileError(table.path, str(magnitude_problem(float(table.values[row, k]), unit)),
                         line=int(table.lines[row]), column=name)


def read_poses(path: str | os.PathLike, machine, mapping: "ImportMapping | None" = None) -> np.ndarray:
    """Poses (N, n_dof) of a CSV with the machine's pose columns (mm, deg) in internal units
    (mm, rad); ``mapping``: column renaming and units of a file from another tool. Every
    coordinate must be within ±1e6 mm or degrees (:func:`check_magnitudes`)."""
    from pkmcal.io.orientation import small_angle_limit

    kinds = column_kinds(machine.pose_names, machine.pose_is_angle)
    table = read_table(path, machine.pose_names, kinds=kinds, mapping=mapping,
                       small_angle_deg=small_angle_limit(machine))
    check_magnitudes(table, kinds)
    return from_file_units(table.values, machine.pose_is_angle)


def write_table(path: str | os.PathLike, columns: Mapping[str, Sequence], **kwargs) -> None:
    """:func:`format_table` written atomically to ``path``."""
    try:
        text = format_table(columns, **kwargs)
    except ValueError as exc:
        raise PkmcalError(f"cannot write table '{path}': {exc}") from None
    atomic_write_text(path, text)


__all__ = [
    "DEFAULT_ALIASES",
    "FILE_UNITS",
    "LENGTH_COLUMNS",
    "POSE_KINDS",
    "READING_COLUMNS",
    "Table",
    "canonical_name",
    "check_magnitudes",
    "column_kinds",
    "format_table",
    "from_file_units",
    "mapped_name",
    "read_poses",
    "read_table",
    "to_file_units",
    "write_table",
]

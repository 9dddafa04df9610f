"""Filtering a G-code program: the coordinates of its straight moves replaced, every other
byte kept.

Read (RS-274 as LinuxCNC, Klipper and Marlin take it): a line's code ends at ``;`` (a
comment to the end of the line) and skips ``( … )`` comments (LinuxCNC); its words are a
letter and a number. A line that does not begin with a word (Klipper's extended
commands, ``BED_MESH_PROFILE LOAD=default``, macros) is kept as it is.

* **Moves**: a line with ``G0``/``G1`` (``G00``, ``G01``), or, as LinuxCNC reads it (modal
  motion), with axis words and no G word after a G0/G1 line, whose axis words give some of
  the machine's pose coordinates (X Y Z; a hexapod's A B C in degrees). Coordinates a move
  leaves out keep their last values; a move is filtered only when every coordinate is known
  (given since the start or since the last ``G28``); the moves before that (a printer's
  ``G1 Z15`` after homing) are kept as they are and their lines reported.
* **Refused**, with the line number: relative positioning (``G91``; the filter needs
  absolute targets), inches (``G20``), arcs (``G2``/``G3``: the corrected path of an arc is
  no arc), ``G92`` with axis words (a new origin the filter cannot follow) and any other G
  word with axis words.

Written: each move's axis words with the new numbers in place (the words it lacked appended
after its last axis word, in pose order), every other character of the line — other words,
spacing, comments, line ending — as it was. Numbers are written with 6 decimals (trailing
zeros dropped): 10⁻⁶ mm, far below any machine's resolution.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_FIRST = re.compile(r"\s*[A-Za-z]\s*[-+]?[\d.]")


@dataclass(frozen=True)
class Move:
    """One move to filter: ``line`` (0-based index into the program's lines), the target
    (n,) in file units (mm, deg), and the spans of the axis words' numbers in the line
    (pose coordinate → (start, end)); ``after`` the position after the last axis word.
    Split (``segment``): ``pieces`` (k, n) the intermediate targets, each written as a line
    of its own before this one (``motion`` G0 or G1, ``piece_e`` the E text of each, None
    without extrusion), and ``e_edit`` ((start, end), text) the line's own E word rewritten
    (relative extrusion: its share), or None."""

    line: int
    target: np.ndarray
    spans: dict
    after: int
    pieces: np.ndarray | None = None
    motion: float = 1.0
    piece_e: tuple = ()
    e_edit: tuple | None = None

    @property
    def targets(self) -> np.ndarray:
        """(k + 1, n): the pieces' targets, then the move's own."""
        return self.target[None] if self.pieces is None else np.vstack([self.pieces, self.target[None]])


def _code_spans(line: str) -> list[tuple[int, int]]:
    """(start, end) pieces of ``line`` that are code: before ``;``, outside ``( … )``."""
    out, start, depth = [], 0, 0
    for i, ch in enumerate(line):
        if depth == 0 and ch == ";":
            break
        if ch == "(" and depth == 0:
            out.append((start, i))
            depth = 1
        elif ch == ")" and depth == 1:
            depth = 0
            start = i + 1
    else:
        i = len(line)
    if depth == 0:
        out.append((start, i))
    return out


def _words(line: str) -> list[tuple[str, str, int, int]]:
    """(letter, number text, start of the number, end) of each word of the line's code."""
    out = []
    for a, b in _code_spans(line):
        for m in _WORD.finditer(line, a, b):
            out.append((m.group(1).upper(), m.group(2), m.start(2), m.end(2)))
    return out


def parse_moves(lines: list[str], axes: tuple[str, ...], src: str, segment: float | None = None
                ) -> tuple[list[Move], list[int]]:
    """The moves of a program (module docstring) and the line numbers (1-based) of the moves
    left as they are because some coordinate is not known yet; ``axes`` the pose
    coordinates as G-code letters (``("X", "Y", "Z")``, a hexapod's ``("X", "Y", "Z", "A",
    "B", "C")``). ``segment`` (mm): a move longer than that in x, y, z (from the last
    filtered move's target) is split into equal pieces no longer than it, the extrusion
    shared among them (absolute E, M82, Klipper's and Marlin's default: interpolated;
    relative E, M83: divided), as Klipper's bed mesh splits moves (bed_mesh.py
    ``MoveSplitter.split``, every ``move_check_distance`` 5 mm)."""
    moves: list[Move] = []
    skipped: list[int] = []
    position: dict[str, float | None] = {a: None for a in axes}
    motion = None
    previous = None                 # the last filtered target: where a split starts
    e_relative, e_position = False, 0.0
    for k, line in enumerate(lines):
        where = f"{src}:{k + 1}"
        code = "".join(line[a:b] for a, b in _code_spans(line))
        if not code.strip() or not _FIRST.match(code):
            continue
        words = _words(line)
        gs = [float(v) for letter, v, _, _ in words if letter == "G"]
        given = {letter: (v, s, e) for letter, v, s, e in words if letter in axes}
        ms = [float(v) for letter, v, _, _ in words if letter == "M"]
        for code_m in ms:
            if code_m in (82, 83):
                e_relative = code_m == 83
        e_word = next(((v, s, e) for letter, v, s, e in words if letter == "E"), None)
        if 92 in gs and e_word is not None:
            e_position = float(e_word[0])
        if any(letter in ("M", "T") for letter, *_ in words) and not gs:
            continue
        for g in gs:
            if g == 91:
                raise PkmcalError(f"{where}: relative positioning (G91) is not filtered; write the program with "
                                  "absolute coordinates (G90)")
            if g == 20:
                raise PkmcalError(f"{where}: inches (G20) are not filtered; write the program in mm (G21)")
            if g in (2, 3):
                raise PkmcalError(f"{where}: an arc (G{g:g}) is not filtered (its corrected path is no arc); let the "
                                  "slicer or CAM write straight moves (G1)")
        motion_words = [g for g in gs if g in (0, 1)]
        if motion_words:
            motion = motion_words[-1]
        if 28 in gs:
            position = {a: None for a in axes}
            previous = None
            continue
        if 92 in gs and given:
            raise PkmcalError(f"{where}: G92 with {', '.join(given)} sets a new origin, which the filter cannot "
                              "follow; remove it or give the coordinates in the machine's frame")
        others = [g for g in gs if g not in (0, 1, 90, 21, 94, 17, 40, 49, 80, 92, 4, 61, 64)]
        if given and others:
            raise PkmcalError(f"{where}: G{others[0]:g} with axis words is not filtered; only straight moves "
                              "(G0, G1) are")
        e_delta = None
        if e_word is not None and 92 not in gs and (motion_words or motion is not None):
            e_value = float(e_word[0])
            e_delta = e_value if e_relative else e_value - e_position
            e_position = e_position + e_value if e_relative else e_value
        if not given or (not motion_words and motion is None):
            continue
        for a, (v, _, _) in given.items():
            position[a] = float(v)
        unknown = [a for a in axes if position[a] is None]
        if unknown:
            skipped.append(k + 1)
            previous = None
            continue
        spans = {a: (s, e) for a, (_, s, e) in given.items()}
        target = np.array([position[a] for a in axes])
        move = Move(k, target, spans, max(e for _, e in spans.values()), motion=motion)
        if segment is not None and previous is not None:
            n = int(np.ceil(np.linalg.norm(target[:3] - previous[:3]) / segment - 1e-9))
            if n > 1:
                move = _split(move, previous, n, e_word, e_delta, e_relative, e_position)
        moves.append(move)
        previous = target
    return moves, skipped


def _split(move: Move, start: np.ndarray, n: int, e_word, e_delta, e_relative: bool, e_end: float) -> Move:
    """``move`` split into n equal pieces from ``start`` (:func:`parse_moves`)."""
    from dataclasses import replace

    frac = np.arange(1, n)[:, None] / n
    pieces = start[None] + frac * (move.target - start)[None]
    piece_e: tuple = (None,) * (n - 1)
    e_edit = None
    if e_delta is not None:
        if e_relative:
            share = [number_text(e_delta / n) for _ in range(n - 1)]
            piece_e = tuple(share)
            e_edit = ((e_word[1], e_word[2]), number_text(e_delta - sum(float(v) for v in share)))
        else:
            piece_e = tuple(number_text(e_end - e_delta + e_delta * f) for f in frac[:, 0])
    return replace(move, pieces=pieces, piece_e=piece_e, e_edit=e_edit)


def number_text(value: float) -> str:
    """``%.6f`` without trailing zeros (module docstring); never ``-0``."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def rewrite(lines: list[str], moves: list[Move], values: np.ndarray, axes: tuple[str, ...]) -> list[str]:
    """``lines`` with each move's axis words set to ``values`` (rows in the order of the
    moves' :attr:`Move.targets`, the pieces of a split move first; module docstring); a
    split move's pieces are lines of their own (``G0``/``G1``, the axes, E) before its line,
    with its line ending."""
    out = list(lines)
    k = 0
    for mv in moves:
        rows = values[k:k + len(mv.targets)]
        k += len(mv.targets)
        line, row = lines[mv.line], rows[-1]
        edits = [(s, e, number_text(v)) for a, v in zip(axes, row) if a in mv.spans for s, e in [mv.spans[a]]]
        if mv.e_edit is not None:
            edits.append((*mv.e_edit[0], mv.e_edit[1]))
        missing = "".join(f" {a}{number_text(v)}" for a, v in zip(axes, row) if a not in mv.spans)
        line = line[:mv.after] + missing + line[mv.after:]
        for s, e, text in sorted(edits, reverse=True):
            shift = len(missing) if s >= mv.after else 0
            line = line[:s + shift] + text + line[e + shift:]
        ending = lines[mv.line][len(lines[mv.line].rstrip("\r\n")):]
        pieces = "".join(f"G{mv.motion:g} " + " ".join(f"{a}{number_text(v)}" for a, v in zip(axes, r))
                         + (f" E{e}" if e is not None else "") + (ending or "\n")
                         for r, e in zip(rows[:-1], mv.piece_e))
        out[mv.line] = pieces + line
    return out


__all__ = ["Move", "number_text", "parse_moves", "rewrite"]

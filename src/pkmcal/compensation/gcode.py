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
    (pose coordinate → (start, end)); ``after`` the position after the last axis word."""

    line: int
    target: np.ndarray
    spans: dict
    after: int


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


def parse_moves(lines: list[str], axes: tuple[str, ...], src: str) -> tuple[list[Move], list[int]]:
    """The moves of a program (module docstring) and the line numbers (1-based) of the moves
    left as they are because some coordinate is not known yet; ``axes`` the pose
    coordinates as G-code letters (``("X", "Y", "Z")``, a hexapod's ``("X", "Y", "Z", "A",
    "B", "C")``)."""
    moves: list[Move] = []
    skipped: list[int] = []
    position: dict[str, float | None] = {a: None for a in axes}
    motion = None
    for k, line in enumerate(lines):
        where = f"{src}:{k + 1}"
        code = "".join(line[a:b] for a, b in _code_spans(line))
        if not code.strip() or not _FIRST.match(code):
            continue
        words = _words(line)
        gs = [float(v) for letter, v, _, _ in words if letter == "G"]
        given = {letter: (v, s, e) for letter, v, s, e in words if letter in axes}
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
            continue
        if 92 in gs and given:
            raise PkmcalError(f"{where}: G92 with {', '.join(given)} sets a new origin, which the filter cannot "
                              "follow; remove it or give the coordinates in the machine's frame")
        others = [g for g in gs if g not in (0, 1, 90, 21, 94, 17, 40, 49, 80, 92, 4, 61, 64)]
        if given and others:
            raise PkmcalError(f"{where}: G{others[0]:g} with axis words is not filtered; only straight moves "
                              "(G0, G1) are")
        if not given or (not motion_words and motion is None):
            continue
        for a, (v, _, _) in given.items():
            position[a] = float(v)
        unknown = [a for a in axes if position[a] is None]
        if unknown:
            skipped.append(k + 1)
            continue
        spans = {a: (s, e) for a, (_, s, e) in given.items()}
        moves.append(Move(k, np.array([position[a] for a in axes]), spans, max(e for _, e in spans.values())))
    return moves, skipped


def number_text(value: float) -> str:
    """``%.6f`` without trailing zeros (module docstring); never ``-0``."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def rewrite(lines: list[str], moves: list[Move], values: np.ndarray, axes: tuple[str, ...]) -> list[str]:
    """``lines`` with each move's axis words set to ``values`` (N, n) (module docstring)."""
    out = list(lines)
    for mv, row in zip(moves, values):
        line = lines[mv.line]
        edits = sorted(((s, e, number_text(v)) for a, v in zip(axes, row) if a in mv.spans
                        for s, e in [mv.spans[a]]), reverse=True)
        missing = "".join(f" {a}{number_text(v)}" for a, v in zip(axes, row) if a not in mv.spans)
        line = line[:mv.after] + missing + line[mv.after:]
        for s, e, text in edits:
            line = line[:s] + text + line[e:]
        out[mv.line] = line
    return out


__all__ = ["Move", "number_text", "parse_moves", "rewrite"]

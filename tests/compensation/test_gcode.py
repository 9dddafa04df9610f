"""The G-code filter (pkmcal.compensation.gcode): moves found as RS-274 reads them (modal
motion, comments, Klipper's extended commands left alone), every byte but the axis numbers
kept, and what it cannot follow refused with the line number."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkmcal.compensation.gcode import number_text, parse_moves, rewrite
from pkmcal.errors import PkmcalError

AXES = ("X", "Y", "Z")
PROGRAM = (
    "; sliced by hand \u00b5m\r\n"
    "G28 ; home\r\n"
    "G1 Z15 F6000\r\n"                       # X, Y unknown after G28: left as it is
    "BED_MESH_PROFILE LOAD=default\r\n"
    "G90\r\n"
    "G1 X10 Y-20.5 Z0.3 F1500 E0.1 ; first\r\n"
    "G1   x12.25 (LinuxCNC comment X99) E0.2\r\n"
    "X13 Y5\r\n"                              # modal G1
    "M104 S200 X5\r\n"                        # an M word's X is no axis
    "G92 E0\r\n"
    "G0 Z5.0\r\n"
    "G1 E-1 F2400\r\n"                        # no axis word: not a move
)


def _lines(text):
    return text.splitlines(keepends=True)


def test_moves_are_found_with_modal_coordinates_and_skips():
    moves, skipped = parse_moves(_lines(PROGRAM), AXES, "p.gcode")
    assert [m.line + 1 for m in moves] == [6, 7, 8, 11]
    np.testing.assert_array_equal([m.target for m in moves],
                                  [[10, -20.5, 0.3], [12.25, -20.5, 0.3], [13, 5, 0.3], [13, 5, 5.0]])
    assert skipped == [3]


def test_rewrite_changes_only_the_axis_numbers():
    lines = _lines(PROGRAM)
    moves, _ = parse_moves(lines, AXES, "p.gcode")
    values = np.array([m.target for m in moves]) + 0.123456789
    out = rewrite(lines, moves, values, AXES)
    moved = {m.line for m in moves}
    for k, (a, b) in enumerate(zip(lines, out)):
        if k not in moved:
            assert a == b
    assert out[5] == "G1 X10.123457 Y-20.376543 Z0.423457 F1500 E0.1 ; first\r\n"
    assert out[6] == "G1   x12.373457 Y-20.376543 Z0.423457 (LinuxCNC comment X99) E0.2\r\n"
    assert out[7] == "X13.123457 Y5.123457 Z0.423457\r\n"
    # read back: the new numbers, to the 1e-6 mm written
    again, _ = parse_moves(out, AXES, "p.gcode")
    np.testing.assert_allclose([m.target for m in again], values, atol=5e-7)


@pytest.mark.parametrize("line, what", [("G91", "G91"), ("G20", "G20"), ("G2 X1 Y1 I1 J0", "arc"),
                                        ("G92 X0 Y0", "G92"), ("G10 L2 P1 X5", "G10")])
def test_what_cannot_be_followed_is_refused_with_its_line(line, what):
    text = "G1 X0 Y0 Z1\n; comment\n" + line + "\nG1 X1\n"
    with pytest.raises(PkmcalError, match=f"p.gcode:3: .*{what}"):
        parse_moves(_lines(text), AXES, "p.gcode")


def test_number_text():
    assert number_text(1.0) == "1"
    assert number_text(-0.0000001) == "0"
    assert number_text(-12.5) == "-12.5"
    assert number_text(0.1234567) == "0.123457"


coords = st.floats(-500, 500, allow_nan=False).map(lambda v: round(v, 4))


@given(st.lists(st.tuples(coords, coords, coords, st.sampled_from(["", " F3000", " E1.5", " ; c"])),
                min_size=1, max_size=20),
       st.sampled_from(["\n", "\r\n"]))
def test_parse_rewrite_round_trip(rows, ending):
    text = "".join(f"G1 X{x} Y{y} Z{z}{tail}{ending}" for x, y, z, tail in rows)
    lines = _lines(text)
    moves, skipped = parse_moves(lines, AXES, "h.gcode")
    assert not skipped and len(moves) == len(rows)
    targets = np.array([m.target for m in moves])
    np.testing.assert_array_equal(targets, [r[:3] for r in rows])
    shifted = targets + np.array([0.5, -0.25, 1e-3])
    out = rewrite(lines, moves, shifted, AXES)
    back, _ = parse_moves(out, AXES, "h.gcode")
    np.testing.assert_allclose([m.target for m in back], shifted, atol=5e-7)
    for (x, y, z, tail), new in zip(rows, out):
        assert new.endswith(tail + ending)


def _split(text, segment=5.0):
    lines = _lines(text)
    moves, _ = parse_moves(lines, AXES, "s.gcode", segment=segment)
    values = np.vstack([m.targets for m in moves])
    return moves, rewrite(lines, moves, values, AXES)


def test_split_relative_extrusion_shares_e():
    moves, out = _split("M83\nG1 X0 Y0 Z0.3\nG1 X20 Y0 E1.0 F1200 ; long\n")
    assert len(moves[1].targets) == 4
    assert "".join(out[2:]) == ("G1 X5 Y0 Z0.3 E0.25\nG1 X10 Y0 Z0.3 E0.25\nG1 X15 Y0 Z0.3 E0.25\n"
                                "G1 X20 Y0 Z0.3 E0.25 F1200 ; long\n")


def test_split_absolute_extrusion_interpolates_e_and_keeps_the_end():
    moves, out = _split("G92 E10\nG1 X0 Y0 Z0.3\nG1 X0 Y-12 E12\nG28\nG1 X0 Y0 Z1\n", segment=5.0)
    text = "".join(out)
    assert "G1 X0 Y-4 Z0.3 E10.666667\nG1 X0 Y-8 Z0.3 E11.333333\nG1 X0 Y-12 Z0.3 E12\n" in text
    assert len(moves[2].targets) == 1          # after G28: no start to split from


@given(st.floats(0.5, 20.0), st.lists(st.tuples(coords, coords), min_size=2, max_size=6),
       st.floats(0.01, 3.0).map(lambda v: round(v, 3)))
def test_split_pieces_are_short_and_keep_the_extrusion(segment, xy, e):
    text = "M83\n" + "".join(f"G1 X{x} Y{y} Z0.2 E{e}\n" for x, y in xy)
    lines = _lines(text)
    moves, _ = parse_moves(lines, AXES, "h.gcode", segment=segment)
    out = rewrite(lines, moves, np.vstack([m.targets for m in moves]), AXES)
    again, _ = parse_moves("".join(out).splitlines(keepends=True), AXES, "h.gcode")
    pts = np.array([m.target for m in again])
    assert np.all(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1) <= segment + 1e-5)
    total = sum(float(w.split("E")[1]) for w in "".join(out).split("\n")[1:] if "E" in w)
    assert abs(total - e * len(xy)) <= 1e-6 * len(out)       # pieces written to 1e-6, the last takes the rest

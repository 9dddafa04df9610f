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

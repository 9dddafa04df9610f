"""CSV tables: reading named numeric columns, every error path, exact deterministic writing."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.conventions import POSE_COLUMNS
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.tables import (
    LENGTH_COLUMNS,
    READING_COLUMNS,
    column_kinds,
    format_table,
    from_file_units,
    read_poses,
    read_table,
    to_file_units,
    write_table,
)


def _read(text: str, columns=POSE_COLUMNS, **kw):
    return read_table("t.csv", columns, text=text, **kw)


def _error(text: str, columns=POSE_COLUMNS, **kw) -> InputFileError:
    with pytest.raises(InputFileError) as info:
        _read(text, columns, **kw)
    return info.value


def test_basic_read_with_comments_extra_columns_and_line_numbers():
    text = ("# units: length=mm, angle=deg\n# a comment\n\nid,X, y ,z,a,b,c,note\n"
            "p1,1,2,3,4,5,6,first\n# skipped\n\np2,-1.5e2,0,0.25,0,0,-0,x\n")
    t = _read(text)
    assert t.columns == POSE_COLUMNS
    np.testing.assert_array_equal(t.values, [[1, 2, 3, 4, 5, 6], [-150, 0, 0.25, 0, 0, 0]])
    np.testing.assert_array_equal(t.lines, [5, 8])
    assert t.units == {"length": "mm", "angle": "deg"}
    np.testing.assert_array_equal(t["z"], [3, 0.25])
    np.testing.assert_array_equal(t[["a", "c"]], [[4, 6], [0, 0]])
    assert len(t) == 2


def test_bom_crlf_and_quotes(tmp_path):
    path = tmp_path / "p.csv"
    path.write_bytes('\ufeffx,y,z,a,b,c,"note, with comma"\r\n1,2,3,4,5,6,"a, b"\r\n'.encode("utf-8"))
    t = read_table(path, POSE_COLUMNS)
    np.testing.assert_array_equal(t.values, [[1, 2, 3, 4, 5, 6]])
    assert t.lines.tolist() == [2]


def test_aliases_and_either():
    t = read_table("t.csv", either=[READING_COLUMNS, LENGTH_COLUMNS],
                   text="λ1,Lambda_2,lambda3,LAMBDA4,λ_5,lambda6\n1,2,3,4,5,6\n")
    assert t.columns == READING_COLUMNS
    t = read_table("t.csv", either=[READING_COLUMNS, LENGTH_COLUMNS], text="L1,l_2,l3,l4,length5,l6\n1,2,3,4,5,6\n")
    assert t.columns == LENGTH_COLUMNS
    both = "l1,l2,l3,l4,l5,l6,lambda1,lambda2,lambda3,lambda4,lambda5,lambda6\n" + ",".join(map(str, range(12))) + "\n"
    t = read_table("t.csv", either=[READING_COLUMNS, LENGTH_COLUMNS], text=both)
    assert t.columns == READING_COLUMNS
    np.testing.assert_array_equal(t.values[0], range(6, 12))


def test_unit_conversion():
    t = _read("# units: length=m, angle=rad\nx,y,z,a,b,c\n0.001,1,2.5,3.141592653589793,0,1\n")
    np.testing.assert_allclose(t.values[0], [1, 1000, 2500, 180, 0, np.rad2deg(1)], rtol=1e-15)
    t = _read("# units: length=inch\nx,y,z,a,b,c\n1,0,0,1,0,0\n")
    np.testing.assert_array_equal(t.values[0], [25.4, 0, 0, 1, 0, 0])


@pytest.mark.parametrize(
    "text, expected, line, column",
    [
        ("", "the file is empty: expected a header row naming the columns (e.g. x,y,z,a,b,c)", None, None),
        ("# just a comment\n\n", "the file is empty", None, None),
        ("x,y,z,a,b,c\n", "no data rows after the header", 1, None),
        ("x,y,z,a\n1,2,3,4\n", "missing columns b, c (needs x,y,z,a,b,c); the header has 'x', 'y', 'z', 'a'", 1, None),
        ("1,2,3,4,5,6\n", "the first row is numbers, not names: add a header row 'x,y,z,a,b,c'", 1, None),
        ("x;y;z;a;b;c\n1;2;3;4;5;6\n", "separate the columns with commas", 1, None),
        ("x,y,z,a,b,c\n1,2,3,4,5,6\n1,2,abc,4,5,6\n", "'abc' is not a number; every cell of column 'z' must be a "
         "finite number", 3, "z"),
        ("x,y,z,a,b,c\n1,2,3,4,,6\n", "empty", 2, "b"),
        ("x,y,z,a,b,c\n1,2,3,4,5,nan\n", "'nan' is not a finite number", 2, "c"),
        ("x,y,z,a,b,c\n1,2,3,4,5,inf\n", "'inf' is not a finite number", 2, "c"),
        ("x,y,z,a,b,c\n1,2,3,4,5,6\n1,2,3\n", "3 cells, but the header has 6 columns", 3, None),
        ("x,y,z,a,b,c\n1,2,3,4,5,6,7\n", "7 cells, but the header has 6 columns", 2, None),
        ("x,X,y,z,a,b,c\n1,1,2,3,4,5,6\n", "columns 'x' and 'X' both name 'x'; keep one", 1, "X"),
        ("# units: length=furlong\nx,y,z,a,b,c\n1,2,3,4,5,6\n", "unknown length unit 'furlong'", 1, None),
        ("# units: mass=kg\nx,y,z,a,b,c\n1,2,3,4,5,6\n", "'mass=kg' is not QUANTITY=UNIT", 1, None),
    ],
)
def test_errors(text, expected, line, column):
    err = _error(text)
    assert expected in str(err)
    assert str(err).startswith("t.csv")
    assert err.line == line and err.column == column
    assert "\n" not in str(err)


def test_earliest_bad_cell_is_reported():
    err = _error("x,y,z,a,b,c\n1,2,3,4,5,x6\n1,bad,3,4,5,6\n")
    assert (err.line, err.column) == (2, "c")


def test_ignored_columns_are_not_parsed():
    t = _read("x,y,z,a,b,c,comment\n1,2,3,4,5,6,not a number\n")
    assert t.values.shape == (1, 6)


def test_either_missing_names_alternatives():
    err = _error("a1,a2\n1,2\n", columns=(), either=[READING_COLUMNS, LENGTH_COLUMNS])
    assert "needs lambda1..lambda6 or l1..l6" in str(err)
    assert "the header has 'a1', 'a2'" in str(err)


def test_file_errors(tmp_path):
    with pytest.raises(InputFileError, match="cannot read the table"):
        read_table(tmp_path / "none.csv", POSE_COLUMNS)
    with pytest.raises(InputFileError, match="cannot read the table"):
        read_table(tmp_path, POSE_COLUMNS)
    p = tmp_path / "bin.csv"
    p.write_bytes(b"x,y\n\xff\xfe")
    with pytest.raises(InputFileError, match="not a UTF-8 text file"):
        read_table(p, POSE_COLUMNS)


# -- writing ----------------------------------------------------------------------------

def test_format_is_deterministic_and_typed():
    cols = {"x": np.array([0.1, -2.0, 1e-300]), "n": np.array([1, 0, 3]), "ok": np.array([True, False, True]),
            "s": np.array(["ok", "a,b", ' q"'], dtype=object)}
    text = format_table(cols)
    assert text == ('x,n,ok,s\n0.1,1,1,ok\n-2.0,0,0,"a,b"\n'
                    '1e-300,3,1," q"""\n')
    assert format_table(cols) == text
    commented = format_table(cols, units_comment=True, comments=["made by a test"])
    assert commented == "# units: length=mm, angle=deg\n# made by a test\n" + text
    assert format_table(cols, comments=["not asked for"]) == text


def test_format_rejects_ragged_columns():
    with pytest.raises(ValueError, match="different lengths"):
        format_table({"a": [1.0], "b": [1.0, 2.0]})


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(*[st.floats(allow_nan=False, allow_infinity=False)] * 6), min_size=1, max_size=20))
def test_write_read_round_trip_is_exact(rows):
    data = np.array(rows, dtype=float)
    text = format_table({n: data[:, k] for k, n in enumerate(POSE_COLUMNS)})
    back = _read(text)
    np.testing.assert_array_equal(back.values, data)
    assert np.array_equal(np.signbit(back.values), np.signbit(data))  # even -0.0


def test_write_table_atomic(tmp_path):
    path = tmp_path / "out.csv"
    write_table(path, {"x": np.array([1.0, 2.0])})
    assert path.read_text() == "x\n1.0\n2.0\n"
    assert os.listdir(tmp_path) == ["out.csv"]
    with pytest.raises(PkmcalError, match="cannot write"):
        write_table(tmp_path / "missing-dir" / "out.csv", {"x": np.array([1.0])})
    with pytest.raises(PkmcalError, match="cannot write table"):
        write_table(path, {"x": [1.0], "y": [1.0, 2.0]})
    assert path.read_text() == "x\n1.0\n2.0\n"  # untouched by the failures


def test_file_unit_conversion_closed_form_and_round_trip(tmp_path):
    """Degrees ↔ radians in the angle columns only; lengths untouched; inputs not modified."""
    from pkmcal.mechanisms.library import builtin_machine

    file_poses = np.array([[10.0, -20.0, 500.0, 90.0, -45.0, 180.0], [0.0, 0.0, 0.0, 30.0, 60.0, -90.0]])
    original = file_poses.copy()
    internal = from_file_units(file_poses, (False,) * 3 + (True,) * 3)
    np.testing.assert_array_equal(file_poses, original)
    np.testing.assert_array_equal(internal[:, :3], original[:, :3])
    np.testing.assert_allclose(internal[:, 3:], [[np.pi / 2, -np.pi / 4, np.pi], [np.pi / 6, np.pi / 3, -np.pi / 2]],
                               rtol=1e-15)
    np.testing.assert_allclose(to_file_units(internal, (False,) * 3 + (True,) * 3), original, rtol=1e-14)
    np.testing.assert_allclose(from_file_units(original[0], (False,) * 3 + (True,) * 3), internal[0], rtol=0)
    assert column_kinds(("x", "a"), (False, True)) == {"x": "length", "a": "angle"}
    # read_poses: a file in radians and metres comes back as the same internal poses
    machine = builtin_machine("stewart-prototype")
    text = format_table({c: internal[:, k] * (1e-3 if k < 3 else 1.0) for k, c in enumerate(POSE_COLUMNS)},
                        units={"length": "m", "angle": "rad"}, units_comment=True)
    path = tmp_path / "poses.csv"
    path.write_text(text)
    np.testing.assert_allclose(read_poses(path, machine), internal, rtol=1e-12, atol=1e-12)

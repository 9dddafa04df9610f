"""Orientation columns other than Euler angles: unit quaternions and rotation vectors.

Motion-capture systems, ROS and scipy give an orientation as a unit quaternion
q = (x, y, z, w) (scalar last); robot controllers often as a rotation vector r (the angle
|r| about the axis r/|r|). pkmcal's pose convention is the angles a, b, c of
R = Rz(c)·Ry(b)·Rx(a) (:mod:`pkmcal.conventions`). A table that has, instead of a pose's
``a,b,c`` (or ``cmd_a,cmd_b,cmd_c``), one of

* ``qx,qy,qz,qw`` — the quaternion's components by name (any column order);
* ``q1,q2,q3,q4`` — the quaternion's components by position, in the order
  ``--quaternion-order`` names: ``xyzw`` (default; scipy, ROS) or ``wxyz`` (scalar first);
* ``rx,ry,rz`` — a rotation vector, in the table's angle unit (degrees unless the units line
  or ``--angle-unit`` says ``rad``); these are *not* Euler angles,

(with the same ``cmd_`` prefix for a commanded pose) is read as the a, b, c (degrees) of the
same rotation:

    R = Rotation.from_quat([x, y, z, w]).as_matrix()       R = Rotation.from_rotvec(r).as_matrix()
    (a, b, c) = matrix_to_euler(R)    (b in [−90°, 90°], a and c in (−180°, 180°])

q and −q give the same R, so the same angles. A quaternion whose norm differs from 1 by
more than :data:`NORM_TOLERANCE` is an error naming the file, the line, the pose (data row,
counted from 1) and the norm: a unit quaternion is what the instruments write, and anything
else is a wrong column, a scaled export or a truncated line. Within the tolerance it is
normalised (by scipy). Code used by :func:`pkmcal.io.tables.read_table`; tests:
``tests/io/test_orientation.py``.

Conventions that look wrong (:func:`small_angle_note`, :func:`quaternion_order_note`; issue 24): every reader of
orientation columns notes (the table's ``notes``, and a :class:`~pkmcal.errors.PkmcalWarning`)

* Euler angles or rotation vectors read in degrees whose largest magnitude over the whole
  file is above 0 and below the machine's orientation range in radians read as degrees
  (:func:`small_angle_limit`; at least :data:`SMALL_ANGLE_DEG`, 0.1°, the limit of readers
  that know no machine): radians written where degrees are read give exactly that; the
  note names ``--angle-unit rad``;
* quaternions whose first column in the file has magnitude above :data:`NEAR_ONE` on every
  row while it is not read as the scalar: a scalar-first file read as scalar-last (a
  machine's orientations near the identity have w ≈ 1; read wrongly, every pose turns by
  about 180°); the note names ``--quaternion-order wxyz`` (or, for named columns, the
  ``--columns`` renaming).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from pkmcal.errors import InputFileError

#: Orders of the positional quaternion columns q1..q4 (``--quaternion-order``).
QUATERNION_ORDERS = ("xyzw", "wxyz")
#: Largest accepted | ‖q‖ − 1 | of a quaternion read from a file.
NORM_TOLERANCE = 1e-6
#: Below this largest |angle| (degrees) over a file, angle columns read in degrees look like radians.
SMALL_ANGLE_DEG = 0.1
#: Above this |component| on every row, a quaternion column not read as w looks like the scalar.
NEAR_ONE = 0.9
_EULER = ("a", "b", "c")


@dataclass(frozen=True)
class OrientationSource:
    """Where a pose's a, b, c come from: ``euler`` the three names asked for (``a, b, c``
    or ``cmd_a, ...``), ``kind`` ``"quaternion"`` or ``"rotvec"``, ``columns`` the canonical
    names of the columns read, quaternions in x, y, z, w order."""

    euler: tuple[str, str, str]
    kind: str
    columns: tuple[str, ...]


def euler_triples(wanted: Sequence[str]) -> list[tuple[str, str, str]]:
    """The ``(p+'a', p+'b', p+'c')`` triples all of whose names are in ``wanted``."""
    names = set(wanted)
    out = []
    for name in wanted:
        if name.endswith("a"):
            prefix = name[:-1]
            triple = tuple(prefix + e for e in _EULER)
            if all(t in names for t in triple) and triple not in out:
                out.append(triple)
    return out


def _candidates(prefix: str, order: str) -> list[tuple[str, tuple[str, ...]]]:
    positional = tuple(f"{prefix}q{i}" for i in range(1, 5))
    by_position = positional if order == "xyzw" else positional[1:] + positional[:1]
    return [("quaternion", tuple(f"{prefix}q{c}" for c in "xyzw")),
            ("quaternion", by_position),
            ("rotvec", tuple(f"{prefix}r{c}" for c in "xyz"))]


def find_sources(src: str, header: Sequence[str], present: Mapping[str, int], wanted: Sequence[str],
                 order: str, line: int) -> list[OrientationSource]:
    """The orientation sources of the Euler triples of ``wanted`` missing from the header.

    ``present`` maps the header's canonical names to their cell index. A triple present in
    full is read as such; a triple none of whose names is present is read from the one
    alternative the header has (nothing found: the caller's missing-column error says what
    to give). Two ways of giving one orientation are an :class:`InputFileError`.
    """
    if order not in QUATERNION_ORDERS:
        raise InputFileError(src, f"quaternion order '{order}': choose one of {', '.join(QUATERNION_ORDERS)}")
    out = []
    for triple in euler_triples(wanted):
        prefix = triple[0][:-1]
        found = [(kind, cols) for kind, cols in _candidates(prefix, order) if all(c in present for c in cols)]
        given = [c for c in triple if c in present]
        ways = ([",".join(triple)] if len(given) == 3 else []) + [",".join(cols) for _, cols in found]
        if len(ways) > 1:
            raise InputFileError(src, f"the orientation is given twice, as {' and as '.join(ways)}; keep one "
                                      f"(rename the others away with --columns, e.g. '{found[-1][1][0]}=unused_1')",
                                 line=line)
        if found and not given:
            kind, cols = found[0]
            out.append(OrientationSource(euler=triple, kind=kind, columns=cols))
    return out


def orientation_given(names, triple: Sequence[str], order: str = "xyzw") -> bool:
    """Whether the canonical header ``names`` give the orientation ``triple`` (as Euler
    angles, or in full by one of the alternatives)."""
    prefix = triple[0][:-1]
    ways = [tuple(triple)] + [cols for _, cols in _candidates(prefix, order)]
    return any(all(c in names for c in cols) for cols in ways)


def alternatives_hint(triple: Sequence[str], order: str = "xyzw") -> str:
    """What else gives the orientation ``triple``, for a missing-column message."""
    prefix = triple[0][:-1]
    q = ",".join(f"{prefix}q{c}" for c in "xyzw")
    pos = ",".join(f"{prefix}q{i}" for i in range(1, 5))
    r = ",".join(f"{prefix}r{c}" for c in "xyz")
    return (f"or give the orientation as a unit quaternion {q} (or {pos} in --quaternion-order {order}) "
            f"or a rotation vector {r}")


def euler_from_quaternions(q: np.ndarray, src: str, lines: np.ndarray, columns: Sequence[str],
                           header_names: Sequence[str]) -> np.ndarray:
    """a, b, c (degrees, (N, 3)) of the quaternions ``q`` (N, 4), x, y, z, w order.

    :class:`InputFileError` at the first row (file order) whose norm differs from 1 by more
    than :data:`NORM_TOLERANCE`, naming its line, its pose number (data row from 1), the
    columns and the norm."""
    from scipy.spatial.transform import Rotation

    from pkmcal.conventions import matrix_to_euler

    q = np.asarray(q, dtype=float)
    norm = np.linalg.norm(q, axis=1)
    bad = ~(np.abs(norm - 1.0) <= NORM_TOLERANCE)
    if bad.any():
        k = int(np.argmax(bad))
        values = ", ".join(repr(float(v)) for v in q[k])
        raise InputFileError(
            src, f"pose {k + 1}: the quaternion ({', '.join(header_names)}) = ({values}) has norm "
                 f"{float(norm[k])!r}, not 1 (|norm - 1| > {NORM_TOLERANCE:g}); check the columns "
                 f"(x, y, z, w = {', '.join(columns)}) and that the export writes unit quaternions",
            line=int(lines[k]))
    return np.rad2deg(matrix_to_euler(Rotation.from_quat(q).as_matrix()))


def euler_from_rotvecs(r_deg: np.ndarray) -> np.ndarray:
    """a, b, c (degrees, (N, 3)) of the rotation vectors ``r_deg`` (N, 3), degrees."""
    from scipy.spatial.transform import Rotation

    from pkmcal.conventions import matrix_to_euler

    return np.rad2deg(matrix_to_euler(Rotation.from_rotvec(np.deg2rad(r_deg)).as_matrix()))


def small_angle_limit(machine) -> float:
    """The largest |angle| (degrees) below which a file's orientations look like radians on
    ``machine``: its orientation range in radians read as degrees (a file in degrees that
    uses less than 1/57.3 of the range the machine can tilt is likelier radians), at least
    :data:`SMALL_ANGLE_DEG`."""
    angles = np.asarray(machine.pose_is_angle, dtype=bool)
    if not angles.any():
        return SMALL_ANGLE_DEG
    reach_rad = float(np.max(np.abs(np.asarray(machine.workspace_box(), dtype=float)[angles])))
    return max(SMALL_ANGLE_DEG, reach_rad) if np.isfinite(reach_rad) else SMALL_ANGLE_DEG


def small_angle_note(src: str, columns: Sequence[str], degrees: np.ndarray, what: str,
                     limit: float | None = None) -> str | None:
    """The note of the module docstring for angle ``columns`` (values in degrees, (N, k))
    whose magnitudes are all below ``limit`` (default :data:`SMALL_ANGLE_DEG`) but not all
    zero, else None."""
    limit = SMALL_ANGLE_DEG if limit is None else float(limit)
    with np.errstate(invalid="ignore"):
        largest = float(np.nanmax(np.abs(degrees))) if degrees.size else 0.0
    if not (0.0 < largest < limit):
        return None
    return (f"{src}: the {what} {','.join(columns)} are all below {limit:.3g} degree (largest {largest:.3g}), "
            "they look like radians read as degrees; if they "
            "are radians, give --angle-unit rad (or the file's units line '# units: angle=rad')")


def quaternion_order_note(src: str, q: np.ndarray, header_names: Sequence[str], file_positions: Sequence[int],
                          positional: bool) -> str | None:
    """The note of the module docstring for quaternions ``q`` (N, 4, in x, y, z, w order as
    read) from the file columns ``header_names`` at header positions ``file_positions``
    (same order), else None: the column that comes first in the file is near ±1 on every
    row although it is not read as w."""
    first = int(np.argmin(file_positions))
    if first == 3 or not len(q) or not bool(np.all(np.abs(q[:, first]) > NEAR_ONE)):
        return None
    fix = ("give --quaternion-order wxyz" if positional else
           "rename the columns with --columns so that the scalar is read as w (qw)")
    return (f"{src}: the quaternion column '{header_names[first]}' (read as {'xyz'[first]}) is near 1 in magnitude "
            f"on every pose while the one read as w ('{header_names[3]}') is not: every orientation would be a turn "
            f"of about 180 degrees; the file looks scalar-first (w, x, y, z): {fix}")


__all__ = ["NEAR_ONE", "NORM_TOLERANCE", "SMALL_ANGLE_DEG", "small_angle_limit", "small_angle_note", "quaternion_order_note", "OrientationSource", "QUATERNION_ORDERS", "alternatives_hint", "euler_from_quaternions",
           "euler_from_rotvecs", "euler_triples", "find_sources", "orientation_given"]

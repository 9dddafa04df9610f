"""Units and the pose convention of pkmcal, stated once and imported everywhere.

* Lengths are millimetres (mm).
* Angles are radians inside the library; degrees in files and on the command line.
  Conversion happens only at the edges (``pkmcal.io`` and ``pkmcal.cli``).
* A pose is ``(x, y, z, a, b, c)``: the position of the platform frame {P} origin in the
  base frame {F} (mm), and roll ``a``, pitch ``b``, yaw ``c`` about the *fixed* base axes
  x, y, z, so that

      R = Rz(c) · Ry(b) · Rx(a)          (scipy: ``Rotation.from_euler("xyz", ...)``)

  and a point ``p_P`` of the platform is ``p_F = [x, y, z] + R p_P`` in the base frame.
  This is LinuxCNC genhexkins' ``X Y Z A B C`` (its ``pmRpyMatConvert``).
* A small change of orientation is a rotation vector ``δω`` in the base frame,
  ``R ← exp([δω]×) R``. "Twist" Jacobians are with respect to ``(δp, δω)``; "Euler"
  Jacobians with respect to ``(x, y, z, a, b, c)``, related by ``δω = E(a, b, c) d(a, b, c)``.
"""

from __future__ import annotations

import numpy as np

#: scipy sequence for R = Rz(c) Ry(b) Rx(a): lower case = extrinsic (fixed axes).
EULER_SEQUENCE = "xyz"
#: Names of the pose coordinates, in order, as they appear in every file.
POSE_COLUMNS = ("x", "y", "z", "a", "b", "c")
LENGTH_UNIT = "mm"
FILE_ANGLE_UNIT = "deg"
#: The range of each Euler angle (a, b, c), radians, in which the convention represents every
#: rotation once (away from gimbal lock; :func:`matrix_to_euler` returns these): a and c in
#: (−π, π], b in [−π/2, π/2]. A planning box of orientations never reaches beyond it.
EULER_RANGES = ((-np.pi, np.pi), (-np.pi / 2, np.pi / 2), (-np.pi, np.pi))


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles (radians, any shape) brought into (−π, π] by whole turns: the same rotation
    about the same axis. Angles already in (−π, π] are returned unchanged, bit for bit."""
    x = np.asarray(angle, dtype=float)
    outside = (x > np.pi) | (x <= -np.pi)
    return np.where(outside, np.pi - np.mod(np.pi - x, 2.0 * np.pi), x)


def euler_to_matrix(abc: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(c) Ry(b) Rx(a)`` for angles ``abc`` of shape (..., 3), radians.

    Closed form (fast path for the kinematics); ``tests/test_conventions.py`` checks it
    against ``scipy.spatial.transform.Rotation``.
    """
    abc = np.asarray(abc, dtype=float)
    ca, cb, cc = np.cos(abc[..., 0]), np.cos(abc[..., 1]), np.cos(abc[..., 2])
    sa, sb, sc = np.sin(abc[..., 0]), np.sin(abc[..., 1]), np.sin(abc[..., 2])
    R = np.empty(abc.shape[:-1] + (3, 3))
    R[..., 0, 0] = cc * cb
    R[..., 0, 1] = cc * sb * sa - sc * ca
    R[..., 0, 2] = cc * sb * ca + sc * sa
    R[..., 1, 0] = sc * cb
    R[..., 1, 1] = sc * sb * sa + cc * ca
    R[..., 1, 2] = sc * sb * ca - cc * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def matrix_to_euler(R: np.ndarray) -> np.ndarray:
    """Angles ``(a, b, c)`` (radians) of rotation matrices ``R`` (..., 3, 3); inverse of
    :func:`euler_to_matrix` with ``b`` in [-π/2, π/2] and ``a, c`` in (-π, π] (atan2 gives −π
    for a −0.0 first argument, e.g. R = Rx(−π) as computed; that −π is returned as +π, the
    same angle, so every rotation has one representation away from gimbal lock).

    Closed form (fast path, no per-call overhead), from the last row and first column of R:
    b = atan2(−R₂₀, √(R₀₀² + R₁₀²)), c = atan2(R₁₀, R₀₀); ``a`` from the second row of
    Rz(c)ᵀR = Ry(b)Rx(a), a = atan2(s_c R₀₂ − c_c R₁₂, c_c R₁₁ − s_c R₀₁), which stays
    accurate near gimbal lock (there c → 0 when R₀₀ = R₁₀ = 0). ``tests/test_conventions.py``
    checks it against scipy and by round trips.
    """
    R = np.asarray(R, dtype=float)
    c = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    b = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 0, 0], R[..., 1, 0]))
    cc, sc = np.cos(c), np.sin(c)
    a = np.arctan2(sc * R[..., 0, 2] - cc * R[..., 1, 2], cc * R[..., 1, 1] - sc * R[..., 0, 1])
    a = np.where(a <= -np.pi, a + 2.0 * np.pi, a)
    c = np.where(c <= -np.pi, c + 2.0 * np.pi, c)
    return np.stack([a, b, c], axis=-1)


def euler_rate_matrix(abc: np.ndarray) -> np.ndarray:
    """``E(a, b, c)`` with ``δω = E d(a, b, c)``: the base-frame angular velocity of
    ``R = Rz(c) Ry(b) Rx(a)``; columns ``Rz Ry e_x``, ``Rz e_y``, ``e_z``. Shape (..., 3, 3)."""
    abc = np.asarray(abc, dtype=float)
    cb, sb = np.cos(abc[..., 1]), np.sin(abc[..., 1])
    cc, sc = np.cos(abc[..., 2]), np.sin(abc[..., 2])
    E = np.zeros(abc.shape[:-1] + (3, 3))
    E[..., 0, 0] = cb * cc
    E[..., 1, 0] = cb * sc
    E[..., 2, 0] = -sb
    E[..., 0, 1] = -sc
    E[..., 1, 1] = cc
    E[..., 2, 2] = 1.0
    return E


def euler_pose_jacobian(J_twist: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Twist Jacobian ∂y/∂(δp, δω) (N, m, 6) → Euler Jacobian ∂y/∂(x, y, z, a, b, c).

    Columns: ∂/∂(x, y, z) = the δp block; ∂/∂(a, b, c) = J_ω E with E's columns
    (c_b c_c, c_b s_c, −s_b), (−s_c, c_c, 0), (0, 0, 1) (:func:`euler_rate_matrix`),
    written out so that no (N, 3, 3) matrix product is needed.
    """
    cb, sb = np.cos(poses[:, 4])[:, None], np.sin(poses[:, 4])[:, None]
    cc, sc = np.cos(poses[:, 5])[:, None], np.sin(poses[:, 5])[:, None]
    wx, wy, wz = J_twist[:, :, 3], J_twist[:, :, 4], J_twist[:, :, 5]
    out = np.empty(J_twist.shape)
    out[:, :, :3] = J_twist[:, :, :3]
    out[:, :, 3] = cb * (cc * wx + sc * wy) - sb * wz
    out[:, :, 4] = cc * wy - sc * wx
    out[:, :, 5] = wz
    return out


def poses_from_file_units(poses_deg: np.ndarray) -> np.ndarray:
    """File/CLI poses (mm, degrees) to internal poses (mm, radians)."""
    poses = np.array(poses_deg, dtype=float)
    poses[..., 3:6] = np.deg2rad(poses[..., 3:6])
    return poses


def poses_to_file_units(poses_rad: np.ndarray) -> np.ndarray:
    """Internal poses (mm, radians) to file/CLI poses (mm, degrees)."""
    poses = np.array(poses_rad, dtype=float)
    poses[..., 3:6] = np.rad2deg(poses[..., 3:6])
    return poses


def rotation_vector_to_matrix(w: np.ndarray) -> np.ndarray:
    """``exp([w]×)`` for rotation vectors ``w`` of shape (..., 3) (Rodrigues)."""
    from scipy.spatial.transform import Rotation  # on first use: scipy.spatial takes ~0.4 s to import

    return Rotation.from_rotvec(np.asarray(w, dtype=float).reshape(-1, 3)).as_matrix().reshape(
        np.shape(w)[:-1] + (3, 3)
    )


def rotation_error(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Angle (radians) of the rotation ``R_a R_bᵀ`` that takes ``R_b`` to ``R_a``; shape (...)."""
    rel = np.einsum("...ij,...kj->...ik", R_a, R_b)
    cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    # arccos is ill-conditioned near 0: use the skew part for small angles.
    skew = np.stack(
        [rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0], rel[..., 1, 0] - rel[..., 0, 1]],
        axis=-1,
    )
    return np.arctan2(np.linalg.norm(skew, axis=-1) / 2.0, cos)


# -- numbers printed for people (issue 27 item 4) ---------------------------------------------

#: Below this (mm) a length is printed in µm.
MICROMETRE_BELOW_MM = 0.1
#: Below this (degrees) an angle is printed in arcseconds.
ARCSECOND_BELOW_DEG = 0.01


def length_text(mm: float, digits: int = 4) -> str:
    """A length for a person: ``digits`` significant digits, in mm, or in µm below
    :data:`MICROMETRE_BELOW_MM` (4.921 mm, 13.33 µm)."""
    mm = float(mm)
    if abs(mm) < MICROMETRE_BELOW_MM:
        return f"{_significant(mm * 1000.0, digits)} µm"
    return f"{_significant(mm, digits)} mm"


def angle_text(rad: float, digits: int = 4) -> str:
    """An angle for a person: ``digits`` significant digits, in degrees, or in arcseconds
    below :data:`ARCSECOND_BELOW_DEG` (1.557°, 20.5″)."""
    deg = float(np.degrees(rad))
    if abs(deg) < ARCSECOND_BELOW_DEG:
        return f"{_significant(deg * 3600.0, digits)}″"
    return f"{_significant(deg, digits)}°"


def values_text(values, unit: str, digits: int = 6) -> str:
    """Several values of one quantity for a person: ``305 mm (all 6)`` when they are equal,
    else ``305, 305.2, 304.9 mm`` (``digits`` significant digits, no NumPy repr)."""
    v = np.asarray(values, dtype=float).ravel()
    if v.size and np.all(v == v[0]):
        return f"{v[0]:.{digits}g} {unit}" + (f" (all {v.size})" if v.size > 1 else "")
    return ", ".join(f"{x:.{digits}g}" for x in v) + f" {unit}"


def _significant(value: float, digits: int) -> str:
    """``value`` with ``digits`` significant digits, fixed-point (no exponent), trailing
    zeros kept (4.900, not 4.9): the digits say the precision."""
    if value == 0 or not np.isfinite(value):
        return f"{value:.{digits - 1}f}" if value == 0 else str(value)
    decimals = max(0, digits - 1 - int(np.floor(np.log10(abs(value)))))
    text = f"{value:.{decimals}f}"
    # rounding can add a digit (9.9996 -> 10.000): drop the extra decimal
    if decimals > 0 and len(text.lstrip("-").replace(".", "").lstrip("0")) > digits:
        text = f"{value:.{decimals - 1}f}"
    return text

"""Small helpers shared by the sensor models: argument checks and vectorised 3-D algebra.

* :func:`as_poses`, :func:`check_params`, :func:`check_free`: validate what a caller gives a
  sensor (poses, parameter vectors θ, names of free parameters) with a message naming the
  sensor and the parameter.
* :func:`skew`: [v]× w = v × w.
* :func:`euler_rate_inverse`: E(a, b, c)⁻¹ of the pose convention
  (:func:`pkmcal.conventions.euler_rate_matrix`), d(a, b, c) = E⁻¹ δω (paper 1 §III, the
  orientation rows of the full-pose Jacobian).
"""

from __future__ import annotations

import numpy as np

from pkmcal.errors import PkmcalError


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [v]× (..., 3, 3) of vectors v (..., 3): [v]× w = v × w."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape + (3,))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def euler_rate_inverse(abc: np.ndarray) -> np.ndarray:
    """E(a, b, c)⁻¹ (..., 3, 3): d(a, b, c) = E⁻¹ δω. Singular at b = ±90° (gimbal lock)."""
    abc = np.asarray(abc, dtype=float)
    cb, sb = np.cos(abc[..., 1]), np.sin(abc[..., 1])
    cc, sc = np.cos(abc[..., 2]), np.sin(abc[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        Ei = np.zeros(abc.shape[:-1] + (3, 3))
        Ei[..., 0, 0] = cc / cb
        Ei[..., 0, 1] = sc / cb
        Ei[..., 1, 0] = -sc
        Ei[..., 1, 1] = cc
        Ei[..., 2, 0] = cc * sb / cb
        Ei[..., 2, 1] = sc * sb / cb
        Ei[..., 2, 2] = 1.0
    return Ei


def as_poses(poses: np.ndarray, who: str) -> np.ndarray:
    """``poses`` as a float array (N, 6); a single pose (6,) becomes (1, 6)."""
    poses = np.asarray(poses, dtype=float)
    if poses.ndim == 1:
        poses = poses[None, :]
    if poses.ndim != 2 or poses.shape[1] != 6:
        raise PkmcalError(f"{who} sensor needs poses (N, 6) = x, y, z, a, b, c; got shape {poses.shape}")
    return poses


def check_params(params: np.ndarray, names: tuple[str, ...], who: str) -> np.ndarray:
    """Parameter vector as a read-only float array of the right length."""
    arr = np.array(params, dtype=float).reshape(-1)
    if arr.shape != (len(names),):
        raise PkmcalError(f"{who} sensor has {len(names)} parameters ({', '.join(names)}); got {arr.size} values")
    if not np.all(np.isfinite(arr)):
        bad = names[int(np.argmax(~np.isfinite(arr)))]
        raise PkmcalError(f"{who} sensor parameter '{bad}' is not a finite number")
    arr.setflags(write=False)
    return arr


def check_free(free: tuple[str, ...] | None, names: tuple[str, ...], who: str) -> tuple[str, ...] | None:
    """Validate a list of free sensor-parameter names."""
    if free is None:
        return None
    free = tuple(free)
    unknown = [f for f in free if f not in names]
    if unknown:
        raise PkmcalError(
            f"{who} sensor has no parameter {', '.join(repr(u) for u in unknown)}; "
            f"its parameters are {', '.join(names) or '(none)'}"
        )
    return free

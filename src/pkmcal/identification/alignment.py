"""Best rigid alignment of two sets of frames: what a comparison of poses must remove when
the frames they are expressed in are a gauge choice.

A calibration determines the machine only up to its gauge: where the base and platform
frames sit is a choice (the parameters the automatic gauge fixes), whenever the sensor's
own frames are estimated too (a laser tracker with a free tracker frame and target point).
Two models then agree on everything a sensor can see while their platform poses differ by
fixed transforms on both sides. Poses T_r,j reached by the real machine are compared with
the commanded T_c,j after the best such pair,

    T_r,j ≈ A · T_c,j · B,   A = (R_A, t_A) on the base side, B = (R_B, t_B) on the platform side,

fitted by least squares (scipy.optimize.least_squares) on the residuals per pose

    p_r − (R_A (p_c + R_c t_B) + t_A)  (mm),   ℓ · log(R_r (R_A R_c R_B)ᵀ)  (rad × mm),

with ℓ the RMS distance of the commanded positions from their centroid (at least 1 mm): a
rotation error counts as the displacement it causes across the poses compared. The start
is Kabsch's alignment of the positions (:meth:`scipy.spatial.transform.Rotation.align_vectors`)
and the rotation average for R_B. With a single orientation among the poses, A and B are
not separable; the fit then returns one of the equivalent pairs (same residuals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import euler_to_matrix


@dataclass(frozen=True)
class RigidAlignment:
    """The transforms A (base side) and B (platform side): rotations (3, 3), translations
    (3,) mm; ``scale`` ℓ (mm) of the rotation residuals."""

    R_A: np.ndarray
    t_A: np.ndarray
    R_B: np.ndarray
    t_B: np.ndarray
    scale: float

    def apply(self, p_c: np.ndarray, R_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(p, R) of A · T_c · B for frames (p_c (N, 3), R_c (N, 3, 3))."""
        p = (p_c + np.einsum("nij,j->ni", R_c, self.t_B)) @ self.R_A.T + self.t_A
        return p, self.R_A @ R_c @ self.R_B

    def to_dict(self) -> dict:
        """Rotations as rotation vectors (deg), translations (mm)."""
        from scipy.spatial.transform import Rotation

        return {"base_rotation_vector_deg": [float(v) for v in Rotation.from_matrix(self.R_A).as_rotvec(degrees=True)],
                "base_translation_mm": [float(v) for v in self.t_A],
                "platform_rotation_vector_deg": [float(v) for v in
                                                 Rotation.from_matrix(self.R_B).as_rotvec(degrees=True)],
                "platform_translation_mm": [float(v) for v in self.t_B],
                "rotation_scale_mm": float(self.scale)}


IDENTITY = RigidAlignment(np.eye(3), np.zeros(3), np.eye(3), np.zeros(3), 1.0)


def _polar(M: np.ndarray) -> np.ndarray:
    """The rotation nearest to M (3, 3) (SVD, det +1)."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def align_frames(p_r: np.ndarray, R_r: np.ndarray, p_c: np.ndarray, R_c: np.ndarray) -> RigidAlignment:
    """The best :class:`RigidAlignment` of the commanded frames (p_c, R_c) onto the reached
    ones (p_r, R_r), (N, 3) and (N, 3, 3) each (module docstring)."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    p_r, p_c = np.asarray(p_r, dtype=float), np.asarray(p_c, dtype=float)
    n = len(p_r)
    if n == 0:
        return IDENTITY
    cr, cc = p_r.mean(axis=0), p_c.mean(axis=0)
    scale = max(1.0, float(np.sqrt(np.mean(np.sum((p_c - cc) ** 2, axis=1)))))
    if n >= 2 and np.linalg.matrix_rank(p_c - cc, tol=1e-9 * scale) >= 2:
        rot, _ = Rotation.align_vectors(p_r - cr, p_c - cc)
        R_A = rot.as_matrix()
    else:
        R_A = np.eye(3)
    R_B = _polar(np.einsum("nji,njk->ik", R_A @ R_c, R_r))
    x0 = np.concatenate([Rotation.from_matrix(R_A).as_rotvec(), cr - R_A @ cc,
                         Rotation.from_matrix(R_B).as_rotvec(), np.zeros(3)])

    def unpack(x):
        return Rotation.from_rotvec(x[0:3]).as_matrix(), x[3:6], Rotation.from_rotvec(x[6:9]).as_matrix(), x[9:12]

    def fun(x):
        RA, tA, RB, tB = unpack(x)
        a = RigidAlignment(RA, tA, RB, tB, scale)
        p, R = a.apply(p_c, R_c)
        rot_err = Rotation.from_matrix(R_r @ np.transpose(R, (0, 2, 1))).as_rotvec()
        return np.concatenate([(p_r - p).ravel(), scale * rot_err.ravel()])

    sol = least_squares(fun, x0, method="lm" if 6 * n >= 12 else "trf", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    RA, tA, RB, tB = unpack(sol.x)
    return RigidAlignment(RA, tA, RB, tB, scale)


def align_poses(reached: np.ndarray, commanded: np.ndarray) -> RigidAlignment:
    """:func:`align_frames` of poses x y z a b c (N, 6; mm, rad)."""
    return align_frames(reached[:, 0:3], euler_to_matrix(reached[:, 3:6]), commanded[:, 0:3],
                        euler_to_matrix(commanded[:, 3:6]))


__all__ = ["IDENTITY", "RigidAlignment", "align_frames", "align_poses"]

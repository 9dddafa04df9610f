"""Best rigid alignment of two sets of frames: what a comparison of poses must remove when
the frames they are expressed in are a gauge choice.

A calibration determines the machine only up to its gauge: where the base and platform
frames sit is a choice (the parameters the automatic gauge fixes), whenever the sensor's
own frames are estimated too (a laser tracker with a free tracker frame and target point).
Two models then agree on everything a sensor can see while their platform poses differ by
fixed transforms on both sides. Poses T_r,j reached by the real machine are compared with
the commanded T_c,j after the best such pair,

    T_r,j ≈ A · T_c,j · B,   A = (R_A, t_A) on the base side, B = (R_B, t_B) on the platform side,

fitted by least squares on the residuals per pose

    p_r − (R_A (p_c + R_c t_B) + t_A)  (mm),   ℓ · vee((E − Eᵀ)/2), E = R_r (R_A R_c R_B)ᵀ  (mm),

(the second is ℓ sin θ times the axis of the residual rotation E) with ℓ the RMS distance of the commanded positions from their centroid (at least 1 mm): a
rotation error counts as the displacement it causes across the poses compared. The start
is Kabsch's alignment of the positions (:meth:`scipy.spatial.transform.Rotation.align_vectors`)
and the rotation average for R_B; Gauss–Newton with the exact Jacobian then converges to
rounding. With a single orientation among the poses, A and B are not separable; the fit
then takes the minimum-norm step (one of the equivalent pairs, same residuals).
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


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]× (..., 3, 3) of vectors v (..., 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def _vee_skew(M: np.ndarray) -> np.ndarray:
    """vee((M − Mᵀ)/2) (..., 3): sin θ · axis for a rotation M."""
    return 0.5 * np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]],
                          axis=-1)


def _exp(w: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(w).as_matrix()


def _residual(a: RigidAlignment, p_r, R_r, p_c, R_c):
    """(e_p (N, 3), e_R (N, 3), u = R_A (p_c + R_c t_B) (N, 3), R0 = R_A R_c R_B, E = R_r R0ᵀ)."""
    u = (p_c + np.einsum("nij,j->ni", R_c, a.t_B)) @ a.R_A.T
    R0 = a.R_A @ R_c @ a.R_B
    E = R_r @ np.transpose(R0, (0, 2, 1))
    return p_r - u - a.t_A, a.scale * _vee_skew(E), u, R0, E


#: Gauss–Newton iterations of :func:`align_frames` (each ≈ 12 columns × 6N rows) and the
#: step (mm, or rad × the scale) below which it stops.
MAX_ITER, STEP_TOL = 100, 1e-13


def align_frames(p_r: np.ndarray, R_r: np.ndarray, p_c: np.ndarray, R_c: np.ndarray) -> RigidAlignment:
    """The best :class:`RigidAlignment` of the commanded frames (p_c, R_c) onto the reached
    ones (p_r, R_r), (N, 3) and (N, 3, 3) each (module docstring).

    Gauss–Newton on the rotation group with the exact Jacobian of the residual
    [e_p; ℓ · vee((E − Eᵀ)/2)], E = R_r (R_A R_c R_B)ᵀ (the sine of the angle, which equals
    the angle to third order), in the increments R_A ← exp([δa]×) R_A, R_B ← R_B exp([δb]×),
    t_A ← t_A + δt_A, t_B ← t_B + δt_B; the minimum-norm step where A and B are not
    separable. Converged to rounding, so that the same frames give the same alignment."""
    from scipy.spatial.transform import Rotation

    p_r, p_c = np.asarray(p_r, dtype=float), np.asarray(p_c, dtype=float)
    R_r, R_c = np.asarray(R_r, dtype=float), np.asarray(R_c, dtype=float)
    n = len(p_r)
    if n == 0:
        return IDENTITY
    cr, cc = p_r.mean(axis=0), p_c.mean(axis=0)
    scale = max(1.0, float(np.sqrt(np.mean(np.sum((p_c - cc) ** 2, axis=1)))))
    R_A = np.eye(3)
    if n >= 3 and np.linalg.matrix_rank(p_c - cc, tol=1e-9 * scale) >= 2:
        R_A = Rotation.align_vectors(p_r - cr, p_c - cc)[0].as_matrix()   # Kabsch on the positions
    R_B = _polar(np.einsum("nji,njk->ik", R_A @ R_c, R_r))
    a = RigidAlignment(R_A, cr - R_A @ cc, R_B, np.zeros(3), scale)
    basis = np.eye(3)
    for _ in range(MAX_ITER):
        e_p, e_R, u, R0, E = _residual(a, p_r, R_r, p_c, R_c)
        J = np.zeros((n, 6, 12))
        J[:, 0:3, 0:3] = _skew(u)                       # ∂e_p/∂δa
        J[:, 0:3, 3:6] = -np.eye(3)                     # ∂e_p/∂δt_A
        J[:, 0:3, 9:12] = -(a.R_A @ R_c)                # ∂e_p/∂δt_B
        # ∂E/∂ω_k = −E [e_k]×, ω = δa + R0 δb
        C = np.stack([scale * _vee_skew(-E @ _skew(basis[k])) for k in range(3)], axis=-1)
        J[:, 3:6, 0:3] = C
        J[:, 3:6, 6:9] = C @ R0
        r = np.concatenate([e_p, e_R], axis=1).reshape(-1)
        step = np.linalg.lstsq(J.reshape(-1, 12), -r, rcond=1e-12)[0]
        a = RigidAlignment(_exp(step[0:3]) @ a.R_A, a.t_A + step[3:6], a.R_B @ _exp(step[6:9]), a.t_B + step[9:12],
                           scale)
        if np.max(np.abs(step * np.r_[np.full(3, scale), np.ones(3), np.full(3, scale), np.ones(3)])) < \
                STEP_TOL * max(scale, 1.0):
            break
    return a


def align_poses(reached: np.ndarray, commanded: np.ndarray, mechanism=None) -> RigidAlignment:
    """:func:`align_frames` of the platform frames of poses (N, n) of ``mechanism`` (its
    :meth:`~pkmcal.mechanisms.base.Mechanism.frame`; None: poses x y z a b c, mm and rad)."""
    if mechanism is None:
        return align_frames(reached[:, 0:3], euler_to_matrix(reached[:, 3:6]), commanded[:, 0:3],
                            euler_to_matrix(commanded[:, 3:6]))
    f_r, f_c = mechanism.frame(reached), mechanism.frame(commanded)
    return align_frames(f_r.p, f_r.R, f_c.p, f_c.R)


def transport_poses(model, reference, poses: np.ndarray) -> tuple[np.ndarray, RigidAlignment]:
    """``(poses in model's frames, alignment)``: the poses (N, n) given in the frames of
    ``reference`` (the nominal machine) expressed in the frames of ``model`` (a calibration,
    whose gauge placed its base and platform frames elsewhere). Both models' FK at the
    reference's IK of the poses give the same machine seen in two frame pairs,
    T_ref ≈ A · T_model · B (:func:`align_frames` of the platform frames); the transported
    pose is that of the frame A⁻¹ T_ref B⁻¹, the pose the user means, in the model's frames
    (``model.poses_from_frame``; a machine that does not rotate, a delta, keeps R = I)."""
    from pkmcal.identification.heldout import held_out_fk
    from pkmcal.mechanisms.frame import Frame

    poses = np.asarray(poses, dtype=float)
    with np.errstate(all="ignore"):
        q = reference.ik(poses)
    good = np.all(np.isfinite(q), axis=1)
    x_m, ok, _ = held_out_fk(model, np.where(good[:, None], q, 0.0), poses.copy(), reference)
    ok &= good
    if not ok.any():
        return poses, IDENTITY
    a = align_poses(poses[ok], x_m[ok], model)
    f = model.frame(poses)
    R = a.R_A.T @ f.R @ a.R_B.T
    p = (f.p - a.t_A) @ a.R_A - R @ a.t_B
    return model.poses_from_frame(Frame(p, R)), a


__all__ = ["IDENTITY", "RigidAlignment", "align_frames", "align_poses", "transport_poses"]

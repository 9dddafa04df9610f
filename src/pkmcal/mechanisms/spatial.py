"""The frame part of the contract for a platform with six pose coordinates in the pose
convention of :mod:`pkmcal.conventions` (x, y, z, a, b, c; R = Rz(c) Ry(b) Rx(a)): the
platform frame is the pose itself, T = ∂(δp, δω)/∂pose = diag(I, E(a, b, c)) with
E = :func:`~pkmcal.conventions.euler_rate_matrix`, independent of ρ."""

from __future__ import annotations

import numpy as np

from pkmcal.conventions import POSE_COLUMNS, euler_pose_jacobian, euler_rate_matrix, matrix_to_euler
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.frame import Frame


class SpatialPlatform(Mechanism):
    """Pose names, the ``"pose-convention"`` ability and the frame methods of a six-pose
    platform (module docstring); the kinematics are the subclass's."""

    pose_names = POSE_COLUMNS
    pose_is_angle = (False, False, False, True, True, True)
    abilities = frozenset({"pose-convention"})

    def frame(self, poses: np.ndarray, params: np.ndarray | None = None) -> Frame:
        """The platform frame of each pose: p = (x, y, z), R = Rz(c) Ry(b) Rx(a)."""
        return Frame.from_poses(self.as_pose_array(poses))

    def frame_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None) -> tuple[np.ndarray, None]:
        """``(T, None)``: T = diag(I, E(a, b, c)) (N, 6, 6); the frame does not depend on ρ."""
        poses = self.as_pose_array(poses)
        T = np.zeros((poses.shape[0], 6, 6))
        T[:, 0:3, 0:3] = np.eye(3)
        T[:, 3:6, 3:6] = euler_rate_matrix(poses[:, 3:6])
        return T, None

    def pose_jacobian_from_twist(self, J_twist: np.ndarray, poses: np.ndarray,
                                 params: np.ndarray | None = None) -> np.ndarray:
        """J_twist · diag(I, E) written out (:func:`~pkmcal.conventions.euler_pose_jacobian`)."""
        return euler_pose_jacobian(J_twist, self.as_pose_array(poses))

    def poses_from_frame(self, frame: Frame) -> np.ndarray:
        """(x, y, z, a, b, c) of frames: p and the Euler angles of R (|b| ≤ 90°)."""
        return np.concatenate([frame.p, matrix_to_euler(frame.R)], axis=1)


def leg_closure(joints, a: np.ndarray, lengths: np.ndarray):
    """The loop-closure equations of a six-legged platform whose legs of ``lengths`` (6,)
    join the platform joints ``a`` (6, 3, platform frame) to base-side joints that the
    readings place, ``joints(λ)`` → (M, 6, 3) (a crank's end, a carriage), for
    :func:`~pkmcal.mechanisms.solver.solve_fk`:

        e_i(x) = (ℓ_i² − |w_i|²) / (2 ℓ_i),   w_i = p + R a_i − joint_i   (≈ ℓ_i − |w_i|, mm),
        −∂e_i/∂(δp, δω) = [w_i, (R a_i) × w_i] / ℓ_i   (× T for the pose),

    finite at every pose, where IK is NaN outside a leg's reach."""
    r = lengths[None, :]

    def equations(poses: np.ndarray, readings: np.ndarray, jac: bool):
        fr = Frame.from_poses(poses)
        Ra = np.einsum("nij,kj->nki", fr.R, a)
        w = poses[:, None, 0:3] + Ra - joints(readings)
        e = (r**2 - np.einsum("nkj,nkj->nk", w, w)) / (2.0 * r)
        if not jac:
            return e, None
        twist = np.concatenate([w, np.cross(Ra, w)], axis=2) / r[..., None]
        return e, euler_pose_jacobian(twist, poses)

    return equations


def twist_signs(w: np.ndarray, Ra: np.ndarray) -> np.ndarray:
    """sign det (N,) of the twist Jacobian with rows [w_i, (R a_i) × w_i] (N, 6, 6), 0 where
    it is not finite or singular: the platform's assembly mode for legs whose constraint
    gradient at the platform joint R a_i is w_i."""
    J = np.concatenate([w, np.cross(Ra, w)], axis=2)
    good = np.all(np.isfinite(J), axis=(1, 2))
    det = np.zeros(len(J))
    det[good] = np.linalg.det(J[good])
    return np.sign(det)


__all__ = ["SpatialPlatform", "twist_signs"]

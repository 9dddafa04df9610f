"""Mechanisms whose platform only translates (the deltas: parallelograms keep the effector
level): the pose is the tool point p = (x, y, z) in the base frame, and the platform frame
is (p, I). Its twist Jacobian T = ∂(δp, δω)/∂(x, y, z) is [I; 0], independent of ρ, so a
sensor's twist Jacobian pulls back to the pose by keeping its δp columns."""

from __future__ import annotations

import numpy as np

from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.frame import Frame


class TranslatingMechanism(Mechanism):
    """The frame part of the contract for a platform that does not rotate."""

    abilities = frozenset({"translating"})

    def frame(self, poses: np.ndarray, params: np.ndarray | None = None) -> Frame:
        """(p, I) of poses (N, 3)."""
        p = self.as_pose_array(poses)
        return Frame(p=p.copy(), R=np.broadcast_to(np.eye(3), (p.shape[0], 3, 3)).copy())

    def frame_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None) -> tuple[np.ndarray, None]:
        """``(T, None)``: T (N, 6, 3) = [I; 0]; the frame does not depend on ρ."""
        n = self.as_pose_array(poses).shape[0]
        T = np.zeros((n, 6, 3))
        T[:, [0, 1, 2], [0, 1, 2]] = 1.0
        return T, None

    def pose_jacobian_from_twist(self, J_twist: np.ndarray, poses: np.ndarray,
                                 params: np.ndarray | None = None) -> np.ndarray:
        """J_twist · T: the δp columns of the twist Jacobian."""
        return J_twist[..., 0:3]

    def poses_from_frame(self, frame: Frame) -> np.ndarray:
        """The frames' positions (their rotations are the identity for this machine)."""
        return np.array(frame.p, dtype=float)


__all__ = ["TranslatingMechanism"]

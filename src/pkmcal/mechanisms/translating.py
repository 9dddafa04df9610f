"""Mechanisms whose platform only translates (the deltas: parallelograms keep the effector
level): the pose is the tool point p = (x, y, z) in the base frame, and the platform frame
is (p, I). Its twist Jacobian T = ∂(δp, δω)/∂(x, y, z) is [I; 0], independent of ρ, so a
sensor's twist Jacobian pulls back to the pose by keeping its δp columns.

:class:`TranslatingMechanism` also holds what the deltas share besides: three actuators
``lambda1..3``, and a named parameter vector ``rho``
(:class:`~pkmcal.mechanisms.param_vector.ParameterVector`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.frame import Frame
from pkmcal.mechanisms.param_vector import ParameterVector


@dataclass(frozen=True)
class ArmLayout:
    """The parameter vector ρ of a delta: the same named parameters for each of its three
    arms (towers) ``a, b, c`` in turn, ``<parameter>_<arm>``, then the tool offset
    ``tool.x, tool.y, tool.z`` (mm). ``angles``: the per-arm parameters that are angles."""

    params: tuple[str, ...]
    angles: frozenset[str]
    arms: tuple[str, ...] = ("a", "b", "c")
    tool: tuple[str, ...] = ("tool.x", "tool.y", "tool.z")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f"{p}_{a}" for a in self.arms for p in self.params) + self.tool

    @property
    def is_angle(self) -> tuple[bool, ...]:
        return tuple(p in self.angles for _ in self.arms for p in self.params) + (False,) * len(self.tool)

    def position(self, param: str, arm: int) -> int:
        """Index in ρ of ``param`` of arm number ``arm`` (0, 1, 2)."""
        return arm * len(self.params) + self.params.index(param)

    def split(self, rho: np.ndarray) -> dict[str, np.ndarray]:
        """Per-arm arrays (3,) of every per-arm parameter, and ``"tool"`` (3,)."""
        per_arm = np.asarray(rho)[: len(self.arms) * len(self.params)].reshape(len(self.arms), len(self.params))
        out = {p: per_arm[:, k] for k, p in enumerate(self.params)}
        out["tool"] = np.asarray(rho)[-len(self.tool):]
        return out


class TranslatingMechanism(ParameterVector, Mechanism):
    """The frame part of the contract for a platform that does not rotate, and the
    parameter vector of a dataclass subclass with fields ``name``, ``rho``, ``covariance``."""

    abilities = frozenset({"translating"})
    pose_names = ("x", "y", "z")
    pose_is_angle = (False, False, False)
    actuator_names = ("lambda1", "lambda2", "lambda3")
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


__all__ = ["ArmLayout", "TranslatingMechanism"]

"""Position sensor: a 3D laser tracker reads one target point (a reflector) on the platform.

Model (the position rows of paper 1's full-pose model, §II). The target sits at t in the
platform frame {P} (params ``target.x, target.y, target.z``, free by default since its
mounting is rarely known to the micrometre); the tracker reads in its world frame {W},
in which the base frame {F} sits at (p_w, R_w) (params ``world.x … world.c``, identity
and held by default):

    y = p_w + R_w (p + R t)                                                     (readings px, py, pz)

    ∂y/∂p = R_w,   ∂y/∂δω = −R_w [R t]×,   ∂y/∂t = R_w R,
    ∂y/∂p_w = I,   ∂y/∂(world abc) = −[R_w (p + R t)]× E(world abc)

with the Euler pose Jacobian the twist one times diag(I, E(a, b, c)).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pkmcal.conventions import euler_pose_jacobian, euler_rate_matrix, euler_to_matrix
from pkmcal.sensors.base import Sensor
from pkmcal.sensors.full_pose import (
    WORLD_PARAM_NAMES,
    as_poses,
    check_free,
    check_params,
    skew,
)

TARGET_PARAM_NAMES = ("target.x", "target.y", "target.z")


@dataclass(frozen=True, eq=False)
class PositionSensor(Sensor):
    """Position of one target point on the platform, read in the world frame.

    Parameters
    ----------
    target : (3,) target point in the platform frame {P}, mm; default the origin of {P}.
    world : (6,) pose of the base frame {F} in the tracker frame {W} (mm, rad); default identity.
    free : sensor parameters estimated by the identification (default: the target offset).
    """

    target: np.ndarray = None  # type: ignore[assignment]
    world: np.ndarray = None  # type: ignore[assignment]
    free: tuple[str, ...] | None = None

    kind = "position"

    def __post_init__(self) -> None:
        t = np.zeros(3) if self.target is None else self.target
        w = np.zeros(6) if self.world is None else self.world
        object.__setattr__(self, "target", check_params(t, TARGET_PARAM_NAMES, self.kind))
        object.__setattr__(self, "world", check_params(w, WORLD_PARAM_NAMES, self.kind))
        object.__setattr__(self, "free", check_free(self.free, self.param_names, self.kind))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PositionSensor):
            return NotImplemented
        return bool(np.array_equal(self.params, other.params) and self.free == other.free)

    __hash__ = None  # type: ignore[assignment]

    @property
    def reading_names(self) -> tuple[str, ...]:
        return ("px", "py", "pz")

    @property
    def param_names(self) -> tuple[str, ...]:
        return TARGET_PARAM_NAMES + WORLD_PARAM_NAMES

    @property
    def params(self) -> np.ndarray:
        return np.concatenate([self.target, self.world])

    @property
    def default_free(self) -> tuple[str, ...]:
        return TARGET_PARAM_NAMES if self.free is None else self.free

    def with_params(self, params: np.ndarray) -> "PositionSensor":
        theta = check_params(params, self.param_names, self.kind)
        return replace(self, target=theta[:3], world=theta[3:])

    def _frames(self, poses):
        poses = as_poses(poses, self.kind)
        R = euler_to_matrix(poses[:, 3:6])
        Rw = euler_to_matrix(self.world[3:6])
        Rt = R @ self.target                                          # R t (N, 3)
        v = poses[:, 0:3] + Rt
        return poses, R, Rw, Rt, v

    def predict(self, poses: np.ndarray) -> np.ndarray:
        """Readings (N, 3): the target point in {W}, mm."""
        _, _, Rw, _, v = self._frames(poses)
        return self.world[0:3] + v @ Rw.T

    def pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂(x, y, z, a, b, c) (N, 3, 6)."""
        poses, _, Rw, Rt, _ = self._frames(poses)
        Jt = np.concatenate([np.broadcast_to(Rw, (poses.shape[0], 3, 3)), -Rw @ skew(Rt)], axis=2)
        return euler_pose_jacobian(Jt, poses)

    def param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂θ (N, 3, 9), θ = target.x, target.y, target.z, world.x … world.c."""
        poses, R, Rw, _, v = self._frames(poses)
        n = poses.shape[0]
        J = np.zeros((n, 3, 9))
        J[:, :, 0:3] = Rw @ R
        J[:, :, 3:6] = np.eye(3)
        J[:, :, 6:9] = -skew(v @ Rw.T) @ euler_rate_matrix(self.world[3:6])
        return J

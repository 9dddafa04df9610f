"""Full-pose sensor: a laser tracker in 6D mode or a CMM reads the pose of a target frame.

Model (paper 1 §II–III, where x̂_j is the measured pose). The platform frame {P} is at pose
(p, R) in the base frame {F}; the target frame {T} sits on the platform at (p_t, R_t) in
{P} (params ``tool.x … tool.c``); the sensor reads in its world frame {W}, in which the
base frame sits at (p_w, R_w) (params ``world.x … world.c``, i.e. the pose of {F} in {W}).
Both transforms use the pose convention of :mod:`pkmcal.conventions`; identity by default.

    y_pos = p_w + R_w (p + R p_t),     R_T = R_w R R_t,     y_ang = euler(R_T)

Derivatives (δω a small base-frame rotation, E = :func:`~pkmcal.conventions.euler_rate_matrix`,
[v]× the cross-product matrix):

    ∂y_pos/∂p = R_w,     ∂y_pos/∂δω = −R_w [R p_t]×,     ∂y_ang/∂δω = E(y_ang)⁻¹ R_w
    ∂y_pos/∂p_w = I,     ∂y_pos/∂(world abc) = −[R_w (p + R p_t)]× E_w,  ∂y_ang/∂(world abc) = E(y_ang)⁻¹ E_w
    ∂y_pos/∂p_t = R_w R, ∂y_ang/∂(tool abc) = E(y_ang)⁻¹ R_w R E_t

and the pose (Euler) Jacobian is the twist one times diag(I, E(a, b, c)). The position rows
are the chain of :mod:`pkmcal.sensors._frames` with the point t = p_t, shared with
:class:`~pkmcal.sensors.position.PositionSensor`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import POSE_COLUMNS, euler_pose_jacobian, euler_rate_matrix, euler_to_matrix, matrix_to_euler
from pkmcal.sensors._common import euler_rate_inverse
from pkmcal.sensors._frames import TRANSFORM_IS_ANGLE, WORLD_GROUP, PointChain
from pkmcal.sensors.base import ParamGroup, Sensor

TOOL_PARAM_NAMES = tuple(f"tool.{c}" for c in POSE_COLUMNS)
_GROUPS = (WORLD_GROUP, ParamGroup("tool", TOOL_PARAM_NAMES, TRANSFORM_IS_ANGLE))


@dataclass(frozen=True, eq=False)
class FullPoseSensor(Sensor):
    """Measured x, y, z, a, b, c of a target frame (laser tracker 6D, CMM); see module doc.

    Parameters
    ----------
    world : (6,) pose of the base frame {F} in the sensor frame {W} (mm, rad); default identity.
    tool : (6,) pose of the target frame {T} in the platform frame {P}; default identity.
    free : sensor parameters estimated by the identification (default: none).
    """

    world: np.ndarray = None  # type: ignore[assignment]
    tool: np.ndarray = None  # type: ignore[assignment]
    free: tuple[str, ...] | None = None

    kind = "full-pose"

    def __post_init__(self) -> None:
        self._init_params()
        # the constant parts of the chain, once per sensor (not per pose batch)
        object.__setattr__(self, "_chain", PointChain(self.world, self.tool[0:3], self.kind))
        object.__setattr__(self, "_Rt", euler_to_matrix(self.tool[3:6]))
        object.__setattr__(self, "_identity", not (np.any(self.world) or np.any(self.tool)))

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        return _GROUPS

    @property
    def is_identity(self) -> bool:
        """No world or tool transform: the readings are the platform pose (|b| < 90°)."""
        return self._identity

    @property
    def reading_names(self) -> tuple[str, ...]:
        return POSE_COLUMNS

    @property
    def reading_is_angle(self) -> tuple[bool, ...]:
        return TRANSFORM_IS_ANGLE

    def _frames(self, poses) -> dict:
        """The chain's batch dict plus ``ang``, the Euler angles of R_T = R_w R R_t."""
        fr = self._chain.frames(poses)
        if "ang" not in fr:
            fr["ang"] = matrix_to_euler(self._chain.RwR(fr) @ self._Rt)
        return fr

    def _Ei(self, fr: dict) -> np.ndarray:
        """E(y_ang)⁻¹ of the frames ``fr`` (computed once per pose batch)."""
        if "Ei" not in fr:
            fr["Ei"] = euler_rate_inverse(fr["ang"])
        return fr["Ei"]

    def predict(self, poses: np.ndarray) -> np.ndarray:
        """Readings (N, 6): target position (mm) and Euler angles (rad) in {W}."""
        fr = self._frames(poses)
        out = np.empty((fr["poses"].shape[0], 6))
        out[:, 0:3] = self._chain.position(fr)
        out[:, 3:6] = fr["ang"]
        return out

    def pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂(x, y, z, a, b, c) (N, 6, 6) (module docstring)."""
        fr = self._frames(poses)
        Jt = np.zeros((fr["poses"].shape[0], 6, 6))
        self._chain.twist_jacobian(fr, Jt[:, 0:3, :])
        Jt[:, 3:6, 3:6] = self._Ei(fr) @ self._chain.Rw
        return euler_pose_jacobian(Jt, fr["poses"])

    def param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂θ (N, 6, 12), θ = world.x … world.c, tool.x … tool.c (module docstring)."""
        fr = self._frames(poses)
        Ei, RwR = self._Ei(fr), self._chain.RwR(fr)
        J = np.zeros((fr["poses"].shape[0], 6, 12))
        self._chain.world_jacobian(fr, J[:, 0:3, 0:6])
        J[:, 3:6, 3:6] = Ei @ self._chain.Ew
        J[:, 0:3, 6:9] = RwR
        J[:, 3:6, 9:12] = Ei @ (RwR @ euler_rate_matrix(self.tool[3:6]))
        return J

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

(the twist Jacobian; the engine composes it with the mechanism's T). The readings determine
the frame (:meth:`FullPoseSensor.invert`, closed form). The position rows
are the chain of :mod:`pkmcal.sensors._frames` with the point t = p_t, shared with
:class:`~pkmcal.sensors.position.PositionSensor`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import POSE_COLUMNS, euler_rate_matrix, euler_to_matrix, matrix_to_euler
from pkmcal.mechanisms.frame import Frame
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
    invertible = True

    def __post_init__(self) -> None:
        self._init_params()
        # the constant parts of the chain, once per sensor (not per pose batch)
        object.__setattr__(self, "_chain", PointChain(self.world, self.tool[0:3], self.kind))
        object.__setattr__(self, "_Rt", euler_to_matrix(self.tool[3:6]))

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        return _GROUPS

    @property
    def reading_names(self) -> tuple[str, ...]:
        return POSE_COLUMNS

    @property
    def reading_is_angle(self) -> tuple[bool, ...]:
        return TRANSFORM_IS_ANGLE

    def reads_pose(self, params: np.ndarray | None = None) -> bool:
        """No world or tool transform at θ: the readings are the platform frame's pose (|b| < 90°)."""
        theta = self._theta(params)
        return not (np.any(self.world) or np.any(self.tool)) if theta is None else not np.any(theta)

    def _parts(self, params) -> tuple[PointChain, np.ndarray, np.ndarray]:
        """(chain, R_t, tool (6,)) of θ = ``params`` (this sensor's own for None)."""
        theta = self._theta(params)
        if theta is None:
            return self._chain, self._Rt, self.tool
        return PointChain(theta[0:6], theta[6:9], self.kind), euler_to_matrix(theta[9:12]), theta[6:12]

    def _at(self, frame: Frame, chain: PointChain, Rt: np.ndarray) -> dict:
        """The chain's batch dict plus ``ang``, the Euler angles of R_T = R_w R R_t."""
        fr = chain.at(frame)
        fr["ang"] = matrix_to_euler(chain.RwR(fr) @ Rt)
        return fr

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings (N, 6): target position (mm) and Euler angles (rad) in {W}."""
        chain, Rt, _ = self._parts(params)
        fr = self._at(frame, chain, Rt)
        out = np.empty((len(frame), 6))
        out[:, 0:3] = chain.position(fr)
        out[:, 3:6] = fr["ang"]
        return out

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(δp, δω) (N, 6, 6) (module docstring)."""
        chain, Rt, _ = self._parts(params)
        fr = self._at(frame, chain, Rt)
        Jt = np.zeros((len(frame), 6, 6))
        chain.twist_jacobian(fr, Jt[:, 0:3, :])
        Jt[:, 3:6, 3:6] = euler_rate_inverse(fr["ang"]) @ chain.Rw
        return Jt

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂θ (N, 6, 12), θ = world.x … world.c, tool.x … tool.c (module docstring)."""
        chain, Rt, tool = self._parts(params)
        fr = self._at(frame, chain, Rt)
        Ei, RwR = euler_rate_inverse(fr["ang"]), chain.RwR(fr)
        J = np.zeros((len(frame), 6, 12))
        chain.world_jacobian(fr, J[:, 0:3, 0:6])
        J[:, 3:6, 3:6] = Ei @ chain.Ew
        J[:, 0:3, 6:9] = RwR
        J[:, 3:6, 9:12] = Ei @ (RwR @ euler_rate_matrix(tool[3:6]))
        return J

    def invert(self, readings: np.ndarray, params: np.ndarray | None = None) -> Frame:
        """The platform frames of readings (N, 6), closed form (paper 1's measured pose x̂):
        R = R_wᵀ R_T R_tᵀ with R_T = R(y_a, y_b, y_c), p = R_wᵀ (y_pos − p_w) − R p_t."""
        chain, Rt, tool = self._parts(params)
        y = np.atleast_2d(np.asarray(readings, dtype=float))
        R = chain.Rw.T @ euler_to_matrix(y[:, 3:6]) @ Rt.T
        p = (y[:, 0:3] - chain.world[0:3]) @ chain.Rw - R @ tool[0:3]
        return Frame(p=p, R=R)

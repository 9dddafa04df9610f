"""Position sensor: a 3D laser tracker reads one target point (a reflector) on the platform.

Model (the position rows of paper 1's full-pose model, §II). The target sits at t in the
platform frame {P} (params ``target.x, target.y, target.z``, free by default since its
mounting is rarely known to the micrometre); the tracker reads in its world frame {W},
in which the base frame {F} sits at (p_w, R_w) (params ``world.x … world.c``, identity
and held by default):

    y = p_w + R_w (p + R t)                                                     (readings px, py, pz)

    ∂y/∂p = R_w,   ∂y/∂δω = −R_w [R t]×,   ∂y/∂t = R_w R,
    ∂y/∂p_w = I,   ∂y/∂(world abc) = −[R_w (p + R t)]× E(world abc)

(the twist Jacobian; the engine composes it with the mechanism's T). This is the chain of
:mod:`pkmcal.sensors._frames` with the point t = target, the position rows of
:class:`~pkmcal.sensors.full_pose.FullPoseSensor` whose tool origin is the target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors._frames import WORLD_GROUP, PointChain
from pkmcal.sensors.base import ParamGroup, Sensor

TARGET_PARAM_NAMES = ("target.x", "target.y", "target.z")
_GROUPS = (ParamGroup("target", TARGET_PARAM_NAMES, (False, False, False)), WORLD_GROUP)


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
    free_when_unset = TARGET_PARAM_NAMES

    def __post_init__(self) -> None:
        self._init_params()
        object.__setattr__(self, "_chain", PointChain(self.world, self.target, self.kind))

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        return _GROUPS

    @property
    def reading_names(self) -> tuple[str, ...]:
        return ("px", "py", "pz")

    def _chain_of(self, params) -> PointChain:
        """The chain of θ = ``params`` (this sensor's own for None)."""
        theta = self._theta(params)
        return self._chain if theta is None else PointChain(theta[3:9], theta[0:3], self.kind)

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings (N, 3): the target point in {W}, mm."""
        chain = self._chain_of(params)
        return chain.position(chain.at(frame))

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(δp, δω) (N, 3, 6)."""
        chain = self._chain_of(params)
        Jt = np.empty((len(frame), 3, 6))
        chain.twist_jacobian(chain.at(frame), Jt)
        return Jt

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂θ (N, 3, 9), θ = target.x, target.y, target.z, world.x … world.c."""
        chain = self._chain_of(params)
        fr = chain.at(frame)
        J = np.empty((len(frame), 3, 9))
        J[:, :, 0:3] = chain.RwR(fr)
        chain.world_jacobian(fr, J[:, :, 3:9])
        return J

"""The frame chain shared by the full-pose and position sensors: world ← base ← platform ← point.

Paper 1 §II. The platform frame {P} is at pose (p, R) in the base frame {F}; a point t is
fixed in {P} (the full-pose sensor's tool origin p_t, the position sensor's target); the
sensor reads in its world frame {W}, in which {F} sits at (p_w, R_w) (params
``world.x … world.c``, the pose of {F} in {W}, pose convention of :mod:`pkmcal.conventions`):

    y_pos = p_w + R_w v,      v = p + R t                                        (point in {W})

    ∂y_pos/∂p = R_w,     ∂y_pos/∂δω = −R_w [R t]×,     ∂y_pos/∂t = R_w R,
    ∂y_pos/∂p_w = I,     ∂y_pos/∂(world abc) = −[R_w v]× E(world abc)

(δω a small base-frame rotation of the platform, E = :func:`~pkmcal.conventions.euler_rate_matrix`).
:class:`PointChain` computes these for a batch of frames for both sensors.
"""

from __future__ import annotations

import numpy as np

from pkmcal.conventions import POSE_COLUMNS, euler_rate_matrix, euler_to_matrix
from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors._common import skew
from pkmcal.sensors.base import ParamGroup

#: Angle flags of a transform (x, y, z, a, b, c): the last three are angles.
TRANSFORM_IS_ANGLE = (False, False, False, True, True, True)
WORLD_PARAM_NAMES = tuple(f"world.{c}" for c in POSE_COLUMNS)
#: θ group of the pose of the base frame {F} in the sensor frame {W}.
WORLD_GROUP = ParamGroup("world", WORLD_PARAM_NAMES, TRANSFORM_IS_ANGLE)


class PointChain:
    """y_pos = p_w + R_w (p + R t) and its derivatives (module docstring) for one sensor's
    ``world`` (6,) and point ``t`` (3,); :meth:`at` computes the quantities of one batch of
    frames, which the caller passes to the other methods (no state is kept between calls)."""

    __slots__ = ("world", "point", "Rw", "Ew", "who")

    def __init__(self, world: np.ndarray, point: np.ndarray, who: str) -> None:
        self.world = world
        self.point = point
        self.who = who
        self.Rw = euler_to_matrix(world[3:6])      # R_w and E(world abc): once per sensor,
        self.Ew = euler_rate_matrix(world[3:6])    # not per pose batch

    def at(self, frame: Frame) -> dict:
        """The batch dict of ``frame``: ``R`` (N, 3, 3), ``Rt`` = R t and ``v`` = p + R t (N, 3)."""
        R = frame.R
        Rt = R @ self.point
        return {"R": R, "Rt": Rt, "v": frame.p + Rt}

    def RwR(self, fr: dict) -> np.ndarray:
        """R_w R (N, 3, 3) = ∂y_pos/∂t (once per batch)."""
        if "RwR" not in fr:
            fr["RwR"] = self.Rw @ fr["R"]
        return fr["RwR"]

    def position(self, fr: dict) -> np.ndarray:
        """y_pos (N, 3), mm."""
        return self.world[0:3] + fr["v"] @ self.Rw.T

    def twist_jacobian(self, fr: dict, out: np.ndarray) -> None:
        """Write ∂y_pos/∂(p, δω) into ``out`` (N, 3, 6)."""
        out[:, :, 0:3] = self.Rw
        out[:, :, 3:6] = -self.Rw @ skew(fr["Rt"])

    def world_jacobian(self, fr: dict, out: np.ndarray) -> None:
        """Write ∂y_pos/∂(world.x … world.c) into ``out`` (N, 3, 6)."""
        out[:, :, 0:3] = np.eye(3)
        out[:, :, 3:6] = -skew(fr["v"] @ self.Rw.T) @ self.Ew

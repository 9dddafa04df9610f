"""The frame chain shared by the full-pose and position sensors: world ← base ← platform ← point.

Paper 1 §II. The platform frame {P} is at pose (p, R) in the base frame {F}; a point t is
fixed in {P} (the full-pose sensor's tool origin p_t, the position sensor's target); the
sensor reads in its world frame {W}, in which {F} sits at (p_w, R_w) (params
``world.x … world.c``, the pose of {F} in {W}, pose convention of :mod:`pkmcal.conventions`):

    y_pos = p_w + R_w v,      v = p + R t                                        (point in {W})

    ∂y_pos/∂p = R_w,     ∂y_pos/∂δω = −R_w [R t]×,     ∂y_pos/∂t = R_w R,
    ∂y_pos/∂p_w = I,     ∂y_pos/∂(world abc) = −[R_w v]× E(world abc)

(δω a small base-frame rotation of the platform, E = :func:`~pkmcal.conventions.euler_rate_matrix`).
:class:`PointChain` computes these once per pose batch for both sensors.
"""

from __future__ import annotations

import numpy as np

from pkmcal.conventions import POSE_COLUMNS, euler_rate_matrix, euler_to_matrix
from pkmcal.sensors._common import as_poses, skew
from pkmcal.sensors.base import ParamGroup

#: Angle flags of a transform (x, y, z, a, b, c): the last three are angles.
TRANSFORM_IS_ANGLE = (False, False, False, True, True, True)
WORLD_PARAM_NAMES = tuple(f"world.{c}" for c in POSE_COLUMNS)
#: θ group of the pose of the base frame {F} in the sensor frame {W}.
WORLD_GROUP = ParamGroup("world", WORLD_PARAM_NAMES, TRANSFORM_IS_ANGLE)


class PointChain:
    """y_pos = p_w + R_w (p + R t) and its derivatives (module docstring) for one sensor's
    ``world`` (6,) and point ``t`` (3,). The frames of the last pose batch are kept, since a
    fit asks for the readings, ∂y/∂x and ∂y/∂θ at the same poses; a sensor may store more
    quantities of that batch in the same dict (see :meth:`frames`)."""

    __slots__ = ("world", "point", "Rw", "Ew", "who", "_last")

    def __init__(self, world: np.ndarray, point: np.ndarray, who: str) -> None:
        self.world = world
        self.point = point
        self.who = who
        self.Rw = euler_to_matrix(world[3:6])      # R_w and E(world abc): once per sensor,
        self.Ew = euler_rate_matrix(world[3:6])    # not per pose batch
        self._last: tuple[bytes, dict] | None = None

    def frames(self, poses) -> dict:
        """The batch dict: ``poses`` (N, 6, a private copy), ``R`` (N, 3, 3), ``Rt`` = R t and
        ``v`` = p + R t (N, 3); the same dict again for the same poses."""
        poses = as_poses(poses, self.who)
        key = poses.tobytes()
        last = self._last
        if last is not None and last[0] == key:
            return last[1]
        poses = poses.copy()                                         # the cache owns its poses
        R = euler_to_matrix(poses[:, 3:6])
        Rt = R @ self.point
        fr = {"poses": poses, "R": R, "Rt": Rt, "v": poses[:, 0:3] + Rt}
        self._last = (key, fr)
        return fr

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

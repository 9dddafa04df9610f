"""The platform frame: what a sensor sees of a machine, whatever its pose coordinates.

A mechanism maps its pose coordinates x (a hexapod's x, y, z, a, b, c; a planar machine's
x, y or x, y, φ) to the pose of its platform frame {P} in the base frame {F}: a position
p (mm) and a rotation R, here for N poses at once. Sensors read a :class:`Frame`, never
pose coordinates, so any sensor works with any mechanism where it makes sense.

Small changes of a frame are twists (δp, δω), δω a rotation vector in the base frame:

    p ← p + δp,      R ← exp([δω]×) R                      (:mod:`pkmcal.conventions`)

A sensor gives ∂y/∂(δp, δω) (N, m, 6); a mechanism gives T = ∂(δp, δω)/∂x (N, 6, n), and the
engine composes H = ∂y/∂x = (∂y/∂twist) · T (:meth:`Mechanism.frame_jacobians`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import euler_to_matrix


@dataclass(frozen=True, eq=False)
class Frame:
    """N platform frames in the base frame: ``p`` (N, 3) mm, ``R`` (N, 3, 3) rotations."""

    p: np.ndarray
    R: np.ndarray

    @classmethod
    def from_poses(cls, poses: np.ndarray) -> Frame:
        """The frames of poses (N, 6) x, y, z, a, b, c in the pose convention of
        :mod:`pkmcal.conventions` (p = (x, y, z), R = Rz(c) Ry(b) Rx(a)); a single pose
        (6,) gives one frame."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim == 1:
            poses = poses[None, :]
        return cls(p=poses[:, 0:3], R=euler_to_matrix(poses[:, 3:6]))

    def __len__(self) -> int:
        return int(self.p.shape[0])

    def __getitem__(self, index) -> Frame:
        """The frames ``index`` (an index array, boolean mask or slice) as a Frame."""
        return Frame(p=self.p[index], R=self.R[index])

    def moved(self, twist: np.ndarray) -> Frame:
        """The frames displaced by twists (N, 6) or (6,) = (δp, δω): p + δp, exp([δω]×) R."""
        from pkmcal.conventions import rotation_vector_to_matrix

        t = np.array(np.broadcast_to(np.asarray(twist, dtype=float), (len(self), 6)))
        return Frame(p=self.p + t[:, 0:3], R=rotation_vector_to_matrix(t[:, 3:6]) @ self.R)

    def point(self, t: np.ndarray) -> np.ndarray:
        """Points t (3,) fixed in the platform, in the base frame (N, 3): p + R t."""
        return self.p + self.R @ np.asarray(t, dtype=float)


__all__ = ["Frame"]

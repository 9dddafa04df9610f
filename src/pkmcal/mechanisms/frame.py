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
    """N platform frames in the base frame: ``p`` (N, 3) mm, ``R`` (N, 3, 3) rotations.

    ``normal`` (N, 3), optional: the platform's z axis R e_z as its constructor computed it
    in closed form (:meth:`from_poses`: the pose convention's third column without forming R,
    the formula the indicators have always used), equal to ``R[:, :, 2]`` to one rounding;
    :attr:`z_axis` gives it, or ``R[:, :, 2]`` when None. It keeps the indicator readings
    of a hexapod bit-identical to those before frames existed."""

    p: np.ndarray
    R: np.ndarray
    normal: np.ndarray | None = None

    @classmethod
    def from_poses(cls, poses: np.ndarray) -> Frame:
        """The frames of poses (N, 6) x, y, z, a, b, c in the pose convention of
        :mod:`pkmcal.conventions` (p = (x, y, z), R = Rz(c) Ry(b) Rx(a)); a single pose
        (6,) gives one frame."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim == 1:
            poses = poses[None, :]
        return cls(p=poses[:, 0:3].copy(), R=euler_to_matrix(poses[:, 3:6]), normal=z_axes(poses[:, 3:6]))

    @property
    def z_axis(self) -> np.ndarray:
        """R e_z (N, 3): :attr:`normal` when the constructor gave it, else ``R[:, :, 2]``."""
        return self.R[:, :, 2] if self.normal is None else self.normal

    def __len__(self) -> int:
        return int(self.p.shape[0])

    def __getitem__(self, index) -> Frame:
        """The frames ``index`` (an index array, boolean mask or slice) as a Frame."""
        return Frame(p=self.p[index], R=self.R[index], normal=None if self.normal is None else self.normal[index])

    def moved(self, twist: np.ndarray) -> Frame:
        """The frames displaced by twists (N, 6) or (6,) = (δp, δω): p + δp, exp([δω]×) R."""
        from pkmcal.conventions import rotation_vector_to_matrix

        t = np.array(np.broadcast_to(np.asarray(twist, dtype=float), (len(self), 6)))
        return Frame(p=self.p + t[:, 0:3], R=rotation_vector_to_matrix(t[:, 3:6]) @ self.R)

    def point(self, t: np.ndarray) -> np.ndarray:
        """Points t (3,) fixed in the platform, in the base frame (N, 3): p + R t."""
        return self.p + self.R @ np.asarray(t, dtype=float)


def z_axes(abc: np.ndarray) -> np.ndarray:
    """R e_z (N, 3) of angles (N, 3), the third column of R = Rz(c) Ry(b) Rx(a)
    (:func:`~pkmcal.conventions.euler_to_matrix`) without forming R:
    (c_c s_b c_a + s_c s_a, s_c s_b c_a − c_c s_a, c_b c_a)."""
    c, s = np.cos(abc), np.sin(abc)
    ca, sa = c[:, 0], s[:, 0]
    cb_ca, sb_ca = c[:, 1] * ca, s[:, 1] * ca
    n = np.empty(abc.shape)
    n[:, 0] = c[:, 2] * sb_ca + s[:, 2] * sa
    n[:, 1] = s[:, 2] * sb_ca - c[:, 2] * sa
    n[:, 2] = cb_ca
    return n


__all__ = ["Frame", "z_axes"]

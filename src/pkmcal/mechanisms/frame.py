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

import numpy as np

from pkmcal.conventions import euler_to_matrix


class Frame:
    """N platform frames in the base frame: ``p`` (N, 3) mm, ``R`` (N, 3, 3) rotations.

    Built from pose-convention angles (:meth:`from_poses`), R and the platform's z axis
    R e_z are computed on first use, each once: a sensor that needs only the z axis (the
    indicators) never forms R. :attr:`z_axis` is then the closed form of the convention's
    third column (the formula the indicators have always used), equal to ``R[:, :, 2]`` to one
    rounding, so the indicator readings of a hexapod are bit-identical to those before frames
    existed; for a frame given by its R it is ``R[:, :, 2]``. A Frame is never changed after
    construction (the lazily computed R and z axis are derived values, not state)."""

    __slots__ = ("p", "_R", "_abc", "_z")

    def __init__(self, p: np.ndarray, R: np.ndarray | None = None, *, abc: np.ndarray | None = None) -> None:
        if R is None and abc is None:
            raise ValueError("a Frame needs its rotations R or their pose-convention angles abc")
        self.p, self._R, self._abc, self._z = p, R, abc, None

    @classmethod
    def from_poses(cls, poses: np.ndarray) -> Frame:
        """The frames of poses (N, 6) x, y, z, a, b, c in the pose convention of
        :mod:`pkmcal.conventions` (p = (x, y, z), R = Rz(c) Ry(b) Rx(a)); a single pose
        (6,) gives one frame."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim == 1:
            poses = poses[None, :]
        return cls(p=poses[:, 0:3].copy(), abc=poses[:, 3:6].copy())

    @property
    def R(self) -> np.ndarray:
        """Rotations (N, 3, 3)."""
        if self._R is None:
            self._R = euler_to_matrix(self._abc)
        return self._R

    @property
    def z_axis(self) -> np.ndarray:
        """R e_z (N, 3) (class docstring)."""
        if self._z is None:
            self._z = self._R[:, :, 2] if self._abc is None else z_axes(self._abc)
        return self._z

    def __len__(self) -> int:
        return int(self.p.shape[0])

    def __getitem__(self, index) -> Frame:
        """The frames ``index`` (an index array, boolean mask or slice) as a Frame."""
        if self._abc is not None:
            return Frame(p=self.p[index], abc=self._abc[index])
        return Frame(p=self.p[index], R=self._R[index])

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

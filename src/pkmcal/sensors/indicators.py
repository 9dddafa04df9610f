"""Dial indicators fixed in the world (= base) frame, touching the platform's lower plane.

Model (paper 2 §3, eqs. 4–6). K ≥ 3 indicators with axes along z of the base frame {F}
stand at (x_k, y_k). The platform's lower surface is a plane through
x0 = p − d_off n with normal n = R e_z = (n_x, n_y, n_z) (paper 2 writes (a, b, c); here
a, b, c are Euler angles), d_off = ``plane_offset`` (the platform origin lies d_off above
its lower surface). Indicator k reads the height of that plane above (x_k, y_k), less its
zero offset ζ_k (params ``zero1 … zeroK``; real indicators are relative, so free them
when the zero is not referenced):

    n·x + d = 0,  d = −n·x0,  x0 = p − d_off n                                   (4)–(5)
    z_k = (−d − n_x x_k − n_y y_k) / n_z − ζ_k
        = (n·p − d_off − n_x x_k − n_y y_k) / n_z − ζ_k                          (6)

Derivatives: with N_k = n·p − d_off − n_x x_k − n_y y_k and
g_k = ∂z_k/∂n = ((p_x − x_k)/n_z, (p_y − y_k)/n_z, p_z/n_z − N_k/n_z²), and δn = δω × n,

    ∂z_k/∂p = n / n_z,     ∂z_k/∂δω = (n × g_k)ᵀ,     ∂z_k/∂ζ_k = −1,

the Euler pose Jacobian being the twist one times diag(I, E(a, b, c)). A plane that is
(near) vertical, |n_z| < :data:`MIN_NORMAL_Z`, cannot be read: :class:`PkmcalError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import euler_pose_jacobian
from pkmcal.errors import PkmcalError
from pkmcal.sensors._common import as_poses
from pkmcal.sensors.base import ParamGroup, Sensor

#: Smallest |n_z| (cosine of the plane tilt) at which the indicators are evaluated (≈ 89.9°).
MIN_NORMAL_Z = 1e-3


def plane_normals(abc: np.ndarray) -> np.ndarray:
    """n = R e_z (N, 3), the third column of R = Rz(c) Ry(b) Rx(a) (:func:`euler_to_matrix`):
    (c_c s_b c_a + s_c s_a, s_c s_b c_a − c_c s_a, c_b c_a), without forming R."""
    c, s = np.cos(abc), np.sin(abc)
    ca, sa = c[:, 0], s[:, 0]
    cb_ca, sb_ca = c[:, 1] * ca, s[:, 1] * ca
    n = np.empty(abc.shape)
    n[:, 0] = c[:, 2] * sb_ca + s[:, 2] * sa
    n[:, 1] = s[:, 2] * sb_ca - c[:, 2] * sa
    n[:, 2] = cb_ca
    return n


@dataclass(frozen=True, eq=False)
class IndicatorSensor(Sensor):
    """K ≥ 3 dial indicators along z of the base frame; see module docstring.

    Parameters
    ----------
    positions : (K, 2) indicator positions (x_k, y_k) in the base frame, mm.
    plane_offset : d_off, distance of the platform origin above its lower plane, mm.
    zero : (K,) indicator zero offsets ζ_k, mm; default 0.
    free : sensor parameters estimated by the identification (default: none).
    """

    positions: np.ndarray
    plane_offset: float = 0.0
    zero: np.ndarray | None = None
    free: tuple[str, ...] | None = None

    kind = "indicators"

    def __post_init__(self) -> None:
        pos = np.array(self.positions, dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 2 or pos.shape[0] < 3:
            raise PkmcalError(
                f"indicators sensor needs at least 3 indicator positions [x, y] (mm); got shape {pos.shape}"
            )
        if not np.all(np.isfinite(pos)):
            raise PkmcalError("indicators sensor: an indicator position is not a finite number")
        pos.setflags(write=False)
        object.__setattr__(self, "positions", pos)
        if not np.isfinite(self.plane_offset):
            raise PkmcalError("indicators sensor: plane_offset is not a finite number")
        object.__setattr__(self, "plane_offset", float(self.plane_offset))
        self._init_params()

    @property
    def n_indicators(self) -> int:
        return self.positions.shape[0]

    @property
    def reading_names(self) -> tuple[str, ...]:
        return tuple(f"d{k + 1}" for k in range(self.n_indicators))

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        """θ = the zero offsets ζ_1 … ζ_K, lengths (mm)."""
        k = self.n_indicators
        return (ParamGroup("zero", tuple(f"zero{i + 1}" for i in range(k)), (False,) * k),)

    def _plane(self, poses):
        """Poses (N, 6), normals n (N, 3), N_k (N, K): numerators of eq. (6)."""
        poses = as_poses(poses, self.kind)
        n = plane_normals(poses[:, 3:6])
        bad = np.abs(n[:, 2]) < MIN_NORMAL_Z
        if bad.any():
            k = int(np.argmax(bad))
            tilt = np.rad2deg(np.arccos(np.clip(n[k, 2], -1, 1)))
            raise PkmcalError(
                f"indicators cannot read pose {k} (x y z a b c = "
                f"{' '.join(f'{v:.6g}' for v in np.r_[poses[k, :3], np.rad2deg(poses[k, 3:])])} mm/deg): "
                f"its platform plane is tilted {tilt:.3f}° (near vertical); remove the pose"
            )
        num = (np.einsum("nk,nk->n", n, poses[:, 0:3]) - self.plane_offset)[:, None] \
            - n[:, 0:2] @ self.positions.T
        return poses, n, num

    def predict(self, poses: np.ndarray) -> np.ndarray:
        """Readings z_k − ζ_k (N, K), mm: eq. (6)."""
        _, n, num = self._plane(poses)
        return num / n[:, 2:3] - self.zero

    def pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂z/∂(x, y, z, a, b, c) (N, K, 6) (module docstring)."""
        poses, n, num = self._plane(poses)
        inz = 1.0 / n[:, 2:3]                                           # (N, 1)
        gx = (poses[:, 0:1] - self.positions[:, 0]) * inz               # g_k, (N, K) each
        gy = (poses[:, 1:2] - self.positions[:, 1]) * inz
        gz = (poses[:, 2:3] - num * inz) * inz
        nx, ny, nz = n[:, 0:1], n[:, 1:2], n[:, 2:3]
        Jt = np.empty(num.shape + (6,))
        Jt[..., 0:3] = (n * inz)[:, None, :]
        Jt[..., 3] = ny * gz - nz * gy                                  # n × g_k
        Jt[..., 4] = nz * gx - nx * gz
        Jt[..., 5] = nx * gy - ny * gx
        return euler_pose_jacobian(Jt, poses)

    def param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂z/∂ζ (N, K, K) = −I."""
        poses = as_poses(poses, self.kind)
        return np.broadcast_to(-np.eye(self.n_indicators), (poses.shape[0],) + (self.n_indicators,) * 2).copy()

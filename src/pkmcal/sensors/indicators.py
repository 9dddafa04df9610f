"""Dial indicators on an external plate, touching the platform's lower plane.

Model (paper 2 §3, eqs. 4–6). K ≥ 3 indicators stand on the plate {W} at (x_k, y_k, 0),
their axes along z_W. The plate's pose in the base frame {F} is (p_W, R_W) (params
``plate.x … plate.c``, pose convention of :mod:`pkmcal.conventions`; identity by default:
paper 2's "{F} and {W} parallel, origins collinear", which its conclusion says is not a
limitation). In plate coordinates the platform is at p' = R_Wᵀ (p − p_W) with normal
n' = R_Wᵀ n, n = R e_z = (n_x, n_y, n_z) (paper 2 writes (a, b, c); here a, b, c are Euler
angles). The platform's lower surface is the plane through x0 = p − d_off n, d_off =
``plane_offset`` (the platform origin lies d_off above its lower surface). Indicator k
reads the distance along z_W from the plate to that plane, less its zero offset ζ_k
(params ``zero1 … zeroK``; real indicators are relative, so free them when the zero is not
referenced):

    n·x + d = 0,  d = −n·x0,  x0 = p − d_off n                                   (4)–(5)
    z_k = (−d' − n'_x x_k − n'_y y_k) / n'_z − ζ_k
        = (n'·p' − d_off − n'_x x_k − n'_y y_k) / n'_z − ζ_k                     (6)

(d' = −n'·x0', the plane in plate coordinates; with the identity plate this is eq. 6 as
printed.) Derivatives in plate coordinates: with N_k = n'·p' − d_off − n'_x x_k − n'_y y_k,
a' = n'/n'_z and g_k = ∂z_k/∂n' = ((p'_x − x_k)/n'_z, (p'_y − y_k)/n'_z, p'_z/n'_z − N_k/n'_z²),

    ∂z_k/∂p' = a'ᵀ,     ∂z_k/∂δω' = (n' × g_k)ᵀ,     ∂z_k/∂ζ_k = −1,

and in the base frame (δp' = R_Wᵀ δp, δω' = R_Wᵀ δω) the twist Jacobian rows are
(R_W a', R_W (n' × g_k)) (the twist Jacobian; the engine composes it with the mechanism's T).
The plate parameters (a plate displacement δp_W and small base-frame rotation δφ about
p_W, with v = p − p_W):

    ∂z_k/∂p_W = −(R_W a')ᵀ,     ∂z_k/∂δφ = ((R_W a') × v + (R_W g_k) × n)ᵀ,

∂/∂(plate.a, b, c) = ∂z_k/∂δφ · E(plate a, b, c). A rigid motion of the plate and the
platform together changes no reading, so the plate pose is identifiable only against a
base frame pinned by the mechanism parameters (the engine's gauge analysis names the
combinations); hold it (known from a survey) or free it. A plane that is (near) vertical
to the plate, |n'_z| < :data:`MIN_NORMAL_Z`, cannot be read: :class:`PkmcalError`. With the
identity plate the computation is the plate-free one, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import euler_rate_matrix, euler_to_matrix
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.frame import Frame, z_axes
from pkmcal.sensors._frames import TRANSFORM_IS_ANGLE
from pkmcal.sensors.base import ParamGroup, Sensor

#: Names of the plate-pose parameters (the pose of the plate {W} in the base frame {F}).
PLATE_PARAM_NAMES = tuple(f"plate.{c}" for c in ("x", "y", "z", "a", "b", "c"))

#: Smallest |n_z| (cosine of the plane tilt) at which the indicators are evaluated (≈ 89.9°).
MIN_NORMAL_Z = 1e-3


#: n = R e_z of Euler angles without forming R (the sensor reads :attr:`Frame.z_axis`,
#: which is this for the frames of poses).
plane_normals = z_axes


@dataclass(frozen=True, eq=False)
class IndicatorSensor(Sensor):
    """K ≥ 3 dial indicators along z of the plate frame; see module docstring.

    Parameters
    ----------
    positions : (K, 2) indicator positions (x_k, y_k) in the plate frame (= the base frame
        when the plate is the identity), mm.
    plane_offset : d_off, distance of the platform origin above its lower plane, mm.
    zero : (K,) indicator zero offsets ζ_k, mm; default 0.
    plate : (6,) pose x, y, z (mm), a, b, c (rad) of the plate frame in the base frame;
        default the identity (paper 2's parallel frames).
    free : sensor parameters estimated by the identification (default: none).
    """

    positions: np.ndarray
    plane_offset: float = 0.0
    zero: np.ndarray | None = None
    free: tuple[str, ...] | None = None
    plate: np.ndarray | None = None

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
        """θ = the zero offsets ζ_1 … ζ_K (mm), then the plate pose ``plate.x … plate.c``
        (mm, rad)."""
        k = self.n_indicators
        return (ParamGroup("zero", tuple(f"zero{i + 1}" for i in range(k)), (False,) * k),
                ParamGroup("plate", PLATE_PARAM_NAMES, TRANSFORM_IS_ANGLE))

    @property
    def plate_is_identity(self) -> bool:
        """True when the plate frame is the base frame (every plate parameter exactly 0)."""
        return not np.any(self.plate)

    def _plate(self, params) -> tuple[np.ndarray, np.ndarray]:
        """(zero offsets ζ (K,), plate pose (6,)) of θ = ``params`` (own for None)."""
        theta = self._theta(params)
        if theta is None:
            return self.zero, self.plate
        k = self.n_indicators
        return theta[:k], theta[k:k + 6]

    def _in_plate(self, frame: Frame, plate: np.ndarray):
        """Plate-frame positions p' (N, 3) and normals n' (N, 3) of the frames (module
        docstring); p' = p and n' = n = R e_z, unchanged bits, for the identity plate."""
        n = frame.z_axis
        if not np.any(plate):
            return frame.p, n
        Rw = euler_to_matrix(plate[3:6])
        return (frame.p - plate[0:3]) @ Rw, n @ Rw

    def readable(self, frame: Frame) -> tuple[np.ndarray, str]:
        """Frames whose platform plane is (near) vertical to the plate (|n'_z| <
        :data:`MIN_NORMAL_Z`) cannot be read."""
        _, n = self._in_plate(frame, self.plate)
        return np.abs(n[:, 2]) >= MIN_NORMAL_Z, "indicator plane near vertical"

    def _plane(self, frame: Frame, plate: np.ndarray):
        """Plate-frame p' and n' (N, 3), N_k (N, K): numerators of eq. (6)."""
        p, n = self._in_plate(frame, plate)
        bad = np.abs(n[:, 2]) < MIN_NORMAL_Z
        if bad.any():
            k = int(np.argmax(bad))
            tilt = np.rad2deg(np.arccos(np.clip(n[k, 2], -1, 1)))
            raise PkmcalError(
                f"indicators cannot read pose {k} (platform origin x y z = "
                f"{' '.join(f'{v:.6g}' for v in frame.p[k])} mm): "
                f"its platform plane is tilted {tilt:.3f}° (near vertical); remove the pose"
            )
        num = (np.einsum("nk,nk->n", n, p) - self.plane_offset)[:, None] - n[:, 0:2] @ self.positions.T
        return p, n, num

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings z_k − ζ_k (N, K), mm: eq. (6)."""
        zero, plate = self._plate(params)
        _, n, num = self._plane(frame, plate)
        return num / n[:, 2:3] - zero

    def touch_points(self, frame: Frame) -> np.ndarray:
        """Where each indicator touches the platform plane (N, K, 3), base frame, mm:
        p_W + R_W (x_k, y_k, z_k + ζ_k)."""
        z = self.predict(frame) + self.zero
        pts = np.stack([np.broadcast_to(self.positions[:, 0], z.shape),
                        np.broadcast_to(self.positions[:, 1], z.shape), z], axis=-1)
        if self.plate_is_identity:
            return pts
        return self.plate[0:3] + pts @ euler_to_matrix(self.plate[3:6]).T

    def _plate_twist(self, p, n, num):
        """Plate-frame twist Jacobian (N, K, 6): (a', n' × g_k) (module docstring)."""
        inz = 1.0 / n[:, 2:3]                                           # (N, 1)
        gx = (p[:, 0:1] - self.positions[:, 0]) * inz                   # g_k, (N, K) each
        gy = (p[:, 1:2] - self.positions[:, 1]) * inz
        gz = (p[:, 2:3] - num * inz) * inz
        nx, ny, nz = n[:, 0:1], n[:, 1:2], n[:, 2:3]
        Jt = np.empty(num.shape + (6,))
        Jt[..., 0:3] = (n * inz)[:, None, :]
        Jt[..., 3] = ny * gz - nz * gy                                  # n × g_k
        Jt[..., 4] = nz * gx - nx * gz
        Jt[..., 5] = nx * gy - ny * gx
        return Jt, np.stack([gx, gy, gz], axis=-1)

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂z/∂(δp, δω) (N, K, 6) (module docstring)."""
        _, plate = self._plate(params)
        p, n, num = self._plane(frame, plate)
        Jt, _ = self._plate_twist(p, n, num)
        if np.any(plate):                                               # rows (R_W a', R_W (n' × g_k))
            Rw = euler_to_matrix(plate[3:6])
            Jt[..., 0:3] = Jt[..., 0:3] @ Rw.T
            Jt[..., 3:6] = Jt[..., 3:6] @ Rw.T
        return Jt

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂z/∂θ (N, K, K + 6): −I for the zero offsets, then the plate pose (module docstring)."""
        _, plate = self._plate(params)
        p, n, num = self._plane(frame, plate)
        k = self.n_indicators
        J = np.zeros((len(frame), k, k + 6))
        J[:, :, :k] = -np.eye(k)
        _, g = self._plate_twist(p, n, num)
        Rw = euler_to_matrix(plate[3:6])
        a = (n / n[:, 2:3]) @ Rw.T                                      # R_W a' (N, 3)
        g_base = g @ Rw.T                                               # R_W g_k (N, K, 3)
        n_base = n @ Rw.T                                               # = n (N, 3)
        v = frame.p - plate[0:3]
        J[:, :, k:k + 3] = -a[:, None, :]
        dphi = np.cross(a, v)[:, None, :] + np.cross(g_base, n_base[:, None, :])
        J[:, :, k + 3:k + 6] = dphi @ euler_rate_matrix(plate[3:6])
        return J

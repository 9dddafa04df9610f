"""Distance sensor: a double ballbar, a string potentiometer or a laser interferometer aimed at
a fixed point reads the distance between base points and one point on the platform.

Model. A ball (the tool point) sits at t in the platform frame {P} (params ``ball.x,
ball.y, ball.z``); K pivots sit at c_k in the base frame {F} (params ``pivot<k>.x …``);
the instrument reads the distance less a reference length ℓ_k (params ``length<k>``:
the ballbar's calibrated length, so that the readings are its deviations; 0 by default, so
that they are absolute distances). With the platform frame F = (p, R):

    v_k = p + R t − c_k,   d_k = ‖v_k‖,   r_k = d_k − ℓ_k                   (readings dist1 … distK)

    ∂r_k/∂p = u_kᵀ,   ∂r_k/∂δω = (R t × u_k)ᵀ,   ∂r_k/∂t = u_kᵀ R,   ∂r_k/∂c_k = −u_kᵀ,   ∂r_k/∂ℓ_k = −1

with u_k = v_k / d_k (δω a small base-frame rotation: δ(R t) = δω × R t, and
u·(δω × a) = δω·(a × u)). A distance says nothing about the direction of v_k, so one
instrument sees far less than a tracker; the identifiability analysis says what it misses
on each machine. The readings are defined away from d_k = 0 (``readable``).

Circle test (ISO 230-4, the ballbar's usual use; ability ``"circle-test"``,
:meth:`DistanceSensor.circle_frames`): n ball positions equally spaced on the circle about
pivot 1 of radius ℓ_1 (or, when ℓ_1 = 0, the distance from pivot 1 to the ball at the
machine's home), in a plane through the pivot (xy, yz or zx of the base frame), the platform
keeping its home orientation: the platform frames are (b − R t, R).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors.base import ParamGroup, Sensor

BALL_PARAM_NAMES = ("ball.x", "ball.y", "ball.z")
#: Smallest distance (mm) at which the readings and their derivatives are defined.
MIN_DISTANCE_MM = 1e-6


@dataclass(frozen=True, eq=False)
class DistanceSensor(Sensor):
    """Distances from K base pivots to one ball on the platform (module docstring).

    Parameters
    ----------
    pivots : (K, 3) pivot points c_k in the base frame {F}, mm (K ≥ 1).
    ball : (3,) ball centre t in the platform frame {P}, mm; default the origin of {P}.
    lengths : (K,) reference lengths ℓ_k subtracted from the distances, mm; default 0.
    free : sensor parameters estimated by the identification (default: none).
    """

    pivots: np.ndarray = None  # type: ignore[assignment]
    ball: np.ndarray = None  # type: ignore[assignment]
    lengths: np.ndarray = None  # type: ignore[assignment]
    free: tuple[str, ...] | None = None

    kind = "distance"
    abilities = frozenset({"circle-test"})
    #: Planes of the circle test: their two in-plane axes (indices of x, y, z).
    CIRCLE_PLANES = {"xy": (0, 1), "yz": (1, 2), "zx": (2, 0)}

    def __post_init__(self) -> None:
        if self.pivots is None:
            raise PkmcalError("a distance sensor needs its pivot points (pivots: [[x, y, z], ...], mm)")
        piv = np.array(self.pivots, dtype=float)
        if piv.ndim == 1 and piv.size % 3 == 0:
            piv = piv.reshape(-1, 3)          # flat, as θ holds them
        if piv.ndim != 2 or piv.shape[1] != 3 or len(piv) < 1:
            raise PkmcalError(f"distance sensor pivots must be K points [x, y, z] (mm); got shape {piv.shape}")
        object.__setattr__(self, "pivots", piv.ravel())
        self._init_params()

    @property
    def n_pivots(self) -> int:
        return len(self.pivots) // 3

    @cached_property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        K = self.n_pivots
        pivot_names = tuple(f"pivot{k + 1}.{a}" for k in range(K) for a in "xyz")
        return (ParamGroup("ball", BALL_PARAM_NAMES, (False,) * 3),
                ParamGroup("pivots", pivot_names, (False,) * 3 * K),
                ParamGroup("lengths", tuple(f"length{k + 1}" for k in range(K)), (False,) * K))

    @cached_property
    def reading_names(self) -> tuple[str, ...]:
        return tuple(f"dist{k + 1}" for k in range(self.n_pivots))

    def _parts(self, params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t (3,), c (K, 3), ℓ (K,)) at θ = ``params`` (this sensor's own for None)."""
        theta = self._theta(params)
        if theta is None:
            return self.ball, self.pivots.reshape(-1, 3), self.lengths
        K = self.n_pivots
        return theta[0:3], theta[3:3 + 3 * K].reshape(K, 3), theta[3 + 3 * K:]

    @staticmethod
    def _geometry(frame: Frame, t: np.ndarray, c: np.ndarray):
        """R t (N, 3), v (N, K, 3), d (N, K)."""
        Rt = frame.R @ t
        v = (frame.p + Rt)[:, None, :] - c[None, :, :]
        return Rt, v, np.linalg.norm(v, axis=2)

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings (N, K): distance minus reference length, mm."""
        t, c, lengths = self._parts(params)
        return self._geometry(frame, t, c)[2] - lengths

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂r/∂(δp, δω) (N, K, 6)."""
        t, c, _ = self._parts(params)
        Rt, v, d = self._geometry(frame, t, c)
        u = v / d[:, :, None]
        J = np.empty(d.shape + (6,))
        J[:, :, 0:3] = u
        J[:, :, 3:6] = np.cross(Rt[:, None, :], u)
        return J

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂r/∂θ (N, K, 3 + 4K), θ = ball, pivots, lengths."""
        t, c, _ = self._parts(params)
        _, v, d = self._geometry(frame, t, c)
        u = v / d[:, :, None]
        N, K = d.shape
        J = np.zeros((N, K, 3 + 4 * K))
        J[:, :, 0:3] = u @ frame.R                      # u_kᵀ R, per pose
        k = np.arange(K)
        J[:, k[:, None], 3 + 3 * k[:, None] + np.arange(3)] = -u     # pivot k's own three columns
        J[:, k, 3 + 3 * K + k] = -1.0
        return J

    def readable(self, frame: Frame) -> tuple[np.ndarray, str]:
        t, c, _ = self._parts(None)
        d = self._geometry(frame, t, c)[2]
        return np.all(d > MIN_DISTANCE_MM, axis=1), f"the ball is within {MIN_DISTANCE_MM:g} mm of a pivot"

    def circle_frames(self, n: int, home: Frame, plane: str = "xy") -> Frame:
        """The platform frames (n) of a circle test about pivot 1 (module docstring), the
        platform at the orientation of ``home`` (one frame); ball angles 0, 2π/n, …"""
        if plane not in self.CIRCLE_PLANES:
            raise PkmcalError(f"unknown circle plane '{plane}'; use one of {', '.join(self.CIRCLE_PLANES)}")
        if n < 1:
            raise PkmcalError(f"a circle test needs at least one pose, not {n}")
        t, c, lengths = self._parts(None)
        R = home.R[0]
        radius = float(lengths[0]) if lengths[0] != 0 else float(np.linalg.norm(home.p[0] + R @ t - c[0]))
        if not radius > MIN_DISTANCE_MM:
            raise PkmcalError("the circle test has no radius: give the ballbar length (lengths: [...]) or move "
                              "pivot 1 away from the ball's home position")
        phi = 2.0 * np.pi * np.arange(n) / n
        i, j = self.CIRCLE_PLANES[plane]
        ball = np.tile(c[0], (n, 1))
        ball[:, i] += radius * np.cos(phi)
        ball[:, j] += radius * np.sin(phi)
        return Frame(p=ball - R @ t, R=np.broadcast_to(R, (n, 3, 3)).copy())

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

and the pose (Euler) Jacobian is the twist one times diag(I, E(a, b, c)).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pkmcal.conventions import (
    POSE_COLUMNS,
    euler_pose_jacobian,
    euler_rate_matrix,
    euler_to_matrix,
    matrix_to_euler,
)
from pkmcal.errors import PkmcalError
from pkmcal.sensors.base import Sensor

WORLD_PARAM_NAMES = tuple(f"world.{c}" for c in POSE_COLUMNS)
TOOL_PARAM_NAMES = tuple(f"tool.{c}" for c in POSE_COLUMNS)


# -- small vectorised helpers shared by the sensors -------------------------------------


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices [v]× (..., 3, 3) of vectors v (..., 3): [v]× w = v × w."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape + (3,))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def as_poses(poses: np.ndarray, who: str) -> np.ndarray:
    """``poses`` as a float array (N, 6); a single pose (6,) becomes (1, 6)."""
    poses = np.asarray(poses, dtype=float)
    if poses.ndim == 1:
        poses = poses[None, :]
    if poses.ndim != 2 or poses.shape[1] != 6:
        raise PkmcalError(f"{who} sensor needs poses (N, 6) = x, y, z, a, b, c; got shape {poses.shape}")
    return poses


def check_params(params: np.ndarray, names: tuple[str, ...], who: str) -> np.ndarray:
    """Parameter vector as a read-only float array of the right length."""
    arr = np.array(params, dtype=float).reshape(-1)
    if arr.shape != (len(names),):
        raise PkmcalError(f"{who} sensor has {len(names)} parameters ({', '.join(names)}); got {arr.size} values")
    if not np.all(np.isfinite(arr)):
        bad = names[int(np.argmax(~np.isfinite(arr)))]
        raise PkmcalError(f"{who} sensor parameter '{bad}' is not a finite number")
    arr.setflags(write=False)
    return arr


def check_free(free: tuple[str, ...] | None, names: tuple[str, ...], who: str) -> tuple[str, ...] | None:
    """Validate a list of free sensor-parameter names."""
    if free is None:
        return None
    free = tuple(free)
    unknown = [f for f in free if f not in names]
    if unknown:
        raise PkmcalError(
            f"{who} sensor has no parameter {', '.join(repr(u) for u in unknown)}; "
            f"its parameters are {', '.join(names) or '(none)'}"
        )
    return free


def euler_rate_inverse(abc: np.ndarray) -> np.ndarray:
    """E(a, b, c)⁻¹ (..., 3, 3): d(a, b, c) = E⁻¹ δω. Singular at b = ±90° (gimbal lock)."""
    abc = np.asarray(abc, dtype=float)
    cb, sb = np.cos(abc[..., 1]), np.sin(abc[..., 1])
    cc, sc = np.cos(abc[..., 2]), np.sin(abc[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        Ei = np.zeros(abc.shape[:-1] + (3, 3))
        Ei[..., 0, 0] = cc / cb
        Ei[..., 0, 1] = sc / cb
        Ei[..., 1, 0] = -sc
        Ei[..., 1, 1] = cc
        Ei[..., 2, 0] = cc * sb / cb
        Ei[..., 2, 1] = sc * sb / cb
        Ei[..., 2, 2] = 1.0
    return Ei


# -- the sensor -------------------------------------------------------------------------


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

    def __post_init__(self) -> None:
        for attr in ("world", "tool"):
            value = np.zeros(6) if getattr(self, attr) is None else getattr(self, attr)
            names = WORLD_PARAM_NAMES if attr == "world" else TOOL_PARAM_NAMES
            object.__setattr__(self, attr, check_params(value, names, self.kind))
        object.__setattr__(self, "free", check_free(self.free, self.param_names, self.kind))
        # the constant rotations of the two transforms, once per sensor (not per pose batch)
        object.__setattr__(self, "_Rw", euler_to_matrix(self.world[3:6]))
        object.__setattr__(self, "_Rt", euler_to_matrix(self.tool[3:6]))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, FullPoseSensor):
            return NotImplemented
        return bool(np.array_equal(self.params, other.params) and self.free == other.free)

    __hash__ = None  # type: ignore[assignment]

    @property
    def reading_names(self) -> tuple[str, ...]:
        return POSE_COLUMNS

    @property
    def reading_is_angle(self) -> tuple[bool, ...]:
        return (False, False, False, True, True, True)

    @property
    def param_names(self) -> tuple[str, ...]:
        return WORLD_PARAM_NAMES + TOOL_PARAM_NAMES

    @property
    def params(self) -> np.ndarray:
        return np.concatenate([self.world, self.tool])

    @property
    def default_free(self) -> tuple[str, ...]:
        return () if self.free is None else self.free

    def with_params(self, params: np.ndarray) -> "FullPoseSensor":
        theta = check_params(params, self.param_names, self.kind)
        return replace(self, world=theta[:6], tool=theta[6:])

    def _frames(self, poses) -> dict:
        """Poses, R (N, 3, 3), R p_t, the target v = p + R p_t in {F}, R_w R, R_T = R_w R R_t
        and its Euler angles; kept for the last pose batch, since a fit asks for the
        readings, ∂y/∂x and ∂y/∂θ at the same poses (the keys of the returned dict)."""
        poses = as_poses(poses, self.kind)
        key = poses.tobytes()
        cached = self.__dict__.get("_last_frames")
        if cached is not None and cached[0] == key:
            return cached[1]
        poses = poses.copy()                                         # the cache owns its poses
        R = euler_to_matrix(poses[:, 3:6])
        Rpt = R @ self.tool[0:3]                                     # R p_t (N, 3)
        v = poses[:, 0:3] + Rpt                                      # target in {F}
        RwR = self._Rw @ R
        RT = RwR @ self._Rt
        fr = {"poses": poses, "R": R, "Rpt": Rpt, "v": v, "RwR": RwR, "ang": matrix_to_euler(RT)}
        object.__setattr__(self, "_last_frames", (key, fr))
        return fr

    def _Ei(self, fr: dict) -> np.ndarray:
        """E(y_ang)⁻¹ of the frames ``fr`` (computed once per pose batch)."""
        if "Ei" not in fr:
            fr["Ei"] = euler_rate_inverse(fr["ang"])
        return fr["Ei"]

    def predict(self, poses: np.ndarray) -> np.ndarray:
        """Readings (N, 6): target position (mm) and Euler angles (rad) in {W}."""
        fr = self._frames(poses)
        out = np.empty((fr["poses"].shape[0], 6))
        out[:, 0:3] = self.world[0:3] + fr["v"] @ self._Rw.T
        out[:, 3:6] = fr["ang"]
        return out

    def pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂(x, y, z, a, b, c) (N, 6, 6) (module docstring)."""
        fr = self._frames(poses)
        Rw = self._Rw
        Jt = np.zeros((fr["poses"].shape[0], 6, 6))
        Jt[:, 0:3, 0:3] = Rw
        Jt[:, 0:3, 3:6] = -Rw @ skew(fr["Rpt"])
        Jt[:, 3:6, 3:6] = self._Ei(fr) @ Rw
        return euler_pose_jacobian(Jt, fr["poses"])

    def param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂θ (N, 6, 12), θ = world.x … world.c, tool.x … tool.c (module docstring)."""
        fr = self._frames(poses)
        Ei, RwR = self._Ei(fr), fr["RwR"]
        Ew = euler_rate_matrix(self.world[3:6])
        Et = euler_rate_matrix(self.tool[3:6])
        J = np.zeros((fr["poses"].shape[0], 6, 12))
        J[:, 0:3, 0:3] = np.eye(3)
        J[:, 0:3, 3:6] = -skew(fr["v"] @ self._Rw.T) @ Ew
        J[:, 3:6, 3:6] = Ei @ Ew
        J[:, 0:3, 6:9] = RwR
        J[:, 3:6, 9:12] = Ei @ (RwR @ Et)
        return J

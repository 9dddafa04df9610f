"""Planar tool-point sensor: a laser tracker reads the tool point P_t of a planar machine.

Paper 3 §3 measures the position of the tool-plate centre P_t with a Leica AT901 tracker
(position only). For a planar pose x = (x, y) (translating plate) or (x, y, φ), with the
target t = (P_tx, P_ty) in the plate frame (params ``target.x, target.y``, free by
default, the paper identifies them) and the tracker frame holding the base frame at
(p_w, c_w) (params ``world.x, world.y, world.c``; identity and held by default — free
them when the tracker's frame is unknown):

    p_t = (x, y) + R(φ) t          (R(φ) = I for the 2-d.o.f. machine)
    y   = p_w + R(c_w) p_t                                                   (readings px, py)

    ∂y/∂(x, y) = R(c_w),   ∂y/∂φ = R(c_w) R'(φ) t,   ∂y/∂t = R(c_w) R(φ),
    ∂y/∂p_w = I,           ∂y/∂c_w = R'(c_w) p_t.

Pose Jacobians are (N, 2, n) with n = 2 or 3, the mechanism's pose dimension.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.sensors.base import ParamGroup, Sensor

PLANAR_TARGET_NAMES = ("target.x", "target.y")
PLANAR_WORLD_NAMES = ("world.x", "world.y", "world.c")
_GROUPS = (ParamGroup("target", PLANAR_TARGET_NAMES, (False, False)),
           ParamGroup("world", PLANAR_WORLD_NAMES, (False, False, True)))


def _rot(c):
    c = np.asarray(c, dtype=float)
    cs, sn = np.cos(c), np.sin(c)
    return np.stack([np.stack([cs, -sn], -1), np.stack([sn, cs], -1)], -2)


def _drot(c):
    c = np.asarray(c, dtype=float)
    cs, sn = np.cos(c), np.sin(c)
    return np.stack([np.stack([-sn, -cs], -1), np.stack([cs, -sn], -1)], -2)


@dataclass(frozen=True, eq=False)
class PlanarToolSensor(Sensor):
    """Tracker reading of the tool point of a planar machine (module docstring).

    Parameters
    ----------
    n_pose : 2 (translating plate, pose x, y) or 3 (pose x, y, φ).
    target : (2,) tool point in the plate frame, mm (paper's P_tx, P_ty); default 0.
    world : (3,) base frame in the tracker frame (x, y mm; c rad); default identity.
    free : sensor parameters estimated by default (default: the target).
    """

    n_pose: int = 2
    target: np.ndarray = None  # type: ignore[assignment]
    world: np.ndarray = None  # type: ignore[assignment]
    free: tuple[str, ...] | None = None

    kind = "planar-tool"

    def __post_init__(self) -> None:
        if self.n_pose not in (2, 3):
            raise PkmcalError(f"planar tool sensor: n_pose must be 2 or 3, got {self.n_pose}")
        if self.free is None:                       # stored: the setup file writes it back
            object.__setattr__(self, "free", PLANAR_TARGET_NAMES)
        self._init_params()

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        return _GROUPS

    @property
    def reading_names(self) -> tuple[str, ...]:
        return ("px", "py")

    def with_deltas(self, deltas: dict[str, float]) -> "PlanarToolSensor":
        p = self.params
        for k, v in deltas.items():
            p[self.param_names.index(k)] += v
        return self.with_params(p)

    def _poses(self, poses):
        x = np.atleast_2d(np.asarray(poses, dtype=float))
        if x.shape[-1] != self.n_pose:
            raise PkmcalError(f"planar tool sensor expects poses with {self.n_pose} coordinates; got shape {x.shape}")
        return x

    def tool_point(self, poses: np.ndarray) -> np.ndarray:
        """p_t (N, 2) in the machine's base frame (the point a load acts on)."""
        x = self._poses(poses)
        if self.n_pose == 2:
            return x + self.target
        return x[:, :2] + np.einsum("nij,j->ni", _rot(x[:, 2]), self.target)

    def predict(self, poses: np.ndarray) -> np.ndarray:
        """Readings y = p_w + R(c_w) p_t (N, 2)."""
        return self.world[:2] + self.tool_point(poses) @ _rot(self.world[2]).T

    def tool_pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂p_t/∂x (N, 2, n) in the base frame (J_f of paper 3 eq. 3)."""
        x = self._poses(poses)
        J = np.zeros((x.shape[0], 2, self.n_pose))
        J[:, :, :2] = np.eye(2)
        if self.n_pose == 3:
            J[:, :, 2] = np.einsum("nij,j->ni", _drot(x[:, 2]), self.target)
        return J

    def pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂x (N, 2, n)."""
        return np.einsum("ij,njk->nik", _rot(self.world[2]), self.tool_pose_jacobian(poses))

    def param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂(target.x, target.y, world.x, world.y, world.c) (N, 2, 5)."""
        x = self._poses(poses)
        N = x.shape[0]
        Rw = _rot(self.world[2])
        J = np.zeros((N, 2, 5))
        if self.n_pose == 2:
            J[:, :, 0:2] = Rw
        else:
            J[:, :, 0:2] = np.einsum("ij,njk->nik", Rw, _rot(x[:, 2]))
        J[:, :, 2:4] = np.eye(2)
        J[:, :, 4] = self.tool_point(x) @ _drot(self.world[2]).T
        return J

    def poses_for_readings(self, readings: np.ndarray, angles: np.ndarray | None = None) -> np.ndarray:
        """Poses (N, n) whose reading is ``readings`` (N, 2); for n = 3 the plate angles φ
        (N,) are given (closed-form inverse of :meth:`predict`)."""
        y = np.atleast_2d(np.asarray(readings, dtype=float))
        p_t = (y - self.world[:2]) @ _rot(self.world[2])          # R(c_w)ᵀ (y − p_w)
        if self.n_pose == 2:
            return p_t - self.target
        if angles is None:
            raise PkmcalError("poses_for_readings: a 3-d.o.f. planar machine needs the plate angle of each pose")
        phi = np.broadcast_to(np.asarray(angles, dtype=float), (y.shape[0],))
        xy = p_t - np.einsum("nij,j->ni", _rot(phi), self.target)
        return np.concatenate([xy, phi[:, None]], axis=1)

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

The sensor reads the plate frame (p, R) (:class:`~pkmcal.mechanisms.frame.Frame`; p in the
plane z = 0, R = Rz(φ)): p_t = (p + R (t, 0))_xy, and its twist Jacobian is (I 0 | rows x, y
of −[R t]×), which the mechanism's T turns into the pose Jacobian above (∂/∂φ = the δω_z
column). ``n_pose`` (2 or 3) is the pose dimension of the machines it measures
(:meth:`PlanarToolSensor.works_with`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.frame import Frame
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
    abilities = frozenset({"tool-point"})

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

    def works_with(self, mechanism) -> str | None:
        """A planar machine (``"planar"`` in its abilities) with ``n_pose`` pose coordinates."""
        if "planar" not in mechanism.abilities:
            return (f"a 'planar-tool' sensor cannot measure machine '{mechanism.name}' ({mechanism.n_dof} pose "
                    "coordinates, not a planar machine); use a 'full-pose', 'position' or 'indicators' setup")
        if mechanism.n_dof != self.n_pose:
            return (f"the planar-tool sensor is set up for {self.n_pose} pose coordinates; machine "
                    f"'{mechanism.name}' has {mechanism.n_dof}")
        return None

    def _parts(self, params) -> tuple[np.ndarray, np.ndarray]:
        """(target (2,), world (3,)) of θ = ``params`` (own for None)."""
        theta = self._theta(params)
        if theta is None:
            return self.target, self.world
        return theta[0:2], theta[2:5]

    def tool_point(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """p_t (N, 2) in the machine's base frame (the point a load acts on): the x, y of
        p + R (t, 0)."""
        target, _ = self._parts(params)
        return frame.p[:, 0:2] + np.einsum("nij,j->ni", frame.R[:, 0:2, 0:2], target)

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings y = p_w + R(c_w) p_t (N, 2)."""
        _, world = self._parts(params)
        return world[:2] + self.tool_point(frame, params) @ _rot(world[2]).T

    def tool_frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂p_t/∂(δp, δω) (N, 2, 6) in the base frame: (I 0 | rows x, y of −[R t]×); with the
        mechanism's T it is J_f of paper 3 eq. 3."""
        target, _ = self._parts(params)
        Rt = np.einsum("nij,j->ni", frame.R[:, :, 0:2], target)         # R (t, 0), (N, 3)
        J = np.zeros((len(frame), 2, 6))
        J[:, 0, 0] = J[:, 1, 1] = 1.0
        J[:, 0, 4], J[:, 0, 5] = Rt[:, 2], -Rt[:, 1]                    # −[Rt]× rows 0, 1
        J[:, 1, 3], J[:, 1, 5] = -Rt[:, 2], Rt[:, 0]
        return J

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(δp, δω) (N, 2, 6) = R(c_w) ∂p_t/∂(δp, δω)."""
        _, world = self._parts(params)
        return np.einsum("ij,njk->nik", _rot(world[2]), self.tool_frame_jacobian(frame, params))

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(target.x, target.y, world.x, world.y, world.c) (N, 2, 5)."""
        _, world = self._parts(params)
        Rw = _rot(world[2])
        J = np.zeros((len(frame), 2, 5))
        J[:, :, 0:2] = np.einsum("ij,njk->nik", Rw, frame.R[:, 0:2, 0:2])
        J[:, :, 2:4] = np.eye(2)
        J[:, :, 4] = self.tool_point(frame, params) @ _drot(world[2]).T
        return J

    def frame_for_readings(self, readings: np.ndarray, R: np.ndarray) -> Frame:
        """The plate frames with rotations R (N, 3, 3) whose reading is ``readings`` (N, 2)
        (closed-form inverse of :meth:`predict` at a given plate rotation):
        p = (R(c_w)ᵀ (y − p_w) − R₂ t, 0)."""
        y = np.atleast_2d(np.asarray(readings, dtype=float))
        p_t = (y - self.world[:2]) @ _rot(self.world[2])          # R(c_w)ᵀ (y − p_w)
        R = np.broadcast_to(np.asarray(R, dtype=float), (y.shape[0], 3, 3))
        p = np.zeros((y.shape[0], 3))
        p[:, 0:2] = p_t - np.einsum("nij,j->ni", R[:, 0:2, 0:2], self.target)
        return Frame(p=p, R=np.array(R))

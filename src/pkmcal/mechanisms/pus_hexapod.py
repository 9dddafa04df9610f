"""Sliding-joint hexapods (6-PUS: the Hexaglide, vertical-rail positioners): six carriages
driven along fixed rails; legs of constant length with a universal joint on the carriage
and a spherical joint on the platform.

Pose x, y, z, a, b, c of the platform frame {P} in the base frame {F} (the pose convention
of :mod:`pkmcal.conventions`). Parameters of leg i (10 per leg, 60):

* ``r<i>.x, r<i>.y, r<i>.z``: the rail origin O_i (base frame, mm);
* ``tilt_x_<i>``, ``tilt_y_<i>``: the rail direction u_i = Q_i Rx(θx) Ry(θy) e_z, small
  tilts (rad inside, degrees in files) of the rail from its nominal direction Q_i e_z.
  Q_i is fixed, not a parameter: the machine file's ``rail`` direction (a rotation taking
  e_z to it), so that the tilts are never at the singularity of two angles;
* ``leg_<i>`` = ℓ_i (mm);
* ``a<i>.x, a<i>.y, a<i>.z``: the platform joint a_i (platform frame, mm);
* ``offset_<i>`` = o_i (mm): the reading is λ_i = s_i − o_i, s_i the carriage's position
  along the rail from O_i (the rail origin and the offset move together along u_i: one
  direction no measurement sees, which the gauge fixes).

Carriage joint B_i = O_i + s_i u_i, platform joint P_i = p + R a_i, |P_i − B_i| = ℓ_i.

Inverse kinematics (closed form). With d = P_i − O_i: s² − 2 s u·d + |d|² − ℓ² = 0, so
s = u·d + σ_i √((u·d)² − |d|² + ℓ²), σ_i = ±1 the machine's branch of leg i
(``branches``: +1 when the carriage is beyond the foot of the perpendicular from the
platform joint onto the rail); NaN where the leg cannot reach the rail.

Jacobians (implicit differentiation of f = |P − B|² − ℓ² = 0; w = P − B, g = w·u, zero at
the singularity where the leg is perpendicular to its rail):

    ∂s/∂(δp, δω) = [w, (R a) × w] / g      (the twist; × T for the pose)
    ∂s/∂O = −w/g,   ∂s/∂θ = −s w·(∂u/∂θ)/g,   ∂s/∂ℓ = −ℓ/g,   ∂s/∂a = wᵀR/g,   ∂λ/∂o = −1

with ∂u/∂θx = Q (e_x × Rx Ry e_z) and ∂u/∂θy = Q Rx (e_y × Ry e_z).
Forward kinematics: the shared batched solver (:mod:`pkmcal.mechanisms.solver`) on the
loop-closure equations, not on λ − IK(x): with the readings the carriage joints
B_i = O_i + (λ_i + o_i) u_i are known, and the platform solves |P_i(x) − B_i| = ℓ_i,

    e_i(x) = (ℓ_i² − |P_i − B_i|²) / (2 ℓ_i)   (≈ ℓ_i − |P_i − B_i|, mm),
    −∂e_i/∂(δp, δω) = [w, (R a) × w] / ℓ_i,   w = P_i − B_i,

finite at every pose, whereas IK is NaN wherever a leg cannot reach its rail (a start pose
there left the solver without a direction). A pose is converged when IK(x) reproduces λ
(``FK_RES_TOL``), which also rejects a closure solution on a carriage's other branch.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import ClassVar

import numpy as np

from pkmcal.conventions import euler_pose_jacobian, values_text
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import LimitReport
from pkmcal.mechanisms.frame import Frame
from pkmcal.mechanisms.param_vector import ParameterVector
from pkmcal.mechanisms.spatial import SpatialPlatform, leg_closure, twist_signs

N_LEGS = 6
LEG_PARAMS = ("r{i}.x", "r{i}.y", "r{i}.z", "tilt_x_{i}", "tilt_y_{i}", "leg_{i}",
              "a{i}.x", "a{i}.y", "a{i}.z", "offset_{i}")
PER_LEG = len(LEG_PARAMS)
PARAM_NAMES = tuple(s.format(i=i + 1) for i in range(N_LEGS) for s in LEG_PARAMS)
PARAM_IS_ANGLE = tuple(s.startswith("tilt") for _ in range(N_LEGS) for s in LEG_PARAMS)
_O, _TX, _TY, _LEG, _A, _OFF = 0, 3, 4, 5, 6, 9


def _legs(rho: np.ndarray) -> dict[str, np.ndarray]:
    g = np.asarray(rho, dtype=float).reshape(N_LEGS, PER_LEG)
    return {"O": g[:, _O:_O + 3], "tx": g[:, _TX], "ty": g[:, _TY], "leg": g[:, _LEG], "a": g[:, _A:_A + 3],
            "offset": g[:, _OFF]}


def rail_frames(directions: np.ndarray) -> np.ndarray:
    """Q (6, 3, 3): for each unit direction d a rotation with Q e_z = d (the smallest
    rotation from e_z; for d = −e_z, the half turn about e_x)."""
    d = np.asarray(directions, dtype=float).reshape(N_LEGS, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    Q = np.empty((N_LEGS, 3, 3))
    ez = np.array([0.0, 0.0, 1.0])
    for i in range(N_LEGS):           # six legs, at construction only
        v, c = np.cross(ez, d[i]), float(ez @ d[i])
        if c < -1.0 + 1e-12:
            Q[i] = np.diag([1.0, -1.0, -1.0])
            continue
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        Q[i] = np.eye(3) + vx + vx @ vx / (1.0 + c)
    return Q


def _directions(Q: np.ndarray, tx: np.ndarray, ty: np.ndarray):
    """u, ∂u/∂θx, ∂u/∂θy (6, 3) each (module docstring)."""
    cx, sx, cy, sy = np.cos(tx), np.sin(tx), np.cos(ty), np.sin(ty)
    w = np.stack([sy, -sx * cy, cx * cy], axis=1)                      # Rx Ry e_z
    dwx = np.stack([np.zeros_like(sy), -cx * cy, -sx * cy], axis=1)    # ∂/∂θx
    dwy = np.stack([cy, sx * sy, -cx * sy], axis=1)                    # ∂/∂θy
    return (np.einsum("kij,kj->ki", Q, w), np.einsum("kij,kj->ki", Q, dwx), np.einsum("kij,kj->ki", Q, dwy))


@dataclass(frozen=True, eq=False)
class PUSHexapod(ParameterVector, SpatialPlatform):
    """A 6-PUS hexapod (module docstring). ``rho`` (60,) in the order of
    :data:`PARAM_NAMES`; ``rails`` (6, 3) the nominal rail directions (unit, fixed);
    ``branches`` (6,) ±1 the IK branch of each leg; ``stroke`` (6, 2) the readings' range
    (mm); ``max_joint_angle`` the largest angle between a leg and the platform's z axis
    (rad); ``workspace`` (6, 2) the planning box (default about home: ±0.15 of the mean
    stroke in x, y, z, ±8° in roll/pitch, ±10° in yaw); ``home`` (6,) (default level,
    centred, at the height where the mean reading is mid-stroke)."""

    name: str
    rho: np.ndarray
    rails: np.ndarray
    stroke: np.ndarray
    branches: np.ndarray | None = None
    max_joint_angle: float = np.deg2rad(60.0)
    workspace: np.ndarray | None = None
    home: np.ndarray | None = None
    description: str = ""
    covariance: np.ndarray | None = None
    metadata: dict = field(default_factory=dict, compare=False)

    kind: ClassVar[str] = "6-PUS"
    abilities: ClassVar[frozenset[str]] = frozenset({"pose-convention", "stroke"})
    PARAM_NAMES: ClassVar[tuple[str, ...]] = PARAM_NAMES
    PARAM_IS_ANGLE: ClassVar[tuple[bool, ...]] = PARAM_IS_ANGLE
    LABEL: ClassVar[str] = "6-PUS hexapod"
    actuator_names = tuple(f"lambda{i + 1}" for i in range(N_LEGS))
    point_sets = MappingProxyType({"rail origins": tuple(f"r{i + 1}" for i in range(N_LEGS)),
                                   "platform joints": tuple(f"a{i + 1}" for i in range(N_LEGS))})

    def __post_init__(self) -> None:
        def frozen(value, shape, what):
            arr = np.array(value, dtype=float)
            if arr.size != int(np.prod(shape)):
                raise PkmcalError(f"machine '{self.name}': {what} needs {int(np.prod(shape))} numbers, got {arr.size}")
            arr = arr.reshape(shape)
            arr.flags.writeable = False
            return arr

        set_ = object.__setattr__
        rails = frozen(self.rails, (N_LEGS, 3), "rails")
        if np.any(np.linalg.norm(rails, axis=1) < 1e-12):
            raise PkmcalError(f"machine '{self.name}': a rail direction is the zero vector")
        set_(self, "rails", frozen(rails / np.linalg.norm(rails, axis=1, keepdims=True), (N_LEGS, 3), "rails"))
        set_(self, "stroke", frozen(self.stroke, (N_LEGS, 2), "stroke"))
        if np.any(self.stroke[:, 1] <= self.stroke[:, 0]):
            raise PkmcalError(f"machine '{self.name}': stroke of leg {int(np.argmax(self.stroke[:, 1] <= self.stroke[:, 0])) + 1} "
                              "has max <= min")
        set_(self, "branches", frozen(np.ones(N_LEGS) if self.branches is None else np.sign(self.branches),
                                      (N_LEGS,), "branches"))
        if np.any(self.branches == 0):
            raise PkmcalError(f"machine '{self.name}': each branch is +1 or -1")
        set_(self, "_Q", rail_frames(self.rails))
        self._freeze_params()
        set_(self, "home", frozen(self._default_home() if self.home is None else self.home, (6,), "home"))
        if self.workspace is not None:
            set_(self, "workspace", frozen(self.workspace, (6, 2), "workspace"))

    def parameter_problem(self) -> tuple[str, str] | None:
        if not np.all(np.isfinite(self.rho)):
            return PARAM_NAMES[int(np.flatnonzero(~np.isfinite(self.rho))[0])], "is not a finite number"
        g = _legs(self.rho)
        for i in range(N_LEGS):
            if g["leg"][i] <= 0:
                return f"leg_{i + 1}", "must be positive (mm)"
            for t in ("tx", "ty"):
                if abs(g[t][i]) >= np.pi / 4:
                    return f"tilt_{t[1]}_{i + 1}", "must be within ±45° (a tilt from the nominal rail direction)"
        return None

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        same = lambda x, y: (x is None and y is None) or (x is not None and y is not None  # noqa: E731
                                                          and np.array_equal(x, y))
        return bool(self.name == other.name and all(np.array_equal(getattr(self, k), getattr(other, k))
                                                    for k in ("rho", "rails", "stroke", "branches", "home"))
                    and self.max_joint_angle == other.max_joint_angle and same(self.workspace, other.workspace)
                    and same(self.covariance, other.covariance) and self.description == other.description)

    __hash__ = None  # type: ignore[assignment]

    @property
    def home_pose(self) -> np.ndarray:
        return self.home

    def _default_home(self) -> np.ndarray:
        """Level, centred, at the height where the mean reading is mid-stroke (bisection
        over heights where every leg reaches its rail)."""
        from scipy.optimize import brentq

        mid = float(np.mean(self.stroke))
        g = _legs(self.rho)
        top = float(np.max(g["O"][:, 2]) + np.max(g["leg"]) + np.max(np.abs(self.stroke)))
        zs = np.linspace(float(np.min(g["O"][:, 2])) - top, top, 801)
        grid = np.zeros((len(zs), 6))
        grid[:, 2] = zs
        vals = np.mean(self.ik(grid) - mid, axis=1)            # one call over the grid
        ok = np.isfinite(vals)
        change = np.flatnonzero(ok[:-1] & ok[1:] & (np.sign(vals[:-1]) != np.sign(vals[1:])))
        if not len(change):
            raise PkmcalError(f"machine '{self.name}': no level, centred pose puts the carriages mid-stroke; "
                              "give 'home:' or check the rails, legs and stroke")
        k = int(change[0])
        f = lambda z: float(np.mean(self.ik(np.array([0, 0, z, 0, 0, 0.0])) - mid))  # noqa: E731
        return np.array([0.0, 0.0, brentq(f, zs[k], zs[k + 1], xtol=1e-12), 0.0, 0.0, 0.0])

    def workspace_box(self) -> np.ndarray:
        if self.workspace is not None:
            return self.workspace.copy()
        s = 0.15 * float(np.mean(self.stroke[:, 1] - self.stroke[:, 0]))
        span = np.array([s, s, s, np.deg2rad(8.0), np.deg2rad(8.0), np.deg2rad(10.0)])
        return np.stack([self.home - span, self.home + span], axis=1)

    def summary(self) -> str:
        g = _legs(self.rho)
        return "\n".join([
            f"{self.name}: 6-PUS sliding-joint hexapod, {len(PARAM_NAMES)} kinematic parameters (readings "
            "lambda1..6 = carriage positions)",
            f"  legs {values_text(g['leg'], 'mm')}, strokes "
            f"{self.stroke[0, 0]:g}..{self.stroke[0, 1]:g} mm (leg 1)",
            f"  platform joints at radius {np.mean(np.hypot(g['a'][:, 0], g['a'][:, 1])):.3f} mm; legs within "
            f"{np.rad2deg(self.max_joint_angle):g} deg of the platform normal",
        ])

    # -- kinematics ------------------------------------------------------------------------

    def _loop(self, poses: np.ndarray, rho: np.ndarray):
        g = _legs(rho)
        u, du_x, du_y = _directions(self._Q, g["tx"], g["ty"])
        fr = Frame.from_poses(poses)
        Ra = np.einsum("nij,kj->nki", fr.R, g["a"])
        d = poses[:, None, 0:3] + Ra - g["O"][None]                     # P − O
        ud = np.einsum("nkj,kj->nk", d, u)
        with np.errstate(invalid="ignore"):
            s = ud + self.branches[None, :] * np.sqrt(ud**2 - np.einsum("nkj,nkj->nk", d, d) + g["leg"][None, :]**2)
        return g, u, du_x, du_y, Ra, d, s, fr

    def ik(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Carriage readings λ = s − o (N, 6), mm; NaN where a leg cannot reach its rail."""
        rho = self._rho(params)
        g, *_, s, _ = self._loop(self.as_pose_array(poses), rho)
        return s - g["offset"][None, :]

    def ik_and_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None):
        """(λ (N, 6), ∂λ/∂pose (N, 6, 6), ∂λ/∂ρ (N, 6, 60)) in one pass (module docstring)."""
        poses = self.as_pose_array(poses)
        rho = self._rho(params)
        g, u, du_x, du_y, Ra, d, s, fr = self._loop(poses, rho)
        w = d - s[..., None] * u[None]                                   # P − B
        gq = np.einsum("nkj,kj->nk", w, u)
        n = len(poses)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / gq
            A = euler_pose_jacobian(np.concatenate([w, np.cross(Ra, w)], axis=2) * inv[..., None], poses)
            B = np.zeros((n, N_LEGS, len(PARAM_NAMES)))
            legs, base = np.arange(N_LEGS), np.arange(N_LEGS) * PER_LEG
            for k in range(3):
                B[:, legs, base + _O + k] = -w[..., k] * inv
            B[:, legs, base + _TX] = -s * np.einsum("nkj,kj->nk", w, du_x) * inv
            B[:, legs, base + _TY] = -s * np.einsum("nkj,kj->nk", w, du_y) * inv
            B[:, legs, base + _LEG] = -g["leg"][None, :] * inv
            wR = np.einsum("nkj,nji->nki", w, fr.R)
            for k in range(3):
                B[:, legs, base + _A + k] = wR[..., k] * inv
            B[:, legs, base + _OFF] = -1.0
        return s - g["offset"][None, :], A, B

    def actuator_pose_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[1]

    def actuator_param_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[2]

    def actuator_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None):
        _, A, B = self.ik_and_jacobians(poses, params)
        return A, B

    def _closure(self, rho: np.ndarray):
        """The loop-closure equations of FK (module docstring) at ρ, for
        :func:`~pkmcal.mechanisms.solver.solve_fk`: e(x, λ) (M, 6) and −∂e/∂x (M, 6, 6)."""
        g = _legs(rho)
        u = _directions(self._Q, g["tx"], g["ty"])[0]

        def carriages(readings: np.ndarray) -> np.ndarray:                        # B (M, 6, 3)
            return g["O"][None] + (readings + g["offset"][None, :])[..., None] * u[None]

        return leg_closure(carriages, g["a"], g["leg"])

    def fk(self, readings: np.ndarray, guess: np.ndarray | None = None, params: np.ndarray | None = None,
           **options):
        """Poses from carriage readings λ (N, 6) by the shared solver on the loop-closure
        equations (module docstring); ``options`` those of
        :func:`~pkmcal.mechanisms.solver.solve_fk`."""
        from pkmcal.mechanisms.solver import solve_fk

        return solve_fk(self, readings, guess, params, equations=self._closure(self._rho(params)), **options)

    def assembly_signs(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Per leg the sign of w·u (the carriage's side of the foot of the perpendicular),
        and the sign of det of the twist Jacobian (the platform's mode)."""
        poses = self.as_pose_array(poses)
        g, u, _, _, Ra, d, s, _ = self._loop(poses, self._rho(params))
        w = d - s[..., None] * u[None]
        return np.concatenate([np.sign(np.nan_to_num(-np.einsum("nkj,kj->nk", w, u))), twist_signs(w, Ra)[:, None]],
                              axis=1).astype(np.int8)

    def reading_range(self) -> np.ndarray:
        return self.stroke.copy()

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """``reach``, ``stroke`` (mm; ``margin`` mm inside both ends), ``joint_angle`` (a leg
        more than :attr:`max_joint_angle` from the platform's z axis)."""
        poses = self.as_pose_array(poses)
        g, u, _, _, _, d, s, fr = self._loop(poses, self.rho)
        lam = s - g["offset"][None, :]
        reach = np.all(np.isfinite(lam), axis=1)
        with np.errstate(invalid="ignore"):
            stroke_m = np.where(reach, np.min(np.minimum(lam - self.stroke[:, 0], self.stroke[:, 1] - lam), axis=1),
                                -np.inf) - margin
            leg = d - s[..., None] * u[None]                                # P − B
            cosang = np.einsum("nkj,nj->nk", leg, fr.R[:, :, 2]) / g["leg"][None, :]
            tilt = np.arccos(np.clip(cosang, -1.0, 1.0))
        joint_m = np.where(reach, self.max_joint_angle - np.max(tilt, axis=1), -np.inf)
        values = {"reach": np.where(reach, 0.0, -np.inf), "stroke": stroke_m, "joint_angle": joint_m}
        return LimitReport(violations={k: ~(v >= 0) for k, v in values.items()}, margins=values if margins else {})


def symmetric_pus_hexapod(name: str, rail_radius: float, platform_radius: float, leg: float, stroke: float, *,
                          rail_half_angle_deg: float = 10.0, platform_half_angle_deg: float = 50.0,
                          **fields) -> PUSHexapod:
    """Six vertical rails in pairs at 120°k ± ``rail_half_angle`` on a circle of
    ``rail_radius`` (origins at z = 0), readings 0..``stroke``, the legs rising from the
    carriages to the platform (branch −1: the carriage below the foot of the perpendicular
    from the platform joint onto its rail); platform joints in pairs at 120°k ±
    ``platform_half_angle`` on ``platform_radius`` (pairs shifted by 60°)."""
    rho = np.zeros(len(PARAM_NAMES))
    for i in range(N_LEGS):
        k, side = i // 2, (1 if i % 2 else -1)
        th = np.deg2rad(120.0 * k + side * rail_half_angle_deg)
        tp = np.deg2rad(120.0 * k + side * platform_half_angle_deg)
        b = i * PER_LEG
        rho[b + _O:b + _O + 3] = [rail_radius * np.cos(th), rail_radius * np.sin(th), 0.0]
        rho[b + _LEG] = leg
        rho[b + _A:b + _A + 3] = [platform_radius * np.cos(tp), platform_radius * np.sin(tp), 0.0]
    return PUSHexapod(name=name, rho=rho, rails=np.tile([0.0, 0.0, 1.0], (N_LEGS, 1)),
                      stroke=np.tile([0.0, stroke], (N_LEGS, 1)), branches=-np.ones(N_LEGS), **fields)


__all__ = ["PARAM_NAMES", "PUSHexapod", "rail_frames", "symmetric_pus_hexapod"]

"""Rotary delta robots (Clavel's delta: pick-and-place robots, rotary delta printers):
three motors on the base turn upper arms; parallelogram forearms join the elbows to the
effector, which does not rotate.

Pose: the tool point p = (x, y, z) in the base frame {F} (mm): origin at the centre of the
base, z up (the effector hangs below the base: z < 0). Frame (p, I).

Geometry of arm i ∈ {a, b, c} (parameters ``angle_a``, ``radius_a``, …):

* e_r = (cos θ_i, sin θ_i, 0), e_t, e_z: the arm's radial and tangential directions at
  angle θ_i (``angle``; nominally 90°, 210°, 330°);
* the shoulder (on the motor axis) at S_i = r_i e_r + h_i e_z (``radius``: the shoulder's
  distance from the axis of the base *minus* that of the effector joints, which enter only
  through it; ``height``);
* the motor axis k_i and the arm's plane: Q_i = Rz(θ_i + ψ_i) Rx(χ_i), k_i = Q_i e_y,
  v1 = Q_i e_x (outwards), v2 = −Q_i e_z (downwards), ψ_i the axis' yaw and χ_i its tilt
  (``axis_yaw``, ``axis_tilt``; 0 for an axis tangent to the base circle, horizontal);
* the elbow at E_i = S_i + a_i (cos φ_i v1 + sin φ_i v2), φ_i the upper arm's angle below
  the outward horizontal (``upper`` = a_i);
* the forearm joins E_i to the effector joint centre q = p − t (``forearm`` b_i; t the
  tool offset ``tool.x/y/z``): |E_i − q| = b_i.

Readings: the motor angles λ_i = φ_i − ζ_i (``lambda1..3``, rad inside, degrees in files),
ζ_i the motor's zero offset (``zero``).

Inverse kinematics (closed form). With d = S_i − q: A cos φ + B sin φ = C, A = 2a d·v1,
B = 2a d·v2, C = b² − a² − |d|²; φ = atan2(B, A) + arccos(C / hypot(A, B)), the elbow-out
branch (the elbow outside the line from the shoulder to the effector joint; the other
root folds the arm inwards).

Jacobians (analytic). With w = E_i − q and G = a w·(−sin φ v1 + cos φ v2) (zero at the
singularity where the forearm is in line with the upper arm's motion), a change of the
elbow dE, of q and of b gives dφ = −(w·(dE − dq) − b db)/G.

Forward kinematics (closed form): the elbows from the readings, then q the intersection of
the three spheres of radius b_i about them, below the elbows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import FKResult, LimitReport
from pkmcal.mechanisms.translating import ArmLayout, TranslatingMechanism
from pkmcal.mechanisms.trilateration import trilaterate

#: The parameter vector: per arm ``angle, radius, height, upper, forearm, zero, axis_yaw,
#: axis_tilt``, then the tool offset.
LAYOUT = ArmLayout(("angle", "radius", "height", "upper", "forearm", "zero", "axis_yaw", "axis_tilt"),
                   frozenset({"angle", "zero", "axis_yaw", "axis_tilt"}))
ARMS = LAYOUT.arms
ARM_PARAMS = LAYOUT.params
TOOL_PARAMS = LAYOUT.tool
PARAM_NAMES = LAYOUT.names
PARAM_IS_ANGLE = LAYOUT.is_angle
NOMINAL_ANGLES_DEG = (90.0, 210.0, 330.0)
#: FK is converged where the IK of its pose reproduces the readings within this (rad).
FK_TOL = 1e-10
param_position = LAYOUT.position
_arms = LAYOUT.split


def _geometry(g: dict):
    """Per arm (rows): shoulders S (3, 3), e_r, e_t, v1, v2, k (3, 3 each)."""
    th, psi, chi = g["angle"], g["axis_yaw"], g["axis_tilt"]
    z0 = np.zeros(3)
    e_r = np.stack([np.cos(th), np.sin(th), z0], axis=1)
    e_t = np.stack([-np.sin(th), np.cos(th), z0], axis=1)
    S = g["radius"][:, None] * e_r + g["height"][:, None] * np.array([0.0, 0.0, 1.0])
    c, s = np.cos(th + psi), np.sin(th + psi)
    cx, sx = np.cos(chi), np.sin(chi)
    # Q = Rz(θ + ψ) Rx(χ): columns Q e_x, Q e_y, Q e_z
    Qx = np.stack([c, s, z0], axis=1)
    Qy = np.stack([-s * cx, c * cx, sx], axis=1)
    Qz = np.stack([s * sx, -c * sx, cx], axis=1)
    return S, e_r, e_t, Qx, -Qz, Qy


@dataclass(frozen=True, eq=False)
class RotaryDelta(TranslatingMechanism):
    """A rotary delta (module docstring). ``rho`` (27,) internal units (mm, rad) in the
    order of :data:`PARAM_NAMES`; ``motor_range`` (2,) the motor angles' limits (rad);
    ``max_joint_angle`` the largest angle of a forearm from the vertical at the effector
    (rad, the ball joints' cone); the workspace a cylinder of ``workspace_radius`` between
    ``z_range``."""

    name: str
    rho: np.ndarray
    motor_range: tuple[float, float] = (np.deg2rad(-40.0), np.deg2rad(100.0))
    max_joint_angle: float = np.deg2rad(60.0)
    workspace_radius: float = 400.0
    z_range: tuple[float, float] = (-1000.0, -500.0)
    description: str = ""
    covariance: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    kind: ClassVar[str] = "rotary-delta"
    #: Planning keeps safety margins from its limits (:mod:`pkmcal.planning.margins`).
    abilities: ClassVar[frozenset[str]] = frozenset({"translating", "safety-margins"})
    PARAM_NAMES: ClassVar[tuple[str, ...]] = PARAM_NAMES
    PARAM_IS_ANGLE: ClassVar[tuple[bool, ...]] = PARAM_IS_ANGLE
    LABEL: ClassVar[str] = "rotary delta"
    #: Parameters held unless freed by name (the tool offset: exactly absorbed by the
    #: shoulders' positions for a sensor that sees the tool point only).
    default_fixed: ClassVar[tuple[str, ...]] = TOOL_PARAMS

    def __post_init__(self) -> None:
        self._freeze_params()

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return bool(self.name == other.name and np.array_equal(self.rho, other.rho)
                    and tuple(self.motor_range) == tuple(other.motor_range)
                    and self.max_joint_angle == other.max_joint_angle
                    and self.workspace_radius == other.workspace_radius
                    and tuple(self.z_range) == tuple(other.z_range))

    __hash__ = None  # type: ignore[assignment]

    @property
    def actuator_is_angle(self) -> tuple[bool, ...]:
        return (True, True, True)

    @property
    def home_pose(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.5 * (self.z_range[0] + self.z_range[1])])

    def parameter_problem(self) -> tuple[str, str] | None:
        if not np.all(np.isfinite(self.rho)):
            return PARAM_NAMES[int(np.flatnonzero(~np.isfinite(self.rho))[0])], "is not a finite number"
        g = _arms(self.rho)
        for i, t in enumerate(ARMS):
            for p in ("radius", "upper", "forearm"):
                if g[p][i] <= 0:
                    return f"{p}_{t}", "must be positive (mm)"
            if g["forearm"][i] <= g["upper"][i] * 0.5:
                return f"forearm_{t}", f"must be longer than half of upper_{t}"
            for p in ("axis_yaw", "axis_tilt"):
                if abs(g[p][i]) >= np.pi / 4:
                    return f"{p}_{t}", "must be within ±45°"
        angles = np.sort(np.mod(g["angle"], 2 * np.pi))
        if np.min(np.diff(np.r_[angles, angles[0] + 2 * np.pi])) < np.deg2rad(10.0):
            return "angle_a", "the three arms must be at least 10° apart"
        return None

    def workspace_box(self) -> np.ndarray:
        r = self.workspace_radius
        return np.array([[-r, r], [-r, r], list(self.z_range)])

    def summary(self) -> str:
        g = _arms(self.rho)
        lines = [f"{self.name}: rotary delta (3 motors, pose x, y, z of the tool point, readings lambda1..3 = "
                 "motor angles)"]
        for i, t in enumerate(ARMS):
            lines.append(f"  arm {t}: angle {np.rad2deg(g['angle'][i]):.3f} deg, radius {g['radius'][i]:.3f} mm, "
                         f"height {g['height'][i]:.3f} mm, upper {g['upper'][i]:.3f} mm, forearm "
                         f"{g['forearm'][i]:.3f} mm, zero {np.rad2deg(g['zero'][i]):.3f} deg")
        lo, hi = np.rad2deg(self.motor_range)
        lines.append(f"  motors {lo:g}..{hi:g} deg; forearms within {np.rad2deg(self.max_joint_angle):g} deg of "
                     f"vertical; workspace radius {self.workspace_radius:g} mm, z {self.z_range[0]:g}.."
                     f"{self.z_range[1]:g} mm")
        return "\n".join(lines)

    # -- kinematics ------------------------------------------------------------------------

    @staticmethod
    def _angles(q, g, S, v1, v2):
        """φ (N, 3) of effector joint centres q (N, 3); NaN where an arm cannot reach."""
        d = S[None] - q[:, None, :]
        a, b = g["upper"][None, :], g["forearm"][None, :]
        A = 2 * a * np.einsum("ntk,tk->nt", d, v1)
        B = 2 * a * np.einsum("ntk,tk->nt", d, v2)
        C = b**2 - a**2 - np.einsum("ntk,ntk->nt", d, d)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.arctan2(B, A) + np.arccos(C / np.hypot(A, B))

    def elbows(self, readings: np.ndarray, params=None) -> np.ndarray:
        """Elbow positions (N, 3, 3) of motor readings (N, 3)."""
        g = _arms(self._rho(params))
        S, _, _, v1, v2, _ = _geometry(g)
        phi = np.asarray(readings, dtype=float) + g["zero"][None, :]
        return S[None] + g["upper"][None, :, None] * (np.cos(phi)[..., None] * v1[None] + np.sin(phi)[..., None]
                                                     * v2[None])

    def ik(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params, jacobians=False)[0]

    def ik_and_jacobians(self, poses: np.ndarray, params=None, jacobians: bool = True):
        """(λ (N, 3), ∂λ/∂pose (N, 3, 3), ∂λ/∂ρ (N, 3, 27)) in one pass (module docstring)."""
        poses = self.as_pose_array(poses)
        g = _arms(self._rho(params))
        S, e_r, e_t, v1, v2, k = _geometry(g)
        q = poses - g["tool"][None, :]
        phi = self._angles(q, g, S, v1, v2)
        lam = phi - g["zero"][None, :]
        if not jacobians:
            return lam, None, None
        c, s = np.cos(phi)[..., None], np.sin(phi)[..., None]
        a = g["upper"][None, :, None]
        u_arm = c * v1[None] + s * v2[None]                    # (N, 3, 3) upper arm direction
        E = S[None] + a * u_arm
        w = E - q[:, None, :]
        G = np.einsum("ntk,ntk->nt", w, a * (-s * v1[None] + c * v2[None]))
        with np.errstate(divide="ignore", invalid="ignore"):
            A = w / G[..., None]                               # ∂φ/∂p (dq = dp)
            ez = np.array([0.0, 0.0, 1.0])
            dE = {                                             # ∂E/∂(parameter) per arm (N, 3, 3)
                "angle": g["radius"][None, :, None] * e_t[None] + a * np.cross(ez, u_arm),
                "radius": np.broadcast_to(e_r[None], w.shape),
                "height": np.broadcast_to(ez, w.shape),
                "upper": u_arm,
                "axis_yaw": a * np.cross(ez, u_arm),
                "axis_tilt": a * s * k[None],
            }
            n = len(poses)
            Bj = np.zeros((n, 3, len(PARAM_NAMES)))
            for p, de in dE.items():
                col = [param_position(p, i) for i in range(3)]
                Bj[:, range(3), col] = -np.einsum("ntk,ntk->nt", w, de) / G
            Bj[:, range(3), [param_position("forearm", i) for i in range(3)]] = g["forearm"][None, :] / G
            Bj[:, range(3), [param_position("zero", i) for i in range(3)]] = -1.0
            Bj[:, :, -3:] = -A                                 # dq = −dt
        return lam, A, Bj

    def actuator_pose_jacobian(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[1]

    def actuator_param_jacobian(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[2]

    def fk(self, readings: np.ndarray, guess: np.ndarray | None = None, params=None, **options) -> FKResult:
        """Closed-form FK (module docstring): exact, so neither ``guess`` nor the shared
        solver's ``options`` apply."""
        lam = np.asarray(readings, dtype=float)
        lam = lam[None, :] if lam.ndim == 1 else lam
        if lam.ndim != 2 or lam.shape[1] != 3:
            raise PkmcalError(f"machine '{self.name}' needs 3 readings per pose; got an array of shape {lam.shape}")
        g = _arms(self._rho(params))
        q, ok = trilaterate(self.elbows(lam, params), g["forearm"])
        poses = q + g["tool"][None, :]
        with np.errstate(invalid="ignore"):
            back = self.ik(np.where(ok[:, None], poses, 0.0), params)
            res = np.max(np.abs(np.angle(np.exp(1j * (back - lam)))), axis=1)
        conv = ok & (res <= FK_TOL)
        return FKResult(poses=np.where(conv[:, None], poses, np.nan), converged=conv,
                        iterations=np.zeros(len(lam), dtype=int), residual=np.where(ok, res, np.inf))

    def assembly_signs(self, poses: np.ndarray, params=None) -> np.ndarray:
        """Per arm, the sign of G (module docstring): +1 on the elbow-out branch the IK
        chooses, 0 at the singularity."""
        poses = self.as_pose_array(poses)
        rho = self._rho(params)
        g = _arms(rho)
        _, _, _, v1, v2, _ = _geometry(g)
        lam = self.ik(poses, rho)
        phi = lam + g["zero"][None, :]
        w = self.elbows(lam, rho) - (poses - g["tool"][None, :])[:, None, :]
        G = np.einsum("ntk,ntk->nt", w, -np.sin(phi)[..., None] * v1[None] + np.cos(phi)[..., None] * v2[None])
        return np.sign(np.nan_to_num(-G)).astype(np.int8)

    def reading_range(self) -> np.ndarray:
        """(3, 2): the motor range less the zero offsets (rad)."""
        zero = _arms(self.rho)["zero"]
        return np.stack([self.motor_range[0] - zero, self.motor_range[1] - zero], axis=1)

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """``reach``, ``motor_range`` (rad; ``margin`` in rad), ``joint_angle`` (a forearm
        more than :attr:`max_joint_angle` from the vertical), ``workspace`` (the cylinder)."""
        poses = self.as_pose_array(poses)
        g = _arms(self.rho)
        lam = self.ik(poses)
        phi = lam + g["zero"][None, :]
        reach = np.all(np.isfinite(lam), axis=1)
        lo, hi = self.motor_range
        motor_m = np.where(reach[:, None], np.minimum(phi - lo, hi - phi), -np.inf).min(axis=1) - margin
        with np.errstate(invalid="ignore"):
            E = self.elbows(np.where(reach[:, None], lam, 0.0))
            f = E - (poses - g["tool"][None, :])[:, None, :]
            tilt = np.arccos(np.clip(f[..., 2] / g["forearm"][None, :], -1.0, 1.0))
        joint_m = np.where(reach, self.max_joint_angle - tilt.max(axis=1), -np.inf)
        r = np.hypot(poses[:, 0], poses[:, 1])
        ws_m = np.minimum.reduce([self.workspace_radius - r, poses[:, 2] - self.z_range[0],
                                  self.z_range[1] - poses[:, 2]])
        limit_margins = {"reach": np.where(reach, 0.0, -np.inf), "motor_range": motor_m, "joint_angle": joint_m,
                         "workspace": ws_m}
        return LimitReport(violations={k: ~(v >= 0) for k, v in limit_margins.items()}, margins=limit_margins)


def symmetric_rotary_delta(name: str, radius: float, upper: float, forearm: float, height: float = 0.0,
                           **limits) -> RotaryDelta:
    """An ideal rotary delta: arms at 90°, 210°, 330°, equal lengths, axes tangent and level."""
    rho = np.zeros(len(PARAM_NAMES))
    for i in range(3):
        rho[param_position("angle", i)] = np.deg2rad(NOMINAL_ANGLES_DEG[i])
        rho[param_position("radius", i)] = radius
        rho[param_position("height", i)] = height
        rho[param_position("upper", i)] = upper
        rho[param_position("forearm", i)] = forearm
    return RotaryDelta(name=name, rho=rho, **limits)


__all__ = ["ARMS", "ARM_PARAMS", "LAYOUT", "PARAM_NAMES", "RotaryDelta", "param_position", "symmetric_rotary_delta"]

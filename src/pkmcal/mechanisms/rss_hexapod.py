"""Rotary hexapods (6-RSS: motion simulators, most hobby Stewart platforms): six motors on the
base each turn a crank; a rod with ball joints at both ends joins the crank end to the
platform.

Pose x, y, z, a, b, c of the platform frame {P} in the base frame {F} (the pose convention
of :mod:`pkmcal.conventions`, as the 6-UPS hexapod). Parameters of leg i (11 per leg, 66):

* ``s<i>.x, s<i>.y, s<i>.z``: the crank pivot S_i on the motor axis (base frame, mm);
* ``beta_<i>``, ``tilt_<i>``: the crank plane. Q_i = Rz(β_i) Rx(χ_i); the crank turns in
  the plane spanned by v1 = Q_i e_x (its direction at angle 0) and v2 = Q_i e_z, about the
  motor axis k_i = Q_i e_y (χ = 0: a horizontal axis, the crank turning in a vertical plane
  of azimuth β);
* ``crank_<i>`` = c_i (mm) and ``rod_<i>`` = r_i (mm);
* ``a<i>.x, a<i>.y, a<i>.z``: the platform ball joint a_i (platform frame, mm);
* ``zero_<i>`` = ζ_i: the motor's zero offset; the reading is λ_i = φ_i − ζ_i (rad inside,
  degrees in files), φ_i the crank angle from v1 towards v2.

Crank end C_i = S_i + c_i u_i, u_i = cos φ_i v1 + sin φ_i v2; platform joint
P_i = p + R a_i; the rod closes the loop: |P_i − C_i| = r_i.

Inverse kinematics (closed form). With d = S_i − P_i: A cos φ + B sin φ = D, A = 2c d·v1,
B = 2c d·v2, D = r² − c² − |d|², so φ = atan2(B, A) + arccos(D / hypot(A, B)): the branch
whose crank end lies on the far side of the line S–P from the crank's motion (for the usual
design, crank near horizontal and rod near vertical, φ ≈ 0 at home); NaN where the rod
cannot reach.

Jacobians (analytic, implicit differentiation of f = |P − C|² − r² = 0). With
w = C − P and G = c w·(−sin φ v1 + cos φ v2) (zero where the rod is in line with the crank's
motion, the singularity), ∂φ/∂ξ = −(∂f/∂ξ)/(2G):

    ∂φ/∂(δp, δω) = [w, (R a) × w] / G                 (the twist; × T for the pose)
    ∂φ/∂S = −w/G,   ∂φ/∂c = −w·u/G,   ∂φ/∂r = r/G,   ∂φ/∂a = wᵀR/G,
    ∂φ/∂β = −w·(e_z × (C − S))/G,   ∂φ/∂χ = −w·(e_χ × (C − S))/G,   ∂λ/∂ζ = −1

(e_χ = Rz(β) e_x, the axis of the tilt; ∂Q/∂β = [e_z]× Q, ∂Q/∂χ = [e_χ]× Q).
Forward kinematics: the shared batched solver (:mod:`pkmcal.mechanisms.solver`) on the
loop-closure equations, not on λ − IK(x): with the readings the crank ends C_i are known, and
the platform solves the Gough–Stewart problem |P_i(x) − C_i| = r_i,

    e_i(x) = (r_i² − |P_i − C_i|²) / (2 r_i)   (≈ r_i − |P_i − C_i|, mm),
    −∂e_i/∂(δp, δω) = [w, (R a) × w] / r_i,   w = P_i − C_i,

which is finite at every pose, whereas IK is NaN wherever one rod cannot reach its crank: a
start pose just outside one leg's reach (the commanded pose at a trial machine of a fit)
left the solver without a direction, though the solution was ~1 mm away. A pose is
converged when IK(x) reproduces λ (``FK_RES_TOL``), which also rejects a closure solution
on the crank's other root.
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
LEG_PARAMS = ("s{i}.x", "s{i}.y", "s{i}.z", "beta_{i}", "tilt_{i}", "crank_{i}", "rod_{i}",
              "a{i}.x", "a{i}.y", "a{i}.z", "zero_{i}")
PER_LEG = len(LEG_PARAMS)
PARAM_NAMES = tuple(s.format(i=i + 1) for i in range(N_LEGS) for s in LEG_PARAMS)
_ANGLES = {"beta_{i}", "tilt_{i}", "zero_{i}"}
PARAM_IS_ANGLE = tuple(s in _ANGLES for _ in range(N_LEGS) for s in LEG_PARAMS)
#: Column of each per-leg quantity within a leg's block.
_S, _BETA, _TILT, _CRANK, _ROD, _A, _ZERO = 0, 3, 4, 5, 6, 7, 10


def _legs(rho: np.ndarray) -> dict[str, np.ndarray]:
    """Per-leg arrays of ρ (66,): S (6, 3), beta, tilt, crank, rod (6,), a (6, 3), zero (6,)."""
    g = np.asarray(rho, dtype=float).reshape(N_LEGS, PER_LEG)
    return {"S": g[:, _S:_S + 3], "beta": g[:, _BETA], "tilt": g[:, _TILT], "crank": g[:, _CRANK],
            "rod": g[:, _ROD], "a": g[:, _A:_A + 3], "zero": g[:, _ZERO]}


def _crank_planes(beta: np.ndarray, tilt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(v1, v2, e_χ) (6, 3) each: Q e_x, Q e_z of Q = Rz(β) Rx(χ), and Rz(β) e_x."""
    cb, sb, ct, st = np.cos(beta), np.sin(beta), np.cos(tilt), np.sin(tilt)
    v1 = np.stack([cb, sb, np.zeros_like(cb)], axis=1)
    v2 = np.stack([sb * st, -cb * st, ct], axis=1)
    return v1, v2, v1.copy()


@dataclass(frozen=True, eq=False)
class RSSHexapod(ParameterVector, SpatialPlatform):
    """A 6-RSS rotary hexapod (module docstring). ``rho`` (66,) in the order of
    :data:`PARAM_NAMES` (mm, rad); ``motor_range`` (2,) the crank angles' limits φ (rad);
    ``max_joint_angle`` the largest angle between a rod and the platform's z axis at its
    ball joint (rad); ``workspace`` (6, 2) the planning box (default about home: x, y
    ±0.8 c, z ±0.6 c, roll and pitch ±atan(0.4 c / r_p), yaw ±atan(0.6 c / r_p), c the mean
    crank, r_p the mean platform-joint radius); ``home`` (6,) the FK start pose (default: level, centred, at the height where
    the cranks are at φ = 0 on average)."""

    name: str
    rho: np.ndarray
    motor_range: tuple[float, float] = (np.deg2rad(-60.0), np.deg2rad(60.0))
    max_joint_angle: float = np.deg2rad(60.0)
    workspace: np.ndarray | None = None
    home: np.ndarray | None = None
    description: str = ""
    covariance: np.ndarray | None = None
    metadata: dict = field(default_factory=dict, compare=False)

    kind: ClassVar[str] = "6-RSS"
    PARAM_NAMES: ClassVar[tuple[str, ...]] = PARAM_NAMES
    PARAM_IS_ANGLE: ClassVar[tuple[bool, ...]] = PARAM_IS_ANGLE
    LABEL: ClassVar[str] = "6-RSS hexapod"
    actuator_names = tuple(f"lambda{i + 1}" for i in range(N_LEGS))
    point_sets = MappingProxyType({"crank pivots": tuple(f"s{i + 1}" for i in range(N_LEGS)),
                                   "platform joints": tuple(f"a{i + 1}" for i in range(N_LEGS))})

    def __post_init__(self) -> None:
        self._freeze_params()
        if self.home is None:
            object.__setattr__(self, "home", self._default_home())
        home = np.array(self.home, dtype=float).reshape(6)
        home.flags.writeable = False
        object.__setattr__(self, "home", home)
        if self.workspace is not None:
            ws = np.array(self.workspace, dtype=float).reshape(6, 2)
            ws.flags.writeable = False
            object.__setattr__(self, "workspace", ws)

    def parameter_problem(self) -> tuple[str, str] | None:
        """(name, what is wrong) of the first implausible parameter, or None."""
        if not np.all(np.isfinite(self.rho)):
            return PARAM_NAMES[int(np.flatnonzero(~np.isfinite(self.rho))[0])], "is not a finite number"
        g = _legs(self.rho)
        for i in range(N_LEGS):
            for p in ("crank", "rod"):
                if g[p][i] <= 0:
                    return f"{p}_{i + 1}", "must be positive (mm)"
            if g["rod"][i] <= g["crank"][i]:
                return f"rod_{i + 1}", f"must be longer than crank_{i + 1}"
            if abs(g["tilt"][i]) >= np.pi / 2:
                return f"tilt_{i + 1}", "must be within ±90°"
        return None

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        same = lambda x, y: (x is None and y is None) or (x is not None and y is not None  # noqa: E731
                                                          and np.array_equal(x, y))
        return bool(self.name == other.name and np.array_equal(self.rho, other.rho)
                    and tuple(self.motor_range) == tuple(other.motor_range)
                    and self.max_joint_angle == other.max_joint_angle and same(self.workspace, other.workspace)
                    and np.array_equal(self.home, other.home) and same(self.covariance, other.covariance)
                    and self.description == other.description)

    __hash__ = None  # type: ignore[assignment]

    @property
    def actuator_is_angle(self) -> tuple[bool, ...]:
        return (True,) * N_LEGS

    @property
    def home_pose(self) -> np.ndarray:
        return self.home

    def _default_home(self) -> np.ndarray:
        """Level and centred, at the height z where the mean crank angle is 0 (bisection on
        z over the reach; the rods' mean vertical reach as the starting bracket)."""
        g = _legs(self.rho)
        z_lo, z_hi = float(np.min(g["S"][:, 2])), float(np.max(g["S"][:, 2]) + 2 * np.max(g["rod"] + g["crank"]))

        def mean_phi(z: float) -> float:
            phi = self._phi(np.array([[0.0, 0.0, z, 0.0, 0.0, 0.0]]), self.rho)[0]
            return float(np.mean(phi)) if np.all(np.isfinite(phi)) else np.nan

        zs = np.linspace(z_lo, z_hi, 400)
        grid = np.zeros((len(zs), 6))
        grid[:, 2] = zs
        vals = np.mean(self._phi(grid, self.rho), axis=1)      # NaN where a rod cannot reach, as mean_phi
        ok = np.isfinite(vals)
        if not ok.any():
            raise PkmcalError(f"machine '{self.name}': no level, centred pose is reachable; check the rods and cranks")
        k = int(np.flatnonzero(ok)[np.argmin(np.abs(vals[ok]))])
        z = zs[k]
        for j in (k - 1, k + 1):                 # refine across a sign change of the grid
            if 0 <= j < len(zs) and ok[j] and np.sign(vals[j]) != np.sign(vals[k]):
                from scipy.optimize import brentq

                z = brentq(mean_phi, min(zs[j], zs[k]), max(zs[j], zs[k]), xtol=1e-12)
                break
        return np.array([0.0, 0.0, z, 0.0, 0.0, 0.0])

    def workspace_box(self) -> np.ndarray:
        if self.workspace is not None:
            return self.workspace.copy()
        g = _legs(self.rho)
        c, rp = float(np.mean(g["crank"])), float(np.mean(np.hypot(g["a"][:, 0], g["a"][:, 1])))
        tilt, yaw = np.arctan(0.4 * c / rp), np.arctan(0.6 * c / rp)
        span = np.array([0.8 * c, 0.8 * c, 0.6 * c, tilt, tilt, yaw])
        return np.stack([self.home - span, self.home + span], axis=1)

    def summary(self) -> str:
        g = _legs(self.rho)
        lo, hi = np.rad2deg(self.motor_range)
        return "\n".join([
            f"{self.name}: 6-RSS rotary hexapod, {len(PARAM_NAMES)} kinematic parameters (readings lambda1..6 = "
            "crank angles)",
            f"  crank pivots at radius {np.mean(np.hypot(g['S'][:, 0], g['S'][:, 1])):.3f} mm, platform joints at "
            f"radius {np.mean(np.hypot(g['a'][:, 0], g['a'][:, 1])):.3f} mm",
            f"  cranks {values_text(g['crank'], 'mm')}, rods {values_text(g['rod'], 'mm')}",
            f"  crank angles {lo:g}..{hi:g} deg; rods within {np.rad2deg(self.max_joint_angle):g} deg of the "
            "platform normal",
        ])

    # -- kinematics ------------------------------------------------------------------------

    def _loop(self, poses: np.ndarray, rho: np.ndarray):
        """(g, v1, v2, e_χ, R a (N, 6, 3), d = S − P (N, 6, 3))."""
        g = _legs(rho)
        v1, v2, ex = _crank_planes(g["beta"], g["tilt"])
        fr = Frame.from_poses(poses)
        Ra = np.einsum("nij,kj->nki", fr.R, g["a"])
        d = g["S"][None] - (poses[:, None, 0:3] + Ra)
        return g, v1, v2, ex, Ra, d, fr

    @staticmethod
    def _solve_phi(g, v1, v2, d) -> np.ndarray:
        c, r = g["crank"][None, :], g["rod"][None, :]
        A = 2 * c * np.einsum("nkj,kj->nk", d, v1)
        B = 2 * c * np.einsum("nkj,kj->nk", d, v2)
        D = r**2 - c**2 - np.einsum("nkj,nkj->nk", d, d)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.arctan2(B, A) + np.arccos(D / np.hypot(A, B))

    def _phi(self, poses: np.ndarray, rho: np.ndarray) -> np.ndarray:
        g, v1, v2, _, _, d, _ = self._loop(poses, rho)
        return self._solve_phi(g, v1, v2, d)

    def ik(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Crank readings λ = φ − ζ (N, 6), rad; NaN where a rod cannot reach."""
        rho = self._rho(params)
        return self._phi(self.as_pose_array(poses), rho) - _legs(rho)["zero"][None, :]

    def ik_and_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None):
        """(λ (N, 6), ∂λ/∂pose (N, 6, 6), ∂λ/∂ρ (N, 6, 66)) in one pass (module docstring)."""
        poses = self.as_pose_array(poses)
        rho = self._rho(params)
        g, v1, v2, ex, Ra, d, fr = self._loop(poses, rho)
        phi = self._solve_phi(g, v1, v2, d)
        lam = phi - g["zero"][None, :]
        cph, sph = np.cos(phi)[..., None], np.sin(phi)[..., None]
        u = cph * v1[None] + sph * v2[None]                       # crank direction (N, 6, 3)
        arm = g["crank"][None, :, None] * u                       # C − S
        w = d + arm                                               # C − P
        G = np.einsum("nkj,nkj->nk", w, g["crank"][None, :, None] * (-sph * v1[None] + cph * v2[None]))
        n = len(poses)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / G
            twist = np.concatenate([w, np.cross(Ra, w)], axis=2) * inv[..., None]
            A = euler_pose_jacobian(twist, poses)
            B = np.zeros((n, N_LEGS, len(PARAM_NAMES)))
            legs, base = np.arange(N_LEGS), np.arange(N_LEGS) * PER_LEG
            ez = np.array([0.0, 0.0, 1.0])
            for k in range(3):
                B[:, legs, base + _S + k] = -w[..., k] * inv
            B[:, legs, base + _BETA] = -np.einsum("nkj,nkj->nk", w, np.cross(ez, arm)) * inv
            B[:, legs, base + _TILT] = -np.einsum("nkj,nkj->nk", w, np.cross(ex[None], arm)) * inv
            B[:, legs, base + _CRANK] = -np.einsum("nkj,nkj->nk", w, u) * inv
            B[:, legs, base + _ROD] = g["rod"][None, :] * inv
            wR = np.einsum("nkj,nji->nki", w, fr.R)                # wᵀ R
            for k in range(3):
                B[:, legs, base + _A + k] = wR[..., k] * inv
            B[:, legs, base + _ZERO] = -1.0
        return lam, A, B

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
        v1, v2, _ = _crank_planes(g["beta"], g["tilt"])
        S, c = g["S"], g["crank"][None, :, None]

        def crank_ends(readings: np.ndarray) -> np.ndarray:                      # C (M, 6, 3)
            phi = (readings + g["zero"][None, :])[..., None]
            return S[None] + c * (np.cos(phi) * v1[None] + np.sin(phi) * v2[None])

        return leg_closure(crank_ends, g["a"], g["rod"])

    def fk(self, readings: np.ndarray, guess: np.ndarray | None = None, params: np.ndarray | None = None,
           **options):
        """Poses from crank readings λ (N, 6) by the shared solver on the loop-closure
        equations (module docstring); ``options`` those of
        :func:`~pkmcal.mechanisms.solver.solve_fk`."""
        from pkmcal.mechanisms.solver import solve_fk

        return solve_fk(self, readings, guess, params, equations=self._closure(self._rho(params)), **options)

    def assembly_signs(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Per leg, the sign of G (module docstring): the crank's branch, 0 at the
        singularity; with the sign of det of the twist Jacobian (the platform's mode)."""
        poses = self.as_pose_array(poses)
        rho = self._rho(params)
        g, v1, v2, _, Ra, d, _ = self._loop(poses, rho)
        phi = self._solve_phi(g, v1, v2, d)
        cph, sph = np.cos(phi)[..., None], np.sin(phi)[..., None]
        w = d + g["crank"][None, :, None] * (cph * v1[None] + sph * v2[None])
        G = np.einsum("nkj,nkj->nk", w, -sph * v1[None] + cph * v2[None])
        return np.concatenate([np.sign(np.nan_to_num(G)), twist_signs(w, Ra)[:, None]], axis=1).astype(np.int8)

    # -- limits ----------------------------------------------------------------------------

    def reading_range(self) -> np.ndarray:
        """(6, 2): the crank range less the zero offsets (rad)."""
        zero = _legs(self.rho)["zero"]
        return np.stack([self.motor_range[0] - zero, self.motor_range[1] - zero], axis=1)

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """``reach`` (a rod cannot close), ``motor_range`` (rad; ``margin`` in rad),
        ``joint_angle`` (a rod more than :attr:`max_joint_angle` from the platform's z axis)."""
        poses = self.as_pose_array(poses)
        g, v1, v2, _, _, d, fr = self._loop(poses, self.rho)
        phi = self._solve_phi(g, v1, v2, d)
        reach = np.all(np.isfinite(phi), axis=1)
        lo, hi = self.motor_range
        with np.errstate(invalid="ignore"):
            motor_m = np.where(reach, np.min(np.minimum(phi - lo, hi - phi), axis=1), -np.inf) - margin
            rod = -(d + g["crank"][None, :, None] * (np.cos(phi)[..., None] * v1[None]
                                                       + np.sin(phi)[..., None] * v2[None]))   # P − C
            cosang = np.einsum("nkj,nj->nk", rod, fr.R[:, :, 2]) / g["rod"][None, :]
            tilt = np.arccos(np.clip(cosang, -1.0, 1.0))
        joint_m = np.where(reach, self.max_joint_angle - np.max(tilt, axis=1), -np.inf)
        values = {"reach": np.where(reach, 0.0, -np.inf), "motor_range": motor_m, "joint_angle": joint_m}
        return LimitReport(violations={k: ~(v >= 0) for k, v in values.items()}, margins=values if margins else {})


def symmetric_rss_hexapod(name: str, base_radius: float, platform_radius: float, crank: float, rod: float, *,
                          base_half_angle_deg: float = 10.0, platform_half_angle_deg: float = 50.0,
                          **fields) -> RSSHexapod:
    """A symmetric 6-RSS design: crank pivots in pairs at angles 120°k ± ``base_half_angle``
    on a circle of ``base_radius``, each crank turning in the vertical plane tangent to that
    circle and pointing away from its pair partner at angle 0; platform joints in pairs at
    120°k ± ``platform_half_angle`` on ``platform_radius`` (the pairs shifted by 60°, so that
    each rod leans over a crank end)."""
    rho = np.zeros(len(PARAM_NAMES))
    for i in range(N_LEGS):
        k, side = i // 2, (1 if i % 2 else -1)
        th = np.deg2rad(120.0 * k + side * base_half_angle_deg)
        tp = np.deg2rad(120.0 * k + side * platform_half_angle_deg)
        b = i * PER_LEG
        rho[b + _S:b + _S + 3] = [base_radius * np.cos(th), base_radius * np.sin(th), 0.0]
        rho[b + _BETA] = th + side * np.pi / 2            # tangent, away from the pair partner
        rho[b + _CRANK] = crank
        rho[b + _ROD] = rod
        rho[b + _A:b + _A + 3] = [platform_radius * np.cos(tp), platform_radius * np.sin(tp), 0.0]
    return RSSHexapod(name=name, rho=rho, **fields)


__all__ = ["PARAM_NAMES", "RSSHexapod", "symmetric_rss_hexapod"]

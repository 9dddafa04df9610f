"""Redundantly actuated planar machines of paper 3 (Jeon, Kim, Jeong, Kim, CIRP 2010, §3).

Both machines implement :class:`~pkmcal.mechanisms.base.Mechanism` with the pose x as the
independent coordinates q_u of the paper, so that (paper 3 eq. 1–5)

    Γ = ∂q/∂x  (:meth:`actuator_pose_jacobian`),   H = ∂q/∂ρ at fixed x
    (:meth:`actuator_param_jacobian`, encoder offsets included as parameters).

Encoder convention (one sign everywhere): the encoder *reading* of actuator i is the true
actuator position plus its indexing offset, ``q_i = θ_i + dq_i`` (rad for rotary, mm for
linear actuators), so ∂q_i/∂dq_i = +1. Paper 3's Δq_r is −dq in this convention.
The tool point P_t that the tracker reads is a sensor parameter
(:class:`pkmcal.sensors.planar_tool.PlanarToolSensor`, ``target.x/y`` = paper's P_tx, P_ty).

``planar-2dof-3act`` (paper case 1, Table 1, Fig. 2; reconstruction, see
docs/redundant-machines.md): three RR chains. Chain i: rotary actuator at base joint B_i,
proximal link l_i1 at absolute angle θ_i to the elbow A_i = B_i + l_i1 e(θ_i), distal link
l_i2 from A_i to the joint C_i of a triangular tool plate that translates (2 d.o.f.):
C_i = x + D_i u_i, u_i = e(β_i) with fixed β = (210°, 330°, 90°). Closure
‖C_i − A_i‖ = l_i2 gives

    θ_i = atan2(w_i) + σ_i arccos((l_i1² + ‖w_i‖² − l_i2²) / (2 l_i1 ‖w_i‖)),  w_i = C_i − B_i,

and, by implicit differentiation of f = ‖C_i − A_i‖² − l_i2² with g = C_i − A_i,
s = l_i1 gᵀe'(θ_i) (e' = de/dθ):  ∂θ/∂C = gᵀ/s, ∂θ/∂B = −gᵀ/s, ∂θ/∂l_i1 = −gᵀe(θ)/s,
∂θ/∂l_i2 = −l_i2/s, ∂C/∂x = I, ∂C/∂D_i = u_i.

``planar-3dof-4act`` (paper case 2, Table 2, Fig. 6, machine of In et al. 2008;
reconstruction): two parallel guide-ways; way i passes through (0, y_i) with direction
e(α_i); two sliders per way, at signed distance s_ij from (0, y_i). Slider j of way i
carries a leg of length ρ_ij to the revolute joint C_i; the tool plate joins C_1 and C_2
(distance L3). Pose x = (x, y, φ) of the plate: C_1,2 = (x, y) ∓ (L3/2) e(φ). Closure
‖C_i − O_i − s_ij d_i‖ = ρ_ij, with a = (C_i − O_i)·d_i, b = (C_i − O_i)·n_i:

    s_ij = a + τ_j √(ρ_ij² − b²),  τ = (−1, +1),  reading q_ij = s_ij + dq_ij,

    ∂s/∂C_i = d_i − τ_j (b/√) n_i,   ∂s/∂ρ_ij = τ_j ρ_ij/√,   ∂s/∂y_i = −∂s/∂C_i · e_y,
    ∂s/∂α_i = b + τ_j (b/√) a,       ∂C_{1,2}/∂L3 = ∓ e(φ)/2,  ∂C_{1,2}/∂φ = ∓ (L3/2) e'(φ).

IK returns NaN outside a chain's reach (no clipping: a clipped arccos/sqrt would create
false FK minima). Case 1's actuator angles are kept on one continuous branch
θ ∈ (−π/2, 3π/2] (the proximal links point upward in the workspace).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import LimitReport, Mechanism
from pkmcal.mechanisms.frame import Frame
from pkmcal.mechanisms.solver import FK_MAX_ITER, FK_TOL  # noqa: F401  (their FK: the shared solver)


def _e(t):
    return np.stack([np.cos(t), np.sin(t)], axis=-1)


def _frozen(a, shape=None) -> np.ndarray:
    arr = np.array(a, dtype=float)
    if shape is not None:
        arr = arr.reshape(shape)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class PlanarMechanism(Mechanism):
    """Common machinery of the planar machines: a named parameter vector, the platform frame
    in the plane z = 0, workspace box; FK is the shared solver (:mod:`.solver`: Gauss–Newton
    least squares over all l actuators, batched over poses)."""

    name: str
    rho: np.ndarray
    home: np.ndarray
    workspace: np.ndarray
    description: str = ""
    covariance: np.ndarray | None = None
    #: Free-form information kept in the machine file (e.g. the ``calibration`` block).
    metadata: dict = field(default_factory=dict)

    #: A platform frame in the plane z = 0 turning about z only (what the planar-tool sensor reads).
    abilities: ClassVar[frozenset[str]] = frozenset({"planar"})
    #: Parameter names, in the order of ``rho`` (set by each machine class).
    _names: ClassVar[tuple[str, ...]] = ()
    #: Parameters that are link lengths: a machine is impossible unless they are positive.
    _lengths: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "rho", _frozen(self.rho, (len(self._names),)))
        object.__setattr__(self, "home", _frozen(self.home, (self.n_dof,)))
        object.__setattr__(self, "workspace", _frozen(self.workspace, (self.n_dof, 2)))

    @property
    def param_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def params(self) -> np.ndarray:
        return self.rho.copy()

    def with_params(self, params: np.ndarray, name: str | None = None, covariance=None) -> "PlanarMechanism":
        params = np.asarray(params, dtype=float)
        if params.shape != (len(self._names),):
            raise PkmcalError(f"machine '{self.name}' has {len(self._names)} parameters; got {params.shape}")
        return replace(self, rho=params, name=self.name if name is None else name, covariance=covariance)

    def with_deltas(self, deltas: dict[str, float], name: str | None = None) -> "PlanarMechanism":
        """A copy with named parameters raised by the given amounts (internal units)."""
        rho = self.params
        for k, v in deltas.items():
            rho[self.param_index([k])] += v
        return self.with_params(rho, name=name)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return bool(self.name == other.name and np.array_equal(self.rho, other.rho)
                    and np.array_equal(self.home, other.home) and np.array_equal(self.workspace, other.workspace))

    __hash__ = None  # type: ignore[assignment]

    @property
    def home_pose(self) -> np.ndarray:
        return self.home

    def p(self, name: str) -> float:
        return float(self.rho[self._names.index(name)])

    def parameter_problem(self) -> tuple[str, str] | None:
        """``(name, why)`` of the first parameter that makes the machine impossible — not
        finite, or a link length (:attr:`_lengths`) that is not positive (a zero link makes
        every Jacobian singular) — or None. The machine-file loader calls it; a fit may pass
        through such values and is not checked."""
        for name, value in zip(self._names, self.rho):
            if not np.isfinite(value):
                return name, f"{value!r} is not a finite number"
        for name in self._lengths:
            if not self.p(name) > 0:
                return name, f"{self.p(name)!r} mm is not a link length: give a positive length (mm)"
        return None

    def workspace_box(self) -> np.ndarray:
        """The workspace box (n, 2) of the machine file (mm, rad)."""
        return self.workspace.copy()

    def _rho(self, params) -> np.ndarray:
        """ρ (p,): this machine's for ``params=None``."""
        return self.rho if params is None else self.as_param_vector(params)

    # -- the platform frame: p = (x, y, 0), R = Rz(φ) (R = I for the translating plate) ---

    #: Twist rows (δp_x, δp_y, δω_z) = (0, 1, 5) that the pose coordinates move, in order.
    _TWIST_ROWS: ClassVar[tuple[int, ...]] = (0, 1)

    def frame(self, poses: np.ndarray, params: np.ndarray | None = None) -> Frame:
        """The plate frame: p = (x, y, 0), R = Rz(φ), or I for a translating plate."""
        x = self.as_pose_array(poses)
        p = np.zeros((x.shape[0], 3))
        p[:, 0:2] = x[:, 0:2]
        R = np.zeros((x.shape[0], 3, 3))
        if self.n_dof == 3:
            c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
            R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
            R[:, 2, 2] = 1.0
        else:
            R[:] = np.eye(3)
        return Frame(p=p, R=R)

    def frame_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None) -> tuple[np.ndarray, None]:
        """``(T, None)``: T (N, 6, n) selects the twist rows δp_x, δp_y (and δω_z = δφ); the
        frame does not depend on ρ."""
        x = self.as_pose_array(poses)
        T = np.zeros((x.shape[0], 6, self.n_dof))
        T[:, list(self._TWIST_ROWS), np.arange(self.n_dof)] = 1.0
        return T, None

    def pose_jacobian_from_twist(self, J_twist: np.ndarray, poses: np.ndarray,
                                 params: np.ndarray | None = None) -> np.ndarray:
        """J_twist · T: the columns δp_x, δp_y (and δω_z) of the twist Jacobian."""
        return J_twist[..., list(self._TWIST_ROWS)]

    def poses_from_frame(self, frame: Frame) -> np.ndarray:
        """(x, y) or (x, y, φ = atan2(R₁₀, R₀₀)) of plate frames."""
        if self.n_dof == 2:
            return frame.p[:, 0:2].copy()
        return np.concatenate([frame.p[:, 0:2], np.arctan2(frame.R[:, 1, 0], frame.R[:, 0, 0])[:, None]], axis=1)

    @property
    def actuator_is_angle(self) -> tuple[bool, ...]:
        """True for every actuator of a machine with rotary actuators (readings in rad inside,
        degrees in files)."""
        return (self._actuator_unit.startswith("rotary"),) * self.n_actuators

    @property
    def param_is_angle(self) -> tuple[bool, ...]:
        """True for parameters that are angles (rad inside, degrees in files): the way
        directions α_i and the encoder offsets of rotary actuators."""
        return tuple(n.startswith("alpha") or (n.startswith("dq") and "rad" in self._actuator_unit)
                     for n in self._names)

    def summary(self) -> str:
        """A few human-readable lines describing the machine."""
        ang = self.param_is_angle
        vals = ", ".join(f"{n}={np.rad2deg(v) if a else v:.4g}{'°' if a else ''}"
                         for n, v, a in zip(self._names, self.rho, ang))
        box = ", ".join(f"{p} {np.rad2deg(lo) if a else lo:g}..{np.rad2deg(hi) if a else hi:g}"
                        for p, a, (lo, hi) in zip(self.pose_names, self.pose_is_angle, self.workspace))
        return "\n".join([
            f"{self.name}: {self.n_dof}-dof planar machine, {self.n_actuators} actuators ({self._actuator_unit}), "
            f"{len(self._names)} kinematic parameters" + (f" — {self.description}" if self.description else ""),
            f"  parameters (mm, deg): {vals}",
            f"  workspace: {box}",
        ])

    _actuator_unit: ClassVar[str] = "mm"

    def _workspace_margin(self, x: np.ndarray) -> np.ndarray:
        """Distance (N,) of poses x (N, n) inside the workspace box (negative outside)."""
        return np.min(np.minimum(x - self.workspace[:, 0], self.workspace[:, 1] - x), axis=1)

    def sample_poses(self, n: int, rng: np.random.Generator, shrink: float = 1.0) -> np.ndarray:
        """``n`` poses uniform in the workspace box (shrunk about its centre by ``shrink``)."""
        c = self.workspace.mean(axis=1)
        h = 0.5 * (self.workspace[:, 1] - self.workspace[:, 0]) * shrink
        return c + rng.uniform(-1.0, 1.0, size=(n, self.n_dof)) * h


# -- case 1 ------------------------------------------------------------------------------

_P2_NAMES = ("l11", "l12", "l21", "l22", "l31", "l32", "B1.x", "B1.y", "B2.x", "B2.y", "B3.x", "B3.y",
             "D1", "D2", "D3", "dq1", "dq2", "dq3")
#: Plate joint directions β_i (fixed; not calibration parameters) and elbow branches σ_i.
P2_BETA = np.deg2rad([210.0, 330.0, 90.0])
P2_ELBOW = np.array([1.0, -1.0, -1.0])


@dataclass(frozen=True, eq=False)
class Planar2Dof3Act(PlanarMechanism):
    """Paper 3 case 1: 2-d.o.f. translating tool plate, three rotary actuators (module doc)."""

    _names: ClassVar[tuple[str, ...]] = _P2_NAMES
    _lengths: ClassVar[tuple[str, ...]] = ("l11", "l12", "l21", "l22", "l31", "l32")
    min_transmission: float = np.deg2rad(15.0)

    kind = "planar-2dof-3act"
    pose_names = ("x", "y")
    pose_is_angle = (False, False)
    actuator_names = ("q1", "q2", "q3")
    _actuator_unit: ClassVar[str] = "rotary, rad"

    def _unpack(self, params=None):
        r = self._rho(params)
        l1 = r[[0, 2, 4]]
        l2 = r[[1, 3, 5]]
        B = r[6:12].reshape(3, 2)
        D = r[12:15]
        dq = r[15:18]
        return l1, l2, B, D, dq

    def _chains(self, poses, params=None):
        """Per chain: (w, theta, g, s) with w = C − B, g = C − A, s = l1 gᵀe'(θ)."""
        x = self.as_pose_array(poses)
        l1, l2, B, D, _ = self._unpack(params)
        u = _e(P2_BETA)
        C = x[:, None, :] + (D[:, None] * u)[None]
        w = C - B[None]
        d = np.linalg.norm(w, axis=2)
        cosg = (l1**2 + d**2 - l2**2) / (2.0 * l1 * d)
        with np.errstate(invalid="ignore"):
            theta = np.arctan2(w[..., 1], w[..., 0]) + P2_ELBOW * np.arccos(cosg)   # NaN out of reach
        # one continuous branch: θ in (π/2 − π, π/2 + π] (the proximal links point upward)
        theta = np.pi / 2 - np.remainder(np.pi / 2 - theta + np.pi, 2 * np.pi) + np.pi
        A = B[None] + l1[None, :, None] * _e(theta)
        g = C - A
        ep = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
        s = l1 * np.einsum("nik,nik->ni", g, ep)
        return w, theta, g, s, cosg

    def ik(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Encoder readings q_i = θ_i + dq_i (N, 3), rad."""
        _, theta, _, _, _ = self._chains(poses, params)
        return theta + self._unpack(params)[4]

    def actuator_pose_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Γ = ∂q/∂(x, y) (N, 3, 2) = gᵀ/s."""
        _, _, g, s, _ = self._chains(poses, params)
        return g / s[..., None]

    def actuator_param_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """H = ∂q/∂ρ (N, 3, 18) at fixed pose (module docstring)."""
        _, theta, g, s, _ = self._chains(poses, params)
        l1, l2, _, _, _ = self._unpack(params)
        N = g.shape[0]
        J = np.zeros((N, 3, len(self._names)))
        i = np.arange(3)
        dC = g / s[..., None]
        J[:, i, 2 * i] = -np.einsum("nik,nik->ni", g, _e(theta)) / s
        J[:, i, 2 * i + 1] = -l2 / s
        J[:, i, 6 + 2 * i] = -dC[..., 0]
        J[:, i, 7 + 2 * i] = -dC[..., 1]
        J[:, i, 12 + i] = np.einsum("nik,ik->ni", dC, _e(P2_BETA))
        J[:, i, 15 + i] = 1.0
        return J

    def assembly_signs(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """None (N, 0): each chain's working mode (elbow σ_i) is fixed by the IK, so every
        pose whose IK reproduces the readings has it; and three chains determine the
        translating plate uniquely (two circles about A_i − D_i u_i meet in at most two
        points, and the third chain picks one), so the mirror pose of two chains does not
        reproduce the third reading and is reported not converged."""
        return np.zeros((self.as_pose_array(poses).shape[0], 0), dtype=np.int8)

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """Workspace box, reach of every chain, and transmission angle (angle between the
        proximal and distal link, |sin| ≥ sin(min_transmission), away from singularity).
        These limits take no safety ``margin`` (accepted, not applied)."""
        x = self.as_pose_array(poses)
        _, _, g, s, cosg = self._chains(x)
        l1, l2, _, _, _ = self._unpack()
        limit_margins = {
            "workspace": self._workspace_margin(x),
            "reach": np.min(1.0 - np.abs(cosg), axis=1),
            "transmission": np.min(np.abs(s) / (l1 * l2), axis=1) - np.sin(self.min_transmission),
        }
        return LimitReport(violations={k: ~(m >= 0) for k, m in limit_margins.items()}, margins=limit_margins)


#: Paper 3 Table 1 nominal values, mm (l32 and B1, B2.y: see docs/redundant-machines.md).
P2_NOMINAL = dict(l11=280.0, l12=280.0, l21=280.0, l22=280.0, l31=280.0, l32=280.0,
                  **{"B1.x": -300.0, "B1.y": 0.0, "B2.x": 300.0, "B2.y": 0.0, "B3.x": 150.0, "B3.y": 420.0},
                  D1=215.0, D2=215.0, D3=215.0, dq1=0.0, dq2=0.0, dq3=0.0)
#: Paper 3 Table 1 identified errors (mm; the Δq in degrees converted to rad).
P2_TABLE1_ERRORS = {"l11": 0.089, "l12": -0.244, "l21": 0.024, "l22": -0.458, "l31": -0.177,
                    "B2.x": -0.547, "B3.x": -0.076, "B3.y": -0.037, "D1": -0.042, "D2": -0.029, "D3": 0.080,
                    "dq1": np.deg2rad(0.024), "dq2": np.deg2rad(0.064), "dq3": np.deg2rad(-0.057)}
#: Paper 3 Table 1 sensor (tool point) errors, mm.
P2_TABLE1_TOOL = {"target.x": 0.067, "target.y": -0.103}
#: Paper 3's identified set for case 1 (its Table 1 rows; tool point in the sensor).
P2_PAPER_FREE = ("l11", "l12", "l21", "l22", "l31", "B2.x", "B3.x", "B3.y", "D1", "D2", "D3",
                 "dq1", "dq2", "dq3")


def planar_2dof_3act() -> Planar2Dof3Act:
    """Paper 3 case 1 at its Table 1 nominal values (our reconstruction of the geometry)."""
    rho = np.array([P2_NOMINAL[n] for n in _P2_NAMES])
    return Planar2Dof3Act(
        name="planar-2dof-3act", rho=rho, home=np.array([0.0, 205.0]),
        workspace=np.array([[-60.0, 60.0], [160.0, 250.0]]),
        description="2-dof planar machine with 3 rotary actuators, paper 3 case 1 (Table 1; reconstructed)",
    )


# -- case 2 ------------------------------------------------------------------------------

_P3_NAMES = ("L3", "y1", "y2", "alpha1", "alpha2", "rho11", "rho12", "rho21", "rho22",
             "dq1", "dq2", "dq3", "dq4")
_TAU = np.array([-1.0, 1.0, -1.0, 1.0])   # slider j = 1 on the −d side of C_i, j = 2 on the + side
_WAY = np.array([0, 0, 1, 1])              # guide-way of each actuator
_SIDE = 2.0 * _WAY - 1.0                   # C_1 = (x, y) − (L3/2) e(φ), C_2 = … + …: ∓ of each actuator's joint


@dataclass(frozen=True, eq=False)
class Planar3Dof4Act(PlanarMechanism):
    """Paper 3 case 2: 3-d.o.f. tool plate on two guide-ways with four linear actuators."""

    _names: ClassVar[tuple[str, ...]] = _P3_NAMES
    #: L3: the plate joints' distance (0 leaves the plate angle φ undetermined); ρ_ij: the legs.
    _lengths: ClassVar[tuple[str, ...]] = ("L3", "rho11", "rho12", "rho21", "rho22")
    min_leg_angle: float = np.deg2rad(15.0)

    kind = "planar-3dof-4act"
    pose_names = ("x", "y", "phi")
    pose_is_angle = (False, False, True)
    actuator_names = ("q1", "q2", "q3", "q4")
    _actuator_unit: ClassVar[str] = "linear, mm"
    _TWIST_ROWS: ClassVar[tuple[int, ...]] = (0, 1, 5)

    def _unpack(self, params=None):
        r = self._rho(params)
        L3, y = r[0], r[1:3]
        alpha = r[3:5]
        rho = r[5:9]
        dq = r[9:13]
        return L3, y, alpha, rho, dq

    def _geometry(self, poses, params=None):
        x = self.as_pose_array(poses)
        L3, yw, alpha, rho, _ = self._unpack(params)
        ephi = _e(x[:, 2])
        C = np.stack([x[:, :2] - 0.5 * L3 * ephi, x[:, :2] + 0.5 * L3 * ephi], axis=1)    # (N, 2, 2)
        O = np.stack([np.zeros(2), yw], axis=1)                                            # (2 ways, 2)
        d = _e(alpha)
        nrm = np.stack([-np.sin(alpha), np.cos(alpha)], axis=-1)
        w = C[:, _WAY] - O[_WAY][None]                                                     # (N, 4, 2)
        a = np.einsum("nik,ik->ni", w, d[_WAY])
        b = np.einsum("nik,ik->ni", w, nrm[_WAY])
        with np.errstate(invalid="ignore"):
            root = np.sqrt(rho**2 - b**2)                     # NaN out of reach
        s = a + _TAU * root
        return x, ephi, d, nrm, a, b, root, s

    def ik(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Encoder readings q = s + dq (N, 4), mm."""
        *_, s = self._geometry(poses, params)
        return s + self._unpack(params)[4]

    def _dsdC(self, d, nrm, b, root):
        """∂s_ij/∂C_i (N, 4, 2) = d_i − τ_j (b/√) n_i."""
        return d[_WAY][None] - (_TAU * b / root)[..., None] * nrm[_WAY][None]

    def actuator_pose_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Γ = ∂q/∂(x, y, φ) (N, 4, 3); ∂C_i/∂φ = ∓(L3/2) e'(φ)."""
        x, ephi, d, nrm, a, b, root, s = self._geometry(poses, params)
        L3 = self._unpack(params)[0]
        dsdC = self._dsdC(d, nrm, b, root)
        eperp = np.stack([-ephi[:, 1], ephi[:, 0]], axis=-1)
        dCdphi = (0.5 * L3) * _SIDE[None, :, None] * eperp[:, None, :]
        return np.concatenate([dsdC, np.einsum("nik,nik->ni", dsdC, dCdphi)[..., None]], axis=2)

    def actuator_param_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """H = ∂q/∂ρ (N, 4, 13) at fixed pose."""
        x, ephi, d, nrm, a, b, root, s = self._geometry(poses, params)
        L3, yw, alpha, rho, _ = self._unpack(params)
        N = x.shape[0]
        J = np.zeros((N, 4, len(self._names)))
        dsdC = self._dsdC(d, nrm, b, root)
        J[:, :, 0] = np.einsum("nik,nik->ni", dsdC, 0.5 * _SIDE[None, :, None] * ephi[:, None, :])
        # O_i = (0, y_i): ∂s/∂y_i = −∂s/∂C_i · e_y  (y1 is column 1, y2 column 2)
        way_col = 1 + _WAY
        i = np.arange(4)
        J[:, i, way_col] = -dsdC[..., 1]
        # α_i: ∂d/∂α = n, ∂n/∂α = −d: ∂a/∂α = w·n = b, ∂b/∂α = −w·d = −a
        da, db = b, -a
        J[:, i, 3 + _WAY] = da - _TAU * (b / root) * db
        J[:, i, 5 + i] = _TAU * rho / root
        J[:, i, 9 + i] = 1.0
        return J

    def assembly_signs(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """sign b_i (N, 2): the side of guide-way i on which the plate joint C_i lies. The IK
        s_ij = a + τ_j √(ρ_ij² − b²) depends on b only through b², so C_i mirrored across its
        way gives the same readings: that is the assembly-mode change this flags."""
        b = self._geometry(poses, params)[5]
        with np.errstate(invalid="ignore"):
            return np.sign(np.nan_to_num(b[:, [0, 2]])).astype(np.int8)

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """Workspace box, leg reach (|b| < ρ) and leg angle to the way ≥ ``min_leg_angle``
        (a leg parallel to its way is a singularity), slider order on each way. These
        limits take no safety ``margin`` (accepted, not applied)."""
        x, ephi, d, nrm, a, b, root, s = self._geometry(poses)
        rho = self._unpack()[3]
        limit_margins = {
            "workspace": self._workspace_margin(x),
            "reach": np.min(rho - np.abs(b), axis=1),
            "leg_angle": np.min(np.abs(b) / rho, axis=1) - np.sin(self.min_leg_angle),
        }
        return LimitReport(violations={k: ~(m >= 0) for k, m in limit_margins.items()}, margins=limit_margins)


#: Paper 3 Table 2 nominal L3 and our reconstructed way and leg dimensions, mm / rad.
P3_NOMINAL = dict(L3=230.0, y1=0.0, y2=460.0, alpha1=0.0, alpha2=0.0,
                  rho11=340.0, rho12=340.0, rho21=340.0, rho22=340.0, dq1=0.0, dq2=0.0, dq3=0.0, dq4=0.0)
#: Paper 3 Table 2 identified errors. The table prints 8 values for its 9 names; we read
#: Δρ22 as the missing one (set to 0). α in degrees converted to rad.
P3_TABLE2_ERRORS = {"L3": 0.079, "rho11": -0.151, "rho12": -0.421, "rho21": 0.136, "rho22": 0.0,
                    "alpha1": np.deg2rad(-0.065), "alpha2": np.deg2rad(0.035)}
P3_TABLE2_TOOL = {"target.x": -0.111, "target.y": -0.064}
#: Paper 3's nine identified parameters (tool point in the sensor).
P3_PAPER_FREE = ("L3", "rho11", "rho12", "rho21", "rho22", "alpha1", "alpha2")


def planar_3dof_4act() -> Planar3Dof4Act:
    """Paper 3 case 2 at its Table 2 nominal L3 (other dimensions reconstructed)."""
    rho = np.array([P3_NOMINAL[n] for n in _P3_NAMES])
    return Planar3Dof4Act(
        name="planar-3dof-4act", rho=rho, home=np.array([0.0, 230.0, 0.0]),
        workspace=np.array([[-100.0, 100.0], [190.0, 270.0], [np.deg2rad(-25.0), np.deg2rad(25.0)]]),
        description="3-dof planar platform with 4 linear actuators on 2 guide-ways, paper 3 case 2 (Table 2; reconstructed)",
    )

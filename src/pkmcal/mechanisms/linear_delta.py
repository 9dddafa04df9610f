"""Linear delta robots (delta 3D printers, linear pick-and-place deltas): three carriages on
three rails ("towers"), each joined to the effector by a parallelogram arm of length L_i.

Pose: the tool point (nozzle) p = (x, y, z) in the machine frame {F} (mm), the firmware's
Cartesian coordinates: origin on the bed at the centre of the towers, z up. The effector
does not rotate (the parallelograms keep it level): its frame is (p, I).

Geometry of tower i ∈ {a, b, c} (parameters ``angle_a``, ``radius_a``, …):

* e_r = (cos θ_i, sin θ_i, 0), e_t = (−sin θ_i, cos θ_i, 0): the radial and tangential
  directions of the tower at angle θ_i (Klipper's ``angle``: 210°, 330°, 90° by default);
* the rail passes through B_i = r_i e_r on the bed plane (r_i: Klipper's ``delta_radius``,
  the horizontal distance of the carriage joints from the effector joints' centre — the
  carriage's and the effector's own joint offsets enter only through it, see below);
* the rail direction, leaning by α_i towards the centre and β_i sideways (``lean_radial``,
  ``lean_tangential``), is u_i = −sin α_i e_r + cos α_i sin β_i e_t + cos α_i cos β_i e_z
  (a unit vector; u_i = e_z for a vertical rail);
* the carriage joint is at C_i = B_i + s_i u_i, s_i its position along the rail;
* the arm joins C_i to the effector joint q = p − t (t: the tool offset ``tool.x/y/z``, the
  nozzle relative to the effector joints' centre), |C_i − q| = L_i (``arm``).

Inverse kinematics (closed form). With d = B_i − q, the constraint |d + s u|² = L² gives
s_i = −u·d + sqrt((u·d)² − |d|² + L²) (the carriage above the effector). For a vertical
rail this is Klipper's stepper position s = z + sqrt(L² − (x − x_i)² − (y − y_i)²).

Readings. λ_i (``lambda1..3``, mm) is the carriage position in the firmware's convention:
Klipper's stepper position, the carriage height the firmware computes. The machine counts
its travel from the endstop switch, so a reading means "travel H^fw_i − λ_i below the
switch", where H^fw_i is the switch's reading in the firmware configuration the readings
refer to (:attr:`LinearDelta.reading_reference`; Klipper's ``abs_endstop`` =
position_endstop + sqrt(arm² − radius²)). The switch itself sits where the carriage is when
the nozzle is at (0, 0, E_i), E_i = ``endstop_i`` (Klipper's ``position_endstop``): s at the
switch S_i = s_i((0, 0, E_i)). Hence

    λ_i = s_i(p) − S_i + H^fw_i,

which is s_i(p) for a machine whose parameters are its firmware's (H^fw = S, the default),
and gives a calibrated machine the readings its old firmware shows for the same physical
carriage positions. Exporting to firmware makes the readings refer to the new
configuration (:meth:`LinearDelta.as_firmware_reference`).

Exactly absorbed, so not parameters: offsets of the carriage joints (fixed to a carriage
that translates along u_i: a constant shift of B_i) and of the effector joints (a constant
shift of q), which change only B_i — that is r_i, θ_i and E_i. The tool offset t is a
common shift of all three B_i and E_i, hence also absorbed; it is a parameter, fixed by
default (:attr:`LinearDelta.default_fixed`), for sensors that see the nozzle and the
effector apart.

Jacobians (analytic). With w = C_i − q and D = w·u_i ≠ 0 (the arm not perpendicular to its
rail): ∂s/∂p = wᵀ/D; for a parameter change, from w·(dB + s du + u ds − dq) = L dL,
ds = (L dL − w·dB − s w·du + w·dq)/D with dq = −dt. ∂λ/∂ρ adds −∂S/∂ρ (S at the pose
(0, 0, E_i), whose height moves with E_i).

Forward kinematics (closed form): q is the intersection of the three spheres of radius
L_i about C_i (trilateration), the effector below the plane of the carriage joints.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import FKResult, LimitReport, NamedDirection
from pkmcal.mechanisms.translating import ArmLayout, TranslatingMechanism
from pkmcal.mechanisms.trilateration import trilaterate

#: The parameter vector: per tower (angles: θ, α, β) ``angle, radius, arm, endstop,
#: lean_radial, lean_tangential``, then the tool offset.
LAYOUT = ArmLayout(("angle", "radius", "arm", "endstop", "lean_radial", "lean_tangential"),
                   frozenset({"angle", "lean_radial", "lean_tangential"}))
TOWERS = LAYOUT.arms
TOWER_PARAMS = LAYOUT.params
TOOL_PARAMS = LAYOUT.tool
PARAM_NAMES = LAYOUT.names
PARAM_IS_ANGLE = LAYOUT.is_angle
#: Klipper's default tower angles (degrees): stepper_a, b, c.
KLIPPER_TOWER_ANGLES_DEG = (210.0, 330.0, 90.0)
#: The tower set's slide (mm) beyond which a print sits noticeably off its place on the bed
#: (the named direction's tolerance, :meth:`LinearDelta.named_directions`).
TOWER_SHIFT_TOLERANCE = 1.0
#: FK is converged where the IK of its pose reproduces the readings within this (mm).
FK_TOL = 1e-9
param_position = LAYOUT.position
_towers = LAYOUT.split


def _frames(g: dict[str, np.ndarray]):
    """e_r, e_t (3, 3), rail directions u (3, 3) and the derivatives of u with respect to
    θ, α and β (3, 3 each), one row per tower."""
    th, al, be = g["angle"], g["lean_radial"], g["lean_tangential"]
    z0 = np.zeros(3)
    e_r = np.stack([np.cos(th), np.sin(th), z0], axis=1)
    e_t = np.stack([-np.sin(th), np.cos(th), z0], axis=1)
    e_z = np.broadcast_to([0.0, 0.0, 1.0], (3, 3))
    ca, sa, cb, sb = np.cos(al)[:, None], np.sin(al)[:, None], np.cos(be)[:, None], np.sin(be)[:, None]
    u = -sa * e_r + ca * sb * e_t + ca * cb * e_z
    du_dth = -sa * e_t - ca * sb * e_r              # de_r/dθ = e_t, de_t/dθ = −e_r
    du_dal = -ca * e_r - sa * sb * e_t - sa * cb * e_z
    du_dbe = ca * cb * e_t - ca * sb * e_z
    return e_r, e_t, u, du_dth, du_dal, du_dbe


@dataclass(frozen=True, eq=False)
class LinearDelta(TranslatingMechanism):
    """A linear delta (module docstring). ``rho`` (21,) internal units (mm, rad) in the
    order of :data:`PARAM_NAMES`; ``reading_reference`` (3,) H^fw (mm), default the
    switch readings of ``rho`` itself; ``travel`` (3,) the rail length below each switch
    (mm): readings within [H^fw − travel, H^fw]."""

    name: str
    rho: np.ndarray
    reading_reference: np.ndarray | None = None
    travel: np.ndarray | float = 400.0
    print_radius: float = 85.0
    min_z: float = 0.0
    #: Smallest angle between an arm and the horizontal plane (rad).
    min_arm_angle: float = np.deg2rad(20.0)
    description: str = ""
    covariance: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    kind: ClassVar[str] = "linear-delta"
    #: Planning keeps safety margins from its limits (:mod:`pkmcal.planning.margins`).
    abilities: ClassVar[frozenset[str]] = frozenset({"translating", "safety-margins"})
    PARAM_NAMES: ClassVar[tuple[str, ...]] = PARAM_NAMES
    PARAM_IS_ANGLE: ClassVar[tuple[bool, ...]] = PARAM_IS_ANGLE
    LABEL: ClassVar[str] = "linear delta"
    #: Parameters held unless freed by name (exactly absorbed by the tower positions).
    default_fixed: ClassVar[tuple[str, ...]] = TOOL_PARAMS
    #: Held by default when the sensor reads only heights (a Z probe), as Klipper's
    #: DELTA_CALIBRATE holds them (klippy/kinematics/delta.py,
    #: ``DeltaCalibration.coordinate_descent_params``: the arms only in its extended mode,
    #: with printed distances): the arms, whose common scale with the radius heights leave
    #: to σ ≈ 1.5 % (a 100 mm part 1.5 mm off). A prior on the measured arms frees them.
    held_without_length: ClassVar[tuple[str, ...]] = ("arm_*",)
    #: Held by default when every reading is on the bed (a Z probe, a printed object), as
    #: Klipper holds them (it has none): the rail leans, which such readings confuse with the
    #: endstops and angles (fitted from a bed they make the print's shape worse, even with
    #: the printed object: docs/studies.md).
    held_on_one_plane: ClassVar[tuple[str, ...]] = ("lean_*",)

    def __post_init__(self) -> None:
        self._freeze_params()
        ref = self.switch_positions() if self.reading_reference is None else np.array(self.reading_reference,
                                                                                       dtype=float)
        if ref.shape != (3,) or not np.all(np.isfinite(ref)):
            raise PkmcalError(f"linear delta '{self.name}': reading_reference must be 3 finite numbers (mm)")
        ref.setflags(write=False)
        object.__setattr__(self, "reading_reference", ref)
        travel = np.broadcast_to(np.array(self.travel, dtype=float), (3,)).copy()
        if not np.all(travel > 0):
            raise PkmcalError(f"linear delta '{self.name}': the rail travel must be positive (mm)")
        travel.setflags(write=False)
        object.__setattr__(self, "travel", travel)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return bool(self.name == other.name and np.array_equal(self.rho, other.rho)
                    and np.array_equal(self.reading_reference, other.reading_reference)
                    and np.array_equal(self.travel, other.travel) and self.print_radius == other.print_radius
                    and self.min_z == other.min_z and self.min_arm_angle == other.min_arm_angle)

    __hash__ = None  # type: ignore[assignment]

    # -- declarations --------------------------------------------------------------------

    def as_firmware_reference(self, name: str | None = None) -> "LinearDelta":
        """This machine with its own parameters as the firmware configuration (after an
        export): readings λ_i = s_i, the switch readings S_i."""
        return replace(self, reading_reference=None, name=self.name if name is None else name)

    @property
    def home_pose(self) -> np.ndarray:
        """Where FK starts and the workspace's centre: the centre, at half the lowest switch
        height (the firmware homes to the top; this is inside the print volume)."""
        return np.array([0.0, 0.0, 0.5 * float(np.min(_towers(self.rho)["endstop"]))])

    def named_directions(self) -> tuple[NamedDirection, ...]:
        """The common scale ε of the three arms and radii (arm_i += ε L_i, radius_i += ε r_i):
        what Z-probe heights barely see (issue 13; Klipper's DELTA_CALIBRATE leaves the arms
        alone without DELTA_ANALYZE's printed distances); and the slide of the tower set in x
        and in y (:meth:`tower_shift`), which no height on a flat bed sees (issue 25 item 2)."""
        g = _towers(self.rho)
        direction = {f"arm_{t}": float(g["arm"][i]) for i, t in enumerate(TOWERS)}
        direction.update({f"radius_{t}": float(g["radius"][i]) for i, t in enumerate(TOWERS)})
        arm = float(np.mean(g["arm"]))
        scale = NamedDirection(
            meaning="a common scale of the arm lengths and the radius", direction=direction, unit="1",
            tolerance=1e-3,
            tolerance_why=f"0.1 % of the size, {1e-3 * arm:.2g} mm of a {arm:.4g} mm arm: a 100 mm print 0.1 mm off",
            remedy="add measurements that see a length (printed-object distances, a ballbar, a position sensor) or "
                   "priors on the measured arm lengths, e.g. --prior 'arm_*=" + f"{arm:.6g}" + "±0.1'")
        shifts = tuple(NamedDirection(
            meaning=f"where the tower set stands along {axis} on the bed (the firmware's origin; the probe's "
                    f"{axis}_offset likewise)", direction=self.tower_shift(k), unit="mm",
            tolerance=TOWER_SHIFT_TOLERANCE,
            tolerance_why=f"a print placed {TOWER_SHIFT_TOLERANCE:g} mm off on the bed",
            remedy="harmless to the print's shape and size (it moves prints on the bed as a whole; export puts the "
                   f"firmware's origin at the towers' centre); heights cannot check the probe's {axis}_offset either: "
                   "measure it by hand (the nozzle and the probe over one mark on the bed); to place prints exactly, "
                   "measure a printed mark from the bed's edge, or the nozzle with a position sensor",
            placement=True) for k, axis in enumerate("xy"))
        return (scale,) + shifts

    def tower_shift(self, axis: int) -> dict[str, float]:
        """The parameter change per mm that slides the tower set by 1 mm along base axis
        ``axis`` (0: x, 1: y) without changing any reading (first order): the machine moved
        as a whole, FK'(λ) = FK(λ) + δ. Rail i's foot B_i = r_i e_r(θ_i) moves by δ (dr_i =
        δ·e_r, dθ_i = δ·e_t / r_i); its direction u_i stays (its leans are measured in the
        tower's turned frame: dα_i = −dθ_i sin β_i, dβ_i = dθ_i tan α_i cos β_i, zero on a
        vertical rail and then left out); its switch keeps its rail position S_i, found at the
        nozzle (0, 0, E_i'): ∂s/∂p = wᵀ/D at the switch gives dE_i = w·δ / w_z, w = C_i − q there."""
        g = _towers(self.rho)
        e_r, e_t, u, *_ = _frames(g)
        _, W = self._switch(g, u, g["radius"][:, None] * e_r)
        delta = np.zeros(3)
        delta[axis] = 1.0
        out: dict[str, float] = {}
        for i, t in enumerate(TOWERS):
            dth = float(delta @ e_t[i]) / g["radius"][i]
            out[f"angle_{t}"] = dth
            out[f"radius_{t}"] = float(delta @ e_r[i])
            out[f"endstop_{t}"] = float(W[i] @ delta / W[i, 2])
            al, be = g["lean_radial"][i], g["lean_tangential"][i]
            out[f"lean_radial_{t}"] = float(-dth * np.sin(be))
            out[f"lean_tangential_{t}"] = float(dth * np.tan(al) * np.cos(be))
        return {n: c for n, c in out.items() if c != 0.0}

    def parameter_problem(self) -> tuple[str, str] | None:
        """``(name, why)`` of the first parameter that makes the machine impossible."""
        g = _towers(self.rho)
        if not np.all(np.isfinite(self.rho)):
            k = int(np.flatnonzero(~np.isfinite(self.rho))[0])
            return PARAM_NAMES[k], "is not a finite number"
        for i, t in enumerate(TOWERS):
            if g["radius"][i] <= 0:
                return f"radius_{t}", "must be positive (mm)"
            if g["arm"][i] <= g["radius"][i]:
                return f"arm_{t}", f"must be longer than radius_{t} (the nozzle could not reach the centre)"
            for lean in ("lean_radial", "lean_tangential"):
                if abs(g[lean][i]) >= np.pi / 4:
                    return f"{lean}_{t}", "must be within ±45° of vertical"
        angles = np.sort(np.mod(g["angle"], 2 * np.pi))
        gaps = np.diff(np.r_[angles, angles[0] + 2 * np.pi])
        if np.min(gaps) < np.deg2rad(10.0):
            return "angle_a", "the three towers must be at least 10° apart"
        return None

    def workspace_box(self) -> np.ndarray:
        """(3, 2) the box planning and ``info`` search in: the print radius in x and y,
        ``min_z`` to the lowest switch height in z (mm)."""
        top = float(np.min(_towers(self.rho)["endstop"]))
        return np.array([[-self.print_radius, self.print_radius], [-self.print_radius, self.print_radius],
                         [self.min_z, top]])

    def summary(self) -> str:
        g = _towers(self.rho)
        lines = [f"{self.name}: linear delta (3 towers, pose x, y, z of the nozzle, readings lambda1..3 = "
                 "carriage positions, Klipper's stepper positions)"]
        for i, t in enumerate(TOWERS):
            lines.append(f"  tower {t}: angle {np.rad2deg(g['angle'][i]):.3f} deg, radius {g['radius'][i]:.3f} mm, "
                         f"arm {g['arm'][i]:.3f} mm, endstop {g['endstop'][i]:.3f} mm, lean "
                         f"{np.rad2deg(g['lean_radial'][i]):.3f}/{np.rad2deg(g['lean_tangential'][i]):.3f} deg")
        lines.append(f"  print radius {self.print_radius:g} mm, z from {self.min_z:g} mm, arms at least "
                     f"{np.rad2deg(self.min_arm_angle):g} deg above horizontal")
        return "\n".join(lines)

    # -- kinematics ------------------------------------------------------------------------

    @staticmethod
    def _rail_positions(q: np.ndarray, g: dict, u: np.ndarray, B: np.ndarray):
        """s (N, 3) of effector-joint centres q (N, 3) and w = C − q (N, 3, 3); NaN where an
        arm cannot reach its rail."""
        d = B[None, :, :] - q[:, None, :]                       # (N, 3 towers, 3)
        ud = np.einsum("tk,ntk->nt", u, d)
        disc = ud**2 - np.einsum("ntk,ntk->nt", d, d) + g["arm"][None, :] ** 2
        with np.errstate(invalid="ignore"):
            s = -ud + np.sqrt(np.where(disc >= 0, disc, np.nan))
        w = d + s[:, :, None] * u[None, :, :]
        return s, w

    def _switch(self, g, u, B) -> tuple[np.ndarray, np.ndarray]:
        """S (3,) the rail position of each switch, and w (3, 3) there (tower i at the
        nozzle pose (0, 0, E_i)): the diagonal of the three poses' rail positions."""
        q = np.stack([np.zeros(3), np.zeros(3), g["endstop"]], axis=1) - g["tool"][None, :]
        s, w = self._rail_positions(q, g, u, B)
        k = np.arange(3)
        return s[k, k], w[k, k]

    def switch_positions(self, params=None) -> np.ndarray:
        """S (3,): the rail position of each tower's switch (module docstring), mm."""
        g = _towers(self._rho(params))
        e_r, _, u, *_ = _frames(g)
        return self._switch(g, u, g["radius"][:, None] * e_r)[0]

    def ik(self, poses: np.ndarray, params=None) -> np.ndarray:
        """λ (N, 3) mm; NaN where an arm cannot reach its rail."""
        return self.ik_and_jacobians(poses, params, jacobians=False)[0]

    def ik_and_jacobians(self, poses: np.ndarray, params=None, jacobians: bool = True):
        """(λ (N, 3), ∂λ/∂pose (N, 3, 3), ∂λ/∂ρ (N, 3, 21)) in one pass (module docstring)."""
        poses = self.as_pose_array(poses)
        rho = self._rho(params)
        g = _towers(rho)
        e_r, e_t, u, du_th, du_al, du_be = _frames(g)
        B = g["radius"][:, None] * e_r
        q = poses - g["tool"][None, :]
        s, w = self._rail_positions(q, g, u, B)
        S, W = self._switch(g, u, B)
        lam = s - S[None, :] + self.reading_reference[None, :]
        if not jacobians:
            return lam, None, None
        D = np.einsum("ntk,tk->nt", w, u)
        with np.errstate(divide="ignore", invalid="ignore"):
            A = w / D[:, :, None]                                # ∂s/∂p = wᵀ/D
        n = len(poses)
        Bj = np.zeros((n, 3, len(PARAM_NAMES)))

        def ds(w_, s_, D_, i, dB, du, dL):
            """ds for tower i of one parameter direction (module docstring); w_ (..., 3)."""
            return (g["arm"][i] * dL - w_ @ dB - s_ * (w_ @ du)) / D_

        D_sw = np.einsum("tk,tk->t", W, u)
        for i in range(3):    # three towers × six parameters: columns, not poses
            dirs = {"angle": (g["radius"][i] * e_t[i], du_th[i], 0.0), "radius": (e_r[i], np.zeros(3), 0.0),
                    "arm": (np.zeros(3), np.zeros(3), 1.0), "lean_radial": (np.zeros(3), du_al[i], 0.0),
                    "lean_tangential": (np.zeros(3), du_be[i], 0.0)}
            with np.errstate(divide="ignore", invalid="ignore"):
                for p, (dB, du, dL) in dirs.items():
                    col = param_position(p, i)
                    Bj[:, i, col] = ds(w[:, i], s[:, i], D[:, i], i, dB, du, dL) - ds(W[i], S[i], D_sw[i], i, dB,
                                                                                        du, dL)
                # the switch pose (0, 0, E_i) rises with E_i: −∂S/∂p · e_z
                Bj[:, i, param_position("endstop", i)] = -W[i, 2] / D_sw[i]
                # the tool offset: dq = −dt, at the pose and at the switch
                Bj[:, i, -3:] = -w[:, i] / D[:, i, None] + W[i] / D_sw[i]
        return lam, A, Bj

    def actuator_pose_jacobian(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[1]

    def actuator_param_jacobian(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[2]

    def fk(self, readings: np.ndarray, guess: np.ndarray | None = None, params=None, **options) -> FKResult:
        """Closed-form FK (trilateration, module docstring): exact, so neither ``guess`` nor
        the shared solver's ``options`` apply; the solution is the effector below its
        carriage joints, the branch the IK takes."""
        lam = np.asarray(readings, dtype=float)
        lam = lam[None, :] if lam.ndim == 1 else lam
        if lam.ndim != 2 or lam.shape[1] != 3:
            raise PkmcalError(f"machine '{self.name}' needs 3 readings per pose; got an array of shape {lam.shape}")
        rho = self._rho(params)
        g = _towers(rho)
        e_r, _, u, *_ = _frames(g)
        B = g["radius"][:, None] * e_r
        S, _ = self._switch(g, u, B)
        s = lam - self.reading_reference[None, :] + S[None, :]
        C = B[None, :, :] + s[:, :, None] * u[None, :, :]        # (N, 3, 3) carriage joints
        q, ok = trilaterate(C, g["arm"])
        poses = q + g["tool"][None, :]
        with np.errstate(invalid="ignore"):
            back = self.ik(np.where(ok[:, None], poses, 0.0), params)
            res = np.max(np.abs(back - lam), axis=1)
        conv = ok & (res <= FK_TOL * np.maximum(1.0, np.max(np.abs(lam), axis=1)))
        poses = np.where(conv[:, None], poses, np.nan)
        return FKResult(poses=poses, converged=conv, iterations=np.zeros(len(lam), dtype=int),
                        residual=np.where(ok, res, np.inf))

    def assembly_signs(self, poses: np.ndarray, params=None) -> np.ndarray:
        """One sign per tower: +1 where the effector is below the carriage joint along the
        rail's arm (w·u > 0, the branch the IK and FK choose), −1 above, 0 at the arm ⊥ rail
        singularity."""
        poses = self.as_pose_array(poses)
        g = _towers(self._rho(params))
        e_r, _, u, *_ = _frames(g)
        _, w = self._rail_positions(poses - g["tool"][None, :], g, u, g["radius"][:, None] * e_r)
        return np.sign(np.nan_to_num(np.einsum("ntk,tk->nt", w, u))).astype(np.int8)

    def reading_range(self) -> np.ndarray:
        """(3, 2): from the rail's end to the switch, [H^fw − travel, H^fw] (mm)."""
        return np.stack([self.reading_reference - self.travel, self.reading_reference], axis=1)

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """``reach`` (an arm cannot reach its rail), ``travel`` (a reading beyond the switch
        or the rail's end), ``arm_angle`` (an arm flatter than :attr:`min_arm_angle`),
        ``print_radius`` and ``min_z``; margins in mm (rad for the arm angle)."""
        poses = self.as_pose_array(poses)
        g = _towers(self.rho)
        e_r, _, u, *_ = _frames(g)
        B = g["radius"][:, None] * e_r
        s, w = self._rail_positions(poses - g["tool"][None, :], g, u, B)
        lam = s - self._switch(g, u, B)[0][None, :] + self.reading_reference[None, :]   # the IK's readings
        reach = np.all(np.isfinite(s), axis=1)
        hi = self.reading_reference[None, :]
        lo = hi - self.travel[None, :]
        travel_m = np.where(reach[:, None], np.minimum(hi - lam, lam - lo), -np.inf).min(axis=1) - margin
        with np.errstate(invalid="ignore"):
            elev = np.arcsin(np.clip(w[..., 2] / g["arm"][None, :], -1.0, 1.0))
        angle_m = np.min(np.where(np.isfinite(elev), elev, -np.inf), axis=1, initial=np.inf) - self.min_arm_angle
        radius_m = self.print_radius - np.hypot(poses[:, 0], poses[:, 1]) - margin
        z_m = poses[:, 2] - self.min_z
        limit_margins = {"reach": np.where(reach, 0.0, -np.inf), "travel": travel_m, "arm_angle": angle_m,
                         "print_radius": radius_m, "min_z": z_m}
        return LimitReport(violations={k: ~(v >= 0) for k, v in limit_margins.items()}, margins=limit_margins)


def klipper_delta(name: str, delta_radius: float, arm_length: float | tuple, position_endstop: float | tuple,
                  angles_deg: tuple = KLIPPER_TOWER_ANGLES_DEG, **limits) -> LinearDelta:
    """A linear delta from Klipper's ``[printer] kinematics: delta`` parameters (vertical
    rails, one radius, per-tower ``angle``, ``arm_length`` and ``position_endstop``)."""
    arms = np.broadcast_to(np.asarray(arm_length, dtype=float), (3,))
    ends = np.broadcast_to(np.asarray(position_endstop, dtype=float), (3,))
    rho = np.zeros(len(PARAM_NAMES))
    for i in range(3):
        rho[param_position("angle", i)] = np.deg2rad(angles_deg[i])
        rho[param_position("radius", i)] = delta_radius
        rho[param_position("arm", i)] = arms[i]
        rho[param_position("endstop", i)] = ends[i]
    return LinearDelta(name=name, rho=rho, **limits)


__all__ = ["KLIPPER_TOWER_ANGLES_DEG", "LAYOUT", "LinearDelta", "PARAM_NAMES", "TOWERS", "TOWER_PARAMS",
           "klipper_delta", "param_position"]

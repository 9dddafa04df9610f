"""The Gough–Stewart hexapod (6-UPS) and its 48 kinematic parameters.

Model (paper 2 §2.1 eq. 1–2, paper 1 §II eq. 1): leg i joins the base (universal) joint
b_i, given in the base frame {F}, to the platform (spherical) joint a_i, given in the
platform frame {P}; with the pose (p, R) of {P} in {F},

    l_i = p + R a_i − b_i,    L_i = ‖l_i‖,    L_i = L0_i + g_i λ_i,  λ_i = (L_i − L0_i) / g_i   (1)–(2)

where λ_i is the actuator reading in the instrument's unit (:attr:`Hexapod.actuator_unit`:
mm, motor revolutions, encoder counts, ...), L0_i the leg offset (mm) and g_i > 0 the leg's
gain (mm of leg length per reading unit; 1 for readings in mm, the papers' model). The
parameter vector ρ (48,) is ordered per leg i = 1..6 as ``b_i.x, b_i.y, b_i.z, a_i.x,
a_i.y, a_i.z, L0_i`` (the 42 parameters of papers 1 and 2), then the gains ``gain_1 ..
gain_6``, which the machine holds unless freed by name (:attr:`Hexapod.default_fixed`: only
a campaign that measures lengths, not just the readings' changes, can tell a gain from the
geometry's scale, and the papers hold them at 1).

Analytic derivatives, with the unit leg vector u_i = l_i / L_i:

    ∂λ_i/∂p = u_iᵀ / g_i,    ∂λ_i/∂δω = ((R a_i) × u_i)ᵀ / g_i,    ∂λ_i/∂(a,b,c) = ((R a_i) × u_i)ᵀ E / g_i
    ∂λ_i/∂b_i = −u_iᵀ / g_i,  ∂λ_i/∂a_i = u_iᵀ R / g_i,   ∂λ_i/∂L0_i = −1 / g_i,   ∂λ_i/∂g_i = −λ_i / g_i

(E from :func:`pkmcal.conventions.euler_rate_matrix`). With every g_i = 1 these are the
papers' formulas, bit for bit (a division by 1.0 is exact). Limits (paper 2 §5): actuator
stroke (in reading units, as the readings), U-joint tilt (angle between u_i and the base joint axis), S-joint tilt (angle
between u_i and the platform joint axis R n_i), leg–leg collision (minimum distance
between leg segments b_i → p + R a_i below the leg diameter) and a singularity margin
(inverse condition number of the length-scaled pose Jacobian). They are computed by a
compiled kernel (``_hexapod_kernels.limit_margins``) tested against the vectorised NumPy
formulas (:meth:`Hexapod._limit_margins_numpy`), which decide every pose near a limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from pkmcal.conventions import euler_to_matrix, values_text
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import FKResult, LimitReport
from pkmcal.mechanisms.spatial import SpatialPlatform

def _kernels():
    """The compiled kernels (:mod:`._hexapod_kernels`), imported on first use: numba takes
    ~0.5 s to import, which commands that never run the kinematics (``--help``, listings)
    should not pay."""
    from pkmcal.mechanisms import _hexapod_kernels

    return _hexapod_kernels


N_LEGS = 6
#: Geometry parameters per leg (b_i, a_i, L0_i): the first 6 × 7 = 42 entries of ρ.
PARAMS_PER_LEG = 7
N_GEOMETRY_PARAMS = N_LEGS * PARAMS_PER_LEG
_LEG_PARAM_SUFFIXES = ("b{i}.x", "b{i}.y", "b{i}.z", "a{i}.x", "a{i}.y", "a{i}.z", "L0_{i}")
#: The gains g_i, appended after the 42 geometry parameters.
GAIN_NAMES = tuple(f"gain_{i + 1}" for i in range(N_LEGS))
HEXAPOD_PARAM_NAMES = tuple(s.format(i=i + 1) for i in range(N_LEGS) for s in _LEG_PARAM_SUFFIXES) + GAIN_NAMES
#: The unit of readings in mm of leg length (gains 1): the default ``actuator_unit``.
DEFAULT_ACTUATOR_UNIT = "mm"

#: Batches of at least this many poses run the compiled IK kernel (0.08 µs/pose against NumPy's
#: 1.3 µs/pose at 100,000 poses); below it NumPy's ~40 µs per call is cheaper than importing numba.
COMPILED_FROM = 64
#: Default FK tolerance on leg lengths (mm) and iteration cap.
FK_TOL_MM = 1e-9
FK_MAX_ITER = 30
#: The limits checked, in the order of :class:`LimitReport` and of the compiled kernel's columns.
LIMIT_NAMES = ("stroke", "u_joint_tilt", "s_joint_tilt", "leg_collision", "singularity")
#: Batches of at least this many poses are checked by the compiled kernel; smaller ones by the
#: NumPy formulas (the same verdicts), so that a command on a few poses does not import numba.
LIMITS_COMPILED_FROM = 64
#: Limit margins of the compiled kernel closer than this to zero (mm, rad, or inverse
#: condition number) are recomputed by NumPy, so that the verdicts are NumPy's exactly;
#: over 10⁴ × the largest kernel–NumPy difference measured (5e-14 mm, the leg distance).
EXACT_VERDICT_TOL = 1e-9
#: Leg-length steps of the continuation that re-solves a row whose Newton FK converged on
#: another assembly mode than its guess (:meth:`Hexapod.fk_lengths`).
FK_CONTINUATION_STEPS = 8


@dataclass(frozen=True)
class HexapodLimits:
    """Joint and leg limits. Angles in radians, lengths in mm; ``None`` disables a check.

    ``singularity_margin`` is the smallest accepted inverse condition number of the pose
    Jacobian ∂L/∂(p, r·δω), r being the mean platform-joint radius (so both blocks are mm).
    """

    u_joint_tilt: float | None = None
    s_joint_tilt: float | None = None
    leg_diameter: float | None = None
    singularity_margin: float = 0.01


def _frozen(a, shape) -> np.ndarray:
    arr = np.array(a, dtype=float).reshape(shape)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Hexapod(SpatialPlatform):
    """A 6-UPS Gough–Stewart platform. Immutable; compare with ``==``.

    Parameters
    ----------
    name : machine name.
    base : (6, 3) base joint centres b_i in {F}, mm.
    platform : (6, 3) platform joint centres a_i in {P}, mm.
    offset : (6,) leg offsets L0_i, mm (leg length = L0_i + g_i λ_i).
    stroke : (6, 2) actuator reading range [λ_min, λ_max], in reading units (``actuator_unit``).
    base_axis, platform_axis : (6, 3) joint axis directions (unit), default z of {F}/{P}.
    limits : :class:`HexapodLimits`.
    home : (6,) home pose (mm, rad); default: level, centred, mid-stroke.
    workspace : optional (6, 2) box [min, max] of each pose coordinate (mm, rad).
    covariance : optional (48, 48) covariance of the parameters (identified machines).
    description : free text.
    metadata : free-form information carried along (e.g. ``{"calibration": {...}}`` from a
        machine file); not part of the kinematic identity, so ``==`` ignores it.
    gains : (6,) leg gains g_i > 0, mm of leg length per reading unit; default all 1.
    actuator_unit : the unit of the readings and the stroke (text: ``mm``, ``rev``, ``deg``,
        ``count``, ...); a label, never converted (a gain turns readings into mm). Default mm.
    """

    name: str
    base: np.ndarray
    platform: np.ndarray
    offset: np.ndarray
    stroke: np.ndarray
    base_axis: np.ndarray | None = None
    platform_axis: np.ndarray | None = None
    limits: HexapodLimits = field(default_factory=HexapodLimits)
    home: np.ndarray | None = None
    workspace: np.ndarray | None = None
    covariance: np.ndarray | None = None
    description: str = ""
    metadata: dict = field(default_factory=dict, compare=False)
    gains: np.ndarray | None = None
    actuator_unit: str = DEFAULT_ACTUATOR_UNIT

    kind = "6-UPS"
    actuator_names = tuple(f"lambda{i + 1}" for i in range(N_LEGS))
    abilities = frozenset({"leg-lengths", "drawing", "linuxcnc", "pose-convention", "stroke", "safety-margins"})
    point_sets = MappingProxyType({"base joints": tuple(f"b{i + 1}" for i in range(N_LEGS)),
                                   "platform joints": tuple(f"a{i + 1}" for i in range(N_LEGS))})
    #: The gains are held unless freed by name (``--free 'gain_*'``; module docstring).
    default_fixed = ("gain_*",)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "base", _frozen(self.base, (N_LEGS, 3)))
        set_(self, "platform", _frozen(self.platform, (N_LEGS, 3)))
        set_(self, "offset", _frozen(self.offset, (N_LEGS,)))
        set_(self, "stroke", _frozen(self.stroke, (N_LEGS, 2)))
        set_(self, "gains", _frozen(np.ones(N_LEGS) if self.gains is None else self.gains, (N_LEGS,)))
        if not np.all(np.isfinite(self.gains) & (self.gains > 0)):
            leg = int(np.argmax(~(np.isfinite(self.gains) & (self.gains > 0)))) + 1
            raise PkmcalError(f"machine '{self.name}': leg {leg} gain {float(self.gains[leg - 1])!r} is not a positive "
                              "finite number (mm of leg length per reading unit)")
        if not isinstance(self.actuator_unit, str) or not self.actuator_unit.strip():
            raise PkmcalError(f"machine '{self.name}': the actuator unit must be a non-empty text (mm, rev, ...)")
        z = np.tile([0.0, 0.0, 1.0], (N_LEGS, 1))
        for attr in ("base_axis", "platform_axis"):
            axes = np.array(z if getattr(self, attr) is None else getattr(self, attr), dtype=float)
            axes = axes.reshape(N_LEGS, 3)
            norms = np.linalg.norm(axes, axis=1)
            if np.any(norms < 1e-12):
                raise PkmcalError(f"machine '{self.name}': a {attr.replace('_', ' ')} is the zero vector")
            set_(self, attr, _frozen(axes / norms[:, None], (N_LEGS, 3)))
        if np.any(self.stroke[:, 1] < self.stroke[:, 0]):
            leg = int(np.argmax(self.stroke[:, 1] < self.stroke[:, 0])) + 1
            raise PkmcalError(f"machine '{self.name}': leg {leg} stroke has max < min")
        if self.home is None:
            set_(self, "home", _frozen(self._default_home(), (6,)))
        else:
            set_(self, "home", _frozen(self.home, (6,)))
        if self.workspace is not None:
            set_(self, "workspace", _frozen(self.workspace, (6, 2)))
        if self.covariance is not None:
            set_(self, "covariance", _frozen(self.covariance, (len(HEXAPOD_PARAM_NAMES),) * 2))

    # -- parameters ---------------------------------------------------------------------

    @property
    def param_names(self) -> tuple[str, ...]:
        return HEXAPOD_PARAM_NAMES

    @property
    def params(self) -> np.ndarray:
        geometry = np.concatenate([self.base, self.platform, self.offset[:, None]], axis=1).ravel()
        return np.concatenate([geometry, self.gains])

    @property
    def param_units(self) -> tuple[str, ...]:
        """mm for the 42 geometry parameters; for the gains mm per reading unit (``mm/rev``),
        "1" for readings in mm (a pure number)."""
        gain = "1" if self.actuator_unit == "mm" else f"mm/{self.actuator_unit}"
        return ("mm",) * N_GEOMETRY_PARAMS + (gain,) * N_LEGS

    @property
    def actuator_units(self) -> tuple[str, ...]:
        """:attr:`actuator_unit` for every leg."""
        return (self.actuator_unit,) * N_LEGS

    def with_params(self, params: np.ndarray, name: str | None = None, covariance=None) -> "Hexapod":
        """This machine with parameters ρ (48,) (and ``name``, ``covariance``, default none).

        Cheap (studies and simulations build many machines; the identification passes ρ
        explicitly instead), so it does not go through ``dataclasses.replace``: only the
        changed fields are validated and
        frozen; the others (axes, stroke, limits, home, workspace, description, metadata)
        are this machine's already-validated objects, shared. The home pose is kept, not
        recomputed from the new parameters (as with ``replace``, since home is never None
        after construction).
        """
        flat = self.as_param_vector(params)
        rho = flat[:N_GEOMETRY_PARAMS].reshape(N_LEGS, PARAMS_PER_LEG)
        changes = dict(
            name=self.name if name is None else name,
            base=rho[:, 0:3],
            platform=rho[:, 3:6],
            offset=rho[:, 6],
            gains=flat[N_GEOMETRY_PARAMS:],
            covariance=covariance,
        )
        if type(self) is not Hexapod or not np.all(np.isfinite(changes["gains"]) & (changes["gains"] > 0)):
            return replace(self, **changes)  # a subclass may validate more; a bad gain is refused there
        for key in ("base", "platform", "offset", "gains"):
            arr = changes[key].copy()  # C-contiguous float64 (6, 3) / (6,), as _frozen makes
            arr.flags.writeable = False
            changes[key] = arr
        if covariance is not None:
            changes["covariance"] = _frozen(covariance, (len(HEXAPOD_PARAM_NAMES),) * 2)
        new = object.__new__(Hexapod)
        new.__dict__.update(self.__dict__)
        new.__dict__.update(changes)
        return new

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Hexapod):
            return NotImplemented
        arrays = ("base", "platform", "offset", "stroke", "base_axis", "platform_axis", "home", "gains")
        same = all(np.array_equal(getattr(self, a), getattr(other, a)) for a in arrays)
        for opt in ("workspace", "covariance"):
            x, y = getattr(self, opt), getattr(other, opt)
            same &= (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
        return bool(same and self.name == other.name and self.limits == other.limits
                    and self.description == other.description and self.actuator_unit == other.actuator_unit)

    __hash__ = None  # type: ignore[assignment]

    @property
    def home_pose(self) -> np.ndarray:
        return self.home

    def _geometry(self, params) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(b (6, 3), a (6, 3), L0 (6,), g (6,))`` of parameters ρ (48,), C-contiguous as
        the compiled kernels take them; this machine's own arrays for ``params=None``."""
        if params is None:
            return self.base, self.platform, self.offset, self.gains
        flat = self.as_param_vector(params)
        rho = flat[:N_GEOMETRY_PARAMS].reshape(N_LEGS, PARAMS_PER_LEG)
        return (np.ascontiguousarray(rho[:, 0:3]), np.ascontiguousarray(rho[:, 3:6]),
                np.ascontiguousarray(rho[:, 6]), np.ascontiguousarray(flat[N_GEOMETRY_PARAMS:]))

    def workspace_box(self) -> np.ndarray:
        """:attr:`workspace` when given, else home ± (s, s, s/2, s/r, s/r, s/r) with s the
        mean actuator stroke in mm of leg length (g_i times the stroke) and r the platform-joint radius (docs/planning.md's default
        box shape); an error when the machine cannot move (no stroke) or orient (r = 0)."""
        if self.workspace is not None:
            return self.workspace.copy()
        half = self._box_shape(self.gains * (self.stroke[:, 1] - self.stroke[:, 0]))
        return np.stack([self.home - half, self.home + half], axis=1)

    def reach_search_shape(self) -> np.ndarray | None:
        """Planning's box shape (s, s, s/2, s/r, s/r, s/r) when no :attr:`workspace` is given
        (planning searches the reach along it), else None. Here s is the mean stroke in
        reading units, as planning has always had it (so plans stay the same); it differs from
        :meth:`workspace_box`'s (mm of leg length) on machines with leg gains g ≠ 1."""
        return None if self.workspace is not None else self._box_shape(self.stroke[:, 1] - self.stroke[:, 0])

    def within_geometry(self) -> tuple["Hexapod", tuple[str, ...]]:
        """The machine with its stroke within what struts of its home length reach and its
        joint tilts below 90°, with a note per limit that was looser
        (:func:`pkmcal.mechanisms.hexapod_reach.reachable_machine`)."""
        from pkmcal.mechanisms.hexapod_reach import reachable_machine

        return reachable_machine(self)

    @property
    def length_scale(self) -> float:
        """The platform joint radius (mm): :attr:`platform_radius`."""
        return self.platform_radius

    def _box_shape(self, strokes: np.ndarray) -> np.ndarray:
        s = float(np.mean(strokes))
        r = self.platform_radius
        if not s > 0:
            raise PkmcalError(f"machine '{self.name}': the actuators have no stroke (mean {s:g} mm), so the "
                              "platform cannot move; check the legs' 'stroke: [min, max]'")
        if not r > 1e-9 * s:
            raise PkmcalError(f"machine '{self.name}': every platform joint is at the platform origin (radius "
                              f"{r:g} mm), so the legs cannot set the platform's orientation; check the legs' "
                              "'platform:' joints")
        return np.array([s, s, s / 2, s / r, s / r, s / r])

    @property
    def platform_radius(self) -> float:
        """Mean distance of the platform joints from the platform origin (mm)."""
        return float(np.mean(np.linalg.norm(self.platform, axis=1)))

    def _default_home(self) -> np.ndarray:
        """Level, centred pose at which the mean reading is mid-stroke."""
        target = self.offset + self.gains * self.stroke.mean(axis=1)
        horiz = np.linalg.norm((self.platform - self.base)[:, :2], axis=1)
        dz = self.base[:, 2] - self.platform[:, 2]
        z = np.sqrt(np.maximum(target**2 - horiz**2, 0.0)) + dz
        return np.array([0.0, 0.0, float(np.mean(z)), 0.0, 0.0, 0.0])

    # -- kinematics ---------------------------------------------------------------------

    def leg_vectors(self, poses: np.ndarray, params: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(R, Ra, l)``: rotations (N, 3, 3), platform joints in {F} relative to p
        (N, 6, 3) = R a_i, and leg vectors l_i = p + R a_i − b_i (N, 6, 3)."""
        poses = self.as_pose_array(poses)
        base, platform, _, _ = self._geometry(params)
        R = euler_to_matrix(poses[:, 3:6])
        Ra = np.einsum("nrc,ic->nir", R, platform)
        legs = poses[:, None, 0:3] + Ra - base[None]
        return R, Ra, legs

    def leg_lengths(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Leg lengths L (N, 6) = ‖p + R a_i − b_i‖, mm.

        Batches of :data:`COMPILED_FROM` poses or more run the compiled kernel; smaller ones
        NumPy (:meth:`leg_vectors`), so that a command on a few poses does not import numba
        (~1 s with the SciPy BLAS check it triggers). Same formula; the two agree to a few
        ulp of the leg length (``tests/mechanisms/test_hexapod.py``). Which one runs depends
        only on the batch size, never on what ran before.
        """
        poses = self.as_pose_array(poses)
        if poses.shape[0] < COMPILED_FROM:
            legs = self.leg_vectors(poses, params)[2]
            return np.sqrt(np.einsum("nik,nik->ni", legs, legs))
        base, platform, _, _ = self._geometry(params)
        return _kernels().ik_lengths(poses, base, platform)

    def ik(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Actuator readings λ = (L − L0) / g (N, 6), in reading units."""
        _, _, offset, gains = self._geometry(params)
        return (self.leg_lengths(poses, params) - offset) / gains

    def reading_gains(self, params: np.ndarray | None = None) -> np.ndarray:
        """The gains g (6,) of parameters ρ (this machine's for ``params=None``)."""
        return self._geometry(params)[3]

    def lengths_from_readings(self, readings: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Leg lengths L = L0 + g λ (N, 6), mm, of readings λ (N, 6) (the inverse of the
        reading map of :meth:`ik`; no kinematics)."""
        _, _, offset, gains = self._geometry(params)
        return offset + gains * np.asarray(readings, dtype=float)

    def readings_from_lengths(self, lengths: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Readings λ = (L − L0) / g (N, 6) of leg lengths L (N, 6), mm (measured leg lengths,
        the ``l1..l6`` columns of a measurement file)."""
        _, _, offset, gains = self._geometry(params)
        return (np.asarray(lengths, dtype=float) - offset) / gains

    def lengths_from_readings_param_jacobian(self, readings: np.ndarray) -> np.ndarray:
        """∂(L0 + g λ)/∂ρ (N, 6, 48) at fixed readings λ (N, 6): 1 in leg i's L0 column, λ_i in
        its gain column, 0 elsewhere (the squared ik-residual's L_q)."""
        lam = np.atleast_2d(np.asarray(readings, dtype=float))
        J = np.zeros((lam.shape[0], N_LEGS, len(HEXAPOD_PARAM_NAMES)))
        legs = np.arange(N_LEGS)
        J[:, legs, legs * PARAMS_PER_LEG + PARAMS_PER_LEG - 1] = 1.0
        J[:, legs, N_GEOMETRY_PARAMS + legs] = lam
        return J

    def twist_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """∂L/∂(δp, δω) (N, 6, 6): row i = [u_iᵀ, ((R a_i) × u_i)ᵀ] (NumPy; the compiled
        :meth:`actuator_jacobians` is tested against it)."""
        _, Ra, legs = self.leg_vectors(poses, params)
        u = legs / np.linalg.norm(legs, axis=2, keepdims=True)
        return np.concatenate([u, np.cross(Ra, u)], axis=2)

    def actuator_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)`` = (∂λ/∂(x, y, z, a, b, c) (N, 6, 6), ∂λ/∂ρ (N, 6, 48)) in one compiled
        pass: A = twist Jacobian · diag(I, E(a, b, c)) / g (row i of the twist Jacobian
        [u_iᵀ, ((R a_i) × u_i)ᵀ], divided by g_i); B row i non-zero only on leg i's 7
        columns, [−u_iᵀ, u_iᵀ R, −1] / g_i, and its gain column, −λ_i / g_i."""
        return self.ik_and_jacobians(poses, params)[1:]

    def ik_and_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(λ, A, B)`` of :meth:`ik` and :meth:`actuator_jacobians` in one compiled pass,
        whatever the batch size (the identification's hot path)."""
        return _kernels().readings_and_jacobians(self.as_pose_array(poses), *self._geometry(params))

    def actuator_pose_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """∂λ/∂(x, y, z, a, b, c) (N, 6, 6), see :meth:`actuator_jacobians`."""
        return self.actuator_jacobians(poses, params)[0]

    def actuator_param_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """∂λ/∂ρ (N, 6, 48), see :meth:`actuator_jacobians`."""
        return self.actuator_jacobians(poses, params)[1]

    def length_param_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """∂L/∂ρ (N, 6, 48): the parameter Jacobian of unit-gain readings with the L0 and gain
        columns zero (a leg's length at a given pose depends on neither)."""
        base, platform, _, _ = self._geometry(params)
        J = _kernels().readings_and_jacobians(self.as_pose_array(poses), base, platform, np.zeros(N_LEGS),
                                              np.ones(N_LEGS))[2]
        J[:, :, PARAMS_PER_LEG - 1 : N_GEOMETRY_PARAMS : PARAMS_PER_LEG] = 0.0
        J[:, :, N_GEOMETRY_PARAMS:] = 0.0
        return J

    # -- the platform frame: SpatialPlatform's (the pose convention) ---------------------

    def fk(
        self,
        readings: np.ndarray,
        guess: np.ndarray | None = None,
        params: np.ndarray | None = None,
        *,
        tol: float = FK_TOL_MM,
        max_iter: int = FK_MAX_ITER,
        polish: int = 0,
    ) -> FKResult:
        """Poses from actuator readings λ (N, 6) by Newton–Raphson on SO(3), on the leg
        lengths L = L0 + g λ (:meth:`fk_lengths`; ``tol`` is on L, mm).

        ``guess`` is one pose (6,) or one per reading (N, 6); default the home pose.
        """
        return self.fk_lengths(self.lengths_from_readings(readings, params), guess, params, tol=tol,
                               max_iter=max_iter, polish=polish)

    def fk_precise(self, readings: np.ndarray, guess: np.ndarray | None = None,
                   params: np.ndarray | None = None) -> FKResult:
        """:meth:`fk` plus one polishing Newton step per converged pose, so that the poses are
        exact to rounding (the identification's FK; see ``_hexapod_kernels.fk_newton``)."""
        return self.fk(readings, guess, params=params, polish=1)

    def fk_lengths(self, lengths, guess=None, params: np.ndarray | None = None, *, tol: float = FK_TOL_MM,
                   max_iter: int = FK_MAX_ITER, polish: int = 0) -> FKResult:
        """As :meth:`fk`, from leg lengths L (N, 6) instead of readings.

        Branch check (:attr:`FKResult.same_branch`): the returned pose must be on the
        assembly mode of its guess, sign det J(pose) = sign det J(guess) with J the twist
        Jacobian (:meth:`assembly_signs`; the pose's sign comes free from the last Newton
        factorisation). A row whose Newton iteration lands on another assembly mode is
        solved again by continuation from its guess: the leg lengths are moved from L(guess)
        to L in :data:`FK_CONTINUATION_STEPS` equal steps, each solved by Newton from the
        previous pose, the path a machine takes when its legs move together from the guess;
        that answer replaces Newton's when it converges on the guess's assembly mode
        (``iterations`` stays Newton's count). Rows still on another assembly mode keep
        their (valid) pose with ``same_branch`` False; rows that did not converge are left
        as Newton left them.
        """
        lengths = np.ascontiguousarray(np.atleast_2d(np.asarray(lengths, dtype=float)))
        if lengths.ndim != 2 or lengths.shape[1] != N_LEGS:
            raise PkmcalError(f"FK needs 6 leg lengths per pose; got an array of shape {lengths.shape}")
        g = self.home if guess is None else np.asarray(guess, dtype=float)
        guesses = np.broadcast_to(g, lengths.shape)
        if g.ndim == 1 or g.shape[0] == 1:
            guesses = guesses[:1]  # one guess for all: the kernel broadcasts it
        K = _kernels()
        base, platform, _, _ = self._geometry(params)
        poses, conv, iters, res, sign = K.fk_newton_signed(lengths, guesses, base, platform, tol, max_iter, polish)
        ref_sign = K.twist_det_signs(guesses, base, platform)
        ref_sign = np.broadcast_to(ref_sign, conv.shape) if ref_sign.shape[0] == 1 else ref_sign
        same = (sign == ref_sign) | (sign == 0) | (ref_sign == 0)
        retry = np.flatnonzero(conv & ~same)
        if retry.size:
            gr = np.ascontiguousarray(guesses[retry] if guesses.shape[0] > 1 else np.repeat(guesses, retry.size, 0))
            x, ok = self._fk_continuation(lengths[retry], gr, tol, max_iter, polish, params)
            s_new = K.twist_det_signs(x, base, platform)
            r_ref = ref_sign[retry]
            better = ok & ((s_new == r_ref) | (s_new == 0) | (r_ref == 0))
            take = retry[better]
            if take.size:
                poses[take] = x[better]
                same[take] = True
                res[take] = np.max(np.abs(self.leg_lengths(x[better], params) - lengths[take]), axis=1)
        return FKResult(poses=poses, converged=conv, iterations=iters, residual=res, same_branch=same)

    def _fk_continuation(self, lengths, guesses, tol, max_iter, polish, params=None) -> tuple[np.ndarray, np.ndarray]:
        """Poses (M, 6) and converged (M,) of FK by continuation from ``guesses`` (M, 6): leg
        lengths L(guess) + t (L − L(guess)), t = 1/K, 2/K, …, 1, each solved by Newton from
        the previous step's pose (see :meth:`fk_lengths`)."""
        K = _kernels()
        base, platform, _, _ = self._geometry(params)
        start = self.leg_lengths(guesses, params)
        x = np.array(guesses, dtype=float)
        ok = np.ones(len(x), dtype=bool)
        for t in np.arange(1, FK_CONTINUATION_STEPS + 1) / FK_CONTINUATION_STEPS:
            target = np.ascontiguousarray(start + t * (lengths - start))
            x, conv, _, _ = K.fk_newton(target, x, base, platform, tol, max_iter, polish if t == 1.0 else 0)
            ok &= conv
        return x, ok

    def assembly_signs(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """sign det J (N, 1) of the twist Jacobian ∂L/∂(δp, δω) (module docstring), compiled;
        it changes sign only through a singularity, so two poses with different signs are on
        different assembly modes. 0 where singular to working precision."""
        poses = self.as_pose_array(poses)
        base, platform, _, _ = self._geometry(params)
        return _kernels().twist_det_signs(poses, base, platform)[:, None]

    # -- limits -------------------------------------------------------------------------

    def reach(self) -> float:
        """The longest leg at full stroke plus the farthest base joint from the origin (mm)."""
        top = np.asarray(self.stroke)[:, 1]
        return float(np.max(self.lengths_from_readings(top))) + float(np.max(np.linalg.norm(np.asarray(self.base),
                                                                                              axis=1)))

    def reading_range(self) -> np.ndarray:
        """The stroke (6, 2), in reading units (:attr:`actuator_unit`)."""
        return self.stroke

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """Reachability of N poses against every limit of the machine.

        ``margin`` shrinks every limit by that safety margin (mm for stroke and collision,
        the same number in degrees for the joint tilts). The stroke margin is in mm of leg
        length: g_i times the distance of the reading λ_i to the nearer end of its stroke. A pose with a NaN or infinite
        coordinate cannot be evaluated: it violates every limit and all its margins are NaN
        (likewise any single margin that cannot be evaluated, e.g. a zero-length leg).

        ``margins=False`` gives the same verdicts without the margins (``margins`` of the
        report empty), faster: the singularity verdict then comes from a Cholesky
        certificate instead of the SVD (:func:`~._hexapod_kernels.singularity_certificate`).

        From :data:`LIMITS_COMPILED_FROM` poses on, the compiled kernel
        (:func:`~._hexapod_kernels.limit_margins`) computes the stroke, tilt and collision
        margins (the singularity margin is the NumPy SVD's), and every pose with a kernel
        margin within :data:`EXACT_VERDICT_TOL` of zero (or NaN), or an undecided
        certificate, is recomputed by the NumPy formulas (:meth:`_limit_margins_numpy`), so
        the verdicts are exactly theirs whatever the rounding (the kernel agrees with them
        to ~1e-13, tested); smaller batches use the NumPy formulas directly, except without
        ``margins``: the verdicts-only callers (candidates, simulation, verification) run
        where the compiled FK is loaded anyway, and the kernel checked the 15–20 poses of a
        study trial in about half the NumPy time (2026-11-23).
        """
        poses = self.as_pose_array(poses)
        finite = np.all(np.isfinite(poses), axis=1)
        safe = np.where(finite[:, None], poses, self.home)
        if len(poses) < LIMITS_COMPILED_FROM and margins:
            result = self._limit_margins_numpy(safe, margin)
        else:
            result = self._limit_margins_compiled(safe, finite, margin, margins)
        for m in result.values():
            m[~finite] = np.nan
        violations = {k: ~(m >= 0.0) for k, m in result.items()}
        return LimitReport(violations=violations, margins=result if margins else {})

    def _limit_margins_compiled(self, safe: np.ndarray, finite: np.ndarray, margin: float,
                                margins: bool) -> dict[str, np.ndarray]:
        """:meth:`check_limits`' margins by the compiled kernel, every pose near a limit (or
        undecided) recomputed by :meth:`_limit_margins_numpy`; without ``margins`` the
        singularity entry is the certificate (+1 ok, −1 violated)."""
        from pkmcal.mechanisms import _hexapod_kernels as kernels

        lim = self.limits
        on = self._limits_enabled()
        names = [n for n, enabled in zip(LIMIT_NAMES, on) if enabled]
        table = np.array([np.nan if v is None else v for v in (lim.u_joint_tilt, lim.s_joint_tilt, lim.leg_diameter)]
                         + [lim.singularity_margin, self.platform_radius, margin, np.deg2rad(margin)])
        out = kernels.limit_margins(safe, self.base, self.platform, self.offset, self.gains, self.stroke,
                                    self.base_axis,
                                    self.platform_axis, self._leg_pairs(), on[:4] + (not margins,), table)
        result = {n: out[:, LIMIT_NAMES.index(n)] for n in names}
        unsure = ~np.all([np.abs(result[n]) > EXACT_VERDICT_TOL for n in names if n != "singularity"], axis=0)
        if margins:
            result["singularity"] = self._singularity_margin(safe)
        else:
            unsure |= np.isnan(result["singularity"])  # certificate undecided
        unsure &= finite
        if unsure.any():
            exact = self._limit_margins_numpy(safe[unsure], margin)
            for n in names:
                result[n][unsure] = exact[n]
        return result

    def _limits_enabled(self) -> tuple[bool, ...]:
        """Which limits of :data:`LIMIT_NAMES` this machine checks."""
        lim = self.limits
        return (True, lim.u_joint_tilt is not None, lim.s_joint_tilt is not None, lim.leg_diameter is not None, True)

    def _singularity_margin(self, poses: np.ndarray) -> np.ndarray:
        """Inverse condition number of the length-scaled twist Jacobian minus the margin
        (N,), by SVD, only where the Jacobian is finite (LAPACK rejects NaN/inf); else NaN."""
        with np.errstate(invalid="ignore", divide="ignore"):
            Jt = self.twist_jacobian(poses)
            Jt[:, :, 3:] /= self.platform_radius
        good = np.all(np.isfinite(Jt), axis=(1, 2))
        out = np.full(len(Jt), np.nan)
        if np.any(good):
            sv = np.linalg.svd(Jt[good], compute_uv=False)
            out[good] = sv[:, -1] / sv[:, 0] - self.limits.singularity_margin
        return out

    def _limit_margins_numpy(self, poses: np.ndarray, margin: float = 0.0) -> dict[str, np.ndarray]:
        """The limit margins by vectorised NumPy (finite poses): the reference formulas of
        :meth:`check_limits` (module docstring), which the compiled kernel is tested against."""
        margins: dict[str, np.ndarray] = {}
        lim = self.limits
        with np.errstate(invalid="ignore", divide="ignore"):
            R, Ra, legs = self.leg_vectors(poses)
            L = np.linalg.norm(legs, axis=2)
            u = legs / L[..., None]
            lam = (L - self.offset) / self.gains
            to_end = np.minimum(lam - self.stroke[:, 0], self.stroke[:, 1] - lam) * self.gains  # mm of leg length
            margins["stroke"] = np.min(to_end, axis=1) - margin
            if lim.u_joint_tilt is not None:
                tilt = np.arccos(np.clip(np.einsum("nir,ir->ni", u, self.base_axis), -1, 1))
                margins["u_joint_tilt"] = lim.u_joint_tilt - np.deg2rad(margin) - tilt.max(axis=1)
            if lim.s_joint_tilt is not None:
                axes = np.einsum("nrc,ic->nir", R, self.platform_axis)
                tilt = np.arccos(np.clip(np.einsum("nir,nir->ni", u, axes), -1, 1))
                margins["s_joint_tilt"] = lim.s_joint_tilt - np.deg2rad(margin) - tilt.max(axis=1)
            if lim.leg_diameter is not None:
                tops = poses[:, None, 0:3] + Ra
                margins["leg_collision"] = self._min_leg_distance(tops) - lim.leg_diameter - margin
        margins["singularity"] = self._singularity_margin(poses)
        return margins

    def _leg_pairs(self) -> np.ndarray:
        """Leg pairs (i, j) whose segments can collide: pairs sharing a joint centre
        (3-6 designs) meet by construction and are left out. In (i, j) order, i < j; one
        vectorised pass (every limit check asks: the 30 scalar norms of a loop took ~0.15 ms,
        a tenth of a study trial's limit checks, 2026-11-23)."""
        i, j = np.triu_indices(N_LEGS, 1)
        shared = ((np.linalg.norm(self.base[i] - self.base[j], axis=1) < 1e-6)
                  | (np.linalg.norm(self.platform[i] - self.platform[j], axis=1) < 1e-6))
        return np.stack([i[~shared], j[~shared]], axis=1).astype(int).reshape(-1, 2)

    def _min_leg_distance(self, tops: np.ndarray) -> np.ndarray:
        """Minimum distance (N,) between the leg segments b_i → top_i over leg pairs."""
        pairs = self._leg_pairs()
        if len(pairs) == 0:
            return np.full(tops.shape[0], np.inf)
        i, j = pairs[:, 0], pairs[:, 1]
        p1 = np.broadcast_to(self.base[i], tops[:, i].shape)
        p2 = np.broadcast_to(self.base[j], tops[:, j].shape)
        return segment_distance(p1, tops[:, i], p2, tops[:, j]).min(axis=1)

    # -- description --------------------------------------------------------------------

    def summary(self) -> str:
        """A few human-readable lines describing the machine."""
        lim = self.limits
        deg = lambda v: "off" if v is None else f"{np.rad2deg(v):.1f}°"  # noqa: E731
        lines = [
            f"{self.name}: 6-UPS hexapod, 48 kinematic parameters (the gains held unless freed)"
            + (f" — {self.description}" if self.description else ""),
            f"  base joint radius {np.mean(np.linalg.norm(self.base[:, :2], axis=1)):.3f} mm, "
            f"platform joint radius {self.platform_radius:.3f} mm",
            f"  leg offsets L0 {values_text(self.offset, 'mm')}, "
            f"stroke {self.stroke[0, 0]:g}..{self.stroke[0, 1]:g} {self.actuator_unit}"
            + ("" if np.all(self.gains == 1.0) and self.actuator_unit == DEFAULT_ACTUATOR_UNIT else
               f", gains {values_text(self.gains, 'mm/' + self.actuator_unit)}"),
            f"  limits: U-joint tilt {deg(lim.u_joint_tilt)}, S-joint tilt {deg(lim.s_joint_tilt)}, "
            f"leg diameter {'off' if lim.leg_diameter is None else f'{lim.leg_diameter:g} mm'}, "
            f"singularity margin {lim.singularity_margin:g}",
            f"  home pose x y z = {self.home[0]:.3f} {self.home[1]:.3f} {self.home[2]:.3f} mm, "
            f"a b c = {np.rad2deg(self.home[3]):.2f} {np.rad2deg(self.home[4]):.2f} {np.rad2deg(self.home[5]):.2f}°",
        ]
        return "\n".join(lines)


def segment_distance(p1, q1, p2, q2) -> np.ndarray:
    """Minimum distance between segments p1→q1 and p2→q2, arrays (..., 3) → (...).

    Closed form: minimise ‖p1 + s d1 − p2 − t d2‖ over s, t ∈ [0, 1], clamping s, then t,
    then s again (Ericson, *Real-Time Collision Detection*, §5.1.9), including its
    degenerate cases: a zero-length segment is a point (s = 0 or t = 0), so the result is
    the point–segment (or point–point) distance.
    """
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("...k,...k->...", d1, d1)
    e = np.einsum("...k,...k->...", d2, d2)
    f = np.einsum("...k,...k->...", d2, r)
    c = np.einsum("...k,...k->...", d1, r)
    b = np.einsum("...k,...k->...", d1, d2)
    point1 = a <= np.finfo(float).tiny  # segment 1 has zero length
    point2 = e <= np.finfo(float).tiny
    a_ = np.where(point1, 1.0, a)
    e_ = np.where(point2, 1.0, e)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-12 * a * e, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = (b * s + f) / e_
        s = np.where(t < 0.0, np.clip(-c / a_, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a_, 0.0, 1.0), s))
        t = np.clip(t, 0.0, 1.0)
        # degenerate cases: point 1 → closest point of segment 2 (s = 0, t = f / e);
        # point 2 → closest point of segment 1 (t = 0, s = −c / a); two points: s = t = 0
        s = np.where(point1, 0.0, np.where(point2, np.clip(-c / a_, 0.0, 1.0), s))
        t = np.where(point2, 0.0, np.where(point1, np.clip(f / e_, 0.0, 1.0), t))
    diff = p1 + s[..., None] * d1 - p2 - t[..., None] * d2
    dist = np.linalg.norm(diff, axis=-1)
    # (near-)parallel segments: s = 0 above is one of the closest points only when the
    # segments overlap along their common direction; the minimum is attained at an endpoint
    # of one of them, so take the smallest of the four endpoint-to-segment distances
    parallel = ~(denom > 1e-12 * a * e) & ~point1 & ~point2
    if np.any(parallel):
        ends = np.minimum.reduce([_point_segment(p1, p2, d2, e_), _point_segment(q1, p2, d2, e_),
                                  _point_segment(p2, p1, d1, a_), _point_segment(q2, p1, d1, a_)])
        dist = np.where(parallel, np.minimum(dist, ends), dist)
    return dist


def _point_segment(x, p, d, dd):
    """Distance from points x to segments p + u d, u ∈ [0, 1] (dd = d·d > 0), (..., 3) → (...)."""
    u = np.clip(np.einsum("...k,...k->...", x - p, d) / dd, 0.0, 1.0)
    return np.linalg.norm(p + u[..., None] * d - x, axis=-1)

"""The mechanism interface shared by every machine pkmcal calibrates.

A mechanism is an immutable description of a machine (value equality): what it is
(``kind``), its pose coordinates x, actuators q and named kinematic parameters ρ (with
units and angle flags), and pure, vectorised functions of N poses in which ρ may be given
explicitly (``params=``, default the machine's own; the identification engine passes the
trial ρ and never builds a machine per evaluation):

* ``ik(poses, params)``                 → actuator readings q (N, l)
* ``ik_and_jacobians(poses, params)``   → (q, A = ∂q/∂x (N, l, n), B = ∂q/∂ρ (N, l, p))
* ``frame(poses, params)``              → the platform frame (p, R) of each pose
  (:class:`~pkmcal.mechanisms.frame.Frame`), the only thing a sensor sees
* ``frame_jacobians(poses, params)``    → (T = ∂twist/∂x (N, 6, n), T_ρ = ∂twist/∂ρ (N, 6, p)
  or None when the frame does not depend on ρ), twist = (δp, δω) as in :mod:`.frame`
* ``poses_from_frame(frame)``           → the pose coordinates of frames (the inverse map)
* ``fk(readings, guess, params)``       → poses (N, n), with per-pose convergence and
  same-assembly-mode flags (:class:`FKResult`)
* ``check_limits(poses)``               → :class:`LimitReport`

This is everything the identification engine needs: every calibration model in pkmcal is
the closure equation ``q = IK(x, ρ)`` plus a sensor model ``y = h(frame(x), s)``, with the
pose x of each measurement as a nuisance unknown; the engine composes the sensor's twist
Jacobian with T (:meth:`Mechanism.pose_jacobian_from_twist`). Optional features are
declared in :attr:`Mechanism.abilities`, never probed. The hexapod (n = l = 6) and the
redundantly actuated planar machines (l > n) implement this class.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.frame import Frame


@dataclass(frozen=True)
class FKResult:
    """Forward kinematics of N actuator-reading sets.

    ``poses`` (N, n) in internal units; ``converged`` (N,) is True only where the IK of the
    returned pose reproduces the readings within ``tol``; ``iterations`` (N,) Newton steps
    taken; ``residual`` (N,) the final max |q − IK(pose)| (mm or rad, per actuator).

    ``same_branch`` (N,) is True where the returned pose is on the assembly mode of the start
    pose it was solved from (the guess, default the home pose): every sign of
    :meth:`Mechanism.assembly_signs` (for a hexapod sign det J of the twist Jacobian) is the
    same at both poses. A pose that reproduces the readings on another assembly mode is a
    mathematically valid FK solution but not where a machine that started at the guess is:
    :attr:`ok` is False for it, and every FK-based result of pkmcal (``pkmcal fk`` and
    ``info``, simulation, verification, the fk-residual fit) flags or drops it.
    """

    poses: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray
    same_branch: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.same_branch is None:
            object.__setattr__(self, "same_branch", np.ones(np.shape(self.converged), dtype=bool))

    @property
    def ok(self) -> np.ndarray:
        """(N,) True where the pose reproduces the readings on the start pose's assembly
        mode: the answer a caller should use."""
        return np.asarray(self.converged, dtype=bool) & np.asarray(self.same_branch, dtype=bool)

    @property
    def branch_changed(self) -> np.ndarray:
        """(N,) True where FK converged, but on another assembly mode than its start pose."""
        return np.asarray(self.converged, dtype=bool) & ~np.asarray(self.same_branch, dtype=bool)

    @property
    def all_converged(self) -> bool:
        return bool(np.all(self.converged))


@dataclass(frozen=True)
class LimitReport:
    """Which limits each of N poses violates.

    ``violations`` maps a limit name (e.g. ``"stroke"``, ``"u_joint_tilt"``) to a boolean
    array (N,) that is True where the pose violates it; ``margins`` maps the same names to
    the signed margin (N,) (negative = violated), in the limit's own unit (mm or radians).
    """

    violations: dict[str, np.ndarray]
    margins: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def ok(self) -> np.ndarray:
        n = len(next(iter(self.violations.values()))) if self.violations else 0
        bad = np.zeros(n, dtype=bool)
        for v in self.violations.values():
            bad |= v
        return ~bad

    def reasons(self, k: int) -> list[str]:
        """Names of the limits pose ``k`` violates (empty when reachable)."""
        return [name for name, v in self.violations.items() if v[k]]

    def verdicts(self) -> list[str]:
        """One string per pose: ``"ok"`` or the violated limits joined by ``+`` (in the order
        of :attr:`violations`). Vectorised over poses: pose k's violations v_kj are coded as
        c_k = Σ_j v_kj 2^j and the text is built once per distinct code."""
        names = list(self.violations)
        if not names:
            return []
        bits = np.stack([np.asarray(self.violations[n], dtype=bool) for n in names], axis=1)
        codes = bits @ (1 << np.arange(len(names), dtype=np.int64 if len(names) < 63 else object))
        uniq, inverse = np.unique(codes, return_inverse=True)
        labels = np.array(["+".join(n for j, n in enumerate(names) if (int(c) >> j) & 1) or "ok" for c in uniq],
                          dtype=object)
        return labels[inverse.reshape(-1)].tolist()


@dataclass(frozen=True)
class NamedDirection:
    """A parameter direction a machine's users know by name, for the identifiability report
    to say in their words whether the measurements see it (issue 13, item 5).

    ``meaning`` the words ("a common scale of the arm lengths and the radius");
    ``direction`` {parameter name: coefficient} (internal units per unit ``amount``);
    ``unit`` the unit of the amount ("1" for a relative change, "rad", "mm");
    ``tolerance`` the amount's standard deviation beyond which the measurements are said
    not to determine it (with ``tolerance_why``, the reason for that figure);
    ``remedy`` what measurement or prior would fix it; ``placement`` True for a direction
    that only places the machine's motions as a whole (a delta's tower set slid across the
    bed): harmless to their shape and size, and no firmware number depends on it."""

    meaning: str
    direction: dict
    unit: str
    tolerance: float
    tolerance_why: str
    remedy: str
    placement: bool = False


class Mechanism(ABC):
    """Abstract parallel mechanism (see module docstring)."""

    name: str
    #: Registry key, written in machine files and shown by ``pkmcal machines`` (``6-UPS``,
    #: ``planar-2dof-3act``, ...).
    kind: str = ""
    #: Names of the pose coordinates, e.g. ("x", "y", "z", "a", "b", "c").
    pose_names: tuple[str, ...]
    #: True for pose coordinates that are angles (degrees in files, radians inside).
    pose_is_angle: tuple[bool, ...]
    #: Names of the actuator readings, e.g. ("lambda1", ..., "lambda6").
    actuator_names: tuple[str, ...]
    #: Optional features, asked as ``"x" in mech.abilities``: ``"leg-lengths"`` (has
    #: ``leg_lengths``, ``fk_lengths``, ``length_param_jacobian``, the reading map
    #: L = L0 + g λ: ``lengths_from_readings``, ``readings_from_lengths``, ``reading_gains``,
    #: ``lengths_from_readings_param_jacobian``), ``"drawing"`` (has ``leg_vectors`` and
    #: ``base``: the report draws it), ``"linuxcnc"`` (exportable to a LinuxCNC kinematics
    #: module), ``"pose-convention"`` (the pose coordinates are the platform frame's x, y, z,
    #: a, b, c of :mod:`pkmcal.conventions`: ``frame`` is ``Frame.from_poses``), ``"stroke"``
    #: (:meth:`reading_range` is an actuator stroke, exported as such), ``"planar"``,
    #: ``"safety-margins"`` (planning keeps safety margins from the limits, by the rule of
    #: :mod:`pkmcal.planning.margins` for the machine's kind: the 6-UPS hexapod's stroke,
    #: U/S-joint tilts and leg clearance; the deltas' travel, arm angles and workspace).
    abilities: frozenset[str] = frozenset()
    #: One line of free text (machine files' ``description``); every concrete machine holds it.
    description: str = ""
    #: Free-form information carried along (``calibration``, ``setup`` of an identified
    #: machine); every concrete machine holds it as a field, empty by default.
    metadata: Mapping = MappingProxyType({})
    #: Limit keywords of the constructor → True for angles (a number or a pair), the
    #: ``limits:`` of the generic machine file (:mod:`pkmcal.io.parameter_machine_file`).
    limit_keywords: Mapping[str, bool] = MappingProxyType({})
    #: The workspace box (n, 2) the machine file declares (internal units), None when it
    #: declares none; :meth:`workspace_box` is the box searched in either case.
    workspace: np.ndarray | None = None
    #: True when the platform frame depends on ρ (a tool offset): then
    #: :meth:`frame_jacobians` gives T_ρ and the engine adds (∂y/∂twist) · T_ρ to ∂y/∂ρ.
    frame_depends_on_params: bool = False
    #: Parameter names or shell patterns held at their values unless freed by name (a
    #: hexapod's leg gains, a delta's tool offset).
    default_fixed: tuple[str, ...] = ()
    #: Parameter names or shell patterns a fit also holds by default when its sensor sees no
    #: length (``Sensor.sees_length`` False, a Z probe), or reads on one plane only
    #: (``Sensor.reads_one_plane``, a bed), unless freed by name or given a prior
    #: (:func:`pkmcal.identification.residuals.sensor_held_parameters`).
    held_without_length: tuple[str, ...] = ()
    held_on_one_plane: tuple[str, ...] = ()
    #: Named sets of points among the parameters: set name → point labels, each label P
    #: with parameters ``P.x, P.y, P.z`` (mm). Shown gauge-free after an identification
    #: (:mod:`pkmcal.identification.geometry`); none by default.
    point_sets: Mapping[str, tuple[str, ...]] = MappingProxyType({})
    #: Covariance (p, p) of the parameters (mm², rad²; zero rows for fixed ones) of an
    #: identified machine, None otherwise (every concrete mechanism holds it as a field).
    covariance: np.ndarray | None = None

    def named_directions(self) -> tuple[NamedDirection, ...]:
        """Parameter directions known by name (:class:`NamedDirection`), which the
        identifiability report judges one by one; none by default."""
        return ()

    @property
    def actuator_is_angle(self) -> tuple[bool, ...]:
        """True for actuator readings that are angles (rotary actuators: radians inside,
        degrees in files and on the command line); all False (linear, mm) by default."""
        return (False,) * self.n_actuators

    @property
    def actuator_units(self) -> tuple[str, ...]:
        """File unit of each actuator reading: "deg" for angles, else "mm"."""
        return tuple("deg" if a else "mm" for a in self.actuator_is_angle)

    @property
    def n_dof(self) -> int:
        return len(self.pose_names)

    @property
    def n_actuators(self) -> int:
        return len(self.actuator_names)

    @property
    @abstractmethod
    def param_names(self) -> tuple[str, ...]:
        """Names of the kinematic parameters, in the order of :attr:`params`."""

    @property
    def param_is_angle(self) -> tuple[bool, ...]:
        """Which parameters are angles (rad inside, degrees in files and on screen); default
        none (the hexapod's are all lengths, mm)."""
        return (False,) * len(self.param_names)

    @property
    def param_units(self) -> tuple[str, ...]:
        """File unit of each parameter: "deg" for angles, else "mm" (a dimensionless
        parameter, e.g. a gain, declares "1")."""
        return tuple("deg" if a else "mm" for a in self.param_is_angle)

    @property
    @abstractmethod
    def params(self) -> np.ndarray:
        """The kinematic parameter vector ρ (p,) in internal units."""

    @abstractmethod
    def with_params(self, params: np.ndarray, name: str | None = None, covariance=None) -> "Mechanism":
        """A copy of this machine with the parameter vector replaced (and ``name``,
        ``covariance`` (p, p) of the parameters, default none)."""

    @property
    @abstractmethod
    def home_pose(self) -> np.ndarray:
        """The pose (n,) the FK starts from by default."""

    @abstractmethod
    def workspace_box(self) -> np.ndarray:
        """The box (n, 2) [min, max] of the pose coordinates (internal units) in which
        planning and ``pkmcal info`` search for poses."""

    def reach_search_shape(self) -> np.ndarray | None:
        """Half-widths h (n,) about :attr:`home_pose` along which planning searches each
        coordinate's reach (:func:`pkmcal.planning.candidates.workspace_box`: the largest
        home ± t_i h_i, t_i ∈ (0, 1], within the limits), when :meth:`workspace_box` is only
        that shape; None (default): :meth:`workspace_box` is the planning box itself."""
        return None

    def limit_source(self, limit: str, default: str) -> str:
        """Where the machine's ``limit`` (``"stroke"``, ``"workspace"``) was set, for messages:
        the importer's record (``metadata.limits_from``, e.g. ``[JOINT_N] MIN_LIMIT/MAX_LIMIT
        of hexapod.ini``) or ``default``."""
        record = self.metadata.get("limits_from") if self.metadata else None
        found = record.get(limit) if isinstance(record, Mapping) else None
        return found if isinstance(found, str) and found else default

    def within_geometry(self) -> tuple["Mechanism", tuple[str, ...]]:
        """This machine with its limits clipped to what its joint geometry reaches, and one
        note (a line of text) per limit that was looser: planning plans on it
        (:func:`pkmcal.planning.plan.plan_poses`). Default: the machine itself, no notes
        (limits that are the geometry's own); the 6-UPS hexapod's struts and joint tilts:
        :mod:`pkmcal.mechanisms.hexapod_reach`."""
        return self, ()

    @property
    def length_scale(self) -> float:
        """A length (mm) that turns the platform's rotations into displacements (rad × mm),
        e.g. to weigh orientation errors against position errors or to make a Jacobian's
        rotation columns dimensionless; 1 by default (the hexapod: its platform joint radius)."""
        return 1.0

    @abstractmethod
    def summary(self) -> str:
        """A few human-readable lines describing the machine."""

    # -- kinematics, ρ explicit ---------------------------------------------------------

    @abstractmethod
    def ik(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Actuator readings q (N, l) of poses (N, n), at parameters ``params`` (default
        :attr:`params`)."""

    @abstractmethod
    def actuator_pose_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """∂q/∂pose (N, l, n), with respect to the pose coordinates of :attr:`pose_names`."""

    @abstractmethod
    def actuator_param_jacobian(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """∂q/∂ρ (N, l, p) at fixed pose."""

    def actuator_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
        """``(∂q/∂pose, ∂q/∂ρ)`` together; a mechanism overrides this when one pass over the
        poses computes both more cheaply than two."""
        return self.actuator_pose_jacobian(poses, params), self.actuator_param_jacobian(poses, params)

    def ik_and_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, A = ∂q/∂pose, B = ∂q/∂ρ)`` together, the identification's hot path; a
        mechanism overrides this when one pass computes them more cheaply."""
        return (self.ik(poses, params), *self.actuator_jacobians(poses, params))

    @abstractmethod
    def frame(self, poses: np.ndarray, params: np.ndarray | None = None) -> Frame:
        """The platform frames (p, R) of poses (N, n) in the base frame."""

    @abstractmethod
    def frame_jacobians(self, poses: np.ndarray, params: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray | None]:
        """``(T, T_ρ)``: T = ∂(δp, δω)/∂pose (N, 6, n) and T_ρ = ∂(δp, δω)/∂ρ (N, 6, p), or
        None when the frame does not depend on ρ (the twist of :mod:`.frame`)."""

    def pose_jacobian_from_twist(self, J_twist: np.ndarray, poses: np.ndarray,
                                 params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂pose (N, m, n) = J_twist (N, m, 6) · T: a sensor's twist Jacobian pulled back
        to the pose coordinates. A mechanism overrides this with the product written out
        (T is sparse: the hexapod's is diag(I, E), a planar machine's a column selection)."""
        T, _ = self.frame_jacobians(poses, params)
        return J_twist @ T

    @abstractmethod
    def poses_from_frame(self, frame: Frame) -> np.ndarray:
        """The pose coordinates (N, n) of platform frames (the inverse of :meth:`frame` on
        frames the machine can take)."""

    def fk(self, readings: np.ndarray, guess: np.ndarray | None = None,
           params: np.ndarray | None = None, **options) -> FKResult:
        """Poses (N, n) whose IK (at ``params``, default :attr:`params`) reproduces
        ``readings`` (N, l), from ``guess`` (one pose or one per reading; default home).

        Default: the shared batched Gauss–Newton solver with backtracking, per-pose
        convergence and branch check (:func:`pkmcal.mechanisms.solver.solve_fk`; its
        keyword ``options`` tol, max_iter, res_tol)."""
        from pkmcal.mechanisms.solver import solve_fk

        return solve_fk(self, readings, guess, params, **options)

    def fk_precise(self, readings: np.ndarray, guess: np.ndarray | None = None,
                   params: np.ndarray | None = None) -> FKResult:
        """FK exact to rounding, not just to the convergence tolerance, for residuals that a
        least-squares solver evaluates at 1e-12 tolerances or differentiates numerically.
        Default :meth:`fk`, for mechanisms whose FK already stops at a rounding-level step."""
        return self.fk(readings, guess, params=params)

    def assembly_signs(self, poses: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """Signs (N, k) in {−1, 0, +1} that tell the assembly modes of poses (N, n) apart:
        two poses are on the same branch when every sign agrees (0: singular, undecided).

        Default: for as many actuators as pose coordinates, sign det ∂q/∂pose (k = 1), which
        changes only through a singularity; a redundantly actuated machine has no single
        such determinant and declares its own signs (default none, k = 0). A mechanism
        overrides this where a better-defined quantity exists (the hexapod: the twist
        Jacobian, free of the Euler-angle factor cos b)."""
        poses = self.as_pose_array(poses)
        if self.n_actuators != self.n_dof:
            return np.zeros((poses.shape[0], 0), dtype=np.int8)
        with np.errstate(invalid="ignore"):
            A = self.actuator_pose_jacobian(poses, params)
            good = np.all(np.isfinite(A), axis=(1, 2))
            det = np.zeros(poses.shape[0])
            if np.any(good):
                det[good] = np.linalg.det(A[good])
        return np.sign(det).astype(np.int8)[:, None]

    def same_branch(self, poses: np.ndarray, reference: np.ndarray, params: np.ndarray | None = None) -> np.ndarray:
        """(N,) True where each of ``poses`` (N, n) is on the assembly mode of its
        ``reference`` (one pose (n,) or one per pose (N, n)): the signs of
        :meth:`assembly_signs` agree wherever both are non-zero."""
        poses = self.as_pose_array(poses)
        ref = self.as_pose_array(reference)
        s = self.assembly_signs(poses, params)
        r = self.assembly_signs(ref, params)
        r = np.broadcast_to(r, s.shape) if r.shape[0] == 1 else r
        return np.all((s == r) | (s == 0) | (r == 0), axis=1)

    def reach(self) -> float | None:
        """An upper bound (mm) of how far the platform can be from the base origin, the
        half-width ``pkmcal info`` searches each translation over; None when the machine
        states none (1000 mm is searched)."""
        return None

    def reading_range(self) -> np.ndarray | None:
        """(l, 2) [min, max] of each actuator reading (internal units) where the machine
        states one (a hexapod's stroke), else None: what a reading outside it, or stuck at
        one of its ends, is judged against (:func:`pkmcal.io.measurements.clipped_readings`)."""
        return None

    @abstractmethod
    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """Which of the machine's limits each pose violates, each shrunk by the safety
        ``margin`` in its own unit where the limit takes one (a machine whose limits take
        none accepts and ignores it). ``margins=False`` says that the
        caller reads only the verdicts: a mechanism may then leave
        :attr:`LimitReport.margins` empty and take a faster path (the hexapod's compiled
        kernel for small batches)."""

    # -- conveniences shared by every mechanism ---------------------------------------

    def param_index(self, names: "list[str] | tuple[str, ...]") -> np.ndarray:
        """Indices of the named parameters; a clear error for an unknown name.

        A name may be a shell-style pattern (``"b1.*"``, ``"L0_*"``) matching several.
        """
        from fnmatch import fnmatchcase

        out: list[int] = []
        for name in names:
            hits = [i for i, p in enumerate(self.param_names) if fnmatchcase(p, name)]
            if not hits:
                raise PkmcalError(
                    f"machine '{self.name}' has no parameter '{name}'; "
                    f"its parameters are {', '.join(self.param_names)}"
                )
            out.extend(h for h in hits if h not in out)
        return np.array(out, dtype=int)

    def as_param_vector(self, params: np.ndarray) -> np.ndarray:
        """``params`` as a float vector (p,) in the order of :attr:`param_names`; a clear
        error for a vector of another length."""
        rho = np.asarray(params, dtype=float)
        if rho.shape != (len(self.param_names),):
            raise PkmcalError(f"machine '{self.name}' has {len(self.param_names)} parameters; "
                              f"got an array of shape {rho.shape}")
        return rho

    def as_pose_array(self, poses: np.ndarray) -> np.ndarray:
        """``poses`` as a float array (N, n); a single pose (n,) becomes (1, n)."""
        poses = np.asarray(poses, dtype=float)
        if poses.ndim == 1:
            poses = poses[None, :]
        if poses.ndim != 2 or poses.shape[1] != self.n_dof:
            raise PkmcalError(
                f"machine '{self.name}' needs poses with {self.n_dof} coordinates "
                f"({', '.join(self.pose_names)}); got an array of shape {poses.shape}"
            )
        return poses

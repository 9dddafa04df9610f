"""The mechanism interface shared by every machine pkmcal calibrates.

A mechanism is an immutable description of a machine: a vector of named kinematic
parameters ρ, and pure, vectorised functions of N poses:

* ``ik(poses)``                    → actuator readings q (N, l)
* ``actuator_pose_jacobian(poses)`` → ∂q/∂pose (N, l, n) at fixed ρ
* ``actuator_param_jacobian(poses)``→ ∂q/∂ρ (N, l, p) at fixed pose
* ``fk(readings)``                 → poses (N, n), with per-pose convergence and
  same-assembly-mode flags (:class:`FKResult`)

This is everything the identification engine needs: every calibration model in pkmcal is
the closure equation ``q = IK(x, ρ)`` plus a sensor model ``y = h(x, θ)``, with the pose x
of each measurement as a nuisance unknown. The hexapod (n = l = 6) and the redundantly
actuated planar machines (l > n) are both implementations of this class.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from pkmcal.errors import PkmcalError


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


class Mechanism(ABC):
    """Abstract parallel mechanism (see module docstring)."""

    name: str
    #: Names of the pose coordinates, e.g. ("x", "y", "z", "a", "b", "c").
    pose_names: tuple[str, ...]
    #: True for pose coordinates that are angles (degrees in files, radians inside).
    pose_is_angle: tuple[bool, ...]
    #: Names of the actuator readings, e.g. ("lambda1", ..., "lambda6").
    actuator_names: tuple[str, ...]

    @property
    def actuator_is_angle(self) -> tuple[bool, ...]:
        """True for actuator readings that are angles (rotary actuators: radians inside,
        degrees in files and on the command line); all False (linear, mm) by default."""
        return (False,) * self.n_actuators

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
    @abstractmethod
    def params(self) -> np.ndarray:
        """The kinematic parameter vector ρ (p,) in internal units."""

    @abstractmethod
    def with_params(self, params: np.ndarray, name: str | None = None) -> "Mechanism":
        """A copy of this machine with the parameter vector replaced."""

    @property
    @abstractmethod
    def home_pose(self) -> np.ndarray:
        """The pose (n,) the FK starts from by default."""

    @abstractmethod
    def ik(self, poses: np.ndarray) -> np.ndarray:
        """Actuator readings q (N, l) of poses (N, n)."""

    @abstractmethod
    def actuator_pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂q/∂pose (N, l, n), with respect to the pose coordinates of :attr:`pose_names`."""

    @abstractmethod
    def actuator_param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂q/∂ρ (N, l, p) at fixed pose."""

    def actuator_jacobians(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(∂q/∂pose, ∂q/∂ρ)`` together; a mechanism overrides this when one pass over the
        poses computes both more cheaply than two."""
        return self.actuator_pose_jacobian(poses), self.actuator_param_jacobian(poses)

    def ik_and_jacobians(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, ∂q/∂pose, ∂q/∂ρ)`` together, for a solver that needs all three at every
        point; a mechanism overrides this when one pass computes them more cheaply."""
        return (self.ik(poses), *self.actuator_jacobians(poses))

    @abstractmethod
    def fk(self, readings: np.ndarray, guess: np.ndarray | None = None) -> FKResult:
        """Poses (N, n) whose IK reproduces ``readings`` (N, l)."""

    def fk_precise(self, readings: np.ndarray, guess: np.ndarray | None = None) -> FKResult:
        """FK exact to rounding, not just to the convergence tolerance, for residuals that a
        least-squares solver evaluates at 1e-12 tolerances or differentiates numerically.
        Default :meth:`fk`, for mechanisms whose FK already stops at a rounding-level step."""
        return self.fk(readings, guess)

    def assembly_signs(self, poses: np.ndarray) -> np.ndarray:
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
            A = self.actuator_pose_jacobian(poses)
            good = np.all(np.isfinite(A), axis=(1, 2))
            det = np.zeros(poses.shape[0])
            if np.any(good):
                det[good] = np.linalg.det(A[good])
        return np.sign(det).astype(np.int8)[:, None]

    def same_branch(self, poses: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """(N,) True where each of ``poses`` (N, n) is on the assembly mode of its
        ``reference`` (one pose (n,) or one per pose (N, n)): the signs of
        :meth:`assembly_signs` agree wherever both are non-zero."""
        poses = self.as_pose_array(poses)
        ref = self.as_pose_array(reference)
        s = self.assembly_signs(poses)
        r = self.assembly_signs(ref)
        r = np.broadcast_to(r, s.shape) if r.shape[0] == 1 else r
        return np.all((s == r) | (s == 0) | (r == 0), axis=1)

    @abstractmethod
    def check_limits(self, poses: np.ndarray) -> LimitReport:
        """Which of the machine's limits each pose violates."""

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

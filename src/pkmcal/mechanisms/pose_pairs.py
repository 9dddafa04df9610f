"""Pairs of poses of one machine as the poses of a mechanism: how the engine reads a
measurement that couples two poses (issue 13, item 3: the distance between two printed
points, Klipper's ``DELTA_ANALYZE``).

Why a mechanism. The engine eliminates one nuisance pose per measurement row
(``identification/residuals.py``): x_j = FK(q_j, ρ), r_j = y_j − h(frame(x_j), s), with the
block structure ∂x_j/∂ρ = −A_j⁻¹B_j per row. A reading of two poses, y = h(x_1, x_2), fits
that structure unchanged when the *row* is the pair: its pose is X = (x_1, x_2) (2n
coordinates), its actuator readings Q = (q_1, q_2) (2l), its parameters the machine's own ρ.
Then, with the machine's IK, A and B of each pose,

    IK_pair(X, ρ) = (IK(x_1, ρ), IK(x_2, ρ)),   A_pair = diag(A_1, A_2),   B_pair = [B_1; B_2],
    FK_pair(Q, ρ) = (FK(q_1, ρ), FK(q_2, ρ)),

and the fk-residual's ∂r/∂ρ = H_pair A_pair⁻¹ B_pair = H_1 A_1⁻¹ B_1 + H_2 A_2⁻¹ B_2 is the
chain rule through both poses; the covariance H A⁻¹ Σ_Q A⁻ᵀ Hᵀ adds the actuator noise of
both. No engine code changes (the least invasive correct design: a reading coupling poses
that share rows with other readings would need cross-row covariances, which the engine's
per-row blocks do not hold; a pair row keeps both poses' noise in its own block).

The frame of a pair (:class:`PairFrame`) is the frame of pose 1 (``p``, ``R``: what a sensor
of one pose reads) with the frame of pose 2 beside it (``second``); its twist is the two
twists stacked, (δp_1, δω_1, δp_2, δω_2) (12), so T_pair = diag(T_1, T_2) (N, 12, 2n) and a
pair sensor's ``frame_jacobian`` is (N, m, 12). Only a sensor that declares it reads pairs
(``works_with`` asks for the ``"pose-pairs"`` ability) can measure this mechanism.

Names: the pose coordinates and actuator readings of pose 2 carry the suffix ``_2``
(``x_2``, ``lambda1_2``); the parameters are the machine's (the same names: a fit of pairs
is a fit of the machine, :attr:`PosePairs.single` is the machine itself).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import FKResult, LimitReport, Mechanism
from pkmcal.mechanisms.frame import Frame

#: Suffix of the second pose's coordinate and actuator names.
SECOND = "_2"


class PairFrame(Frame):
    """Frames of pose pairs: ``p``, ``R`` of pose 1 and ``second`` (a :class:`Frame`) of
    pose 2 (module docstring); twists (N, 12)."""

    __slots__ = ("second",)

    def __init__(self, first: Frame, second: Frame) -> None:
        super().__init__(first.p, first.R)
        self.second = second

    @property
    def first(self) -> Frame:
        return Frame(p=self.p, R=self.R)

    def __getitem__(self, index) -> PairFrame:
        return PairFrame(self.first[index], self.second[index])

    def moved(self, twist: np.ndarray) -> PairFrame:
        """Both frames displaced by twists (N, 12) = (twist of pose 1, twist of pose 2)."""
        t = np.array(np.broadcast_to(np.asarray(twist, dtype=float), (len(self), 12)))
        return PairFrame(self.first.moved(t[:, 0:6]), self.second.moved(t[:, 6:12]))


def _join(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.concatenate([a, b], axis=-1)


@dataclass(frozen=True, eq=False)
class PosePairs(Mechanism):
    """Pairs of poses of ``single`` as one mechanism (module docstring)."""

    single: Mechanism

    def __post_init__(self) -> None:
        if "pose-pairs" in self.single.abilities:
            raise PkmcalError(f"machine '{self.single.name}' is already a machine of pose pairs")

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return self.single == other.single

    __hash__ = None  # type: ignore[assignment]

    # -- declarations: the machine's, pose and actuator names doubled --------------------

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.single.name

    @property
    def kind(self) -> str:  # type: ignore[override]
        return self.single.kind

    @property
    def abilities(self) -> frozenset[str]:  # type: ignore[override]
        return frozenset({"pose-pairs"})

    @property
    def frame_depends_on_params(self) -> bool:  # type: ignore[override]
        return self.single.frame_depends_on_params

    @property
    def default_fixed(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.single.default_fixed

    @property
    def held_without_length(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.single.held_without_length

    @property
    def held_on_one_plane(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.single.held_on_one_plane

    @property
    def point_sets(self):  # type: ignore[override]
        return self.single.point_sets

    @property
    def covariance(self):  # type: ignore[override]
        return self.single.covariance

    @property
    def metadata(self) -> dict:
        return getattr(self.single, "metadata", {})

    @property
    def pose_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(self.single.pose_names) + tuple(n + SECOND for n in self.single.pose_names)

    @property
    def pose_is_angle(self) -> tuple[bool, ...]:  # type: ignore[override]
        return tuple(self.single.pose_is_angle) * 2

    @property
    def actuator_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(self.single.actuator_names) + tuple(n + SECOND for n in self.single.actuator_names)

    @property
    def actuator_is_angle(self) -> tuple[bool, ...]:
        return tuple(self.single.actuator_is_angle) * 2

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.single.param_names

    @property
    def param_is_angle(self) -> tuple[bool, ...]:
        return self.single.param_is_angle

    @property
    def param_units(self) -> tuple[str, ...]:
        return self.single.param_units

    @property
    def params(self) -> np.ndarray:
        return self.single.params

    def with_params(self, params: np.ndarray, name: str | None = None, covariance=None) -> PosePairs:
        return PosePairs(self.single.with_params(params, name=name, covariance=covariance))

    def named_directions(self):
        return self.single.named_directions()

    @property
    def home_pose(self) -> np.ndarray:
        return np.tile(self.single.home_pose, 2)

    def workspace_box(self) -> np.ndarray:
        return np.vstack([self.single.workspace_box()] * 2)

    def summary(self) -> str:
        return self.single.summary() + "\n  (read as pairs of poses: pose 2's names end in '_2')"

    def reading_range(self):
        r = self.single.reading_range()
        return None if r is None else np.vstack([r, r])

    # -- kinematics: the machine's, once per pose of the pair ---------------------------

    def _halves(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = self.as_pose_array(poses)
        n = self.single.n_dof
        return x[:, :n], x[:, n:]

    def _stacked(self, poses: np.ndarray) -> tuple[np.ndarray, int]:
        """The 2N single poses (pose 1 of every pair, then pose 2) and N."""
        x1, x2 = self._halves(poses)
        return np.concatenate([x1, x2], axis=0), len(x1)

    def ik(self, poses: np.ndarray, params=None) -> np.ndarray:
        x, N = self._stacked(poses)
        q = self.single.ik(x, params)
        return _join(q[:N], q[N:])

    def ik_and_jacobians(self, poses: np.ndarray, params=None):
        """(Q, diag(A_1, A_2), [B_1; B_2]) (module docstring)."""
        x, N = self._stacked(poses)
        q, A, B = self.single.ik_and_jacobians(x, params)
        l, n = A.shape[1:]
        A2 = np.zeros((N, 2 * l, 2 * n))
        A2[:, :l, :n], A2[:, l:, n:] = A[:N], A[N:]
        return _join(q[:N], q[N:]), A2, np.concatenate([B[:N], B[N:]], axis=1)

    def actuator_pose_jacobian(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[1]

    def actuator_param_jacobian(self, poses: np.ndarray, params=None) -> np.ndarray:
        return self.ik_and_jacobians(poses, params)[2]

    def frame(self, poses: np.ndarray, params=None) -> PairFrame:
        x1, x2 = self._halves(poses)
        return PairFrame(self.single.frame(x1, params), self.single.frame(x2, params))

    def frame_jacobians(self, poses: np.ndarray, params=None):
        """(diag(T_1, T_2) (N, 12, 2n), [T_ρ1; T_ρ2] (N, 12, p) or None)."""
        x, N = self._stacked(poses)
        T, Tr = self.single.frame_jacobians(x, params)
        n = T.shape[2]
        T2 = np.zeros((N, 12, 2 * n))
        T2[:, :6, :n], T2[:, 6:, n:] = T[:N], T[N:]
        return T2, None if Tr is None else np.concatenate([Tr[:N], Tr[N:]], axis=1)

    def pose_jacobian_from_twist(self, J_twist: np.ndarray, poses: np.ndarray, params=None) -> np.ndarray:
        """[J_1 · T_1, J_2 · T_2] with J_twist = [J_1, J_2] (N, m, 12)."""
        x1, x2 = self._halves(poses)
        return _join(self.single.pose_jacobian_from_twist(J_twist[..., 0:6], x1, params),
                     self.single.pose_jacobian_from_twist(J_twist[..., 6:12], x2, params))

    def poses_from_frame(self, frame: PairFrame) -> np.ndarray:
        return _join(self.single.poses_from_frame(frame.first), self.single.poses_from_frame(frame.second))

    def _fk(self, solve, readings, guess, params) -> FKResult:
        q = np.asarray(readings, dtype=float)
        q = q[None, :] if q.ndim == 1 else q
        l = self.single.n_actuators
        if q.ndim != 2 or q.shape[1] != 2 * l:
            raise PkmcalError(f"machine '{self.name}' read as pose pairs needs {2 * l} readings per pair; got an "
                              f"array of shape {q.shape}")
        N = len(q)
        g = None
        if guess is not None:
            g = np.broadcast_to(np.asarray(guess, dtype=float), (N, 2 * self.single.n_dof))
            g, _ = self._stacked(g)
        r = solve(np.concatenate([q[:, :l], q[:, l:]], axis=0), g, params=params)

        def both(a, f):
            return f(a[:N], a[N:])
        return FKResult(poses=both(r.poses, _join), converged=both(r.converged, np.logical_and),
                        iterations=both(r.iterations, np.maximum), residual=both(r.residual, np.maximum),
                        same_branch=both(r.same_branch, np.logical_and))

    def fk(self, readings, guess=None, params=None, **options) -> FKResult:
        return self._fk(lambda q, g, params: self.single.fk(q, g, params=params, **options), readings, guess, params)

    def fk_precise(self, readings, guess=None, params=None) -> FKResult:
        return self._fk(self.single.fk_precise, readings, guess, params)

    def assembly_signs(self, poses: np.ndarray, params=None) -> np.ndarray:
        x1, x2 = self._halves(poses)
        return _join(self.single.assembly_signs(x1, params), self.single.assembly_signs(x2, params))

    def check_limits(self, poses: np.ndarray, margin: float = 0.0, *, margins: bool = True) -> LimitReport:
        """A pair violates a limit where either of its poses does (margins: the smaller)."""
        x, N = self._stacked(poses)
        rep = self.single.check_limits(x, margin, margins=margins) if margin else \
            self.single.check_limits(x, margins=margins)
        return LimitReport(violations={k: v[:N] | v[N:] for k, v in rep.violations.items()},
                           margins={k: np.minimum(v[:N], v[N:]) for k, v in (rep.margins or {}).items()})


def read_by(machine: Mechanism, sensor) -> Mechanism:
    """``machine`` as the sensor reads it: as :class:`PosePairs` for a sensor whose readings
    couple two poses (its declared ``reads_pose_pairs``), else itself."""
    return PosePairs(machine) if sensor.reads_pose_pairs and "pose-pairs" not in machine.abilities else machine


def single_machine(machine: Mechanism) -> Mechanism:
    """The machine of a :class:`PosePairs` (what a machine file holds), else ``machine``."""
    return machine.single if "pose-pairs" in machine.abilities else machine


__all__ = ["PairFrame", "PosePairs", "SECOND", "read_by", "single_machine"]

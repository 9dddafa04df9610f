"""The elimination strategies: residuals, analytic Jacobians and noise covariances per pose.

Every calibration model in pkmcal is ``q_j = IK(x_j, ρ)`` (actuators) plus ``y_j = h(x_j, s)``
(external sensor), with the pose x_j of measurement j a nuisance unknown. The unknowns of
the engine are θ = [ρ; s]. A *method* eliminates x_j and returns, for all N poses at once,

* ``r``   (N, k)     the residual of each pose,
* ``J``   (N, k, P)  its analytic derivative ∂r/∂θ (all P = p + s parameters),
* ``cov`` (N, k, k)  the covariance the sensor and actuator noise induce on r (first order),

with, per pose, A = ∂IK/∂x (l×n), B = ∂IK/∂ρ (l×p), H = ∂h/∂x (m×n), G = ∂h/∂s (m×s),
Σ_q = diag(σ_q²), Σ_y = diag(σ_y²). The sensor reads the platform frame F(x, ρ) of the
mechanism (``Mechanism.frame``), so H = (∂h/∂twist) · T with T = ∂twist/∂x
(``Mechanism.pose_jacobian_from_twist``), and where the frame depends on ρ (a tool offset
of the mechanism: ``Mechanism.frame_depends_on_params``) ∂h/∂ρ = (∂h/∂twist) · T_ρ enters
the ρ columns. Parameters are passed explicitly: ``mech.ik_and_jacobians(x, params=ρ)``,
``sensor.predict(frame, params=s)``; no machine or sensor object is built per evaluation.

``ik-residual`` (paper 1 §V, eq. 3; x measured by a full-pose sensor)
    x̂_j = the pose of the frame the readings determine (``Sensor.invert``, closed form;
    ``Mechanism.poses_from_frame``);
    r_j = q_j − IK(x̂_j, ρ);  ∂r/∂ρ = −B;  ∂r/∂s = A H⁻¹ G  (x̂ moves with s);
    Σ_j = Σ_q + A H⁻¹ Σ_y H⁻ᵀ Aᵀ.
    ``form="squared"`` is the paper's own residual (L_q² − ‖l(x̂, ρ)‖²) with L_q = L0 + g q
    the measured leg length (g the leg gains, 1 for readings in mm); it needs a mechanism
    with leg lengths (the hexapod).

``fk-residual`` (paper 2 §3, eq. 3; x from the forward kinematics)
    x_j = FK(q_j, ρ);  r_j = y_j − h(x_j, s);  implicit differentiation of IK(x, ρ) = q:
    ∂x/∂ρ = −A⁻¹B, so ∂r/∂ρ = H A⁻¹ B and ∂r/∂s = −G (one batched solve over the poses);
    Σ_j = Σ_y + H A⁻¹ Σ_q A⁻ᵀ Hᵀ.  Poses whose FK does not converge, or converges on another
    assembly mode than its start pose (``FKResult.ok``), are flagged (``converged``); the engine drops those that fail at the nominal machine (error if
    more than 10 %), rejects a trial point where one fails (``engine._Objective``) and
    reports those failing at the solution. A pose whose FK fails keeps the residual at
    its pose at θ0 (finite, for reports; not a derivative of its Jacobian row).
    x_j(θ) is a function of θ alone (a least-squares solver assumes the residual is): never
    warm-started from an earlier evaluation, whose poses depend on the order in which the
    solver tried its points (a far trial point left a tracker campaign's pose on another
    FK solution of the same assembly mode, c = 168° where 1° was commanded, and
    Levenberg–Marquardt stopped on ``xtol`` at cost 2.8e6 where the residual from the
    commanded poses gives 1.2e8; the fit's minimum is 5.568). Per pose, the first of
      1. Newton from its start pose (the commanded pose, else home);
      2. Newton from its pose at θ0 (the model's values; the FK of 1. there);
      3. continuation along θ0 → θ: θ_t = θ0 + t (θ − θ0), t = 1/K … 1
         (K = :data:`FK_CONTINUATION_STEPS`), each Newton from the previous pose, from its
         pose at θ0, a failed step cut into K again (:data:`FK_CONTINUATION_DEPTH` times),
    that converges on the start pose's assembly mode, each a function of θ. 2. and 3. are
    for a start pose outside a chain's reach at θ (a mechanism whose IK is NaN there gives
    Newton no direction): on a 6-RSS fit with the shared solver on λ − IK instead of its
    loop-closure FK (tests/identification/test_engine.py), 93 of 150 commanded poses were outside a rod's
    reach at the fit's minimum, and 4 poses needed 3.; main's warm starts (one pose solve
    per evaluation) found that minimum in 1.2 s CPU, these in 3.5 s. On machines whose FK finds
    the pose from the start (the hexapod, the loop-closure FK of the 6-RSS and 6-PUS, the
    delta's closed form) 1. alone runs: 2.5 Newton iterations per pose against main's 1.5 on
    paper 2's 100-pose indicator fit (2000 against 1200 in all; the fit 10.1-10.4 ms against
    9.8 ms, benchmarks/identification.py --quick, same run).

``projection`` (paper 3 §2, eq. 4–10; general errors-in-variables)
    e_j(x, θ) = W [y_j − h(x, s); q_j − IK(x, ρ)] with W = Σ_e^{-1/2} (identity if
    unweighted); x_j*(θ) = argmin_x ‖e_j‖ (Gauss–Newton); Q = W [H; A] ((m+l)×n) and U⊥
    an orthonormal basis of the orthogonal complement of range(Q) (complete QR), so that
    R = I − Q(QᵀQ)⁻¹Qᵀ = U⊥U⊥ᵀ (eq. 7); r_j = U⊥ᵀ e_j (m + l − n rows, eq. 8–9),
    ∂r/∂θ = U⊥ᵀ ∂e/∂θ (the x-dependence is projected out; the derivative of U⊥ is dropped,
    which leaves the gradient Jᵀr of the cost exact at x*). Weighted, cov = I.

Several sessions (:mod:`pkmcal.sensors.sessions`): s is the stacked per-session sensor
parameters, read through a session sensor bound to the poses (one evaluation per session),
and with re-homing offsets δq (θ = [ρ; s; δq]) each method reads the actuators as
q_j + δq_{s(j)} (:meth:`Model.q_at`): ik-residual ∂r/∂δq = I (squared form 2 L_q),
fk-residual x = FK(q + δq) so ∂r/∂δq = −H A⁻¹, projection ∂e/∂δq = W [0; I], each pose's
block in its session's columns (:meth:`Model.offset_jacobian`); the first session has none.

A :class:`Method` object is the objective of one fit and owns that fit's scratch: the
eliminated poses (and the Jacobian pieces A, B, H A⁻¹ computed from them) of the last θ it
was evaluated at, so that the residual and the Jacobian the solver asks for separately at
one point share one pose solve (``Method._at``); the fk-residual's poses at θ0 (its
fallback starts); the projection's start poses; the ik-residual's
measured poses at the last s.
Machines and sensors hold no state.
"""

from __future__ import annotations

import functools
import sys
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass
from fnmatch import fnmatchcase

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import NoiseModel, Sensor
from pkmcal.sensors.sessions import Sessions, bind_sessions, offset_names

METHODS = ("ik-residual", "fk-residual", "projection", "projection-single")
IK_FORMS = ("plain", "squared")

#: Steps of the fk-residual's continuation along θ0 → θ, and how many times a failed step
#: is cut into as many again (:meth:`FKResidual._follow`): steps down to 4⁻⁴ of the way.
#: On the 6-RSS fit below (150 poses), 8 steps without cutting left 4 poses unsolved at the
#: fit's minimum, 32 solved them; the whole fit took 3.5 s CPU with 4 steps cut 3 times,
#: 8.0 s with 8 cut twice, 4.6 s with 2 cut 7 times (one run each, 2026-12-03).
FK_CONTINUATION_STEPS = 4
FK_CONTINUATION_DEPTH = 3

#: Newton tolerance (mm/rad) and iteration cap for inverting the full-pose sensor and for
#: the projection's inner pose solve.
_POSE_TOL = 1e-11
_POSE_MAX_ITER = 30


@dataclass(frozen=True)
class Evaluation:
    """Residuals of all poses at one parameter vector (module docstring); ``measured`` (N, k)
    the residual entries that are measurements where some are not (None: all;
    :meth:`~pkmcal.sensors.base.Sensor.measured_readings`)."""

    r: np.ndarray
    J: np.ndarray | None
    cov: np.ndarray | None
    converged: np.ndarray
    poses: np.ndarray
    measured: np.ndarray | None = None


@dataclass
class Model:
    """A machine, a sensor, their noise and the measured data, with θ = [ρ; s; δq] packing.

    ``sessions`` (:class:`~pkmcal.sensors.sessions.Sessions`, the session of every pose):
    with several sessions the sensor is a :class:`~pkmcal.sensors.sessions.SessionSensor`
    (s the stacked per-session parameters, ``NAME@LABEL``), bound here to these poses, and
    with ``sessions.offsets`` the sessions after the first have actuator zero offsets δq
    (``dq_i@LABEL``, re-homing): the actuators then read q_j, and the machine's own readings
    are q_j + δq_{s(j)} (:meth:`q_at`). One session (or None): no δq, names as always."""

    mechanism: Mechanism
    sensor: Sensor
    noise: NoiseModel
    q: np.ndarray
    y: np.ndarray
    commanded: np.ndarray | None = None
    sessions: Sessions | None = None

    def __post_init__(self) -> None:
        self.q = np.asarray(self.q, dtype=float)
        self.y = np.asarray(self.y, dtype=float)
        n_pose = self.q.shape[0] if self.q.ndim == 2 else -1
        if self.q.ndim != 2 or self.q.shape[1] != self.mechanism.n_actuators:
            raise PkmcalError(
                f"actuator readings must be an array (N, {self.mechanism.n_actuators}) "
                f"({', '.join(self.mechanism.actuator_names)}); got shape {self.q.shape}"
            )
        if self.y.shape != (n_pose, self.sensor.n_readings):
            raise PkmcalError(
                f"sensor readings must be an array ({n_pose}, {self.sensor.n_readings}) "
                f"({', '.join(self.sensor.reading_names)}), one row per actuator row; got shape {self.y.shape}"
            )
        for what, arr in (("actuator", self.q), ("sensor", self.y)):
            bad = ~np.all(np.isfinite(arr), axis=1)
            if bad.any():
                raise PkmcalError(f"{what} readings of pose {int(np.argmax(bad)) + 1} are not finite numbers")
        if self.commanded is not None:
            self.commanded = self.mechanism.as_pose_array(self.commanded)
            if self.commanded.shape[0] != n_pose:
                raise PkmcalError(f"{self.commanded.shape[0]} commanded poses for {n_pose} measured poses")
        self._bind_sessions(n_pose)
        names = self.names
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise PkmcalError(f"machine and sensor both have parameters named {', '.join(dup)}")
        self.sigma_q = np.broadcast_to(np.asarray(self.noise.actuator_std, dtype=float), (self.q.shape[1],)).copy()
        self.sigma_y = np.broadcast_to(np.asarray(self.noise.reading_std, dtype=float), (self.y.shape[1],)).copy()

    def _bind_sessions(self, n_pose: int) -> None:
        """Several sessions: the session sensor bound to these poses, and the offset names."""
        ses = self.sessions
        self.offset_names: tuple[str, ...] = ()
        if ses is not None and len(ses) != n_pose:
            raise PkmcalError(f"{len(ses)} session labels for {n_pose} measured poses")
        self.sensor = bind_sessions(self.sensor, ses)
        if ses is not None and ses.several and ses.offsets:
            self.offset_names = offset_names(self.mechanism.n_actuators, ses.labels)

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    @property
    def n_mech(self) -> int:
        return len(self.mechanism.param_names)

    @property
    def n_sensor(self) -> int:
        return len(self.sensor.param_names)

    @property
    def n_offsets(self) -> int:
        """Number of re-homing offsets δq (0 without them)."""
        return len(self.offset_names)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.mechanism.param_names) + tuple(self.sensor.param_names) + self.offset_names

    @property
    def param_is_angle(self) -> tuple[bool, ...]:
        """Angle flags of :attr:`names` (an offset is an angle for a rotary actuator)."""
        off = tuple(self.mechanism.actuator_is_angle) * (self.n_offsets // max(self.mechanism.n_actuators, 1))
        return tuple(self.mechanism.param_is_angle) + tuple(self.sensor.param_is_angle) + off

    @property
    def theta0(self) -> np.ndarray:
        return np.concatenate([self.mechanism.params, self.sensor.params, np.zeros(self.n_offsets)])

    def parts(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ρ (p,), s (s,)) of θ = [ρ; s; δq] (views)."""
        theta = np.asarray(theta, dtype=float)
        return theta[:self.n_mech], theta[self.n_mech:self.n_mech + self.n_sensor]

    def q_at(self, theta: np.ndarray) -> np.ndarray:
        """The actuator readings of the machine's own zeros, q_j + δq_{s(j)} (N, l); ``q``
        itself without offsets."""
        if not self.n_offsets:
            return self.q
        l = self.mechanism.n_actuators
        dq = np.zeros((self.sessions.n_sessions, l))
        dq[1:] = np.asarray(theta, dtype=float)[self.n_mech + self.n_sensor:].reshape(-1, l)
        return self.q + dq[self.sessions.index]

    def offset_jacobian(self, dr_dq: np.ndarray) -> np.ndarray | None:
        """∂r/∂δq (N, k, o) from ∂r/∂q (N, k, l) (the same matrix for every pose may be
        given as (k, l)): pose j's block in the columns of its session's δq; None without
        offsets."""
        if not self.n_offsets:
            return None
        l = self.mechanism.n_actuators
        M = np.broadcast_to(dr_dq, (self.n_poses,) + np.shape(dr_dq)[-2:])
        out = np.zeros(M.shape[:2] + (self.n_offsets,))
        for k, g in enumerate(self.sessions.groups[1:]):
            out[g, :, k * l:(k + 1) * l] = M[g]
        return out

    def split(self, theta: np.ndarray) -> tuple[Mechanism, Sensor]:
        """The machine and sensor objects at θ = [ρ; s; δq] (for results; the methods pass ρ
        and s explicitly instead)."""
        rho, s = self.parts(theta)
        # sensors are immutable values: one whose parameters did not move is returned as is
        sensor = self.sensor if np.array_equal(s, self.sensor.params) else self.sensor.with_params(s.copy())
        return self.mechanism.with_params(rho.copy()), sensor

    def subset(self, keep: np.ndarray) -> "Model":
        """The same model on the poses ``keep`` (boolean or index array), with their sessions."""
        return Model(self.mechanism, self.sensor, self.noise, self.q[keep], self.y[keep],
                     None if self.commanded is None else self.commanded[keep],
                     None if self.sessions is None else self.sessions.subset(keep))

    def start_poses(self) -> np.ndarray:
        """Starting poses (N, n) for the FK / pose solves: the commanded poses, else home."""
        if self.commanded is not None:
            return self.commanded.copy()
        return np.tile(self.mechanism.home_pose, (self.n_poses, 1))


# -- small dense linear algebra --------------------------------------------------------


#: The BLAS libraries' threadpoolctl controllers, by whether scipy's own BLAS was loaded
#: when the inventory was taken (scipy ships a BLAS of its own beside NumPy's).
_BLAS_CONTROLLERS: dict[bool, list] = {}


def _blas_controllers() -> list:
    with_scipy = "scipy.linalg" in sys.modules
    found = _BLAS_CONTROLLERS.get(with_scipy)
    if found is None:
        try:
            from threadpoolctl import ThreadpoolController

            found = [c for c in ThreadpoolController().lib_controllers if c.user_api == "blas"]
        except ImportError:
            found = []
        _BLAS_CONTROLLERS[with_scipy] = found
    return found


@contextmanager
def single_threaded_blas(scipy: bool = True):
    """Run the block with one BLAS thread (threadpoolctl, when installed).

    The engine's matrices are small (≤ a few thousand rows × ≤ ~60 columns); a threaded
    BLAS only adds synchronisation: the SVD of a 90×42 Jacobian took 0.76 ms (median)
    with two OpenBLAS threads and 0.47 ms with one (2-core Xeon, 2026-11-22).

    ``scipy``: load scipy's own BLAS first so that it is limited too (the engine's blocks
    call scipy); planning, which runs on NumPy alone, passes False and limits the BLAS
    libraries loaded so far (scipy.linalg takes ~0.4 s to import).
    """
    if scipy:
        import scipy.linalg  # noqa: F401
    # set and restore the thread counts directly: ThreadpoolController.limit re-reads the
    # library inventory on every call (0.017 ms against 0.008 ms for this block, measured
    # 2026-11-22 on a 2-core Xeon)
    libs = [(c, c.get_num_threads()) for c in _blas_controllers()]
    libs = [(c, n) for c, n in libs if isinstance(n, int) and n != 1]
    for c, _ in libs:
        c.set_num_threads(1)
    try:
        yield
    finally:
        for c, n in libs:
            c.set_num_threads(n)


# -- parameter selection ---------------------------------------------------------------


def pattern_matches(names: tuple[str, ...], pat: str) -> list[int]:
    """Indices of the parameter ``names`` that the shell pattern ``pat`` of a ``free``/``fix``
    list names (a sensor parameter named without ``@LABEL``: that parameter in every session)."""
    hits = [i for i, n in enumerate(names) if fnmatchcase(n, pat)]
    if not hits and "@" not in pat:
        # several sessions: a sensor parameter named without @LABEL is that parameter in every session
        hits = [i for i, n in enumerate(names) if fnmatchcase(n, pat + "@*")]
    return hits


def _match(names: tuple[str, ...], patterns, what: str) -> list[int]:
    if isinstance(patterns, str):
        patterns = [p for p in patterns.replace(",", " ").split() if p]
    out: list[int] = []
    for pat in patterns:
        hits = pattern_matches(names, pat)
        if not hits:
            raise PkmcalError(f"{what}: no parameter matches '{pat}'; the parameters are {', '.join(names)}")
        out.extend(h for h in hits if h not in out)
    return out


def default_fixed_parameters(mechanism) -> tuple[str, ...]:
    """The parameters the mechanism holds unless they are freed by name (its
    ``default_fixed`` names and patterns: a delta's tool offset, which a sensor of the tool
    point cannot tell from the towers' positions)."""
    return _matching(tuple(mechanism.param_names), tuple(mechanism.default_fixed))


@functools.lru_cache(maxsize=64)
def _matching(names: tuple[str, ...], patterns: tuple[str, ...]) -> tuple[str, ...]:
    """The ``names`` that match one of the shell ``patterns`` (a pure function of two
    tuples of strings, so cached: every fit asks it of its machine)."""
    return tuple(n for n in names if any(fnmatchcase(n, pat) for pat in patterns))


def default_estimated_index(mechanism) -> np.ndarray:
    """Indices of the machine parameters a fit estimates unless told otherwise: all but
    :func:`default_fixed_parameters` (a hexapod's 42 geometry parameters of papers 1 and 2,
    without its leg gains)."""
    held = set(default_fixed_parameters(mechanism))
    return np.array([i for i, n in enumerate(mechanism.param_names) if n not in held], dtype=int)


def sensor_held_parameters(mechanism, sensor, priors=()) -> tuple[str, ...]:
    """The machine parameters a fit holds by default because its ``sensor`` cannot determine
    them and no prior in ``priors`` (:class:`~pkmcal.identification.priors.Prior` or
    ``NAME=MEAN±STD`` strings) names them: the mechanism's ``held_without_length`` when the
    sensor sees no length (``sensor.sees_length`` False: a Z probe reads heights only; a
    delta's arms) and its ``held_on_one_plane`` when every reading is on one plane
    (``sensor.reads_one_plane``: a bed; a delta's rail leans). A prior on a parameter is a
    measurement of it (rods measured with calipers), so it is freed."""
    patterns = []
    if not sensor.sees_length:                  # declared by every sensor (sensors/base.py)
        patterns += list(mechanism.held_without_length)
    if sensor.reads_one_plane:
        patterns += list(mechanism.held_on_one_plane)
    if not patterns:
        return ()
    from pkmcal.identification.priors import parse_prior

    given = [(parse_prior(p) if isinstance(p, str) else p).pattern for p in (priors or ())]
    held = _matching(tuple(mechanism.param_names), tuple(patterns))
    return tuple(n for n in held if not any(fnmatchcase(n, pat) for pat in given))


def candidate_parameters(model: Model, free=None, fix=None, priors=None) -> tuple[list[int], bool]:
    """Indices of the parameters to estimate before any automatic gauge, and whether the
    choice was explicit (``free`` or a ``fix`` list given). Without ``free``: every machine
    parameter but those it holds by default (:func:`default_fixed_parameters`) and, when
    ``priors`` is given (a fit's, possibly empty), those its sensor cannot see
    (:func:`sensor_held_parameters`); and the sensor's ``default_free``. Without ``priors``
    (an analysis of what the sensor sees: identifiability, planning) every parameter the
    machine does not hold is a candidate. The sessions' actuator offsets, when the model has
    them, are candidates in both cases (``fix`` holds them)."""
    names = model.names
    offsets = list(range(model.n_mech + model.n_sensor, len(names)))
    if free is None:
        held = set(default_fixed_parameters(model.mechanism))
        if priors is not None:
            held |= set(sensor_held_parameters(model.mechanism, model.sensor, priors))
        cand = [i for i in range(model.n_mech) if names[i] not in held] + \
            [names.index(n) for n in model.sensor.default_free] + offsets
        explicit = False
    else:
        cand = sorted(set(_match(names, free, "--free")) | set(offsets))
        explicit = True
    if fix is not None and not (isinstance(fix, str) and fix == "auto"):
        drop = set(_match(names, fix, "--fix"))
        cand = [i for i in cand if i not in drop]
        explicit = True
    return cand, explicit


# -- helpers ----------------------------------------------------------------------------


def _diag_cov(sigma: np.ndarray, n: int) -> np.ndarray:
    return np.broadcast_to(np.diag(sigma**2), (n, sigma.size, sigma.size))


def _full_jacobian(J_mech: np.ndarray, J_sensor: np.ndarray | None, n_sensor: int,
                   J_offsets: np.ndarray | None = None, negate_mech: bool = False) -> np.ndarray:
    """[±J_mech, J_sensor, J_offsets] (N, k, p + s + o) (−J_mech for ``negate_mech``, negated
    in place: no copy); the sensor columns NaN when not computed; no offset columns for
    ``J_offsets=None``."""
    N, k, p = J_mech.shape
    n_off = 0 if J_offsets is None else J_offsets.shape[-1]
    J = np.empty((N, k, p + n_sensor + n_off))
    if negate_mech:
        np.negative(J_mech, out=J[..., :p])
    else:
        J[..., :p] = J_mech
    J[..., p:p + n_sensor] = np.nan if J_sensor is None else J_sensor
    if n_off:
        J[..., p + n_sensor:] = J_offsets
    return J


def _sandwich(M: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """M diag(σ²) Mᵀ for stacks M (N, a, b)."""
    Ms = M * sigma**2
    return Ms @ np.swapaxes(M, 1, 2)


def sensor_pose_jacobian(mech: Mechanism, sensor: Sensor, x: np.ndarray, frame, rho, s) -> np.ndarray:
    """H = ∂h/∂x (N, m, n) = (∂h/∂twist) · T at poses x with frames ``frame``."""
    return mech.pose_jacobian_from_twist(sensor.frame_jacobian(frame, s), x, rho)


def sensor_mech_jacobian(mech: Mechanism, sensor: Sensor, x: np.ndarray, frame, rho, s) -> np.ndarray | None:
    """∂h/∂ρ (N, m, p) at fixed x = (∂h/∂twist) · T_ρ, or None when the frame does not
    depend on ρ (``Mechanism.frame_depends_on_params``)."""
    if not mech.frame_depends_on_params:
        return None
    _, T_rho = mech.frame_jacobians(x, rho)
    return None if T_rho is None else sensor.frame_jacobian(frame, s) @ T_rho


# -- the methods ------------------------------------------------------------------------


class Method(ABC):
    """One elimination strategy; subclasses implement :meth:`evaluate`.

    ``sensor_columns``: when False (set by the engine when no sensor parameter is free),
    a method may skip the sensor-parameter columns of J and fill them with NaN.
    ``prewhitened``: the weighted residual already has unit covariance (the engine applies
    no whitening). ``single_step``: the engine takes one Gauss–Newton step from the start
    instead of iterating to convergence. ``path_independent``: the residual at θ is the
    same whatever the object evaluated before (no pose solve started from an earlier
    point's poses), so the engine checks the solver's stop on this object's own evaluation
    at the solution instead of a new object's (``engine._checked``).
    """

    name: str
    sensor_columns: bool = True
    prewhitened: bool = False
    single_step: bool = False
    path_independent: bool = False

    def __init__(self, model: Model, weighted: bool = True):
        self.model = model
        self.weighted = weighted
        self._last: tuple | None = None

    def _at(self, theta: np.ndarray, solve) -> dict:
        """``solve(θ)``: a dict of the eliminated poses and what depends on them, kept for
        the last θ together with the pieces :meth:`_piece` adds. A solver asks for the
        residual and then for the Jacobian at the same point; both must see the same poses
        (the pose solves are not repeated, and an iterative one re-solved could differ at
        round-off), and the engine's start and end evaluations reuse the solver's."""
        theta = np.ascontiguousarray(theta, dtype=float)
        key = theta.tobytes()
        if self._last is None or self._last[0] != key:
            self._last = (key, solve(theta))
        return self._last[1]

    @staticmethod
    def _piece(state: dict, name: str, compute):
        """``state[name]``, computed by ``compute()`` on first use at this θ."""
        value = state.get(name)
        if value is None:
            value = state[name] = compute()
        return value

    @abstractmethod
    def rows_per_pose(self) -> int:
        """Residual rows k per pose."""

    @abstractmethod
    def evaluate(self, theta: np.ndarray, jac: bool = True, cov: bool = True) -> Evaluation:
        """Residuals (and Jacobian, covariance) of all poses at the full parameter vector θ."""

    def row_names(self) -> tuple[str, ...]:
        return tuple(f"r{i + 1}" for i in range(self.rows_per_pose()))

    def row_units(self) -> tuple[str, ...]:
        """Unit of each raw residual row: "mm", "rad", or "1" for rows without one physical
        unit (whitened, or combining readings of different units)."""
        return ("1",) * self.rows_per_pose()


class IKResidual(Method):
    """``ik-residual``: r_j = q_j − IK(x̂_j, ρ), x̂_j from a full-pose sensor (paper 1)."""

    name = "ik-residual"
    path_independent = True     # the measured poses depend on s alone

    def __init__(self, model: Model, weighted: bool = True, form: str = "plain"):
        super().__init__(model, weighted)
        if form not in IK_FORMS:
            raise PkmcalError(f"ik-residual form must be one of {', '.join(IK_FORMS)}; got '{form}'")
        mech, sensor = model.mechanism, model.sensor
        if sensor.n_readings != mech.n_dof:
            raise PkmcalError(
                f"method 'ik-residual' needs a full-pose sensor ({mech.n_dof} readings per pose); "
                f"the '{sensor.kind}' sensor gives {sensor.n_readings} ({', '.join(sensor.reading_names)}): "
                "use --method fk-residual or projection"
            )
        if not sensor.invertible:
            raise PkmcalError(f"method 'ik-residual' needs a sensor whose readings determine the platform frame "
                              f"(full pose); the '{sensor.kind}' sensor's do not: use --method fk-residual or "
                              "projection")
        if mech.frame_depends_on_params:
            raise PkmcalError(f"method 'ik-residual' needs a platform frame independent of the machine's "
                              f"parameters; machine '{mech.name}' has a parametrised tool frame: use --method "
                              "fk-residual or projection")
        if form == "squared" and "leg-lengths" not in mech.abilities:
            raise PkmcalError(f"ik-residual form 'squared' needs leg lengths; machine '{mech.name}' has none")
        self.form = form
        #: this fit's measured poses at the last sensor parameters s (they depend on s only)
        self._measured: tuple[np.ndarray, dict] | None = None

    def rows_per_pose(self) -> int:
        return self.model.mechanism.n_actuators

    def row_names(self) -> tuple[str, ...]:
        return tuple(self.model.mechanism.actuator_names)

    def row_units(self) -> tuple[str, ...]:
        if self.form == "squared":   # L_q² − L²: mm² rows, no unit of the readings
            return ("1",) * self.rows_per_pose()
        mech = self.model.mechanism
        return tuple("rad" if a else u for a, u in zip(mech.actuator_is_angle, mech.actuator_units))

    def _measured_poses(self, rho, s) -> dict:
        """x̂ (the poses of the frames the readings determine) and converged, and on demand
        H⁻¹ and H⁻¹G: kept while the sensor parameters s do not change (they depend on s
        only, the frame not on ρ)."""
        last = self._measured
        if last is None or not np.array_equal(last[0], s):
            m = self.model
            if "pose-convention" in m.mechanism.abilities and m.sensor.reads_pose(s):
                # the readings are the pose (declared by both): x̂ = y, H = I, bit for bit
                x = np.array(m.y, dtype=float)
                frame, identity = m.mechanism.frame(x, rho), True
            else:
                frame, identity = m.sensor.invert(m.y, s), False
                x = m.mechanism.poses_from_frame(frame)
            conv = np.all(np.isfinite(x), axis=1)
            last = self._measured = (np.array(s), {"x": x, "conv": conv, "frame": frame, "rho": rho, "s": s,
                                                   "identity": identity})
        return last[1]

    def _Hinv(self, poses: dict) -> np.ndarray | None:
        """H⁻¹ (N, n, m), or None when the readings are the pose (H = I)."""
        if poses["identity"]:
            return None
        m = self.model
        return self._piece(poses, "Hinv", lambda: np.linalg.inv(
            sensor_pose_jacobian(m.mechanism, m.sensor, poses["x"], poses["frame"], poses["rho"], poses["s"])))

    def _AHinv(self, A: np.ndarray, poses: dict) -> np.ndarray:
        """A H⁻¹: how the sensor noise moves the actuator residual."""
        Hinv = self._Hinv(poses)
        return A if Hinv is None else A @ Hinv

    def _HinvG(self, poses: dict) -> np.ndarray:
        def compute():
            G = self.model.sensor.param_jacobian(poses["frame"], poses["s"])
            Hinv = self._Hinv(poses)
            return G if Hinv is None else Hinv @ G

        return self._piece(poses, "HinvG", compute)

    def _solve(self, theta):
        # IK with its Jacobians in one pass: a solver asks for the Jacobian at most points
        rho, s = self.model.parts(theta)
        poses = self._measured_poses(rho, s)
        q, A, B = self.model.mechanism.ik_and_jacobians(poses["x"], rho)
        return {"rho": rho, "poses": poses, "q": q, "AB": (A, B), "q_meas": self.model.q_at(theta)}

    def evaluate(self, theta, jac=True, cov=True):
        m = self.model
        mech = m.mechanism
        st = self._at(theta, self._solve)
        rho, poses, q_model = st["rho"], st["poses"], st["q"]
        x, conv = poses["x"], poses["conv"]
        q_meas = st["q_meas"]          # the readings, shifted by the session's offsets δq
        r = q_meas - q_model
        need_Js = jac and self.sensor_columns
        A, B = st["AB"] if (jac or cov) else (None, None)
        J = C = None
        if jac:
            Js = A @ self._HinvG(poses) if need_Js else None
            J = _full_jacobian(B, Js, m.n_sensor, m.offset_jacobian(np.eye(m.q.shape[1])), negate_mech=True)
        if cov:
            AH = self._AHinv(A, poses)
            C = _diag_cov(m.sigma_q, m.n_poses) + _sandwich(AH, m.sigma_y)
        if self.form == "squared":
            # r² = L_q² − L(x)², L_q = L0 + g q = g q + (L(x) − g IK(x)) (L0 independent of x;
            # for unit gains these are the operations of L_q = q + L0, bit for bit).
            g = mech.reading_gains(rho)
            L = mech.leg_lengths(x, rho)
            Lq = g * q_meas + (L - g * q_model)
            r = Lq**2 - L**2
            if jac:
                dL = mech.length_param_jacobian(x, rho)                # ∂L/∂ρ
                dLq = mech.lengths_from_readings_param_jacobian(q_meas)   # ∂L_q/∂ρ: 1 on L0_i, q_i on gain_i
                Jr = 2.0 * Lq[..., None] * dLq - 2.0 * L[..., None] * dL
                # ∂L/∂x = g A: the sensor columns 2 L g · ∂λ/∂s; ∂L_q/∂δq = g
                J = _full_jacobian(Jr, None if Js is None else 2.0 * (L * g)[..., None] * Js, m.n_sensor,
                                   m.offset_jacobian(2.0 * (Lq * g)[:, :, None] * np.eye(m.q.shape[1])))
            if cov:
                AH = self._AHinv(A, poses)
                C = _diag_cov(m.sigma_q, m.n_poses) * (2 * Lq * g)[:, :, None] * (2 * Lq * g)[:, None, :] \
                    + _sandwich(2 * (L * g)[..., None] * AH, m.sigma_y)
        return Evaluation(r=r, J=J, cov=C, converged=conv, poses=x)


class FKResidual(Method):
    """``fk-residual``: r_j = y_j − h(FK(q_j, ρ), s) (paper 2)."""

    name = "fk-residual"
    path_independent = True     # FK from the start poses, θ0's poses, or along θ0 → θ

    def __init__(self, model: Model, weighted: bool = True):
        super().__init__(model, weighted)
        mech = model.mechanism
        if mech.n_actuators != mech.n_dof:
            raise PkmcalError(
                f"method 'fk-residual' needs as many actuators as degrees of freedom; machine "
                f"'{mech.name}' has {mech.n_actuators} for {mech.n_dof}: use --method projection"
            )
        self._start = model.start_poses()
        #: the poses at θ0 and where they were solved (computed on first need), fallback 2 and 3
        self._base: tuple[np.ndarray, np.ndarray] | None = None

    def rows_per_pose(self) -> int:
        return self.model.sensor.n_readings

    def row_names(self) -> tuple[str, ...]:
        return tuple(self.model.sensor.reading_names)

    def row_units(self) -> tuple[str, ...]:
        return tuple("rad" if a else "mm" for a in self.model.sensor.reading_is_angle)

    def _fk(self, theta, idx, guess, precise: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(poses, solved) of the poses ``idx`` at θ by Newton from ``guess`` (len(idx), n):
        converged, finite, and on the assembly mode of the guess."""
        m = self.model
        solve = m.mechanism.fk_precise if precise else m.mechanism.fk
        fk = solve(m.q_at(theta)[idx], guess, params=m.parts(theta)[0])
        return fk.poses, fk.ok & np.all(np.isfinite(fk.poses), axis=1)

    def _base_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """(poses (N, n), solved (N,)) at θ0, from the start poses (fallbacks 2 and 3)."""
        if self._base is None:
            x0, ok0 = self._fk(self.model.theta0, np.arange(self.model.n_poses), self._start)
            self._base = (np.where(ok0[:, None], x0, self._start), ok0)
        return self._base

    def poses_at(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """(x (N, n), solved (N,)): FK of every pose at θ, a function of θ alone (module
        docstring: from the start poses, else from the poses at θ0, else by continuation
        along θ0 → θ); where none solves, the pose at θ0 (finite) with solved False."""
        m = self.model
        theta = np.asarray(theta, dtype=float)
        idx = np.arange(m.n_poses)
        x, ok = self._fk(theta, idx, self._start)
        if ok.all():
            return x, ok
        x0, ok0 = self._base_poses()
        x = np.where(ok[:, None], x, x0)
        bad = idx[~ok & ok0]
        if len(bad) and not np.array_equal(theta, m.theta0):
            xb, okb = self._fk(theta, bad, x0[bad])
            x[bad[okb]] = xb[okb]
            ok[bad[okb]] = True
            bad = bad[~okb]
            if len(bad):
                xc, okc = self._follow(theta, bad, x0[bad], 0.0, 1.0, FK_CONTINUATION_DEPTH)
                x[bad[okc]] = xc[okc]
                ok[bad[okc]] = True
        return x, ok

    def _follow(self, theta, idx, x, t0: float, t1: float, depth: int) -> tuple[np.ndarray, np.ndarray]:
        """(poses, solved) of the poses ``idx`` at θ_t1 (θ_t = θ0 + t (θ − θ0)) followed
        from their poses ``x`` at θ_t0 in :data:`FK_CONTINUATION_STEPS` equal steps, each a
        Newton solve from the previous step's pose on its assembly mode (polished at t = 1);
        a pose whose step fails is followed again over that step in as many sub-steps, down
        to ``depth`` levels, and is given up where the finest step fails (its path left the
        reach, or went through a singularity)."""
        theta0 = self.model.theta0
        x = np.array(x, dtype=float)
        alive = np.ones(len(idx), dtype=bool)
        ts = t0 + (t1 - t0) * np.arange(1, FK_CONTINUATION_STEPS + 1) / FK_CONTINUATION_STEPS
        ts[-1] = t1
        prev = t0
        for t in ts:
            a = np.flatnonzero(alive)
            if not len(a):
                break
            xt, okt = self._fk(theta0 + t * (theta - theta0), idx[a], x[a], precise=t == 1.0)
            x[a[okt]] = xt[okt]
            failed = a[~okt]
            if len(failed) and depth > 0:
                xs, oks = self._follow(theta, idx[failed], x[failed], prev, t, depth - 1)
                x[failed[oks]] = xs[oks]
                failed = failed[~oks]
            alive[failed] = False
            prev = t
        return x, alive

    def _solve(self, theta):
        m = self.model
        rho, s = m.parts(theta)
        x, ok = self.poses_at(theta)
        frame = m.mechanism.frame(x, rho)
        return {"rho": rho, "s": s, "x": x, "frame": frame, "ok": ok,
                "r": m.sensor.reading_residual(m.y, m.sensor.predict(frame, s))}

    @staticmethod
    def _HAi(A, H):
        """H A⁻¹ (m×n per pose) by one batched solve with m right-hand sides (m ≪ p); NaN
        where A is singular (never at a converged FK pose, whose Newton steps solved it)."""
        from pkmcal.identification._small_linalg import solve_right  # compiled: numba on first use

        return solve_right(A, H)[0]

    def evaluate(self, theta, jac=True, cov=True):
        m = self.model
        mech, sensor = m.mechanism, m.sensor
        st = self._at(theta, self._solve)
        rho, s, x, frame, ok, r = (st[k] for k in ("rho", "s", "x", "frame", "ok", "r"))
        J = C = None
        if jac or cov:
            A, B = self._piece(st, "AB", lambda: mech.actuator_jacobians(x, rho))
            HAi = self._piece(st, "HAi", lambda: self._HAi(A, sensor_pose_jacobian(mech, sensor, x, frame, rho, s)))
        if jac:
            # ∂r/∂ρ = H A⁻¹ B (− ∂h/∂ρ at fixed x), ∂r/∂s = −G (skipped when no sensor parameter
            # is free), ∂r/∂δq = −H A⁻¹ (x = FK(q + δq): A ∂x/∂δq = I); kept for this θ (the
            # engine's end evaluation and its check of the solver's stop both ask for it)
            def jacobian():
                Jr = HAi @ B
                Gr = sensor_mech_jacobian(mech, sensor, x, frame, rho, s)
                if Gr is not None:
                    Jr = Jr - Gr
                out = _full_jacobian(Jr, -sensor.param_jacobian(frame, s) if self.sensor_columns else None,
                                     m.n_sensor, m.offset_jacobian(-HAi) if m.n_offsets else None)
                out.flags.writeable = False      # shared by the callers at this θ
                return out

            J = self._piece(st, ("J", self.sensor_columns), jacobian)
        if cov:
            C = _diag_cov(m.sigma_y, m.n_poses) + _sandwich(HAi, m.sigma_q)
        measured = sensor.measured_readings(frame)      # the rows are the readings
        return Evaluation(r=r, J=J, cov=C, converged=ok, poses=x, measured=None if measured.all() else measured)


class Projection(Method):
    """``projection``: the nuisance pose projected out of the stacked residual (paper 3).

    ``hold_poses=True`` is ``projection-single``, paper 3 eq. 10 as published: the residual
    is linearised at the commanded poses (not re-solved for x_j*), and the engine takes one
    Gauss–Newton step from the nominal parameters (:attr:`single_step`).
    """

    name = "projection"
    prewhitened = True

    @property
    def single_step(self) -> bool:  # type: ignore[override]
        return self.hold_poses

    def __init__(self, model: Model, weighted: bool = True, hold_poses: bool = False):
        super().__init__(model, weighted)
        if hold_poses and model.commanded is None:
            raise PkmcalError("method 'projection-single' (paper 3 eq. 10) linearises at the commanded poses: "
                              "the measurements need them (cmd_x ... columns)")
        self.hold_poses = hold_poses
        if hold_poses:
            self.name = "projection-single"
        mech, sensor = model.mechanism, model.sensor
        k = sensor.n_readings + mech.n_actuators - mech.n_dof
        if k <= 0:
            raise PkmcalError("method 'projection' needs more readings (sensor + actuators) than pose coordinates")
        sig = np.concatenate([model.sigma_y, model.sigma_q])
        if weighted:
            if np.any(sig <= 0):
                raise PkmcalError(
                    "the weighted projection method needs a positive noise standard deviation for every "
                    "sensor and actuator reading; give them in the setup or use --unweighted"
                )
            self._w = 1.0 / sig
        else:
            self._w = np.ones_like(sig)
        self._sig = sig
        # every inner pose solve starts from the FK of the readings at the nominal machine (fixed
        # for the fit, so that x_j*(θ) is a function of θ alone, as for the fk-residual)
        start = model.start_poses()
        if mech.n_actuators == mech.n_dof:
            fk = mech.fk(model.q, guess=start)
            start = np.where(fk.ok[:, None], fk.poses, start)
        self._start = start

    def rows_per_pose(self) -> int:
        mech = self.model.mechanism
        return self.model.sensor.n_readings + mech.n_actuators - mech.n_dof

    def row_units(self) -> tuple[str, ...]:
        """r = U⊥ᵀ W e combines all readings: "1" when whitened (weighted) or when the
        readings mix lengths and angles, else their common unit."""
        flags = tuple(self.model.sensor.reading_is_angle) + tuple(self.model.mechanism.actuator_is_angle)
        unit = "1" if self.weighted or (any(flags) and not all(flags)) else ("rad" if all(flags) else "mm")
        return (unit,) * self.rows_per_pose()

    def _stacked_and_Q(self, rho, s, x, q, Q: bool = True):
        """(e (N, m+l), Q (N, m+l, n) or None): the whitened stacked residual and its pose
        Jacobian W [H; A] at poses x, with the actuator readings ``q`` (δq applied)."""
        m = self.model
        mech, sensor = m.mechanism, m.sensor
        frame = mech.frame(x, rho)
        ey = sensor.reading_residual(m.y, sensor.predict(frame, s))
        eq = q - mech.ik(x, rho)
        e = np.concatenate([ey, eq], axis=1) * self._w
        if not Q:
            return e, None
        H = sensor_pose_jacobian(mech, sensor, x, frame, rho, s)
        return e, np.concatenate([H, mech.actuator_pose_jacobian(x, rho)], axis=1) * self._w[:, None]

    def solve_poses(self, rho, s, q=None) -> tuple[np.ndarray, np.ndarray]:
        """x_j* = argmin ‖e_j(x)‖ for every pose by batched Gauss–Newton from the fit's start
        poses (never from an earlier evaluation's: x_j* is a function of θ alone); ``q`` the
        actuator readings with δq applied (default the model's)."""
        q = self.model.q if q is None else q
        x = self._start.copy()
        conv = np.zeros(len(x), dtype=bool)
        for _ in range(_POSE_MAX_ITER):
            e, Q = self._stacked_and_Q(rho, s, x, q)
            QtQ = np.swapaxes(Q, 1, 2) @ Q
            step = np.linalg.solve(QtQ, (np.swapaxes(Q, 1, 2) @ e[..., None]))[..., 0]
            x = x + step
            conv = np.max(np.abs(step), axis=1) <= 1e-12 * (1.0 + np.max(np.abs(x), axis=1))
            if conv.all():
                break
        return x, conv & np.all(np.isfinite(x), axis=1)

    def _solve(self, theta):
        rho, s = self.model.parts(theta)
        q = self.model.q_at(theta)
        if self.hold_poses:
            x, ok = self.model.commanded.copy(), np.ones(self.model.n_poses, dtype=bool)
        else:
            x, ok = self.solve_poses(rho, s, q)
        return {"rho": rho, "s": s, "x": x, "ok": ok, "q": q}

    def _projector(self, rho, s, x, q):
        """(e (N, m+l), U⊥ᵀ (N, k, m+l)): the stacked whitened residual and the orthonormal
        complement of range(Q) (complete QR of Q, eq. 7)."""
        e, Q = self._stacked_and_Q(rho, s, x, q)
        Qfull, _ = np.linalg.qr(Q, mode="complete")
        return e, np.swapaxes(Qfull[:, :, self.model.mechanism.n_dof:], 1, 2)

    def _param_jacobian(self, rho, s, x, Ut):
        """U⊥ᵀ ∂e/∂θ = −U⊥ᵀ W [∂h/∂θ; ∂IK/∂θ] (eq. 10), and U⊥ᵀ W [0; I] for the offsets δq
        (e's actuator rows are q + δq − IK)."""
        m = self.model
        mech, sensor = m.mechanism, m.sensor
        ms = sensor.n_readings
        frame = mech.frame(x, rho)
        de = np.zeros((len(x), ms + mech.n_actuators, m.n_mech + m.n_sensor + m.n_offsets))
        de[:, ms:, : m.n_mech] = -mech.actuator_param_jacobian(x, rho)
        de[:, :ms, m.n_mech:m.n_mech + m.n_sensor] = -sensor.param_jacobian(frame, s)
        if m.n_offsets:
            de[:, ms:, m.n_mech + m.n_sensor:] = m.offset_jacobian(np.eye(mech.n_actuators))
        Gr = sensor_mech_jacobian(mech, sensor, x, frame, rho, s)
        if Gr is not None:
            de[:, :ms, : m.n_mech] = -Gr
        return Ut @ (de * self._w[:, None])

    def project(self, theta, x, jac: bool = True):
        """Paper 3 eq. 7–10 at θ and the given poses ``x`` (not re-solved): (r (N, k), J
        (N, k, P) or None, U⊥ᵀ (N, k, m+l)) with r = U⊥ᵀ e(x, θ), J = U⊥ᵀ ∂e/∂θ =
        −U⊥ᵀ W [∂h/∂θ; ∂IK/∂θ]."""
        rho, s = self.model.parts(theta)
        e, Ut = self._projector(rho, s, x, self.model.q_at(theta))
        return (Ut @ e[..., None])[..., 0], self._param_jacobian(rho, s, x, Ut) if jac else None, Ut

    def evaluate(self, theta, jac=True, cov=True):
        st = self._at(theta, self._solve)
        rho, s, x, ok = st["rho"], st["s"], st["x"], st["ok"]
        # the projector is computed once per θ, for the residual and then the Jacobian
        e, Ut = self._piece(st, "projector", lambda: self._projector(rho, s, x, st["q"]))
        r = self._piece(st, "r", lambda: (Ut @ e[..., None])[..., 0])
        J = self._piece(st, "J", lambda: self._param_jacobian(rho, s, x, Ut)) if jac else None
        C = None
        if cov:
            # whitened e has covariance diag((w σ)²); projected: U⊥ᵀ diag(.) U⊥ (= I if weighted)
            C = _sandwich(Ut, self._w * self._sig)
        return Evaluation(r=r, J=J, cov=C, converged=ok, poses=x)


#: :func:`default_method` in words, for the commands' ``--method`` help.
DEFAULT_METHOD_RULE = ("projection for redundantly actuated machines, else ik-residual for a full-pose sensor "
                       "(one whose readings give the platform frame), else fk-residual")


def default_method(setup, mechanism: Mechanism | None = None) -> str:
    """The method used when none is named, the one rule for every command and function
    (``identify``, ``identifiability``, ``plan``, ``observability``, studies' ``auto``, the
    demo, :func:`pkmcal.identify`; :data:`DEFAULT_METHOD_RULE`): ``projection``
    for a redundantly actuated machine (paper 3), else ``ik-residual`` for a full-pose sensor
    (paper 1: the sensor's readings determine the platform frame, ``Sensor.invertible``) and
    ``fk-residual`` otherwise (paper 2). Without ``mechanism`` the machine is taken as not
    redundant."""
    if mechanism is not None and mechanism.n_actuators != mechanism.n_dof:
        return "projection"
    return "ik-residual" if setup.sensor.invertible else "fk-residual"


def make_method(name: str, model: Model, weighted: bool = True, form: str = "plain") -> Method:
    """The method called ``name`` (one of :data:`METHODS`) on ``model``."""
    if name == "ik-residual":
        return IKResidual(model, weighted, form=form)
    if form != "plain":
        raise PkmcalError(f"option form='{form}' only applies to method 'ik-residual'")
    if name == "fk-residual":
        return FKResidual(model, weighted)
    if name in ("projection", "projection-single"):
        return Projection(model, weighted, hold_poses=name == "projection-single")
    raise PkmcalError(f"unknown identification method '{name}'; use one of {', '.join(METHODS)}")


def whitening(cov: np.ndarray, what: str = "residual") -> np.ndarray:
    """W_j = L_j⁻¹ with L_j L_jᵀ = Σ_j (batched Cholesky), so that W_j r_j has unit covariance.

    A singular Σ_j (a zero noise standard deviation that leaves a residual noise-free) is
    a user error: the weighted fit needs every residual to have some noise.
    """
    from pkmcal.identification._small_linalg import cholesky_inverse  # compiled: numba on first use

    W, bad = cholesky_inverse(cov)
    if bad >= 0:
        raise PkmcalError(
            f"the noise model makes the {what} of pose {bad + 1} noise-free (singular covariance): "
            "give positive standard deviations for the sensor and actuator noise in the setup, "
            "or fit unweighted (--unweighted)"
        )
    return W

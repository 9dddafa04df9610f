"""Projection identification of redundantly actuated machines (paper 3 §2, eq. 4–10).

Per pose j the stacked, noise-whitened residual of tool reading and encoder readings,

    e_j = W [ŷ_j − h(x_j, s);  q̂_j − IK(x_j, ρ)],      W = diag(1/σ_y, 1/σ_q),

is linear in the unknown pose deviation through Q = W [J_f; Γ] ((m + l) × n, eq. 5–6).
Eliminating it with R = I − Q(QᵀQ)⁻¹Qᵀ = U⊥U⊥ᵀ (eq. 7), U⊥ an orthonormal basis of the
complement of range(Q) from a complete QR of the *whitened* Q (no (QᵀQ)⁻¹ with mixed
units), leaves m + l − n independent equations per pose (eq. 8–9):

    U⊥ᵀ e_j = −U⊥ᵀ W [J_ρ; H] Δθ,                Δθ = [Δρ (incl. dq); Δs].

The encoder offsets dq are ordinary mechanism parameters (reading = true position + dq,
see :mod:`pkmcal.mechanisms.planar`), so the paper's separate −R₂ Δq_r block is the dq
columns of H. Two ways to solve eq. 10:

* ``linearisation="single"`` — the paper: one least-squares step, linearised at the
  commanded poses and the nominal parameters.
* ``linearisation="iterated"`` (default) — re-linearised Gauss–Newton: each iteration
  re-solves the pose x_j* = argmin ‖e_j‖ at the current parameters and projects there
  (:class:`pkmcal.identification.residuals.Projection`, the engine's ``projection``
  method), then takes a rank-revealing least-squares step. This is Gauss–Newton on the
  full errors-in-variables problem with the poses eliminated.

Steps use the column-scaled pseudo-inverse with the rank of
:func:`pkmcal.identification.identifiability.analyse_jacobian`, so unidentifiable
combinations (named in the report) stay at their starting values (minimum-norm step).

Baselines (paper 3 §1): ``ignore_redundancy`` (actuators assumed at their commands: the
measured following errors are replaced by zero) and ``actuator_subset`` (only n of the l
actuators used, a non-redundant calibration). Compensation commands a target tool
reading through the identified model; evaluation runs the real machine's equilibrium
(:func:`pkmcal.mechanisms.statics.equilibrium`) under those commands.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.identifiability import IdentifiabilityReport, analyse_jacobian, identifiability
from pkmcal.identification.residuals import Model, Projection
from pkmcal.mechanisms.base import LimitReport, Mechanism
from pkmcal.mechanisms.planar import PlanarMechanism
from pkmcal.mechanisms.statics import equilibrium
from pkmcal.sensors.base import MeasurementSetup, NoiseModel, Sensor

LINEARISATIONS = ("iterated", "single")


@dataclass(frozen=True)
class RedundantFit:
    """Result of :func:`identify_redundant`.

    ``mechanism``, ``sensor`` the identified models; ``free`` the estimated parameter names;
    ``delta`` (len(free),) their change from the start; ``report`` the identifiability of
    the free set (rank, null space by name, gauge); ``cost`` ½‖r‖² per iteration;
    ``poses`` (N, n) the estimated real poses; ``iterations``; ``message``; ``covariance``
    (len(free),)² of the estimates, (JᵀJ)⁺ of the whitened projected Jacobian truncated to
    the rank (weighted fits only; unidentifiable directions get zero variance: read it
    together with ``report``).
    """

    mechanism: Mechanism
    sensor: Sensor
    free: tuple[str, ...]
    delta: np.ndarray
    report: IdentifiabilityReport
    cost: list[float]
    poses: np.ndarray
    iterations: int
    message: str
    rows_per_pose: int = 0
    covariance: np.ndarray | None = None

    @property
    def std(self) -> np.ndarray | None:
        """Standard deviations (len(free),) of the estimates (weighted fits; first order)."""
        return None if self.covariance is None else np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


def _free_index(names: tuple[str, ...], free) -> np.ndarray:
    out = []
    for f in free:
        if f not in names:
            raise PkmcalError(f"no parameter '{f}' to identify; the parameters are {', '.join(names)}")
        out.append(names.index(f))
    return np.array(out, dtype=int)


def single_linearisation(model: Model, weighted: bool = True, method: Projection | None = None):
    """Paper 3 eq. 10 at the commanded poses: (r (N, k), J (N, k, P)) with k = m + l − n,
    r = U⊥ᵀ W e(x_c, θ₀), J = ∂r/∂θ = −U⊥ᵀ W [∂h/∂θ; ∂IK/∂θ] (:meth:`Projection.project`
    without the pose solve; ``method`` an existing :class:`Projection` of ``model``)."""
    method = Projection(model, weighted=weighted) if method is None else method
    r, J, _ = method.project(model.mechanism, model.sensor, model.start_poses())
    return r, J


def _scaled_svd(J: np.ndarray, rank: int):
    """SVD of the column-scaled J (unit column norms; zero columns stay zero) truncated to
    ``rank``: (U (M, k), s (k,), Vt (k, P), scale (P,))."""
    col = np.linalg.norm(J, axis=0)
    scale = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 0.0)
    U, s, Vt = np.linalg.svd(J * scale, full_matrices=False)
    k = min(rank, int(np.sum(s > 0)))
    return U[:, :k], s[:k], Vt[:k], scale


def _pinv_normal(J: np.ndarray, rank: int) -> np.ndarray:
    """(JᵀJ)⁺ of the column-scaled J truncated to ``rank``, in physical units."""
    _, s, Vt, scale = _scaled_svd(J, rank)
    V = Vt.T / s
    return (V @ V.T) * np.outer(scale, scale)


def _step(J: np.ndarray, r: np.ndarray, rank: int) -> np.ndarray:
    """Minimum-norm Gauss–Newton step −J⁺r of the column-scaled J truncated to ``rank``."""
    U, s, Vt, scale = _scaled_svd(J, rank)
    return -(Vt.T @ ((U.T @ r) / s)) * scale


def identify_redundant(
    mechanism: Mechanism,
    sensor: Sensor,
    commanded: np.ndarray,
    readings: np.ndarray,
    tool: np.ndarray,
    noise: NoiseModel,
    free: "tuple[str, ...] | list[str] | None" = None,
    *,
    linearisation: str = "iterated",
    weighted: bool = True,
    max_iter: int = 30,
    tol: float = 1e-10,
) -> RedundantFit:
    """Identify mechanism and sensor parameters by projection (module docstring).

    ``commanded`` (N, n) commanded poses (linearisation points); ``readings`` (N, l)
    measured encoder readings (command + following error); ``tool`` (N, m) tracker
    readings; ``noise`` their standard deviations (weights); ``free`` parameter names of
    mechanism and sensor to estimate (default: every mechanism parameter and the sensor's
    default free ones). Neither the actuator stiffness nor the load is needed.
    """
    if linearisation not in LINEARISATIONS:
        raise PkmcalError(f"linearisation must be one of {', '.join(LINEARISATIONS)}; got '{linearisation}'")
    model = Model(mechanism, sensor, noise, q=readings, y=tool, commanded=commanded)
    names = model.names
    if free is None:
        free = tuple(mechanism.param_names) + tuple(sensor.default_free)
    free = tuple(free)
    idx = _free_index(names, free)
    theta = model.theta0.copy()
    cost: list[float] = []
    method = Projection(model, weighted=weighted)
    poses = model.start_poses()
    report = None
    it = 0
    message = "converged" if linearisation == "iterated" else "single linearisation at the commanded poses (eq. 10)"
    theta_prev = d_prev = None
    halvings = 0
    for it in range(1, (1 if linearisation == "single" else max_iter) + 1):
        if linearisation == "single":
            r, J = single_linearisation(model, method=method)
        else:
            ev = method.evaluate(theta, jac=True, cov=False)
            if not ev.converged.all():
                bad = int(np.argmax(~ev.converged)) + 1
                raise PkmcalError(f"projection: the pose solve of pose {bad} did not converge; check its readings")
            r, J, poses = ev.r, ev.J, ev.poses
        r = r.reshape(-1)
        c_now = 0.5 * float(r @ r)
        if cost and c_now > cost[-1] * (1.0 + 1e-9) and halvings < 10:
            # the Gauss–Newton step overshot (large errors): halve it and re-evaluate
            d_prev = 0.5 * d_prev
            theta[idx] = theta_prev + d_prev
            halvings += 1
            continue
        halvings = 0
        cost.append(c_now)
        Jf = J.reshape(r.size, -1)[:, idx]
        report = analyse_jacobian(Jf, free, tuple(mechanism.param_names))
        d = _step(Jf, r, report.rank)
        theta_prev, d_prev = theta[idx].copy(), d
        theta[idx] += d
        # stop when the step is negligible or cannot lower the cost any more (the decrease
        # a Gauss–Newton step predicts is ½‖J d‖²)
        small = np.max(np.abs(d) * np.linalg.norm(Jf, axis=0)) <= tol * max(1.0, np.sqrt(2 * cost[-1]))
        stalled = 0.5 * float(np.sum((Jf @ d) ** 2)) <= 1e-10 * cost[-1]
        if small or stalled:
            break
    else:
        if linearisation == "iterated":
            message = f"stopped after {max_iter} iterations"
    mech_fit, sens_fit = model.split(theta)
    if linearisation == "iterated":
        ev = method.evaluate(theta, jac=False, cov=False)
        cost.append(0.5 * float(np.sum(ev.r**2)))
        poses = ev.poses
    return RedundantFit(mechanism=mech_fit, sensor=sens_fit, free=free, delta=theta[idx] - model.theta0[idx],
                        report=report, cost=cost, poses=poses, iterations=it, message=message,
                        rows_per_pose=sensor.n_readings + mechanism.n_actuators - mechanism.n_dof,
                        covariance=_pinv_normal(Jf, report.rank) if weighted else None)


def projection_identifiability(mechanism, sensor, poses, noise, free) -> IdentifiabilityReport:
    """Rank and named null space of the projected Jacobian at ``poses`` (noise-free data):
    :func:`pkmcal.identification.identifiability.identifiability` with ``method="projection"``
    (the report lists ``free`` in the machine's then the sensor's parameter order)."""
    free = tuple(free)
    _free_index(tuple(mechanism.param_names) + tuple(sensor.param_names), free)
    return identifiability(mechanism, MeasurementSetup(sensor, noise), poses, method="projection", free=list(free))


# -- baselines ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ActuatorSubset(Mechanism):
    """The machine seen through only some of its actuators (a non-redundant baseline)."""

    base: Mechanism
    keep: tuple[int, ...] = field(default=())

    @property
    def name(self) -> str:  # type: ignore[override]
        return f"{self.base.name}[{','.join(self.base.actuator_names[i] for i in self.keep)}]"

    @property
    def pose_names(self):  # type: ignore[override]
        return self.base.pose_names

    @property
    def pose_is_angle(self):  # type: ignore[override]
        return self.base.pose_is_angle

    @property
    def actuator_names(self):  # type: ignore[override]
        return tuple(self.base.actuator_names[i] for i in self.keep)

    @property
    def param_names(self):
        return self.base.param_names

    @property
    def params(self):
        return self.base.params

    def with_params(self, params, name=None):
        return ActuatorSubset(self.base.with_params(params), self.keep)

    @property
    def home_pose(self):
        return self.base.home_pose

    @property
    def home(self):
        return self.base.home_pose

    def ik(self, poses):
        return self.base.ik(poses)[:, list(self.keep)]

    def actuator_pose_jacobian(self, poses):
        return self.base.actuator_pose_jacobian(poses)[:, list(self.keep)]

    def actuator_param_jacobian(self, poses):
        return self.base.actuator_param_jacobian(poses)[:, list(self.keep)]

    fk = PlanarMechanism.fk

    def noise(self, noise: NoiseModel) -> NoiseModel:
        """``noise`` (of the full machine) with the actuator standard deviations of ``keep``."""
        act = np.broadcast_to(np.asarray(noise.actuator_std, dtype=float), (self.base.n_actuators,))[list(self.keep)]
        return NoiseModel(noise.reading_std, act, noise.distribution)

    def check_limits(self, poses) -> LimitReport:
        return self.base.check_limits(poses)


def identify_ignoring_redundancy(mechanism, sensor, commanded, commands, tool, noise, free=None, **kw) -> RedundantFit:
    """Baseline: actuators assumed at their commands (``commands`` (N, l) in place of the
    measured readings; the following errors are ignored)."""
    return identify_redundant(mechanism, sensor, commanded, commands, tool, noise, free, **kw)


def identify_actuator_subset(mechanism, sensor, commanded, readings, tool, noise, keep, free=None, **kw) -> RedundantFit:
    """Baseline: a non-redundant calibration with the n actuators ``keep`` only (their
    measured readings); parameters those actuators do not see stay nominal."""
    sub = ActuatorSubset(mechanism, tuple(int(k) for k in keep))
    if free is None:
        free = tuple(mechanism.param_names) + tuple(sensor.default_free)
    fit = identify_redundant(sub, sensor, commanded, np.asarray(readings)[:, list(sub.keep)], tool, sub.noise(noise),
                             free, **kw)
    return dataclasses.replace(fit, mechanism=fit.mechanism.base)


# -- compensation and evaluation ---------------------------------------------------------


def commands_for_targets(mechanism: Mechanism, sensor, targets: np.ndarray, angles=None) -> tuple[np.ndarray, np.ndarray]:
    """Poses (N, n) and commanded readings (N, l) that put the tool on ``targets`` (N, 2,
    tracker frame) according to the model (``sensor.poses_for_readings`` then IK)."""
    poses = sensor.poses_for_readings(targets, angles)
    return poses, mechanism.ik(poses)


def _settled(real, real_sensor, commands, stiffness, load, guess):
    """The real machine's equilibrium under ``commands``; an error if a pose does not settle."""
    eq = equilibrium(real, commands, stiffness, load, real_sensor, guess=guess)
    if not eq.converged.all():
        raise PkmcalError(f"equilibrium did not converge at pose {int(np.argmax(~eq.converged)) + 1}")
    return eq


def tool_errors(real: Mechanism, real_sensor, commands, targets, stiffness, load, guess) -> np.ndarray:
    """|y_real − target| (N,) of the real machine at equilibrium under ``commands``."""
    eq = _settled(real, real_sensor, commands, stiffness, load, guess)
    return np.linalg.norm(real_sensor.predict(eq.poses) - targets, axis=1)


def simulate_measurements(real, real_sensor, nominal, poses, stiffness, load, noise: NoiseModel, rng):
    """Commands of the nominal model at ``poses``, the real machine's equilibrium, and noisy
    encoder and tracker readings: ``(commands, readings, tool, equilibrium_result)``."""
    commands = nominal.ik(poses)
    eq = _settled(real, real_sensor, commands, stiffness, load, poses)
    e_y, e_q = noise.sample(rng, (len(poses), real_sensor.n_readings), (len(poses), real.n_actuators))
    return commands, eq.readings + e_q, real_sensor.predict(eq.poses) + e_y, eq


@dataclass(frozen=True)
class HeldOutResult:
    """Held-out tool errors (mm) before and after calibration by each method."""

    before: np.ndarray
    after: dict[str, np.ndarray]
    fits: dict[str, RedundantFit]

    def improvement_pct(self, method: str) -> float:
        return 100.0 * (1.0 - float(np.mean(self.after[method])) / float(np.mean(self.before)))


def calibration_experiment(
    nominal: Mechanism,
    nominal_sensor,
    real: Mechanism,
    real_sensor,
    calib_poses: np.ndarray,
    check_poses: np.ndarray,
    stiffness,
    load,
    noise: NoiseModel,
    rng: np.random.Generator,
    free=None,
    subset=None,
    methods=("projection", "projection-single", "ignore-redundancy", "actuator-subset"),
    weights: NoiseModel | None = None,
) -> HeldOutResult:
    """Paper 3 §3 in simulation: measure ``calib_poses`` on the real machine, identify by
    each method, command the held-out ``check_poses``' tool points through each model and
    measure the real tool errors (before: the nominal model).

    ``noise`` is drawn on the simulated readings; ``weights`` (default ``noise``) are the
    standard deviations the identification weights its rows with."""
    commands, readings, tool, _ = simulate_measurements(real, real_sensor, nominal, calib_poses, stiffness, load, noise, rng)
    noise = noise if weights is None else weights
    fits: dict[str, RedundantFit] = {}
    if "projection" in methods:
        fits["projection"] = identify_redundant(nominal, nominal_sensor, calib_poses, readings, tool, noise, free)
    if "projection-single" in methods:
        fits["projection-single"] = identify_redundant(nominal, nominal_sensor, calib_poses, readings, tool, noise, free,
                                                       linearisation="single")
    if "projection-unweighted" in methods:
        fits["projection-unweighted"] = identify_redundant(nominal, nominal_sensor, calib_poses, readings, tool, noise,
                                                           free, weighted=False)
    if "ignore-redundancy" in methods:
        fits["ignore-redundancy"] = identify_ignoring_redundancy(nominal, nominal_sensor, calib_poses, commands, tool,
                                                                 noise, free)
    if "actuator-subset" in methods:
        keep = tuple(range(nominal.n_dof)) if subset is None else tuple(subset)
        fits["actuator-subset"] = identify_actuator_subset(nominal, nominal_sensor, calib_poses, readings, tool, noise,
                                                           keep, free)
    targets = nominal_sensor.predict(check_poses)
    angles = check_poses[:, 2] if nominal.n_dof == 3 else None
    before = tool_errors(real, real_sensor, nominal.ik(check_poses), targets, stiffness, load, check_poses)
    after = {}
    for name, fit in fits.items():
        poses, cmd = commands_for_targets(fit.mechanism, fit.sensor, targets, angles)
        after[name] = tool_errors(real, real_sensor, cmd, targets, stiffness, load, poses)
    return HeldOutResult(before=before, after=after, fits=fits)

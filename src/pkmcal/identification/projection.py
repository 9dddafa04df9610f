"""Paper 3 (Jeon et al., CIRP 2010) as named configurations of the identification engine.

Per pose j the stacked, noise-whitened residual of tool reading and encoder readings,

    e_j = W [ŷ_j − h(x_j, s);  q̂_j − IK(x_j, ρ)],      W = diag(1/σ_y, 1/σ_q),

is linear in the unknown pose deviation through Q = W [J_f; Γ] ((m + l) × n, eq. 5–6).
Eliminating it with R = I − Q(QᵀQ)⁻¹Qᵀ = U⊥U⊥ᵀ (eq. 7) leaves m + l − n equations per
pose (eq. 8–9),  U⊥ᵀ e_j = −U⊥ᵀ W [J_ρ; H] Δθ : the engine's ``projection`` method
(:class:`pkmcal.identification.residuals.Projection`). The encoder offsets dq are ordinary
mechanism parameters (reading = true position + dq), so the paper's −R₂ Δq_r block is the
dq columns of H.

:func:`fit_redundant` runs one of :data:`METHODS` by name, every one through
:func:`pkmcal.identification.engine.identify` with ``method="projection"`` and the
engine's automatic gauge (``fix="auto"``: an unidentifiable combination is fixed at its
start by pivoted QR and named in ``identifiability``):

* ``projection`` — weighted; the engine re-solves x_j* = argmin ‖e_j‖ at every iterate
  (Gauss–Newton on the errors-in-variables problem with the poses eliminated);
* ``projection-single`` — the paper's eq. 10: one linear least-squares step, linearised at
  the commanded poses and the nominal parameters (the engine's ``projection-single``);
* ``projection-unweighted`` — rows in raw mm and rad (W = I);
* ``ignore-redundancy``, ``actuator-subset`` — the baselines of paper 3 §1
  (:func:`pkmcal.identification.redundant_campaign.baseline_inputs`).

:func:`calibration_experiment` is paper 3 §3 in simulation: the real machine settles at
static equilibrium (:func:`~pkmcal.identification.redundant_campaign.simulate_redundant_campaign`),
each method identifies, and the held-out tool errors of the real machine commanded through
each model are measured (:func:`~pkmcal.identification.redundant_campaign.tool_errors`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import IdentificationResult, identify
from pkmcal.identification.redundant_campaign import (
    BASELINES,
    baseline_inputs,
    baseline_result,
    simulate_redundant_campaign,
    tool_errors,
)
from pkmcal.identification.residuals import Model, make_method
from pkmcal.identification.simulation import SimulationResult
from pkmcal.mechanisms.base import LimitReport, Mechanism
from pkmcal.sensors.base import MeasurementSetup, NoiseModel, Sensor

#: The paper-3 fits :func:`fit_redundant` knows (the reproduction's and benchmark's rows).
METHODS = ("projection", "projection-single", "projection-unweighted") + BASELINES


def single_linearisation(model: Model, weighted: bool = True):
    """Paper 3 eq. 10 at the commanded poses: (r (N, k), J (N, k, P)) with k = m + l − n,
    r = U⊥ᵀ W e(x_c, θ₀), J = ∂r/∂θ = −U⊥ᵀ W [∂h/∂θ; ∂IK/∂θ]: the engine's
    ``projection-single`` residual at the start."""
    ev = make_method("projection-single", model, weighted).evaluate(model.theta0, jac=True, cov=False)
    return ev.r, ev.J


def fit_redundant(method: str, machine: Mechanism, setup: MeasurementSetup, measurements, free=None,
                  keep=None) -> IdentificationResult:
    """Identify ``machine`` (+ the setup's sensor) from ``measurements`` by the paper-3
    ``method`` (module docstring), through :func:`~pkmcal.identification.engine.identify`
    with the automatic gauge. ``keep``: the actuators (0-based) of ``actuator-subset``."""
    if method not in METHODS:
        raise PkmcalError(f"unknown paper-3 method '{method}'; use one of {', '.join(METHODS)}")
    fit_machine, fit_setup, data = machine, setup, measurements
    if method in BASELINES:
        fit_machine, fit_setup, data = baseline_inputs(method, machine, setup, measurements, keep)
    result = identify(fit_machine, fit_setup, data, method="projection-single" if method == "projection-single"
                      else "projection", free=free, fix="auto", weighted=method != "projection-unweighted")
    return baseline_result(result, machine, method) if method in BASELINES else result


# -- the non-redundant view of a machine (actuator-subset baseline) -----------------------


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

    def with_params(self, params, name=None, covariance=None):
        return ActuatorSubset(self.base.with_params(params), self.keep)

    @property
    def kind(self) -> str:  # type: ignore[override]
        return self.base.kind

    @property
    def abilities(self):  # type: ignore[override]
        return self.base.abilities

    @property
    def frame_depends_on_params(self) -> bool:  # type: ignore[override]
        return self.base.frame_depends_on_params

    @property
    def home_pose(self):
        return self.base.home_pose

    @property
    def home(self):
        return self.base.home_pose

    def workspace_box(self):
        return self.base.workspace_box()

    def summary(self) -> str:
        return f"{self.name}: {self.base.kind} seen through actuators {', '.join(self.actuator_names)}"

    def ik(self, poses, params=None):
        return self.base.ik(poses, params)[:, list(self.keep)]

    def actuator_pose_jacobian(self, poses, params=None):
        return self.base.actuator_pose_jacobian(poses, params)[:, list(self.keep)]

    def actuator_param_jacobian(self, poses, params=None):
        return self.base.actuator_param_jacobian(poses, params)[:, list(self.keep)]

    def frame(self, poses, params=None):
        return self.base.frame(poses, params)

    def frame_jacobians(self, poses, params=None):
        return self.base.frame_jacobians(poses, params)

    def pose_jacobian_from_twist(self, J_twist, poses, params=None):
        return self.base.pose_jacobian_from_twist(J_twist, poses, params)

    def poses_from_frame(self, frame):
        return self.base.poses_from_frame(frame)

    def noise(self, noise: NoiseModel) -> NoiseModel:
        """``noise`` (of the full machine) with the actuator standard deviations of ``keep``."""
        act = np.broadcast_to(np.asarray(noise.actuator_std, dtype=float), (self.base.n_actuators,))[list(self.keep)]
        return NoiseModel(noise.reading_std, act, noise.distribution)

    def check_limits(self, poses) -> LimitReport:
        return self.base.check_limits(poses)


# -- paper 3 §3 in simulation --------------------------------------------------------------


@dataclass(frozen=True)
class HeldOutResult:
    """Held-out tool errors (mm) before and after calibration by each method, the fits and
    the simulated calibration campaign."""

    before: np.ndarray
    after: dict[str, np.ndarray]
    fits: dict
    simulation: SimulationResult

    def improvement_pct(self, method: str) -> float:
        """100 (1 − mean(after) / mean(before)) (paper 3 §3.1, §3.2)."""
        return 100.0 * (1.0 - float(np.mean(self.after[method])) / float(np.mean(self.before)))


def calibration_experiment(
    nominal: Mechanism,
    nominal_sensor: Sensor,
    real: Mechanism,
    setup: MeasurementSetup,
    calib_poses: np.ndarray,
    check_poses: np.ndarray,
    rng: np.random.Generator,
    free=None,
    keep=None,
    methods=METHODS,
    weights: NoiseModel | None = None,
    ignore_limits: tuple[str, ...] = ("workspace",),
) -> HeldOutResult:
    """Paper 3 §3 in simulation: measure ``calib_poses`` on ``real`` (``setup``: its true
    sensor, the noise drawn and the actuator stiffness and load of its ``simulation``
    block), identify by each of ``methods`` (:func:`fit_redundant`, starting from
    ``nominal`` and ``nominal_sensor``), command the held-out ``check_poses``' tool points
    y* = h(x_c, θ_nominal) through each model and measure the real tool errors ("before":
    the nominal model). ``weights`` (default the setup's noise) are the standard deviations
    the identification weights its rows with. ``ignore_limits``: the sampled poses lie in
    the nominal workspace box, which the real machine may leave by its errors; reach and
    transmission limits stay checked (a pose that fails them is an error here)."""
    sim = simulate_redundant_campaign(nominal, real, setup, calib_poses, rng, ignore_limits)
    if sim.dropped:
        k, why = next(iter(sim.dropped.items()))
        raise PkmcalError(f"calibration pose {k + 1} was not reached by the real machine: {why}")
    fit_setup = MeasurementSetup(nominal_sensor, setup.noise if weights is None else weights)
    fits = {m: fit_redundant(m, nominal, fit_setup, sim.measurements, free, keep) for m in methods}
    for m, f in fits.items():
        if not f.success:
            raise PkmcalError(f"the {m} fit did not converge ({f.message})")

    def held_out(model, model_sensor, name):
        err = tool_errors(model, model_sensor, real, setup, check_poses, name, ignore_limits, nominal_sensor)
        if not err.valid.all():
            k, why = next(iter(err.dropped.items()))
            raise PkmcalError(f"held-out pose {k + 1} was not reached by the real machine ({name}): {why}")
        return err.tool

    return HeldOutResult(before=held_out(nominal, nominal_sensor, "before"),
                         after={m: held_out(f.mechanism, f.sensor, m) for m, f in fits.items()},
                         fits=fits, simulation=sim)

"""Paper 3 (Jeon et al., CIRP 2010) through the identification engine: the projection
residual at the commanded poses, and the non-redundant view of a machine.

Per pose j the stacked, noise-whitened residual of tool reading and encoder readings,

    e_j = W [ŷ_j − h(x_j, s);  q̂_j − IK(x_j, ρ)],      W = diag(1/σ_y, 1/σ_q),

is linear in the unknown pose deviation through Q = W [J_f; Γ] ((m + l) × n, eq. 5–6).
Eliminating it with R = I − Q(QᵀQ)⁻¹Qᵀ = U⊥U⊥ᵀ (eq. 7) leaves m + l − n equations per
pose (eq. 8–9),  U⊥ᵀ e_j = −U⊥ᵀ W [J_ρ; H] Δθ : the engine's ``projection`` method
(:class:`pkmcal.identification.residuals.Projection`). The encoder offsets dq are ordinary
mechanism parameters (reading = true position + dq), so the paper's −R₂ Δq_r block is the
dq columns of H. :func:`single_linearisation` is eq. 10 at the commanded poses.

:class:`ActuatorSubset` is a machine seen through n of its l actuators (the
``actuator-subset`` baseline of paper 3 §1, :mod:`pkmcal.identification.baselines`). The
paper-3 experiment (each method's fit, held-out tool errors) is
:mod:`pkmcal.reproduce.paper3_experiment`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pkmcal.identification.residuals import Model, make_method
from pkmcal.mechanisms.base import LimitReport, Mechanism
from pkmcal.sensors.base import NoiseModel

def single_linearisation(model: Model, weighted: bool = True):
    """Paper 3 eq. 10 at the commanded poses: (r (N, k), J (N, k, P)) with k = m + l − n,
    r = U⊥ᵀ W e(x_c, θ₀), J = ∂r/∂θ = −U⊥ᵀ W [∂h/∂θ; ∂IK/∂θ]: the engine's
    ``projection-single`` residual at the start."""
    ev = make_method("projection-single", model, weighted).evaluate(model.theta0, jac=True, cov=False)
    return ev.r, ev.J


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

"""Paper 3's reference [7] (Jeong et al., J. Mech. Design 2004) as a baseline: calibration of a
redundantly actuated machine whose actuator stiffness K and load F are known.

Paper 3 §1–2: "the stiffness of the actuating joints should be measured before the
parallel mechanism machine is assembled" — with K and the load known, the pose a command
produces is predicted by the statics (paper 3 eqs. 1–3) and the kinematic parameters are
fitted to the tool and encoder readings. Nonlinearly, per pose j with commands c_j (the
nominal IK of the commanded pose), the model machine θ = [ρ; s] settles at

    x_j(θ):  g(x, θ) = Γᵀ K (IK(x, ρ) − c_j) − J_f(x, s)ᵀ F = 0      (:func:`~pkmcal.mechanisms.statics.equilibrium`)

and the whitened residual is e_j = [(ŷ_j − h(x_j, s)) / σ_y ; (q̂_j − IK(x_j, ρ)) / σ_q]
(tracker and encoders; the encoders read IK at equilibrium). The Jacobian follows from the
implicit function theorem, dx_j/dθ = −(∂g/∂x)⁻¹ ∂g/∂θ, with ∂g/∂x and ∂g/∂θ by central
differences of the analytic g (as the equilibrium solver forms its Hessian), so

    ∂e_j/∂θ = −W [∂h/∂x dx/dθ + ∂h/∂s ;  Γ dx/dθ + ∂IK/∂ρ].

Solved by :func:`scipy.optimize.least_squares` (Levenberg–Marquardt, ``x_scale="jac"``);
covariance (J̃ᵀJ̃)⁻¹ × max(1, χ²_ν) (:mod:`pkmcal.identification.uncertainty`). The fit is
only as good as K and F: :func:`fit_known_stiffness` takes the values the calibration
*believes*, which may differ from the machine's (paper 3: "the stiffness of the each
joint could be changed after the assembly").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.uncertainty import Uncertainty, parameter_uncertainty
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.statics import StaticsModel, equilibrium, force_balance
from pkmcal.sensors.base import NoiseModel

#: Relative central-difference step for ∂g/∂x and ∂g/∂θ (the analytic g is exact to rounding).
FD_STEP = 1e-6


@dataclass(frozen=True)
class KnownStiffnessResult:
    """The fitted machine and sensor, the free parameter names and estimates with their
    :class:`~pkmcal.identification.uncertainty.Uncertainty`, the equilibrium poses and the
    solver's outcome."""

    mechanism: Mechanism
    sensor: object
    free: tuple[str, ...]
    x: np.ndarray
    uncertainty: Uncertainty
    poses: np.ndarray
    rms_whitened: float
    nfev: int
    success: bool
    message: str


class KnownStiffnessModel:
    """Residual and Jacobian of the known-stiffness fit (module docstring) for ``free``
    parameters of (``mechanism``, ``sensor``), commands ``commands`` (N, l), tracker and
    encoder readings ``y`` (N, 2), ``q`` (N, l), the ``statics`` believed and the ``noise``."""

    def __init__(self, mechanism, sensor, free, commands, y, q, statics: StaticsModel, noise: NoiseModel,
                 guess: np.ndarray):
        self.mech0, self.sensor0 = mechanism, sensor
        self.names = tuple(mechanism.param_names) + tuple(sensor.param_names)
        unknown = [n for n in free if n not in self.names]
        if unknown:
            raise PkmcalError(f"known-stiffness fit: no parameter {', '.join(unknown)}")
        self.free = tuple(free)
        self.idx = np.array([self.names.index(n) for n in self.free], dtype=int)
        self.theta0 = np.r_[mechanism.params, sensor.params]
        self.c, self.y, self.q = (np.asarray(a, dtype=float) for a in (commands, y, q))
        self.K = statics.stiffness_for(mechanism)
        self.F = statics.load
        self.w = np.r_[1.0 / np.broadcast_to(noise.reading_std, (2,)),
                       1.0 / np.broadcast_to(noise.actuator_std, (mechanism.n_actuators,))]
        self.guess = np.array(guess, dtype=float)
        self._cache: tuple[bytes, tuple] | None = None

    def split(self, theta):
        p = len(self.mech0.params)
        return self.mech0.with_params(theta[:p]), self.sensor0.with_params(theta[p:])

    def theta(self, x):
        th = self.theta0.copy()
        th[self.idx] = x
        return th

    def _g(self, theta, x):
        mech, sensor = self.split(theta)
        return force_balance(mech, self.c, self.K, x, self.F, sensor)

    def state(self, x):
        """(θ, machine, sensor, equilibrium poses) at the free values ``x``; the poses warm-
        start the next solve."""
        key = np.asarray(x, dtype=float).tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        th = self.theta(x)
        mech, sensor = self.split(th)
        eq = equilibrium(mech, self.c, self.K, self.F, sensor, guess=self.guess)
        if not eq.converged.all():
            bad = int(np.flatnonzero(~eq.converged)[0])
            raise PkmcalError(f"known-stiffness fit: the model's equilibrium did not converge at pose {bad + 1}")
        self.guess = eq.poses
        out = (th, mech, sensor, eq.poses)
        self._cache = (key, out)
        return out

    def residual(self, x) -> np.ndarray:
        _, mech, sensor, xe = self.state(x)
        r = np.concatenate([self.y - sensor.predict(mech.frame(xe)), self.q - mech.ik(xe)], axis=1)
        return (r * self.w).ravel()

    def jacobian(self, x) -> np.ndarray:
        th, mech, sensor, xe = self.state(x)
        N, n = xe.shape
        hx = FD_STEP * np.maximum(np.abs(xe), 1.0)
        Gx = np.empty((N, n, n))
        for k in range(n):
            e = np.zeros(n)
            e[k] = 1.0
            Gx[:, :, k] = (self._g(th, xe + hx[:, k:k + 1] * e) - self._g(th, xe - hx[:, k:k + 1] * e)) \
                / (2.0 * hx[:, k:k + 1])
        Gt = np.empty((N, n, self.idx.size))
        for j, i in enumerate(self.idx):
            h = FD_STEP * max(abs(th[i]), 1.0)
            tp, tm = th.copy(), th.copy()
            tp[i] += h
            tm[i] -= h
            Gt[:, :, j] = (self._g(tp, xe) - self._g(tm, xe)) / (2.0 * h)
        dx = -np.linalg.solve(Gx, Gt)                                   # (N, n, k)
        p = len(self.mech0.params)
        frame = mech.frame(xe)
        Hx = mech.pose_jacobian_from_twist(sensor.frame_jacobian(frame), xe)
        Hs = sensor.param_jacobian(frame)
        G = mech.actuator_pose_jacobian(xe)
        Hr = mech.actuator_param_jacobian(xe)
        Jy = Hx @ dx
        Jq = G @ dx
        for j, i in enumerate(self.idx):
            if i < p:
                Jq[:, :, j] += Hr[:, :, i]
            else:
                Jy[:, :, j] += Hs[:, :, i - p]
        J = -np.concatenate([Jy, Jq], axis=1) * self.w[None, :, None]
        return J.reshape(-1, self.idx.size)


def fit_known_stiffness(nominal: Mechanism, sensor, measurements, commanded_poses: np.ndarray, free,
                        statics: StaticsModel, noise: NoiseModel) -> KnownStiffnessResult:
    """Identify ``free`` parameters of ``nominal`` (and ``sensor``) by paper 3's ref. [7]
    (module docstring): the commands are the nominal IK of ``commanded_poses``; the
    ``statics`` (stiffness, load) and ``noise`` are those the calibration believes."""
    from scipy.optimize import least_squares

    commanded_poses = nominal.as_pose_array(commanded_poses)
    commands = nominal.ik(commanded_poses)
    model = KnownStiffnessModel(nominal, sensor, free, commands, measurements.readings, measurements.actuators,
                                statics, noise, commanded_poses)
    x0 = model.theta0[model.idx]
    sol = least_squares(model.residual, x0, jac=model.jacobian, method="lm", x_scale="jac", ftol=1e-10, xtol=1e-10,
                        gtol=1e-10)
    J = model.jacobian(sol.x)
    r = model.residual(sol.x)
    k = 2 + nominal.n_actuators
    unc = parameter_uncertainty(model.free, J.reshape(-1, k, model.idx.size), r.reshape(-1, k), weighted=True)
    _, mech, sens, xe = model.state(sol.x)
    return KnownStiffnessResult(mechanism=mech, sensor=sens, free=model.free, x=sol.x, uncertainty=unc, poses=xe,
                                rms_whitened=float(np.sqrt(np.mean(r**2))), nfev=int(sol.nfev),
                                success=bool(sol.status > 0), message=str(sol.message))


__all__ = ["KnownStiffnessModel", "KnownStiffnessResult", "fit_known_stiffness"]

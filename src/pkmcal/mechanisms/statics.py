"""Static equilibrium of a redundantly actuated machine (paper 3 §2, eq. 1–3).

The simulation, never the identifier, knows the actuator stiffness K and the load F.
Each actuator i is a position-controlled spring of stiffness K_i about its commanded
reading c_i: its generalised force is τ_i = K_i (c_i − q_i(x)), with q(x) = IK(x, ρ) the
encoder reading at pose x (true actuator position + encoder offset). An external force F
(gravity, process force; N) acts on the tool point p_t(x). The machine rests where the
potential energy

    U(x) = ½ Σ_i K_i (q_i(x) − c_i)² − Fᵀ p_t(x)

is stationary, i.e. the force balance in the independent coordinates x = q_u holds:

    g(x) = Γᵀ K (q(x) − c) − J_fᵀ F = 0,      Γ = ∂q/∂x,  J_f = ∂p_t/∂x.

We solve it nonlinearly, batched over poses: Newton steps with the Hessian of U by central
differences of the analytic g (n ≤ 3 pose coordinates: 2n extra gradient evaluations),
falling back to the Gauss–Newton Hessian ΓᵀKΓ where that is not positive definite, with a
backtracking line search on U (so every accepted step lowers the energy). This is a
per-pose n-dimensional minimisation; a batched Newton is faster than one
``scipy.optimize.least_squares`` call per pose, and the result is checked by the
force-balance residual |g| (``force_residual``).

Linearised (paper 3 eq. 1–3, in our sign convention: readings q = θ + dq, load F as a force
on the tool): with Γ, H, J_f, J_ρ at the commanded pose of the nominal model and Δρ, Δθ the
mechanism and sensor parameter errors,

    dx   = (ΓᵀKΓ)⁻¹ [ −ΓᵀK H Δρ + J_fᵀ F ]                                     (1)
    dq_m = Γ dx + H Δρ        (following error = reading − command)            (2), (4)
    dP_t = J_f dx + J_ρ Δθ                                                     (3)

(paper 3 writes Δq_r − HΔρ; its Δq_r is −dq here and its P the generalised load −J_fᵀF).

Backlash (simulation only, never seen by the identifier): a dead band b_i between actuator
i's motor (which the servo positions and the encoder reads) and its joint. Moving along
a path, the joint lags the motor by b_i/2 against the direction s_i ∈ {−1, +1} of the
actuator's last commanded motion (s_i kept while the command does not change; +1 before
the first motion: the path is approached from below). The spring then acts on
m_i = q_i(x) + s_i b_i/2, i.e. the equilibrium is that of the commands c − s b/2, and the
encoder reads q(x) + s b/2 (:meth:`StaticsModel.backlash_shift`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism

_TOL = 1e-10
_MAX_ITER = 50


@dataclass(frozen=True)
class EquilibriumResult:
    """Static equilibrium of N commanded poses.

    ``poses`` (N, n) the real rest poses; ``readings`` (N, l) the encoder readings there;
    ``following_error`` (N, l) = readings − commands; ``actuator_force`` (N, l) = K (c − q)
    (N or N·mm/rad); ``force_residual`` (N,) max |g| of the force balance (N or N·mm);
    ``converged`` (N,); ``iterations`` (N,).
    """

    poses: np.ndarray
    readings: np.ndarray
    following_error: np.ndarray
    actuator_force: np.ndarray
    force_residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray


@dataclass(frozen=True)
class StaticsModel:
    """What a simulation of a redundantly actuated machine needs besides the kinematics:
    actuator stiffness K (one value or one per actuator; N/mm for linear, N·mm/rad for
    rotary actuators), the in-plane load F (2,) on the tool point (N, base frame; None
    for no load) and the backlash b (one value or one per actuator, mm or rad as the
    actuator; None for none; module docstring). Written in the ``simulation:`` block of a
    setup file."""

    stiffness: np.ndarray
    load: np.ndarray | None = None
    backlash: np.ndarray | None = None

    def __post_init__(self) -> None:
        k = np.array(self.stiffness, dtype=float).reshape(-1)
        if k.size == 0 or not np.all(np.isfinite(k)) or np.any(k <= 0):
            raise PkmcalError("actuator stiffness must be positive numbers (N/mm or N·mm/rad)")
        object.__setattr__(self, "stiffness", k if k.size > 1 else k.reshape(()))
        if self.load is not None:
            f = np.array(self.load, dtype=float).reshape(-1)
            if f.shape != (2,) or not np.all(np.isfinite(f)):
                raise PkmcalError(f"the tool load is an in-plane force [Fx, Fy] in N; got {self.load!r}")
            object.__setattr__(self, "load", f)
        if self.backlash is not None:
            b = np.array(self.backlash, dtype=float).reshape(-1)
            if b.size == 0 or not np.all(np.isfinite(b)) or np.any(b < 0):
                raise PkmcalError("actuator backlash must be non-negative numbers (mm or rad, as the actuator)")
            object.__setattr__(self, "backlash", None if not np.any(b) else (b if b.size > 1 else b.reshape(())))

    def backlash_shift(self, commands: np.ndarray) -> np.ndarray:
        """s b/2 (N, l) for ``commands`` (N, l) in path order (module docstring): the motor
        sits this far beyond the joint; zeros without backlash. A command that does not
        change (or is not finite) keeps the previous direction."""
        c = np.asarray(commands, dtype=float)
        if self.backlash is None:
            return np.zeros_like(c)
        b = np.asarray(self.backlash, dtype=float)
        if b.ndim and b.size != c.shape[1]:
            raise PkmcalError(f"the setup gives {b.size} actuator backlash values for {c.shape[1]} actuators; "
                              "give one value or one per actuator")
        step = np.zeros_like(c)
        with np.errstate(invalid="ignore"):
            step[1:] = np.sign(np.nan_to_num(np.diff(c, axis=0), nan=0.0))
        # direction of the last motion: the last non-zero step so far (+1 before any)
        k = np.arange(c.shape[0])[:, None]
        last = np.maximum.accumulate(np.where(step != 0, k, -1), axis=0)
        s = np.where(last >= 0, step[np.maximum(last, 0), np.arange(c.shape[1])], 1.0)
        return s * (0.5 * np.broadcast_to(b, c.shape[1:]))

    def stiffness_for(self, mechanism: Mechanism) -> np.ndarray:
        """K (l,) for ``mechanism``; a clear error when the count does not match."""
        k = np.asarray(self.stiffness, dtype=float)
        if k.ndim and k.size != mechanism.n_actuators:
            raise PkmcalError(f"the setup gives {k.size} actuator stiffnesses but machine '{mechanism.name}' has "
                              f"{mechanism.n_actuators} actuators; give one value or one per actuator")
        return np.broadcast_to(k, (mechanism.n_actuators,)).copy()


def _load_terms(mechanism, load_point, load, x):
    """(p_t (N, 2) or None, J_f (N, 2, n) or None, F (2,) or None): the tool point of the
    frames of x and J_f = ∂p_t/∂twist · T."""
    if load is None:
        return None, None, None
    if load_point is None:
        raise PkmcalError("a load needs the point it acts on (load_point: a planar tool sensor)")
    F = np.asarray(load, dtype=float)
    frame = mechanism.frame(x)
    Jf = mechanism.pose_jacobian_from_twist(load_point.tool_frame_jacobian(frame), x)
    return load_point.tool_point(frame), Jf, F


def _balance_and_jacobian(mechanism: Mechanism, commands, stiffness, poses, load, load_point):
    """(g (N, n), Γ (N, l, n)): :func:`force_balance` and the Γ it was computed with."""
    x = mechanism.as_pose_array(poses)
    K = np.broadcast_to(np.asarray(stiffness, dtype=float), (mechanism.n_actuators,))
    G = mechanism.actuator_pose_jacobian(x)
    g = np.einsum("nli,nl->ni", G, K * (mechanism.ik(x) - commands))
    _, Jf, F = _load_terms(mechanism, load_point, load, x)
    if F is not None:
        g = g - np.einsum("nki,k->ni", Jf, F)
    return g, G


def force_balance(mechanism: Mechanism, commands, stiffness, poses, load=None, load_point=None) -> np.ndarray:
    """g(x) = Γᵀ K (q(x) − c) − J_fᵀ F (N, n): the gradient of U (module docstring)."""
    return _balance_and_jacobian(mechanism, commands, stiffness, poses, load, load_point)[0]


def potential_energy(mechanism: Mechanism, commands, stiffness, poses, load=None, load_point=None) -> np.ndarray:
    """U(x) (N,) (module docstring), N·mm."""
    x = mechanism.as_pose_array(poses)
    K = np.broadcast_to(np.asarray(stiffness, dtype=float), (mechanism.n_actuators,))
    U = 0.5 * np.sum(K * (mechanism.ik(x) - commands) ** 2, axis=1)
    pt, _, F = _load_terms(mechanism, load_point, load, x)
    if F is not None:
        U = U - pt @ F
    return U


def equilibrium(
    mechanism: Mechanism,
    commands: np.ndarray,
    stiffness,
    load=None,
    load_point=None,
    guess: np.ndarray | None = None,
    *,
    tol: float = _TOL,
    max_iter: int = _MAX_ITER,
) -> EquilibriumResult:
    """Real rest poses of ``mechanism`` (the *real* machine) under ``commands`` (N, l).

    ``stiffness`` K (l,) or scalar (N/mm for linear, N·mm/rad for rotary actuators);
    ``load`` F (2,) in N on the tool point of ``load_point`` (a
    :class:`~pkmcal.sensors.planar_tool.PlanarToolSensor` of the real machine, in the
    base frame); ``guess`` start poses (default: FK of the commands).
    """
    c = np.atleast_2d(np.asarray(commands, dtype=float))
    n = mechanism.n_dof
    K = np.broadcast_to(np.asarray(stiffness, dtype=float), (mechanism.n_actuators,))
    if np.any(K <= 0):
        raise PkmcalError("actuator stiffness must be positive")
    if guess is None:
        x = mechanism.fk(c, guess=mechanism.home_pose).poses
    else:
        x = np.array(np.broadcast_to(np.asarray(guess, dtype=float), (c.shape[0], n)))
    args = (load, load_point)
    scale = np.maximum(np.abs(x).max(axis=1), 1.0)
    h = 1e-5 * np.maximum(np.abs(x), 1.0)
    U = potential_energy(mechanism, c, K, x, *args)
    it = np.zeros(c.shape[0], dtype=int)
    done = np.zeros(c.shape[0], dtype=bool)
    ts = 0.5 ** np.arange(10)
    for _ in range(max_iter):
        g, G = _balance_and_jacobian(mechanism, c, K, x, *args)
        # Hessian by central differences of the analytic gradient (all poses, 2n evaluations)
        Hs = np.empty((c.shape[0], n, n))
        for k in range(n):
            e = np.zeros(n)
            e[k] = 1.0
            gp = force_balance(mechanism, c, K, x + h[:, k:k + 1] * e, *args)
            gm = force_balance(mechanism, c, K, x - h[:, k:k + 1] * e, *args)
            Hs[:, :, k] = (gp - gm) / (2.0 * h[:, k:k + 1])
        Hs = 0.5 * (Hs + np.swapaxes(Hs, 1, 2))
        Hgn = np.einsum("nli,l,nlj->nij", G, K, G)
        pd = np.all(np.linalg.eigvalsh(Hs) > 0, axis=1)
        Hs = np.where(pd[:, None, None], Hs, Hgn)
        dx = -np.linalg.solve(Hs, g[..., None])[..., 0]
        dx[done] = 0.0
        xc = x[None] + ts[:, None, None] * dx[None]
        Uc = potential_energy(mechanism, np.tile(c, (len(ts), 1)), K, xc.reshape(-1, n), *args).reshape(len(ts), -1)
        Uc = np.where(np.isfinite(Uc), Uc, np.inf)
        ok = Uc <= U[None] + 1e-12 * np.abs(U[None]) + 1e-18
        k = np.argmax(ok, axis=0)
        sel = np.arange(c.shape[0])
        take = ok.any(axis=0) & ~done
        x = np.where(take[:, None], xc[k, sel], x)
        U = np.where(take, Uc[k, sel], U)
        it += ~done
        done |= (np.max(np.abs(dx), axis=1) <= tol * scale) | ~ok.any(axis=0)
        if done.all():
            break
    q = mechanism.ik(x)
    g, G = _balance_and_jacobian(mechanism, c, K, x, *args)
    res = np.max(np.abs(g), axis=1)
    # converged: the displacement a further Gauss–Newton step would make is negligible
    Hgn = np.einsum("nli,l,nlj->nij", G, K, G)
    with np.errstate(invalid="ignore"):
        left = np.max(np.abs(np.linalg.solve(Hgn, g[..., None])[..., 0]), axis=1)
    conv = done & np.isfinite(res) & (left <= 1e-8 * scale)
    return EquilibriumResult(poses=x, readings=q, following_error=q - c, actuator_force=K * (c - q),
                             force_residual=res, converged=conv, iterations=it)


def linear_response(
    nominal: Mechanism,
    nominal_sensor,
    poses: np.ndarray,
    delta_rho: np.ndarray,
    delta_sensor: np.ndarray,
    stiffness,
    load=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linearised error propagation (paper 3 eq. 1–3, module docstring) at commanded poses.

    Returns ``(dx, dq_m, dP_t)``: pose deviation (N, n), following error (N, l) and tool
    point error (N, 2) in the base frame (``nominal_sensor`` with identity world).
    """
    x = nominal.as_pose_array(poses)
    K = np.broadcast_to(np.asarray(stiffness, dtype=float), (nominal.n_actuators,))
    G = nominal.actuator_pose_jacobian(x)
    H = nominal.actuator_param_jacobian(x)
    frame = nominal.frame(x)
    Jf = nominal.pose_jacobian_from_twist(nominal_sensor.tool_frame_jacobian(frame), x)
    Jr = nominal_sensor.param_jacobian(frame)
    Hd = H @ np.asarray(delta_rho, dtype=float)
    A = np.einsum("nli,l,nlj->nij", G, K, G)
    b = -np.einsum("nli,l,nl->ni", G, K, Hd)
    if load is not None:
        b = b + np.einsum("nki,k->ni", Jf, np.asarray(load, dtype=float))
    dx = np.linalg.solve(A, b[..., None])[..., 0]
    dqm = np.einsum("nli,ni->nl", G, dx) + Hd
    dPt = np.einsum("nki,ni->nk", Jf, dx) + Jr @ np.asarray(delta_sensor, dtype=float)
    return dx, dqm, dPt

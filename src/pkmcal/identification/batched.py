"""Many ik-residual fits of one machine and setup at once: a study's trials, batched.

Each fit is the engine's (:func:`pkmcal.identification.engine.identify`) noise-weighted
``ik-residual`` fit (paper 1 §V, eq. 3) of its own measurements,

    θ̂ = argmin_θ Σ_j ‖W_j (q_j − IK(x̂_j, ρ))‖²,   W_j = L_j⁻¹, L_j L_jᵀ = Σ_j   (GLS)

with x̂_j the pose of the frame the sensor readings determine (fixed: no sensor parameter
is free), the weights W_j computed once at the nominal machine (as the engine does), the
same free set (the engine's candidates, :func:`~pkmcal.identification.residuals.candidate_parameters`)
judged on the same design Jacobian (the whitened Jacobian at the commanded poses, noise-free,
nominal machine; :func:`~pkmcal.identification.identifiability.design_jacobian`), and the
same covariance: weights recomputed at the solution, C = (J̃ᵀJ̃)⁻¹ and χ² = ‖r̃‖²
(:func:`~pkmcal.identification.uncertainty.parameter_uncertainty`).

What is batched: the start (x̂, Jacobian and noise covariance of every pose of every fit
at the nominal machine, one pass of the method), the design Jacobians (one pass), and the
solver: Levenberg–Marquardt on the normal equations,

    (J̃ᵀJ̃ + λ D²) δ = −J̃ᵀr̃,   D² = diag(J̃ᵀJ̃) (running maximum, Marquardt's scaling)

for all fits of one size together (stacked (B, k N, n) Jacobians, one stacked solve per
iteration), each fit with its own damping λ (÷3 after a successful step, ×10 after a
failed one) and its own stop, MINPACK's tests on its own numbers: ‖D δ‖ ≤ xtol ‖D x‖, or
both the actual and the predicted relative reduction of the cost ≤ ftol. The problem is
nearly linear in ρ (the errors are mm on legs of ~1 m), so Gauss–Newton steps converge
quadratically and the fit stops at the minimiser the engine's MINPACK run stops at, to
its tolerances (``tests/test_batched_fit.py`` compares parameters, χ², covariance and rank).

Every number of fit b is computed from fit b's data by stacked per-pose / per-fit
operations only (matmul, solve and reductions over each fit's own axes), so a fit's bits
do not depend on which other fits share its batch (tested): a study gives the same bits
on any number of workers.

A fit the batch cannot do as the engine would comes back ``None``, and the caller runs the
engine on it: a start pose that cannot be solved, a free set the cheap certificate cannot
prove of full rank (the engine then fixes a gauge), no more residuals than free
parameters, a non-finite step, or no convergence in :data:`MAX_ITERATIONS`. Which fits
the batch applies to at all is :func:`batch_applies` (weighted ik-residual, plain form,
least squares, no priors, no sessions, no free sensor parameter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError

#: Solver iterations (each one residual-and-Jacobian evaluation) before a fit is handed back.
MAX_ITERATIONS = 50
#: Starting damping λ (relative to the diagonal of J̃ᵀJ̃): nearly Gauss–Newton.
START_DAMPING = 1e-6


@dataclass(frozen=True)
class BatchReport:
    """The identifiability numbers a study reads (the engine's report, full rank proven):
    ``rank`` = ``n_params`` and the 2-norm condition number of the column-scaled design
    Jacobian (σ₁/σ_P, singular values only)."""

    rank: int
    n_params: int
    condition_number: float


@dataclass(frozen=True)
class BatchedFit:
    """One fit of :func:`identify_batch`, with the attributes of
    :class:`~pkmcal.identification.engine.IdentificationResult` a study reads (same
    meaning, internal units): the calibrated ``mechanism`` (with its covariance), ``names``,
    ``free``, ``initial`` and ``estimate`` (full vectors), ``uncertainty``, ``identifiability``
    (:class:`BatchReport`), ``gauge`` (empty: the batch never fixes one), ``nfev`` / ``njev``
    (evaluations of this fit's residual and Jacobian), ``cost`` = ½ Σ ‖W r‖² at the solution
    with the start weights."""

    mechanism: object
    names: tuple[str, ...]
    free: tuple[str, ...]
    initial: np.ndarray
    estimate: np.ndarray
    uncertainty: object
    identifiability: BatchReport
    nfev: int
    njev: int
    cost: float
    gauge: tuple[str, ...] = ()
    success: bool = True

    @property
    def free_index(self) -> np.ndarray:
        return np.array([self.names.index(n) for n in self.free], dtype=int)

    @property
    def covariance(self) -> np.ndarray:
        return self.uncertainty.covariance


def batch_applies(setup, method: str, weighted: bool, form: str = "plain") -> bool:
    """Whether :func:`identify_batch` does these fits (module docstring; the rest per fit
    with the data: free sensor parameters, sessions)."""
    return (method == "ik-residual" and weighted and form == "plain" and not tuple(setup.priors or ())
            and not setup.session_sensors)


def identify_batch(machine, setup, measurements: list, *, free=None, fix=None, xtol: float | None = None,
                   ftol: float | None = None) -> list[BatchedFit | None]:
    """The weighted ik-residual fits of ``measurements`` (one per fit; anything
    :func:`~pkmcal.identification.engine.measurement_arrays` takes, with commanded poses) of
    ``machine`` with ``setup``, free set ``free`` / ``fix`` as :func:`identify`'s, to the
    engine's tolerances by default. ``None`` for a fit the batch leaves to the engine
    (module docstring)."""
    from pkmcal.identification.engine import TOLERANCE, measurement_arrays, measurement_sessions
    from pkmcal.identification.identifiability import RANK_RTOL, ScaledJacobian, design_jacobian
    from pkmcal.identification.residuals import Model, candidate_parameters, make_method, whitening

    xtol = TOLERANCE if xtol is None else xtol
    ftol = TOLERANCE if ftol is None else ftol
    out: list[BatchedFit | None] = [None] * len(measurements)
    data = []
    for b, meas in enumerate(measurements):
        q, y, cmd = measurement_arrays(meas)
        if cmd is None or len(q) == 0 or measurement_sessions(meas, None, len(q), setup.session_offsets) is not None:
            continue
        data.append((b, q, y, cmd))
    if not data:
        return out
    sizes = np.array([len(d[1]) for d in data])
    starts = np.concatenate([[0], np.cumsum(sizes)])
    try:
        model = Model(machine, setup.sensor, setup.noise, np.concatenate([d[1] for d in data]),
                      np.concatenate([d[2] for d in data]), np.concatenate([d[3] for d in data]))
        cand, _ = candidate_parameters(model, free, fix)
    except PkmcalError:
        return out                          # the engine reports it, per fit
    p = model.n_mech
    if not cand or any(i >= p for i in cand):
        return out                          # a free sensor parameter moves x̂: the engine's fit
    free_idx = np.array(cand, dtype=int)
    meth = make_method("ik-residual", model, True, form="plain")
    meth.sensor_columns = False
    theta0 = model.theta0
    ev0 = meth.evaluate(theta0, jac=True, cov=True)
    try:
        W = whitening(ev0.cov, "ik-residual residual")
    except PkmcalError:
        return out
    Jd, okd, _ = design_jacobian(machine, setup.sensor, setup.noise, model.commanded, "ik-residual", True,
                                 form="plain", sensor_columns=False)
    Jw0 = W @ ev0.J
    names = model.names
    free_names = tuple(names[i] for i in free_idx)
    jobs: dict[int, list] = {}
    for k, (b, q, y, cmd) in enumerate(data):
        sl = slice(starts[k], starts[k + 1])
        if not ev0.converged[sl].all():
            continue                        # the engine drops such poses, with a note
        judged = Jd[sl][okd[sl]].reshape(-1, Jd.shape[-1]) if okd[sl].any() else Jw0[sl].reshape(-1, Jw0.shape[-1])
        scaled = ScaledJacobian(judged[:, free_idx])
        if not scaled.certainly_full_rank(RANK_RTOL) or q.size <= free_idx.size:
            continue                        # a gauge to fix, or an interpolating fit: the engine's
        s = np.linalg.svd(scaled.R, compute_uv=False)
        report = BatchReport(free_idx.size, free_idx.size, float(s[0] / s[-1]))
        jobs.setdefault(len(q), []).append((b, q, y, cmd, ev0.poses[sl], W[sl], report))
    for group in jobs.values():
        x, nfev, cost, ok = _levenberg_marquardt(machine, theta0, free_idx, group, xtol, ftol)
        for g, (b, q, y, cmd, _, _, report) in enumerate(group):
            if ok[g]:
                out[b] = _finish(machine, setup, q, y, cmd, theta0, free_idx, free_names, names, x[g], nfev[g],
                                 cost[g], report)
    return out


def _residuals(machine, theta0: np.ndarray, free_idx: np.ndarray, group: list, x: np.ndarray, rows: np.ndarray):
    """Whitened residuals (G, k N) and Jacobians (G, k N, n) of the fits ``rows`` of
    ``group`` at free parameters ``x`` (G, n): r = q − IK(x̂, ρ), ∂r/∂ρ = −∂IK/∂ρ (the
    ik-residual's, :class:`~pkmcal.identification.residuals.IKResidual`, at fixed x̂),
    times the start weights, pose by pose."""
    p = len(machine.param_names)
    r_all, J_all = [], []
    for g, i in enumerate(rows):
        _, q, _, _, xhat, W, _ = group[i]
        th = theta0.copy()
        th[free_idx] = x[g]
        q_model, _, B = machine.ik_and_jacobians(xhat, th[:p])
        r_all.append(q - q_model)
        J_all.append(-B[:, :, free_idx])
    Wst = np.stack([group[i][5] for i in rows])
    r = (Wst @ np.stack(r_all)[..., None])[..., 0]
    J = Wst @ np.stack(J_all)
    G, N, k = r.shape
    return r.reshape(G, N * k), J.reshape(G, N * k, -1)


def _levenberg_marquardt(machine, theta0, free_idx, group, xtol, ftol):
    """The batched solver (module docstring): ``(x (G, n), nfev (G,), cost (G,), converged (G,))``."""
    G, n = len(group), free_idx.size
    x = np.tile(theta0[free_idx], (G, 1))
    every = np.arange(G)
    r, J = _residuals(machine, theta0, free_idx, group, x, every)
    f = 0.5 * np.sum(r * r, axis=1)
    nfev = np.ones(G, dtype=int)
    lam = np.full(G, START_DAMPING)
    D2 = np.zeros((G, n))
    active = np.isfinite(f)
    done = np.zeros(G, dtype=bool)
    for _ in range(MAX_ITERATIONS):
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        Ja, ra = J[a], r[a]
        Jt = np.swapaxes(Ja, 1, 2)
        JtJ = Jt @ Ja
        grad = (Jt @ ra[..., None])[..., 0]
        diag = np.diagonal(JtJ, axis1=1, axis2=2)
        D2[a] = np.maximum(D2[a], diag)
        A = JtJ + (lam[a, None] * D2[a])[:, :, None] * np.eye(n)
        try:
            step = -np.linalg.solve(A, grad[..., None])[..., 0]
        except np.linalg.LinAlgError:
            active[a] = False
            break
        pred = -(np.sum(grad * step, axis=1) + 0.5 * np.sum(step * (JtJ @ step[..., None])[..., 0], axis=1))
        x_new = x[a] + step
        r_new, J_new = _residuals(machine, theta0, free_idx, group, x_new, a)
        nfev[a] += 1
        f_new = 0.5 * np.sum(r_new * r_new, axis=1)
        fa = f[a]
        good = np.isfinite(f_new) & (f_new < fa)
        D = np.sqrt(D2[a])
        small_step = np.sqrt(np.sum((D * step) ** 2, axis=1)) <= xtol * np.sqrt(np.sum((D * x_new) ** 2, axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            small_gain = (np.abs(fa - f_new) <= ftol * fa) & (pred <= ftol * fa)
        acc = a[good]
        x[acc], r[acc], J[acc], f[acc] = x_new[good], r_new[good], J_new[good], f_new[good]
        ratio = np.where(pred > 0, (fa - f_new) / np.where(pred > 0, pred, 1.0), 0.0)
        lam[a] = np.where(good, lam[a] * np.maximum(1.0 / 3.0, 1.0 - (2.0 * np.clip(ratio, 0, 1) - 1.0) ** 3),
                          lam[a] * 10.0)
        stop = (good & small_step) | (~good & small_gain & np.isfinite(f_new))
        done[a[stop]] = True
        active[a[stop]] = False
        active[a[~np.isfinite(step).all(axis=1)]] = False
    return x, nfev, f, done


def _finish(machine, setup, q, y, cmd, theta0, free_idx, free_names, names, x, nfev, cost, report) -> BatchedFit | None:
    """The fit's result: the engine's evaluation at the solution (weights recomputed
    there), its covariance and χ², the calibrated machine."""
    from pkmcal.identification.residuals import Model, make_method, whitening
    from pkmcal.identification.uncertainty import embed, parameter_uncertainty

    theta = theta0.copy()
    theta[free_idx] = x
    model = Model(machine, setup.sensor, setup.noise, q, y, cmd)
    meth = make_method("ik-residual", model, True, form="plain")
    meth.sensor_columns = False
    ev = meth.evaluate(theta, jac=True, cov=True)
    if not ev.converged.all():
        return None
    try:
        W_end = whitening(ev.cov, "ik-residual residual")
    except PkmcalError:
        return None
    J_free = W_end @ ev.J[:, :, free_idx]
    r_w = (W_end @ ev.r[..., None])[..., 0]
    unc = parameter_uncertainty(free_names, J_free, r_w, weighted=True)
    p = model.n_mech
    mech = machine.with_params(theta[:p], covariance=embed(unc.covariance, free_idx, p))
    return BatchedFit(mechanism=mech, names=names, free=free_names, initial=model.theta0, estimate=theta,
                      uncertainty=unc, identifiability=report, nfev=int(nfev), njev=int(nfev), cost=float(cost))


__all__ = ["BatchReport", "BatchedFit", "batch_applies", "identify_batch"]

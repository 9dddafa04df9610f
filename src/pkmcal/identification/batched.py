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
at the nominal machine, one pass of the method), the design Jacobians (one pass over the
distinct commanded poses), and the solver: Levenberg–Marquardt on the normal equations,

    (J̃ᵀJ̃ + λ D²) δ = −J̃ᵀr̃,   D² = diag(J̃ᵀJ̃) (running maximum, Marquardt's scaling)

for all fits of one size together (stacked (B, k N, n) Jacobians, one stacked solve per
iteration, in the scaled variables D x), each fit with its own damping λ (0 at the start:
Gauss–Newton steps; 1e-6, then ×10 after a failed step; shrunk after a successful one by
Nielsen's rule) and its own stop, MINPACK's tests on its own numbers: the step
‖D δ‖ ≤ xtol ‖D x‖, the gradient (every column of J̃ within gtol of orthogonal to r̃),
or — where a step fails — both the actual and the predicted relative reduction of the cost
≤ ftol (nothing left to gain at rounding). J̃ᵀJ̃ is formed at the start and after the
first :data:`FULL_STEPS` steps, then kept, the gradient always exact (a Newton chord:
same fixed point J̃ᵀr̃ = 0). The problem is nearly linear in ρ (errors of mm on legs of
~1 m), so a fit takes 5–7 evaluations (MINPACK's: 5 residuals, 4 Jacobians) and stops at
the minimiser the engine's MINPACK run stops at, to their tolerances
(``tests/identification/test_batched.py`` compares parameters, χ², covariance, rank and condition).

Every number of fit b is computed from fit b's data by stacked per-pose / per-fit
operations only (the compiled kernels row by row, NumPy's stacked matmul and solve slice
by slice, reductions over each fit's own axes), so a fit's bits do not depend on which
other fits share its batch, nor in which order (tested, as are a study's rows for 1 and 2
workers, batches of 1 and 3 trials, and Dask): a study gives the same bits on any number of
workers.

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
#: Damping λ (relative to the running diagonal of J̃ᵀJ̃) after the first failed step; the
#: solver starts undamped (Gauss–Newton): with the column-scaled J̃ conditioned ~1e4 (a
#: 15-pose fit of the default machine) a start of even 1e-6 damps its weakest directions
#: (σ²/σ₁² ~ 1e-8) and halves the convergence.
FIRST_DAMPING = 1e-6
#: Successful steps after which J̃ᵀJ̃ is formed again (then kept: :func:`_levenberg_marquardt`).
FULL_STEPS = 2


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
    ``free`` (and ``free_index``, their indices in ``names``), ``initial`` and ``estimate``
    (full vectors), ``uncertainty``, ``identifiability``
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
    free_index: np.ndarray | None = None
    gauge: tuple[str, ...] = ()
    success: bool = True

    def __post_init__(self):
        if self.free_index is None:
            object.__setattr__(self, "free_index", np.array([self.names.index(n) for n in self.free], dtype=int))

    @property
    def covariance(self) -> np.ndarray:
        return self.uncertainty.covariance


def batch_applies(setup, method: str, weighted: bool, form: str = "plain") -> bool:
    """Whether :func:`identify_batch` does these fits (module docstring; the rest per fit
    with the data: free sensor parameters, sessions)."""
    return (method == "ik-residual" and weighted and form == "plain" and not tuple(setup.priors or ())
            and not setup.session_sensors)


def identify_batch(machine, setup, measurements: list, *, free=None, fix=None, xtol: float | None = None,
                   ftol: float | None = None, gtol: float | None = None) -> list[BatchedFit | None]:
    """The weighted ik-residual fits of ``measurements`` (one per fit; anything
    :func:`~pkmcal.identification.engine.measurement_arrays` takes, with commanded poses) of
    ``machine`` with ``setup``, free set ``free`` / ``fix`` as :func:`identify`'s, to the
    engine's tolerances by default. ``None`` for a fit the batch leaves to the engine
    (module docstring), and for every fit when their shared start raises a
    :class:`~pkmcal.errors.PkmcalError` (a sensor the ik-residual cannot use, a noise-free
    residual, a free-set pattern that matches nothing): the engine reports it, fit by fit."""
    try:
        return _identify_batch(machine, setup, measurements, free=free, fix=fix, xtol=xtol, ftol=ftol, gtol=gtol)
    except PkmcalError:
        return [None] * len(measurements)


def _identify_batch(machine, setup, measurements: list, *, free, fix, xtol, ftol, gtol) -> list[BatchedFit | None]:
    from pkmcal.identification.engine import TOLERANCE, measurement_arrays, measurement_sessions
    from pkmcal.identification.identifiability import RANK_RTOL, ScaledJacobian, design_jacobian
    from pkmcal.identification.residuals import Model, candidate_parameters, make_method, whitening

    xtol = TOLERANCE if xtol is None else xtol
    ftol = TOLERANCE if ftol is None else ftol
    gtol = TOLERANCE if gtol is None else gtol
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
    model = Model(machine, setup.sensor, setup.noise, np.concatenate([d[1] for d in data]),
                  np.concatenate([d[2] for d in data]), np.concatenate([d[3] for d in data]))
    cand, _ = candidate_parameters(model, free, fix)
    p = model.n_mech
    if not cand or any(i >= p for i in cand):
        return out                          # a free sensor parameter moves x̂: the engine's fit
    free_idx = np.array(cand, dtype=int)
    meth = make_method("ik-residual", model, True, form="plain")
    meth.sensor_columns = False
    theta0 = model.theta0
    ev0 = meth.evaluate(theta0, jac=True, cov=True)
    W = whitening(ev0.cov, "ik-residual residual")
    # the design Jacobian row by row, once per distinct commanded pose (a study's trials draw
    # their poses from one pool: 64 trials of 15 box corners have 64 distinct poses)
    every = np.ascontiguousarray(model.commanded)
    rows = every.view(np.dtype((np.void, every.dtype.itemsize * every.shape[1]))).ravel()   # bit patterns
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    Jd, okd, _ = design_jacobian(machine, setup.sensor, setup.noise, every[first], "ik-residual", True,
                                 form="plain", sensor_columns=False)
    Jd, okd = Jd[inverse.ravel()], okd[inverse.ravel()]
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
        r0 = (W[sl] @ ev0.r[sl][..., None])[..., 0].ravel()
        jobs.setdefault(len(q), []).append(_Job(b, q, y, cmd, ev0.poses[sl], W[sl], report, r0,
                                                Jw0[sl][:, :, free_idx].reshape(r0.size, free_idx.size)))
    for group in jobs.values():
        x, nfev, cost, ok = _levenberg_marquardt(machine, theta0, free_idx, group, xtol, ftol, gtol)
        for g, job in enumerate(group):
            if ok[g]:
                out[job.index] = _finish(machine, setup, job.q, job.y, job.commanded, theta0, free_idx, free_names,
                                         names, x[g], nfev[g], cost[g], job.report)
    return out


@dataclass
class _Job:
    """One fit of a group: its index in the call, data, measured poses x̂ (N, n), start
    weights W (N, k, k), report, and whitened residual (k N,) and Jacobian (k N, n) at the start."""

    index: int
    q: np.ndarray
    y: np.ndarray
    commanded: np.ndarray
    xhat: np.ndarray
    W: np.ndarray
    report: BatchReport
    r0: np.ndarray
    J0: np.ndarray


def _residuals(machine, theta0: np.ndarray, free_idx: np.ndarray, jobs: list[_Job], x: np.ndarray,
               rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r̃, W, B)`` of the fits ``rows`` at free parameters ``x`` (G, n): the whitened
    residuals (G, k N) of r = q − IK(x̂, ρ) (the ik-residual's,
    :class:`~pkmcal.identification.residuals.IKResidual`, at fixed x̂), the start weights
    (G, N, k, k) and B = ∂IK/∂ρ of the free parameters (G, N, k, n): J̃ = −W B pose by pose."""
    p = len(machine.param_names)
    r_all, B_all = [], []
    for g, i in enumerate(rows):
        job = jobs[i]
        th = theta0.copy()
        th[free_idx] = x[g]
        q_model, _, B = machine.ik_and_jacobians(job.xhat, th[:p])
        r_all.append(job.q - q_model)
        B_all.append(B[:, :, free_idx])
    W = np.stack([jobs[i].W for i in rows])
    r = (W @ np.stack(r_all)[..., None])[..., 0]
    return r.reshape(len(rows), -1), W, np.stack(B_all)


def _whitened_jacobian(W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """J̃ (G, k N, n) = −W B pose by pose."""
    J = -(W @ B)
    return J.reshape(J.shape[0], -1, J.shape[-1])


def _gradient(r: np.ndarray, W: np.ndarray, B: np.ndarray) -> np.ndarray:
    """J̃ᵀ r̃ (G, n) = −Σ_j B_jᵀ W_jᵀ r̃_j, without forming J̃."""
    G, N, k, n = B.shape
    u = np.swapaxes(W, 2, 3) @ r.reshape(G, N, k, 1)
    return -(np.swapaxes(B.reshape(G, N * k, n), 1, 2) @ u.reshape(G, N * k, 1))[..., 0]


def _levenberg_marquardt(machine, theta0, free_idx, jobs: list[_Job], xtol, ftol, gtol):
    """The batched solver (module docstring): ``(x (G, n), nfev (G,), cost (G,), converged (G,))``.

    J̃ᵀJ̃ is formed at the start and after the first :data:`FULL_STEPS` successful steps;
    after that the steps use the last one with the exact gradient J̃ᵀr̃ at the current point
    (a Newton chord: the same fixed point J̃ᵀr̃ = 0, the same minimiser; J̃ changes by
    O(δρ/L) between the start and the solution, so the steps stay Gauss–Newton's to that
    order), and a failed step forms it again at the current point before damping more."""
    G, n = len(jobs), free_idx.size
    x = np.tile(theta0[free_idx], (G, 1))
    r = np.stack([j.r0 for j in jobs])
    J = np.stack([j.J0 for j in jobs])
    W = np.stack([j.W for j in jobs])
    B = None                                 # B at the current points, once a step has been taken
    f = 0.5 * np.sum(r * r, axis=1)
    H = np.swapaxes(J, 1, 2) @ J
    grad = (np.swapaxes(J, 1, 2) @ r[..., None])[..., 0]
    D2 = np.diagonal(H, axis1=1, axis2=2).copy()
    fresh = np.ones(G, dtype=bool)
    steps = np.zeros(G, dtype=int)
    nfev = np.ones(G, dtype=int)
    lam = np.zeros(G)
    active = np.isfinite(f)
    done = np.zeros(G, dtype=bool)
    eye = np.eye(n)
    for _ in range(MAX_ITERATIONS):
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        # gtol: every column of J̃ at most gtol from orthogonal to r̃ (cosine)
        diag = np.diagonal(H[a], axis1=1, axis2=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = np.abs(grad[a]) / np.sqrt(diag * (2.0 * f[a])[:, None])
        flat = np.all((cosine <= gtol) | (diag == 0), axis=1) & fresh[a]
        done[a[flat]] = True
        active[a[flat]] = False
        a = a[~flat]
        if a.size == 0:
            break
        Ha, ga = H[a], grad[a]
        # solved in the scaled variables D x (D² the running diagonal), where the normal
        # matrix has the condition of the column-scaled J̃ squared, not that of J̃ squared
        Di = 1.0 / np.sqrt(np.where(D2[a] > 0, D2[a], 1.0))
        try:
            y = np.linalg.solve(Di[:, :, None] * Ha * Di[:, None, :] + lam[a, None, None] * eye,
                                (Di * ga)[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        step = -Di * y
        pred = -(np.sum(ga * step, axis=1) + 0.5 * np.sum(step * (Ha @ step[..., None])[..., 0], axis=1))
        x_new = x[a] + step
        r_new, W_new, B_new = _residuals(machine, theta0, free_idx, jobs, x_new, a)
        nfev[a] += 1
        f_new = 0.5 * np.sum(r_new * r_new, axis=1)
        fa = f[a]
        good = np.isfinite(f_new) & (f_new < fa)
        D = np.sqrt(D2[a])
        small_step = np.sqrt(np.sum((D * step) ** 2, axis=1)) <= xtol * np.sqrt(np.sum((D * x_new) ** 2, axis=1))
        with np.errstate(divide="ignore", invalid="ignore"):
            small_gain = (np.abs(fa - f_new) <= ftol * fa) & (pred <= ftol * fa)
            ratio = np.where(pred > 0, (fa - f_new) / np.where(pred > 0, pred, 1.0), 0.0)
        if B is None:
            B = np.empty((G,) + B_new.shape[1:])
        acc = a[good]
        x[acc], r[acc], f[acc], B[acc] = x_new[good], r_new[good], f_new[good], B_new[good]
        steps[acc] += 1
        grad[acc] = _gradient(r_new[good], W_new[good], B_new[good])
        # J̃ᵀJ̃ again: after the first steps, and where a step failed on an old one (then
        # not damped more: the next step is Gauss–Newton's at the current point)
        was_fresh = fresh[a].copy()
        renew = np.union1d(acc[steps[acc] <= FULL_STEPS], a[~good & ~was_fresh & (steps[a] > 0)])
        fresh[acc] = False
        if renew.size:
            Jr = _whitened_jacobian(W[renew], B[renew])
            H[renew] = np.swapaxes(Jr, 1, 2) @ Jr
            grad[renew] = (np.swapaxes(Jr, 1, 2) @ r[renew][..., None])[..., 0]
            D2[renew] = np.maximum(D2[renew], np.diagonal(H[renew], axis1=1, axis2=2))
            fresh[renew] = True
        lam[a] = np.where(good, lam[a] * np.maximum(1.0 / 3.0, 1.0 - (2.0 * np.clip(ratio, 0, 1) - 1.0) ** 3),
                          np.where(was_fresh, np.maximum(lam[a] * 10.0, FIRST_DAMPING), lam[a]))
        stop = (good & small_step) | (~good & was_fresh & small_gain & np.isfinite(f_new))
        done[a[stop]] = True
        active[a[stop]] = False
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
                      uncertainty=unc, identifiability=report, nfev=int(nfev), njev=int(nfev), cost=float(cost),
                      free_index=free_idx)


__all__ = ["BatchReport", "BatchedFit", "batch_applies", "identify_batch"]

"""Compiled (numba) inner loops of the hexapod's IK and FK: the two hot paths.

Why numba: batched NumPy needs one LAPACK call per 6×6 Newton system; measured on the
2-core reference machine, ``np.linalg.solve`` on 100,000 stacked 6×6 systems alone costs
0.5–0.9 µs/pose per iteration, so a NumPy FK cannot meet the 1 µs/pose target
(``benchmarks/kinematics.py``). These kernels do the 6×6 elimination in registers and
allocate nothing per pose.

Conventions (see :mod:`pkmcal.conventions`): pose = (x, y, z, a, b, c), R = Rz(c)Ry(b)Rx(a),
leg vector l_i = p + R a_i − b_i (paper 1 eq. 1; paper 2 eq. 1 with its Rᵀ read as R),
leg length L_i = ‖l_i‖. FK is Newton–Raphson on the twist (δp, δω):

    J δ = L_target − L(p, R),   row i of J = [u_iᵀ, ((R a_i) × u_i)ᵀ],   u_i = l_i / L_i,
    p ← p + δp,   R ← exp([δω]×) R          (multiplicative SO(3) update)

A pose is reported converged only when max_i |L_i − L_target,i| ≤ tol, i.e. only when its
IK reproduces the input lengths; NaN/inf lengths or guesses and singular systems are
reported not converged.

Structure, chosen for compile time: ONE serial ``@njit(nogil=True, cache=True)`` kernel per
function, working on a row range [start, stop). Large batches are split into row chunks
run by a small Python thread pool (:mod:`concurrent.futures`, ``numba.get_num_threads()``
workers, the caller working too); the kernels release the GIL, so the chunks run in
parallel without numba's ``parallel=True`` (parfor) machinery, which had to be compiled
in addition to a serial variant. Every input is made C-contiguous, writable float64 before
the call, so each kernel is compiled for exactly one signature.

Measured on the 2-core reference machine (``benchmarks/kinematics.py``; another job was
using about one core throughout, so absolute figures are pessimistic; A/B runs interleaved):
cold-cache compile (fresh process, empty NUMBA_CACHE_DIR) of IK + FK went from 4.6 + 58 s
(parallel + serial variants, inlined helpers; ~2 + 23 s on an idle machine) to the figure
in the module constant below; FK µs/pose on 2 threads stayed within noise. See the report
in the benchmark's JSON (``compile_s``) for the current numbers.

Kept, because measured faster: loops with constant trip counts that LLVM unrolls, and
reciprocal pivots (solve ~0.12 µs instead of ~0.35); hoisting the first Newton step from a
guess shared by the batch (see :func:`fk_newton`).
Tried and dropped: fastmath on the solve (no measurable gain); a second-order first step
from the guess's leg-length Hessians (−0.36 iterations per pose, no net time saved).
"""

from __future__ import annotations

import itertools
import math
import threading
from concurrent.futures import ThreadPoolExecutor

import numba as nb
import numpy as np

#: Helpers are inlined by numba (``inline="always"``) only where it pays; see the docstring.
_OPTS = dict(cache=True, nogil=True, error_model="numpy")
#: Rows per thread below which a batch runs on the calling thread only (a thread hand-off
#: costs ~20–50 µs; IK is ~0.1 µs/pose, FK ~1 µs/pose on one thread).
_IK_GRAIN = 20_000
_FK_GRAIN = 500
#: Chunks per worker thread, for load balance when a core is busy with something else.
_CHUNKS_PER_THREAD = 4
#: The shared-guess first step (see :func:`fk_newton`) is hoisted from this many rows on.
_HOIST_FROM = 8

import os
_EXP = os.environ.get("PKMCAL_KIN_INLINE", "")
def _inl(name):
    return "always" if name in _EXP else "never"

_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _pool(workers: int) -> ThreadPoolExecutor:
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL._max_workers < workers:
            _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="pkmcal-kin")
        return _POOL


def _run_rows(kernel, n: int, grain: int, args: tuple) -> None:
    """Run ``kernel(*args, start, stop)`` over rows [0, n): in the calling thread for small
    n, else in chunks shared by the calling thread and ``numba.get_num_threads() − 1`` pool
    threads (the kernels release the GIL)."""
    workers = min(nb.get_num_threads(), n // grain) if n >= 2 * grain else 1
    if workers <= 1:
        kernel(*args, 0, n)
        return
    n_chunks = workers * _CHUNKS_PER_THREAD
    bounds = [n * i // n_chunks for i in range(n_chunks + 1)]
    nxt = itertools.count().__next__  # atomic under the GIL

    def work():
        while (i := nxt()) < n_chunks:
            kernel(*args, bounds[i], bounds[i + 1])

    pool = _pool(workers - 1)
    futures = [pool.submit(work) for _ in range(workers - 1)]
    work()
    for f in futures:
        f.result()


def _f64(a) -> np.ndarray:
    """C-contiguous, writable float64 (one compiled signature per kernel)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


@nb.njit(inline=_inl("euler"), **_OPTS)
def _euler_matrix(a, b, c, R):
    ca, cb, cc = math.cos(a), math.cos(b), math.cos(c)
    sa, sb, sc = math.sin(a), math.sin(b), math.sin(c)
    R[0, 0] = cc * cb
    R[0, 1] = cc * sb * sa - sc * ca
    R[0, 2] = cc * sb * ca + sc * sa
    R[1, 0] = sc * cb
    R[1, 1] = sc * sb * sa + cc * ca
    R[1, 2] = sc * sb * ca - cc * sa
    R[2, 0] = -sb
    R[2, 1] = cb * sa
    R[2, 2] = cb * ca


@nb.njit(**_OPTS)
def _ik_range(poses, base, platform, out, start, stop):
    """out[k, i] = ‖p_k + R_k a_i − b_i‖ for rows k in [start, stop)."""
    R = np.empty((3, 3))
    for k in range(start, stop):
        _euler_matrix(poses[k, 3], poses[k, 4], poses[k, 5], R)
        for i in range(6):
            s = 0.0
            for r in range(3):
                v = poses[k, r] - base[i, r]
                for q in range(3):
                    v += R[r, q] * platform[i, q]
                s += v * v
            out[k, i] = math.sqrt(s)


def ik_lengths(poses, base, platform):
    """Leg lengths L (N, 6) of poses (N, 6) [mm, rad]; base, platform (6, 3).

    L_i = ‖p + R a_i − b_i‖. Batches of 2 × ``_IK_GRAIN`` poses or more are split over
    threads.
    """
    poses, base, platform = _f64(poses), _f64(base), _f64(platform)
    out = np.empty((poses.shape[0], 6))
    _run_rows(_ik_range, poses.shape[0], _IK_GRAIN, (poses, base, platform, out))
    return out


@nb.njit(inline=_inl("solve"), **_OPTS)
def _solve6(J, rhs, d):
    """Solve J d = rhs (6×6) by Gaussian elimination with partial pivoting, in place.

    Returns False when a pivot is below 1e-12 × the largest entry (singular system). The
    loops have constant trip counts with ``if r > col`` guards so that LLVM unrolls them
    fully (measured 2.4× faster than variable-bound loops); on exit the diagonal of J
    holds the reciprocal pivots.
    """
    scale = 0.0
    for r in range(6):
        for c in range(6):
            scale = max(scale, abs(J[r, c]))
    if not scale > 0.0:
        return False
    tiny = 1e-12 * scale
    for col in range(6):
        piv = col
        best = abs(J[col, col])
        for r in range(6):
            if r > col:
                v = abs(J[r, col])
                if v > best:
                    best = v
                    piv = r
        if not best > tiny:
            return False
        if piv != col:
            for c in range(6):
                t = J[col, c]
                J[col, c] = J[piv, c]
                J[piv, c] = t
            t = rhs[col]
            rhs[col] = rhs[piv]
            rhs[piv] = t
        inv = 1.0 / J[col, col]
        J[col, col] = inv
        for r in range(6):
            if r > col:
                f = J[r, col] * inv
                for c in range(6):
                    if c > col:
                        J[r, c] -= f * J[col, c]
                rhs[r] -= f * rhs[col]
    for rr in range(6):
        r = 5 - rr
        s = rhs[r]
        for c in range(6):
            if c > r:
                s -= J[r, c] * d[c]
        d[r] = s * J[r, r]
    return True


@nb.njit(inline=_inl("res"), **_OPTS)
def _residual_jacobian(target, p, R, base, platform, J, rhs, ra):
    """rhs_i = target_i − L_i and row i of J = [u_iᵀ, ((R a_i) × u_i)ᵀ] at (p, R);
    returns max_i |rhs_i| (NaN/inf propagate, so a non-finite pose is never converged)."""
    err = 0.0
    for i in range(6):
        s = 0.0
        for r in range(3):
            ra[r] = R[r, 0] * platform[i, 0] + R[r, 1] * platform[i, 1] + R[r, 2] * platform[i, 2]
            J[i, r] = p[r] + ra[r] - base[i, r]
            s += J[i, r] * J[i, r]
        L = math.sqrt(s)
        res = target[i] - L
        rhs[i] = res
        a = abs(res)
        if not a <= err:  # also catches NaN
            err = a
        if L > 0.0:
            inv = 1.0 / L
            for r in range(3):
                J[i, r] *= inv
        J[i, 3] = ra[1] * J[i, 2] - ra[2] * J[i, 1]
        J[i, 4] = ra[2] * J[i, 0] - ra[0] * J[i, 2]
        J[i, 5] = ra[0] * J[i, 1] - ra[1] * J[i, 0]
    return err


@nb.njit(inline=_inl("step"), **_OPTS)
def _apply_step(d, p, R, Rn):
    """p ← p + δp,  R ← exp([δω]×) R (Rodrigues), δ = (δp, δω) = d."""
    for r in range(3):
        p[r] += d[r]
    wx, wy, wz = d[3], d[4], d[5]
    th = math.sqrt(wx * wx + wy * wy + wz * wz)
    if th > 0.0:
        kx, ky, kz = wx / th, wy / th, wz / th
        ct, st = math.cos(th), math.sin(th)
        vt = 1.0 - ct
        E00 = ct + kx * kx * vt
        E01 = kx * ky * vt - kz * st
        E02 = kx * kz * vt + ky * st
        E10 = ky * kx * vt + kz * st
        E11 = ct + ky * ky * vt
        E12 = ky * kz * vt - kx * st
        E20 = kz * kx * vt - ky * st
        E21 = kz * ky * vt + kx * st
        E22 = ct + kz * kz * vt
        for c in range(3):
            Rn[0, c] = E00 * R[0, c] + E01 * R[1, c] + E02 * R[2, c]
            Rn[1, c] = E10 * R[0, c] + E11 * R[1, c] + E12 * R[2, c]
            Rn[2, c] = E20 * R[0, c] + E21 * R[1, c] + E22 * R[2, c]
        for r in range(3):
            for c in range(3):
                R[r, c] = Rn[r, c]


@nb.njit(**_OPTS)
def _fk_range(lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
              start, stop):
    """Newton FK of rows [start, stop) (see :func:`fk_newton`); ``guesses`` is (1, 6), one
    guess for every row, or (N, 6)."""
    R = np.empty((3, 3))
    Rn = np.empty((3, 3))
    J = np.empty((6, 6))
    rhs = np.empty(6)
    d = np.empty(6)
    p = np.empty(3)
    ra = np.empty(3)
    Lg = np.zeros(6)
    Jg = np.empty((6, 6))
    Jinv = np.empty((6, 6))
    per_row = guesses.shape[0] > 1
    g0 = start if per_row else 0
    # hoisted: leg lengths L_g and J_g⁻¹ at the chunk's first guess (6 solves)
    shared_ok = False
    if stop - start >= _HOIST_FROM and max_iter > 0:
        _euler_matrix(guesses[g0, 3], guesses[g0, 4], guesses[g0, 5], R)
        for r in range(3):
            p[r] = guesses[g0, r]
        shared_ok = math.isfinite(_residual_jacobian(Lg, p, R, base, platform, Jg, rhs, ra))
        for i in range(6):
            Lg[i] = -rhs[i]
        for col in range(6):
            if not shared_ok:
                break
            for r in range(6):
                rhs[r] = 1.0 if r == col else 0.0
                for c in range(6):
                    J[r, c] = Jg[r, c]
            shared_ok = _solve6(J, rhs, d)
            for r in range(6):
                Jinv[r, col] = d[r]
    for k in range(start, stop):
        g = k if per_row else 0
        target = lengths[k]
        _euler_matrix(guesses[g, 3], guesses[g, 4], guesses[g, 5], R)
        for r in range(3):
            p[r] = guesses[g, r]
        it = 0
        err = np.inf
        first = shared_ok
        if first and per_row:
            for c in range(6):
                if guesses[k, c] != guesses[g0, c]:
                    first = False
        if first:
            # iteration 0 at the shared guess: residual and step from the hoisted L_g, J_g⁻¹
            err = 0.0
            for i in range(6):
                rhs[i] = target[i] - Lg[i]
                a = abs(rhs[i])
                if not a <= err:
                    err = a
            if math.isfinite(err) and err > tol:
                for r in range(6):
                    s = 0.0
                    for c in range(6):
                        s += Jinv[r, c] * rhs[c]
                    d[r] = s
                _apply_step(d, p, R, Rn)
                it = 1
        while True:
            if not (first and it == 0):  # else: converged at the guess, or non-finite input
                err = _residual_jacobian(target, p, R, base, platform, J, rhs, ra)
            first = False
            if not math.isfinite(err):
                break
            if err <= tol:
                converged[k] = True
                break
            if it >= max_iter:
                break
            if not _solve6(J, rhs, d):
                break
            it += 1
            _apply_step(d, p, R, Rn)
        iterations[k] = it
        residual[k] = err
        for r in range(3):
            poses[k, r] = p[r]
        # Euler angles of R = Rz(c) Ry(b) Rx(a); |b| < 90° on any hexapod workspace.
        poses[k, 4] = -math.asin(min(1.0, max(-1.0, R[2, 0])))
        poses[k, 3] = math.atan2(R[2, 1], R[2, 2])
        poses[k, 5] = math.atan2(R[1, 0], R[0, 0])


def fk_newton(lengths, guesses, base, platform, tol, max_iter):
    """Newton–Raphson FK for N sets of leg lengths (N, 6) from guesses (N, 6) or one guess
    for all, (1, 6) or (6,).

    Returns poses (N, 6) [mm, rad], converged (N,) bool, iterations (N,) int and the final
    max |L − L_target| (N,) in mm.

    Hoisted work: in each chunk of rows, poses whose guess equals the chunk's first guess
    (the usual cold start from the home pose) share that guess's leg lengths L_g and J_g⁻¹,
    computed once; their first Newton step is then δ = J_g⁻¹ (L_target − L_g), a 6×6
    product instead of an IK evaluation plus a factorisation. It is the same step, so
    iterates and iteration counts are those of plain Newton up to rounding. Batches of
    2 × ``_FK_GRAIN`` poses or more are split over threads.
    """
    lengths = _f64(lengths)
    guesses = _f64(np.atleast_2d(guesses))
    n = lengths.shape[0]
    if lengths.ndim != 2 or lengths.shape[1] != 6 or guesses.shape[1:] != (6,) or guesses.shape[0] not in (1, n):
        raise ValueError(f"fk_newton: lengths (N, 6) and guesses (1 or N, 6) expected; got {lengths.shape}, "
                         f"{guesses.shape}")
    poses = np.empty((n, 6))
    converged = np.zeros(n, dtype=np.bool_)
    iterations = np.zeros(n, dtype=np.int64)
    residual = np.empty(n)
    if n:
        args = (lengths, guesses, _f64(base), _f64(platform), float(tol), int(max_iter),
                poses, converged, iterations, residual)
        _run_rows(_fk_range, n, _FK_GRAIN, args)
    return poses, converged, iterations, residual

"""Compiled (numba) inner loops of the hexapod's IK and FK: the two hot paths.

Why numba: batched NumPy needs one LAPACK call per 6×6 Newton system; measured on the
2-core reference machine, ``np.linalg.solve`` on 100,000 stacked 6×6 systems alone costs
0.5–0.9 µs/pose per iteration (0.49 as first measured; 0.91 re-measured with the other
core busy), so a NumPy FK cannot meet the 1 µs/pose target (``benchmarks/kinematics.py``).
These kernels loop over poses in parallel (``prange``), do the 6×6 elimination in
registers and allocate nothing per pose.

Conventions (see :mod:`pkmcal.conventions`): pose = (x, y, z, a, b, c), R = Rz(c)Ry(b)Rx(a),
leg vector l_i = p + R a_i − b_i (paper 1 eq. 1; paper 2 eq. 1 with its Rᵀ read as R),
leg length L_i = ‖l_i‖. FK is Newton–Raphson on the twist (δp, δω):

    J δ = L_target − L(p, R),   row i of J = [u_iᵀ, ((R a_i) × u_i)ᵀ],   u_i = l_i / L_i,
    p ← p + δp,   R ← exp([δω]×) R          (multiplicative SO(3) update)

A pose is reported converged only when max_i |L_i − L_target,i| ≤ tol, i.e. only when its
IK reproduces the input lengths; NaN/inf lengths or guesses and singular systems are
reported not converged.

Where the FK time goes (one thread, stewart-prototype, 100,000 poses cold-started from
home, ±20° box, ~4 Newton steps per pose): the 6×6 solve dominated (~0.35 µs per solve
with variable-bound loops, ~0.08 µs per IK + Jacobian evaluation). Kept, because measured
faster: loops with constant trip counts that LLVM unrolls, and reciprocal pivots (solve
~0.12 µs); hoisting the first step from a guess shared by the batch (:func:`fk_newton`);
a serial kernel for small batches. FK, before → after, same iterates and iteration
counts (mean 3.99, all converged): 1.19 → 0.47–0.49 µs/pose on 2 threads in a quiet
window (2.47 → 0.87–0.91 on one thread); interleaved A/B runs with other jobs on the
machine: 1.18–1.27 → 0.71–0.73 (2.35–2.38 → 1.37–1.39). Cost: the first call compiles the
FK kernels (parallel, serial) for ~23 s and the IK ones for ~2 s on this machine; later
processes load them from numba's on-disk cache in ~0.02 s.
Tried and dropped: fastmath on the solve (no measurable gain); a second-order first
step from the guess's leg-length Hessians (−0.36 iterations per pose, no net time saved);
plain (non-inlined) helpers (compile 9 s instead of 23 s, but FK 15–25 % slower).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_OPTS = dict(cache=True, nogil=True, error_model="numpy")
_CHUNK = 512
#: Batches smaller than this run on one thread (no thread-pool start-up).
_SERIAL_BELOW = 64
#: The shared-guess first step (see :func:`fk_newton`) is hoisted from this batch size on.
_HOIST_FROM = 8


@nb.njit(inline="always", **_OPTS)
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


@nb.njit(inline="always", **_OPTS)
def _ik_rows(poses, base, platform, out, start, stop):
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


@nb.njit(parallel=True, **_OPTS)
def _ik_parallel(poses, base, platform):
    n = poses.shape[0]
    out = np.empty((n, 6))
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    for chunk in nb.prange(n_chunks):
        _ik_rows(poses, base, platform, out, chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK))
    return out


@nb.njit(**_OPTS)
def _ik_serial(poses, base, platform):
    out = np.empty((poses.shape[0], 6))
    _ik_rows(poses, base, platform, out, 0, poses.shape[0])
    return out


def ik_lengths(poses, base, platform):
    """Leg lengths L (N, 6) of poses (N, 6) [mm, rad]; base, platform (6, 3).

    L_i = ‖p + R a_i − b_i‖. Below ``_SERIAL_BELOW`` poses a serial kernel is used: starting
    the thread pool costs more than the work (measured ~10 µs per call).
    """
    if poses.shape[0] < _SERIAL_BELOW:
        return _ik_serial(poses, base, platform)
    return _ik_parallel(poses, base, platform)


@nb.njit(inline="always", **_OPTS)
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


@nb.njit(inline="always", **_OPTS)
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


@nb.njit(inline="always", **_OPTS)
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
def _shared_guess_step(guess, base, platform):
    """For the guess shared by many poses: its leg lengths L_g (6,) and J_g⁻¹ (6, 6).

    Returns ``(ok, L_g, Jinv)``; ``ok`` is False when J_g is singular or the guess is not
    finite, in which case every pose takes the generic path.
    """
    R = np.empty((3, 3))
    J = np.empty((6, 6))
    Jc = np.empty((6, 6))
    rhs = np.empty(6)
    d = np.empty(6)
    p = np.empty(3)
    ra = np.empty(3)
    zero = np.zeros(6)
    Lg = np.empty(6)
    Jinv = np.empty((6, 6))
    _euler_matrix(guess[3], guess[4], guess[5], R)
    for r in range(3):
        p[r] = guess[r]
    err = _residual_jacobian(zero, p, R, base, platform, J, rhs, ra)
    if not math.isfinite(err):
        return False, Lg, Jinv
    for i in range(6):
        Lg[i] = -rhs[i]
    for col in range(6):
        for r in range(6):
            rhs[r] = 1.0 if r == col else 0.0
            for c in range(6):
                Jc[r, c] = J[r, c]
        if not _solve6(Jc, rhs, d):
            return False, Lg, Jinv
        for r in range(6):
            Jinv[r, col] = d[r]
    return True, Lg, Jinv


def fk_newton(lengths, guesses, base, platform, tol, max_iter):
    """Newton–Raphson FK for N sets of leg lengths (N, 6) from guesses (N, 6).

    Returns poses (N, 6) [mm, rad], converged (N,) bool, iterations (N,) int and the final
    max |L − L_target| (N,) in mm.

    Hoisted work: poses whose guess equals ``guesses[0]`` (the usual cold start from the
    home pose) share the guess's leg lengths L_g and J_g⁻¹, computed once; their first
    Newton step is then δ = J_g⁻¹ (L_target − L_g), a 6×6 product instead of an IK
    evaluation plus a factorisation. It is the same step, so iterates and iteration counts
    are those of plain Newton up to rounding. Small batches run on one thread.
    """
    n = lengths.shape[0]
    if n == 0:
        return np.empty((0, 6)), np.zeros(0, dtype=np.bool_), np.zeros(0, dtype=np.int64), np.empty(0)
    if n < _SERIAL_BELOW:
        return _fk_serial(lengths, guesses, base, platform, float(tol), int(max_iter))
    return _fk_parallel(lengths, guesses, base, platform, float(tol), int(max_iter))


@nb.njit(inline="always", **_OPTS)
def _fk_rows(lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
             shared_ok, Lg, Jinv, start, stop):
    # scratch space allocated once per call/chunk, not per pose
    R = np.empty((3, 3))
    Rn = np.empty((3, 3))
    J = np.empty((6, 6))
    rhs = np.empty(6)
    d = np.empty(6)
    p = np.empty(3)
    ra = np.empty(3)
    for k in range(start, stop):
        _fk_one(k, lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
                shared_ok, Lg, Jinv, R, Rn, J, rhs, d, p, ra)


@nb.njit(parallel=True, **_OPTS)
def _fk_parallel(lengths, guesses, base, platform, tol, max_iter):
    n = lengths.shape[0]
    poses = np.empty((n, 6))
    converged = np.zeros(n, dtype=np.bool_)
    iterations = np.zeros(n, dtype=np.int64)
    residual = np.empty(n)
    shared_ok, Lg, Jinv = _shared_guess_step(guesses[0], base, platform)
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    for chunk in nb.prange(n_chunks):
        _fk_rows(lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
                 shared_ok, Lg, Jinv, chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK))
    return poses, converged, iterations, residual


@nb.njit(**_OPTS)
def _fk_serial(lengths, guesses, base, platform, tol, max_iter):
    n = lengths.shape[0]
    poses = np.empty((n, 6))
    converged = np.zeros(n, dtype=np.bool_)
    iterations = np.zeros(n, dtype=np.int64)
    residual = np.empty(n)
    if n >= _HOIST_FROM:
        shared_ok, Lg, Jinv = _shared_guess_step(guesses[0], base, platform)
    else:  # J_g⁻¹ costs 6 solves: not worth it for a handful of poses
        shared_ok, Lg, Jinv = False, np.empty(6), np.empty((6, 6))
    _fk_rows(lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
             shared_ok, Lg, Jinv, 0, n)
    return poses, converged, iterations, residual


@nb.njit(inline="always", **_OPTS)
def _fk_one(k, lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
            shared_ok, Lg, Jinv, R, Rn, J, rhs, d, p, ra):
    target = lengths[k]
    _euler_matrix(guesses[k, 3], guesses[k, 4], guesses[k, 5], R)
    for r in range(3):
        p[r] = guesses[k, r]
    it = 0
    err = np.inf
    first = False
    if shared_ok and max_iter > 0:
        first = True
        for c in range(6):
            if guesses[k, c] != guesses[0, c]:
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
        if first and it == 0:
            pass  # converged at the guess, or non-finite input: err already set
        else:
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

"""Compiled (numba) inner loops of the hexapod's IK and FK: the two hot paths.

Why numba: batched NumPy needs one LAPACK call per 6×6 Newton system; measured on the
2-core reference machine, ``np.linalg.solve`` on 100,000 stacked 6×6 systems alone costs
0.49 µs/pose per iteration, so a NumPy FK cannot meet the 1 µs/pose target
(``benchmarks/kinematics.py``). These kernels loop over poses in parallel (``prange``),
do the 6×6 elimination in registers and allocate nothing per pose.

Conventions (see :mod:`pkmcal.conventions`): pose = (x, y, z, a, b, c), R = Rz(c)Ry(b)Rx(a),
leg vector l_i = p + R a_i − b_i (paper 1 eq. 1; paper 2 eq. 1 with its Rᵀ read as R),
leg length L_i = ‖l_i‖. FK is Newton–Raphson on the twist (δp, δω):

    J δ = L_target − L(p, R),   row i of J = [u_iᵀ, ((R a_i) × u_i)ᵀ],   u_i = l_i / L_i,
    p ← p + δp,   R ← exp([δω]×) R          (multiplicative SO(3) update)

A pose is reported converged only when max_i |L_i − L_target,i| ≤ tol, i.e. only when its
IK reproduces the input lengths.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_OPTS = dict(cache=True, nogil=True, error_model="numpy")
_CHUNK = 512


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


@nb.njit(parallel=True, **_OPTS)
def ik_lengths(poses, base, platform):
    """Leg lengths L (N, 6) of poses (N, 6) [mm, rad]; base, platform (6, 3)."""
    n = poses.shape[0]
    out = np.empty((n, 6))
    for k in nb.prange(n):
        R = np.empty((3, 3))
        _euler_matrix(poses[k, 3], poses[k, 4], poses[k, 5], R)
        for i in range(6):
            s = 0.0
            for r in range(3):
                v = poses[k, r] - base[i, r]
                for q in range(3):
                    v += R[r, q] * platform[i, q]
                s += v * v
            out[k, i] = math.sqrt(s)
    return out


@nb.njit(inline="always", **_OPTS)
def _solve6(J, rhs, d):
    """Solve J d = rhs (6×6) by Gaussian elimination with partial pivoting, in place.
    Returns False when a pivot is below 1e-12 × the largest entry (singular system)."""
    scale = 0.0
    for r in range(6):
        for c in range(6):
            scale = max(scale, abs(J[r, c]))
    if scale == 0.0:
        return False
    for col in range(6):
        piv = col
        best = abs(J[col, col])
        for r in range(col + 1, 6):
            if abs(J[r, col]) > best:
                best = abs(J[r, col])
                piv = r
        if best <= 1e-12 * scale:
            return False
        if piv != col:
            for c in range(6):
                J[col, c], J[piv, c] = J[piv, c], J[col, c]
            rhs[col], rhs[piv] = rhs[piv], rhs[col]
        for r in range(col + 1, 6):
            f = J[r, col] / J[col, col]
            for c in range(col, 6):
                J[r, c] -= f * J[col, c]
            rhs[r] -= f * rhs[col]
    for r in range(5, -1, -1):
        s = rhs[r]
        for c in range(r + 1, 6):
            s -= J[r, c] * d[c]
        d[r] = s / J[r, r]
    return True


@nb.njit(parallel=True, **_OPTS)
def fk_newton(lengths, guesses, base, platform, tol, max_iter):
    """Newton–Raphson FK for N sets of leg lengths (N, 6) from guesses (N, 6).

    Returns poses (N, 6) [mm, rad], converged (N,) bool, iterations (N,) int and the final
    max |L − L_target| (N,) in mm.
    """
    n = lengths.shape[0]
    poses = np.empty((n, 6))
    converged = np.zeros(n, dtype=np.bool_)
    iterations = np.zeros(n, dtype=np.int64)
    residual = np.empty(n)
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    for chunk in nb.prange(n_chunks):
        # scratch space allocated once per chunk, not per pose
        R = np.empty((3, 3))
        Rn = np.empty((3, 3))
        J = np.empty((6, 6))
        rhs = np.empty(6)
        d = np.empty(6)
        p = np.empty(3)
        ra = np.empty(3)
        for k in range(chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK)):
            _fk_one(k, lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
                    R, Rn, J, rhs, d, p, ra)
    return poses, converged, iterations, residual


@nb.njit(inline="always", **_OPTS)
def _fk_one(k, lengths, guesses, base, platform, tol, max_iter, poses, converged, iterations, residual,
            R, Rn, J, rhs, d, p, ra):
    _euler_matrix(guesses[k, 3], guesses[k, 4], guesses[k, 5], R)
    for r in range(3):
        p[r] = guesses[k, r]
    it = 0
    err = np.inf
    while True:
        err = 0.0
        for i in range(6):
            s = 0.0
            for r in range(3):
                ra[r] = R[r, 0] * platform[i, 0] + R[r, 1] * platform[i, 1] + R[r, 2] * platform[i, 2]
                J[i, r] = p[r] + ra[r] - base[i, r]
                s += J[i, r] * J[i, r]
            L = math.sqrt(s)
            res = lengths[k, i] - L
            rhs[i] = res
            err = max(err, abs(res))
            if L > 0.0:
                for r in range(3):
                    J[i, r] /= L
            # (R a_i) × u_i
            J[i, 3] = ra[1] * J[i, 2] - ra[2] * J[i, 1]
            J[i, 4] = ra[2] * J[i, 0] - ra[0] * J[i, 2]
            J[i, 5] = ra[0] * J[i, 1] - ra[1] * J[i, 0]
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
        for r in range(3):
            p[r] += d[r]
        # R <- exp([w]x) R, Rodrigues
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
    iterations[k] = it
    residual[k] = err
    for r in range(3):
        poses[k, r] = p[r]
    # Euler angles of R = Rz(c) Ry(b) Rx(a); |b| < 90° on any hexapod workspace.
    poses[k, 4] = -math.asin(min(1.0, max(-1.0, R[2, 0])))
    poses[k, 3] = math.atan2(R[2, 1], R[2, 2])
    poses[k, 5] = math.atan2(R[1, 0], R[0, 0])

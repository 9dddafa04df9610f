"""Compiled (numba) inner loops of the hexapod's IK, FK and limit checks: the hot paths.

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
function (:func:`_ik_range`, :func:`_fk_range`) working on a row range [start, stop).
Batches of 2 grains or more (``_IK_GRAIN``, ``_FK_GRAIN``) are cut into row chunks that the
calling thread and the process's shared thread pool (:func:`pkmcal.parallel.run_rows`:
``numba.get_num_threads()`` workers in all, so ``numba.set_num_threads(1)`` still means one thread) take in turn; the
kernels release the GIL, so the chunks run in parallel without ``parallel=True``, whose
parfor lowering had to be compiled on top of a serial variant. Helpers are plain ``@njit``
functions (LLVM inlines them; numba-level ``inline="always"`` only re-types them at every
call site), and every input is made C-contiguous, writable float64 first, so each kernel
is compiled for exactly one signature.

Measured on the 2-core reference machine while other jobs kept it busy (load average
1.5–2.7), before → after, interleaved runs:

* cold-cache compile (fresh process, empty NUMBA_CACHE_DIR, as ``benchmarks/kinematics.py``
  does): IK + FK 3.3–4.6 + 39–58 s → 1.0–1.3 + 3.1–5.6 s (the old kernels took ~2 + 23 s
  on an idle machine). Variants of the new kernels, same conditions: no
  ``inline="always"`` 0.7 + 3.6 s; Euler matrix inlined 1.3 + 5.9 s; every helper inlined
  1.9 + 9.6 s, and neither inlined variant was faster per pose.
* 100,000 poses, 2 threads (best of 9): IK 0.06–0.24 → 0.05–0.15 µs/pose; FK (cold start
  from home, 3.99 iterations, same iterates) 0.76–1.77 → 0.66–1.80 µs/pose, the spread
  being the other jobs (one thread: 1.0–1.7 µs/pose for both).
* whole commands on a cold cache: ``pkmcal info stewart-prototype`` 31 s → 7.9 s,
  ``pkmcal demo`` 133 s → 20.5 s (that "before" run shared the machine with a test run
  and predates other engineers' speed-ups, so it overstates this module's share).

Kept, because measured faster: loops with constant trip counts that LLVM unrolls, and
reciprocal pivots (solve ~0.12 µs instead of ~0.35); hoisting the first Newton step from a
guess shared by the rows of a chunk (see :func:`fk_newton`).
Tried and dropped: fastmath on the solve (no measurable gain); a second-order first step
from the guess's leg-length Hessians (−0.36 iterations per pose, no net time saved).

**Limit checks** (:func:`limit_margins`, used by ``Hexapod.check_limits``): planning checks
every candidate pose, ~8 poses tested per pose accepted on the prototype, so 10^5 candidates
mean 8·10^5 checks. The vectorised NumPy formulas cost 20–24 µs/pose (measured, 200,000
poses, 2-core reference machine, load ~2): the leg-segment distances of 15 leg pairs on
(N, 15, 3) temporaries and one LAPACK SVD per 6×6 Jacobian (~6 µs) dominate. The kernel
does one pose in registers: 1.2 µs/pose on one thread, same run (stroke and IK 0.16, tilts
0.19, segment distances 0.68, singularity certificate 0.23). The pair distances take each
leg's vector and squared length once per pose and the pairs' base offsets once per call,
pass scalars (an array slice handed to a helper costs NRT reference counting) and return
squared distances (one square root per pose). The singularity test needs only the verdict
σ_min/σ_max ≥ m, decided by two 6×6 Cholesky factorisations
(:func:`singularity_certificate`) instead of an SVD (a one-sided Jacobi SVD in the kernel
measured 2.7 µs/pose alone); undecided poses go to the SVD.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from pkmcal.parallel import run_rows

#: No ``inline="always"``: LLVM inlines the small helpers anyway (see the module docstring).
_OPTS = dict(cache=True, nogil=True, error_model="numpy")
#: Rows per thread below which a batch runs on the calling thread only: handing chunks to
#: the pool costs ~50 µs per call (measured), IK is ~0.1 µs/pose and FK ~1 µs/pose on one
#: thread, so IK is threaded from 10,000 poses and FK from 1,000.
_IK_GRAIN = 5_000
_FK_GRAIN = 500
#: The shared-guess first step (see :func:`fk_newton`) is hoisted from this many rows on.
_HOIST_FROM = 8


def _run_rows(kernel, n: int, grain: int, args: tuple) -> None:
    """Run ``kernel(*args, start, stop)`` over rows [0, n) on this process's threads
    (:func:`pkmcal.parallel.run_rows`: the calling thread alone for small n)."""
    run_rows(lambda start, stop: kernel(*args, start, stop), n, grain)


def _f64(a) -> np.ndarray:
    """C-contiguous, writable float64 (one compiled signature per kernel)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


@nb.njit(**_OPTS)
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
    """out[k, i] = ‖p_k + R_k a_i − b_i‖ for rows k in [start, stop), in the operation order
    of :func:`_jacobians_range` (so both give the same bits)."""
    R = np.empty((3, 3))
    for k in range(start, stop):
        _euler_matrix(poses[k, 3], poses[k, 4], poses[k, 5], R)
        for i in range(6):
            s = 0.0
            for r in range(3):
                v = poses[k, r] + (R[r, 0] * platform[i, 0] + R[r, 1] * platform[i, 1]
                                   + R[r, 2] * platform[i, 2]) - base[i, r]
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


@nb.njit(**_OPTS)
def _jacobians_range(poses, base, platform, offset, gains, A, B, lam, start, stop):
    """For rows k in [start, stop): A[k] = ∂λ/∂(x, y, z, a, b, c) (6×6), the non-zero
    entries of B[k] = ∂λ/∂ρ (6×48; B must be zero on entry) and the readings
    lam[k] = (L − L0) / g (6,) (L bit-identical to :func:`_ik_range`).

    Leg i: u_i = l_i/‖l_i‖, w_i = (R a_i) × u_i; A row i = [u_iᵀ, w_iᵀ E(a, b, c)] / g_i
    with E the Euler rate matrix (:func:`pkmcal.conventions.euler_rate_matrix`), B row i on
    leg i's 7 columns = [−u_iᵀ, u_iᵀ R, −1] / g_i and on its gain column 42 + i −λ_i / g_i
    (paper 1 eq. 1–2: l_i = p + R a_i − b_i, λ_i = (‖l_i‖ − L0_i) / g_i). Every factor
    1 / g_i is 1.0 for a unit gain, so those entries are the papers' bits exactly.
    """
    R = np.empty((3, 3))
    ng = 7 * 6  # the gain columns follow the 42 geometry columns
    for k in range(start, stop):
        _euler_matrix(poses[k, 3], poses[k, 4], poses[k, 5], R)
        cb, sb = math.cos(poses[k, 4]), math.sin(poses[k, 4])
        cc, sc = math.cos(poses[k, 5]), math.sin(poses[k, 5])
        for i in range(6):
            ra0 = R[0, 0] * platform[i, 0] + R[0, 1] * platform[i, 1] + R[0, 2] * platform[i, 2]
            ra1 = R[1, 0] * platform[i, 0] + R[1, 1] * platform[i, 1] + R[1, 2] * platform[i, 2]
            ra2 = R[2, 0] * platform[i, 0] + R[2, 1] * platform[i, 1] + R[2, 2] * platform[i, 2]
            l0 = poses[k, 0] + ra0 - base[i, 0]
            l1 = poses[k, 1] + ra1 - base[i, 1]
            l2 = poses[k, 2] + ra2 - base[i, 2]
            length = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
            g = gains[i]
            reading = (length - offset[i]) / g
            lam[k, i] = reading
            inv = 1.0 / length
            u0, u1, u2 = l0 * inv, l1 * inv, l2 * inv
            wx = ra1 * u2 - ra2 * u1
            wy = ra2 * u0 - ra0 * u2
            wz = ra0 * u1 - ra1 * u0
            ig = 1.0 / g
            A[k, i, 0] = u0 * ig
            A[k, i, 1] = u1 * ig
            A[k, i, 2] = u2 * ig
            A[k, i, 3] = (cb * (cc * wx + sc * wy) - sb * wz) * ig
            A[k, i, 4] = (cc * wy - sc * wx) * ig
            A[k, i, 5] = wz * ig
            c0 = 7 * i
            B[k, i, c0] = -u0 * ig
            B[k, i, c0 + 1] = -u1 * ig
            B[k, i, c0 + 2] = -u2 * ig
            for c in range(3):
                B[k, i, c0 + 3 + c] = (u0 * R[0, c] + u1 * R[1, c] + u2 * R[2, c]) * ig
            B[k, i, c0 + 6] = -ig
            B[k, i, ng + i] = -reading * ig


def readings_and_jacobians(poses, base, platform, offset, gains):
    """``(λ, A, B)``: readings (N, 6) = (L − L0) / g, ∂λ/∂pose (N, 6, 6) and ∂λ/∂ρ
    (N, 6, 48) of poses (N, 6) [mm, rad] in one pass (see :func:`_jacobians_range`);
    offset, gains (6,); threaded like :func:`ik_lengths`."""
    poses, base, platform, offset, gains = _f64(poses), _f64(base), _f64(platform), _f64(offset), _f64(gains)
    n = poses.shape[0]
    A = np.empty((n, 6, 6))
    B = np.zeros((n, 6, 48))
    lam = np.empty((n, 6))
    _run_rows(_jacobians_range, n, _IK_GRAIN, (poses, base, platform, offset, gains, A, B, lam))
    return lam, A, B



@nb.njit(**_OPTS)
def _solve6(J, rhs, d):
    """Solve J d = rhs (6×6) by Gaussian elimination with partial pivoting, in place.

    Returns 0 when a pivot is below 1e-12 × the largest entry (singular system), else the
    sign of det J (±1: (−1)^(row swaps) times the signs of the pivots), for free. The
    loops have constant trip counts with ``if r > col`` guards so that LLVM unrolls them
    fully (measured 2.4× faster than variable-bound loops); on exit the diagonal of J
    holds the reciprocal pivots.
    """
    scale = 0.0
    for r in range(6):
        for c in range(6):
            scale = max(scale, abs(J[r, c]))
    if not scale > 0.0:
        return 0
    tiny = 1e-12 * scale
    sign = 1
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
            return 0
        if piv != col:
            sign = -sign
            for c in range(6):
                t = J[col, c]
                J[col, c] = J[piv, c]
                J[piv, c] = t
            t = rhs[col]
            rhs[col] = rhs[piv]
            rhs[piv] = t
        if J[col, col] < 0.0:
            sign = -sign
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
    return sign


@nb.njit(**_OPTS)
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


@nb.njit(**_OPTS)
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
def _fk_range(lengths, guesses, base, platform, tol, max_iter, polish, poses, converged, iterations, residual,
              signs, start, stop):
    """Newton FK of rows [start, stop) (see :func:`fk_newton`); ``guesses`` is (1, 6), one
    guess for every row, or (N, 6). ``signs[k]``: sign det J of the twist Jacobian at the
    converged pose, from the factorisation of the last Newton system (free; see the comment
    at its end), 0 where not converged."""
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
    shared_sign = 0
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
            shared_sign = _solve6(J, rhs, d)
            shared_ok = shared_sign != 0
            for r in range(6):
                Jinv[r, col] = d[r]
    for k in range(start, stop):
        g = k if per_row else 0
        target = lengths[k]
        _euler_matrix(guesses[g, 3], guesses[g, 4], guesses[g, 5], R)
        for r in range(3):
            p[r] = guesses[g, r]
        it = 0
        extra = 0
        err = np.inf
        last_sign = 0  # sign det J of the last Newton system solved (0: none)
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
                last_sign = shared_sign
        j_here = False  # J holds the twist Jacobian at the current (p, R)
        while True:
            fresh = not (first and it == 0)  # else: converged at the guess, or non-finite input
            if fresh:
                err = _residual_jacobian(target, p, R, base, platform, J, rhs, ra)
                j_here = True
            first = False
            if not math.isfinite(err):
                break
            if err <= tol:
                if extra >= polish:
                    break
                # polishing step from the converged pose: the error goes from err to ~err²
                if not fresh:
                    err = _residual_jacobian(target, p, R, base, platform, J, rhs, ra)
                extra += 1
                j_here = False
                sgn = _solve6(J, rhs, d)
                if sgn == 0:
                    break
                last_sign = sgn
                _apply_step(d, p, R, Rn)
                continue
            if it >= max_iter:
                break
            j_here = False
            sgn = _solve6(J, rhs, d)
            if sgn == 0:
                break
            last_sign = sgn
            it += 1
            _apply_step(d, p, R, Rn)
        converged[k] = err <= tol
        # sign det J at the pose: that of the last Newton system, solved at the previous
        # iterate, one converged step (≲ √(tol·L) mm) away, so the same unless the pose is
        # singular to that distance; computed afresh only when no system was solved
        signs[k] = 0
        if err <= tol:
            if last_sign != 0:
                signs[k] = last_sign
            else:
                if not j_here:
                    _residual_jacobian(target, p, R, base, platform, J, rhs, ra)
                signs[k] = _solve6(J, rhs, d)
        iterations[k] = it
        residual[k] = err
        for r in range(3):
            poses[k, r] = p[r]
        # Euler angles of R = Rz(c) Ry(b) Rx(a); |b| < 90° on any hexapod workspace.
        poses[k, 4] = -math.asin(min(1.0, max(-1.0, R[2, 0])))
        poses[k, 3] = math.atan2(R[2, 1], R[2, 2])
        poses[k, 5] = math.atan2(R[1, 0], R[0, 0])


@nb.njit(**_OPTS)
def _det_sign_range(poses, base, platform, out, start, stop):
    """out[k] = sign det J(pose_k) of the twist Jacobian, row i = [u_iᵀ, ((R a_i) × u_i)ᵀ],
    for rows k in [start, stop): the sign :func:`_solve6` finds while factorising J (0 when
    singular to working precision, or for a pose that is not finite)."""
    R = np.empty((3, 3))
    J = np.empty((6, 6))
    rhs = np.empty(6)
    d = np.empty(6)
    ra = np.empty(3)
    p = np.empty(3)
    zero = np.zeros(6)
    for k in range(start, stop):
        _euler_matrix(poses[k, 3], poses[k, 4], poses[k, 5], R)
        for r in range(3):
            p[r] = poses[k, r]
        err = _residual_jacobian(zero, p, R, base, platform, J, rhs, ra)
        out[k] = _solve6(J, rhs, d) if math.isfinite(err) else 0


def twist_det_signs(poses, base, platform):
    """sign det J (N,) int8 of the twist Jacobian ∂L/∂(δp, δω) at poses (N, 6) [mm, rad]:
    +1, −1, or 0 where singular to working precision (or not finite). Its sign tells the
    assembly mode apart: it changes only through a singularity (det J = 0)."""
    poses, base, platform = _f64(np.atleast_2d(poses)), _f64(base), _f64(platform)
    out = np.zeros(poses.shape[0], dtype=np.int8)
    _run_rows(_det_sign_range, poses.shape[0], _IK_GRAIN, (poses, base, platform, out))
    return out


def fk_newton(lengths, guesses, base, platform, tol, max_iter, polish=0):
    """``(poses, converged, iterations, residual)`` of :func:`fk_newton_signed`."""
    return fk_newton_signed(lengths, guesses, base, platform, tol, max_iter, polish)[:4]


def fk_newton_signed(lengths, guesses, base, platform, tol, max_iter, polish=0):
    """Newton–Raphson FK for N sets of leg lengths (N, 6) from guesses (N, 6) or one guess
    for all, (1, 6) or (6,).

    ``polish`` extra Newton steps are taken once a pose has converged (max |ΔL| ≤ tol), each
    squaring the error, so one step takes a pose converged to 1e-9 mm to rounding level;
    they are not counted in ``iterations``. Least-squares fits through FK need it: their
    1e-12 tolerances, and finite-difference Jacobians with steps ~1e-8·|θ|, see an FK
    error of 1e-10 mm as noise.

    Returns poses (N, 6) [mm, rad], converged (N,) bool, iterations (N,) int and the final
    max |L − L_target| (N,) in mm (:func:`fk_newton_signed` also the sign det J of each
    converged pose).

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
    signs = np.zeros(n, dtype=np.int8)
    if n:
        args = (lengths, guesses, _f64(base), _f64(platform), float(tol), int(max_iter), int(polish),
                poses, converged, iterations, residual, signs)
        _run_rows(_fk_range, n, _FK_GRAIN, args)
    return poses, converged, iterations, residual, signs


# -- limits (Hexapod.check_limits) -------------------------------------------------------

#: Rows per thread below which :func:`limit_margins` runs on the calling thread only
#: (~1 µs/pose; see the IK/FK grains above).
_LIMIT_GRAIN = 2_000
#: Slack of the singularity certificate, relative to tr(JᵀJ) ≥ λ_max: 100× the rounding
#: error of forming JᵀJ and of its 6×6 Cholesky factorisation (≈ 36 ε tr).
_CERTIFICATE_SLACK = 1e-12


@nb.njit(**_OPTS)
def _clip01(x):
    """np.clip(x, 0, 1), NaN propagated."""
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@nb.njit(**_OPTS)
def _point_segment_sq(w0, w1, w2, d0, d1, d2, inv_dd):
    """Squared distance ‖u d − w‖² from a point to the segment p + u d, u ∈ [0, 1], with
    w = point − p and inv_dd = 1 / d·d: u = clip(w·d / d·d, 0, 1)."""
    u = _clip01((w0 * d0 + w1 * d1 + w2 * d2) * inv_dd)
    e0, e1, e2 = u * d0 - w0, u * d1 - w1, u * d2 - w2
    return e0 * e0 + e1 * e1 + e2 * e2


@nb.njit(**_OPTS)
def _segment_distance_sq(r0, r1, r2, d10, d11, d12, d20, d21, d22, a, e):
    """Squared minimum distance between the segments p1 → p1 + d1 and p2 → p2 + d2, given
    r = p1 − p2, d1, d2 and a = d1·d1, e = d2·d2 (the limit kernel has them per leg and per
    leg pair), by the formula of :func:`pkmcal.mechanisms.hexapod.segment_distance`
    (Ericson §5.1.9, with its zero-length and parallel cases), in registers. Squared, so
    that a minimum over pairs takes one square root."""
    f = d20 * r0 + d21 * r1 + d22 * r2
    c = d10 * r0 + d11 * r1 + d12 * r2
    b = d10 * d20 + d11 * d21 + d12 * d22
    point1 = a <= 2.2250738585072014e-308  # np.finfo(float).tiny: segment 1 is a point
    point2 = e <= 2.2250738585072014e-308
    inv_a = 1.0 if point1 else 1.0 / a
    inv_e = 1.0 if point2 else 1.0 / e
    denom = a * e - b * b
    skew = denom > 1e-12 * a * e
    s = _clip01((b * f - c * e) / denom) if skew else 0.0
    t = (b * s + f) * inv_e
    if t < 0.0:
        s = _clip01(-c * inv_a)
    elif t > 1.0:
        s = _clip01((b - c) * inv_a)
    t = _clip01(t)
    if point1:
        s = 0.0
    elif point2:
        s = _clip01(-c * inv_a)
    if point2:
        t = 0.0
    elif point1:
        t = _clip01(f * inv_e)
    g0 = r0 + s * d10 - t * d20
    g1 = r1 + s * d11 - t * d21
    g2 = r2 + s * d12 - t * d22
    dist = g0 * g0 + g1 * g1 + g2 * g2
    if not skew and not point1 and not point2:
        # (near-)parallel: the minimum is also attained at an endpoint of one segment:
        # p1, q1 against segment 2 (w = r, r + d1), p2, q2 against segment 1 (w = −r, d2 − r)
        ends = min(_point_segment_sq(r0, r1, r2, d20, d21, d22, inv_e),
                   _point_segment_sq(r0 + d10, r1 + d11, r2 + d12, d20, d21, d22, inv_e),
                   _point_segment_sq(-r0, -r1, -r2, d10, d11, d12, inv_a),
                   _point_segment_sq(d20 - r0, d21 - r1, d22 - r2, d10, d11, d12, inv_a))
        if ends < dist:
            dist = ends
    return dist


@nb.njit(**_OPTS)
def segment_distances(p1, q1, p2, q2, out):
    """out[k] = distance between the segments p1[k]→q1[k] and p2[k]→q2[k], arrays (N, 3):
    the compiled :func:`_segment_distance_sq` (which the limit kernel uses), for testing it
    against the NumPy formula."""
    for k in range(p1.shape[0]):
        r0, r1, r2 = p1[k, 0] - p2[k, 0], p1[k, 1] - p2[k, 1], p1[k, 2] - p2[k, 2]
        d10, d11, d12 = q1[k, 0] - p1[k, 0], q1[k, 1] - p1[k, 1], q1[k, 2] - p1[k, 2]
        d20, d21, d22 = q2[k, 0] - p2[k, 0], q2[k, 1] - p2[k, 1], q2[k, 2] - p2[k, 2]
        out[k] = math.sqrt(_segment_distance_sq(r0, r1, r2, d10, d11, d12, d20, d21, d22,
                                                d10 * d10 + d11 * d11 + d12 * d12, d20 * d20 + d21 * d21 + d22 * d22))


@nb.njit(**_OPTS)
def _cholesky_succeeds(C, shift, L):
    """True when the Cholesky factorisation of C − shift·I (6×6) has only positive pivots;
    L (6×6) is workspace."""
    for i in range(6):
        for k in range(i + 1):
            s = C[i, k] - (shift if i == k else 0.0)
            for q in range(k):
                s -= L[i, q] * L[k, q]
            if i == k:
                if not s > 0.0:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, k] = s / L[k, k]
    return True


@nb.njit(**_OPTS)
def singularity_certificate(J, m, C, L):
    """Decide σ_min(J)/σ_max(J) ≥ m for a 6×6 J without its singular values: +1.0 when
    certainly ≥ m, −1.0 when certainly < m, NaN when undecided (then compute the SVD).

    With C = JᵀJ, λ_min(C) = σ_min², and bounds lo = max_i C_ii ≤ λ_max(C) ≤ hi =
    min(tr C, max_i Σ_k |C_ik|): if C − (m² hi + δ) I has a Cholesky factor then λ_min >
    m² hi ≥ m² λ_max (≥ m); if C − (m² lo − δ) I has none then λ_min < m² lo ≤ m² λ_max
    (< m). δ = :data:`_CERTIFICATE_SLACK` · tr C covers the rounding of both steps. C, L
    (6×6) are workspace.
    """
    for i in range(6):
        for k in range(i + 1):
            s = 0.0
            for q in range(6):
                s += J[q, i] * J[q, k]
            C[i, k] = s
            C[k, i] = s
    tr = 0.0
    lo = 0.0
    hi = 0.0
    for i in range(6):
        tr += C[i, i]
        lo = max(lo, C[i, i])
        row = 0.0
        for k in range(6):
            row += abs(C[i, k])
        hi = max(hi, row)
    if not (tr > 0.0 and tr < np.inf):  # NaN, inf or J = 0
        return np.nan
    hi = min(hi, tr)
    slack = _CERTIFICATE_SLACK * tr
    m2 = m * m
    if _cholesky_succeeds(C, m2 * hi + slack, L):
        return 1.0
    shift = m2 * lo - slack
    if shift > slack and not _cholesky_succeeds(C, shift, L):
        return -1.0
    return np.nan


@nb.njit(**_OPTS)
def _tilt(cosine):
    """The joint tilt (rad) of a cosine, clipped to [−1, 1]; NaN stays NaN."""
    return math.acos(max(-1.0, min(1.0, cosine))) if cosine == cosine else cosine


@nb.njit(**_OPTS)
def _limits_range(poses, base, platform, offset, gains, stroke, base_axis, platform_axis, pairs, enabled, limit,
                  out, start, stop):
    """out[k] (columns stroke, U tilt, S tilt, leg collision, singularity:
    ``hexapod.LIMIT_NAMES``) for rows k in [start, stop): the stroke, tilt
    and collision margins by the formulas of ``Hexapod._limit_margins_numpy`` and, when
    ``enabled[4]``, the singularity certificate (:func:`singularity_certificate`) of the
    length-scaled twist Jacobian; ``limit`` = (U-tilt limit, S-tilt limit, leg diameter,
    singularity margin, platform radius, safety margin mm, safety margin rad). Disabled
    columns are NaN. Leg i is the segment b_i → b_i + l_i; pair (i, j) has r = b_i − b_j."""
    R = np.empty((3, 3))
    legs = np.empty((6, 3))
    sq = np.empty(6)
    u = np.empty((6, 3))
    Jt = np.empty((6, 6))
    C = np.empty((6, 6))
    L = np.empty((6, 6))
    n_pairs = pairs.shape[0]
    r = np.empty((n_pairs, 3))
    for q in range(n_pairs):
        for c in range(3):
            r[q, c] = base[pairs[q, 0], c] - base[pairs[q, 1], c]
    for k in range(start, stop):
        _euler_matrix(poses[k, 3], poses[k, 4], poses[k, 5], R)
        worst = np.inf
        for i in range(6):
            s = 0.0
            for q in range(3):
                ra = R[q, 0] * platform[i, 0] + R[q, 1] * platform[i, 1] + R[q, 2] * platform[i, 2]
                Jt[i, 3 + q] = ra
                legs[i, q] = poses[k, q] + ra - base[i, q]
                s += legs[i, q] * legs[i, q]
            sq[i] = s
            length = math.sqrt(s)
            for q in range(3):
                u[i, q] = legs[i, q] / length
            lam = (length - offset[i]) / gains[i]  # the reading, in the stroke's unit
            m = min(lam - stroke[i, 0], stroke[i, 1] - lam) * gains[i]  # mm of leg length
            if not m >= worst:  # NaN propagates
                worst = m
        out[k, 0] = worst - limit[5]
        for c in range(1, 5):
            out[k, c] = np.nan
        # the largest tilt is acos of the smallest cosine (acos decreases): one acos per joint kind
        if enabled[1]:
            worst = np.inf
            for i in range(6):
                d = u[i, 0] * base_axis[i, 0] + u[i, 1] * base_axis[i, 1] + u[i, 2] * base_axis[i, 2]
                if not d >= worst:  # NaN propagates
                    worst = d
            out[k, 1] = limit[0] - limit[6] - _tilt(worst)
        if enabled[2]:
            worst = np.inf
            for i in range(6):
                d = 0.0
                for q in range(3):
                    d += u[i, q] * (R[q, 0] * platform_axis[i, 0] + R[q, 1] * platform_axis[i, 1]
                                    + R[q, 2] * platform_axis[i, 2])
                if not d >= worst:
                    worst = d
            out[k, 2] = limit[1] - limit[6] - _tilt(worst)
        if enabled[3]:
            worst = np.inf
            for q in range(n_pairs):
                i, j = pairs[q, 0], pairs[q, 1]
                d = _segment_distance_sq(r[q, 0], r[q, 1], r[q, 2], legs[i, 0], legs[i, 1], legs[i, 2],
                                         legs[j, 0], legs[j, 1], legs[j, 2], sq[i], sq[j])
                if not d >= worst:
                    worst = d
            out[k, 3] = math.sqrt(worst) - limit[2] - limit[5]
        if enabled[4]:
            # twist Jacobian row i = [u_iᵀ, ((R a_i) × u_i)ᵀ / r]  (r = platform radius)
            for i in range(6):
                ra0, ra1, ra2 = Jt[i, 3], Jt[i, 4], Jt[i, 5]
                Jt[i, 0], Jt[i, 1], Jt[i, 2] = u[i, 0], u[i, 1], u[i, 2]
                Jt[i, 3] = (ra1 * u[i, 2] - ra2 * u[i, 1]) / limit[4]
                Jt[i, 4] = (ra2 * u[i, 0] - ra0 * u[i, 2]) / limit[4]
                Jt[i, 5] = (ra0 * u[i, 1] - ra1 * u[i, 0]) / limit[4]
            out[k, 4] = singularity_certificate(Jt, limit[3], C, L)


def limit_margins(poses, base, platform, offset, gains, stroke, base_axis, platform_axis, pairs, enabled, limit):
    """(N, 5) array, columns ``hexapod.LIMIT_NAMES``, for poses (N, 6) [mm, rad]: margins of
    the stroke, tilt and collision limits and the singularity certificate (+1 / −1 / NaN
    undecided), see :func:`_limits_range`; ``pairs`` (P, 2) the leg pairs checked for
    collision, ``enabled`` (5,) which columns to compute. Batches of 2 × ``_LIMIT_GRAIN``
    poses or more are split over threads."""
    poses = _f64(poses)
    out = np.empty((poses.shape[0], 5))
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    enabled = np.ascontiguousarray(enabled, dtype=np.bool_).copy()
    args = (poses, _f64(base), _f64(platform), _f64(offset), _f64(gains), _f64(stroke), _f64(base_axis),
            _f64(platform_axis), pairs, enabled, _f64(limit), out)
    _run_rows(_limits_range, poses.shape[0], _LIMIT_GRAIN, args)
    return out

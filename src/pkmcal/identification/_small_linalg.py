"""Dense linear algebra of the engine: stacks of tiny matrices (compiled), and the R factor.

The engine works on N poses of k ≤ ~9 residual rows each. NumPy's batched ``linalg``
calls LAPACK once per matrix, ~1 µs of overhead for a 3×3 or 6×6 system: on the 2-core
reference machine (2026-11-22, best of 300) ``np.linalg.solve`` of 100 6×6 systems with 3
right-hand sides took 103 µs and the Cholesky factor plus its inverse of 100 3×3
covariances 110 µs; these loops do the same in a few µs. They run once or twice per
Jacobian (the FK residual's H A⁻¹) and twice per fit (the whitening).

* :func:`solve_right`: X_j = H_j A_j⁻¹ by LU with partial pivoting of A_jᵀ.
* :func:`cholesky_inverse`: W_j = L_j⁻¹ with L_j L_jᵀ = Σ_j (Cholesky–Banachiewicz, then
  forward substitution), so that W_j r_j has unit covariance.
* :func:`qr_triangle`: R of A = QR straight from LAPACK ``dgeqrf`` (``numpy.linalg.qr``'s
  wrapping adds ~25 µs to the 40 µs of a 90 × 42 factorisation).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_OPTS = dict(cache=True, nogil=True, error_model="numpy")


@nb.njit(**_OPTS)
def _solve_right(A, H, out, ok):
    N, n, _ = A.shape
    m = H.shape[1]
    M = np.empty((n, n))
    z = np.empty(n)
    perm = np.empty(n, dtype=np.int64)
    for k in range(N):
        # LU (partial pivoting) of Aᵀ: rows of Aᵀ are the columns of A
        scale = 0.0
        for r in range(n):
            for c in range(n):
                M[r, c] = A[k, c, r]
                scale = max(scale, abs(M[r, c]))
            perm[r] = r
        good = scale > 0.0
        for col in range(n):
            if not good:
                break
            piv, best = col, abs(M[col, col])
            for r in range(col + 1, n):
                if abs(M[r, col]) > best:
                    piv, best = r, abs(M[r, col])
            if not best > 1e-14 * scale:
                good = False
                break
            if piv != col:
                for c in range(n):
                    M[col, c], M[piv, c] = M[piv, c], M[col, c]
                perm[col], perm[piv] = perm[piv], perm[col]
            for r in range(col + 1, n):
                f = M[r, col] / M[col, col]
                M[r, col] = f
                for c in range(col + 1, n):
                    M[r, c] -= f * M[col, c]
        ok[k] = good
        if not good:
            for i in range(m):
                for c in range(n):
                    out[k, i, c] = np.nan
            continue
        # x_i = h_i A⁻¹  ⇔  Aᵀ x_iᵀ = h_iᵀ
        for i in range(m):
            for r in range(n):
                z[r] = H[k, i, perm[r]]
            for r in range(n):
                s = z[r]
                for c in range(r):
                    s -= M[r, c] * z[c]
                z[r] = s
            for r in range(n - 1, -1, -1):
                s = z[r]
                for c in range(r + 1, n):
                    s -= M[r, c] * z[c]
                z[r] = s / M[r, r]
            for c in range(n):
                out[k, i, c] = z[c]


def solve_right(A: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(X, ok)``: X_j = H_j A_j⁻¹ for A (N, n, n), H (N, m, n); ``ok`` (N,) False (and X_j
    NaN) where A_j is singular to 1e-14 relative."""
    A = np.ascontiguousarray(A, dtype=np.float64)
    H = np.ascontiguousarray(H, dtype=np.float64)
    if A.ndim != 3 or H.ndim != 3 or A.shape[1] != A.shape[2] or A.shape[::2] != H.shape[::2]:
        # the kernel indexes without bounds checks: a mismatch would write past its arrays
        raise ValueError(f"solve_right needs A (N, n, n) and H (N, m, n); got {A.shape} and {H.shape}")
    out = np.empty(H.shape)
    ok = np.empty(A.shape[0], dtype=np.bool_)
    _solve_right(A, H, out, ok)
    return out, ok


@nb.njit(**_OPTS)
def _cholesky_inverse(C, W):
    N, n, _ = C.shape
    L = np.empty((n, n))
    for k in range(N):
        for i in range(n):
            for j in range(n):
                W[k, i, j] = 0.0
        for i in range(n):
            for j in range(i + 1):
                s = C[k, i, j]
                for q in range(j):
                    s -= L[i, q] * L[j, q]
                if i == j:
                    if not s > 0.0:  # also NaN
                        return k
                    L[i, i] = math.sqrt(s)
                else:
                    L[i, j] = s / L[j, j]
        # W = L⁻¹ (lower triangular), column by column: L w_c = e_c
        for c in range(n):
            for i in range(c, n):
                s = 1.0 if i == c else 0.0
                for q in range(c, i):
                    s -= L[i, q] * W[k, q, c]
                W[k, i, c] = s / L[i, i]
    return -1


def cholesky_inverse(C: np.ndarray) -> tuple[np.ndarray, int]:
    """``(W, bad)``: W_j = L_j⁻¹, L_j L_jᵀ = C_j for C (N, n, n) symmetric; ``bad`` the first
    j whose C_j is not positive definite (W then incomplete), else −1."""
    C = np.ascontiguousarray(C, dtype=np.float64)
    if C.ndim != 3 or C.shape[1] != C.shape[2]:
        raise ValueError(f"cholesky_inverse needs C (N, n, n); got {C.shape}")   # unchecked kernel indexing
    W = np.empty(C.shape)
    bad = int(_cholesky_inverse(C, W))
    return W, bad


def qr_triangle(A: np.ndarray) -> np.ndarray:
    """The upper triangle R (n, n) of A = QR for A (m, n), m ≥ n (signs as LAPACK leaves them)."""
    from scipy.linalg.lapack import dgeqrf  # on first use: scipy.linalg takes ~0.4 s to import

    qr, _, _, info = dgeqrf(np.asarray(A, dtype=np.float64))
    if info != 0:
        raise ValueError(f"dgeqrf failed (info={info})")
    return np.triu(qr[: A.shape[1]])

"""Pose selection on per-pose Jacobian blocks G (N, m, n) (paper 2 §4; paper 1 §IV).

Every algorithm picks ``n`` of the N candidate poses; it sees only the blocks G_j (each
candidate's whitened, column-scaled identification Jacobian rows, restricted to the
identifiable parameters), so it is independent of the machine and sensor. The
information matrix of a set is M = Σ_j G_jᵀ G_j.

* ``default`` — D-optimal (max log det M, ⇔ O1 at fixed size; for another index, then
  polished by the add/remove exchange on it): greedy forward selection on M₀ = δI, then
  DETMAX exchanges (add the best candidate, remove the least useful
  pose, stop when the removed one is the one just added). Adding/removing pose k is a
  rank-m update; with S_j = G_j M⁻¹ G_jᵀ,

      det(M ± G_kᵀG_k) = det M · det(I ± S_k)                 (determinant lemma)
      M⁻¹ ← M⁻¹ ∓ U (I ± S_k)⁻¹ Uᵀ,   U = M⁻¹ G_kᵀ               (Woodbury)

  and S_j ← S_j ∓ A_j (I ± S_k)⁻¹ A_jᵀ with A_j = G_j U for all candidates in one
  compiled pass (:mod:`._selection_kernels`), each step scores all candidates at once in
  O(N m² n) (no per-candidate Python loop).
* ``detmax`` — paper 2 §4 steps (i)–(iv) with an exact add step on any index O1–O5
  (pruned by an eigenvalue bound, :meth:`_IndexScorer.best_add`):
  (i) random initial set; (ii) add the candidate maximising the index of the enlarged set;
  (iii) remove the pose whose removal leaves the best index; (iv) repeat until the removed
  pose is the one just added.
* ``cuckoo`` — the same add/remove framework with the add step done by cuckoo search with
  Lévy flights (Yang & Deb 2009; paper 2 Fig. 4, n = 25 nests, p_a = 0.25) over the
  candidates' normalised pose coordinates, each cuckoo snapped to its nearest candidate.
* ``random`` — n distinct candidates drawn uniformly.
* ``corners`` (paper 1 §IV) is ``random`` applied to the 2^6 workspace-box corners; the
  corners are built in :mod:`pkmcal.planning.candidates`.
* ``circle`` — a ballbar circle test (ISO 230-4): every candidate, in order; the caller
  makes the candidates the circle's poses (:meth:`~pkmcal.sensors.distance.DistanceSensor.circle_frames`).

``select`` and the ``select_*`` functions run with BLAS limited to one thread
(:func:`~pkmcal.identification.residuals.single_threaded_blas`).

All are seeded through a ``numpy.random.Generator`` and reproducible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.planning.indices import (
    as_blocks,
    blas_single_threaded,
    check_index_name,
    index_from_eigenvalues,
    information_matrix,
    observability_indices,
)

ALGORITHMS = ("default", "detmax", "cuckoo", "corners", "random", "circle")
#: Which index each algorithm maximises (documented in docs/planning.md and ``--help``).
OPTIMISED_INDEX = {"default": "O1 (or --index, after the D-optimal start)", "detmax": "any (default O4)",
                   "cuckoo": "any (default O4)", "corners": "none", "random": "none", "circle": "none"}
Progress = Callable[[int, int], None]
#: Greedy start of the default algorithm: M₀ = δI with δ = _DELTA_REL · mean per-pose
#: information per parameter.
_DELTA_REL = 1e-9


def _kernels():
    """The compiled exchange kernels (:mod:`._selection_kernels`), imported on first use
    (numba takes ~0.5 s to import)."""
    from pkmcal.planning import _selection_kernels

    return _selection_kernels


@dataclass(frozen=True)
class Selection:
    """Result of a selection: ``chosen`` candidate indices (n,), the ``algorithm`` and the
    ``criterion`` it maximised, O1..O5 of the chosen set (``indices``), and counters."""

    chosen: np.ndarray
    algorithm: str
    criterion: str
    indices: dict[str, float]
    iterations: int = 0
    evaluations: int = 0
    message: str = ""
    extra: dict = field(default_factory=dict)


def _check(G, n: int) -> tuple[np.ndarray, int, int, int]:
    G = np.ascontiguousarray(as_blocks(G))
    N, m, p = G.shape
    if n < 1 or n > N:
        raise PkmcalError(f"cannot select {n} poses from {N} candidates; ask for 1..{N} poses or give more candidates")
    return G, N, m, p


def _need_rank(n: int, m: int, p: int) -> None:
    if n * m < p:
        raise PkmcalError(
            f"{n} poses give {n * m} readings, fewer than the {p} identifiable parameters; "
            f"ask for at least {math.ceil(p / m)} poses"
        )


def _batch_logdet(S: np.ndarray, sign: float, identity: bool = True) -> np.ndarray:
    """log det(I + sign·S_j) (or log det(sign·S_j) without the identity) for S (K, m, m);
    −inf where not positive definite."""
    m = S.shape[-1]
    A = sign * S + np.eye(m) if identity else sign * S
    s, ld = np.linalg.slogdet(A)
    return np.where(s > 0, ld, -np.inf)


#: Candidates per GEMM of the passes over all of them (:func:`_all_S`, :func:`_all_gains`,
#: :func:`_leverages`):
#: bounds their temporaries (G L⁻ᵀ of a slice: 10 MB at 42 parameters) whatever N.
_PASS_ROWS = 5_000


def _inverse_factor(M: np.ndarray) -> np.ndarray:
    """L⁻¹ with M = L Lᵀ (Cholesky); a clear error when M is singular."""
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        raise PkmcalError("the candidate poses do not identify every parameter (singular information matrix); "
                          "use more poses or more varied candidates") from None
    return np.linalg.inv(L)


def _whitened(flatF: np.ndarray, m: int, Linv: np.ndarray, start: int, stop: int) -> np.ndarray:
    """G_j L⁻ᵀ (stop − start, m, p) of the candidates [start, stop): one GEMM."""
    return (flatF[start * m:stop * m] @ Linv.T).reshape(stop - start, m, -1)


def _over_slices(fn: Callable[[int, int], None], N: int) -> None:
    """``fn(start, stop)`` over the candidates in slices of :data:`_PASS_ROWS`, on local
    threads (:func:`~pkmcal.parallel.thread_map`); each slice writes its own rows.
    The slices depend only on N, and each is computed alone, so the bits do not depend on
    the threads (tested in ``tests/planning/test_executors.py``)."""
    from pkmcal.parallel import thread_map

    for _ in thread_map(lambda start: fn(start, min(N, start + _PASS_ROWS)), range(0, N, _PASS_ROWS)):
        pass


def _all_S(flatF: np.ndarray, N: int, m: int, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """M⁻¹ and S_j = G_j M⁻¹ G_jᵀ (N, m, m) for all candidates."""
    Linv = _inverse_factor(M)
    S = np.empty((N, m, m))

    def fill(start, stop):
        W = _whitened(flatF, m, Linv, start, stop)
        S[start:stop] = np.einsum("nip,njp->nij", W, W, optimize=True)

    _over_slices(fill, N)
    return Linv.T @ Linv, S


def _all_gains(flatF: np.ndarray, N: int, m: int, M: np.ndarray) -> np.ndarray:
    """log det(I + S_j) (N,) for all candidates (−∞ where not positive definite), slice by
    slice: W = G L⁻ᵀ of a slice by one GEMM, then S_j = W_j W_jᵀ and its log-determinant in
    one compiled pass (:func:`~pkmcal.planning._selection_kernels.gains_of_whitened`), without
    holding S of all N. The values of :func:`_all_S` then ``gains_of``, to the rounding of
    the dot products."""
    Linv = _inverse_factor(M)
    gain = np.empty(N)

    def fill(start, stop):
        _kernels().gains_of_whitened(_whitened(flatF, m, Linv, start, stop), gain[start:stop])

    _over_slices(fill, N)
    return gain


def _leverages(flatF: np.ndarray, N: int, M: np.ndarray) -> np.ndarray:
    """tr(G_j M⁻¹ G_jᵀ) = ‖G_j L⁻ᵀ‖²_F (N,) for all candidates."""
    m = flatF.shape[0] // max(N, 1)
    Linv = _inverse_factor(M)
    out = np.empty(N)

    def fill(start, stop):
        W = _whitened(flatF, m, Linv, start, stop)
        out[start:stop] = np.einsum("nij,nij->ni", W, W).sum(axis=1)

    _over_slices(fill, N)
    return out


#: Candidates per thread below which a rank-m update runs on the calling thread only (the
#: update took 0.74 µs per candidate on an 11,000-candidate working set; handing chunks to
#: the pool costs ~50 µs, see :mod:`pkmcal.mechanisms._hexapod_kernels`).
_UPDATE_GRAIN = 2_000


class _DState:
    """M, M⁻¹ and S_j = G_j M⁻¹ G_jᵀ of all candidates, kept by rank-m updates (Woodbury)."""

    def __init__(self, G: np.ndarray, M: np.ndarray, flatF: np.ndarray | None = None):
        self.G = G
        self.N, self.m, self.p = G.shape
        self.flatF = G.reshape(self.N * self.m, self.p) if flatF is None else flatF   # a view (G is C-ordered)
        self.M = np.array(M, dtype=float)
        self.updates = 0
        self.refresh()

    def refresh(self) -> None:
        """Exact M⁻¹, S and gains from M (bounds the drift of the updates)."""
        self.Minv, self.S = _all_S(self.flatF, self.N, self.m, self.M)
        self.S = np.ascontiguousarray(self.S)
        self.gain = np.empty(self.N)
        _kernels().gains_of(self.S, self.gain)

    def update(self, k: int, sign: float) -> None:
        """M ← M ± G_kᵀG_k: M⁻¹ ∓= U C⁻¹ Uᵀ and S_j ∓= (G_j U) C⁻¹ (G_j U)ᵀ for all j, with
        U = M⁻¹G_kᵀ and C = I ± S_k, and the gains (compiled loop, :mod:`._selection_kernels`).

        With C = Q diag(μ) Qᵀ (symmetric eigendecomposition) and v_c = U q_c / √|μ_c|, both
        updates are sums of m rank-one terms: ∓ Σ_c sgn(μ_c) v_c v_cᵀ and
        ∓ Σ_c sgn(μ_c) (G_j v_c)(G_j v_c)ᵀ, so a candidate costs G_j V and its outer products."""
        Gk = self.G[k]
        U = self.Minv @ Gk.T
        mu, Q = np.linalg.eigh(np.eye(self.m) + sign * self.S[k])
        V = (U @ Q) / np.sqrt(np.abs(mu))
        coef = sign * np.sign(mu)
        self.Minv -= (V * coef) @ V.T
        from pkmcal.parallel import run_rows

        VT, update = np.ascontiguousarray(V.T), _kernels().update_and_gain
        run_rows(lambda start, stop: update(self.G, VT, coef, self.S, self.gain, start, stop), self.N, _UPDATE_GRAIN)
        self.M += sign * (Gk.T @ Gk)
        self.updates += 1
        if self.updates % 50 == 0:
            self.refresh()

    def gains(self) -> np.ndarray:
        """log det(M + G_jᵀG_j) − log det M for every candidate (N,) (a copy; NaN → −∞)."""
        return np.where(np.isnan(self.gain), -np.inf, self.gain)


#: The DETMAX exchange runs over all N candidates up to max(_WORK_MIN, 5 × pool) of them;
#: above, on a working set (:func:`_detmax_exchange`) of 5 × pool candidates, or fewer when
#: their blocks would hold more than _WORK_NUMBERS numbers (m·n per candidate), but never
#: fewer than the pool. Every exchange step reads the working set twice; at 110 of 100,000
#: full-pose candidates (m·n = 252) the updates of the 11,000 of 5 × pool took 0.31 s of the
#: selection's 1.0-1.4 s, those of the 2,976 of the budget 0.17 s (line profiles, 36 and 37
#: exchanges; see :func:`_work_size` for what it does to the designs).
_WORK_MIN = 10_000
_WORK_NUMBERS = 750_000


def _work_size(N: int, pool: int, m: int, p: int) -> int:
    """The exchange's working-set size (N: over all candidates; constants above).

    The budget changes which DETMAX optimum is reached (a local search: another working set
    is another path), not the stopping rule. Measured on 6 seeds of 100,000 full-pose
    candidates (110 poses): log det M of the design −0.008 on average against the 11,000-
    candidate working set (range −0.049 … +0.018; the seeds' own spread is ±0.05), the
    selection 0.97 s against 1.41 s."""
    if N <= max(_WORK_MIN, 5 * pool):
        return N
    return max(pool, min(5 * pool, _WORK_NUMBERS // (m * p)))


def _detmax_exchange(G: np.ndarray, flatF: np.ndarray, chosen: list[int], max_ex: int, work_size: int,
                     progress: Callable[[int], None] | None) -> tuple[list[int], int, int]:
    """DETMAX exchanges of the set ``chosen`` over all N candidates of G: add the candidate
    of largest gain, remove the pose of least loss; stop when that is the one just added or
    nothing improves. Returns (chosen, exchanges, candidates evaluated).

    Each exchange is two rank-m updates of the candidates' S_j, which reads all of G
    (N·m·p numbers: 200 MB at 100,000 full-pose candidates of 42 parameters). So the
    updates run on a *working set*: the ``work_size`` candidates of largest gain at the
    current design (and the chosen ones), from the exact S_j of all N (one GEMM). When the
    exchange stops on the working set, the exact gains of all N are recomputed at the final
    design: if the best candidate is in the working set, the working set's stop is the
    stop over all N (the same add step, so the same decision); otherwise the exchange goes
    on from a new working set around it. The result is therefore a DETMAX optimum over all
    N candidates with the same stopping rule; with N ≤ ``work_size`` the path is that of
    exchanging over all N directly."""
    N, m, _ = G.shape
    in_set = np.zeros(N, dtype=bool)
    in_set[chosen] = True
    M = information_matrix(G, np.array(chosen))
    exchanges = evaluations = 0
    last_work = None
    while exchanges < max_ex:
        if N <= work_size:
            work = np.arange(N)
        else:
            gain_all = _all_gains(flatF, N, m, M)
            gain_all = np.where(np.isnan(gain_all) | in_set, -np.inf, gain_all)
            evaluations += N
            best = int(np.argmax(gain_all))
            if last_work is not None and last_work[best]:
                break          # the working set's stop is the stop over all N
            work = np.union1d(np.argpartition(-gain_all, work_size - 1)[:work_size], np.flatnonzero(in_set))
        last_work = np.zeros(N, dtype=bool)
        last_work[work] = True
        state = _DState(np.ascontiguousarray(G[work]), M)
        w_in = in_set[work]
        stopped = False
        while exchanges < max_ex:
            gain = state.gains()
            evaluations += len(work)
            gain[w_in] = -np.inf
            k = int(np.argmax(gain))
            if not np.isfinite(gain[k]):
                stopped = True
                break
            state.update(k, 1.0)
            cand = np.append(np.searchsorted(work, chosen), k)     # work is sorted
            loss = _batch_logdet(state.S[cand], -1.0)
            r = int(np.argmax(loss))
            if cand[r] == k or gain[k] + loss[r] <= 1e-10:
                state.update(k, -1.0)
                stopped = True
                break
            state.update(int(cand[r]), -1.0)
            k_all, r_all = int(work[k]), int(work[cand[r]])
            w_in[k], w_in[cand[r]] = True, False
            in_set[k_all], in_set[r_all] = True, False
            chosen[chosen.index(r_all)] = k_all
            exchanges += 1
            if progress is not None:
                progress(exchanges)
        M, state = state.M, None       # the working set's copy of G freed before the next one
        if N <= work_size or not stopped:
            break
    return chosen, exchanges, evaluations


@blas_single_threaded
def select_default(G: np.ndarray, n: int, *, index: str = "O1", pool: int | None = None,
                   max_exchanges: int | None = None, progress: Progress | None = None) -> Selection:
    """D-optimal selection (max log det M ⇔ O1 at fixed size); deterministic.

    1. Pool: when N > ``pool`` (default max(2000, 20n)), the ``pool`` candidates of largest
       leverage tr(G_j M_all⁻¹ G_jᵀ) (M_all: all candidates) — D-optimal designs sit on
       high-leverage points; the exchange below still sees every candidate.
    2. Greedy forward selection in the pool on M₀ = δI (δ = 1e-9 · mean per-pose
       information per parameter): add argmax_j log det(I + S_j), S_j = G_j M⁻¹ G_jᵀ.
       For the first ⌊n/m⌋ picks this is taken in its δ → 0 limit, argmax_j
       log det(R_j R_jᵀ) with R_j = G_j projected off the span of the chosen rows (a
       block pivoted QR, no 1/δ round-off); then all candidates are updated by one rank-m
       update per step (module docstring), recomputing S exactly while a direction is
       still held only by δ.
    3. DETMAX exchange on the exact M of the chosen set over *all* N candidates: add the
       candidate of largest gain, remove the pose of least loss log det(I − S_i); stop
       when that is the one just added (paper 2 §4 iv) or nothing improves. Above
       max(10,000, 5·pool) candidates the updates run on a working set of the largest
       gains (:func:`_work_size`), re-checked against all N when it stops
       (:func:`_detmax_exchange`).
    4. For ``index`` O2..O5: paper 2's add/remove exchange on that index started from the
       D-optimal set, the add step scoring exactly the (at most 256) candidates of largest
       eigenvalue bound (:meth:`_IndexScorer.best_add`).
    """
    G, N, m, p = _check(G, n)
    _need_rank(n, m, p)
    flatF = G.reshape(N * m, p)   # a view: a Fortran copy costs more than the GEMMs it would feed
    K = max(2000, 20 * n) if pool is None else max(int(pool), n)
    evaluations = 0
    if K < N:
        lev = _leverages(flatF, N, information_matrix(G))
        pool_idx = np.sort(np.argpartition(-lev, K - 1)[:K])
        evaluations += N
    else:
        pool_idx = np.arange(N)
    Gp = np.ascontiguousarray(G[pool_idx])
    delta = _DELTA_REL * float(np.einsum("nip,nip->", Gp, Gp)) / (len(Gp) * p) + np.finfo(float).tiny
    in_pool = np.zeros(len(Gp), dtype=bool)
    max_ex = 4 * n if max_exchanges is None else max_exchanges
    total = n + max_ex
    # 2a. while every pick can add m new directions: the δ → 0 limit of the greedy step,
    #     argmax_j log det(R_j R_jᵀ) with R_j = G_j projected off the chosen rows' span
    #     (log det(I + G_j M⁻¹ G_jᵀ) = m log(1/δ) + log det(R_j R_jᵀ) + O(δ)); exact, no 1/δ.
    R = Gp.copy()
    n_span = min(n, p // m)
    for step in range(n_span):
        gain = _batch_logdet(R @ R.transpose(0, 2, 1), 1.0, identity=False)
        gain[in_pool] = -np.inf
        k = int(np.argmax(gain))
        q, _ = np.linalg.qr(R[k].T)                             # new orthonormal directions (p, m)
        R -= ((R.reshape(-1, p) @ q) @ q.T).reshape(R.shape)
        in_pool[k] = True
        evaluations += len(Gp)
        if progress is not None:
            progress(step + 1, total)
    # 2b. the rest of the greedy phase by rank-m updates of all candidates
    state = _DState(Gp, delta * np.eye(p) + information_matrix(Gp, np.flatnonzero(in_pool)))
    for step in range(n_span, n):
        gain = state.gains()
        gain[in_pool] = -np.inf
        k = int(np.argmax(gain))
        state.update(k, 1.0)
        if (step + 1) * m <= p + m:
            # while δ still dominates a direction S_j ~ 1/δ and the update cancels digits:
            # recompute exactly until the chosen rows span the parameter space
            state.refresh()
        in_pool[k] = True
        evaluations += len(Gp)
        if progress is not None:
            progress(step + 1, total)
    chosen = [int(i) for i in pool_idx[np.flatnonzero(in_pool)]]
    chosen, exchanges, n_eval = _detmax_exchange(G, flatF, chosen, max_ex, _work_size(N, K, m, p),
                                                 None if progress is None else (lambda i: progress(n + i, total)))
    evaluations += n_eval
    out = np.array(sorted(chosen))
    message = f"greedy D-optimal start ({len(Gp)} pool) + {exchanges} DETMAX exchanges"
    index = check_index_name(index)
    if index != "O1":
        polish = select_detmax(G, n, index=index, initial=out, max_exact=256, progress=progress)
        return Selection(polish.chosen, "default", index, polish.indices, iterations=exchanges + polish.iterations,
                         evaluations=evaluations + polish.evaluations,
                         message=f"{message}, then {polish.iterations} add/remove iterations on {index}")
    return Selection(out, "default", "O1", observability_indices(G, out), iterations=exchanges,
                     evaluations=evaluations, message=message)


# -- generic index: exhaustive and cuckoo add steps ------------------------------------


class _IndexScorer:
    """Index of M + G_jᵀG_j (or M − G_jᵀG_j) for batches of candidates, by eigenvalues."""

    def __init__(self, G: np.ndarray, index: str, chunk: int = 512):
        self.G = G
        self.index = check_index_name(index)
        self.chunk = chunk
        self.evaluations = 0

    def score(self, M: np.ndarray, idx: np.ndarray, sign: float, n_rows: int) -> np.ndarray:
        """(index, tie-break) arrays for the sets M + sign·G_jᵀG_j, j in ``idx``.

        The tie-break is log det(M' + δI): it ranks rank-deficient sets (index 0)."""
        idx = np.asarray(idx, dtype=int)
        val = np.empty(len(idx))
        tie = np.empty(len(idx))
        p = M.shape[0]
        delta = 1e-9 * max(np.trace(M), 1e-300) / p
        for s in range(0, len(idx), self.chunk):
            Gs = self.G[idx[s:s + self.chunk]]
            Ms = M[None] + sign * np.einsum("kip,kiq->kpq", Gs, Gs)
            ev = np.linalg.eigvalsh(Ms)
            val[s:s + len(Gs)] = index_from_eigenvalues(self.index, ev, n_rows)
            tie[s:s + len(Gs)] = np.sum(np.log(np.maximum(ev, 0.0) + delta), axis=1)
        self.evaluations += len(idx)
        return val, tie

    def best_add(self, M: np.ndarray, free: np.ndarray, n_rows: int, batch: int = 64,
                 max_exact: int | None = None) -> int:
        """The candidate of ``free`` maximising the index of M + G_jᵀG_j, exactly, scoring
        few candidates: with V_k the k = m + 2 smallest eigenvectors of M (eigenvalues Λ_k),
        Courant–Fischer gives μ_j = λ_min(Λ_k + (G_j V_k)ᵀ(G_j V_k)) ≥ λ_min(M + G_jᵀG_j),
        and λ_max(M + G_jᵀG_j) ≥ λ_max(M), so

            O2 ≤ √(μ_j/λ_max),   O3 ≤ √μ_j,   O4 ≤ μ_j/√λ_max;

        candidates are scored exactly in order of that bound until the best exact value
        reaches the next bound (or ``max_exact`` were scored: then the result is the best
        of the most promising). O1 and O5 (and a singular M) are scored exhaustively."""
        free = np.asarray(free, dtype=int)
        ev, V = np.linalg.eigh(M)
        lmin, lmax = ev[0], ev[-1]
        if self.index in ("O1", "O5") or not (lmax > 0 and lmin > 1e-12 * lmax):
            val, tie = self.score(M, free, 1.0, n_rows)
            return int(free[_best(val, tie)])
        k = min(M.shape[0], self.G.shape[1] + 2)
        P = np.einsum("nip,pk->nik", self.G[free], V[:, :k])          # G_j V_k
        top = np.linalg.eigvalsh(np.diag(ev[:k])[None] + np.einsum("nik,nil->nkl", P, P))[:, 0]
        ub = {"O2": np.sqrt(top / lmax), "O3": np.sqrt(top), "O4": top / np.sqrt(lmax)}[self.index]
        order = np.argsort(-ub, kind="stable")
        best_val, best_j = -np.inf, -1
        for s in range(0, len(order), batch):
            cand = order[s:s + batch]
            val, _ = self.score(M, free[cand], 1.0, n_rows)
            b = int(np.argmax(val))
            if val[b] > best_val:
                best_val, best_j = float(val[b]), int(free[cand[b]])
            if s + batch >= len(order) or best_val >= ub[order[s + batch]]:
                break
            if max_exact is not None and s + batch >= max_exact:
                break
        return best_j


def _best(val: np.ndarray, tie: np.ndarray) -> int:
    """Position of the largest ``val``, ties (e.g. all zero) broken by ``tie``."""
    return int(np.lexsort((tie, val))[-1])


def _add_remove(G, n, index, rng, add_step, initial, max_iter, progress, name) -> Selection:
    """Paper 2 §4 steps (i)–(iv) with a pluggable add step ``add_step(M, in_set, n_rows)``."""
    G, N, m, p = _check(G, n)
    _need_rank(n, m, p)
    scorer = _IndexScorer(G, index)
    if initial is None:
        chosen = [int(i) for i in rng.choice(N, size=n, replace=False)]        # step (i)
    else:
        chosen = [int(i) for i in np.asarray(initial, dtype=int)]
        if len(chosen) != n or len(set(chosen)) != n:
            raise PkmcalError(f"the initial set must hold {n} distinct candidate indices")
    in_set = np.zeros(N, dtype=bool)
    in_set[chosen] = True
    M = information_matrix(G, np.array(chosen))
    it = 0
    for it in range(1, max_iter + 1):
        k = add_step(M, in_set, (n + 1) * m, scorer)                          # step (ii)
        if k is None:
            break
        M_plus = M + G[k].T @ G[k]
        cand = np.array(chosen + [k])
        val, tie = scorer.score(M_plus, cand, -1.0, n * m)                     # step (iii)
        r = _best(val, tie)
        if cand[r] == k:                                                       # step (iv)
            break
        M = M_plus - G[cand[r]].T @ G[cand[r]]
        in_set[k] = True
        in_set[cand[r]] = False
        chosen[chosen.index(int(cand[r]))] = k
        if progress is not None:
            progress(it, max_iter)
    out = np.array(sorted(chosen))
    return Selection(out, name, scorer.index, observability_indices(G, out), iterations=it,
                     evaluations=scorer.evaluations, message=f"{it} add/remove iterations")


@blas_single_threaded
def select_detmax(G: np.ndarray, n: int, *, index: str = "O4", rng: np.random.Generator | None = None,
                  initial: np.ndarray | None = None, max_iter: int | None = None, max_exact: int | None = None,
                  progress: Progress | None = None) -> Selection:
    """Paper 2 §4 add/remove exchange with an exact add step on index O1..O5 (steps i–iv)."""
    rng = np.random.default_rng() if rng is None else rng
    G = as_blocks(G)

    def add_step(M, in_set, n_rows, scorer):
        free = np.flatnonzero(~in_set)
        if len(free) == 0:
            return None
        return scorer.best_add(M, free, n_rows, max_exact=max_exact)

    return _add_remove(G, n, index, rng, add_step, initial, max_iter or 10 * n, progress, "detmax")


def levy_steps(rng: np.random.Generator, shape, beta: float = 1.5) -> np.ndarray:
    """Lévy-stable steps by Mantegna's algorithm: u / |v|^(1/β), u ~ N(0, σ_u²), v ~ N(0, 1),
    σ_u = [Γ(1+β) sin(πβ/2) / (Γ((1+β)/2) β 2^((β−1)/2))]^(1/β) (Yang & Deb 2009)."""
    sigma = (math.gamma(1 + beta) * math.sin(math.pi * beta / 2)
             / (math.gamma((1 + beta) / 2) * beta * 2 ** ((beta - 1) / 2))) ** (1 / beta)
    u = rng.standard_normal(shape) * sigma
    v = rng.standard_normal(shape)
    return u / np.abs(v) ** (1 / beta)


@blas_single_threaded
def select_cuckoo(G: np.ndarray, n: int, *, positions: np.ndarray, index: str = "O4",
                  rng: np.random.Generator | None = None, n_nests: int = 25, pa: float = 0.25,
                  generations: int = 20, alpha: float = 0.05, initial: np.ndarray | None = None,
                  max_iter: int | None = None, progress: Progress | None = None) -> Selection:
    """Paper 2 §4: add/remove framework whose add step is a cuckoo search (Fig. 4).

    Nests are candidates; a cuckoo from nest x_i flies to x_i + α·Lévy(1.5) in the
    candidates' pose coordinates normalised to [0, 1] (``positions`` (N, d)) and lands on
    the nearest candidate not yet in the set; it replaces a random nest if fitter; each
    generation the fraction ``pa`` of worst nests is abandoned for random candidates.
    Fitness (eq. 9) = index of the set with the candidate added.
    """
    rng = np.random.default_rng() if rng is None else rng
    G = as_blocks(G)
    X = np.asarray(positions, dtype=float)
    if X.ndim != 2 or X.shape[0] != G.shape[0]:
        raise PkmcalError(f"cuckoo search needs one position per candidate; got {X.shape} for {G.shape[0]} candidates")
    lo, hi = X.min(axis=0), X.max(axis=0)
    Xn = (X - lo) / np.where(hi > lo, hi - lo, 1.0)
    from scipy.spatial import cKDTree  # on first use: scipy.spatial takes ~0.4 s to import

    tree = cKDTree(Xn)
    n_abandon = max(1, int(round(pa * n_nests)))
    k_near = min(len(Xn), n + 8)

    def snap(points, in_set):
        _, nb = tree.query(points, k=k_near)
        nb = np.atleast_2d(nb)
        ok = ~in_set[nb]
        first = np.argmax(ok, axis=1)
        got = nb[np.arange(len(nb)), first]
        return np.where(ok.any(axis=1), got, -1)

    def add_step(M, in_set, n_rows, scorer):
        free = np.flatnonzero(~in_set)
        if len(free) == 0:
            return None
        nests = rng.choice(free, size=min(n_nests, len(free)), replace=False)
        fit, tie = scorer.score(M, nests, 1.0, n_rows)
        for _ in range(generations):
            new = snap(Xn[nests] + alpha * levy_steps(rng, (len(nests), Xn.shape[1])), in_set)
            valid = new >= 0
            if valid.any():
                f_new, t_new = scorer.score(M, new[valid], 1.0, n_rows)
                tgt = rng.integers(0, len(nests), size=int(valid.sum()))
                for c, f, t, j in zip(new[valid], f_new, t_new, tgt):
                    if (f, t) > (fit[j], tie[j]):
                        nests[j], fit[j], tie[j] = c, f, t
            worst = np.lexsort((tie, fit))[:n_abandon]
            fresh = rng.choice(free, size=len(worst), replace=len(free) < len(worst))
            keep_best = _best(fit, tie)
            worst = worst[worst != keep_best]
            fresh = fresh[: len(worst)]
            nests[worst] = fresh
            fit[worst], tie[worst] = scorer.score(M, fresh, 1.0, n_rows)
        return int(nests[_best(fit, tie)])

    return _add_remove(G, n, index, rng, add_step, initial, max_iter or 10 * n, progress, "cuckoo")


def select_random(n_candidates: int, n: int, rng: np.random.Generator | None = None) -> np.ndarray:
    """``n`` distinct candidate indices drawn uniformly (sorted)."""
    rng = np.random.default_rng() if rng is None else rng
    if n < 1 or n > n_candidates:
        raise PkmcalError(f"cannot select {n} poses from {n_candidates} candidates; ask for 1..{n_candidates} poses")
    return np.sort(rng.choice(n_candidates, size=n, replace=False))


def select(G: np.ndarray, n: int, *, algorithm: str = "default", index: str | None = None,
           rng: np.random.Generator | None = None, positions: np.ndarray | None = None,
           progress: Progress | None = None) -> Selection:
    """Dispatch to one algorithm of :data:`ALGORITHMS` (``corners``: random choice among
    the given candidates, which the caller makes the box corners)."""
    algorithm = str(algorithm).lower()
    rng = np.random.default_rng() if rng is None else rng
    G = as_blocks(G)
    if algorithm == "default":
        return select_default(G, n, index=index or "O1", progress=progress)
    if algorithm == "detmax":
        return select_detmax(G, n, index=index or "O4", rng=rng, progress=progress)
    if algorithm == "cuckoo":
        if positions is None:
            raise PkmcalError("cuckoo search needs the candidates' pose coordinates")
        return select_cuckoo(G, n, positions=positions, index=index or "O4", rng=rng, progress=progress)
    if algorithm == "circle":
        if n != G.shape[0]:
            raise PkmcalError(f"a circle test measures all its {G.shape[0]} poses, not {n} of them")
        chosen = np.arange(n)
        return Selection(chosen, algorithm, "none", observability_indices(G, chosen),
                         message="every pose of the ballbar circle test, in order")
    if algorithm in ("random", "corners"):
        chosen = select_random(G.shape[0], n, rng)
        return Selection(chosen, algorithm, "none", observability_indices(G, chosen))
    raise PkmcalError(f"unknown selection algorithm '{algorithm}'; use one of {', '.join(ALGORITHMS)}")

"""Observability indices of an identification Jacobian (paper 2 §4, Tables 1–2).

The identification Jacobian of a pose set is the stack J (m_tot × n) of per-pose blocks
G_j (m × n): the whitened (noise-weighted), column-scaled rows of the linearised residual
with respect to the *identifiable* parameters. With σ_1 ≥ … ≥ σ_n its singular values and
m_tot its number of rows:

    O1 = (σ_1 ⋯ σ_n)^(1/n) / √m_tot      Borm & Menq; D-optimality (det M = Π σ_i²)
    O2 = σ_n / σ_1                        inverse condition number
    O3 = σ_n                              minimum singular value (E-optimality)
    O4 = σ_n² / σ_1                       Nahvi & Hollerbach noise amplification index
    O5 = 1 / Σ 1/σ_i²  = 1 / tr(M⁻¹)      A-optimality

with M = JᵀJ = Σ_j G_jᵀ G_j the information matrix. All are 0 for a rank-deficient J.
Scaling laws (tested): duplicating every row multiplies σ by √2, so O1 and O2 are
unchanged, O3 grows by √2, O4 by √2 and O5 by 2.

Which algorithm optimises which (:mod:`pkmcal.planning.selection`): the default exchange
maximises log det M (D-optimality ⇔ O1 at fixed size; given another index it then polishes
the set on that index); ``detmax`` and ``cuckoo`` maximise any of O1–O5 (default O4, as
paper 2); ``random`` and ``corners`` optimise nothing.
"""

from __future__ import annotations

import functools

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.residuals import single_threaded_blas

INDEX_NAMES = ("O1", "O2", "O3", "O4", "O5")
INDEX_DESCRIPTIONS = {
    "O1": "(σ1⋯σn)^(1/n)/√m, D-optimality (Borm–Menq)",
    "O2": "σmin/σmax, inverse condition number",
    "O3": "σmin, E-optimality",
    "O4": "σmin²/σmax, noise amplification (Nahvi–Hollerbach)",
    "O5": "1/Σ(1/σi²), A-optimality",
}
#: Relative singular-value threshold below which J counts as rank-deficient.
RANK_RTOL = 1e-10


def blas_single_threaded(func):
    """Decorator: run ``func`` with one BLAS thread
    (:func:`pkmcal.identification.residuals.single_threaded_blas`). Planning multiplies many
    small matrices, where a threaded BLAS only adds synchronisation. Planning runs on
    NumPy alone: scipy is not imported for it."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with single_threaded_blas(scipy=False):
            return func(*args, **kwargs)
    return wrapper


def check_index_name(name: str) -> str:
    """``name`` upper-cased if it is one of O1..O5; a clear error otherwise."""
    key = str(name).upper()
    if key not in INDEX_NAMES:
        raise PkmcalError(f"unknown observability index '{name}'; use one of {', '.join(INDEX_NAMES)}")
    return key


def as_blocks(G: np.ndarray) -> np.ndarray:
    """``G`` as a float array (N, m, n) of per-pose Jacobian blocks."""
    G = np.asarray(G, dtype=float)
    if G.ndim == 2:
        G = G[:, None, :]
    if G.ndim != 3:
        raise PkmcalError(f"per-pose Jacobian blocks must have shape (N, m, n); got {G.shape}")
    return G


def information_matrix(G: np.ndarray, subset: np.ndarray | None = None) -> np.ndarray:
    """M = Σ_j G_jᵀ G_j over the poses ``subset`` (indices; all when None), shape (n, n)."""
    G = as_blocks(G)
    if subset is not None:
        G = G[np.asarray(subset, dtype=int)]
    flat = G.reshape(-1, G.shape[2])
    return flat.T @ flat


def singular_values(G: np.ndarray, subset: np.ndarray | None = None) -> np.ndarray:
    """Singular values (descending) of the stacked Jacobian of ``subset`` (SVD, accurate
    down to σ_min ≈ 1e-16 σ_max)."""
    G = as_blocks(G)
    if subset is not None:
        G = G[np.asarray(subset, dtype=int)]
    J = G.reshape(-1, G.shape[2])
    s = np.linalg.svd(J, compute_uv=False)
    if len(s) < J.shape[1]:
        s = np.concatenate([s, np.zeros(J.shape[1] - len(s))])
    return s


def indices_from_singular_values(s: np.ndarray, n_rows: int) -> dict[str, float]:
    """O1..O5 (module docstring) from singular values ``s`` (n,) of a Jacobian with
    ``n_rows`` rows. All indices are 0 when σ_min ≤ RANK_RTOL·σ_max."""
    s = np.sort(np.asarray(s, dtype=float))[::-1]
    smax, smin = float(s[0]) if len(s) else 0.0, float(s[-1]) if len(s) else 0.0
    if smax <= 0.0 or smin <= RANK_RTOL * smax:
        return {k: 0.0 for k in INDEX_NAMES}
    return {
        "O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(n_rows)),
        "O2": smin / smax,
        "O3": smin,
        "O4": smin**2 / smax,
        "O5": float(1.0 / np.sum(1.0 / s**2)),
    }


@blas_single_threaded
def observability_indices(G: np.ndarray, subset: np.ndarray | None = None) -> dict[str, float]:
    """O1..O5 of the poses ``subset`` of the blocks ``G`` (N, m, n) (module docstring)."""
    G = as_blocks(G)
    k = G.shape[0] if subset is None else len(np.asarray(subset))
    return indices_from_singular_values(singular_values(G, subset), k * G.shape[1])


def index_from_eigenvalues(name: str, ev: np.ndarray, n_rows: int | np.ndarray) -> np.ndarray:
    """Index ``name`` of a batch of information matrices given their eigenvalues ``ev``
    (K, n) (any order), σ_i = √λ_i; 0 where rank-deficient. Shape (K,).

    Used by the search loops, which score many candidate sets ``M + G_jᵀ G_j`` at once.
    """
    name = check_index_name(name)
    ev = np.sort(np.asarray(ev, dtype=float), axis=-1)
    lmin, lmax = ev[..., 0], ev[..., -1]
    ok = (lmax > 0.0) & (lmin > (RANK_RTOL**2) * lmax)
    with np.errstate(divide="ignore", invalid="ignore"):
        lsafe = np.where(ok[..., None], ev, 1.0)
        if name == "O1":
            val = np.exp(0.5 * np.mean(np.log(lsafe), axis=-1)) / np.sqrt(n_rows)
        elif name == "O2":
            val = np.sqrt(lsafe[..., 0] / lsafe[..., -1])
        elif name == "O3":
            val = np.sqrt(lsafe[..., 0])
        elif name == "O4":
            val = lsafe[..., 0] / np.sqrt(lsafe[..., -1])
        else:
            val = 1.0 / np.sum(1.0 / lsafe, axis=-1)
    return np.where(ok, val, 0.0)


def log_det_information(G: np.ndarray, subset: np.ndarray | None = None) -> float:
    """log det M of the poses ``subset`` (−inf when singular): the D-criterion."""
    sign, logdet = np.linalg.slogdet(information_matrix(G, subset))
    return float(logdet) if sign > 0 else -np.inf


# -- singularity of a pose (paper 2 §2.1: Merlet's detector) ---------------------------------


def singularity_measures(mechanism, poses: np.ndarray, length: float | None = None) -> dict[str, np.ndarray]:
    """Two measures of how close each pose is to a singularity of the hexapod, per pose (N,).

    J⁻¹ is the inverse kinematic Jacobian, ∂λ/∂(δp, δω) (rows [u_iᵀ, ((R a_i) × u_i)ᵀ],
    :meth:`~pkmcal.mechanisms.hexapod.Hexapod.twist_jacobian`), with its rotation columns
    divided by ``length`` L (default the machine's ``length_scale``: the platform joint
    radius) so that both blocks are
    dimensionless. Then

    * ``det`` = |det J⁻¹_L| = |det J⁻¹| / L³ = Π σ_i: Merlet's criterion (paper 2 §2.1, ref.
      [16]: "evaluating the absolute value of |J⁻¹| against a certain threshold"); 0 at a
      singularity; it also shrinks when every σ_i shrinks together;
    * ``inverse_condition`` = σ_min / σ_max of J⁻¹_L: the criterion of the machine's
      ``singularity`` limit (``HexapodLimits.singularity_margin``); 0 at a singularity,
      insensitive to an overall scale.

    Both depend on L (the unit in which a rotation is compared with a translation); they
    vanish together at a singularity and rank poses differently elsewhere.
    """
    poses = mechanism.as_pose_array(poses)
    L = float(mechanism.length_scale) if length is None else float(length)
    if not (L > 0 and np.isfinite(L)):
        raise PkmcalError(f"the length that scales the rotation columns must be a positive number of mm; got {length}")
    J = mechanism.twist_jacobian(poses)
    J[:, :, 3:] /= L
    with single_threaded_blas(scipy=False):
        s = np.linalg.svd(J, compute_uv=False)
        det = np.abs(np.linalg.det(J))
    return {"det": det, "inverse_condition": s[:, -1] / s[:, 0]}

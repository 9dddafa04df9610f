"""Uncertainty of identified parameters: covariance, standard deviations, correlations.

With the residuals whitened (r̃_j = W_j r_j, W_j = Σ_j^{-1/2}, Σ_j the covariance the sensor
and actuator noise induce on pose j's residual) and J̃ the whitened Jacobian of the free
parameters at the solution, the Gauss–Markov / Cramér–Rao covariance is

    C_prior = (J̃ᵀ J̃)⁻¹ = (Σ_j J_jᵀ Σ_j⁻¹ J_j)⁻¹                              (noise model as given)
    C_post  = χ²_ν · C_prior,   χ²_ν = ‖r̃‖² / (M − p)                       (a-posteriori)

For an unweighted fit (J raw), the estimate is θ̂ = argmin ‖r‖², whose covariance under
the same noise is the sandwich C_prior = (JᵀJ)⁻¹ (Σ_j J_jᵀ Σ_j J_j) (JᵀJ)⁻¹, and
C_post = s² (JᵀJ)⁻¹ with s² = ‖r‖²/(M − p).

The calibrated machine file carries ``C_file = max(1, χ²_ν) · C_prior`` (the Birge-ratio
rule): the instruments' stated noise, inflated when the fit shows more scatter than the
noise model explains (unmodelled errors such as joint backlash), never deflated by a lucky
small residual. (JᵀJ)⁻¹ comes from a QR factorisation of the column-scaled Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np



@dataclass(frozen=True)
class Uncertainty:
    """Covariances of the free parameters ``names`` (internal units: mm, rad)."""

    names: tuple[str, ...]
    covariance_prior: np.ndarray
    covariance_posterior: np.ndarray
    chi2: float
    dof: int

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def covariance(self) -> np.ndarray:
        """The covariance written to the calibrated machine file: max(1, χ²_ν)·C_prior."""
        f = self.reduced_chi2
        return self.covariance_prior * (max(1.0, f) if np.isfinite(f) else 1.0)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def std_prior(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance_prior), 0.0, None))

    @property
    def std_posterior(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance_posterior), 0.0, None))

    @property
    def correlation(self) -> np.ndarray:
        return correlation(self.covariance_prior)


def correlation(cov: np.ndarray) -> np.ndarray:
    """Correlation matrix of a covariance (zero rows/columns stay zero, diagonal 1)."""
    sd = standard_deviations(cov)
    inv = np.where(sd > 0, 1.0 / np.where(sd > 0, sd, 1.0), 0.0)
    C = cov * inv[:, None] * inv[None, :]     # in this order: no overflow for tiny σ
    C = 0.5 * (C + C.T)                       # exactly symmetric
    np.fill_diagonal(C, np.where(sd > 0, 1.0, 0.0))
    return C


def _inverse_normal(J: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ = D R⁻¹R⁻ᵀ D from the QR factorisation J D = Q R of the column-scaled
    Jacobian (D = diag(1/‖J_:,i‖)); J has full column rank (checked by the engine).

    Backward stable like the SVD (the error grows with cond(J D), not its square) at a
    fifth of the cost for the engine's sizes; a wide J (fewer rows than columns, JᵀJ
    singular) falls back to V S⁻² Vᵀ from the SVD.
    """
    M, p = J.shape
    if M < p:
        _, s, Vt = np.linalg.svd(J, full_matrices=False)
        return (Vt.T / s**2) @ Vt
    from scipy.linalg.lapack import dtrtri

    from pkmcal.identification._small_linalg import qr_triangle  # compiled: numba on first use

    col = np.linalg.norm(J, axis=0)
    d = 1.0 / np.where(col > 0, col, 1.0)
    R = qr_triangle(J * d)
    Ri, info = dtrtri(R, lower=0)                              # R⁻¹ (LAPACK triangular inverse)
    if info != 0:                                              # exactly singular: as the SVD would
        _, s, Vt = np.linalg.svd(J, full_matrices=False)
        return (Vt.T / s**2) @ Vt
    return (d[:, None] * Ri) @ (Ri.T * d)


def parameter_uncertainty(
    names: tuple[str, ...],
    J: np.ndarray,
    r: np.ndarray,
    *,
    weighted: bool,
    W: np.ndarray | None = None,
    cov_rows: np.ndarray | None = None,
) -> Uncertainty:
    """Covariances of the parameters from the per-pose Jacobian ``J`` (N, k, p) and
    residuals ``r`` (N, k) of the fit (module docstring).

    Weighted fits pass the whitened ``J`` and ``r``. Unweighted fits pass the raw ones and
    the per-pose noise covariance ``cov_rows`` (N, k, k) (for the sandwich) and its
    whitening ``W`` (N, k, k) (for χ²); without them only C_post is meaningful.
    """
    N, k, p = J.shape
    M = N * k
    dof = M - p
    Jf = J.reshape(M, p)
    inv = _inverse_normal(Jf)
    if weighted:
        chi2 = float(np.sum(r**2))
        prior = inv
        post = inv * (chi2 / dof if dof > 0 else np.nan)
    else:
        s2 = float(np.sum(r**2)) / dof if dof > 0 else np.nan
        post = inv * s2
        if cov_rows is not None:
            meat = np.einsum("nki,nkl,nlj->ij", J, cov_rows, J)
            prior = inv @ meat @ inv
        else:
            prior = np.full((p, p), np.nan)
        chi2 = float(np.sum((W @ r[..., None]) ** 2)) if W is not None else float("nan")
    prior = 0.5 * (prior + prior.T)
    post = 0.5 * (post + post.T)
    return Uncertainty(names=tuple(names), covariance_prior=prior, covariance_posterior=post, chi2=chi2, dof=dof)


def embed(cov_free: np.ndarray, free_index: np.ndarray, n_total: int) -> np.ndarray:
    """The (n_total, n_total) covariance with ``cov_free`` at ``free_index``, zeros elsewhere
    (fixed parameters are exact by definition of the gauge)."""
    C = np.zeros((n_total, n_total))
    idx = np.asarray(free_index, dtype=int)
    C[np.ix_(idx, idx)] = cov_free
    return C


def standard_deviations(cov: np.ndarray) -> np.ndarray:
    """σ_i = √max(Σ_ii, 0): the standard deviations of a covariance Σ (round-off below zero → 0)."""
    return np.sqrt(np.clip(np.diag(np.asarray(cov, dtype=float)), 0.0, None))

"""Uncertainty of identified parameters: covariance, standard deviations, correlations.

With the residuals whitened (r̃_j = W_j r_j, W_j = Σ_j^{-1/2}, Σ_j the covariance the sensor
and actuator noise induce on pose j's residual) and J̃ the whitened Jacobian of the free
parameters at the solution, the Gauss–Markov / Cramér–Rao covariance of the noise-weighted
(GLS) fit is

    C_prior = F⁻¹ = (J̃ᵀ J̃)⁻¹ = (Σ_j J_jᵀ Σ_j⁻¹ J_j)⁻¹                         (noise model as given)
    C_post  = χ²_ν · C_prior,   χ²_ν = ‖r̃‖² / (M − p)                       (a-posteriori)

For an unweighted fit (J raw), the estimate is θ̂ = argmin ‖r‖², whose covariance under
the same noise is the **sandwich**

    C_prior = (JᵀJ)⁻¹ (Σ_j J_jᵀ Σ_j J_j) (JᵀJ)⁻¹ ⪰ F⁻¹                          (Gauss–Markov)

and C_post = s² (JᵀJ)⁻¹ with s² = ‖r‖²/(M − p) (the textbook formula, which assumes equal
noise on every row).

Model check (the Birge ratio). χ² = ‖W r̂‖² at the solution; under the noise model its
expectation is

    E[χ²] = M − p                                     (GLS)
    E[χ²] = ‖W (I − P) L‖_F² = M − 2p + tr(F · C_prior)   (unweighted, P = J(JᵀJ)⁻¹Jᵀ, LLᵀ = Σ)

(tr(W P L) = tr((JᵀJ)⁻¹JᵀLWJ) = p since L_j W_j = I). An unweighted fit leaves more
whitened residual than a GLS fit (tr(F C_prior) ≥ p, with equality only when the two fits
coincide), so dividing its χ² by M − p over-states the scatter: on paper 1's full-pose
set-up χ²/(M − p) ≈ 2.9 with a correct noise model. The **Birge ratio** is
B = χ² / E[χ²], 1 on average when the noise model is right, for both kinds of fit.

The calibrated machine file carries ``C_file = max(1, B) · C_prior``: the instruments'
stated noise (the GLS covariance, or the sandwich for an unweighted fit), inflated when
the fit shows more scatter than the noise model explains (unmodelled errors such as joint
backlash), never deflated by a lucky small residual. :attr:`Uncertainty.description` says
which covariance a number is. (JᵀJ)⁻¹ comes from a QR factorisation of the column-scaled
Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.covariance import correlation, standard_deviations  # noqa: F401  (below io/: pkmcal.covariance)

#: :attr:`Uncertainty.kind` → what ``covariance_prior`` is.
KINDS = {
    "gls": "a-priori (noise model) covariance of the noise-weighted fit",
    "sandwich": "sandwich covariance of the unweighted fit under the noise model",
    "map": "posterior covariance (J^T W J + P)^-1 of the maximum-a-posteriori fit (noise model and Gaussian priors)",
    "robust": "noise-model covariance of the robust fit, A^-1 B A^-1 on the inlier poses (pkmcal.identification.robust)",
}


@dataclass(frozen=True)
class Uncertainty:
    """Covariances of the free parameters ``names`` (internal units: mm, rad).

    ``kind`` says what ``covariance_prior`` is (:data:`KINDS`): ``"gls"`` for a
    noise-weighted fit, ``"sandwich"`` for an unweighted one, ``"map"`` with Gaussian priors
    (:mod:`.priors`), ``"robust"`` with a robust loss (:mod:`.robust`); ``chi2_expected`` is
    E[χ²] under the noise model (module docstring; NaN when the noise model is unknown);
    ``note`` details the kind (loss, priors) in :attr:`description`."""

    names: tuple[str, ...]
    covariance_prior: np.ndarray
    covariance_posterior: np.ndarray
    chi2: float
    dof: int
    kind: str = "gls"
    chi2_expected: float = float("nan")
    note: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown covariance kind {self.kind!r}; one of {', '.join(KINDS)}")
        if self.kind != "sandwich" and not np.isfinite(self.chi2_expected) and self.dof > 0:
            object.__setattr__(self, "chi2_expected", float(self.dof))

    @property
    def reduced_chi2(self) -> float:
        """χ²/(M − p); for an unweighted fit this is not 1 on average (use :attr:`birge_ratio`)."""
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def birge_ratio(self) -> float:
        """B = χ² / E[χ²]: 1 on average when the noise model is right (module docstring);
        equal to :attr:`reduced_chi2` for a noise-weighted fit."""
        e = self.chi2_expected
        return self.chi2 / e if np.isfinite(e) and e > 0 else float("nan")

    @property
    def inflation(self) -> float:
        """max(1, B), the factor applied to ``covariance_prior`` in :attr:`covariance` (1
        when B is undefined)."""
        b = self.birge_ratio
        return max(1.0, b) if np.isfinite(b) else 1.0

    @property
    def covariance(self) -> np.ndarray:
        """The covariance written to the calibrated machine file: max(1, B)·C_prior."""
        return self.covariance_prior * self.inflation

    @property
    def description(self) -> str:
        """Which covariance :attr:`covariance` (and :attr:`std`) is, in one line."""
        e = self.chi2_expected
        why = (f" (= dof {self.dof})" if self.kind != "sandwich" else
               f" (dof {self.dof}: an unweighted fit leaves more whitened residual)") if np.isfinite(e) else ""
        note = f" [{self.note}]" if self.note else ""
        return (f"{KINDS[self.kind]}{note} x max(1, chi2/E[chi2]) = x {self.inflation:.4g}; chi2 {self.chi2:.6g}, "
                f"E[chi2] {e:.6g}{why}")

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
    measured: np.ndarray | None = None,
) -> Uncertainty:
    """Covariances of the parameters from the per-pose Jacobian ``J`` (N, k, p) and
    residuals ``r`` (N, k) of the fit (module docstring).

    Weighted fits pass the whitened ``J`` and ``r`` (``kind="gls"``). Unweighted fits pass
    the raw ones and the per-pose noise covariance ``cov_rows`` (N, k, k) (for the sandwich
    and E[χ²]) and its whitening ``W`` (N, k, k) (for χ²), ``kind="sandwich"``; without
    them only C_post is meaningful (C_prior NaN).

    ``measured`` (N, k): the residual entries that are measurements (None: all). An entry
    that is not (a reading its row does not take: residual 0, Jacobian row 0, and after
    whitening still alone in its row) adds nothing to χ² and no degree of freedom, so the
    M of dof = M − p and of E[χ²] counts the measured entries only.
    """
    N, k, p = J.shape
    rows = N * k
    M = rows if measured is None else int(np.count_nonzero(measured))
    dof = M - p
    Jf = J.reshape(rows, p)
    inv = _inverse_normal(Jf)
    if weighted:
        chi2 = float(np.sum(r**2))
        prior = inv
        post = inv * (chi2 / dof if dof > 0 else np.nan)
    else:
        s2 = float(np.sum(r**2)) / dof if dof > 0 else np.nan
        post = inv * s2
        expected = float("nan")
        if cov_rows is not None:
            meat = Jf.T @ (cov_rows @ J).reshape(rows, p)         # Σ_j J_jᵀ Σ_j J_j
            prior = inv @ meat @ inv
            prior = 0.5 * (prior + prior.T)
            if W is not None:
                Jw = (W @ J).reshape(rows, p)
                expected = float(M - 2 * p + np.sum((Jw.T @ Jw) * prior))   # M − 2p + tr(F C)
        else:
            prior = np.full((p, p), np.nan)
        chi2 = float(np.sum((W @ r[..., None]) ** 2)) if W is not None else float("nan")
        post = 0.5 * (post + post.T)
        return Uncertainty(names=tuple(names), covariance_prior=prior, covariance_posterior=post, chi2=chi2,
                           dof=dof, kind="sandwich", chi2_expected=expected)
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

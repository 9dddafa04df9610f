"""Standard deviations and correlations of a covariance matrix Σ: σ_i = √max(Σ_ii, 0) and
ρ_ij = Σ_ij / (σ_i σ_j), with zero rows for parameters held (σ 0).

Below every layer that needs them: the engine's uncertainty (:mod:`pkmcal.identification.uncertainty`,
which gives them under its names), the machine file's covariance and correlation
(:mod:`pkmcal.io.machine_file`) and the report.
"""

from __future__ import annotations

import numpy as np


def standard_deviations(cov: np.ndarray) -> np.ndarray:
    """σ_i = √max(Σ_ii, 0): the standard deviations of a covariance Σ (round-off below zero → 0)."""
    return np.sqrt(np.clip(np.diag(np.asarray(cov, dtype=float)), 0.0, None))


def correlation(cov: np.ndarray) -> np.ndarray:
    """Correlation matrix of a covariance (zero rows/columns stay zero, diagonal 1)."""
    sd = standard_deviations(cov)
    inv = np.where(sd > 0, 1.0 / np.where(sd > 0, sd, 1.0), 0.0)
    C = cov * inv[:, None] * inv[None, :]     # in this order: no overflow for tiny σ
    C = 0.5 * (C + C.T)                       # exactly symmetric
    np.fill_diagonal(C, np.where(sd > 0, 1.0, 0.0))
    return C


__all__ = ["correlation", "standard_deviations"]

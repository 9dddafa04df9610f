"""Robust identification: normalised residuals, outlier screening, robust losses, rejection.

**Normalised residuals.** Every fit whitens its residuals with the noise model, z_j = W_j r_j
(W_j = L_j⁻¹, L_j L_jᵀ = Σ_j, :mod:`.engine`); z_ji is row i of pose j in units of its noise
σ, and per pose

    s_j = √(‖z_j‖² / k)                                  (k rows per pose)

is 1 on average when the pose is as noisy as the noise model says. A pose with s_j > K is an
outlier at K σ (default :data:`OUTLIER_SIGMA`; under the noise model k·s_j² ~ χ²_k, so a clean
pose exceeds 3 σ with probability P(χ²_k > 9k): 3e-3 for k = 1, 1e-6 for k = 3, 2e-10
for k = 6). Pose numbers are data rows of the measurement file, counted from 1.

**Robust losses** (``loss="soft_l1" | "huber" | "cauchy"``): the loss of
:func:`scipy.optimize.least_squares`, ½ Σ_i f² ρ(z_i²/f²) over the whitened rows z_i with
``f_scale`` f in σ units (the whitened rows have unit σ), instead of ½ Σ z_i²:

    soft_l1  ρ(u) = 2(√(1 + u) − 1)      huber  ρ(u) = u (u ≤ 1), 2√u − 1     cauchy  ρ(u) = ln(1 + u)

applied to the data rows only (prior rows, :mod:`.priors`, stay quadratic). The influence of
a row is ψ(z) = ρ'(z²/f²)·z: bounded by f for huber and soft_l1, redescending for cauchy. The
default f (:data:`DEFAULT_F_SCALE`) gives 95 % asymptotic efficiency at Gaussian noise:
huber 1.345 and cauchy 2.385 (the textbook constants), soft_l1 the value found the same way.

**Covariance of a robust fit** (the M-estimator's, Huber 1967): at the solution, the poses
within K σ are the inliers, the flagged poses are counted as carrying no information, and
under the Gaussian noise model

    A = a·J̃_inᵀJ̃_in + P,   B = b·J̃_inᵀJ̃_in + P,   C = A⁻¹ B A⁻¹,
    a = E[ψ'(e)],  b = E[ψ(e)²],  e ~ N(0, 1)                       (sandwich on the inliers)

(P the prior precision, zero without priors; without priors C = (b/a²)·(J̃_inᵀJ̃_in)⁻¹, the
loss's efficiency loss a²/b times the Gauss–Newton covariance of the inlier set). χ² is
Σ ‖z_j‖² over the inliers (plus the prior rows), dof = M_in (+ K) − p.

**Rejection** (``reject=K``): fit, drop the poses beyond K σ that are at least half as far
out as the worst one (a gross outlier drags the fit and inflates its neighbours' residuals;
they are judged again once it is gone), refit, until no pose is beyond K σ. Each rejected
pose records the round it was dropped in. More than :data:`MAX_REJECTED_FRACTION` of the
poses rejected is an error: the noise model or the machine model is then wrong, not a few
poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from pkmcal.errors import PkmcalError

#: The losses (``linear``: plain least squares).
LOSSES = ("linear", "soft_l1", "huber", "cauchy")
#: Default threshold of the outlier screening, in σ of the per-pose normalised residual s_j.
OUTLIER_SIGMA = 3.0
#: f_scale (σ units) of 95 % asymptotic efficiency at Gaussian noise (module docstring;
#: tests/identification/test_robust.py checks these against :func:`efficiency`).
DEFAULT_F_SCALE = {"huber": 1.345, "cauchy": 2.385, "soft_l1": 1.287}
#: Rejection stops with an error beyond this fraction of the poses.
MAX_REJECTED_FRACTION = 0.2


def rho(loss: str, u: np.ndarray) -> np.ndarray:
    """(3, m): ρ(u), ρ'(u), ρ''(u) of a scipy loss at u = z²/f² (module docstring)."""
    u = np.asarray(u, dtype=float)
    out = np.empty((3, u.size))
    if loss == "linear":
        out[0], out[1], out[2] = u, 1.0, 0.0
    elif loss == "soft_l1":
        t = 1.0 + u
        out[0], out[1], out[2] = 2.0 * (np.sqrt(t) - 1.0), t**-0.5, -0.5 * t**-1.5
    elif loss == "huber":
        big = u > 1.0
        s = np.sqrt(np.where(big, u, 1.0))
        out[0] = np.where(big, 2.0 * s - 1.0, u)
        out[1] = np.where(big, 1.0 / s, 1.0)
        out[2] = np.where(big, -0.5 / (s * np.where(big, u, 1.0)), 0.0)
    elif loss == "cauchy":
        t = 1.0 + u
        out[0], out[1], out[2] = np.log1p(u), 1.0 / t, -1.0 / t**2
    else:
        raise PkmcalError(f"unknown loss '{loss}'; use one of {', '.join(LOSSES)}")
    return out


#: Largest f_scale accepted (σ): scipy squares it, and beyond a few σ a loss is least squares.
MAX_F_SCALE = 1e3


def check_loss(loss: str, f_scale: float | None) -> float:
    """The f_scale (σ units) of ``loss``: given, else :data:`DEFAULT_F_SCALE` (1 for linear)."""
    if loss not in LOSSES:
        raise PkmcalError(f"unknown loss '{loss}'; use one of {', '.join(LOSSES)}")
    if f_scale is None:
        return DEFAULT_F_SCALE.get(loss, 1.0)
    if not (np.isfinite(f_scale) and f_scale > 0):
        raise PkmcalError(f"f_scale must be a positive number of sigmas; got {f_scale:g}")
    if f_scale > MAX_F_SCALE:
        raise PkmcalError(f"f_scale {f_scale:g} sigma: a loss that turns from quadratic beyond {MAX_F_SCALE:g} noise "
                          "sigmas is least squares on every real residual; give a few sigmas (the default is "
                          f"{DEFAULT_F_SCALE.get(loss, 1.0):g}), or use the linear loss")
    return float(f_scale)


def masked_loss(loss: str, n_data: int):
    """A callable loss for :func:`scipy.optimize.least_squares`: ``loss`` on the first
    ``n_data`` residuals, quadratic on the rest (the prior rows)."""
    def f(u):
        out = np.empty((3, u.size))
        out[:, :n_data] = rho(loss, u[:n_data])
        out[:, n_data:] = rho("linear", u[n_data:])
        return out
    return f


@lru_cache(maxsize=32)
def efficiency(loss: str, f_scale: float) -> tuple[float, float]:
    """(a, b) = (E[ψ'(e)], E[ψ(e)²]) for e ~ N(0, 1) (module docstring), by adaptive
    quadrature (split at the kink z = f of huber); a²/b is the asymptotic efficiency."""
    if loss == "linear":
        return 1.0, 1.0
    from scipy.integrate import quad

    f = float(f_scale)

    def psi(z):
        r = rho(loss, np.array([(z / f) ** 2]))
        return float(r[1, 0] * z)

    def dpsi(z):
        u = (z / f) ** 2
        r = rho(loss, np.array([u]))
        return float(r[1, 0] + 2.0 * u * r[2, 0])

    phi = lambda z: np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi)  # noqa: E731
    # the Gaussian weight is below 1e-300 beyond |z| = 38: integrate [0, 38], split at the kink
    edges = sorted({0.0, min(f, _Z_MAX), _Z_MAX})

    def integral(g):
        return 2.0 * sum(quad(lambda z: g(z) * phi(z), lo, hi, epsabs=1e-14, epsrel=1e-12, limit=200)[0]
                         for lo, hi in zip(edges[:-1], edges[1:]))

    return integral(dpsi), integral(lambda z: psi(z) ** 2)


#: Upper limit of the efficiency integrals (module docstring of :func:`efficiency`).
_Z_MAX = 38.0


# -- screening ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Outlier:
    """A pose beyond the threshold: ``pose`` its number (data row of the file, 1-based),
    ``sigma`` its s_j, ``reading`` the row with the largest |z_ji| and ``reading_sigma`` that
    z_ji (signed), ``dropped`` whether it was left out (``reject``), ``round`` the fit round
    that flagged (and dropped) it, ``where`` the file and line when known."""

    pose: int
    sigma: float
    reading: str
    reading_sigma: float
    dropped: bool
    round: int
    where: str = ""

    def to_dict(self) -> dict:
        return {"pose": self.pose, "sigma": self.sigma, "reading": self.reading, "reading_sigma": self.reading_sigma,
                "dropped": self.dropped, "round": self.round}

    def text(self) -> str:
        return (f"pose {self.pose} ({self.sigma:.3g} sigma; worst row {self.reading} {self.reading_sigma:+.3g} sigma"
                f"{', dropped in round ' + str(self.round) if self.dropped else ''}){self.where}")


@dataclass(frozen=True)
class Screening:
    """Per-pose normalised residuals of a fit and the outliers (module docstring).

    ``pose_numbers`` (N,) the file rows (1-based) of the poses in the fit, ``sigma`` (N,)
    their s_j, ``z`` (N, k) the whitened residual rows, ``row_names`` (k,), ``threshold`` K;
    ``outliers`` the poses beyond K in the final fit plus those rejected before it; ``loss``
    and ``f_scale`` of the fit; ``rounds`` the number of fits (1 without rejection);
    ``reject`` K of the rejection (None: no rejection)."""

    pose_numbers: np.ndarray
    sigma: np.ndarray
    z: np.ndarray
    row_names: tuple[str, ...]
    threshold: float
    outliers: tuple[Outlier, ...] = ()
    loss: str = "linear"
    f_scale: float = 1.0
    rounds: int = 1
    reject: float | None = None
    n_inliers: int = field(default=-1)

    @property
    def inliers(self) -> np.ndarray:
        """Boolean (N,): the poses of the fit within the threshold."""
        return self.sigma <= self.threshold

    @property
    def flagged(self) -> tuple[Outlier, ...]:
        return tuple(o for o in self.outliers if not o.dropped)

    @property
    def rejected(self) -> tuple[Outlier, ...]:
        return tuple(o for o in self.outliers if o.dropped)

    def to_dict(self) -> dict:
        return {"threshold_sigma": self.threshold, "loss": self.loss,
                "f_scale_sigma": None if self.loss == "linear" else self.f_scale,
                "reject_sigma": self.reject, "rounds": self.rounds,
                "pose": [int(p) for p in self.pose_numbers], "sigma": [float(s) for s in self.sigma],
                "rows": list(self.row_names), "row_sigma": [[float(v) for v in row] for row in self.z]}

    def warnings(self) -> list[str]:
        out = []
        if self.rejected:
            out.append(f"rejected {len(self.rejected)} pose(s) beyond {self.reject:g} sigma in {self.rounds - 1} "
                       "round(s), each refit without them: " + "; ".join(o.text() for o in self.rejected))
        if self.flagged:
            kept = ("down-weighted by the " + self.loss + " loss (f_scale " + f"{self.f_scale:g} sigma) and left out "
                    "of chi2 and the covariance") if self.loss != "linear" else \
                "kept in the fit: drop them with --reject K, or bound their influence with --loss soft_l1"
            out.append(f"warning: {len(self.flagged)} pose(s) beyond {self.threshold:g} sigma (normalised residual "
                       "sqrt(|W r|^2/k) of the pose, k rows; whitened with the noise model): "
                       + "; ".join(o.text() for o in self.flagged[:20])
                       + (" ..." if len(self.flagged) > 20 else "") + f"; {kept}")
        return out


def screen(z: np.ndarray, used: np.ndarray, row_names, threshold: float, *, where=None, round_: int = 1, numbers=None,
           loss: str = "linear", f_scale: float = 1.0, measured: np.ndarray | None = None) -> Screening:
    """The :class:`Screening` of whitened residuals ``z`` (N, k) of the poses ``used``
    (indices into the poses given); ``where(i)`` names pose i's file and line, ``numbers``
    (default index + 1) are the poses' numbers in the file. ``measured`` (N, k): the entries
    that are measurements (None: all); a pose's k counts those only (a printed object's
    pair row, one reading of two, is not halved in sigma)."""
    numbers = np.arange(1, int(np.max(used, initial=-1)) + 2) if numbers is None else np.asarray(numbers, dtype=int)
    z = np.asarray(z, dtype=float)
    N, k = z.shape
    per_pose = np.full(N, k) if measured is None else np.count_nonzero(measured, axis=1)
    sigma = np.sqrt(np.sum(z**2, axis=1) / np.maximum(per_pose, 1)) if k else np.zeros(N)
    out = []
    for j in np.flatnonzero(sigma > threshold):
        i = int(np.argmax(np.abs(z[j])))
        out.append(Outlier(pose=int(numbers[used[j]]), sigma=float(sigma[j]), reading=str(row_names[i]),
                           reading_sigma=float(z[j, i]), dropped=False, round=round_,
                           where="" if where is None else f" [{where(int(used[j]))}]"))
    out.sort(key=lambda o: -o.sigma)
    return Screening(pose_numbers=numbers[np.asarray(used, dtype=int)], sigma=sigma, z=z, row_names=tuple(row_names),
                     threshold=float(threshold), outliers=tuple(out), loss=loss, f_scale=float(f_scale),
                     rounds=round_, n_inliers=int(np.sum(sigma <= threshold)))


# -- covariance -----------------------------------------------------------------------------


def robust_uncertainty(names, J: np.ndarray, r: np.ndarray, inliers: np.ndarray, loss: str, f_scale: float,
                       prior_J: np.ndarray | None = None, prior_r: np.ndarray | None = None,
                       measured: np.ndarray | None = None):
    """The :class:`~pkmcal.identification.uncertainty.Uncertainty` of a robust and/or MAP fit
    from the whitened per-pose Jacobian ``J`` (N, k, p) and residuals ``r`` (N, k), the
    ``inliers`` mask (N,) and the prior rows (module docstrings of this module and of
    :mod:`.priors`): kind ``"map"`` for a quadratic loss with priors (posterior
    (J̃ᵀJ̃ + P)⁻¹), ``"robust"`` for a robust loss (sandwich on the inliers). ``measured``
    (N, k): the entries that are measurements, as in
    :func:`~pkmcal.identification.uncertainty.parameter_uncertainty` (None: all)."""
    from pkmcal.identification.uncertainty import Uncertainty, _inverse_normal

    N, k, p = J.shape
    Jin = J[inliers].reshape(-1, p)
    rin = r[inliers].ravel()
    Jp = np.zeros((0, p)) if prior_J is None else np.asarray(prior_J, dtype=float)
    rp = np.zeros(0) if prior_r is None else np.asarray(prior_r, dtype=float)
    a, b = efficiency(loss, f_scale)
    Ainv = _inverse_normal(np.vstack([np.sqrt(a) * Jin, Jp]))
    if loss == "linear":
        C = Ainv
    else:
        B = b * (Jin.T @ Jin) + Jp.T @ Jp
        C = Ainv @ B @ Ainv
    C = 0.5 * (C + C.T)
    n_in = Jin.shape[0] if measured is None else int(np.count_nonzero(np.asarray(measured)[inliers]))
    rows = n_in + Jp.shape[0]
    dof = rows - p
    chi2 = float(rin @ rin + rp @ rp)
    post = C * (chi2 / dof if dof > 0 else np.nan)
    n_out = int(N - np.sum(inliers))
    parts = []
    if loss != "linear":
        parts.append(f"{loss} loss, f_scale {f_scale:g} sigma (efficiency a^2/b = {a * a / b:.4g}), on the "
                     f"{int(np.sum(inliers))} poses within the threshold ({n_out} flagged pose(s) counted as "
                     "carrying no information)")
    if len(rp):
        parts.append(f"{len(rp)} Gaussian prior(s) (posterior covariance; chi2 and dof count the prior rows)")
    return Uncertainty(names=tuple(names), covariance_prior=C, covariance_posterior=post, chi2=chi2, dof=dof,
                       kind="robust" if loss != "linear" else "map", note="; ".join(parts))


# -- rejection ------------------------------------------------------------------------------


def identify_rejecting(fit, reject: float, n_poses: int):
    """Fit with ``fit(exclude=indices)`` (the engine), drop the poses beyond ``reject`` σ
    (module docstring), refit until none is left; the last fit's result, its
    :class:`Screening` listing every rejected pose with its round."""
    if not (np.isfinite(reject) and reject > 0):
        raise PkmcalError(f"--reject takes a positive number of sigmas; got {reject:g}")
    rejected: list[Outlier] = []
    index_of: dict[int, int] = {}      # file pose number → index in the poses given
    round_ = 1
    while True:
        result = fit(exclude=np.array([index_of[o.pose] for o in rejected], dtype=int), round_=round_)
        numbers = range(1, n_poses + 1) if result.pose_numbers is None else result.pose_numbers
        index_of = {int(n): i for i, n in enumerate(numbers)}
        sc = result.screening
        beyond = [o for o in sc.outliers if not o.dropped]
        if not beyond:
            break
        worst = beyond[0].sigma
        drop = [replace(o, dropped=True) for o in beyond if o.sigma >= 0.5 * worst]
        rejected.extend(drop)
        if len(rejected) > MAX_REJECTED_FRACTION * n_poses:
            raise PkmcalError(
                f"--reject {reject:g}: {len(rejected)} of {n_poses} poses beyond {reject:g} sigma after {round_} "
                f"round(s) (chi2/dof {result.uncertainty.reduced_chi2:.3g}): that is not a few bad poses but a "
                "noise model that is too optimistic or a machine model that misses an effect; check the setup's "
                "noise, the units and the free parameters, or raise K")
        round_ += 1
    sc = replace(result.screening, outliers=tuple(rejected) + result.screening.outliers, reject=float(reject),
                 rounds=round_)
    return replace(result, screening=sc, warnings=tuple(result.warnings) + tuple(sc.warnings()[:1]))


# -- JSON -----------------------------------------------------------------------------------

#: The units of the keys :func:`robust_dict` adds to ``identify --json``.
ROBUST_UNITS = {
    "outliers": "pose: data row of the measurement file, 1-based; sigma: sqrt(|W r|^2/k) of the pose, in noise "
                "sigmas; reading_sigma: the worst whitened row of the pose, in noise sigmas; round: 1-based fit "
                "round that flagged (dropped) it",
    "normalised_residuals": "pose: 1-based file rows of the poses in the fit; sigma, row_sigma, threshold_sigma, "
                            "f_scale_sigma, reject_sigma: in noise sigmas (whitened with the noise model)",
    "priors": "mean, std, estimate, posterior_std in each entry's unit (mm; deg for angle parameters); pull: "
              "(estimate - mean)/std, 1",
}


def robust_dict(result) -> dict:
    """The keys ``outliers``, ``normalised_residuals``, ``loss`` and ``priors`` of
    ``identify --json`` (units in :data:`ROBUST_UNITS`)."""
    sc = result.screening
    std = dict(zip(result.free, result.std))
    return {
        "loss": result.loss,
        "outliers": [] if sc is None else [o.to_dict() for o in sc.outliers],
        "normalised_residuals": None if sc is None else sc.to_dict(),
        "priors": result.priors.to_dict(result.estimate, std),
    }


__all__ = ["LOSSES", "OUTLIER_SIGMA", "DEFAULT_F_SCALE", "Outlier", "Screening", "check_loss", "efficiency",
           "identify_rejecting", "masked_loss", "robust_dict", "ROBUST_UNITS", "rho", "robust_uncertainty", "screen"]

"""Gaussian priors on parameters: maximum a posteriori identification.

A machine drawing gives tolerances: parameter θ_k is μ_k ± σ_k. Each such prior adds one
residual row to the noise-weighted least-squares problem of :mod:`.engine`,

    θ̂ = argmin_θ  Σ_j ‖W_j r_j(θ)‖²  +  Σ_k ((θ_k − μ_k) / σ_k)²                  (MAP)

which is the maximum a posteriori estimate for Gaussian noise and independent Gaussian
priors N(μ_k, σ_k²). Linearised at the solution (J̃ the whitened Jacobian, P = diag(1/σ_k²)
on the prior parameters), the posterior covariance is

    C = (J̃ᵀ J̃ + P)⁻¹                                                           (posterior)

and in the linear Gaussian case y = J θ + e, e ~ N(0, Σ), the estimate is the closed form
θ̂ = (JᵀΣ⁻¹J + P)⁻¹ (JᵀΣ⁻¹ y + P μ) (tests/identification/test_priors.py checks both). A prior pins the
direction it acts on, so a combination the data cannot see (a gauge freedom) becomes
identifiable, with the prior's σ; the automatic gauge therefore never fixes a parameter
with a prior (the prior rows enter the identifiability analysis). χ² counts the prior rows
as pseudo-observations: χ² = χ²_data + χ²_prior over M + K rows, dof = M + K − p.

Written as ``NAME=MEAN±STD`` (``+-`` for ASCII; ``NAME=±STD`` centres the prior on the
starting machine's value), names or shell patterns (``L0_*``), in file units: mm, degrees
for angle parameters (docs/conventions.md). In a setup file (docs/file-formats.md)::

    prior:
      L0_*: [640, 0.5]          # mean, std (mm)
      b1.z: "± 0.2"             # centred on the machine file's value
      world.c: "0 ± 0.05"       # degrees: an angle parameter
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.prior import Prior, parse_prior, parse_value  # noqa: F401  (the written form, below io/: pkmcal.prior)


@dataclass(frozen=True)
class ResolvedPriors:
    """The priors matched to the parameters of one fit (internal units: mm, rad).

    ``names`` the parameters with a prior, ``index`` their positions in the fit's full
    parameter vector, ``mean`` μ and ``std`` σ (mm or rad), ``is_angle`` their angle
    flags, ``source`` where each came from."""

    names: tuple[str, ...]
    index: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    is_angle: np.ndarray
    source: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.names)

    def positions(self, free_idx: np.ndarray) -> np.ndarray:
        """Positions of the prior parameters in the free vector ``free_idx``."""
        where = {int(i): k for k, i in enumerate(free_idx)}
        return np.array([where[int(i)] for i in self.index], dtype=int)

    def rows(self, free_idx: np.ndarray, x: np.ndarray | None = None):
        """The prior rows of the problem in the free parameters: Jacobian (K, p) = e_k/σ_k,
        and when ``x`` is given the residuals (x_k − μ_k)/σ_k (K,)."""
        pos = self.positions(free_idx)
        J = np.zeros((len(self), len(free_idx)))
        J[np.arange(len(self)), pos] = 1.0 / self.std
        return J if x is None else (J, (x[pos] - self.mean) / self.std)

    def augment(self, judged: np.ndarray, cand: list[int], basis: str) -> tuple[np.ndarray, str]:
        """The identifiability Jacobian ``judged`` (rows, len(cand)) with the prior rows
        appended (a prior pins its direction: module docstring) and its description."""
        if not len(self):
            return judged, basis
        return (np.vstack([judged, self.rows(np.asarray(cand, dtype=int))]),
                f"{basis} + {len(self)} prior row(s)")

    def to_dict(self, estimate: np.ndarray, std: dict[str, float]) -> list[dict]:
        """JSON-ready, file units: one entry per parameter with its prior, the estimate and
        its posterior std (``std``: internal units by name)."""
        deg = float(np.rad2deg(1.0))
        out = []
        for k, n in enumerate(self.names):
            f = deg if self.is_angle[k] else 1.0
            est = float(estimate[self.index[k]])
            out.append({"parameter": n, "unit": "deg" if self.is_angle[k] else "mm",
                        "mean": float(self.mean[k]) * f, "std": float(self.std[k]) * f,
                        "estimate": est * f, "posterior_std": float(std[n]) * f if n in std else None,
                        "pull": (est - float(self.mean[k])) / float(self.std[k]), "source": self.source[k]})
        return out


NO_PRIORS = ResolvedPriors((), np.zeros(0, dtype=int), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool), ())


def resolve(priors, names: tuple[str, ...], is_angle: tuple[bool, ...], theta0: np.ndarray) -> ResolvedPriors:
    """Match ``priors`` (:class:`Prior`, or ``NAME=MEAN±STD`` strings) to the fit's
    parameters ``names``: file units → internal (degrees → rad for angle parameters), a
    missing mean → the starting value ``theta0``. A later prior replaces an earlier one of
    the same parameter only when it comes from another source (the command line over the
    setup file); a pattern that matches nothing, lengths and angles together, or a parameter
    twice in one source is a :class:`PkmcalError`."""
    items = [parse_prior(p) if isinstance(p, str) else p for p in (priors or ())]
    chosen: dict[int, tuple[Prior, float, float]] = {}
    seen_in: dict[tuple[int, str], str] = {}
    for p in items:
        hits = [i for i, n in enumerate(names) if fnmatchcase(n, p.pattern)]
        if not hits and "@" not in p.pattern:   # several sessions: that parameter in every session
            hits = [i for i, n in enumerate(names) if fnmatchcase(n, p.pattern + "@*")]
        if not hits:
            import difflib

            close = difflib.get_close_matches(p.pattern, names, n=3)
            raise PkmcalError(f"prior '{p.pattern}' ({p.source}): no parameter has this name"
                              + (f" (did you mean {', '.join(close)}?)" if close else "")
                              + f"; the parameters are {', '.join(names)}")
        kinds = {bool(is_angle[i]) for i in hits}
        if len(kinds) > 1:
            raise PkmcalError(f"prior '{p.pattern}' ({p.source}) matches lengths (mm) and angles (deg): "
                              "write one prior per unit")
        for i in hits:
            key = (i, p.origin)
            if key in seen_in:
                raise PkmcalError(f"parameter {names[i]} has two priors in {p.origin} ('{seen_in[key]}' and "
                                  f"'{p.pattern}'): give each parameter one prior")
            seen_in[key] = p.pattern
            f = np.deg2rad(1.0) if is_angle[i] else 1.0
            mean = float(theta0[i]) if p.mean is None else p.mean * f
            chosen[i] = (p, mean, p.std * f)
    idx = np.array(sorted(chosen), dtype=int)
    if not idx.size:
        return NO_PRIORS
    return ResolvedPriors(names=tuple(names[i] for i in idx), index=idx,
                          mean=np.array([chosen[i][1] for i in idx]), std=np.array([chosen[i][2] for i in idx]),
                          is_angle=np.array([bool(is_angle[i]) for i in idx]),
                          source=tuple(chosen[i][0].source for i in idx))


#: Unit mistakes a prior's mean is checked for (mean / starting value ≈ factor), lengths
#: then angles: what the mean would be if written in that unit instead of mm or degrees.
_LENGTH_UNITS = {1e-3: "metres", 0.1: "centimetres", 1 / 25.4: "inches", 1e3: "micrometres"}
_ANGLE_UNITS = {np.pi / 180: "radians"}
#: A factor within this ratio of the mean/start ratio counts as a match.
_UNIT_MATCH = 1.05


def check_plausible(priors: ResolvedPriors, theta0: np.ndarray, is_angle, n_machine: int) -> None:
    """A prior whose mean cannot be meant is a :class:`PkmcalError` naming it (issue 24):

    * |mean| beyond :data:`pkmcal.io.limits.MAX_MAGNITUDE` (1e6 mm or degrees), larger than
      any machine or instrument;
    * the mean is the starting value written in another unit (metres, centimetres, inches,
      micrometres for lengths of at least 1 mm; radians for angles of at least 1°): mean /
      start within 5 % of the unit's factor;
    * a machine parameter (the first ``n_machine`` of ``names``) whose mean moves it from its
      starting value by more than the machine's size (the largest |start| of its length
      parameters), or an angle by more than 90°: no drawing is that far off.

    ``theta0`` and ``is_angle`` are the fit's starting vector and angle flags (internal
    units)."""
    from pkmcal.io.limits import MAX_MAGNITUDE

    deg = float(np.rad2deg(1.0))
    theta0 = np.asarray(theta0, dtype=float)
    machine_lengths = [abs(float(theta0[i])) for i in range(n_machine) if not is_angle[i]]
    size = max([v for v in machine_lengths if np.isfinite(v)] + [1.0])
    for k, (n, i) in enumerate(zip(priors.names, priors.index)):
        angle = bool(priors.is_angle[k])
        f, unit = (deg, "deg") if angle else (1.0, "mm")
        mean, start = float(priors.mean[k]), float(theta0[i])
        where = f"prior on {n} ({priors.source[k]}): mean {mean * f:.6g} {unit}"
        if abs(mean * f) > MAX_MAGNITUDE:
            raise PkmcalError(f"{where} is beyond ±{MAX_MAGNITUDE:g} {unit}, larger than any machine; check the number "
                              "and its unit")
        if abs(start * f) >= 1.0 and mean != start:
            ratio = mean / start
            for factor, name in (_ANGLE_UNITS if angle else _LENGTH_UNITS).items():
                if 1 / _UNIT_MATCH < ratio / factor < _UNIT_MATCH:
                    raise PkmcalError(f"{where} is {ratio:.4g} times its starting value {start * f:.6g} {unit}: it "
                                      f"looks written in {name}; give it in {unit} (e.g. {start * f:.6g}±...)")
        if i < n_machine:
            limit, what = (np.pi / 2, "90 deg") if angle else (size, f"the machine's size ({size:.6g} mm, its "
                                                                       "largest length parameter)")
            if abs(mean - start) > limit:
                raise PkmcalError(f"{where} is {abs(mean - start) * f:.6g} {unit} from its starting value "
                                  f"{start * f:.6g} {unit}, more than {what}: no machine is that far from its "
                                  "drawing; check the value, its unit and the parameter's name")


def check_free(priors: ResolvedPriors, free_names: set[str], gauge: tuple[str, ...] = ()) -> None:
    """A prior on a parameter that is not estimated is an error: it would be silently
    ignored. ``gauge``: parameters the automatic gauge fixed although they have a prior
    (possible only when the prior is too weak to lift the direction above the rank
    tolerance)."""
    for n, src in zip(priors.names, priors.source):
        if n in gauge:
            raise PkmcalError(f"prior on {n} ({src}) is too weak to make its direction identifiable (the gauge "
                              f"fixes {n}): give it a smaller standard deviation, or fix it with --fix")
        if n not in free_names:
            raise PkmcalError(f"prior on {n} ({src}): {n} is held fixed, so the prior would do nothing; free it "
                              "(--free, or the setup's free: list for sensor parameters) or remove the prior")


class PriorObjective:
    """The engine's whitened objective with the prior rows (θ_k − μ_k)/σ_k appended."""

    def __init__(self, obj, priors: ResolvedPriors, free_idx: np.ndarray):
        self.obj, self.priors = obj, priors
        self.J, self._pos = priors.rows(free_idx), priors.positions(free_idx)
        self.n_prior = len(priors)

    def theta(self, x):
        return self.obj.theta(x)

    def fun(self, x):
        return np.concatenate([self.obj.fun(x), (x[self._pos] - self.priors.mean) / self.priors.std])

    def jac(self, x):
        return np.vstack([self.obj.jac(x), self.J])


__all__ = ["Prior", "ResolvedPriors", "PriorObjective", "NO_PRIORS", "parse_prior", "parse_value", "resolve",
           "check_free"]

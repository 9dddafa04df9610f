"""Statistics of a calibration history: did a unit change, and does it stand out of its fleet?

**Two calibrations A and B of a unit** (:func:`compare`). Each carries its parameter
estimate θ and the covariance Σ its machine file carries (``covariance_kind``: the GLS
covariance of the noise model, inflated by max(1, χ²/E[χ²]); :mod:`pkmcal.identification.
uncertainty`). The two campaigns' noises are independent, so under "nothing changed"
Δ = θ_B − θ_A ~ N(0, Σ_A + Σ_B) and

    z_i = Δ_i / √(σ_A,i² + σ_B,i²)                      per parameter, N(0, 1)
    χ² = Δᵀ (Σ_A + Σ_B)⁺ Δ,  ν = rank(Σ_A + Σ_B)         jointly, χ²_ν

over the parameters both fits estimated. The rank is that of the correlation matrix of
Σ_A + Σ_B with eigenvalues below :data:`RANK_RTOL` × the largest dropped (the identifiable
subspace); a held parameter (zero covariance row: the gauge, or a parameter the setup
cannot see) is never tested. A parameter is flagged when |z_i| exceeds the Bonferroni limit
Φ⁻¹(1 − α/(2m)) over the m tested parameters, the comparison jointly when χ² exceeds the
χ²_ν quantile 1 − α; α (:data:`DEFAULT_ALPHA`) is the family-wise false-alarm probability of
each of the two tests when nothing changed (tests/history/test_stats.py measures it).

Gauge: a fit that cannot see some combination of parameters holds a gauge set at the
machine file's values (:mod:`pkmcal.identification.identifiability`), and the free
parameters are then estimated relative to it. Two calibrations are compared in one gauge:
when both hold the same parameters at the same values, directly; when their gauges differ
(the automatic gauge can change from one campaign to the next), B is first re-expressed in
A's gauge along the unidentifiable directions recorded with it (:mod:`pkmcal.history.gauge`:
θ_B + N t with (θ_B + N t)[g_A] = θ_A[g_A], Σ_B' = Π Σ_B Πᵀ). When that is not possible (no
directions recorded, different held sets outside them, priors) the comparison is refused
with the held sets named, and the remedy: hold the same gauge in every calibration
(``pkmcal identify --fix NAMES``).

**A unit against its fleet** (:func:`fleet`, statistical process control across serials).
Each serial of one model contributes its latest calibration. For a parameter and a unit u,
the other n − 1 units give the mean x̄ and standard deviation s (the fleet's spread:
manufacturing scatter plus calibration noise), and

    t_u = (x_u − x̄) / (s √(1 + 1/(n − 1)))             Student t with n − 2 degrees of freedom

exactly when the units' values are independent draws of one normal distribution (the
prediction interval of a new observation). Leaving the unit out keeps an outlier from
inflating its own limit; a second outlier among the others only widens the limits (fewer
alarms, never more). The limit is t_{n−2} at 1 − α/(2 n m), Bonferroni over the m
parameters and n units, so α is the probability that a fleet of units drawn from one
distribution raises any alarm. Hotelling's T² was not chosen: it needs more units than
parameters (a hexapod has 42) and its covariance estimate from a few units is singular; a
robust z (median, MAD) has no exact false-alarm rate for the 3 to 20 units of a fleet. The
test assumes calibrations of comparable precision (same setup and plan); a unit
calibrated with a much worse instrument carries more scatter than the fleet's and can be
flagged for it: compare its σ (printed) with the fleet's spread.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy import stats as _st

from pkmcal.errors import PkmcalError
from pkmcal.history.store import CalibrationRecord

#: Family-wise false-alarm probability of each test when nothing changed.
DEFAULT_ALPHA = 1e-3
#: Eigenvalues of the combined correlation matrix below this fraction of the largest are
#: outside the identifiable subspace (not tested).
RANK_RTOL = 1e-9


def z_limit(alpha: float, m: int) -> float:
    """Bonferroni two-sided limit on |z| for m normal statistics at family-wise ``alpha``."""
    return float(_st.norm.isf(alpha / (2 * max(m, 1))))


def joint_chi2(delta: np.ndarray, cov: np.ndarray) -> tuple[float, int]:
    """(χ², ν): Δᵀ C⁺ Δ over the identifiable subspace of C (module docstring); ``delta``
    (m,) or (k, m) for k differences at once (χ² then (k,))."""
    d = np.asarray(delta, dtype=float)
    c = np.asarray(cov, dtype=float)
    if c.size == 0:
        return (np.zeros(d.shape[:-1]) if d.ndim > 1 else 0.0), 0
    scale = np.sqrt(np.diag(c))
    w, v = np.linalg.eigh(c / np.outer(scale, scale))
    keep = w > RANK_RTOL * w.max()
    proj = (d / scale) @ v[:, keep]
    chi2 = np.sum(proj ** 2 / w[keep], axis=-1)
    return (chi2 if d.ndim > 1 else float(chi2)), int(keep.sum())


def _check_alpha(alpha: float) -> None:
    if not (0.0 < alpha < 1.0):
        raise PkmcalError(f"--alpha {alpha}: give a false-alarm probability between 0 and 1, e.g. 0.001")


def _gauge(rec: CalibrationRecord) -> tuple[tuple[str, ...], tuple[float, ...]]:
    held = rec.held
    return tuple(n for n, h in zip(rec.names, held) if h), tuple(float(v) for v, h in zip(rec.values, held) if h)


def _gauge_difference(a: CalibrationRecord, b: CalibrationRecord) -> str | None:
    """Why ``a`` and ``b`` are not in the same gauge (module docstring), or None."""
    if a.names != b.names:
        return (f"{a.label} and {b.label} have different parameters ({a.kind} '{a.model}' and {b.kind} "
                f"'{b.model}'); compare calibrations of one model")
    ga, gb = _gauge(a), _gauge(b)
    if ga[0] != gb[0]:
        only_a = [n for n in ga[0] if n not in gb[0]]
        only_b = [n for n in gb[0] if n not in ga[0]]
        gauge = [str(n) for n in (a.record.get("gauge") or [])] or only_a
        return (f"different gauges: {a.label} held {', '.join(only_a) or 'nothing more'} that {b.label} estimated, "
                f"{b.label} held {', '.join(only_b) or 'nothing more'} that {a.label} estimated; their free parameters "
                "are not the same quantities: calibrate every unit with the same gauge held (e.g. pkmcal identify "
                f"--fix {','.join(gauge) or 'NAMES'})")
    va, vb = np.array(ga[1]), np.array(gb[1])
    differ = [n for n, x, y in zip(ga[0], va, vb) if abs(x - y) > 1e-12 * max(1.0, abs(x), abs(y))]
    if differ:
        return (f"different gauges: the held parameter(s) {', '.join(differ)} have different values in {a.label} "
                f"and {b.label}; the free parameters are relative to them: calibrate both from the same machine "
                "file")
    return None


def _display_scale(units: tuple[str, ...]) -> tuple[np.ndarray, tuple[str, ...]]:
    angle = np.array([u == "rad" for u in units], dtype=bool)
    return np.where(angle, np.rad2deg(1.0), 1.0), tuple("deg" if a else u for a, u in zip(angle, units))


@dataclass(frozen=True)
class ParameterDifference:
    """One parameter of a comparison, in file units (mm, deg): A's and B's values, Δ = B − A,
    its combined σ = √(σ_A² + σ_B²), z = Δ/σ, and whether |z| passed the limit."""

    name: str
    unit: str
    a: float
    b: float
    delta: float
    sigma: float
    z: float
    flagged: bool

    def to_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit, "a": self.a, "b": self.b, "delta": self.delta,
                "sigma": self.sigma, "z": self.z, "flagged": self.flagged}


@dataclass(frozen=True)
class Comparison:
    """Two calibrations compared (:func:`compare`)."""

    a: CalibrationRecord
    b: CalibrationRecord
    alpha: float
    comparable: bool
    reason: str = ""
    regauged: str = ""
    rows: tuple[ParameterDifference, ...] = ()
    held: tuple[str, ...] = ()
    z_limit: float = float("nan")
    chi2: float = float("nan")
    dof: int = 0
    chi2_limit: float = float("nan")
    p_value: float = float("nan")

    @property
    def flagged(self) -> tuple[ParameterDifference, ...]:
        return tuple(r for r in self.rows if r.flagged)

    @property
    def jointly_flagged(self) -> bool:
        return bool(self.comparable and self.dof > 0 and self.chi2 > self.chi2_limit)

    @property
    def differ(self) -> bool:
        """Whether the calibrations differ beyond their combined uncertainty (a parameter or jointly)."""
        return bool(self.flagged) or self.jointly_flagged

    def to_dict(self) -> dict:
        return {"a": {"id": self.a.id, "serial": self.a.serial, "date": self.a.date},
                "b": {"id": self.b.id, "serial": self.b.serial, "date": self.b.date},
                "alpha": self.alpha, "comparable": self.comparable, "reason": self.reason or None,
                "regauged": self.regauged or None,
                "held": list(self.held), "z_limit": self.z_limit, "chi2": self.chi2, "dof": self.dof,
                "chi2_limit": self.chi2_limit, "p_value": self.p_value, "jointly_flagged": self.jointly_flagged,
                "differ": self.differ, "flagged": [r.name for r in self.flagged],
                "parameters": [r.to_dict() for r in self.rows],
                "units": {"a": "file units (mm, deg)", "b": "file units", "delta": "file units (B - A)",
                          "sigma": "file units: sqrt(sigma_A^2 + sigma_B^2)", "z": "1", "chi2": "1"}}

    def lines(self) -> list[str]:
        out = [f"A {self.a.label} -> B {self.b.label}"]
        if not self.comparable:
            return out + [f"not compared: {self.reason}"]
        if self.regauged:
            out.append(self.regauged)
        out.append(f"{len(self.rows)} parameters tested ({len(self.held)} held in both, not tested"
                   + (f": {', '.join(self.held)}" if self.held else "") + f"); false-alarm probability "
                   f"{self.alpha:g} per test (Bonferroni: |z| > {self.z_limit:.3g})")
        w = max([len(r.name) for r in self.rows] + [9])
        out.append(f"{'parameter':<{w}}  {'A':>12}  {'B':>12}  {'B - A':>11}  {'sigma':>10}  {'z':>7}")
        for r in sorted(self.rows, key=lambda r: -abs(r.z)):
            mark = "  <- differs" if r.flagged else ""
            out.append(f"{r.name:<{w}}  {r.a:>12.6g}  {r.b:>12.6g}  {r.delta:>+11.4g}  {r.sigma:>10.3g}  "
                       f"{r.z:>+7.2f}  {r.unit}{mark}")
        verdict = "differ" if self.jointly_flagged else "consistent"
        out.append(f"joint: chi2 {self.chi2:.4g} on {self.dof} dof (limit {self.chi2_limit:.4g}, p = "
                   f"{self.p_value:.3g}): {verdict}")
        if self.flagged:
            out.append("changed beyond the combined uncertainty: " + ", ".join(
                f"{r.name} {r.delta:+.4g} {r.unit} ({r.z:+.1f} sigma, sigma {r.sigma:.3g} {r.unit})"
                for r in self.flagged))
        elif self.jointly_flagged:
            out.append("no single parameter beyond its limit, but the calibrations differ jointly (a combination "
                       "of parameters changed)")
        else:
            out.append("no change beyond the combined uncertainty")
        return out


def _in_gauge_of(b: CalibrationRecord, a: CalibrationRecord) -> tuple[CalibrationRecord | None, str]:
    """(``b`` in ``a``'s gauge, note) — ``b`` itself when they share it, else re-expressed
    along the recorded unidentifiable directions (:func:`pkmcal.history.gauge.regauge`) —
    or (None, why not)."""
    from pkmcal.history.gauge import regauge

    why = _gauge_difference(a, b)
    if why is None:
        return b, ""
    if a.names != b.names:
        return None, why
    moved, how = regauge(b, a)
    if moved is None:
        return None, f"{why} (not re-expressed in one gauge: {how})"
    return moved, how


def compare(a: CalibrationRecord, b: CalibrationRecord, alpha: float = DEFAULT_ALPHA) -> Comparison:
    """Whether calibration ``b`` differs from ``a`` beyond their combined uncertainty
    (module docstring): per parameter z with Bonferroni limits, jointly χ²."""
    _check_alpha(alpha)
    b_in_a, note = _in_gauge_of(b, a)
    if b_in_a is None:
        return Comparison(a, b, alpha, comparable=False, reason=note)
    held = a.held
    idx = np.flatnonzero(~held)
    scale, units = _display_scale(a.units)
    delta = b_in_a.values[idx] - a.values[idx]
    var = np.diag(a.covariance)[idx] + np.diag(b_in_a.covariance)[idx]
    sigma = np.sqrt(var)
    z = delta / sigma
    lim = z_limit(alpha, len(idx))
    rows = tuple(ParameterDifference(a.names[i], units[i], float(a.values[i] * scale[i]),
                                     float(b_in_a.values[i] * scale[i]), float(d * scale[i]), float(s * scale[i]),
                                     float(zz), bool(abs(zz) > lim))
                 for i, d, s, zz in zip(idx, delta, sigma, z))
    chi2, dof = joint_chi2(delta, (a.covariance + b_in_a.covariance)[np.ix_(idx, idx)])
    return Comparison(a, b, alpha, comparable=True, regauged=note, rows=rows,
                      held=tuple(n for n, h in zip(a.names, held) if h), z_limit=lim, chi2=chi2, dof=dof,
                      chi2_limit=float(_st.chi2.isf(alpha, dof)) if dof else float("nan"),
                      p_value=float(_st.chi2.sf(chi2, dof)) if dof else float("nan"))


def consecutive(records: list[CalibrationRecord], alpha: float = DEFAULT_ALPHA) -> list[Comparison]:
    """Each calibration of a unit compared with the one before it (oldest first)."""
    return [compare(a, b, alpha) for a, b in zip(records, records[1:])]


def leave_one_out_t(x: np.ndarray) -> np.ndarray:
    """t of each unit against the others (module docstring), for ``x`` (..., n, m): n units,
    m parameters; NaN where the others have no spread."""
    x = np.asarray(x, dtype=float)
    n = x.shape[-2]
    mean = (x.sum(axis=-2, keepdims=True) - x) / (n - 1)
    dev = x[..., None, :, :] - mean[..., :, None, :]          # (..., unit left out, unit, m)
    eye = np.eye(n, dtype=bool)[:, :, None]
    ss = np.where(eye, 0.0, dev ** 2).sum(axis=-2)
    s = np.sqrt(ss / (n - 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (x - mean) / (s * np.sqrt(1.0 + 1.0 / (n - 1)))
    return np.where(s > 0, t, np.nan)


@dataclass(frozen=True)
class FleetFlag:
    """A unit's parameter against the rest of its fleet, in file units: its value and σ,
    the others' mean and spread, t and the limit."""

    serial: str
    id: int | None
    name: str
    unit: str
    value: float
    sigma: float
    fleet_mean: float
    fleet_std: float
    t: float
    flagged: bool

    def to_dict(self) -> dict:
        return {"serial": self.serial, "id": self.id, "name": self.name, "unit": self.unit, "value": self.value,
                "sigma": self.sigma, "fleet_mean": self.fleet_mean, "fleet_std": self.fleet_std, "t": self.t,
                "flagged": self.flagged}


@dataclass(frozen=True)
class FleetReport:
    """Statistical process control of one model's fleet (:func:`fleet`)."""

    model: str
    alpha: float
    units: tuple[CalibrationRecord, ...]
    excluded: tuple[tuple[str, str], ...] = ()
    regauged: tuple[str, ...] = ()
    tested: tuple[str, ...] = ()
    held: tuple[str, ...] = ()
    t_limit: float = float("nan")
    dof: int = 0
    rows: tuple[FleetFlag, ...] = ()
    note: str = ""

    @property
    def flagged(self) -> tuple[FleetFlag, ...]:
        return tuple(r for r in self.rows if r.flagged)

    def to_dict(self) -> dict:
        return {"model": self.model, "alpha": self.alpha,
                "units": [{"serial": r.serial, "id": r.id, "date": r.date} for r in self.units],
                "excluded": [{"serial": s, "reason": why} for s, why in self.excluded],
                "regauged": list(self.regauged),
                "tested": list(self.tested), "held": list(self.held), "t_limit": self.t_limit, "dof": self.dof,
                "note": self.note or None, "flagged": [r.to_dict() for r in self.flagged],
                "rows": [r.to_dict() for r in self.rows],
                "units_of_values": "file units (mm, deg) per row's 'unit'"}

    def lines(self) -> list[str]:
        out = [f"fleet '{self.model}': {len(self.units)} unit(s) (latest calibration each)"
               + (f": {', '.join(r.serial for r in self.units)}" if self.units else "")]
        for s, why in self.excluded:
            out.append(f"  excluded {s}: {why}")
        if self.regauged:
            out.append(f"  re-expressed in {self.units[0].serial}'s gauge along the unidentifiable directions: "
                       f"{', '.join(self.regauged)}")
        if self.note:
            return out + [self.note]
        out.append(f"{len(self.tested)} parameters tested ({len(self.held)} held, not tested); a unit against the "
                   f"other {len(self.units) - 1}: |t| > {self.t_limit:.3g} (Student t, {self.dof} dof; false-alarm "
                   f"probability {self.alpha:g} for the fleet, Bonferroni over parameters and units)")
        if not self.flagged:
            out.append("no unit outside the spread of its fleet")
        for r in sorted(self.flagged, key=lambda r: -abs(r.t)):
            out.append(f"  {r.serial} {r.name} = {r.value:.6g} {r.unit} (sigma {r.sigma:.3g}); the others "
                       f"{r.fleet_mean:.6g} ± {r.fleet_std:.3g} {r.unit} (spread): t {r.t:+.2f}  <- outside")
        return out


def fleet(records: list[CalibrationRecord], alpha: float = DEFAULT_ALPHA, model: str | None = None) -> FleetReport:
    """Statistical process control of the units ``records`` (one calibration per serial, one
    model; module docstring): which unit's parameters fall outside the spread of the others."""
    _check_alpha(alpha)
    name = model or (records[0].model if records else "?")
    if not records:
        return FleetReport(name, alpha, (), note="no calibration of this model")
    # the reference: the most common parameter set and gauge (held names and values)
    keys = [(r.names, _gauge(r)) for r in records]
    ref = Counter(keys).most_common(1)[0][0]
    ref_rec = records[keys.index(ref)]
    units, excluded, regauged = [ref_rec], [], []
    for r in records:
        if r is ref_rec:
            continue
        moved, why = _in_gauge_of(r, ref_rec)
        if moved is None:
            excluded.append((r.serial, why))
        else:
            units.append(moved)
            if why:
                regauged.append(r.serial)
    n = len(units)
    held = ref_rec.held
    idx = np.flatnonzero(~held)
    held_names = tuple(n_ for n_, h in zip(ref_rec.names, held) if h)
    if n < 3:
        return FleetReport(name, alpha, tuple(units), tuple(excluded), tuple(regauged), held=held_names,
                           note=f"{n} comparable unit(s): the fleet's spread needs at least 3")
    scale, disp = _display_scale(ref_rec.units)
    x = np.array([r.values[idx] for r in units])                       # (n, m)
    sd = np.array([r.std[idx] for r in units])
    m = len(idx)
    dof = n - 2
    lim = float(_st.t.isf(alpha / (2 * n * m), dof))
    rows = []
    t_all = leave_one_out_t(x)
    for u in range(n):
        others = np.delete(x, u, axis=0)
        mean = others.mean(axis=0)
        s = others.std(axis=0, ddof=1)
        t = t_all[u]
        for j, i in enumerate(idx):
            tj = float(t[j]) if np.isfinite(t[j]) else float("nan")    # others all equal: no spread to test
            rows.append(FleetFlag(units[u].serial, units[u].id, ref_rec.names[i], disp[i], float(x[u, j] * scale[i]),
                                  float(sd[u, j] * scale[i]), float(mean[j] * scale[i]), float(s[j] * scale[i]), tj,
                                  bool(np.isfinite(tj) and abs(tj) > lim)))
    return FleetReport(name, alpha, tuple(units), tuple(excluded), tuple(regauged),
                       tuple(ref_rec.names[i] for i in idx), held_names, lim, dof, tuple(rows))


__all__ = ["DEFAULT_ALPHA", "RANK_RTOL", "Comparison", "FleetFlag", "FleetReport", "ParameterDifference", "compare",
           "consecutive", "fleet", "joint_chi2", "leave_one_out_t", "z_limit"]

"""Whether a fit may be written as a calibration, and what most likely went wrong when not.

A calibrated machine file is acted on: a controller is loaded with it. A fit whose residuals
no noise explains is not a calibration, however well its solver converged (issue 24: radians
read as degrees give χ²/ν ≈ 900, a scalar-first quaternion read scalar-last 2.4e5, a prior in
metres pins arms at 0.2 mm). :func:`judge` states the rule; :func:`diagnose` names the
likely causes; ``pkmcal identify`` refuses to write a refused fit unless the user accepts it
(``--accept-bad-fit``, recorded in the file).

The rule. A fit is refused when

* the solver did not converge, or its cost is not finite; or
* a machine parameter moved from its starting value by more than the machine's size (its
  largest length parameter) or an angle by more than 90° (radians read as degrees on a
  42-parameter hexapod are absorbed by joints moved 4 m, at χ²/ν = 12.7); or
* the readers found the inputs look wrong (:func:`input_causes`: radians, quaternion order)
  and χ² is beyond the 1e-6 tail of the noise model; or
* χ² is beyond what the noise model allows even with every noise σ of the setup
  :data:`NOISE_SLACK` (3) times larger than stated:

      P( χ²_ν ≥ χ² / k² ) < α,     k = NOISE_SLACK, α = TAIL (1e-6), ν = E[χ²]

  (ν the degrees of freedom of a noise-weighted fit; :class:`~.uncertainty.Uncertainty`'s
  E[χ²] for the others; no χ² rule where the setup states a noise of 0 and χ² is infinite). A correct model with noise as stated gives χ²/ν = 1 ± √(2/ν);
  real instruments' stated σ are often optimistic by a factor of 2 or so, and such fits are
  not wrong (their covariance is inflated by χ²/E[χ²]) — :func:`chi2_warning` says so, the
  fit is written. At ν = 138 the refusal starts at χ²/ν ≈ 14.3 (residuals 3.8 times the
  stated noise); the plainly wrong fits above are orders of magnitude beyond it.

The diagnoses (:func:`diagnose`) are the checks the data allow: the readers' notes on
conventions (radians, quaternion order: :mod:`pkmcal.io.orientation`), angle columns that
differ from the poses by 57.3 (:func:`radian_hints`), residuals uniformly many times the
stated noise in every column (the setup's noise), χ² held by a few poses (outliers), priors
the data contradict (the fit without them is acceptable), and a clipped-reading policy that
dropped most poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

#: Tail probability of the χ² refusal (module docstring).
TAIL = 1e-6
#: Factor by which the setup's noise σ may be optimistic before a fit is refused.
NOISE_SLACK = 3.0
#: A refit or a policy that leaves out more than this fraction of the poses is named.
MOST_DROPPED = 0.5


def chi2_tail(chi2: float, nu: float) -> float:
    """P(χ²_ν ≥ chi2) (scipy's survival function; 0.0 when χ² is far out)."""
    from scipy.stats import chi2 as chi2_dist

    return float(chi2_dist.sf(chi2, nu))


def _nu(unc) -> float:
    e = float(unc.chi2_expected)
    return e if np.isfinite(e) and e > 0 else float(unc.dof)


def beyond_noise(unc, slack: float = 1.0) -> bool:
    """Whether χ²/slack² lies in the :data:`TAIL` of χ²_ν (ν = E[χ²]); False without
    degrees of freedom (undefined)."""
    nu = _nu(unc)
    if not nu > 0 or not np.isfinite(unc.chi2):
        return False
    return chi2_tail(float(unc.chi2) / slack**2, nu) < TAIL


def chi2_warning(unc) -> str | None:
    """A warning when χ² is beyond the 1e-6 tail of the noise model but within
    :data:`NOISE_SLACK` (written, with the covariance inflated), else None."""
    if not beyond_noise(unc) or beyond_noise(unc, NOISE_SLACK):
        return None
    b = float(unc.birge_ratio)
    return (f"warning: chi2/E[chi2] = {b:.3g}: the residuals are {np.sqrt(b):.2g} times the noise the setup states, "
            f"beyond the {TAIL:g} tail of the chi2 distribution ({_nu(unc):g} dof): the setup's noise is optimistic or "
            "the model misses an effect; the covariance written is inflated by chi2/E[chi2]")


@dataclass(frozen=True)
class FitVerdict:
    """``problems``: why the fit is refused (empty: acceptable); ``diagnoses``: what most
    likely caused them (:func:`diagnose`)."""

    problems: tuple[str, ...] = ()
    diagnoses: tuple[str, ...] = ()

    @property
    def acceptable(self) -> bool:
        return not self.problems

    def with_diagnoses(self, diagnoses) -> "FitVerdict":
        return FitVerdict(self.problems, tuple(diagnoses))

    def text(self) -> str:
        """One line: the problems, then the likely causes numbered."""
        out = "; ".join(self.problems)
        if self.diagnoses:
            out += "; likely cause" + ("s" if len(self.diagnoses) > 1 else "") + ": " + " ".join(
                f"({k}) {d}" for k, d in enumerate(self.diagnoses, start=1))
        return out

    def to_dict(self) -> dict:
        return {"acceptable": self.acceptable, "problems": list(self.problems), "diagnoses": list(self.diagnoses),
                "rule": RULE}


RULE = (f"refused when the fit did not converge, its cost is not finite, P(chi2_nu >= chi2/{NOISE_SLACK:g}^2) < "
        f"{TAIL:g} with nu = E[chi2] (chi2 beyond what the noise model allows even with every noise sigma "
        f"{NOISE_SLACK:g} times larger; without that slack when the input files look wrong), or a machine parameter "
        "moved by more than the machine's size (90 deg for an angle)")


def judge(result, causes: Sequence[str] = ()) -> FitVerdict:
    """The verdict of the rule of the module docstring on an
    :class:`~.engine.IdentificationResult` (no diagnoses yet). ``causes``: what
    :func:`input_causes` found wrong in the inputs; with any, a χ² beyond the noise's tail
    is refused without the slack (the slack is for an optimistic noise, and here the excess
    has a known cause)."""
    problems = []
    if not result.success:
        problems.append(f"the fit did not converge ({result.message})")
    u = result.uncertainty
    if not np.isfinite(result.cost):
        problems.append("the fit's cost is not finite (a parameter or a prior beyond any machine's scale)")
    # (a noise of 0, an exact simulation fitted unweighted, makes χ² infinite: no scale to judge by)
    elif np.isfinite(u.chi2) and beyond_noise(u, NOISE_SLACK):
        problems.append(f"chi2/E[chi2] = {u.birge_ratio:.4g} ({u.chi2:.6g} over E[chi2] {_nu(u):g}): the residuals "
                        f"are {np.sqrt(u.birge_ratio):.3g} times the noise the setup states, beyond what the noise "
                        f"allows even if every noise sigma were {NOISE_SLACK:g} times larger (P < {TAIL:g})")
    elif np.isfinite(u.chi2) and causes and beyond_noise(u):
        problems.append(f"chi2/E[chi2] = {u.birge_ratio:.4g} ({u.chi2:.6g} over E[chi2] {_nu(u):g}) is beyond the "
                        f"{TAIL:g} tail of the noise model, and the input files look wrong")
    problems += _implausible_moves(result)
    return FitVerdict(tuple(problems))


def _implausible_moves(result) -> list[str]:
    """The machine parameters the fit moved from their starting values by more than the
    machine's size (its largest length parameter) or an angle by more than 90°: no drawing
    is that far off, so the data were fitted by absurd geometry (the rule of
    :func:`pkmcal.identification.priors.check_plausible`, applied to the estimate)."""
    n = len(result.mechanism.param_names)
    start, est = np.asarray(result.initial, dtype=float)[:n], np.asarray(result.estimate, dtype=float)[:n]
    angle = np.asarray(result.param_is_angle[:n] if result.param_is_angle else result.mechanism.param_is_angle,
                       dtype=bool)
    lengths = np.abs(start[~angle])
    size = max(float(lengths.max()) if lengths.size else 1.0, 1.0)
    move = np.abs(est - start)
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(np.where(angle, move > np.pi / 2, move > size) | ~np.isfinite(move))
    if not bad.size:
        return []
    worst = int(bad[np.argmax(np.where(angle[bad], move[bad] / (np.pi / 2), move[bad] / size))])
    f, unit = (np.rad2deg(1.0), "deg") if angle[worst] else (1.0, "mm")
    return [f"{len(bad)} machine parameter(s) moved further than any drawing is off (more than the machine's size, "
            f"{size:.6g} mm, or 90 deg), e.g. {result.names[worst]} by {move[worst] * f:.4g} {unit}: the fit explains "
            "the readings with an absurd geometry"]


def input_causes(nominal, setup, meas) -> list[str]:
    """What is known to be wrong with the inputs, whatever the fit: the readers' notes on
    conventions (:mod:`pkmcal.io.orientation`) and angle columns that differ from the poses
    by 57.3 (:func:`radian_hints`)."""
    out = [n for n in getattr(meas, "notes", ()) if "look" in n]
    return out + [h.removeprefix("warning: ") for h in radian_hints(nominal, setup, meas)]


def diagnose(result, setup, meas, causes: Sequence[str] = (), *, n_read: int | None = None,
             refit_without_priors: Callable[[], object] | None = None) -> list[str]:
    """The likely causes of a refused fit (module docstring), most specific first.

    ``causes`` what :func:`input_causes` found; ``meas`` the measurements fitted; ``n_read``
    how many poses the file had before a clipped-reading policy left some out;
    ``refit_without_priors`` a function that fits again without the priors (called only
    when the fit has priors)."""
    out = list(causes)
    out += _prior_causes(result, refit_without_priors)
    out += _weak_cause(result)
    if not out:   # the generic causes only when no specific one is known
        out += _outlier_cause(result) or _noise_cause(result, setup)
    if n_read is not None and n_read > 0:
        left = n_read - len(getattr(meas, "actuators", ()))
        if left > MOST_DROPPED * n_read:
            out.append(f"the --clipped policy left out {left} of the {n_read} poses of the file (readings at or beyond "
                       "an end of their stroke): check the machine's stroke or travel and the readings' unit")
    dropped = len(result.dropped)
    if dropped > MOST_DROPPED * (dropped + len(result.used_poses)):
        out.append(f"{dropped} poses could not be solved at the nominal machine and were left out: the measurements "
                   "may belong to another machine or setup")
    return out


def _prior_causes(result, refit) -> list[str]:
    pr = result.priors
    if not len(pr) or refit is None:
        return []
    from pkmcal.errors import PkmcalError

    try:
        free = refit()
    except PkmcalError:
        return []
    if not judge(free).acceptable:
        return []
    deg = float(np.rad2deg(1.0))
    at = {n: k for k, n in enumerate(free.free)}
    out = []
    for k, n in enumerate(pr.names):
        if n not in at:
            continue
        est, s_data = float(free.x[at[n]]), float(free.std[at[n]])
        mean, s_prior = float(pr.mean[k]), float(pr.std[k])
        apart = abs(est - mean) / np.hypot(s_data, s_prior)
        if apart > 5:
            f, unit = (deg, "deg") if pr.is_angle[k] else (1.0, "mm")
            out.append(f"the prior on {n} ({pr.source[k]}: {mean * f:.6g} ± {s_prior * f:.3g} {unit}) is {apart:.3g} "
                       f"sigma from what the data say without priors ({est * f:.6g} ± {s_data * f:.3g} {unit}; that "
                       f"fit's chi2/E[chi2] is {free.uncertainty.birge_ratio:.3g}): check the prior's value and unit")
    return out


def _weak_cause(result) -> list[str]:
    """The weakly identifiable directions along which machine parameters moved absurdly."""
    if not _implausible_moves(result):
        return []
    weak = result.identifiability.weak
    if not weak:
        return []
    worst = min(w["ratio"] for w in weak)
    return [f"the data leave {len(weak)} direction(s) weakly identifiable (sigma/sigma_1 down to {worst:.2g}), along "
            "which the fit wandered: measure more or better spread poses (pkmcal plan), or give priors on the "
            "parameters of those directions (--prior), or fix one of them"]


def _outlier_cause(result) -> list[str]:
    w = np.asarray(result.residuals_weighted, dtype=float)
    if w.ndim != 2 or len(w) < 5:
        return []
    per_pose = np.sum(w**2, axis=1)
    total = float(per_pose.sum())
    if not total > 0:
        return []
    order = np.argsort(per_pose)[::-1]
    few = max(1, len(w) // 10)
    share = float(per_pose[order[:few]].sum()) / total
    if share < 0.5:
        return []
    numbers = [result.pose_number(int(result.used_poses[k])) for k in order[:few]]
    return [f"{share:.0%} of chi2 comes from {few} pose(s) ({', '.join(str(n) for n in numbers)}): outliers; "
            "leave them out with --reject K or bound them with --loss soft_l1"]


def _noise_cause(result, setup) -> list[str]:
    w = np.asarray(result.residuals_weighted, dtype=float)
    if w.ndim != 2 or not len(w) or w.shape[1] != len(result.residual_names):
        return []
    ratio = np.sqrt(np.mean(w**2, axis=0))
    if not np.all(ratio > NOISE_SLACK):
        return []
    cols = ", ".join(f"{n} {r:.3g}" for n, r in zip(result.residual_names, ratio))
    return [f"the residuals are many times the setup's noise in every column ({cols} times its sigma): if the files "
            "and units are right, the setup states a noise far too small for this instrument (setup 'noise:')"]


def radian_hints(nominal, setup, meas) -> list[str]:
    """Warnings when the sensor's angle columns and the poses the fit starts from differ in
    spread by about 180/π (57.3): one of them was written in radians where degrees were
    read. The reference poses are the commanded ones (cmd_a..), else the FK of the actuator
    readings at the nominal machine; per angle column the ratio of standard deviations over
    the poses (offsets of world/tool transforms cancel) is compared with [30, 110]."""
    sensor = setup.sensor
    angle_cols = [k for k, a in enumerate(sensor.reading_is_angle) if a]
    if not angle_cols or tuple(sensor.reading_names) != tuple(nominal.pose_names):
        return []
    if meas.commanded is not None:
        ref, what = np.asarray(meas.commanded, dtype=float), "the commanded poses (cmd_ columns)"
    else:
        with np.errstate(all="ignore"):
            fk = nominal.fk(meas.actuators)
        ref, what = np.asarray(fk.poses)[fk.ok], "the poses of the actuator readings (FK at the nominal machine)"
        if len(ref) < 3:
            return []
    y = np.asarray(meas.readings, dtype=float)[: len(ref)] if meas.commanded is not None else \
        np.asarray(meas.readings, dtype=float)[fk.ok]
    out = []
    for k in angle_cols:
        s_ref, s_y = float(np.std(ref[:, k])), float(np.std(y[:, k]))
        if not (s_ref > np.deg2rad(0.5) or s_y > np.deg2rad(0.5)) or s_ref == 0 or s_y == 0:
            continue
        r = s_ref / s_y
        name = sensor.reading_names[k]
        if 30.0 < r < 110.0:
            out.append(f"warning: column '{name}' varies {r:.3g} times less than the angles of {what}: it looks like "
                       "radians where degrees are read; convert it to degrees (or, when every angle column of the "
                       "file is in radians, give --angle-unit rad)")
        elif 1 / 110.0 < r < 1 / 30.0 and meas.commanded is not None:
            out.append(f"warning: column 'cmd_{name}' varies {1 / r:.3g} times less than the measured '{name}': it "
                       "looks like radians where degrees are read; convert it to degrees")
    return out


__all__ = ["MOST_DROPPED", "NOISE_SLACK", "RULE", "TAIL", "FitVerdict", "beyond_noise", "chi2_tail", "chi2_warning",
           "diagnose", "input_causes", "judge", "radian_hints"]

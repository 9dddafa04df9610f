"""Study results: the tidy trial table, its part files, resuming, and summary statistics.

**Tidy table** (``trials.csv``): one row per trial × configuration (configuration =
machine × setup × plan × number of poses × method), columns :data:`COLUMNS` (units in the
names: ``_mm``, ``_deg``; flags as 1/0; a missing value is an empty cell), ordered by
configuration then trial. Floats are written as their shortest round-trip ``repr``, so the
same results give the same bytes. Text (labels, a failed trial's message) is quoted as RFC
4180 says when it holds a comma, a quote or a line break, and every reader here reads
records with the ``csv`` module (never split at line ends), so ``csv``, ``pandas.read_csv``
and ``--resume`` read back exactly the text written.

**Part files** (``parts/c<campaign>-t<first>-<last>.csv``, one per finished batch, each
written atomically): what ``--resume`` reads back; a trial is done when its campaign and
trial number appear in a part. ``manifest.json`` records the study's fingerprint and
``"complete": false`` while the study runs; ``trials.csv`` and ``summary.csv`` are written
only when every trial is done, and the manifest says ``"complete": true`` last. A reader
must check the manifest: a folder without ``"complete": true`` is an unfinished study.

**Summary** (``summary.csv``, long format: one row per configuration × metric):

* continuous metrics: n, mean with the Student-t 95 % interval of the mean, sd, median with
  the distribution-free 95 % interval of the median from binomial order statistics
  (ranks j < k with P(j ≤ B < k) ≥ 0.95, B ~ Bin(n, ½); exact, no resampling), 5 % and
  95 % quantiles (``numpy.quantile``, linear);
* 0/1 metrics (``all_within_95``, ``ellipsoid_within_95``, ``failed``): the fraction with
  the Wilson score 95 % interval (Wilson 1927), which stays inside [0, 1] and keeps its
  coverage for fractions near 0 or 1.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.io.atomic import atomic_write_text
from pkmcal.io.inputs import read_input_text

#: 97.5 % quantile of the standard normal distribution (scipy.stats.norm.ppf(0.975)).
Z95 = 1.959963984540054

#: Column → (type, description). Types: "int", "float", "flag" (1/0), "str".
COLUMNS: dict[str, tuple[str, str]] = {
    "config": ("int", "configuration number (machine × setup × plan × poses × method), from 0"),
    "machine": ("str", "machine label"),
    "setup": ("str", "setup label"),
    "plan": ("str", "plan label"),
    "algorithm": ("str", "pose selection algorithm"),
    "n_poses": ("int", "poses planned"),
    "method": ("str", "method label"),
    "identification": ("str", "identification method used (auto resolved)"),
    "weighted": ("flag", "noise-weighted (GLS) fit"),
    "plan_resampled": ("flag", "1: poses selected anew in every trial; 0: one selection for every trial"),
    "trial": ("int", "trial number, from 0"),
    "failed": ("flag", "1 when the trial could not be completed (see message)"),
    "message": ("str", "why the trial failed; empty when it did not"),
    "poses_measured": ("int", "planned poses the real machine reached and the sensor read"),
    "n_free": ("int", "free parameters estimated (after any gauge)"),
    "rank": ("int", "rank of the start Jacobian on the candidate parameters"),
    "n_candidates": ("int", "candidate parameters before any gauge"),
    "gauge": ("str", "parameters fixed by the automatic gauge, space-separated"),
    "condition": ("float", "condition number of the whitened, column-scaled start Jacobian on its rank"),
    "chi2": ("float", "χ² of the whitened residuals at the solution"),
    "dof": ("int", "degrees of freedom (residuals − free parameters)"),
    "reduced_chi2": ("float", "χ² / dof"),
    "nfev": ("int", "residual evaluations of the solver"),
    "param_error_mean_abs_mm": ("float", "mean |θ̂ − θ*| over the free length parameters (θ*: truth in the fit's gauge)"),
    "param_error_rms_mm": ("float", "rms of θ̂ − θ* over the free length parameters"),
    "param_error_max_abs_mm": ("float", "max |θ̂ − θ*| over the free length parameters"),
    "param_error_rms_deg": ("float", "rms of θ̂ − θ* over the free angle parameters (empty if none)"),
    "param_error_before_mean_abs_mm": ("float", "mean |θ_nominal − θ*| over the same parameters"),
    "param_error_vs_real_mean_abs_mm": ("float", "mean |θ̂ − θ_real| over the free length parameters, no gauge alignment"),
    "truth_refit": ("flag", "1: θ* is the noise-free fit of the same poses (a fixed parameter differs from the truth)"),
    "truth_refit_rms": ("float", "rms residual of that noise-free fit (0 when the model can represent the real machine)"),
    "coverage_fraction": ("float", "fraction of free parameters with θ* inside θ̂ ± 1.96 σ (reported covariance)"),
    "all_within_95": ("flag", "1 when every free parameter's θ* lies inside its reported 95 % interval"),
    "ellipsoid_d2": ("float", "(θ̂ − θ*)ᵀ C⁻¹ (θ̂ − θ*), C the reported covariance of the free parameters"),
    "ellipsoid_within_95": ("flag", "1 when ellipsoid_d2 ≤ χ²(n_free, 0.95): θ* inside the joint 95 % ellipsoid"),
    "error_nsigma_rms": ("float", "rms over the free parameters of (θ̂ − θ*)/σ (≈ 1 for an honest covariance)"),
    "heldout_used": ("int", "held-out poses reached with both models"),
    "heldout_position_rms_mm": ("float", "rms position error on the held-out poses after calibration"),
    "heldout_position_max_mm": ("float", "max position error after"),
    "heldout_orientation_rms_deg": ("float", "rms orientation error after"),
    "heldout_orientation_max_deg": ("float", "max orientation error after"),
    "heldout_tilt_rms_deg": ("float", "rms platform tilt error after (what indicators see)"),
    "heldout_height_rms_mm": ("float", "rms height error at the platform centre after"),
    "heldout_position_rms_before_mm": ("float", "rms position error with the nominal model"),
    "heldout_orientation_rms_before_deg": ("float", "rms orientation error with the nominal model"),
    "heldout_tilt_rms_before_deg": ("float", "rms tilt error with the nominal model"),
    "heldout_height_rms_before_mm": ("float", "rms height error with the nominal model"),
    "heldout_reading_rms_mm": ("float", "rms error of the readings themselves after (compare = sensor, a sensor that "
                                        "reads no position: dial indicators, a Z probe)"),
    "heldout_reading_rms_before_mm": ("float", "rms reading error with the nominal model"),
    "heldout_compare": ("str", "what the held-out errors compare: commanded (the platform poses as commanded), sensor "
                               "(what the instrument reads), aligned (the platform poses after the best rigid alignment "
                               "of each model's frames), tool (the tool on the tracker, a machine at equilibrium)"),
}
#: Columns of a study with a setup of pose pairs (a printed object, :mod:`pkmcal.study.printed`),
#: after :data:`COLUMNS`: whether the measurements determine the in-plane scale.
SCALE_COLUMNS: dict[str, tuple[str, str]] = {
    "scale_status": ("str", "whether the measured poses determine the machine's named direction (a linear delta's "
                            "common scale of arms and radius), as pkmcal identifiability judges it whatever the method "
                            "holds: identified, weak, not determined or unidentifiable; empty for a machine without one"),
    "scale_sigma": ("float", "the standard deviation of that scale the measurements leave (relative: 0.001 = 0.1 %)"),
}
#: The held-out error columns (empty for a measure the machine's kind does not have:
#: :func:`pkmcal.study.trial.absent_columns`).
HELDOUT_COLUMNS = tuple(c for c in COLUMNS if c.startswith("heldout_") and c not in ("heldout_used", "heldout_compare"))
#: The columns that identify a configuration.
CONFIG_COLUMNS = ("config", "machine", "setup", "plan", "algorithm", "n_poses", "method", "identification",
                  "weighted", "plan_resampled")
#: Metrics summarised per configuration (0/1 ones get Wilson intervals).
SUMMARY_METRICS = (
    "failed", "poses_measured", "rank", "condition", "reduced_chi2",
    "param_error_mean_abs_mm", "param_error_rms_mm", "param_error_max_abs_mm", "param_error_before_mean_abs_mm",
    "param_error_vs_real_mean_abs_mm", "coverage_fraction", "all_within_95", "ellipsoid_within_95", "error_nsigma_rms",
    "heldout_position_rms_mm", "heldout_position_max_mm", "heldout_orientation_rms_deg", "heldout_tilt_rms_deg",
    "heldout_height_rms_mm", "heldout_position_rms_before_mm", "heldout_orientation_rms_before_deg",
    "heldout_reading_rms_mm", "heldout_reading_rms_before_mm", "scale_sigma",
)
PART_NAME = re.compile(r"^c(\d+)-t(\d+)-(\d+)\.csv$")


def column_names(extra: tuple[str, ...] = (), scale: bool = False) -> tuple[str, ...]:
    """The columns of ``trials.csv``: :data:`COLUMNS`, :data:`SCALE_COLUMNS` when ``scale`` (a
    study with a printed object), then a reproduction's ``extra`` ones."""
    return tuple(COLUMNS) + (tuple(SCALE_COLUMNS) if scale else ()) + tuple(extra)


_TYPES = {name: kind for name, (kind, _) in (COLUMNS | SCALE_COLUMNS).items()}


def column_type(name: str) -> str:
    return _TYPES.get(name, "float")


def cell(value, kind: str) -> str:
    """One CSV cell: floats as ``repr`` (empty for NaN or None), ints, flags as 1/0, text
    quoted (RFC 4180: in double quotes, a quote doubled) when it holds a comma, a quote, a
    line break, or leading or trailing white space, so that ``csv`` and ``pandas.read_csv``
    read back exactly the text written."""
    if value is None:
        return ""
    if kind == "float":
        v = float(value)
        return "" if math.isnan(v) else repr(v)
    if kind == "int":
        return str(int(value))
    if kind == "flag":
        return "1" if value else "0"
    s = str(value)
    if any(ch in s for ch in ',"\n\r') or s != s.strip():
        # RFC 4180 by hand: csv.writer with lineterminator="" leaves a line break unquoted
        s = '"' + s.replace('"', '""') + '"'
    return s


def format_row(values: dict, names: tuple[str, ...]) -> str:
    """A CSV line of ``values`` (missing keys empty) in the order ``names``."""
    return ",".join(cell(values.get(n), column_type(n)) for n in names)


def part_path(out: Path, campaign: int, first: int, last: int) -> Path:
    return out / "parts" / f"c{campaign:05d}-t{first:07d}-{last:07d}.csv"


# -- the results folder ------------------------------------------------------------------


@dataclass
class ResultFolder:
    """The ``RESULTS/`` folder of one study (module docstring)."""

    path: Path
    fingerprint: str
    names: tuple[str, ...]

    @property
    def manifest(self) -> Path:
        return self.path / "manifest.json"

    def read_manifest(self) -> dict | None:
        if not os.path.lexists(self.manifest):
            return None
        try:
            return json.loads(read_input_text(self.manifest, "study manifest"))
        except (PkmcalError, ValueError) as exc:
            raise PkmcalError(f"'{self.manifest}' is unreadable ({exc}); it is not a pkmcal study folder, or it "
                              "is damaged: choose another -o") from None

    def open(self, resume: bool, study_name: str, trials: int) -> None:
        """Create the folder (or check it for ``--resume``) and write the running manifest;
        what this created is remembered for :meth:`discard`."""
        man = self.read_manifest()
        if man is None:
            if self.path.exists() and any(self.path.iterdir()) and not resume:
                raise PkmcalError(f"output folder '{self.path}' exists and is not empty; choose another -o")
        elif not resume:
            state = "a finished" if man.get("complete") else "an unfinished"
            raise PkmcalError(f"'{self.path}' already holds {state} study ('{man.get('study')}'); continue it with "
                              "--resume or choose another -o")
        elif man.get("fingerprint") != self.fingerprint:
            raise PkmcalError(f"'{self.path}' holds results of a different study or seed ('{man.get('study')}', "
                              "other machines, setups, plans, methods, held-out set, seed or pkmcal version); "
                              "--resume continues only the same study: choose another -o")
        # what is new, in the order to remove it: the manifest, parts/, the folder, its new parents
        made = [self.path / "parts", self.path, *self.path.parents]
        self._created = ((self.manifest,) if man is None else ()) + tuple(
            made[:next((k for k, p in enumerate(made) if p.exists()), len(made))])
        try:
            (self.path / "parts").mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise PkmcalError(f"cannot create the output folder '{self.path}': {exc.strerror or exc}") from None
        self.write_manifest(study_name, trials, complete=False)
        # a finished study that is resumed (e.g. extended) must not look finished while it runs
        for name in ("trials.csv", "summary.csv"):
            if man is not None and (self.path / name).exists():
                os.unlink(self.path / name)

    def discard(self) -> bool:
        """After a failure: when no trial has finished (no part file), remove what :meth:`open`
        created (the manifest, ``parts/``, the folder itself), so that the same command can be
        run again; a folder that held anything before is left as it was. Returns whether the
        folder holds finished trials (then it is kept for ``--resume``). Never raises."""
        if self.done():
            return True
        for p in getattr(self, "_created", ()):
            try:
                os.rmdir(p) if p != self.manifest else os.unlink(p)
            except OSError:
                pass
        return False

    def write_manifest(self, study_name: str, trials: int, complete: bool, extra: dict | None = None) -> None:
        doc = {"format": "pkmcal-study-results", "study": study_name, "fingerprint": self.fingerprint,
               "trials_per_configuration": trials, "complete": complete, **(extra or {})}
        atomic_write_text(self.manifest, json.dumps(doc, indent=2) + "\n")

    def done(self) -> dict[int, set[int]]:
        """{campaign: trial numbers} found in the part files (each complete: written atomically)."""
        out: dict[int, set[int]] = {}
        for p in sorted((self.path / "parts").glob("c*-t*-*.csv")):
            m = PART_NAME.match(p.name)
            if m:
                out.setdefault(int(m.group(1)), set()).update(range(int(m.group(2)), int(m.group(3)) + 1))
        return out

    def write_part(self, campaign: int, first: int, last: int, lines: list[str]) -> None:
        atomic_write_text(part_path(self.path, campaign, first, last), ",".join(self.names) + "\n"
                          + "".join(line + "\n" for line in lines))

    def read_parts(self, trials: int) -> list[str]:
        """Data lines of all parts with trial < ``trials``, ordered by (config, trial)."""
        rows = []
        i_cfg, i_trial = self.names.index("config"), self.names.index("trial")
        for p in sorted((self.path / "parts").glob("c*-t*-*.csv")):
            if not PART_NAME.match(p.name):
                continue
            records = read_records(p)
            if not records or tuple(records[0]) != self.names:
                raise PkmcalError(f"part file '{p}' has other columns than this study writes; it belongs to another "
                                  "version: choose another -o")
            for cells in records[1:]:
                if len(cells) != len(self.names):
                    raise PkmcalError(f"part file '{p}' has a row of {len(cells)} cells for {len(self.names)} "
                                      "columns; it is damaged: delete it and run again with --resume")
                t = int(cells[i_trial])
                if t < trials:
                    rows.append((int(cells[i_cfg]), t, record_line(cells)))
        rows.sort(key=lambda r: (r[0], r[1]))
        return [r[2] for r in rows]


# -- reading a table back ----------------------------------------------------------------


def read_records(path: str | os.PathLike) -> list[list[str]]:
    """The CSV records of a file this module wrote: a quoted cell may hold line breaks
    (a trial's message, a label), so records are read by the csv module, never split at
    line ends."""
    return list(csv.reader(io.StringIO(read_input_text(path, "study table"), newline="")))


def record_line(cells: list[str]) -> str:
    """The CSV text of a record read back (:func:`read_records`): the bytes :func:`format_row`
    wrote (every cell of another type is plain text that needs no quotes)."""
    return ",".join(cell(v, "str") for v in cells)


def parse_table(header: tuple[str, ...], lines: list[str]) -> dict[str, np.ndarray]:
    """Columns of the data ``lines`` (one CSV record each, which may hold quoted line
    breaks): float/int/flag columns as float arrays (NaN where empty), text columns as
    object arrays."""
    return _columns(header, list(csv.reader(lines)) if lines else [])


def _columns(header: tuple[str, ...], cells: list[list[str]]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for k, name in enumerate(header):
        col = [row[k] for row in cells]
        if column_type(name) == "str":
            out[name] = np.array(col, dtype=object)
        else:
            out[name] = np.array([float(v) if v != "" else np.nan for v in col], dtype=float)
    return out


def read_trials(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The columns of a ``trials.csv`` (see :func:`parse_table`)."""
    records = read_records(path)
    if not records:
        raise PkmcalError(f"'{path}' is empty")
    return _columns(tuple(records[0]), records[1:])


# -- statistics --------------------------------------------------------------------------


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial fraction k/n."""
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def t_interval(values: np.ndarray) -> tuple[float, float]:
    """Student-t 95 % interval of the mean."""
    from scipy.special import stdtrit

    n = values.size
    if n < 2:
        return float("nan"), float("nan")
    m = float(values.mean())
    half = float(stdtrit(n - 1, 0.975)) * float(values.std(ddof=1)) / math.sqrt(n)
    return m - half, m + half


def median_interval(values: np.ndarray) -> tuple[float, float]:
    """Distribution-free 95 % interval of the median: order statistics x_(j) ≤ med ≤ x_(k)
    with the largest j and smallest k (k = n + 1 − j) such that P(j ≤ B < k) ≥ 0.95,
    B ~ Bin(n, ½); NaN when n is too small (n < 6) for any such pair."""
    from scipy.special import bdtr

    n = values.size
    x = np.sort(values)
    # P(B ≤ j − 1) ≤ 0.025  ⇔  the interval [x_(j), x_(n+1−j)] has coverage ≥ 0.95
    j = 0
    while j + 1 <= n // 2 and bdtr(j, n, 0.5) <= 0.025:
        j += 1
    if j == 0:
        return float("nan"), float("nan")
    return float(x[j - 1]), float(x[n - j])


SUMMARY_HEADER = CONFIG_COLUMNS + ("metric", "n", "mean", "mean_ci_low", "mean_ci_high", "sd", "median",
                                  "median_ci_low", "median_ci_high", "q05", "q95", "interval", "heldout_compare")
_FLAGS = ("failed", "all_within_95", "ellipsoid_within_95")


def summarise(cols: dict[str, np.ndarray], metrics: tuple[str, ...] = SUMMARY_METRICS,
              absent: dict[int, tuple[str, ...]] | None = None) -> list[dict]:
    """Summary rows (module docstring) of the trial columns ``cols``; ``absent``
    {config: columns} the metrics a configuration's machine does not have (a delta's
    orientation error), left out rather than summarised as an empty set."""
    out = []
    cfg = cols["config"].astype(int) if len(cols["config"]) else np.zeros(0, int)
    for c in np.unique(cfg):
        sel = cfg == c
        first = np.flatnonzero(sel)[0]
        ident = {k: cols[k][first] for k in CONFIG_COLUMNS + ("heldout_compare",) if k in cols}
        skip = () if absent is None else absent.get(int(c), ())
        for metric in metrics:
            if metric not in cols or metric in skip:
                continue
            v = cols[metric][sel]
            v = v[np.isfinite(v)]
            row = dict(ident, metric=metric, n=int(v.size))
            if metric in _FLAGS or column_type(metric) == "flag":
                k = int(np.count_nonzero(v))
                lo, hi = wilson_interval(k, v.size)
                row.update(mean=k / v.size if v.size else float("nan"), mean_ci_low=lo, mean_ci_high=hi,
                           interval="Wilson score 95% (fraction)")
            else:
                lo, hi = t_interval(v)
                mlo, mhi = median_interval(v)
                row.update(mean=float(v.mean()) if v.size else float("nan"), mean_ci_low=lo, mean_ci_high=hi,
                           sd=float(v.std(ddof=1)) if v.size > 1 else float("nan"),
                           median=float(np.median(v)) if v.size else float("nan"), median_ci_low=mlo,
                           median_ci_high=mhi, q05=float(np.quantile(v, 0.05)) if v.size else float("nan"),
                           q95=float(np.quantile(v, 0.95)) if v.size else float("nan"),
                           interval="Student-t 95% (mean); binomial order statistics 95% (median)")
            out.append(row)
    return out


_SUMMARY_TYPES = {"config": "int", "n_poses": "int", "n": "int", "weighted": "flag", "plan_resampled": "flag",
                  "machine": "str", "setup": "str", "plan": "str", "algorithm": "str", "method": "str",
                  "identification": "str", "metric": "str", "interval": "str", "heldout_compare": "str"}


def format_summary(rows: list[dict]) -> str:
    """``summary.csv`` text."""
    lines = [",".join(SUMMARY_HEADER)]
    for r in rows:
        lines.append(",".join(cell(r.get(k), _SUMMARY_TYPES.get(k, "float")) for k in SUMMARY_HEADER))
    return "\n".join(lines) + "\n"


def summary_lookup(rows: list[dict]) -> dict[tuple[int, str], dict]:
    """{(config, metric): summary row}."""
    return {(int(r["config"]), r["metric"]): r for r in rows}


__all__ = ["COLUMNS", "CONFIG_COLUMNS", "HELDOUT_COLUMNS", "SCALE_COLUMNS", "ResultFolder", "SUMMARY_METRICS",
           "format_row", "format_summary", "median_interval", "parse_table", "read_trials", "summarise", "t_interval",
           "wilson_interval"]

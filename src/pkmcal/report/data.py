"""The input of the calibration report: typed, self-contained, independent of the engine.

The report (:mod:`pkmcal.report.html`, :mod:`pkmcal.report.figures`) reads only these
dataclasses, so it does not depend on the internals of planning, sensors or identification;
whoever produces a calibration (``pkmcal demo``, ``pkmcal identify --report``) fills them in.

Units: lengths in mm and angles in radians, as everywhere inside pkmcal
(:mod:`pkmcal.conventions`); the report converts angles to degrees (or arc-seconds) for
display, parameters by the angle flags of :class:`ParameterTable` (never by their names). The summaries of held-out errors are

    rms = sqrt(mean(e_j²)),   max = max_j e_j,   p95 = 95th percentile of e_j

over the held-out poses j, e_j being the position error ‖p_real − p_target‖ (mm) or the
orientation error angle(R_real R_targetᵀ) (rad).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pkmcal.conventions import FILE_ANGLE_UNIT, LENGTH_UNIT
from pkmcal.errors import PkmcalError
# ρ_ij = C_ij / √(C_ii C_jj), zero-variance rows 0: the report's name for the one implementation.
from pkmcal.identification.robust import Outlier
from pkmcal.identification.uncertainty import correlation as correlation_from_covariance  # noqa: F401
from pkmcal.io.tables import to_file_units
from pkmcal.mechanisms.base import Mechanism

#: Unit in which the report shows angle parameters (as in files and on the command line).
DISPLAY_ANGLE_UNIT = FILE_ANGLE_UNIT
#: Units of residual rows (:class:`Residuals`): lengths, angles, none (whitened or mixed);
#: actuator readings in a unit of their own (a hexapod's ``actuator_unit``) carry that unit.
RESIDUAL_UNITS = ("mm", "rad", "1")


def _array(value, name: str, ndim: int | None = None) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if ndim is not None and arr.ndim != ndim:
        raise PkmcalError(f"report: '{name}' must be a {ndim}-D array; got shape {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Identifiability:
    """Rank report of the identification Jacobian (paper 2 §4, paper 3 §3).

    ``singular_values`` (k,) of the column-scaled identification Jacobian, descending;
    ``rank`` its numerical rank; ``fixed`` parameters held at nominal (gauge fixing and
    user choice); ``weak`` parameters (or combinations) that the data barely determine;
    ``null_space`` human-readable descriptions of the unidentifiable directions;
    ``condition_number`` σ_1/σ_rank, the ratio of the largest to the smallest singular
    value *within the rank* (the null directions, σ ~ 1e-16 σ_1, are not identified and
    do not count; the engine's :attr:`IdentifiabilityReport.condition_number`, which
    ``pkmcal identify`` prints); ``basis`` what the Jacobian was evaluated on.
    """

    rank: int
    n_params: int
    singular_values: np.ndarray
    fixed: tuple[str, ...] = ()
    weak: tuple[str, ...] = ()
    null_space: tuple[str, ...] = ()
    condition_number: float | None = None
    basis: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "singular_values", _array(self.singular_values, "singular_values", 1))
        for attr in ("fixed", "weak", "null_space"):
            object.__setattr__(self, attr, tuple(str(s) for s in getattr(self, attr)))
        s = np.sort(self.singular_values)[::-1]
        if self.condition_number is None and 0 < self.rank <= s.size and s[self.rank - 1] > 0:
            object.__setattr__(self, "condition_number", float(s[0] / s[self.rank - 1]))

    @classmethod
    def from_mapping(cls, d: dict) -> "Identifiability":
        """From a plain dict with keys rank, n_params, singular_values, fixed, weak,
        null_space (and optionally condition_number); unknown keys are an error."""
        allowed = {"rank", "n_params", "singular_values", "fixed", "weak", "null_space", "condition_number", "basis"}
        unknown = set(d) - allowed
        if unknown:
            raise PkmcalError(f"report: unknown identifiability keys {sorted(unknown)}; allowed {sorted(allowed)}")
        return cls(**d)


@dataclass(frozen=True, eq=False)
class ParameterTable:
    """Identified parameters against nominal: one entry per parameter of the machine (then
    the sensor parameters that were estimated, when the producer adds them).

    ``std`` is the 1σ standard uncertainty (NaN for parameters held fixed); ``free`` marks
    the estimated parameters; ``true`` (optional) the simulation's ground truth (NaN where
    unknown); ``is_angle`` which parameters are angles (rad here, shown in degrees), as the
    machine's and the sensor's ``param_is_angle`` declare them (None: all lengths, mm);
    ``param_units`` (optional) the file unit of each parameter as the machine declares it
    (``param_units``: mm, deg, or a hexapod gain's "1" / "mm/rev"; None: mm and deg by
    ``is_angle``).
    """

    names: tuple[str, ...]
    nominal: np.ndarray
    identified: np.ndarray
    std: np.ndarray
    free: np.ndarray
    true: np.ndarray | None = None
    is_angle: np.ndarray | None = None
    param_units: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        n = len(self.names)
        if self.param_units is not None:
            object.__setattr__(self, "param_units", tuple(self.param_units))
            if len(self.param_units) != n:
                raise PkmcalError(f"report: parameter table has {len(self.param_units)} units for {n} names")
        for attr in ("nominal", "identified", "std", "true"):
            if attr == "true" and self.true is None:
                continue
            arr = _array(getattr(self, attr), attr, 1)
            if arr.shape != (n,):
                raise PkmcalError(f"report: parameter table '{attr}' has {arr.size} values for {n} names")
            object.__setattr__(self, attr, arr)
        if self.is_angle is None:
            object.__setattr__(self, "is_angle", np.zeros(n, dtype=bool))
        for attr in ("free", "is_angle"):
            flags = np.array(getattr(self, attr), dtype=bool).reshape(-1)
            if flags.shape != (n,):
                raise PkmcalError(f"report: parameter table '{attr}' has {flags.size} values for {n} names")
            flags.setflags(write=False)
            object.__setattr__(self, attr, flags)

    @property
    def deviation(self) -> np.ndarray:
        return self.identified - self.nominal

    @property
    def units(self) -> tuple[str, ...]:
        """Display unit of each parameter: "deg" for angles, "mm" for lengths, else its own
        (:attr:`param_units`: a gain's "1" or "mm/rev")."""
        own = self.param_units or (LENGTH_UNIT,) * len(self.names)
        return tuple(DISPLAY_ANGLE_UNIT if a else u for a, u in zip(self.is_angle, own))

    def display(self, values: np.ndarray) -> np.ndarray:
        """``values`` (n,) of this table (nominal, identified, deviation, std, true) in the
        display units of :attr:`units`: θ_deg = θ_rad · 180/π for angles, mm unchanged
        (:func:`pkmcal.io.tables.to_file_units`, the conversion of every file)."""
        return to_file_units(values, self.is_angle)


@dataclass(frozen=True, eq=False)
class Residuals:
    """Residuals of the final fit, measured − predicted, per pose and per reading.

    ``values`` (N, m) in display-ready internal units (mm, or rad for ``unit == "rad"``);
    ``names`` (m,) the reading names (e.g. "d1", or "lambda3" for actuator residuals);
    ``units`` (m,) "mm", "rad", or "1" for rows without one physical unit (the projection's
    combinations of readings r = U⊥ᵀ W e: whitened, or mixing mm and rad), shown as computed,
    or the unit of actuator readings in a unit of their own (a hexapod's ``actuator_unit``:
    "rev", "count"), shown as they are.
    ``pose_numbers`` (N,) the number of each residual row's pose: its data row in the
    measurement file, 1-based (default 1..N); poses the fit dropped have no row here.
    """

    values: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]
    pose_numbers: np.ndarray | None = None

    def __post_init__(self) -> None:
        values = _array(self.values, "residuals", 2)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "units", tuple(self.units))
        numbers = np.arange(1, values.shape[0] + 1) if self.pose_numbers is None else \
            np.asarray(self.pose_numbers, dtype=int).reshape(-1)
        if numbers.shape != (values.shape[0],):
            raise PkmcalError(f"report: {numbers.size} pose numbers for {values.shape[0]} residual rows")
        numbers.setflags(write=False)
        object.__setattr__(self, "pose_numbers", numbers)
        if len(self.names) != values.shape[1] or len(self.units) != values.shape[1]:
            raise PkmcalError(
                f"report: residuals have {values.shape[1]} columns but {len(self.names)} names, {len(self.units)} units"
            )
        bad = [u for u in self.units if not (isinstance(u, str) and u.strip()) or u == "deg"]
        if bad:
            raise PkmcalError(f"report: residual units must be 'mm', 'rad' (angles are radians here), '1' or a "
                              f"reading unit; got {bad}")


#: A pose beyond the outlier threshold: the fit's own record
#: (:class:`pkmcal.identification.robust.Outlier`: ``pose`` its data row of the measurement
#: file, 1-based, ``sigma`` its normalised residual √(‖W r‖²/k) in noise σ, ``reading`` its
#: worst residual row and ``reading_sigma`` that row in σ, ``dropped`` whether the fit left
#: it out, ``round`` the fit round, 1-based), shared rather than copied.
OutlierRow = Outlier


@dataclass(frozen=True)
class Screening:
    """The outlier screening of the fit: ``threshold`` (σ), ``loss`` and ``f_scale`` (σ) of
    the fit, ``reject`` the rejection threshold (None: no rejection), ``rounds`` the fits
    made, ``outliers`` the poses beyond the threshold or rejected, ``max_sigma`` and
    ``median_sigma`` of the per-pose normalised residuals of the final fit."""

    threshold: float
    loss: str = "linear"
    f_scale: float = 1.0
    reject: float | None = None
    rounds: int = 1
    outliers: tuple[OutlierRow, ...] = ()
    max_sigma: float = float("nan")
    median_sigma: float = float("nan")


@dataclass(frozen=True)
class PriorRow:
    """A Gaussian prior of the fit (:mod:`pkmcal.identification.priors`), in ``unit`` (mm, or
    deg for angle parameters, as in files): ``mean`` ± ``std``, the ``estimate`` and its
    ``posterior_std`` (NaN when not estimated), ``pull`` (estimate − mean)/std (1), and
    ``source`` where the prior was written."""

    parameter: str
    unit: str
    mean: float
    std: float
    estimate: float
    posterior_std: float
    pull: float
    source: str = ""


@dataclass(frozen=True, eq=False)
class HeldOutErrors:
    """Errors at held-out poses (not used for identification), before and after.

    Each array (N,): position error (mm) and orientation error (rad) of the real machine
    when commanded with the nominal model (before) and the identified model (after).
    """

    position_before: np.ndarray
    position_after: np.ndarray
    orientation_before: np.ndarray
    orientation_after: np.ndarray

    def __post_init__(self) -> None:
        n = None
        for attr in ("position_before", "position_after", "orientation_before", "orientation_after"):
            arr = _array(getattr(self, attr), attr, 1)
            if n is not None and arr.shape != (n,):
                raise PkmcalError(f"report: held-out '{attr}' has {arr.size} values, expected {n}")
            n = arr.size
            object.__setattr__(self, attr, arr)

    @property
    def n_poses(self) -> int:
        return int(self.position_before.size)

    def summary(self) -> dict[str, dict[str, float]]:
        """``{"position_before": {"rms", "mean", "p95", "max"}, ...}`` (mm and rad)."""
        out: dict[str, dict[str, float]] = {}
        for attr in ("position_before", "position_after", "orientation_before", "orientation_after"):
            e = getattr(self, attr)
            out[attr] = summarise(e)
        return out


def summarise(e: np.ndarray) -> dict[str, float]:
    """rms, mean, 95th percentile and max of an error sample (module docstring)."""
    e = np.asarray(e, dtype=float)
    if e.size == 0:
        return {"rms": float("nan"), "mean": float("nan"), "p95": float("nan"), "max": float("nan")}
    return {
        "rms": float(np.sqrt(np.mean(e**2))),
        "mean": float(np.mean(e)),
        "p95": float(np.percentile(e, 95)),
        "max": float(np.max(e)),
    }


@dataclass(frozen=True, eq=False)
class ErrorMap:
    """Position error over a grid of target positions, before and after calibration.

    ``x`` (nx,), ``y`` (ny,) grid coordinates (mm) at height ``z`` (mm) and orientation
    ``abc`` (rad); ``before`` and ``after`` (ny, nx) position errors (mm), NaN where the
    pose is unreachable.
    """

    x: np.ndarray
    y: np.ndarray
    z: float
    before: np.ndarray
    after: np.ndarray
    abc: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        x, y = _array(self.x, "x", 1), _array(self.y, "y", 1)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        for attr in ("before", "after"):
            arr = _array(getattr(self, attr), attr, 2)
            if arr.shape != (y.size, x.size):
                raise PkmcalError(f"report: error map '{attr}' has shape {arr.shape}, expected {(y.size, x.size)}")
            object.__setattr__(self, attr, arr)


@dataclass(frozen=True)
class PosePoints:
    """Where a machine's poses put its tool, for the pose cloud and the plan summary:
    ``points`` (N, 3) mm; ``second`` (N, 3) the second point of a pose pair (a reading of two
    poses: printed-object distances; equal to ``points`` for a probe height), else None;
    ``tilt`` (N,) rad, the platform's tilt from the base z axis where the pose has roll and
    pitch (a, b), else None; ``yaw`` (N,) rad, the pose's c where it has one, else None."""

    points: np.ndarray
    second: np.ndarray | None = None
    tilt: np.ndarray | None = None
    yaw: np.ndarray | None = None


def pose_points(mechanism: Mechanism, poses: np.ndarray) -> PosePoints | None:
    """The :class:`PosePoints` of ``poses`` (N, n) of ``mechanism``, read by its pose
    coordinate names (x, y, z; a, b, c; a pose pair's x_2, y_2, z_2); None for a machine
    whose poses have no x, y, z (a planar machine's x, y, φ)."""
    from pkmcal.mechanisms.pose_pairs import SECOND

    names = list(mechanism.pose_names)
    poses = np.atleast_2d(np.asarray(poses, dtype=float))

    def columns(*wanted: str) -> np.ndarray | None:
        if not all(w in names for w in wanted) or poses.shape[1] != len(names):
            return None
        return poses[:, [names.index(w) for w in wanted]]

    points = columns("x", "y", "z")
    if points is None:
        return None
    second = columns(*(c + SECOND for c in "xyz"))
    roll_pitch = columns("a", "b")
    tilt = None if roll_pitch is None else \
        np.arccos(np.clip(np.cos(roll_pitch[:, 0]) * np.cos(roll_pitch[:, 1]), -1.0, 1.0))   # R₃₃ of Rz Ry Rx
    yaw = columns("c")
    return PosePoints(points, second, tilt, None if yaw is None else yaw[:, 0])


@dataclass(frozen=True, eq=False)
class ReportData:
    """Everything the calibration report shows (see :func:`pkmcal.report.write_report`).

    ``poses`` (N, 6) the measured (planned) poses, internal units; ``correlation`` (k, k)
    correlation matrix of the free parameters named ``correlation_names``; ``facts`` are
    extra (label, value) lines for the summary table (method, seed, setup, ...);
    ``held_out_poses`` (K, 6) the verification poses, drawn in the pose cloud;
    ``held_out_total`` how many held-out poses were given and ``held_out_dropped``
    (pose number, reason) of those left out of the comparison (pose numbers: 1-based
    rows of the held-out set), so that the report says why fewer poses were compared;
    ``screening`` the outlier screening of the fit, ``priors`` its Gaussian priors;
    ``measured_validation`` the validation on measured held-out data
    (:meth:`pkmcal.identification.heldout.HeldoutReport.to_dict`, with its ``rows``: the
    (quantity, unit, key) lines to show), None when no held-out measurements were given;
    ``calibrated_file`` and ``setup_name`` the calibrated machine file and the setup (file or
    built-in name) as a command line names them, for the commands the report's opening
    suggests (None: a placeholder is shown).
    """

    title: str
    machine_summary: str
    nominal: Mechanism
    identified: Mechanism
    poses: np.ndarray
    identifiability: Identifiability
    parameters: ParameterTable
    correlation: np.ndarray
    correlation_names: tuple[str, ...]
    residuals: Residuals
    held_out: HeldOutErrors | None = None
    error_map: ErrorMap | None = None
    setup_summary: str = ""
    facts: tuple[tuple[str, str], ...] = field(default_factory=tuple)
    held_out_poses: np.ndarray | None = None
    held_out_total: int | None = None
    held_out_dropped: tuple[tuple[int, str], ...] = ()
    screening: Screening | None = None
    priors: tuple[PriorRow, ...] = ()
    measured_validation: dict | None = None
    calibrated_file: str | None = None
    setup_name: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "priors", tuple(self.priors))
        object.__setattr__(self, "held_out_dropped", tuple((int(k), str(w)) for k, w in self.held_out_dropped))
        object.__setattr__(self, "poses", _array(self.poses, "poses", 2))
        if self.held_out_poses is not None:
            object.__setattr__(self, "held_out_poses", _array(self.held_out_poses, "held_out_poses", 2))
        corr = _array(self.correlation, "correlation", 2)
        names = tuple(self.correlation_names)
        if corr.shape != (len(names), len(names)):
            raise PkmcalError(f"report: correlation matrix {corr.shape} does not match {len(names)} names")
        object.__setattr__(self, "correlation", corr)
        object.__setattr__(self, "correlation_names", names)
        object.__setattr__(self, "facts", tuple((str(k), str(v)) for k, v in self.facts))
        if isinstance(self.identifiability, dict):
            object.__setattr__(self, "identifiability", Identifiability.from_mapping(self.identifiability))

"""The identification engine: one noise-weighted nonlinear least-squares fit for every method.

Unknowns θ = [ρ; s] (mechanism parameters ``Mechanism.param_names``, then sensor
parameters ``Sensor.param_names``), a free subset chosen by name (shell patterns allowed),
and per pose the nuisance pose x_j, eliminated by the method (:mod:`.residuals`:
``ik-residual`` paper 1 §V eq. 3, ``fk-residual`` paper 2 §3 eq. 3, ``projection`` paper 3
§2 eq. 4–10). The fit is

    θ̂ = argmin_θ Σ_j ‖W_j r_j(θ)‖²,    W_j = L_j⁻¹,  L_j L_jᵀ = Σ_j                 (GLS)

with Σ_j the covariance that the sensor and actuator noise induce on pose j's residual
(generalised least squares = maximum likelihood for Gaussian noise; ``weighted=False``
gives the papers' plain fits, W_j = I). The weights are computed **once, at the start**
(nominal machine, initial poses) and held fixed: the objective is then a fixed sum of
squares whose Jacobian is exactly W_j ∂r_j/∂θ (re-weighting at every iterate would make
the Jacobian miss ∂W/∂θ and can stall the solver), and Σ_j changes only by O(δρ/L) ~ 1 %
between the nominal and the identified machine, which moves the estimate by a
second-order amount. The reported covariance uses weights recomputed at the solution.

Solved by Levenberg–Marquardt as in paper 1 (MINPACK ``lmder`` through
:func:`scipy.optimize.leastsq`, see :func:`_least_squares`) or, for under-determined starts,
trust-region-reflective (:func:`scipy.optimize.least_squares`), with the analytic Jacobian
and Jacobian-based variable scaling (``x_scale="jac"``), to ``ftol = xtol = gtol`` =
:data:`TOLERANCE`. Before fitting, the requested free set is checked on the whitened start
Jacobian (:class:`~pkmcal.identification.identifiability.ScaledJacobian`): a QR and a
triangular inverse prove full rank when they can, else the full analysis (SVD, null
space, gauge) runs; an unidentifiable set is a :class:`PkmcalError` naming the
unobservable combination and what to fix; by default the engine fixes the suggested gauge
itself (``fix="auto"``). When the rank was proven, the result's identifiability report is
computed on first use. A solver's stop is a success only when the residual there reproduces
the cost the solver saw and shows no descent (:func:`_checked`; evaluated by a new method
object where the method's pose solves start from earlier points).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.identifiability import (
    RANK_RTOL,
    WEAK_RATIO,
    IdentifiabilityReport,
    ScaledJacobian,
    format_direction,
)
from pkmcal.identification.residuals import (
    METHODS,
    Method,
    Model,
    candidate_parameters,
    default_method,
    make_method,
    single_threaded_blas,
    whitening,
)
from pkmcal.identification.priors import NO_PRIORS, PriorObjective, ResolvedPriors, check_free, check_plausible, resolve
from pkmcal.identification.robust import (
    OUTLIER_SIGMA,
    ROBUST_UNITS,
    Screening,
    check_loss,
    masked_loss,
    robust_dict,
    robust_uncertainty,
    screen,
)
from pkmcal.identification.uncertainty import Uncertainty, embed, parameter_uncertainty
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import MeasurementSetup, Sensor
from pkmcal.sensors.sessions import Sessions, SessionSensor, session_setup_values

#: A fit fails (error) when more than this fraction of the poses has no FK / pose solution.
MAX_DROPPED_FRACTION = 0.1

#: Default ``ftol`` = ``xtol`` = ``gtol`` of the solver. The residuals are exact to ~1e-12
#: relative (IK, and FK polished to rounding), so the cost is known to ~1e-12 relative and
#: tighter tolerances only chase rounding: on the paper-1 fit, 1e-12 took 10 residual and
#: 6 Jacobian evaluations, the last four residuals differing in the 12th digit, and 1e-10
#: took 6 and 5 to the same cost and estimate (all digits printed; 2026-11-22). A relative
#: parameter change of 1e-10 is ~1e-8 mm on a 100 mm parameter, far below any noise.
TOLERANCE = 1e-10


class _DeferredTuple:
    """A dataclass field (descriptor) holding a tuple that may be given as a zero-argument
    callable instead, called once on first read: the engine defers the weak-direction
    warnings, which need the SVD of the identifiability analysis, until someone reads them
    (``dataclasses.replace`` and ``==`` read them, so they see the full tuple)."""

    def __set_name__(self, owner, name):
        self._slot = "_deferred_" + name

    def __get__(self, obj, owner=None):
        if obj is None:
            return ()                                   # the field's default
        value = obj.__dict__[self._slot]
        if callable(value):
            value = obj.__dict__[self._slot] = tuple(value())
        return value

    def __set__(self, obj, value):
        obj.__dict__[self._slot] = value if callable(value) else tuple(value)


@dataclass(frozen=True)
class ParameterEstimate:
    """One parameter of a fit, in file units (``unit``: "mm", "deg" for angles, or the
    machine's declared unit, e.g. "1" or "mm/rev" for a hexapod's leg gains):
    ``initial`` and ``value`` (the estimate), ``std`` its 1σ (the covariance the fit summary
    names; None unless ``status`` is "estimated"), ``status`` "estimated", "held" (fixed by
    the user, the setup or the machine's defaults) or "gauge" (fixed by the engine: the data
    cannot see it, so its value is a convention, not a measurement)."""

    name: str
    unit: str
    initial: float
    value: float
    std: float | None
    status: str


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of :func:`identify` (numbers in internal units: mm, rad).

    Attributes
    ----------
    mechanism, sensor : the calibrated machine (with ``covariance`` where supported, full
        size, zeros for fixed parameters) and the calibrated sensor.
    method, weighted : the method and whether the fit was noise-weighted.
    names : all parameter names (machine then sensor); ``free`` / ``fixed`` the split
        (``fixed`` includes sensor parameters held at their values); ``gauge`` the
        parameters the engine fixed automatically (empty when identifiable as asked).
    initial, estimate : full parameter vectors before / after (len(names),).
    x : the free parameters' estimates (len(free),), with ``std`` and ``covariance``
        (the file covariance, see :mod:`.uncertainty`) and ``correlation``.
    uncertainty : both covariances (a priori, a posteriori), χ² and degrees of freedom.
    residuals : raw residuals per pose (N, k) at the solution; ``residuals_weighted`` whitened.
    poses : the eliminated nuisance poses (N, n) at the solution.
    used_poses : indices (into the input) of the poses used; ``dropped`` those left out.
    cost : ½ Σ ‖W r‖²; ``nfev``, ``njev``, ``status``, ``success``, ``message`` from the solver.
    identifiability : the report on the candidate parameters at the start (a property,
        computed on first use from ``identifiability_analysis`` when not needed by the fit).
    warnings : human-readable notes (dropped poses, auto-fixed gauge, outliers, weak
        directions, …); the weak-direction ones come from the identifiability report, so
        when the fit did not need that report they are computed on first read, with it.
    screening : per-pose normalised residuals and the outliers (:mod:`.robust`; None when
        the noise model cannot whiten); ``priors`` the Gaussian priors of the fit
        (:mod:`.priors`); ``loss`` the scipy loss of the fit ("linear": least squares).
    """

    mechanism: Mechanism
    sensor: Sensor
    method: str
    weighted: bool
    names: tuple[str, ...]
    free: tuple[str, ...]
    fixed: tuple[str, ...]
    initial: np.ndarray
    estimate: np.ndarray
    uncertainty: Uncertainty
    residuals: np.ndarray
    residuals_weighted: np.ndarray
    residual_names: tuple[str, ...]
    poses: np.ndarray
    used_poses: np.ndarray
    dropped: np.ndarray
    cost: float
    nfev: int
    njev: int
    status: int
    success: bool
    message: str
    identifiability_analysis: Callable[[], IdentifiabilityReport] = field(repr=False, compare=False)
    gauge: tuple[str, ...] = ()
    warnings: tuple[str, ...] = _DeferredTuple()
    #: Unit of each residual row ("mm", "rad", or "1" for whitened / mixed rows).
    residual_units: tuple[str, ...] = ()
    screening: Screening | None = None
    priors: ResolvedPriors = NO_PRIORS
    loss: str = "linear"
    #: (N,) the file's pose numbers (1-based data rows, docs/conventions.md) of the N poses
    #: given; None: 1 … N
    pose_numbers: np.ndarray | None = None
    #: angle flags of :attr:`names` (empty: the machine's then the sensor's)
    param_is_angle: tuple[bool, ...] = ()
    #: the sessions of the poses fitted (:mod:`pkmcal.sensors.sessions`); None: one session
    sessions: Sessions | None = None
    #: (N, k) the residual entries that are measurements where some are not (a printed
    #: object's pair rows measure one of their two readings); None: all
    measured: np.ndarray | None = None

    @cached_property
    def identifiability(self) -> IdentifiabilityReport:
        """The identifiability report on the candidate parameters at the start, computed
        on first use when the fit could prove full rank without it
        (:meth:`~pkmcal.identification.identifiability.ScaledJacobian.certainly_full_rank`)."""
        return self.identifiability_analysis()

    @property
    def free_index(self) -> np.ndarray:
        return np.array([self.names.index(n) for n in self.free], dtype=int)

    @property
    def x(self) -> np.ndarray:
        return self.estimate[self.free_index]

    @property
    def covariance(self) -> np.ndarray:
        return self.uncertainty.covariance

    @property
    def std(self) -> np.ndarray:
        return self.uncertainty.std

    @property
    def correlation(self) -> np.ndarray:
        return self.uncertainty.correlation

    @property
    def verdict(self):
        """Whether this fit may be written as a calibration (:func:`.fit_verdict.judge`:
        converged, finite, χ² within what the noise model allows); ``pkmcal identify``
        refuses to write it otherwise."""
        from pkmcal.identification.fit_verdict import judge

        return judge(self)

    def _rms(self, r: np.ndarray, cols=slice(None)) -> float:
        """√(mean r²) of the entries of columns ``cols`` of ``r`` (N, k) that are measurements
        (:attr:`measured`)."""
        kept = np.ones(r.shape, dtype=bool) if self.measured is None else self.measured
        n = int(np.count_nonzero(kept[:, cols]))
        return float(np.sqrt(np.sum(r[:, cols] ** 2) / n)) if n else float("nan")

    @property
    def rms_residual(self) -> float:
        """√(mean r²) over every raw residual row and pose (measured − predicted; the entries
        that are measurements), whatever their units: a single number only when all rows
        share one unit (see :meth:`rms_by_unit`)."""
        return self._rms(self.residuals)

    def rms_by_unit(self) -> dict[str, float]:
        """{unit: rms} of the raw residuals over the rows of each unit, angles in degrees:
        keys "mm", "deg" and "1" (whitened or mixed rows), then any other reading unit (a
        hexapod's ``actuator_unit``: "rev", ...), only those present."""
        units = self.residual_units or ("1",) * self.residuals.shape[1]
        out = {}
        known = (("mm", "mm", 1.0), ("rad", "deg", float(np.rad2deg(1.0))), ("1", "1", 1.0))
        others = tuple((u, u, 1.0) for u in dict.fromkeys(units) if u not in ("mm", "rad", "1"))
        for unit, shown, scale in known + others:
            cols = [k for k, un in enumerate(units) if un == unit]
            if cols and self.residuals.size:
                out[shown] = self._rms(self.residuals, cols) * scale
        return out

    @property
    def rms_whitened(self) -> float:
        """√(χ²/M): rms of the whitened residuals at the solution (weights recomputed there),
        1 when the residuals are as large as the noise model says (unit 1)."""
        return self._rms(self.residuals_weighted) if self.residuals_weighted.size else float("nan")

    def angle_names(self) -> tuple[str, ...]:
        """The parameters that are angles (the machine's and the sensor's ``param_is_angle``)."""
        flags = self.param_is_angle or tuple(self.mechanism.param_is_angle) + tuple(self.sensor.param_is_angle)
        return tuple(n for n, a in zip(self.names, flags) if a)

    @property
    def parameters(self) -> tuple[ParameterEstimate, ...]:
        """One :class:`ParameterEstimate` per parameter of :attr:`names`, in that order, in
        file units: names, values and uncertainties line up (``std`` is over :attr:`free`
        only; here a held or gauge parameter has ``std`` None, never a number)."""
        angles = set(self.angle_names())
        deg = float(np.rad2deg(1.0))
        gauge, free = set(self.gauge), {n: k for k, n in enumerate(self.free)}
        p = len(self.mechanism.param_names)
        units = tuple(self.mechanism.param_units) + tuple("deg" if n in angles else "mm" for n in self.names[p:])
        out = []
        for i, n in enumerate(self.names):
            s = deg if n in angles else 1.0
            k = free.get(n)
            out.append(ParameterEstimate(
                name=n, unit=units[i], initial=float(self.initial[i]) * s,
                value=float(self.estimate[i]) * s, std=None if k is None else float(self.std[k]) * s,
                status="estimated" if k is not None else "gauge" if n in gauge else "held"))
        return tuple(out)

    def session_values(self) -> dict[str, dict]:
        """The identified sensor of every session in setup-file form, file units (mm,
        degrees): {label: {"world": {"x": …, …}, "tool": {…}, "zero": […], …, "dq": […]}}
        (``dq`` the re-homing offsets of the sessions after the first, when fitted, mm or
        degrees per actuator); empty with one session
        (:func:`~pkmcal.sensors.sessions.session_setup_values`)."""
        if self.sessions is None or not self.sessions.several:
            return {}
        offsets = {}
        names = set(self.names)
        l = self.mechanism.n_actuators
        for lab in self.sessions.labels[1:]:
            keys = [f"dq_{i + 1}@{lab}" for i in range(l)]
            if keys[0] in names:
                offsets[lab] = np.array([self.estimate[self.names.index(k)] for k in keys])
        return session_setup_values(self.sensor, offsets, self.mechanism.actuator_is_angle)

    def pose_number(self, i: int) -> int:
        """The file's number of pose index ``i`` (0-based in the poses given)."""
        return int(i) + 1 if self.pose_numbers is None else int(self.pose_numbers[i])

    def to_dict(self) -> dict:
        """A JSON-ready summary. Units as every pkmcal JSON states them (docs/conventions.md):
        parameters in file units (mm, degrees for angle parameters, each with its ``unit``),
        the other numbers named in ``units``."""
        u = self.uncertainty
        angles = set(self.angle_names())
        deg = float(np.rad2deg(1.0))

        def conv(n: str, v: float) -> float:
            return float(v) * (deg if n in angles else 1.0)

        rms = self.rms_by_unit()
        row_units = sorted(set(self.residual_units))
        if row_units == ["rad"]:
            rms_unit = "rad (kept as it was; residual_rms_deg gives it in degrees)"
        elif len(row_units) == 1:
            rms_unit = row_units[0]
        else:
            rms_unit = "mixed: one rms over rows of different units; see residual_rms_mm, residual_rms_deg"
        return {
            "method": self.method,
            "weighted": self.weighted,
            "success": self.success,
            "status": self.status,
            "message": self.message,
            "cost": self.cost,
            "nfev": self.nfev,
            "njev": self.njev,
            "n_poses": int(len(self.used_poses)),
            "dropped_poses": [int(self.pose_number(i)) for i in self.dropped],
            "free": list(self.free),
            "fixed": list(self.fixed),
            "gauge": list(self.gauge),
            "parameters": {
                n: {"unit": "deg" if n in angles else "mm",
                    "initial": conv(n, self.initial[i]), "estimate": conv(n, self.estimate[i]),
                    **({"std": conv(n, u.std[self.free.index(n)]),
                        "std_prior": conv(n, u.std_prior[self.free.index(n)]),
                        "std_posterior": conv(n, u.std_posterior[self.free.index(n)])} if n in self.free else {})}
                for i, n in enumerate(self.names)
            },
            "chi2": u.chi2,
            "dof": u.dof,
            "reduced_chi2": u.reduced_chi2,
            "chi2_expected": u.chi2_expected,
            "birge_ratio": u.birge_ratio,
            "covariance_kind": u.kind,
            "covariance_in_file": u.description,
            "rms_residual": self.rms_residual,
            **{f"residual_rms_{'whitened_mixed' if k == '1' else k}": v for k, v in rms.items()},
            "rms_whitened": self.rms_whitened,
            "residual_names": list(self.residual_names),
            "residual_units": [{"rad": "deg"}.get(un, un) for un in self.residual_units],
            "identifiability": self.identifiability.to_dict(),
            "warnings": list(self.warnings),
            **robust_dict(self),
            **({"sessions": {"labels": list(self.sessions.labels),
                             "n_poses": {lab: int(c) for lab, c in zip(self.sessions.labels, self.sessions.counts())},
                             "actuator_offsets": bool(self.sessions.offsets),
                             "values": self.session_values()}}
               if self.sessions is not None and self.sessions.several else {}),
            "units": {
                "cost": ("1: 1/2 sum |W0 r|^2, residuals whitened with the weights at the start (held fixed "
                         "during the fit)") if self.weighted else
                        "1/2 sum r^2 of the raw residuals, in their units squared (mm^2, rad^2)",
                "nfev": "1", "njev": "1", "status": "1", "n_poses": "1",
                "dropped_poses": "1: pose numbers = data rows of the measurement file, 1-based",
                "chi2": "1: sum |W r|^2 with the weights at the solution", "dof": "1", "reduced_chi2": "1",
                "chi2_expected": "1: E[chi2] under the noise model (dof for weighted fits)",
                "birge_ratio": "1: chi2 / chi2_expected",
                **({"sessions": "labels in order of first appearance in the file; n_poses: poses fitted per "
                                "session; values: each session's sensor in setup-file form, mm and deg"}
                   if self.sessions is not None and self.sessions.several else {}),
                "rms_residual": rms_unit,
                "residual_rms_whitened_mixed": "1", "rms_whitened": "1",
                **ROBUST_UNITS,
            },
        }


# -- input handling ---------------------------------------------------------------------


def measurement_arrays(measurements) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(q, y, commanded)`` from a measurements object, a mapping or a tuple.

    Accepts an object or mapping with ``actuators``/``q`` and ``readings``/``y`` (and
    optionally ``commanded``), or a tuple ``(q, y)`` / ``(q, y, commanded)``.
    """
    if isinstance(measurements, (tuple, list)):
        if len(measurements) not in (2, 3):
            raise PkmcalError("measurements must be (q, y) or (q, y, commanded)")
        q, y, *rest = measurements
        return np.asarray(q, float), np.asarray(y, float), (None if not rest or rest[0] is None else np.asarray(rest[0], float))

    def get(*keys):
        for k in keys:
            v = measurements.get(k) if isinstance(measurements, dict) else getattr(measurements, k, None)
            if v is not None:
                return v
        return None

    q = get("actuators", "q", "actuator_readings")
    y = get("readings", "y", "sensor_readings")
    if q is None or y is None:
        raise PkmcalError("measurements need actuator readings (q) and sensor readings (y)")
    cmd = get("commanded", "commanded_poses")
    return np.asarray(q, float), np.asarray(y, float), (None if cmd is None else np.asarray(cmd, float))


def measurement_sessions(measurements, sessions, n: int, offsets: bool) -> Sessions | None:
    """The sessions of the n poses: ``sessions`` (a :class:`Sessions` or per-pose labels)
    if given, else the measurements' own (``Measurements.sessions``, the file's ``session``
    column); None for one session. ``offsets`` turns on the re-homing offsets."""
    if sessions is None:
        sessions = getattr(measurements, "sessions", None) if measurements is not None else None
    if sessions is None:
        return None
    if not isinstance(sessions, Sessions):
        sessions = Sessions.from_labels(sessions)
    if len(sessions) != n:
        raise PkmcalError(f"{len(sessions)} session labels for {n} measured poses")
    return sessions.with_offsets(offsets) if sessions.several else None


# -- the engine -------------------------------------------------------------------------


class _Objective:
    """Whitened residual and Jacobian of the free parameters.

    ``fun`` evaluates the residual only; ``jac`` the Jacobian at the same point, reusing
    the method's cached poses (:meth:`Method._at`), so a rejected trial step costs no
    Jacobian and an accepted one no second pose solve. The finite-difference comparison
    (``jac="2-point"``) calls the same ``fun``: only the Jacobian differs.

    A trial point where a pose's FK or pose solve fails (every pose solved at the start) is
    a machine that cannot have produced that measurement: ``fun`` returns NaN for its rows,
    which the solvers treat as a failed step and shrink (MINPACK counts a non-finite norm
    as no reduction; ``least_squares`` shrinks its trust region). A finite stand-in there
    (the fk-residual's residual at the pose's last solved pose, whose Jacobian row is no
    derivative of it) let Levenberg–Marquardt accept such a machine and stop on it.
    """

    def __init__(self, method: Method, theta0: np.ndarray, free: np.ndarray, W: np.ndarray | None):
        self.method, self.theta0, self.free, self.W = method, theta0, free, W
        self._th = theta0.copy()
        # a contiguous run of free columns is taken as a view, not a fancy-indexed copy
        contiguous = free.size > 0 and np.array_equal(free, np.arange(free[0], free[0] + free.size))
        self._cols = slice(int(free[0]), int(free[0]) + free.size) if contiguous else free

    def theta(self, x):
        th = self.theta0.copy()
        th[self.free] = x
        return th

    def fun(self, x):
        self._th[self.free] = x
        ev = self.method.evaluate(self._th, jac=False, cov=False)
        r = ev.r
        if self.W is not None:
            r = (self.W @ r[..., None])[..., 0]
        if not ev.converged.all():
            r = np.where(ev.converged[:, None], r, np.nan)      # a failed step (class docstring)
        return r.ravel()

    def jac(self, x):
        self._th[self.free] = x
        J = self.method.evaluate(self._th, jac=True, cov=False).J[:, :, self._cols]
        if self.W is not None:
            J = self.W @ J
        return J.reshape(-1, J.shape[-1])


def _registered(model: Model, cand: list[int], notes: list[str], **kw) -> Model:
    """Several sessions: the model with each session's free sensor parameters started from
    a registration on its own poses with the machine held at its values (and no offsets) —
    a fit of those columns only, cheap, in which the sessions do not interact.
    From the values given, a joint fit of sessions whose frames differ by a large rotation
    can stop in a local minimum (two position-sensor sessions whose worlds differ by 0.2 rad
    about z: rms 85 mm from the given start, 1e-13 mm from the registered one). The
    registration is an fk-residual fit where the machine has one (not redundant). Unchanged
    when no sensor parameter or no machine parameter is free, or the registration fails."""
    p, s = model.n_mech, model.n_sensor
    sensor_free = [model.names[i] for i in cand if i >= p]
    if not any(i < p for i in cand) or not any(p <= i < p + s for i in cand):
        return model
    sensors = model.sensor.sensors
    setup = MeasurementSetup(sensors[0], model.noise, session_sensors=tuple(zip(model.sessions.labels, sensors)))
    mech = model.mechanism
    if mech.n_actuators == mech.n_dof:
        # through FK, which does not depend on the sensor: no pose solve that a far start
        # (a world frame 1.5 rad and 500 mm away) can break, as the projection's can
        kw = {**kw, "method": "fk-residual"}
    try:
        reg = _identify(model.mechanism, setup, None, free=sensor_free, fix="auto", form="plain", jac="analytic",
                        solver="auto", ftol=TOLERANCE, xtol=TOLERANCE, gtol=TOLERANCE, q=model.q, y=model.y,
                        commanded=model.commanded, sessions=model.sessions, session_offsets=False,
                        register=False, **kw)
    except PkmcalError:
        return model
    if not reg.success:
        return model
    notes.append("sessions: the fit started from each session's sensor parameters registered on its poses with "
                 "the machine held (rms residual there " + ", ".join(
                     f"{v:.3g} " + ("(whitened or mixed rows)" if u == "1" else u) for u, v in reg.rms_by_unit().items())
                 + ")")
    start = SessionSensor(reg.sensor.sensors, model.sessions)
    out = Model(model.mechanism, start, model.noise, model.q, model.y, model.commanded, model.sessions)
    return out


def _where(measurements, idx) -> str:
    """' [file, line 12; ...]' for poses ``idx`` when the measurements know their source."""
    where = getattr(measurements, "where", None)
    if where is None or getattr(measurements, "source", None) is None or len(idx) == 0:
        return ""
    return " [" + "; ".join(where(int(k)) for k in idx[:5]) + (" ..." if len(idx) > 5 else "") + "]"


#: MINPACK ``info`` → (``least_squares`` status, message), so that both entry points report alike.
_MINPACK_STATUS = {
    0: (-1, "Improper input parameters status returned from MINPACK."),
    1: (2, "`ftol` termination condition is satisfied."),
    2: (3, "`xtol` termination condition is satisfied."),
    3: (4, "Both `ftol` and `xtol` termination conditions are satisfied."),
    4: (1, "`gtol` termination condition is satisfied."),
    5: (0, "The maximum number of function evaluations is exceeded."),
    6: (2, "`ftol` termination condition is satisfied (no further reduction possible in machine precision)."),
    7: (3, "`xtol` termination condition is satisfied (no further improvement possible in machine precision)."),
    8: (1, "`gtol` termination condition is satisfied (residual orthogonal to the Jacobian in machine precision)."),
}


@dataclass(frozen=True)
class _Solution:
    x: np.ndarray
    cost: float
    nfev: int
    njev: int
    status: int
    message: str
    #: the objective's residual vector at ``x`` as the solver saw it (None: not kept)
    fun: np.ndarray | None = None

    @property
    def success(self) -> bool:
        return self.status > 0


#: :func:`_checked`: how far ½‖f‖² at the solver's stop may differ from a fresh evaluation at
#: the same θ, and how much lower the fresh linear model may put it (relative to ½‖f‖² + 1)
#: along a step longer than this fraction of the scaled parameters. Every method's residual
#: is exact to ~1e-12 relative (poses solved to rounding; the projection's Gauss–Newton to
#: steps of 1e-12 of the pose), so a point that reproduces agrees to ~1e-10 at worst; at a
#: stop by ``ftol`` = ``xtol`` = 1e-10 (:data:`TOLERANCE`) the decrease left and the step to
#: it are of the order of the last step's, 1e-10; the "+ 1" is a χ² change of 2e-6
#: (weighted) or (1e-3 mm)² on one row (unweighted), far below what any fit resolves.
CHECK_RTOL = 1e-6

#: ``status`` of a fit whose stop the fresh evaluation did not confirm (:func:`_checked`):
#: the residual there is not what the solver saw, or the point is no minimum of it.
STATUS_NOT_REPRODUCED = -2
STATUS_NOT_STATIONARY = -3


def _checked(sol: _Solution, fresh, least_squares: bool = True) -> _Solution:
    """``sol``, confirmed by the objective ``fresh`` evaluated at its point (the solver's own
    where the method's residual is a function of θ alone, ``Method.path_independent``; else
    one on a new method object, whose pose solves start from the commanded poses and not from
    the fit's earlier points), or ``sol`` as a failure:

    * :data:`STATUS_NOT_REPRODUCED` where ½‖f‖² there is not what the solver saw;
    * :data:`STATUS_NOT_STATIONARY` (``least_squares``: a sum-of-squares objective, no robust
      loss) where the linear model of the fresh residual and Jacobian promises, along
      steepest descent (the Cauchy step t g, g = Jᵀf in column-scaled variables z = D x,
      t = ‖g‖²/‖J g‖²), a decrease of ½‖f‖² by more than :data:`CHECK_RTOL` (½‖f‖² + 1)
      with a step longer than :data:`CHECK_RTOL` ‖D x‖ (10⁴ times the solver's own
      ``ftol`` and ``xtol``): the solver stopped (``xtol``: every shorter step rejected) at
      no minimum, e.g. because its trial points' residuals were not those of the fit, or
      could not be evaluated (a pose unsolvable there). The step's length matters where
      the noise is at rounding level: a fit to 1e-12 mm noise stopped on ``xtol`` 4.6e-5
      of its cost above the model's minimum, 4e-17 of the parameters away. Over 471 stops the
      solver called a success in the tests of the engine, the methods, priors, robust fits,
      sessions, gains, the CLI pipeline and the FK branches, the largest relative decrease
      was that 4.6e-5 and the longest step 4e-9; main's stop below: 0.83 and 2e-3.

    main's fk-residual FK, warm-started from the previous evaluation's poses, put a tracker
    campaign's pose on another FK solution after a far trial point; every trial point near
    the iterate then cost 1.2e8 where the residual from the commanded poses gives ~2.8e6
    falling to 5.568, and Levenberg–Marquardt stopped on ``xtol`` at 2.8e6 with success.
    Rows not finite in both (poses unsolved) are left out of the comparison."""
    if sol.fun is None or not sol.success:
        return sol
    f = fresh.fun(sol.x)
    both = np.isfinite(f) & np.isfinite(sol.fun)
    seen, again = 0.5 * float(sol.fun[both] @ sol.fun[both]), 0.5 * float(f[both] @ f[both])
    allowed = CHECK_RTOL * (seen + 1.0)
    if abs(again - seen) > allowed:
        return dataclasses.replace(
            sol, status=STATUS_NOT_REPRODUCED,
            message=f"the solver stopped ({sol.message.rstrip('.')}) where it saw the cost {seen:.6g}, but the "
                    f"residual at that point, evaluated afresh, gives {again:.6g}: its residuals depended on the "
                    "order of evaluation (pose solves started from earlier trial points), so the stop is no "
                    "converged fit")
    if least_squares:
        # the decrease the fresh residual's linear model promises along steepest descent,
        # ½ t ‖g‖²: not the full Gauss–Newton step, which jumps along the weak directions
        # (30 residuals for 30 parameters: it promised cost 0 at the minimum of cost 5.568)
        J = fresh.jac(sol.x)[both]
        col = np.linalg.norm(J, axis=0)
        col = np.where(col > 0, col, 1.0)
        g = (J / col).T @ f[both]
        Jg = (J / col) @ g
        curvature = float(Jg @ Jg)
        t = float(g @ g) / curvature if curvature > 0 else 0.0
        model = again - 0.5 * t * float(g @ g)
        step = t * float(np.linalg.norm(g)) / max(float(np.linalg.norm(col * sol.x)), 1e-300)
        if again - model > allowed and step > CHECK_RTOL:
            return dataclasses.replace(
                sol, status=STATUS_NOT_STATIONARY,
                message=f"the solver stopped ({sol.message.rstrip('.')}) at cost {again:.6g}, which is no minimum: "
                        f"the residual's gradient there, evaluated afresh, promises {model:.6g} along steepest "
                        "descent (the solver's trial points near it had other residuals, or poses it could not solve)")
    return sol


def _least_squares(obj: "_Objective", x0: np.ndarray, *, jac: str, method: str, ftol: float, xtol: float,
                   gtol: float, max_nfev: int | None, loss: str = "linear", f_scale: float = 1.0,
                   n_data: int = 0) -> _Solution:
    """Solve the whitened problem with the analytic Jacobian or a scipy finite-difference one.

    Levenberg–Marquardt is MINPACK's ``lmder`` in every case, with the same tolerances,
    ``factor = 100``, Jacobian-based scaling (``x_scale="jac"`` ⇔ MINPACK ``diag=None``),
    evaluation cap (default 100·n) and start. With the analytic Jacobian it is called
    through :func:`scipy.optimize.leastsq`: the paper-1 ik-residual fit (15 poses, 90 × 42)
    took 1.15 ms there and 1.44 ms through ``least_squares(method="lm")``, whose wrapper
    also evaluates one more Jacobian at the solution (best of 30 solver calls, residuals
    and Jacobians included; 2-core Xeon, 2026-11-22, second session). With
    ``jac="2-point"`` / ``"3-point"`` it is called
    through :func:`scipy.optimize.least_squares`, whose finite-difference Jacobian feeds
    the same ``lmder``. ``trf`` / ``dogbox`` always use ``least_squares``. A robust ``loss``
    applies to the first ``n_data`` residuals (:func:`~pkmcal.identification.robust.masked_loss`),
    from the least-squares solution.
    """
    from scipy.optimize import least_squares, leastsq  # on first use: scipy.optimize takes ~0.3 s to import

    n = x0.size
    if method == "lm" and jac == "analytic":
        x, _, info, _, ier = leastsq(obj.fun, x0, Dfun=obj.jac, full_output=True, ftol=ftol, xtol=xtol, gtol=gtol,
                                     maxfev=100 * n if max_nfev is None else max_nfev, factor=100.0, diag=None)
        f = info["fvec"]
        status, message = _MINPACK_STATUS.get(int(ier), (-1, f"MINPACK returned info={ier}"))
        return _Solution(x=np.asarray(x, dtype=float), cost=0.5 * float(f @ f), nfev=int(info["nfev"]),
                         njev=int(info["njev"]), status=status, message=message, fun=np.asarray(f))
    start = None
    if loss != "linear":
        # from the nominal machine every pose is many σ off (the machine's errors are what is
        # identified), where a robust loss is flat and the trust region stops far from the
        # minimum: start from the least-squares solution (soft_l1 from nominal stopped 168 σ
        # away on a 100-pose fk-residual fit with a 5 mm outlier; 0.4 σ from least squares).
        # A redescending loss (cauchy) is not convex: it finds the minimum of the basin the
        # least-squares fit is in, and a gross outlier that drags that fit far needs --reject
        start = _least_squares(obj, x0, jac=jac, method="lm" if obj.fun(x0).size >= n else "trf", ftol=ftol,
                               xtol=xtol, gtol=gtol, max_nfev=max_nfev)
        x0 = start.x
    robust = {} if loss == "linear" else {"loss": masked_loss(loss, n_data), "f_scale": f_scale}
    x_scale = "jac"
    if start is not None:
        # variables scaled by the least-squares Jacobian: scaled by the robust one (which
        # down-weights the outlying rows) the trust region collapsed, steps below xtol far
        # from the minimum (soft_l1, a 20 mm outlier among 100 poses: 716 σ off; 0.4 σ so)
        col = np.linalg.norm(obj.jac(x0), axis=0)
        x_scale = 1.0 / np.where(col > 0, col, 1.0)
    sol = least_squares(obj.fun, x0, jac=obj.jac if jac == "analytic" else jac, method=method, x_scale=x_scale,
                        ftol=ftol, xtol=xtol, gtol=gtol, max_nfev=max_nfev, **robust)
    extra = (0, 0) if start is None else (start.nfev, start.njev)
    return _Solution(x=sol.x, cost=float(sol.cost), nfev=int(sol.nfev) + extra[0],
                     njev=int(sol.njev or 0) + extra[1], status=int(sol.status), message=str(sol.message),
                     fun=np.asarray(sol.fun))


def _gauss_newton_step(obj: "_Objective", x0: np.ndarray) -> _Solution:
    """One Gauss–Newton step x = x0 − J⁺ r at the start (paper 3 eq. 10 solved once), by
    least squares on the column-scaled Jacobian (the free set is identifiable: full rank)."""
    r = obj.fun(x0)
    J = obj.jac(x0)
    col = np.linalg.norm(J, axis=0)
    d = 1.0 / np.where(col > 0, col, 1.0)
    x = x0 - np.linalg.lstsq(J * d, r, rcond=None)[0] * d
    f = obj.fun(x)
    return _Solution(x=x, cost=0.5 * float(f @ f), nfev=2, njev=1, status=1,
                     message="one Gauss-Newton step from the start (single linearisation)")


def _short_direction(direction: dict[str, float], terms: int = 6) -> str:
    """The ``terms`` largest coefficients of a direction, formatted, "+ …" when cut."""
    top = dict(sorted(direction.items(), key=lambda kv: -abs(kv[1]))[:terms])
    return format_direction(top) + (" + …" if len(direction) > terms else "")


def fit_warnings(report: IdentifiabilityReport | None, free: tuple[str, ...], unc: Uncertainty,
                 angle_names: tuple[str, ...] = ()) -> list[str]:
    """Warnings on a fit's result: every weakly identifiable direction of ``report`` (σ/σ₁
    below :data:`~pkmcal.identification.identifiability.WEAK_RATIO`), with the largest
    standard deviation among its free parameters (mm; degrees for ``angle_names``), and a
    χ² beyond what the noise model allows (:mod:`.fit_verdict`: refused by
    ``pkmcal identify`` beyond :data:`~.fit_verdict.NOISE_SLACK`, warned below it)."""
    from pkmcal.identification.fit_verdict import NOISE_SLACK, beyond_noise, chi2_warning

    out = []
    std = dict(zip(free, unc.std))
    for w in [] if report is None else report.weak:
        d = w["direction"]
        named = [n for n in d if n in std]
        text = (f"weakly identifiable direction (sigma/sigma_1 = {w['ratio']:.2g}: the noise is amplified about "
                f"{1.0 / w['ratio']:.2g} times more along it than along the best-determined one): "
                f"{_short_direction(d)}")
        if named:
            worst = max(named, key=lambda n: std[n] * (np.rad2deg(1.0) if n in angle_names else 1.0))
            s = std[worst] * (np.rad2deg(1.0) if worst in angle_names else 1.0)
            text += f"; std up to {s:.3g} {'deg' if worst in angle_names else 'mm'} ({worst})"
        out.append("warning: " + text + ": add poses that move it, or fix one of its parameters")
    if beyond_noise(unc, NOISE_SLACK):
        b = unc.birge_ratio
        out.append(f"warning: chi2/E[chi2] = {b:.4g}: the residuals are {np.sqrt(b):.3g} times the noise the setup "
                   "states, which no noise explains; check the units of the files (angles in degrees, lengths in mm), "
                   "the setup's noise, and that the measurements belong to this machine and setup "
                   "(the file covariance is inflated by chi2/E[chi2])")
    elif (w := chi2_warning(unc)) is not None:
        out.append(w)
    return out


def _solver_args(solver: str, m: int, n: int) -> str:
    if solver == "auto":
        return "lm" if m >= n else "trf"
    if solver not in ("lm", "trf", "dogbox"):
        raise PkmcalError(f"solver must be one of auto, lm, trf, dogbox; got '{solver}'")
    return solver


def identify(
    machine: Mechanism,
    setup: MeasurementSetup,
    measurements=None,
    *,
    method: str | None = None,
    free=None,
    fix=None,
    weighted: bool = True,
    form: str = "plain",
    jac: str = "analytic",
    solver: str = "auto",
    ftol: float = TOLERANCE,
    xtol: float = TOLERANCE,
    gtol: float = TOLERANCE,
    max_nfev: int | None = None,
    q: np.ndarray | None = None,
    y: np.ndarray | None = None,
    commanded: np.ndarray | None = None,
    max_dropped_fraction: float = MAX_DROPPED_FRACTION,
    loss: str = "linear",
    f_scale: float | None = None,
    priors=None,
    reject: float | None = None,
    outlier_sigma: float = OUTLIER_SIGMA,
    exclude=None,
    sessions=None,
    session_offsets: bool | None = None,
) -> IdentificationResult:
    """Identify the kinematic (and free sensor) parameters from measured poses.

    Parameters
    ----------
    machine : the nominal machine (the starting point; its parameters are ρ).
    setup : the sensor (its parameters are s) and the noise model.
    measurements : a measurements object / mapping / tuple (see :func:`measurement_arrays`);
        or give the arrays ``q`` (N, l) actuator readings, ``y`` (N, m) sensor readings and
        optionally ``commanded`` (N, n) poses (FK / pose-solve starting points).
    method : ``"ik-residual"`` (full-pose sensor, paper 1), ``"fk-residual"`` (paper 2),
        ``"projection"`` (paper 3; any sensor, redundant machines) or ``"projection-single"``
        (paper 3 eq. 10 as published: linearised once at the commanded poses, one
        Gauss–Newton step; needs commanded poses). Default (None):
        :func:`~pkmcal.identification.residuals.default_method`, the same rule as every
        command's.
    free : names or shell patterns of the parameters to estimate (default: all machine
        parameters and the sensor's ``default_free``).
    fix : names/patterns held at their nominal values, or ``"auto"``; default (``None``):
        the suggested gauge is fixed automatically unless ``free`` was given.
    weighted : noise-weighted (generalised) least squares; False = the papers' plain fit.
    form : ik-residual only: ``"plain"`` (q − IK) or ``"squared"`` (paper 1 eq. 3).
    jac : ``"analytic"`` or a scipy finite-difference scheme (``"2-point"``, ``"3-point"``),
        for comparison only.
    solver : ``"auto"`` (LM when there are at least as many residuals as unknowns),
        ``"lm"``, ``"trf"`` or ``"dogbox"`` (scipy.optimize.least_squares methods).
    loss, f_scale : ``"linear"`` (least squares) or a robust loss of
        :func:`scipy.optimize.least_squares` (``"soft_l1"``, ``"huber"``, ``"cauchy"``) on
        the whitened rows, ``f_scale`` in noise σ (default: 95 % efficiency;
        :mod:`.robust`). Needs a noise-weighted fit (trust-region solver).
    priors : Gaussian priors (:class:`~pkmcal.identification.priors.Prior` or
        ``"NAME=MEAN±STD"`` strings, file units), added to the setup's ``priors``
        (maximum a posteriori, :mod:`.priors`). Needs a noise-weighted fit.
    reject : drop the poses beyond ``reject`` σ and refit until none is left
        (:func:`~pkmcal.identification.robust.identify_rejecting`).
    outlier_sigma : threshold (σ of the per-pose normalised residual) of the outlier
        screening when ``reject`` is not given.
    exclude : indices of poses to leave out of the fit (the rejection's).
    sessions : the session of every pose (a :class:`~pkmcal.sensors.sessions.Sessions` or
        per-pose labels); default the measurements' own (the file's ``session`` column).
        With several sessions each has its own sensor parameters, ``NAME@LABEL``; a name or
        pattern without ``@`` in ``free``/``fix`` means that parameter in every session.
    session_offsets : give the sessions after the first actuator zero offsets
        ``dq_i@LABEL`` (re-homing), estimated with the free parameters; default the
        setup's ``session_offsets`` (``sessions: {actuator_offsets: true}``).

    Returns
    -------
    IdentificationResult

    Notes
    -----
    GLS objective Σ_j ‖W_j r_j‖² with fixed weights from the start (module docstring);
    covariance (J̃ᵀJ̃)⁻¹ and its a-posteriori version (:mod:`.uncertainty`).

    References
    ----------
    Paper 1 (Agheli & Nategh) §V; paper 2 (Saputra et al.) §2.2–3; paper 3 (Jeon et al.) §2.
    """
    kw = dict(method=method, free=free, fix=fix, weighted=weighted, form=form, jac=jac, solver=solver, ftol=ftol,
              xtol=xtol, gtol=gtol, max_nfev=max_nfev, q=q, y=y, commanded=commanded,
              max_dropped_fraction=max_dropped_fraction, loss=loss, f_scale=f_scale,
              priors=tuple(getattr(setup, "priors", ()) or ()) + tuple(priors or ()), sessions=sessions,
              session_offsets=session_offsets)
    with single_threaded_blas():
        if reject is not None:
            from pkmcal.identification.robust import identify_rejecting

            n = len(measurement_arrays(measurements)[0]) if measurements is not None else len(np.asarray(q))
            return identify_rejecting(lambda exclude, round_: _identify(machine, setup, measurements, **kw,
                                                                        outlier_sigma=reject, exclude=exclude,
                                                                        round_=round_), reject, n)
        return _identify(machine, setup, measurements, **kw, outlier_sigma=outlier_sigma, exclude=exclude)


def _identify(machine, setup, measurements, *, method, free, fix, weighted, form, jac, solver, ftol, xtol, gtol,
              max_nfev, q, y, commanded, max_dropped_fraction, loss="linear", f_scale=None, priors=(),
              outlier_sigma=OUTLIER_SIGMA, exclude=None, round_=1, sessions=None,
              session_offsets=None, register: bool = True) -> IdentificationResult:
    if method is None:
        method = default_method(setup, machine)
    if method not in METHODS:
        raise PkmcalError(f"unknown identification method '{method}'; use one of {', '.join(METHODS)}")
    if jac not in ("analytic", "2-point", "3-point"):
        raise PkmcalError(f"jac must be 'analytic', '2-point' or '3-point'; got '{jac}'")
    if measurements is not None:
        q, y, cmd = measurement_arrays(measurements)
        commanded = cmd if commanded is None else commanded
    if q is None or y is None:
        raise PkmcalError("identify needs measurements: actuator readings q and sensor readings y")
    offsets = bool(getattr(setup, "session_offsets", False) if session_offsets is None else session_offsets)
    ses = measurement_sessions(measurements, sessions, len(np.asarray(q)), offsets)
    sensor = setup.sensor if ses is None else \
        SessionSensor.start(setup.sensor, ses, dict(getattr(setup, "session_sensors", ()) or ()))
    model = Model(machine, sensor, setup.noise, q, y, commanded, ses)
    notes: list[str] = []
    n_total = model.n_poses
    if n_total == 0:
        raise PkmcalError("there are no measured poses to identify from (an empty measurement set; a simulation "
                          "whose real machine reached none of the poses lists why in its dropped poses)")
    used = np.arange(n_total)
    # the file's pose numbers (1-based data rows), kept when poses were left out before the fit
    numbers = np.asarray(getattr(measurements, "pose_numbers", np.arange(1, n_total + 1)), dtype=int)
    f_scale = check_loss(loss, f_scale)
    if exclude is not None and len(exclude):
        used = np.setdiff1d(used, np.asarray(exclude, dtype=int))
        model = model.subset(used)

    cand, explicit = candidate_parameters(model, free, fix, priors=priors)
    if not cand:
        raise PkmcalError("no free parameters to identify (check --free / --fix)")
    theta_given = model.theta0             # the values given (reported as ``initial``)
    if register and ses is not None:
        model = _registered(model, cand, notes, method=method, weighted=weighted, max_nfev=max_nfev,
                            max_dropped_fraction=max_dropped_fraction)
    names = model.names
    prior = resolve(priors, names, model.param_is_angle, model.theta0)
    check_plausible(prior, model.theta0, model.param_is_angle, model.n_mech)
    check_free(prior, {names[i] for i in cand})
    if not weighted and (len(prior) or loss != "linear"):
        raise PkmcalError(("Gaussian priors weigh the prior against the noise model" if len(prior) else
                           f"the {loss} loss's f_scale is in noise sigmas") +
                          ": they need the noise-weighted fit; leave out --unweighted")
    # else the sensor columns of J are not needed
    sensor_free = any(model.n_mech <= i < model.n_mech + model.n_sensor for i in cand)
    meth = make_method(method, model, weighted, form=form)
    meth.sensor_columns = sensor_free
    if meth.single_step and jac != "analytic":
        raise PkmcalError(f"method '{method}' takes one step with the analytic Jacobian; jac='{jac}' does not apply")
    theta0 = model.theta0
    ev0 = meth.evaluate(theta0, jac=True, cov=True)
    if not ev0.converged.all():
        bad = used[np.flatnonzero(~ev0.converged)]
        if len(bad) > max_dropped_fraction * n_total:
            raise PkmcalError(
                f"the pose could not be solved for {len(bad)} of {n_total} poses at the nominal machine "
                f"(poses {', '.join(str(numbers[i]) for i in bad[:10])}{' ...' if len(bad) > 10 else ''}"
                f"{_where(measurements, bad[:3])}): "
                "check that the measurements belong to this machine and setup, or give commanded poses"
            )
        notes.append(f"dropped {len(bad)} pose(s) whose pose could not be solved at the nominal machine "
                     "(FK or pose solve not converged, or converged on another assembly mode than its start "
                     "pose): " + ", ".join(str(numbers[i]) for i in bad) + _where(measurements, bad))
        model = model.subset(np.flatnonzero(ev0.converged))
        used = used[np.flatnonzero(ev0.converged)]
        meth = make_method(method, model, weighted, form=form)
        meth.sensor_columns = sensor_free
        ev0 = meth.evaluate(theta0, jac=True, cov=True)

    W = whitening(ev0.cov, f"{method} residual") if weighted and not meth.prewhitened else None
    Jw0 = ev0.J if W is None else W @ ev0.J

    rows = Jw0.reshape(-1, Jw0.shape[-1])
    cand_names = tuple(names[i] for i in cand)
    angle_names = tuple(n for n, a in zip(names, model.param_is_angle) if a)
    # Which parameters the data can determine is judged on the plan: the Jacobian at the
    # commanded poses with noise-free readings (design_jacobian, what `pkmcal identifiability`
    # analyses). At the measured poses a plan's exact deficiencies (pure-z poses, a flat grid)
    # look like weak directions of σ/σ₁ ~ 1e-7, seen only through the pose errors the
    # noise and the machine's errors cause, above the rank tolerance: they then came out
    # "identified" with σ of 1e7 mm. Without commanded poses the measured data are all there is.
    basis = f"{meth.name} at the {model.n_poses} measured poses (nominal machine; no commanded poses given)"
    judged = rows[:, cand]
    if model.commanded is not None:
        from pkmcal.identification.identifiability import design_jacobian

        Jd, okd, _ = design_jacobian(model.mechanism, model.sensor, model.noise, model.commanded, meth.name,
                                     weighted, form=form, sensor_columns=sensor_free, sessions=model.sessions)
        if okd.any():
            judged = Jd[okd].reshape(-1, Jd.shape[-1])[:, cand]
            basis = f"{meth.name} at the {int(okd.sum())} commanded poses (noise-free, nominal machine)"
    judged, basis = prior.augment(judged, cand, basis)   # a prior pins its direction (.priors)
    scaled = ScaledJacobian(judged)

    done: list[IdentifiabilityReport] = []

    def analyse() -> IdentifiabilityReport:
        """The full analysis (one SVD), computed once: the fit, the result's report and its
        deferred warnings share it. One BLAS thread also when deferred, outside
        :func:`identify`: a threaded SVD of this 42 × 42 triangle took 100 ms instead of
        0.3 ms on a loaded 2-core machine (2026-11-23)."""
        if not done:
            with single_threaded_blas():
                rep = scaled.analyse(cand_names, tuple(model.mechanism.param_names))
            done.append(dataclasses.replace(rep, basis=basis,
                                            angle_names=tuple(n for n in cand_names if n in angle_names)))
        return done[0]

    # The full analysis runs before the fit only when the cheap certificate cannot prove
    # full rank (a gauge may have to be fixed). Otherwise the result computes it on first
    # use of its report, and of its warnings when the certificate could not also prove
    # that no direction is weak (σ/σ₁ > WEAK_RATIO everywhere): the same report, the same
    # warnings, its SVD paid only by those who read them.
    report = None if scaled.certainly_full_rank(RANK_RTOL) else analyse()
    no_weak = report is None and scaled.certainly_full_rank(WEAK_RATIO)
    auto = (fix is None and not explicit) or (isinstance(fix, str) and fix == "auto")
    if report is not None and not report.identifiable:
        if not auto:
            raise PkmcalError(
                f"the requested free parameters are not identifiable from these poses with this sensor: "
                f"{report.describe()} (or use --fix auto)"
            )
        notes.append(f"fixed the gauge automatically (rank {report.rank} of {report.n_params}): "
                     f"{', '.join(report.fixed)}")
        cand = [i for i in cand if names[i] not in report.fixed]
        check_free(prior, {names[i] for i in cand}, tuple(report.fixed))
    free_idx = np.array(cand, dtype=int)
    M = rows.shape[0] + len(prior)
    if M < len(free_idx):
        raise PkmcalError(f"{model.n_poses} poses give {M} residuals for {len(free_idx)} free parameters: "
                          "measure more poses or fix parameters")
    if M == len(free_idx):
        notes.append(f"{M} residuals for {M} free parameters: the fit interpolates the data, so nothing checks "
                     "it (χ² and the a-posteriori covariance are undefined; the file gets the a-priori one); "
                     "measure more poses")

    obj = _Objective(meth, theta0, free_idx, W)
    if len(prior):
        obj = PriorObjective(obj, prior, free_idx)
    lsq_method = _solver_args(solver, M, len(free_idx))
    if loss != "linear":
        if solver == "auto":
            lsq_method = "trf"
        if meth.single_step or lsq_method == "lm":
            raise PkmcalError(f"the {loss} loss needs an iterative trust-region solver: not with "
                              + (f"method '{method}'" if meth.single_step else "solver 'lm'; use solver trf"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if meth.single_step:
            sol = _gauss_newton_step(obj, theta0[free_idx])
        else:
            sol = _least_squares(obj, theta0[free_idx], jac=jac, method=lsq_method, ftol=ftol, xtol=xtol,
                                 gtol=gtol, max_nfev=max_nfev, loss=loss, f_scale=f_scale, n_data=rows.shape[0])
    theta = obj.theta(sol.x)
    ev = meth.evaluate(theta, jac=True, cov=True)   # only the free columns of ev.J are used
    if not meth.single_step:
        # the stop must reproduce, and be a minimum (_checked): on this evaluation where the
        # method's residual is a function of θ alone, else on a new method object's
        check = obj
        if not meth.path_independent:
            again = make_method(method, model, weighted, form=form)
            again.sensor_columns = sensor_free
            check = _Objective(again, theta0, free_idx, W)
            check = PriorObjective(check, prior, free_idx) if len(prior) else check
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            sol = _checked(sol, check, least_squares=loss == "linear")
    if not ev.converged.all():
        bad = used[np.flatnonzero(~ev.converged)]
        notes.append("the pose could not be solved at the identified machine for pose(s) "
                     + ", ".join(str(numbers[i]) for i in bad) + _where(measurements, bad)
                     + "; their residuals are unreliable")

    # covariance with weights recomputed at the solution (module docstring); the weighted
    # projection's residual is already whitened (cov = I)
    J_free = ev.J[:, :, free_idx]
    free_names = tuple(names[i] for i in free_idx)
    if weighted:
        r_w = ev.r
        if not meth.prewhitened:
            if not ev.converged.all() and not np.all(np.isfinite(ev.cov)):
                bad = used[np.flatnonzero(~ev.converged)]
                raise PkmcalError(
                    f"the fit ended at a machine that cannot take {len(bad)} of the {len(used)} poses (no pose "
                    f"solves their readings: poses {', '.join(str(numbers[i]) for i in bad[:10])}"
                    f"{' ...' if len(bad) > 10 else ''}), so no covariance can be computed there and the fit is not "
                    "to be trusted; check those poses' readings (--reject K drops outliers), hold weak parameters "
                    "(--fix, --prior; 'pkmcal identifiability' lists them), or start from a nominal machine closer "
                    "to the real one")
            W_end = whitening(ev.cov, f"{method} residual")
            J_free, r_w = W_end @ J_free, (W_end @ ev.r[..., None])[..., 0]
        z = r_w
    else:
        try:
            W_end = whitening(ev.cov, f"{method} residual")
        except PkmcalError:  # noise-free noise model: no χ², the sandwich covariance is zero
            W_end = None
        unc = parameter_uncertainty(free_names, J_free, ev.r, weighted=False, W=W_end, cov_rows=ev.cov,
                                    measured=ev.measured)
        r_w = ev.r
        z = None if W_end is None else (W_end @ ev.r[..., None])[..., 0]
    where = getattr(measurements, "where", None) if getattr(measurements, "source", None) is not None else None
    screening = None if z is None else screen(z, used, meth.row_names(), outlier_sigma, where=where, round_=round_,
                                              numbers=numbers, loss=loss, f_scale=f_scale, measured=ev.measured)
    if weighted:
        inliers = screening.inliers if loss != "linear" else np.ones(len(used), dtype=bool)
        if loss == "linear" and not len(prior):
            unc = parameter_uncertainty(free_names, J_free, r_w, weighted=True, measured=ev.measured)
        else:
            unc = robust_uncertainty(free_names, J_free, r_w, inliers, loss, f_scale,
                                     *prior.rows(free_idx, theta[free_idx]), measured=ev.measured)
    if screening is not None:
        notes.extend(screening.warnings())

    n_fit_notes = len(notes)     # the fit's warnings (weak directions, χ²) go here, maybe deferred

    def all_notes() -> tuple[str, ...]:
        found = fit_warnings(report if report is not None or no_weak else analyse(), free_names, unc, angle_names)
        return tuple(notes[:n_fit_notes] + found + notes[n_fit_notes:])

    mech_cal, sensor_cal = model.split(theta)
    p = model.n_mech
    mech_free = free_idx[free_idx < p]
    if mech_free.size:
        sel = np.flatnonzero(free_idx < p)
        cov_mech = embed(unc.covariance[np.ix_(sel, sel)], mech_free, p)
        mech_cal = model.mechanism.with_params(theta[:p], covariance=cov_mech)

    free_set = set(free_idx.tolist())
    fixed = tuple(n for i, n in enumerate(names) if i not in free_set)
    is_dropped = np.ones(n_total, dtype=bool)
    is_dropped[used] = False
    if exclude is not None and len(exclude):
        is_dropped[np.asarray(exclude, dtype=int)] = False   # rejected, listed in screening.outliers
    dropped = np.flatnonzero(is_dropped)
    return IdentificationResult(
        mechanism=mech_cal,
        sensor=sensor_cal,
        method=method,
        weighted=weighted,
        names=names,
        free=free_names,
        fixed=fixed,
        initial=theta_given,
        estimate=theta,
        uncertainty=unc,
        residuals=ev.r,
        residuals_weighted=r_w,
        measured=ev.measured,
        residual_names=meth.row_names(),
        poses=ev.poses,
        used_poses=used,
        dropped=dropped,
        cost=sol.cost,
        nfev=sol.nfev,
        njev=sol.njev,
        status=sol.status,
        success=sol.success,
        message=sol.message,
        identifiability_analysis=analyse,
        gauge=tuple(report.fixed) if report is not None and not report.identifiable else (),
        warnings=all_notes() if report is not None or no_weak else all_notes,
        residual_units=meth.row_units(),
        screening=screening,
        priors=prior,
        loss=loss,
        pose_numbers=numbers,
        param_is_angle=model.param_is_angle,
        sessions=model.sessions,
    )


__all__ = ["IdentificationResult", "candidate_parameters", "identify", "measurement_arrays", "format_direction"]

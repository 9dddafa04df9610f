"""Build a :class:`~pkmcal.report.data.ReportData` from the engine's and the verifier's results.

This is the only module of :mod:`pkmcal.report` that knows the identification and
verification result types; ``pkmcal demo`` and ``pkmcal identify --report`` both use it.
Held-out errors are taken over the poses that both models bring the real machine to
(:attr:`~pkmcal.identification.verification.VerificationReport.common`); the error map is
e_p = ‖p_real − p_cmd‖ of :func:`~pkmcal.identification.verification.pose_errors` on an
x–y grid at the home height and orientation.
"""

from __future__ import annotations

import numpy as np

from pkmcal.identification.identifiability import format_direction
from pkmcal.mechanisms.base import Mechanism
from pkmcal.report.data import (
    ErrorMap,
    HeldOutErrors,
    Identifiability,
    ParameterTable,
    PriorRow,
    ReportData,
    Residuals,
    Screening,
)
from pkmcal.sensors.base import MeasurementSetup, Sensor


def identifiability_from_report(report, fixed: tuple[str, ...]) -> Identifiability:
    """Report view of an :class:`~pkmcal.identification.identifiability.IdentifiabilityReport`."""
    weak = tuple(f"{format_direction(w['direction'])} (σ/σ₁ = {w['ratio']:.1e})" for w in report.weak)
    null = tuple(format_direction(d) for d in report.null_space)
    return Identifiability(rank=int(report.rank), n_params=int(report.n_params),
                           singular_values=np.asarray(report.singular_values, dtype=float),
                           fixed=tuple(fixed), weak=weak, null_space=null,
                           condition_number=float(report.condition_number),
                           basis=getattr(report, "basis", ""))


def residual_units(names: tuple[str, ...], setup: MeasurementSetup, mechanism: Mechanism | None = None,
                   weighted: bool = False) -> tuple[str, ...]:
    """Unit of each residual row. A row named after a reading has that reading's unit, from
    the declared flags and units: the sensor's ``reading_is_angle`` ("rad" for angles, "mm"
    otherwise), the mechanism's ``actuator_is_angle`` ("rad") and ``actuator_units`` (mm, or
    a hexapod's ``actuator_unit``: rev, count, ...). Other rows combine readings (the
    projection's r = U⊥ᵀ W [e_y; e_q], paper 3 eq. 8): "1" when whitened (``weighted``) or
    when the readings mix units, else the readings' common unit."""
    sensor = setup.sensor
    unit = {n: "rad" if a else "mm" for n, a in zip(sensor.reading_names, sensor.reading_is_angle)}
    if mechanism is not None:
        # a reading unit that is only a label (a hexapod's actuator_unit: rev, count; "deg" of a
        # motor, never converted) is marked as one where it reads like a unit the report converts
        unit.update((n, "rad" if a else (f"{u} (reading)" if u in ("deg", "rad") else u)) for n, a, u in
                    zip(mechanism.actuator_names, mechanism.actuator_is_angle, mechanism.actuator_units))
    kinds = set(unit.values())
    combined = "1" if weighted or len(kinds) > 1 else (kinds.pop() if kinds else "mm")
    return tuple(unit.get(n, combined) for n in names)


def held_out_from_verification(verification) -> HeldOutErrors | None:
    """Before/after errors on the poses both models reach; None without a 'before'."""
    if verification.before is None:
        return None
    m = verification.common
    b, a = verification.before, verification.after
    return HeldOutErrors(b.position[m], a.position[m], b.orientation[m], a.orientation[m])


def error_map(nominal: Mechanism, calibrated: Mechanism, real: Mechanism, x: np.ndarray, y: np.ndarray,
              z: float, abc=(0.0, 0.0, 0.0)) -> ErrorMap:
    """Position error of ``real`` commanded through ``nominal`` (before) and ``calibrated``
    (after) on the grid x × y at height z and orientation abc (NaN where unreachable)."""
    from pkmcal.identification.verification import pose_errors

    X, Y = np.meshgrid(np.asarray(x, float), np.asarray(y, float))
    grid = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, float(z)), np.tile(np.asarray(abc, float), (X.size, 1))])
    reach = nominal.check_limits(grid).ok
    before = pose_errors(nominal, real, grid).position
    after = pose_errors(calibrated, real, grid).position
    before = np.where(reach, before, np.nan).reshape(X.shape)
    after = np.where(reach, after, np.nan).reshape(X.shape)
    return ErrorMap(np.asarray(x, float), np.asarray(y, float), float(z), before, after, tuple(float(v) for v in abc))


def parameter_table(nominal: Mechanism, result, true_machine: Mechanism | None = None,
                    true_sensor: Sensor | None = None) -> ParameterTable:
    """Every machine parameter, then the sensor parameters the fit estimated (free or gauge),
    with their angle flags from ``nominal.param_is_angle`` and ``result.sensor.param_is_angle``
    (result.names is machine then sensor). ``true`` from ``true_machine`` / ``true_sensor``,
    NaN where not given."""
    p = len(nominal.param_names)
    sensor_angle = dict(zip(result.sensor.param_names, result.sensor.param_is_angle))
    sensor_angle.update(zip(result.names, result.param_is_angle))   # + the sessions' offsets dq_i@LABEL
    sensor_unit = {n: "deg" if a else "mm" for n, a in sensor_angle.items()}
    flags = tuple(nominal.param_is_angle) + tuple(sensor_angle[n] for n in result.names[p:])
    units = tuple(nominal.param_units) + tuple(sensor_unit[n] for n in result.names[p:])
    free_set = {n: k for k, n in enumerate(result.free)}
    shown = list(range(p)) + [i for i in range(p, len(result.names))
                              if result.names[i] in free_set or result.names[i] in result.gauge]
    names = tuple(result.names[i] for i in shown)
    std = np.array([result.std[free_set[n]] if n in free_set else np.nan for n in names])
    true = None
    if true_machine is not None or true_sensor is not None:
        t_mech = np.full(p, np.nan) if true_machine is None else np.asarray(true_machine.params, dtype=float)
        t_sens = dict(zip(true_sensor.param_names, true_sensor.params)) if true_sensor is not None else {}
        true = np.r_[t_mech, [t_sens.get(n, np.nan) for n in result.names[p:]]][shown]
    return ParameterTable(names, np.asarray(result.initial)[shown], np.asarray(result.estimate)[shown], std,
                          np.array([n in free_set for n in names]), true=true,
                          is_angle=np.array(flags, dtype=bool)[shown], param_units=tuple(units[i] for i in shown))


def _compliance_facts(nominal, result, setup, commanded) -> tuple[tuple[str, str], ...]:
    """A warning line when a redundant machine calibrated by projection deflected under its
    load (:func:`~pkmcal.identification.load_deflection.compliance_warning`); needs the
    commanded poses of the measurements (``commanded``, one per input pose)."""
    if commanded is None:
        return ()
    from pkmcal.identification.load_deflection import compliance_warning
    from pkmcal.identification.simulation import settles_at_equilibrium

    poses = np.asarray(commanded, dtype=float)
    if result.method != "projection" or not settles_at_equilibrium(nominal) or poses.ndim != 2 \
            or len(poses) <= int(np.max(result.used_poses, initial=-1)) or "tool-point" not in result.sensor.abilities:
        return ()
    std = float(np.max(np.asarray(setup.noise.reading_std, dtype=float)))
    text = compliance_warning(nominal, result.mechanism, result.sensor, poses[result.used_poses], result.poses, std)
    return () if text is None else (("warning", text),)


def screening_from_result(result) -> Screening | None:
    """Report view of the fit's outlier screening (None when the fit had no noise model)."""
    sc = getattr(result, "screening", None)
    if sc is None:
        return None
    rows = tuple(sc.outliers)
    return Screening(threshold=sc.threshold, loss=sc.loss, f_scale=sc.f_scale, reject=sc.reject, rounds=sc.rounds,
                     outliers=rows, max_sigma=float(np.max(sc.sigma)) if sc.sigma.size else np.nan,
                     median_sigma=float(np.median(sc.sigma)) if sc.sigma.size else np.nan)


def priors_from_result(result) -> tuple[PriorRow, ...]:
    """Report view of the fit's Gaussian priors (file units)."""
    priors = getattr(result, "priors", None)
    if priors is None or not len(priors):
        return ()
    std = dict(zip(result.free, result.std))
    return tuple(PriorRow(e["parameter"], e["unit"], e["mean"], e["std"], e["estimate"],
                          np.nan if e["posterior_std"] is None else e["posterior_std"], e["pull"], e["source"])
                 for e in priors.to_dict(result.estimate, std))


def report_data_from_results(
    nominal: Mechanism,
    result,
    setup: MeasurementSetup,
    poses: np.ndarray,
    *,
    verification=None,
    identified: Mechanism | None = None,
    true_machine: Mechanism | None = None,
    true_sensor: Sensor | None = None,
    error_map: ErrorMap | None = None,
    title: str | None = None,
    setup_summary: str = "",
    facts: tuple[tuple[str, str], ...] = (),
    held_out_poses: np.ndarray | None = None,
    commanded: np.ndarray | None = None,
    heldout=None,
    calibrated_file: str | None = None,
    setup_name: str | None = None,
) -> ReportData:
    """The report of an :class:`~pkmcal.identification.engine.IdentificationResult`.

    ``poses`` (N, 6): the poses measured (commanded or planned); ``verification`` a
    :class:`~pkmcal.identification.verification.VerificationReport` with a 'before'
    column; ``identified`` the calibrated machine as exported (default ``result.mechanism``);
    ``true_machine`` (and ``true_sensor``) the simulation's real machine (sensor), shown
    beside the estimates; ``commanded`` (N, n) the commanded poses of the measurements, from
    which a redundant machine's load deflection is estimated (a warning line when visible);
    ``heldout`` a :class:`~pkmcal.identification.heldout.HeldoutReport` (validation on
    measured held-out data), shown in its own section; ``calibrated_file`` and ``setup_name``
    name the calibrated machine file and the setup in the commands the report suggests.
    """
    table = parameter_table(nominal, result, true_machine, true_sensor)
    corr = np.asarray(result.correlation, dtype=float)
    res_names = tuple(result.residual_names)
    facts = (("identification method", f"{result.method} ({'noise-weighted' if result.weighted else 'plain'} "
                                        "least squares)"),
             ("solver", f"{result.message} ({result.nfev} evaluations)"),
             ("poses used", f"{len(result.used_poses)} (dropped {len(result.dropped)})"
                            + (f": rows {', '.join(str(int(k) + 1) for k in result.dropped[:20])}"
                               f"{' …' if len(result.dropped) > 20 else ''} of the measurement file"
                               if len(result.dropped) else "")),
             ("pose numbers", "data rows of the measurement file, counted from 1 (comment and header lines "
                              "not counted)"),
             ("reduced χ²", f"{result.uncertainty.reduced_chi2:.3f}"),
             ("standard deviations", result.uncertainty.description),
             *facts,
             *(("note", w) for w in result.warnings),
             *_compliance_facts(nominal, result, setup, commanded))
    return ReportData(
        title=title or f"pkmcal calibration report: {nominal.name}",
        machine_summary=nominal.summary(),
        nominal=nominal,
        identified=result.mechanism if identified is None else identified,
        poses=np.asarray(poses, dtype=float),
        identifiability=identifiability_from_report(result.identifiability, result.fixed),
        parameters=table,
        correlation=corr,
        correlation_names=tuple(result.free),
        residuals=Residuals(np.asarray(result.residuals, dtype=float), res_names,
                            residual_units(res_names, setup, nominal, bool(result.weighted)),
                            pose_numbers=np.asarray(result.used_poses, dtype=int) + 1),
        held_out=None if verification is None else held_out_from_verification(verification),
        held_out_total=None if verification is None else int(len(verification.after.valid)),
        held_out_dropped=() if verification is None else tuple((k + 1, why) for k, why in
                                                               verification.dropped.items()),
        error_map=error_map,
        setup_summary=setup_summary,
        facts=facts,
        held_out_poses=held_out_poses,
        screening=screening_from_result(result),
        priors=priors_from_result(result),
        measured_validation=None if heldout is None else {**heldout.to_dict(), "rows": heldout.summary_rows()},
        calibrated_file=calibrated_file,
        setup_name=setup_name,
    )

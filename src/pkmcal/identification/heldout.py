"""Validation on measured held-out data: predict each measurement from its actuator readings.

For a machine model ρ and a sensor θ, the held-out measurement j (actuator readings q_j,
sensor readings y_j) is predicted by the forward kinematics and the sensor model

    x̂_j = FK(q_j, ρ),    ŷ_j = h(F(x̂_j, ρ), θ),    r_j = y_j ⊖ ŷ_j

(paper 2 §3 eq. 3, the fk-residual; ⊖ the sensor's ``reading_residual``: angle readings
wrapped). What is compared depends on what the sensor reads:

* full pose (paper 1 §III): position error e_p = ‖p_y − p_ŷ‖ (mm) of the tool frame and
  orientation error e_R = ∠(R_y R_ŷᵀ) (rad; degrees in summaries), the rotation angle
  between the measured and predicted rotations (:func:`pkmcal.conventions.rotation_error`);
* a tracked point (position sensor, planar tool point): e_p = ‖r_j‖ (mm), no orientation;
* indicators and other sensors that read neither (paper 2 §2.3): the reading residuals
  r_j (mm), summarised as mean, RMS and max of |r| over every reading.

Three models are compared on the same held-out poses (those whose FK converges for all):

* ``before``: the nominal machine with the sensor parameters registered on the
  calibration data (the fair "before": the nominal machine gets its best frames too);
* ``after``: the calibrated machine with the sensor the calibration identified;
* ``after_reregistered``: the calibrated machine with only the sensor's free parameters
  refitted on the held-out data (a new registration of the instrument): what no
  re-registration can remove is the machine's own error.

The registrations are fits of the engine (:func:`pkmcal.identification.engine.identify`,
method fk-residual, noise-weighted when the noise model has no zero σ) with only the
sensor parameters free; everything here is vectorised over the poses.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pkmcal.conventions import euler_to_matrix, rotation_error
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import MeasurementSetup, Sensor

#: The models compared, in the order printed.
MODELS = ("before", "after", "after_reregistered")
#: What each sensor kind's readings give: (position columns, orientation (Euler) columns).
READS = {"full-pose": (slice(0, 3), slice(3, 6)), "position": (slice(0, 3), None),
         "planar-tool": (slice(0, None), None)}


def sensor_values(sensor: Sensor, names=None) -> dict[str, float]:
    """``{name: value}`` of the sensor's parameters (all, or ``names``) in file units (mm,
    degrees for angles)."""
    angles = {n for n, a in zip(sensor.param_names, sensor.param_is_angle) if a}
    return {n: float(np.rad2deg(v)) if n in angles else float(v)
            for n, v in zip(sensor.param_names, sensor.params) if names is None or n in names}


def sensor_from_values(sensor: Sensor, values: dict, source: str) -> Sensor:
    """``sensor`` with the parameters of ``values`` (file units, as :func:`sensor_values`
    gives them) replaced; an unknown name is an error naming ``source``."""
    theta = sensor.params.copy()
    for name, v in values.items():
        if name not in sensor.param_names:
            raise PkmcalError(f"{source}: '{name}' is not a parameter of the '{sensor.kind}' sensor "
                              f"({', '.join(sensor.param_names) or 'it has none'})")
        i = sensor.param_names.index(name)
        theta[i] = float(np.deg2rad(v)) if sensor.param_is_angle[i] else float(v)
    return sensor.with_params(theta)


def _weighted(setup: MeasurementSetup) -> bool:
    """Whether the noise model can weigh a fit (no zero standard deviation)."""
    return bool(np.all(np.asarray(setup.noise.reading_std) > 0) and np.all(np.asarray(setup.noise.actuator_std) > 0))


@dataclass(frozen=True)
class Registration:
    """The sensor registered on a data set with the machine held: ``sensor`` (the free
    parameters refitted), ``free`` their names, ``note`` how (one sentence)."""

    sensor: Sensor
    free: tuple[str, ...]
    note: str
    rms_whitened: float = float("nan")


def register_sensor(machine: Mechanism, setup: MeasurementSetup, measurements, free=None,
                    what: str = "the data") -> Registration:
    """Fit only the sensor parameters ``free`` (default: the setup's ``free:`` list) of
    ``setup`` on ``measurements`` with ``machine`` held (the engine's fk-residual fit,
    noise-weighted when the noise model allows; an unidentifiable combination is held
    at its value by the automatic gauge)."""
    from pkmcal.identification.engine import identify

    sensor = setup.sensor
    free = tuple(sensor.default_free if free is None else free)
    if not free:
        return Registration(sensor, (), "no sensor parameter is free in the setup: the sensor is used as given")
    if machine.n_actuators != machine.n_dof:
        raise PkmcalError(f"machine '{machine.name}' is redundantly actuated: its held-out measurements cannot be "
                          "predicted from the actuator readings by FK alone")
    res = identify(machine, setup, measurements, method="fk-residual", free=list(free), fix="auto",
                   weighted=_weighted(setup))
    if not res.success:
        raise PkmcalError(f"registering the sensor on {what} did not converge ({res.message})")
    held = [n for n in free if n not in res.free]
    note = (f"{', '.join(res.free)} refitted on {what} with the machine '{machine.name}' held "
            f"(fk-residual, {'noise-weighted' if res.weighted else 'unweighted'}, {len(res.used_poses)} poses)")
    if held:
        note += f"; {', '.join(held)} held (not identifiable from these poses)"
    return Registration(res.sensor, tuple(res.free), note, res.rms_whitened)


@dataclass(frozen=True)
class Predicted:
    """Held-out errors of one model (module docstring), per pose (N,): ``residuals`` (N, m)
    measured − predicted (mm, rad), ``position`` (mm) and ``orientation`` (rad) or None
    where the sensor reads no such thing; ``ok`` False where the FK failed (NaN rows);
    ``poses`` (N, n) the FK poses (internal units); ``measured`` (N, m) the readings that are
    measurements where some are not (a printed object's pair rows: one of two; None: all),
    the only ones the reading statistics count."""

    label: str
    machine: str
    sensor: Sensor
    residuals: np.ndarray
    position: np.ndarray | None
    orientation: np.ndarray | None
    ok: np.ndarray
    reason: tuple[str, ...]
    registration: str = ""
    poses: np.ndarray | None = None
    measured: np.ndarray | None = None

    def summary(self, mask: np.ndarray) -> dict:
        """``{n_poses, position_mean_mm, position_rms_mm, position_max_mm, orientation_mean_deg,
        orientation_rms_deg, orientation_max_deg, reading_mean_mm, reading_rms_mm,
        reading_max_mm}`` over ``mask``; null where the sensor reads no such quantity."""
        out: dict = {"n_poses": int(np.count_nonzero(mask))}
        for key, values, scale in (("position", self.position, 1.0),
                                   ("orientation", self.orientation, float(np.rad2deg(1.0)))):
            unit = "mm" if key == "position" else "deg"
            for stat, v in _stats(None if values is None else values[mask] * scale).items():
                out[f"{key}_{stat}_{unit}"] = v
        lengths = [k for k, a in enumerate(self.sensor.reading_is_angle) if not a]
        r = None
        if lengths:
            taken = np.ones(self.residuals.shape, dtype=bool) if self.measured is None else self.measured
            r = self.residuals[mask][:, lengths][taken[mask][:, lengths]]
        for stat, v in _stats(r).items():
            out[f"reading_{stat}_mm"] = v
        return out


def _stats(values: np.ndarray | None) -> dict:
    if values is None or values.size == 0:
        return {"mean": None, "rms": None, "max": None}
    v = np.abs(values)
    return {"mean": float(np.mean(v)), "rms": float(np.sqrt(np.mean(v**2))), "max": float(np.max(v))}


#: Steps of the parameter continuation of :func:`held_out_fk`.
CONTINUATION_STEPS = 8


def held_out_fk(machine: Mechanism, q: np.ndarray, start: np.ndarray, reference: Mechanism | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(poses (N, n), ok (N,), branch_changed (N,))``: FK of ``machine`` at the readings
    ``q`` from ``start`` (N, n). A calibration whose gauge moved the machine's frames far
    from the nominal ones (an identified base joint 200 mm from its drawing) leaves the
    commanded poses, given in the nominal frames, too far for Newton; for the poses that
    fail, the FK is continued from the ``reference`` (nominal) machine's solution along
    ρ(t) = ρ_ref + t (ρ − ρ_ref), t = 1/8 … 1, each step warm-started from the last, as
    the fit itself moved."""
    with np.errstate(all="ignore"):
        fk = machine.fk_precise(q, start)
        x = np.asarray(fk.poses, dtype=float).copy()
        ok = fk.ok & np.all(np.isfinite(x), axis=1)
        branch = np.asarray(fk.branch_changed, dtype=bool).copy()
        if ok.all() or reference is None or reference.kind != machine.kind or \
                len(reference.params) != len(machine.params):
            return x, ok, branch
        bad = np.flatnonzero(~ok)
        ref = reference.fk(q[bad], start[bad])
        xb, good = np.asarray(ref.poses, dtype=float), ref.ok & np.all(np.isfinite(ref.poses), axis=1)
        rho0, rho1 = np.asarray(reference.params, dtype=float), np.asarray(machine.params, dtype=float)
        for t in np.arange(1, CONTINUATION_STEPS + 1) / CONTINUATION_STEPS:
            step = machine.fk(q[bad], np.where(good[:, None], xb, start[bad]), params=rho0 + t * (rho1 - rho0))
            good &= step.ok
            xb = np.where(good[:, None], step.poses, xb)
        final = machine.fk_precise(q[bad], np.where(good[:, None], xb, start[bad]))
        good &= final.ok & np.all(np.isfinite(final.poses), axis=1)
    x[bad] = np.where(good[:, None], final.poses, x[bad])
    ok[bad] = good
    branch[bad] &= ~good
    return x, ok, branch


def predict(machine: Mechanism, sensor: Sensor, measurements, label: str, registration: str = "",
            reference: Mechanism | None = None) -> Predicted:
    """Errors of ``machine`` + ``sensor`` on ``measurements`` (module docstring), all poses
    at once; the FK starts from the commanded poses when the file gives them, else home
    (continued from ``reference`` where that fails: :func:`held_out_fk`)."""
    q = np.asarray(measurements.actuators, dtype=float)
    y = np.asarray(measurements.readings, dtype=float)
    start = measurements.commanded if measurements.commanded is not None else machine.home_pose
    x, ok, branch = held_out_fk(machine, q, np.broadcast_to(start, (len(q), machine.n_dof)).copy(), reference)
    with np.errstate(all="ignore"):
        x = np.where(ok[:, None], x, machine.home_pose)
        frame = machine.frame(x)
        pred = sensor.predict(frame)
        measured = sensor.measured_readings(frame)
    reason = tuple("" if k else ("FK converged on another assembly mode" if b else "FK did not converge")
                   for k, b in zip(ok, branch))
    r, position, orientation = reading_errors(sensor, y, pred, ok)
    return Predicted(label, machine.name, sensor, r, position, orientation, ok, reason, registration, x,
                     None if measured.all() else measured)


def reading_errors(sensor: Sensor, measured: np.ndarray, predicted: np.ndarray, ok: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(r (N, m), e_p (N,) or None, e_R (N,) or None)`` of readings ``measured`` against
    ``predicted`` (module docstring): r = measured ⊖ predicted, the position error of what
    the sensor reads as a position, the rotation angle between the measured and predicted
    rotations (rad) for a full-pose sensor; NaN where ``ok`` is False."""
    ok = np.ones(len(measured), dtype=bool) if ok is None else np.asarray(ok, dtype=bool)
    with np.errstate(invalid="ignore"):
        r = sensor.reading_residual(measured, predicted)
    r[~ok] = np.nan
    pos_cols, rot_cols = READS.get(sensor.kind, (None, None))
    position = None if pos_cols is None else np.linalg.norm(r[:, pos_cols], axis=1)
    orientation = None
    if rot_cols is not None:
        safe = np.where(ok[:, None], predicted[:, rot_cols], 0.0)
        orientation = rotation_error(euler_to_matrix(np.where(ok[:, None], measured[:, rot_cols], 0.0)),
                                     euler_to_matrix(safe))
        orientation = np.where(ok, orientation, np.nan)
    return r, position, orientation


@dataclass(frozen=True)
class HeldoutReport:
    """Before / after / after-reregistered errors on held-out measurements. ``pose_numbers``
    (N,) the file's pose numbers (1-based data rows); figures over the poses every model's
    FK solves (``common``); ``notes`` what the reader must know (missing registration,
    clipped readings left out, ...); ``clipped`` the clipped readings found (JSON-ready
    mappings, :meth:`~pkmcal.io.measurements.ClippedReading.to_dict`)."""

    source: str
    sensor_kind: str
    pose_numbers: np.ndarray
    models: dict[str, Predicted]
    notes: tuple[str, ...] = ()
    clipped: tuple = field(default=())

    @property
    def common(self) -> np.ndarray:
        m = np.ones(len(self.pose_numbers), dtype=bool)
        for p in self.models.values():
            m &= p.ok
        return m

    def measured_as(self) -> str:
        kind = self.sensor_kind
        if kind == "full-pose":
            return ("full pose: position error of the tool frame (mm) and the rotation angle between the measured "
                    "and predicted rotations (deg)")
        if kind in READS:
            return "tracked point: position error (mm); the sensor reads no orientation"
        return f"{kind}: reading residuals measured - predicted (mm); the sensor reads no position or orientation"

    def failed(self) -> list[dict]:
        """Poses left out because some model's FK fails there: pose number and why."""
        out = []
        for i in np.flatnonzero(~self.common):
            why = "; ".join(f"{label}: {p.reason[i]}" for label, p in self.models.items() if not p.ok[i])
            out.append({"pose": int(self.pose_numbers[i]), "reason": why})
        return out

    def to_dict(self) -> dict:
        mask = self.common
        out: dict = {"measurements": self.source, "sensor": self.sensor_kind, "measured_as": self.measured_as(),
                     "n_poses_file": len(mask), "n_poses": int(np.count_nonzero(mask))}
        for label, p in self.models.items():
            out[label] = {**p.summary(mask), "machine": p.machine, "registration": p.registration,
                          "sensor_parameters": sensor_values(p.sensor, _free_names(p.sensor))}
        per_pose = []
        for i in np.flatnonzero(mask):
            row: dict = {"pose": int(self.pose_numbers[i])}
            for label, p in self.models.items():
                e: dict = {}
                if p.position is not None:
                    e["position_mm"] = float(p.position[i])
                if p.orientation is not None:
                    e["orientation_deg"] = float(np.rad2deg(p.orientation[i]))
                if p.position is None:
                    lengths = [k for k, a in enumerate(p.sensor.reading_is_angle) if not a]
                    e["reading_residuals_mm"] = [float(p.residuals[i, k]) for k in lengths]
                row[label] = e
            per_pose.append(row)
        out["per_pose"] = per_pose
        out["failed"] = self.failed()
        out["clipped"] = [dict(c) for c in self.clipped]
        out["notes"] = list(self.notes)
        out["units"] = {"n_poses_file": "1", "n_poses": "1", "pose": "1: data row of the held-out file, 1-based",
                        "n_poses_in_summary": "1",
                        "sensor_parameters": "file units: mm, deg for angle parameters"}
        return out

    def summary_rows(self) -> list[tuple[str, str, str]]:
        """(quantity, unit, key) rows shown in tables: what the sensor reads."""
        p = next(iter(self.models.values()))
        rows = []
        if p.position is not None:
            rows += [(f"position {s}", "mm", f"position_{s}_mm") for s in ("mean", "rms", "max")]
        if p.orientation is not None:
            rows += [(f"orientation {s}", "deg", f"orientation_{s}_deg") for s in ("mean", "rms", "max")]
        if p.position is None:
            rows += [(f"reading residual {s}", "mm", f"reading_{s}_mm") for s in ("mean", "rms", "max")]
        return rows

    def format_table(self) -> str:
        d = self.to_dict()
        labels = list(self.models)
        lines = [f"held-out validation on {d['n_poses']} of {d['n_poses_file']} poses of {self.source}",
                 f"compared: {d['measured_as']}"]
        lines.append(f"{'':<28}" + "".join(f"{lab:>20}" for lab in labels))
        for text, unit, key in self.summary_rows():
            lines.append(f"{text + ' (' + unit + ')':<28}" + "".join(
                f"{d[lab][key]:>20.6g}" if d[lab][key] is not None else f"{'-':>20}" for lab in labels))
        for lab in labels:
            if d[lab]["registration"]:
                lines.append(f"{lab}: {d[lab]['registration']}")
        for f in d["failed"]:
            lines.append(f"  pose {f['pose']} not compared: {f['reason']}")
        for n in self.notes:
            lines.append(n if n.startswith("warning: ") else f"note: {n}")
        return "\n".join(lines)


def _sensor_for(cal_setup: MeasurementSetup, heldout) -> tuple[Sensor, str]:
    """The identified sensor that reads ``heldout``, and how it was chosen: with the
    calibration's sessions (``cal_setup.session_sensors``), each held-out pose is read by
    the sensor of its session label where the calibration had that session, else by the
    first session's."""
    from pkmcal.sensors.sessions import SessionSensor

    known = dict(getattr(cal_setup, "session_sensors", ()) or ())
    ses = getattr(heldout, "sessions", None)
    if not known:
        return cal_setup.sensor, "the sensor identified with the machine"
    first = next(iter(known))
    if ses is None:
        return cal_setup.sensor, (f"the sensor identified with the machine in session {first} (the held-out file "
                                  "has no 'session' column)")
    unknown = [lab for lab in ses.labels if lab not in known]
    how = (f"each pose read by the identified sensor of its session ({', '.join(l for l in ses.labels if l in known)})"
           + (f"; sessions {', '.join(unknown)} were not calibrated: read by session {first}'s" if unknown else ""))
    values = {lab: known[lab] for lab in ses.labels if lab in known}
    if not ses.several:
        return values.get(ses.labels[0], cal_setup.sensor), how
    return SessionSensor.start(cal_setup.sensor, ses, values), how


def _free_names(sensor: Sensor) -> tuple[str, ...]:
    return tuple(sensor.default_free)


def heldout_validation(calibrated: Mechanism, cal_setup: MeasurementSetup, nominal: Mechanism | None,
                       before_sensor: Sensor | None, heldout, *, source: str = "held-out measurements",
                       before_note: str = "", notes=(), clipped=(), before_sessions=()) -> HeldoutReport:
    """:class:`HeldoutReport` of ``calibrated`` with the identified sensor of ``cal_setup``
    on the measurements ``heldout`` (module docstring); ``before`` with ``nominal`` and
    ``before_sensor`` (the sensor registered on the calibration data; with sessions,
    ``before_sessions`` ((label, sensor), ...) each session's, chosen per held-out pose as
    for ``after``) when both are given,
    and ``after_reregistered`` with the setup's free sensor parameters refitted on
    ``heldout``."""
    if calibrated.n_actuators != calibrated.n_dof:
        raise PkmcalError(f"machine '{calibrated.name}' is redundantly actuated: held-out measurements need FK from "
                          "the actuator readings alone; verify it against a true machine with --real")
    models: dict[str, Predicted] = {}
    notes = list(notes)
    if nominal is not None and before_sensor is not None:
        bsetup = dataclasses.replace(cal_setup, sensor=before_sensor, session_sensors=tuple(before_sessions))
        b_sensor, how = _sensor_for(bsetup, heldout)
        models["before"] = predict(nominal, b_sensor, heldout, "before",
                                   before_note + (f"; {how}" if before_sessions else ""))
    else:
        notes.append("no 'before' column: " + (before_note or "no nominal machine"))
    after_sensor, after_note = _sensor_for(cal_setup, heldout)
    models["after"] = predict(calibrated, after_sensor, heldout, "after", after_note, reference=nominal)
    after = models["after"]
    if not after.ok.any():
        raise PkmcalError(f"the calibrated machine's FK fails at every pose of {source}; check that the measurements "
                          "belong to this machine")
    # the re-registration starts its FK from the poses just solved (in the calibrated machine's frames)
    keep = np.flatnonzero(after.ok)
    good = dataclasses.replace(heldout.subset(keep), commanded=after.poses[keep])
    reg = register_sensor(calibrated, cal_setup, good, what=f"the held-out data ({source})")
    models["after_reregistered"] = predict(calibrated, reg.sensor, heldout, "after_reregistered", reg.note,
                                           reference=nominal)
    order = {k: models[k] for k in MODELS if k in models}
    return HeldoutReport(source, cal_setup.sensor.kind, np.asarray(heldout.pose_numbers, dtype=int), order,
                         tuple(notes), tuple(clipped))


__all__ = [
    "MODELS",
    "HeldoutReport",
    "Predicted",
    "Registration",
    "heldout_validation",
    "predict",
    "register_sensor",
    "sensor_from_values",
    "sensor_values",
]

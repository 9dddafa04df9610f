"""Validation of a calibrated machine file on held-out data (``pkmcal verify``, the Python
API's :func:`pkmcal.verify`).

* :func:`verify_measured`: measured held-out data (:mod:`pkmcal.identification.heldout`):
  each held-out measurement predicted from its actuator readings (FK of the calibrated
  machine, then the sensor identified with it, the file's ``setup:``) and compared with what
  was measured; "before" the nominal machine with its sensor frames registered on the
  calibration data (the record's ``before_registration``), "after re-registering" the
  calibrated machine with only the setup's free sensor parameters refitted on the held-out
  data (what no re-registration of the instrument removes).
* :func:`verify_against_real`: a simulated true machine commanded at held-out poses through
  each model (:mod:`pkmcal.identification.verification`: e_p = ‖p_r − p_c‖,
  e_R = ∠(R_r R_cᵀ); sensor readings, aligned frames or commanded poses; a redundantly
  actuated machine at static equilibrium, compared on its tool point).

Both add the standard's figures where the held-out poses follow its pattern
(:class:`WithStandardFigures`: ISO 9283 AP/RP/AD/RD, :mod:`pkmcal.identification.iso9283`;
a ballbar circle's ISO 230-4 figures, :mod:`pkmcal.identification.iso230_4`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError


def _is_spec(value) -> bool:
    return isinstance(value, (str, os.PathLike))


def _machine(spec):
    """A machine from a file or built-in name, or the machine given."""
    from pkmcal.io.lookup import load_machine

    return load_machine(spec) if _is_spec(spec) else spec


def verify_against_real(calibrated, real_spec, poses, *, nominal=None, setup=None, compare: str = "auto",
                        ignore_limits=(), mapping=None):
    """``pkmcal verify CALIBRATED --real REAL --poses HELDOUT.csv``: the
    :class:`~pkmcal.identification.verification.VerificationReport` of the calibrated machine
    (file or machine) against the true machine ``real_spec`` at ``poses`` (a pose file or
    an (N, n) array in internal units); ``nominal`` the "before" model, ``setup`` the true
    instrument (``compare="sensor"``) or a redundant machine's simulation setup."""
    from pkmcal.identification.simulation import settles_at_equilibrium
    from pkmcal.identification.verification import verify
    from pkmcal.io.lookup import load_setup
    from pkmcal.io.tables import read_poses
    from pkmcal.workflow.inputs import single_pose_setup_of

    setup_spec = setup
    cal = _machine(calibrated)
    real = _machine(real_spec)
    nom = None if nominal is None else _machine(nominal)
    for other in (real, nom):
        if other is not None and other.kind != cal.kind:
            raise PkmcalError(f"machine '{other.name}' is not of the kind of '{cal.name}' "
                              f"({other.kind} vs {cal.kind})")
    setup = sensors = true_sensor = frames = None
    if settles_at_equilibrium(cal):
        if setup_spec is None:
            raise PkmcalError(f"machine '{cal.name}' is redundantly actuated: give --setup SETUP with the "
                              "'simulation:' stiffness and load the real machine settles under")
        if compare not in ("auto", "sensor"):
            raise PkmcalError(f"--compare {compare}: a redundantly actuated machine is verified on what its tracker "
                              "reads (the tool point); leave out --compare")
        mode, setup = "tool", load_setup(setup_spec, cal) if _is_spec(setup_spec) else setup_spec
    else:
        mode = ("sensor" if setup_spec is not None else "aligned") if compare == "auto" else compare
        if mode == "sensor":
            if setup_spec is None:
                raise PkmcalError("--compare sensor compares what the true instrument reads: give it with --setup "
                                  "TRUE-SETUP.yaml (the setup the measurements were simulated with)")
            true_sensor = single_pose_setup_of(setup_spec, real).sensor     # printed distances: the probe
            cal_setup = _identified_setup(calibrated, cal, "--compare sensor")
            if cal_setup.sensor.kind != true_sensor.kind:
                raise PkmcalError(f"the true instrument ({setup_spec}) is a '{true_sensor.kind}' sensor, the one "
                                  f"identified in {calibrated} a '{cal_setup.sensor.kind}' sensor; give the same kind")
            before_sensor = None
            if nom is not None:
                before_sensor = _before_sensor(cal, cal_setup, nom, None, None, mapping)[0]
            sensors = (cal_setup.sensor, before_sensor)
        elif setup_spec is not None:
            raise PkmcalError(f"--setup is the true instrument, whose readings --compare sensor compares; with "
                              f"--compare {mode} remove it")
        frames = nom if nom is not None or mode == "commanded" else nominal_from_record(cal)[0]
        if frames is not None and frames.kind != cal.kind:
            frames = None
    x = read_poses(poses, cal, mapping) if _is_spec(poses) else np.asarray(poses, dtype=float)
    report = verify(cal, real, x, nominal=nom, ignore_limits=tuple(ignore_limits), compare=mode, sensors=sensors,
                    true_sensor=true_sensor, frames=frames, setup=setup)
    if mode == "tool":
        return report
    from pkmcal.identification.iso9283 import verification_figures

    # the held-out poses in the ISO 9283 pattern (plan --pattern iso9283): the standard's figures, exact
    return WithStandardFigures(report, verification_figures(report, cal, x, machine_covariance=cal.covariance,
                                                            identified=cal.metadata.get("setup")))


def _identified_setup(path: str, cal, what: str):
    """The setup identified with the calibrated machine (its file's ``setup:``) as it reads
    single poses (a printed-distance calibration: its identified Z probe)."""
    from pkmcal.workflow.inputs import single_pose_setup_of

    if "setup" not in cal.metadata or not os.path.exists(path):
        raise PkmcalError(f"{what}: {path} has no identified setup (setup:, written by 'pkmcal identify' since "
                          "2026-12); recalibrate, or compare without the sensor")
    return single_pose_setup_of(path, cal)


def nominal_from_record(cal):
    """The nominal machine the calibration record names, when it is a built-in or a file
    that still exists; ``(machine or None, why not)``."""
    from pkmcal.io.lookup import load_machine
    from pkmcal.mechanisms.library import is_builtin_name

    record = dict(cal.metadata.get("calibration") or {})
    src = (record.get("inputs") or {}).get("machine") or {}
    spec = src.get("builtin") or src.get("file")
    if not isinstance(spec, str):
        return None, "the calibration record names no nominal machine; give --nominal"
    if "builtin" in src and is_builtin_name(spec) or os.path.isfile(spec):
        return load_machine(spec), ""
    return None, f"the nominal machine of the calibration record ('{spec}') is neither a built-in nor an existing " \
                 "file; give --nominal"


def _before_sensor(cal, cal_setup, nominal, setup, calib_meas, mapping):
    """``(sensor, note)`` of the nominal machine for 'before': the sensor registered on the
    calibration data (calibration.before_registration, else a registration on
    --calibration-measurements), or (None, why); third, with sessions, each session's
    ((label, sensor), ...) from calibration.before_registration_sessions."""
    from pkmcal.identification.heldout import register_sensor, sensor_from_values

    record = dict(cal.metadata.get("calibration") or {})
    stored = record.get("before_registration")
    if not cal_setup.sensor.default_free:
        return cal_setup.sensor, "no free sensor parameter: the sensor as the setup gives it", ()
    if calib_meas is not None:
        from pkmcal.io.measurements import load_measurements

        base = setup if setup is not None else cal_setup
        reg = register_sensor(nominal, base, load_measurements(calib_meas, nominal, base, mapping),
                              what=f"the calibration data ({calib_meas})")
        return reg.sensor, reg.note, ()
    if isinstance(stored, dict):
        per = record.get("before_registration_sessions") or {}
        sessions = tuple((str(lab), sensor_from_values(cal_setup.sensor, v, "calibration.before_registration_sessions"))
                         for lab, v in per.items()) if isinstance(per, dict) else ()
        return (sensor_from_values(cal_setup.sensor, stored, "calibration.before_registration"),
                f"{', '.join(stored)} registered on the calibration data with the nominal machine held "
                "(calibration.before_registration" + (", per session" if sessions else "") + ")", sessions)
    return None, ("the calibrated file has no calibration.before_registration (written by 'pkmcal identify' since "
                  "2026-12): give --nominal and --calibration-measurements MEAS.csv to register the nominal machine's "
                  "sensor frames on the calibration data"), ()


def verify_measured(calibrated, heldout, *, nominal=None, setup=None, calibration_measurements=None,
                    clipped: str = "drop", mapping=None):
    """Measured held-out validation of the calibrated machine file ``calibrated``
    (``pkmcal verify CALIBRATED.yaml --held-out HELDOUT.csv``): each held-out measurement
    predicted from its actuator readings with the calibrated machine and its identified
    sensor, beside "before" (``nominal``, default the record's machine, with its sensor
    registered on the calibration data: the record's ``before_registration``, or a
    registration on ``calibration_measurements``) and "after re-registering" (a
    :class:`~pkmcal.identification.heldout.HeldoutValidation`)."""
    from pkmcal.identification.heldout import heldout_validation
    from pkmcal.identification.simulation import settles_at_equilibrium
    from pkmcal.io.lookup import load_machine
    from pkmcal.io.measurements import apply_clipped_policy, load_measurements
    from pkmcal.io.lookup import load_setup
    from pkmcal.mechanisms.pose_pairs import read_by
    from pkmcal.workflow.inputs import machine_and_setup

    meas_path, setup_spec, calib_meas = heldout, setup, calibration_measurements
    cal = load_machine(calibrated)
    if "setup" in cal.metadata:     # read as the identified sensor reads it (pose pairs: printed distances)
        cal, cal_setup = machine_and_setup(calibrated, calibrated)
    given = None if setup_spec is None else load_setup(setup_spec, cal)
    if "setup" in cal.metadata:
        if given is not None and given.sensor.kind != cal_setup.sensor.kind:
            raise PkmcalError(f"--setup {setup_spec} has a '{given.sensor.kind}' sensor, {calibrated} was identified "
                              f"with a '{cal_setup.sensor.kind}' sensor; give the setup of the calibration")
    elif given is not None:
        cal, cal_setup = machine_and_setup(calibrated, setup_spec)
    else:
        raise PkmcalError(f"{calibrated} has no identified setup (setup:): give the measurement setup with --setup")
    if settles_at_equilibrium(cal):
        raise PkmcalError(f"machine '{cal.name}' is redundantly actuated: held-out measurements need FK from the "
                          "actuator readings alone; verify it against a true machine with --real")
    notes: list[str] = []
    if nominal is not None:
        nom, why = _machine(nominal), ""
    else:
        nom, why = nominal_from_record(cal)
    if nom is not None:
        nom = read_by(nom, cal_setup.sensor)
        if nom.kind != cal.kind:
            raise PkmcalError(f"machine '{nom.name}' is not of the kind of '{cal.name}' ({nom.kind} vs {cal.kind})")
    if calib_meas is not None and nom is None:
        raise PkmcalError(f"--calibration-measurements registers the nominal machine's sensor frames: {why}")
    before_sensor, note, before_sessions = (None, why, ()) if nom is None else \
        _before_sensor(cal, cal_setup, nom, given, calib_meas, mapping)
    read = load_measurements(meas_path, cal, cal_setup, mapping) if _is_spec(meas_path) else meas_path
    held, found, lines = apply_clipped_policy(read, cal, clipped)
    unit = {n: ("deg" if a else "mm") for n, a in zip(cal.actuator_names, cal.actuator_is_angle)}
    notes.extend(f"warning: {w}" for w in lines)
    report = heldout_validation(cal, cal_setup, nom, before_sensor, held, source=str(meas_path), before_note=note,
                                notes=notes, before_sessions=before_sessions, clipped=tuple(c.to_dict(unit[c.actuator]) for c in found))
    from pkmcal.identification.iso230_4 import heldout_circle
    from pkmcal.identification.iso9283 import heldout_figures

    iso = heldout_figures(cal, cal_setup, held, identified=cal.metadata.get("setup"), machine_covariance=cal.covariance)
    if iso is None:       # a ballbar's circle test (plan --algorithm circle)
        iso = heldout_circle(cal, cal_setup, held)
    return WithStandardFigures(report, iso)


@dataclass(frozen=True)
class WithStandardFigures:
    """A verification (``report``: a :class:`~pkmcal.identification.verification.VerificationReport`
    or :class:`~pkmcal.identification.heldout.HeldoutValidation`, whose attributes it
    answers) with the standard figures of its held-out poses: ``iso`` the ISO 9283 figures
    (poses in the pattern of ``plan --pattern iso9283``) or the ISO 230-4 circle's, a text
    saying why the pattern's figures could not be computed, or None (no pattern)."""

    report: object
    iso: object | str | None

    def __getattr__(self, name):
        if name in ("report", "iso"):       # not yet set (copying, unpickling)
            raise AttributeError(name)
        return getattr(self.report, name)

    def to_dict(self) -> dict:
        """The report's JSON with the figures under 'iso9283' or 'iso230_4'."""
        out = self.report.to_dict()
        if isinstance(self.iso, str):
            out["iso9283"] = self.iso
        elif self.iso is not None:
            out[self.iso.json_key] = self.iso.to_dict()
        return out

    def format_table(self) -> str:
        """The report's table, then the standard's (or why it is missing)."""
        out = self.report.format_table()
        if isinstance(self.iso, str):
            return out + f"\nISO 9283: not computed: {self.iso}"
        return out if self.iso is None else out + "\n" + self.iso.format_table()


__all__ = ["WithStandardFigures", "nominal_from_record", "verify_against_real", "verify_measured"]

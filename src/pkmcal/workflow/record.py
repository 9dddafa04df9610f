"""The calibrated machine file (``pkmcal identify``, :meth:`pkmcal.workflow.Calibration.save`):
its ``calibration`` record, its identified ``setup:`` block, the nominal machine's registered
sensor (``before_registration``) and the held-out validation of ``identify --held-out``.

The record names the inputs with their SHA-256 (:mod:`pkmcal.workflow.provenance`) and the fit
(method, poses, gauge, rms residual, chi²/dof, which covariance); ``setup:`` holds the
identified sensor in setup-file form (:func:`pkmcal.io.setup_file.identified_setup`) with the
1σ of its estimated parameters, so that ``--setup CALIBRATED.yaml`` reads it back; a machine
that settles at equilibrium also gets ``calibration.sensor``, the identified tracker that
``pkmcal verify`` commands it with (:func:`pkmcal.identification.tool_errors.calibrated_sensor`).
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import settles_at_equilibrium
from pkmcal.identification.tool_errors import sensor_calibration_block
from pkmcal.io.measurements import apply_clipped_policy, load_measurements


def identified_setup_of(setup, result):
    """``setup`` with the identified sensor: with several sessions the first session's
    (plain, for any poses) and every session's as ``session_sensors`` (label → sensor), as
    ``--setup CALIBRATED.yaml`` reads them back."""
    from pkmcal.sensors.sessions import session_sensors

    per = session_sensors(result.sensor)
    if len(per) == 1:
        return dataclasses.replace(setup, sensor=result.sensor)
    return dataclasses.replace(setup, sensor=next(iter(per.values())), session_sensors=tuple(per.items()))


def sensor_std(result) -> dict[str, float]:
    """{name: 1σ} (internal units) of the sensor parameters the fit estimated."""
    sensor_names = set(result.sensor.param_names)
    return {n: float(s) for n, s in zip(result.free, result.std) if n in sensor_names}


def setup_block(result, cal_setup) -> dict | None:
    """The ``setup:`` mapping of the calibrated file (:func:`pkmcal.io.setup_file.identified_setup`):
    the identified sensor, the 1σ of its estimated parameters and which covariance they are;
    None for a sensor without parameters or one no setup file can describe.

    With several sessions the first session's sensor is the setup's, and ``sessions:`` gives
    every session's (labels as in the measurement file; ``dq`` its re-homing offsets, with
    ``actuator_offsets: true`` when they were fitted), the form the setup loader reads back
    (``--setup CALIBRATED.yaml`` starts each known session there); ``std`` then names the
    parameters with their sessions (``world.x@2``)."""
    from pkmcal.io._yaml import RawFloat, rad_to_deg_text
    from pkmcal.io.setup_file import identified_setup
    from pkmcal.sensors.sessions import session_sensors, session_setup_values

    if cal_setup is None or not cal_setup.sensor.param_names:
        return None
    per = session_sensors(result.sensor)
    if len(per) == 1:
        try:
            return identified_setup(cal_setup, result.sensor, sensor_std(result), result.uncertainty.description)
        except PkmcalError:   # a sensor kind without a setup-file form
            return None
    first = next(iter(per.values()))
    try:
        doc = identified_setup(dataclasses.replace(cal_setup, sensor=first), first, None,
                               result.uncertainty.description)
    except PkmcalError:
        return None
    angles = set(result.angle_names())
    doc["std"] = {n: float(np.rad2deg(v)) if n in angles else float(v) for n, v in sensor_std(result).items()}
    offsets = {}
    for lab in list(per)[1:]:
        keys = [f"dq_{i + 1}@{lab}" for i in range(result.mechanism.n_actuators)]
        if keys[0] in result.names:
            offsets[lab] = np.array([result.estimate[result.names.index(k)] for k in keys])
    sessions: dict = {"actuator_offsets": True} if offsets else {}
    sessions.update(session_setup_values(result.sensor, offsets, result.mechanism.actuator_is_angle,
                                         angle=lambda v: RawFloat(rad_to_deg_text(v))))
    doc["sessions"] = sessions
    for n, v in zip(result.free, result.std):
        if n.startswith("dq_"):
            doc["std"][n] = float(np.rad2deg(v)) if n in angles else float(v)
    return doc


def setup_json(result, cal_setup) -> dict:
    """The identified setup for ``--json``: the ``setup:`` mapping of the file as plain
    JSON values, with its units."""
    from pkmcal.io._yaml import parse_yaml, dump_yaml, plain

    block = setup_block(result, cal_setup) or {}
    doc = plain(parse_yaml(dump_yaml(block))[0]) if block else {}
    doc["units"] = {k: "mm; deg for a, b, c and angle parameters" for k in
                    ("world", "tool", "plate", "target", "indicators", "plane_offset", "zero", "std")}
    doc["units"]["noise"] = "mm; orientation_deg in deg; actuator mm (deg for rotary actuators)"
    doc["units"]["prior"] = "file units: mm, deg for angle parameters"
    doc["units"]["simulation"] = ("stiffness N/mm (N*mm/rad for rotary actuators), load N, backlash mm (rad for "
                                  "rotary actuators)")
    return doc


def before_registration(nominal, setup, meas, result) -> tuple[dict, str, dict] | None:
    """``(values, note, per_session)``: the setup's free sensor parameters fitted on the
    calibration data with the machine held at nominal (file units), or None where no such fit
    applies (no free sensor parameter, a redundantly actuated machine). With several
    sessions each session is registered on its own poses: ``values`` are the first
    session's, ``per_session`` {label: values} all of them (else empty)."""
    from pkmcal.identification.heldout import register_sensor, sensor_values

    if not setup.sensor.default_free or nominal.n_actuators != nominal.n_dof:
        return None
    used = meas.subset(np.asarray(result.used_poses, dtype=int)) if len(result.used_poses) < len(meas) else meas
    if used.sessions is None or not used.sessions.several:
        reg = register_sensor(nominal, setup, used, what="the calibration data")
        return sensor_values(reg.sensor, setup.sensor.default_free), reg.note, {}
    per, notes = {}, []
    for k, label in enumerate(used.sessions.labels):       # each session's frames on its own poses
        part = dataclasses.replace(used.subset(np.flatnonzero(used.sessions.index == k)), sessions=None)
        reg = register_sensor(nominal, setup, part, what=f"the calibration data of session {label}")
        per[label] = sensor_values(reg.sensor, setup.sensor.default_free)
        notes.append(reg.note)
    return per[used.sessions.labels[0]], "; ".join(notes), per


def identify_heldout_validation(calibrated, cal_setup, nominal, before, path, mapping, clipped: str):
    """The held-out validation of ``identify --held-out`` (:mod:`pkmcal.identification.heldout`);
    ``path`` a measurement file or loaded :class:`~pkmcal.io.measurements.Measurements`."""
    from pkmcal.identification.heldout import heldout_validation, sensor_from_values

    read = load_measurements(path, calibrated, cal_setup, mapping) if isinstance(path, (str, os.PathLike)) else path
    held, found, lines = apply_clipped_policy(read, calibrated, clipped)
    if before is not None:
        before_sensor, note = sensor_from_values(cal_setup.sensor, before[0], "before_registration"), before[1]
        before_sessions = tuple((lab, sensor_from_values(cal_setup.sensor, v, "before_registration"))
                                for lab, v in before[2].items())
    else:   # no free sensor parameter: nothing to register, the sensor as the setup gives it
        before_sensor, note = cal_setup.sensor, "no free sensor parameter: the sensor as the setup gives it"
        before_sessions = ()
    unit = {n: ("deg" if a else "mm") for n, a in zip(calibrated.actuator_names, calibrated.actuator_is_angle)}
    source = str(path) if isinstance(path, (str, os.PathLike)) else "the held-out measurements"
    return heldout_validation(calibrated, cal_setup, nominal, before_sensor, held, source=source,
                              before_note=note, before_sessions=before_sessions, notes=[f"warning: {w}" for w in lines],
                              clipped=tuple(c.to_dict(unit[c.actuator]) for c in found))


def with_calibration_record(result, machine, measurements, setup_spec, name: str | None,
                             setup=None, before=None, accepted=None, undetermined=(), command: str | None = None):
    """The identified machine under its own name with a ``calibration`` record in its
    metadata (kept in the machine file; ``pkmcal export --format json`` shows it): name,
    calibrated-from, UTC date, pkmcal version, ``command`` (the command line; None from
    Python), the inputs with their SHA-256 (:mod:`pkmcal.workflow.provenance`; ``machine``,
    ``measurements``, ``setup_spec`` are file paths or built-in names), and the fit; ``before`` (values, note) is stored as
    ``calibration.before_registration``. With ``setup`` (the setup with the identified
    sensor) the identified setup goes under ``setup:`` (:func:`setup_block`).
    ``accepted``: the :class:`~pkmcal.identification.fit_verdict.FitVerdict` of a refused fit
    written with ``--accept-bad-fit``, stored as ``calibration.accepted_bad_fit``.
    ``undetermined``: the named directions the data left undetermined
    (:func:`~pkmcal.identification.identifiability.undetermined_directions`), stored as
    ``calibration.undetermined`` (what ``export`` prints and writes as comments).
    ``SOURCE_DATE_EPOCH`` fixes the date, so that the same inputs give the same bytes."""
    from pkmcal import __version__
    from pkmcal.workflow.provenance import utc_timestamp

    mech = result.mechanism
    if not dataclasses.is_dataclass(mech) or "metadata" not in {f.name for f in dataclasses.fields(mech)}:
        return mech
    date = utc_timestamp()
    new_name = name if name is not None else f"{mech.name}-calibrated-{date[:10]}"
    if not new_name.strip():
        raise PkmcalError("--name '': give the calibrated machine a name, e.g. --name hexapod-A-2026")
    u = result.uncertainty
    record = {
        "name": new_name, "calibrated_from": mech.name, "date": date, "pkmcal_version": __version__,
        "command": command,
        "inputs": {"machine": _input(machine), "setup": _input(setup_spec), "measurements": _input(measurements)},
        "method": result.method, "weighted": bool(result.weighted), "measurements": _spec_text(measurements),
        "setup": _spec_text(setup_spec), "n_poses": int(len(result.used_poses)), "n_free": int(len(result.free)),
        "free": [str(n) for n in result.free],
        "gauge": list(result.gauge), "rms_residual": float(result.rms_residual),
        # undefined (null) without degrees of freedom
        "reduced_chi2": float(u.reduced_chi2) if np.isfinite(u.reduced_chi2) else None, "std": u.description,
    }
    if result.loss != "linear":
        record["loss"] = result.loss
    if accepted is not None:
        record["accepted_bad_fit"] = {"problems": list(accepted.problems), "diagnoses": list(accepted.diagnoses)}
    if undetermined:
        record["undetermined"] = [{"meaning": e["meaning"], "status": e["status"], "unit": e["unit"],
                                   "sigma": float(e["sigma"]) if np.isfinite(e["sigma"]) else None,
                                   "tolerance": float(e["tolerance"]), "held": list(e["held"]), "remedy": e["remedy"],
                                   "placement": bool(e["placement"]), "note": bool(e["note"]),
                                   "text": e["text"]}
                                  for e in undetermined]
    sc = result.screening
    if sc is not None and sc.rejected:
        record["rejected_poses"] = [o.pose for o in sc.rejected]
    if len(result.priors):
        record["priors"] = {e["parameter"]: f"{e['mean']!r} ± {e['std']!r} {e['unit']}"
                            for e in result.priors.to_dict(result.estimate, {})}
    if settles_at_equilibrium(mech):  # its tracker, read back by 'pkmcal verify' (compare="tool")
        from pkmcal.sensors.sessions import session_sensors

        # several sessions: the first session's tracker (the reference; every one is in the summary)
        record["sensor"] = sensor_calibration_block(next(iter(session_sensors(result.sensor).values())))
    if before is not None:
        record["before_registration"] = dict(before[0])
        if before[2]:
            record["before_registration_sessions"] = {lab: dict(v) for lab, v in before[2].items()}
    metadata = {k: v for k, v in dict(mech.metadata).items() if k != "setup"}   # a recalibration's old setup
    metadata["calibration"] = record
    block = setup_block(result, setup)
    if block is not None:
        metadata["setup"] = block
    return dataclasses.replace(mech, name=new_name, metadata=metadata)


def _is_spec(spec) -> bool:
    return isinstance(spec, (str, os.PathLike))


def _input(spec) -> dict:
    """The record of an input: :func:`~pkmcal.workflow.provenance.input_record` of a file or
    built-in name; ``{"python": what}`` of an object given from Python (no file to name)."""
    from pkmcal.workflow.provenance import input_record

    return input_record(spec) if _is_spec(spec) else {"python": _spec_text(spec)}


def _spec_text(spec) -> str:
    """A file path or built-in name as given; an object given from Python as
    ``(python KIND 'NAME')``."""
    if _is_spec(spec):
        return os.fspath(spec)
    name = getattr(spec, "name", None)
    return f"(python {type(spec).__name__}" + (f" '{name}')" if isinstance(name, str) else ")")


def check_loads_back(text: str, output: str) -> None:
    """Refuse to write a calibrated machine file that pkmcal itself would not load (e.g. a
    fit that wandered to a leg offset of 10 km: beyond :mod:`pkmcal.io.limits`)."""
    from pkmcal.errors import InputFileError
    from pkmcal.io.machine_file import machine_from_text

    try:
        machine_from_text(text, output)
    except InputFileError as exc:
        detail = str(exc).split(": ", 1)[1] if ": " in str(exc) else str(exc)
        raise PkmcalError(f"nothing written to {output}: the identified machine would not load as a machine file "
                          f"({detail}); the fit is not meaningful: check the measurements, the setup and the free "
                          "parameters") from None

"""A calibration campaign's result, and the one function that makes it: what ``pkmcal identify``
does, from Python.

:func:`calibrate` reads the inputs (files or objects), fits (:func:`pkmcal.identification.engine.identify`;
paper 1 §V, paper 2 §3, paper 3 §2; the paper-3 baselines :mod:`pkmcal.identification.baselines`),
judges the fit (:mod:`pkmcal.identification.fit_verdict`) and returns a :class:`Calibration`:
the calibrated machine with its calibration record, the identified sensor (``setup:``), the
nominal machine's registered sensor (the fair "before" of held-out validation), and what the
data left undetermined. A :class:`Calibration` then

* ``save(path)``: the calibrated machine file, the same bytes as ``pkmcal identify -o``;
* ``verify(heldout)``: measured held-out validation (before / after / after re-registering the
  instrument, :mod:`pkmcal.identification.heldout`), or ``verify(real=, poses=)`` against a
  true machine (:mod:`pkmcal.identification.verification`);
* ``export(fmt)``: every controller format, with the firmware-limited refit where the firmware
  holds a subset (:mod:`pkmcal.workflow.export`);
* ``report(folder)``: the HTML calibration report (:mod:`pkmcal.report`);
* ``to_dict()``: what ``pkmcal identify --json`` prints.

``pkmcal identify`` is a shell over :func:`calibrate`; ``pkmcal.identify`` calls it too.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from pkmcal.errors import PkmcalError, PkmcalWarning

#: What :func:`calibrate` does with a fit :mod:`pkmcal.identification.fit_verdict` refuses:
#: raise (``pkmcal identify``), accept it and say so in the record (``--accept-bad-fit``), or
#: return it with a :class:`~pkmcal.errors.PkmcalWarning` (``pkmcal.identify``; the record
#: says it was accepted).
BAD_FIT = ("refuse", "accept", "warn")


def names_of(values) -> list[str] | None:
    """Names and patterns from option values (comma or blank separated; a string or a
    sequence of them); None when there are none."""
    if values is None:
        return None
    if isinstance(values, str):
        values = (values,)
    out = [n for v in values for n in str(v).replace(",", " ").split() if n]
    return out or None


def merged_free(free: list[str] | None, setup) -> list[str] | None:
    """The free list the fit gets from ``--free`` and the setup (the rule of ``identify
    --help``): None without ``--free`` (the engine's default: every machine parameter and the
    setup's free sensor parameters); else the ``--free`` names and patterns followed by the
    setup's ``free:`` sensor parameters (merged, not replaced; ``--fix`` holds any of them)."""
    if free is None:
        return None
    return list(free) + [n for n in setup.sensor.default_free if n not in free]


def _is_spec(value) -> bool:
    return isinstance(value, (str, os.PathLike))


@dataclass(frozen=True, eq=False)
class Calibration:
    """The result of a calibration campaign (:func:`calibrate`; module docstring).

    Attributes
    ----------
    result : the engine's :class:`~pkmcal.identification.engine.IdentificationResult` (with
        the workflow's warnings: clipped readings, suspect inputs, undetermined directions);
        its attributes are this object's too (``calibration.parameters``, ``.mechanism``,
        ``.sensor``, ``.success``, ...).
    nominal : the nominal machine as the sensor reads it (pose pairs for printed distances).
    nominal_setup : the setup the fit started from.
    measurements : the measurements fitted (after the clipped-reading policy);
        ``read`` as read, ``clipped`` the clipped readings found, ``clipped_lines`` their warnings.
    verdict : the :class:`~pkmcal.identification.fit_verdict.FitVerdict` (with diagnoses
        when refused); ``causes`` what the inputs look wrong by.
    sources : the machine, measurements and setup as given (files or built-in names are
        recorded with their SHA-256; objects as ``(python KIND 'NAME')``).
    """

    result: Any
    nominal: Any
    nominal_setup: Any
    measurements: Any
    read: Any
    verdict: Any
    sources: tuple = (None, None, None)
    fit_setup: Any = None
    clipped: tuple = ()
    clipped_lines: tuple[str, ...] = ()
    causes: tuple[str, ...] = ()
    baseline: str | None = None
    priors: tuple = ()
    free_option: tuple[str, ...] | None = None
    undetermined: tuple = ()
    name: str | None = None
    command: str | None = None
    mapping: Any = None
    clipped_policy: str = "drop"
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __getattr__(self, name: str):
        if name.startswith("__") or name in ("result", "_cache"):
            raise AttributeError(name)
        return getattr(self.result, name)

    # -- what the calibrated file holds -------------------------------------------------
    @cached_property
    def setup(self):
        """The setup with the identified sensor (with sessions: the first session's sensor
        and every session's as ``session_sensors``), as ``--setup CALIBRATED.yaml`` reads it
        back; None for a paper-3 baseline (a reduced model)."""
        from pkmcal.workflow.record import identified_setup_of

        return identified_setup_of(self.nominal_setup, self.result) if self.baseline is None else None

    @cached_property
    def before(self):
        """``(values, note, per_session)`` of the nominal machine's sensor registered on the
        calibration data (the fair "before" of held-out validation,
        :func:`pkmcal.workflow.record.before_registration`), or None."""
        from pkmcal.workflow.record import before_registration

        if self.baseline is not None or not self._loaded:
            return None
        return before_registration(self.nominal, self.nominal_setup, self.measurements, self.result)

    @cached_property
    def geometry(self):
        """The calibrated geometry in readable terms (:func:`pkmcal.identification.geometry.readable_geometry`),
        or None for a machine without joint points."""
        from pkmcal.identification.geometry import readable_geometry

        mech = self.result.mechanism
        if not (mech.point_sets or "leg-lengths" in mech.abilities):
            return None
        return readable_geometry(self.nominal, mech, "the covariance written to the machine file")

    @cached_property
    def machine(self):
        """The calibrated machine under its new name, with its ``calibration`` record and the
        identified ``setup:`` in its metadata (what :meth:`save` writes)."""
        from pkmcal.workflow.record import with_calibration_record

        machine, measurements, setup = self.sources
        return with_calibration_record(self.result, machine, measurements, setup, self.name, setup=self.setup,
                                       before=self.before,
                                       accepted=None if self.verdict.acceptable else self.verdict,
                                       undetermined=self.undetermined, command=self.command)

    def text(self, where: str = "the calibrated file") -> str:
        """The calibrated machine file's text; an error naming ``where`` when pkmcal would not
        load it back (a fit beyond any machine: :func:`pkmcal.workflow.record.check_loads_back`)."""
        from pkmcal.io.machine_file import machine_to_text
        from pkmcal.workflow.record import check_loads_back

        if "text" not in self._cache:
            self._cache["text"] = machine_to_text(self.machine)
        check_loads_back(self._cache["text"], where)
        return self._cache["text"]

    def save(self, path: str | os.PathLike) -> None:
        """Write the calibrated machine file to ``path`` atomically (never over an input): the
        same bytes as ``pkmcal identify ... -o path`` (with ``SOURCE_DATE_EPOCH`` and the same
        ``command``)."""
        from pkmcal.io.atomic import atomic_write_text, check_output_path

        check_output_path(os.fspath(path), self.input_files())
        atomic_write_text(path, self.text(os.fspath(path)))
        self._cache["saved"] = os.fspath(path)      # named in the report

    def input_files(self) -> list[str]:
        """The input files of the campaign (none of which an output may name)."""
        return [os.fspath(s) for s in self.sources if _is_spec(s)]

    @property
    def _loaded(self) -> bool:
        from pkmcal.io.measurements import Measurements

        return isinstance(self.measurements, Measurements)

    # -- after the fit -------------------------------------------------------------------
    def verify(self, heldout=None, *, real=None, poses=None, mapping=None, clipped: str | None = None, **options):
        """Validate the calibration on held-out data.

        ``heldout``: measured held-out data (a measurement file or
        :class:`~pkmcal.io.measurements.Measurements`, not used in the fit): each
        measurement predicted from its actuator readings and compared with what was
        measured, before (the nominal machine with its registered sensor), after, and after
        re-registering the instrument (a :class:`~pkmcal.identification.heldout.HeldoutValidation`;
        ``pkmcal identify --held-out``, ``pkmcal verify --held-out``). ``mapping`` and
        ``clipped`` (default: the fit's policy) read it as the calibration's measurements.

        ``real`` and ``poses``: the true machine of a simulation commanded at the held-out
        poses through each model (:func:`pkmcal.identification.verification.verify`, whose
        ``options`` apply; ``pkmcal verify --real``)."""
        if (heldout is None) == (real is None):
            raise PkmcalError("verify: give exactly one of the held-out measurements or real= (a true machine, with "
                              "poses=)")
        if real is not None:
            from pkmcal.identification.verification import verify as _verify

            if poses is None:
                raise PkmcalError("verify(real=...) needs the held-out poses: give poses=")
            nominal = options.pop("nominal", self.nominal)
            return _verify(self.result.mechanism, real, np.asarray(poses, dtype=float), nominal, **options)
        if self.setup is None:
            raise PkmcalError(f"held-out validation: the {self.baseline} baseline identifies a reduced model; "
                              "validate the full calibration (without a baseline method) on held-out data")
        from pkmcal.mechanisms.pose_pairs import read_by
        from pkmcal.workflow.record import identify_heldout_validation

        return identify_heldout_validation(read_by(self.result.mechanism, self.nominal_setup.sensor), self.setup,
                                           self.nominal, self.before, heldout,
                                           self.mapping if mapping is None else mapping,
                                           self.clipped_policy if clipped is None else clipped)

    def export(self, fmt: str, **options):
        """The text of ``pkmcal export CALIBRATED.yaml --format fmt`` (``linuxcnc``,
        ``linuxcnc-ini``, ``json``, ``klipper``, ``marlin``): a linear delta for its firmware
        refitted, by default, on this calibration's own measurements when it has what the
        firmware cannot hold (:func:`pkmcal.workflow.export.export_machine`, whose
        ``options`` apply: ``refit=False``, ``heldout=``, ``accept_undetermined=``, ...).
        Returns an :class:`~pkmcal.workflow.export.Exported` (``.text``, ``.notes``, ``.refit``)."""
        from pkmcal.workflow.export import export_machine

        options.setdefault("campaign", self)
        options.setdefault("source", self._cache.get("saved"))     # json's source: the file save() wrote
        return export_machine(self.machine, fmt, **options)

    def report_data(self, heldout=None, *, measurement_file: str | None = None, output: str | None = None):
        """The :class:`~pkmcal.report.data.ReportData` of this calibration (``heldout``: a
        held-out validation to show; ``output``: the calibrated file named, default the one
        :meth:`save` wrote); the measured poses are the commanded ones of the
        measurements, else the nominal machine's FK of the actuator readings."""
        from pkmcal.io.setup_file import setup_to_yaml
        from pkmcal.report.from_results import report_data_from_results

        meas = self.measurements
        if meas.commanded is not None:
            poses = meas.commanded
        else:
            with np.errstate(all="ignore"):
                fk = self.nominal.fk(meas.actuators)
            poses = np.asarray(fk.poses)[fk.ok]
        try:
            setup_text = setup_to_yaml(self.nominal_setup)
        except PkmcalError:
            setup_text = self.nominal_setup.sensor.kind
        machine, measurements, _ = self.sources
        if measurement_file is None:
            measurement_file = os.fspath(measurements) if _is_spec(measurements) else "(given from Python)"
        if output is None:
            output = self._cache.get("saved", "(not written)")
        facts = (("measurement file", str(measurement_file)), ("calibrated machine file", str(output)))
        return report_data_from_results(self.nominal, self.result, self.nominal_setup, poses, setup_summary=setup_text,
                                        commanded=meas.commanded, facts=facts, heldout=heldout,
                                        calibrated_file=None if str(output).startswith("(") else str(output))

    def report(self, folder: str | os.PathLike, heldout=None, **options):
        """Write the HTML calibration report (``report.html`` and its figures) into ``folder``
        (``pkmcal identify --report``); ``heldout`` a held-out validation to show (or held-out
        measurements, validated first). Returns the written report (``.html`` its path)."""
        check_report_dir(os.fspath(folder), self.input_files())
        if heldout is not None and (_is_spec(heldout) or not hasattr(heldout, "format_table")):
            heldout = self.verify(heldout)
        return write_report(self.report_data(heldout, **options), folder)

    def to_dict(self) -> dict:
        """What ``pkmcal identify --json`` prints (without its ``output`` and ``report`` keys)."""
        from pkmcal.io.json_out import finite_or_null
        from pkmcal.workflow.record import setup_json

        result = self.result
        d = finite_or_null(result.to_dict())
        d["free_rule"] = self.free_rule
        d["verdict"] = self.verdict.to_dict()
        units = dict(zip(self.nominal.actuator_names, self.nominal.actuator_units))
        d["clipped"] = [c.to_dict(units[c.actuator]) for c in self.clipped]
        if self.geometry is not None:
            d["geometry"] = finite_or_null(self.geometry.to_dict())
        if self.setup is not None and self.setup.sensor.param_names:
            d["setup"] = setup_json(result, self.setup)
        if self.before is not None:
            d["before_registration"] = {"values": self.before[0], "note": self.before[1],
                                        "units": {"values": "file units: mm, deg for angle parameters"}}
        return d

    @cached_property
    def free_rule(self) -> str:
        """Which parameters were estimated and where each list came from (one line)."""
        from pkmcal.workflow.text import free_statement

        return free_statement(self.result, None if self.free_option is None else list(self.free_option),
                              self.fit_setup)


def write_report(data, folder):
    """Write the report of :meth:`Calibration.report_data`'s ``data`` into ``folder``
    (:func:`pkmcal.report.write_report`; ``pkmcal identify`` makes the data before it writes
    anything, and the report after the calibrated file)."""
    from pkmcal.report import write_report as _write

    return _write(data, folder)


def check_report_dir(report_dir: str, inputs) -> None:
    """The report folder must be a folder that can be created or written into, and must not
    hold an input file under a report file's name."""
    from pkmcal.io.atomic import check_output_dir, check_output_path
    from pkmcal.report import REPORT_NAME

    check_output_dir(report_dir, "--report")
    if os.path.isdir(report_dir):
        check_output_path(os.path.join(report_dir, REPORT_NAME), inputs)


def _undetermined(nominal, setup, meas, result, priors) -> list[dict]:
    """The named directions (a delta's common scale of arms and radius) these measurements
    and priors leave undetermined, at the measurements' commanded poses (else the poses the
    fit solved): :func:`pkmcal.identification.identifiability.undetermined_directions`."""
    from pkmcal.identification.engine import measurement_arrays
    from pkmcal.identification.identifiability import undetermined_directions

    if result.sessions is not None or not nominal.named_directions():
        return []
    cmd = measurement_arrays(meas)[2]
    poses = cmd if cmd is not None else result.poses
    held = [n for n in result.mechanism.param_names if n not in result.free and n not in result.gauge]
    return undetermined_directions(nominal, setup, poses, priors=priors, held=held, method=result.method)


def _firmware_numbers_undetermined(result) -> list[tuple[str, str]]:
    """The firmware numbers of a calibrated linear delta with vertical rails that its
    covariance leaves beyond tolerance (what export refuses:
    :func:`pkmcal.io.delta_firmware.undetermined_firmware_numbers`); none for other machines
    and for leaning rails, which export refits first."""
    from pkmcal.identification.firmware_refit import machine_covariance
    from pkmcal.io.delta_firmware import exact_rewrite, undetermined_firmware_numbers

    mech = result.mechanism
    if mech.kind != "linear-delta" or exact_rewrite(mech) is None:
        return []
    return undetermined_firmware_numbers(mech, machine_covariance(result))


def calibrate(machine, setup, measurements, *, method: str | None = None, keep=None, free=None, fix=None,
              merge_setup_free: bool = False, priors=(), clipped: str = "drop", mapping=None,
              bad_fit: str = "refuse", name: str | None = None, command: str | None = None,
              where: str = "the calibrated file", **options) -> Calibration:
    """Identify ``machine``'s parameters from ``measurements`` taken with ``setup`` and judge
    the fit: the whole of ``pkmcal identify`` before anything is written.

    Parameters
    ----------
    machine, setup, measurements : a machine file or built-in name or a
        :class:`~pkmcal.mechanisms.base.Mechanism`; a setup file, built-in name or
        :class:`~pkmcal.sensors.base.MeasurementSetup` (a calibrated machine file reuses its
        identified sensor); a measurement CSV or :class:`~pkmcal.io.measurements.Measurements`
        (or what the engine takes: arrays, a mapping). Files and built-in names are recorded
        in the calibration record with their SHA-256.
    method : the engine's method, or a paper-3 baseline (``ignore-redundancy``,
        ``actuator-subset`` with ``keep`` the actuators, 1-based).
    free, fix : names or patterns (strings or lists; ``fix="auto"``). With
        ``merge_setup_free`` the setup's ``free:`` sensor parameters are added to ``free``
        (the command line's rule); else ``free`` is the engine's list as given.
    priors : :class:`~pkmcal.identification.priors.Prior` or ``"NAME=MEAN±STD"`` strings.
    clipped : ``drop`` / ``keep`` / ``error`` poses with a clipped or stuck actuator reading.
    mapping : an :class:`~pkmcal.io.import_mapping.ImportMapping` for the measurement file.
    bad_fit : :data:`BAD_FIT`; ``where`` names the output in a refusal.
    name, command : the calibrated machine's name (default MACHINE-calibrated-DATE) and the
        command line recorded (None from Python).
    options : the engine's (``weighted``, ``form``, ``loss``, ``f_scale``, ``reject``,
        ``session_offsets``, ...: :func:`pkmcal.identification.engine.identify`).
    """
    from pkmcal.identification.baselines import BASELINES, identify_by_method
    from pkmcal.identification.fit_verdict import diagnose, input_causes, judge
    from pkmcal.identification.priors import parse_prior
    from pkmcal.io.measurements import Measurements, apply_clipped_policy, clipped_named_in_errors, load_measurements
    from pkmcal.mechanisms.pose_pairs import single_machine
    from pkmcal.workflow.inputs import machine_and_setup

    if bad_fit not in BAD_FIT:
        raise PkmcalError(f"bad_fit='{bad_fit}': use one of {', '.join(BAD_FIT)}")
    nominal, setup_ = machine_and_setup(machine, setup)   # pose pairs for printed distances
    if _is_spec(measurements):
        read = load_measurements(measurements, nominal, setup_, mapping)
    else:
        read = measurements
    loaded = isinstance(read, Measurements)
    if loaded:
        meas, clipped_found, clipped_lines = apply_clipped_policy(read, nominal, clipped)
    else:
        meas, clipped_found, clipped_lines = read, [], []
    if keep is not None and method != "actuator-subset":
        raise PkmcalError("--keep selects the actuators of --method actuator-subset; use them together")
    baseline = method if method in BASELINES else None
    keep_idx = None
    if keep is not None:
        parts = names_of(keep) if isinstance(keep, str) else [str(k) for k in keep] or None
        if parts is not None and not all(k.isdigit() for k in parts):
            raise PkmcalError(f"--keep '{keep}': give actuator numbers separated by commas, e.g. 1,2")
        keep_idx = None if parts is None else [int(k) - 1 for k in parts]
    fix_names = names_of(fix)
    if fix_names == ["auto"]:
        fix_names = "auto"
    free_names = names_of(free) if merge_setup_free else free
    # (a baseline changes the setup's noise, not its sensor: the setup's free sensor parameters hold)
    free_fit = merged_free(free_names, setup_) if merge_setup_free else free_names
    priors = tuple(parse_prior(p) if isinstance(p, str) else p for p in (priors or ()))

    def fit(with_priors=True):
        return identify_by_method(nominal, setup_, meas, method, keep_idx, free=free_fit, fix=fix_names,
                                  priors=priors if with_priors else (), **options)

    with clipped_named_in_errors(clipped_lines):
        result = fit()
        if nominal is not single_machine(nominal):    # pose pairs: the machine file holds the machine
            result = dataclasses.replace(result, mechanism=single_machine(result.mechanism))
        u = result.uncertainty
        if u.dof <= 0 and bad_fit != "warn":
            raise PkmcalError(
                f"{len(result.used_poses)} poses give {u.dof + len(result.free)} residuals for {len(result.free)} free "
                f"parameters{' (after fixing the gauge)' if result.gauge else ''}: no degree of freedom is left to "
                "check the fit (chi2/dof undefined); measure more poses or fix parameters; nothing written")
        causes = input_causes(nominal, setup_, meas) if loaded else []
        verdict = judge(result, causes)
        if not verdict.acceptable:
            if bad_fit == "warn":
                verdict = verdict.with_diagnoses(causes)
                warnings.warn(f"pkmcal identify would refuse this fit: {verdict.text()}", PkmcalWarning, stacklevel=3)
            else:
                verdict = verdict.with_diagnoses(diagnose(
                    result, setup_, meas, causes, n_read=len(read.actuators),
                    refit_without_priors=(lambda: fit(with_priors=False)) if baseline is None and priors else None))
                if bad_fit == "refuse":
                    raise PkmcalError(f"the fit is refused: {verdict.text()}; nothing written to {where}: mend the "
                                      "cause and run again, or write it anyway with --accept-bad-fit (recorded in the "
                                      "file)")
    undetermined = _undetermined(nominal, setup_, meas, result, priors) if baseline is None and loaded else []
    hints = [f"warning: {w}" for w in clipped_lines] + [f"warning: {c}" for c in causes] + \
        [e["text"] if e["note"] else f"warning: {e['text']}" for e in undetermined] + \
        [f"warning: {line}: 'pkmcal export --format klipper|marlin' will refuse it unless accepted by name "
         f"(--accept-undetermined {n})" for n, line in _firmware_numbers_undetermined(result)]
    if not verdict.acceptable and bad_fit == "accept":
        hints.append(f"warning: written with --accept-bad-fit although the fit is refused: {verdict.text()}")
    if hints:
        result = dataclasses.replace(result, warnings=tuple(result.warnings) + tuple(hints))
    return Calibration(result=result, nominal=nominal, nominal_setup=setup_, measurements=meas, read=read,
                       verdict=verdict, sources=(machine, measurements, setup), fit_setup=setup_,
                       clipped=tuple(clipped_found), clipped_lines=tuple(clipped_lines), causes=tuple(causes),
                       baseline=baseline, priors=priors,
                       free_option=None if free_names is None else tuple(free_names),
                       undetermined=tuple(undetermined), name=name, command=command, mapping=mapping,
                       clipped_policy=clipped)


__all__ = ["BAD_FIT", "Calibration", "calibrate", "check_report_dir", "merged_free", "names_of", "write_report"]

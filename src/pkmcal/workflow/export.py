"""A calibrated machine for its controller: the text of every export format, with the
firmware-limited refit where the firmware holds a subset (``pkmcal export``, the Python API's
:func:`pkmcal.export`, :meth:`pkmcal.workflow.Calibration.export`).

* ``linuxcnc`` / ``linuxcnc-ini``: LinuxCNC ``genhexkins`` HAL ``setp`` lines and the INI
  sections that match them (:mod:`pkmcal.io.export_linuxcnc`; strut length
  L_i = ‖p + R a_i − b_i‖, paper 1 eq. 1, paper 2 eq. 1), or a copy of the machine's own INI
  with only pkmcal's keys changed;
* ``klipper`` / ``marlin`` (linear deltas; Klipper also rotary deltas): the firmware's numbers
  (:mod:`pkmcal.io.delta_firmware`, :mod:`pkmcal.io.marlin_settings`). When the machine has
  what the firmware cannot hold (rail leans, a tool offset) the export is, by default, the
  firmware-limited refit (:mod:`pkmcal.identification.firmware_refit`) on the measurements
  the calibration record names (unchanged: their SHA-256) or on the campaign's own
  measurements (:meth:`~pkmcal.workflow.Calibration.export`), or on measurements given;
  what the calibration left undetermined is a comment, and a firmware number whose standard
  deviation (:func:`pkmcal.io.delta_firmware.firmware_sigmas`) is above its tolerance is
  refused unless accepted by name (issue 25);
* ``json``: parameters with σ and correlations (:mod:`pkmcal.io.calibration_json`).

Notes for the user (what the firmware cannot hold, the refit's report) go to a ``note``
callback one line at a time (the command line prints them on standard error as they come)
and are kept in :attr:`Exported.notes`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Callable

from pkmcal.errors import PkmcalError

#: Formats of :func:`export_machine` (those of ``pkmcal export --format``, and the INI sections alone).
EXPORT_FORMATS = ("linuxcnc", "linuxcnc-ini", "json", "klipper", "marlin")


def _ignore(line: str) -> None:
    """The default ``note``: lines are only kept in :attr:`Exported.notes`."""


def _is_spec(value) -> bool:
    return isinstance(value, (str, os.PathLike))


@dataclass
class Exported:
    """What an export made: ``text`` (the main output), ``ini_text`` (LinuxCNC's INI, with
    ``ini=True`` or ``update_ini``), ``notes`` (the lines for the user, ``pkmcal: ...``),
    ``refit`` (the :class:`~pkmcal.identification.firmware_refit.FirmwareRefit` exported, or
    None), ``recorded`` (the measurement file and setup of a refit the calibration record
    named, or None)."""

    fmt: str
    text: str
    ini_text: str | None = None
    notes: list[str] = field(default_factory=list)
    refit: Any = None
    recorded: tuple[str, str] | None = None

    def __str__(self) -> str:
        return self.text


def export_machine(machine, fmt: str, *, source=None, ini: bool = False, update_ini=None,
                   stroke_margin: float | None = None, measurements=None, setup=None, heldout=None,
                   klipper_config=None, marlin_version: str = "2.1.x", steps_per_mm: float | None = None,
                   refit: bool = True, accept_undetermined=(), campaign=None, output=None,
                   note: Callable[[str], None] = _ignore) -> Exported:
    """Export ``machine`` (a calibrated machine, or a machine file / built-in name) as
    ``fmt`` (:data:`EXPORT_FORMATS`); module docstring.

    Parameters
    ----------
    source : the machine file it was read from (``json``'s ``source``; where a relative
        path of the calibration record is looked for).
    ini, update_ini, stroke_margin : ``linuxcnc``: also the INI sections; a copy of the
        machine's own INI file with pkmcal's keys changed; the joint limits' margin (mm).
    measurements, setup, heldout : ``klipper`` / ``marlin``: the firmware-limited refit on
        these (files or loaded), with the held-out rms in its report.
    refit : False: the calibrated machine's own numbers, never refitted (``--no-refit``).
    campaign : a :class:`~pkmcal.workflow.Calibration` whose measurements and setup the
        default refit uses (instead of the files the record names).
    accept_undetermined : names or patterns of firmware numbers exported although the data
        leave them undetermined (``--accept-undetermined``).
    klipper_config, marlin_version, steps_per_mm : Klipper's whole printer.cfg after
        SAVE_CONFIG; Marlin's version and its steps per mm.
    output : the file the text will be written to (a refit's measurements may not be it).
    note : called with each line for the user as it comes.
    """
    from pkmcal.io.atomic import check_output_path

    if fmt not in EXPORT_FORMATS:
        raise PkmcalError(f"unknown export format '{fmt}'; use one of {', '.join(EXPORT_FORMATS)}")
    if isinstance(accept_undetermined, str):
        accept_undetermined = (accept_undetermined,)
    if _is_spec(machine):
        from pkmcal.io.lookup import load_machine

        source = machine if source is None else source
        machine = load_machine(machine)
    notes: list[str] = []

    def say(line: str) -> None:
        notes.append(line)
        note(line)

    out = Exported(fmt, "", notes=notes)
    if fmt in ("linuxcnc", "linuxcnc-ini"):
        from pkmcal.io import export_linuxcnc as ex

        unit = ex.ini_units(update_ini) if update_ini is not None else None
        hal = ex.linuxcnc_hal(machine, unit, stroke_margin)
        if update_ini is not None:
            out.ini_text = ex.updated_ini(update_ini, machine, stroke_margin)
        elif ini or fmt == "linuxcnc-ini":
            out.ini_text = ex.linuxcnc_ini(machine, unit, stroke_margin)
        else:                               # the HAL file alone: its comments give the home, so say it
            try:
                ex.check_home(machine, ex.joint_settings(machine, ex.export_unit(machine)[1], stroke_margin))
            except PkmcalError as exc:
                say(f"pkmcal: warning: {exc}")
        for line in ex.home_warnings(machine):
            say(f"pkmcal: warning: {line}")
        rounding_note(ex.LINUXCNC_ROUNDING, machine, ex.rounded_machine(machine, unit), "the strut lengths", say)
        out.text = out.ini_text if fmt == "linuxcnc-ini" else hal
        return out
    if fmt == "json":
        from pkmcal.io.calibration_json import format_calibration_json

        out.text = format_calibration_json(machine, source=None if source is None else os.fspath(source))
        return out
    found = None
    if measurements is not None:
        found = refit_on(machine, measurements, setup, heldout, source)
    elif refit:
        if campaign is not None and _needs_refit(machine):
            say("pkmcal: note: refitting for the firmware on the calibration's own measurements (refit=False exports "
                "the calibrated numbers as they are)")
            found = refit_on(machine, campaign.read, campaign.nominal_setup, heldout, source)
        elif campaign is None:
            out.recorded = recorded_measurements(machine, source, say)
            if out.recorded is not None:
                if output is not None and output != "-":
                    check_output_path(output, [out.recorded[0]])
                say(f"pkmcal: note: refitting for the firmware on the calibration's measurements {out.recorded[0]} "
                    f"(setup {out.recorded[1]}; --no-refit exports the calibrated numbers as they are)")
                found = refit_on(machine, out.recorded[0], out.recorded[1], None, source)
    out.refit = found
    lines = undetermined_lines(machine, tuple(accept_undetermined), found)
    notes_only = {str(e.get("text")) for e in ((machine.metadata or {}).get("calibration") or {}).get(
        "undetermined") or () if e.get("note")}       # where prints sit on the bed, the leans: said
    for line in lines:
        say(f"pkmcal: {'note' if line in notes_only else 'warning'}: {line}")
    text = delta_firmware_text(machine, fmt, found, klipper_config, marlin_version, steps_per_mm, say)
    out.text = with_comments(text, lines, "#" if fmt == "klipper" else ";")
    return out


def _needs_refit(machine) -> bool:
    """Whether ``machine`` has what its firmware cannot hold (so that a refit changes what is
    exported)."""
    from pkmcal.io.delta_firmware import firmware_subset

    return machine.kind == "linear-delta" and bool(firmware_subset(machine)[1])


def undetermined_lines(machine, accepted: tuple[str, ...], refit=None) -> list[str]:
    """What the calibration's measurements leave undetermined, one plain line each (printed on
    standard error and written as comments): the record's ``undetermined`` directions (from
    identify) and each firmware number whose standard deviation is above its tolerance
    (:func:`pkmcal.io.delta_firmware.undetermined_firmware_numbers` of the calibrated
    ``machine``'s covariance, or of the firmware-limited ``refit``'s own when it is what is
    exported), which is an error unless ``accepted`` names it."""
    from fnmatch import fnmatchcase

    from pkmcal.identification.firmware_refit import FIRMWARE_FREE, RADII
    from pkmcal.io.delta_firmware import FIRMWARE_NUMBERS, undetermined_firmware_numbers

    if machine.kind != "linear-delta":
        return []
    record = (machine.metadata or {}).get("calibration") or {}
    lines = [str(e.get("text") or e.get("meaning")) for e in record.get("undetermined") or ()]
    known = tuple(FIRMWARE_NUMBERS) + FIRMWARE_FREE + RADII
    for pat in accepted:
        if not any(fnmatchcase(n, pat) for n in known):
            raise PkmcalError(f"--accept-undetermined '{pat}': no firmware number has this name; the names are "
                              f"{', '.join(FIRMWARE_NUMBERS)}")
    source = refit.machine if refit is not None else machine
    cov = refit.covariance if refit is not None else machine.covariance
    if cov is None:
        return lines
    refused = []
    for n, line in undetermined_firmware_numbers(source, cov):
        if any(fnmatchcase(n, pat) for pat in accepted):
            lines.append(f"{line}; exported as accepted with --accept-undetermined")
        else:
            refused.append(line)
    if refused:
        remedy = next((str(e["remedy"]) for e in record.get("undetermined") or ()
                       if e.get("remedy") and not e.get("note")),
                      "add measurements that see it, or a prior on its measured value")
        raise PkmcalError("the export is refused: " + "; ".join(refused) + "; the firmware would hold these numbers "
                          f"as if they were known: {remedy}; or export them anyway with "
                          "--accept-undetermined NAME")
    return lines


def with_comments(text: str, lines: list[str], mark: str) -> str:
    """``text`` after comment lines (``mark``: '#' for Klipper, ';' for Marlin's G-code) that
    say what the measurements did not determine."""
    if not lines:
        return text
    import textwrap

    head = [f"{mark} pkmcal: what the calibration's measurements did not determine:"]
    for line in lines:
        head += textwrap.wrap(line, width=100, initial_indent=f"{mark}   ", subsequent_indent=f"{mark}     ",
                              break_on_hyphens=False)
    return "\n".join(head) + "\n\n" + text


def recorded_measurements(machine, calibrated, note=_ignore) -> tuple[str, str] | None:
    """The measurement file and setup the calibration record names, when the machine has
    what its firmware cannot hold (so that a refit changes what is exported) and the file
    is there unchanged (the record's SHA-256); else None, with a note on standard error
    saying why there is no refit (``note``). ``calibrated``: the machine file (its folder is where a relative
    path of the record is looked for too), or None for a machine given from Python."""
    from pkmcal.workflow.provenance import input_record
    from pkmcal.io.delta_firmware import firmware_subset

    if machine.kind != "linear-delta" or not firmware_subset(machine)[1]:
        return None                                # the firmware holds this machine exactly: nothing to refit
    record = (machine.metadata or {}).get("calibration") or {}
    path, setup = record.get("measurements"), record.get("setup")
    if not path or not setup:
        note(f"pkmcal: note: {calibrated or 'the machine'} has no calibration record naming its measurements and "
             "setup: no firmware-limited refit (give --calibration-measurements MEAS.csv --setup SETUP)")
        return None
    want = ((record.get("inputs") or {}).get("measurements") or {}).get("sha256")
    here = "" if calibrated is None else os.path.dirname(os.fspath(calibrated))
    candidates = [path] if os.path.isabs(path) or not here else [path, os.path.join(here, path)]
    for p in candidates:
        if os.path.isfile(p):
            if want is not None and input_record(p).get("sha256") != want:
                note(f"pkmcal: note: {p} has changed since the calibration (its SHA-256 differs from the "
                     "record's): no firmware-limited refit on it (give --calibration-measurements MEAS.csv to refit)")
                return None
            setup_path = setup if os.path.isabs(setup) or os.path.exists(setup) else \
                os.path.join(here, setup)
            return p, setup_path if os.path.exists(setup_path) else setup
    note(f"pkmcal: note: the calibration's measurements {path} are not found: no firmware-limited refit "
         "(give --calibration-measurements MEAS.csv)")
    return None


def refit_on(machine, measurements, setup_spec=None, heldout=None, calibrated=None):
    """The firmware-limited refit of ``machine`` on the measurement files
    (:func:`pkmcal.identification.firmware_refit.firmware_refit`); ``measurements`` and
    ``heldout`` files or :class:`~pkmcal.io.measurements.Measurements`, ``setup_spec`` a setup
    file, built-in name or setup (default: the calibration record's)."""
    if machine.kind != "linear-delta":
        raise PkmcalError(f"--calibration-measurements refits a linear delta for its firmware; machine '{machine.name}' is a "
                          f"{machine.kind or 'machine of another kind'}")
    from pkmcal.workflow.inputs import machine_read_by
    from pkmcal.identification.firmware_refit import firmware_refit
    from pkmcal.io.measurements import load_measurements

    if setup_spec is None:
        setup_spec = ((machine.metadata or {}).get("calibration") or {}).get("setup")
        if setup_spec is None:
            raise PkmcalError(f"{calibrated or 'the machine'} has no calibration record naming its setup: give --setup SETUP (the "
                              "setup of the measurements, e.g. z-probe-klipper)")
    read, setup = machine_read_by(machine, setup_spec)     # printed distances: the machine read as pose pairs
    meas = load_measurements(measurements, read, setup) if _is_spec(measurements) else measurements
    held = heldout if heldout is None or not _is_spec(heldout) else load_measurements(heldout, read, setup)
    return firmware_refit(read, setup, meas, held)


def delta_firmware_text(machine, fmt: str, refit=None, klipper_config: str | None = None,
                        marlin_version: str = "2.1.x", steps_per_mm: float | None = None, note=_ignore) -> str:
    """The Klipper or Marlin text of a linear delta (or of its firmware-limited ``refit``),
    or Klipper's of a rotary delta; what the machine has that the firmware cannot hold, and
    what the refit costs, on standard error. With ``klipper_config`` the user's printer.cfg
    as Klipper's SAVE_CONFIG leaves it. Notes go to ``note``, one line each."""
    rotary = fmt == "klipper" and machine.kind == "rotary-delta" and refit is None
    if machine.kind != "linear-delta" and not rotary:
        also = " and, to Klipper, rotary deltas" if fmt == "klipper" else ""
        raise PkmcalError(f"--format {fmt} exports linear delta printers{also}; machine '{machine.name}' is a "
                          f"{machine.kind or 'machine of another kind'}")
    from pkmcal.io.delta_firmware import (
        KLIPPER_ROUNDING,
        firmware_subset,
        klipper_rounded,
        klipper_saved_config,
        klipper_text,
        rotary_firmware_subset,
    )
    from pkmcal.io.marlin_settings import MARLIN_ROUNDING, marlin_held, marlin_rounded, marlin_text

    fw, dropped = (rotary_firmware_subset if rotary else firmware_subset)(machine)
    angles = dict(zip(machine.param_names, machine.param_is_angle))
    for d in dropped:
        note(f"pkmcal: warning: {d.describe(angles[d.name])}")
    if refit is None and getattr(fw, "origin", (0.0, 0.0)) != (0.0, 0.0):   # the exact rewrite of unequal radii (io/delta_firmware.py)
        note(f"pkmcal: note: the towers are written about their circle's centre, x {fw.origin[0]:.6g}, y "
             f"{fw.origin[1]:.6g} mm of the calibrated frame: the firmware's x, y are the calibrated ones less "
             "that (z unchanged), and its machine is the calibrated one exactly")
    if refit is not None:
        for line in refit.lines():
            note(f"pkmcal: {line}")
        fw, _ = firmware_subset(refit.machine)   # nothing left out: leans and tool at 0, one radius
        note("pkmcal: note: the exported settings are the firmware-limited refit: the best machine the "
             "firmware can hold on these measurements")
    elif dropped:
        note(f"pkmcal: note: the firmware uses the machine without these {len(dropped)} parameter(s); for the "
             "best machine it can hold and what dropping them costs, give the measurements: "
             "--calibration-measurements MEAS.csv --setup SETUP (and --held-out HELDOUT.csv)")
    steps = None if steps_per_mm is None else (steps_per_mm,) * 3
    if fmt == "klipper":
        text = klipper_saved_config(klipper_config, fw) if klipper_config is not None else klipper_text(fw)
        rounding_note(KLIPPER_ROUNDING, fw.machine("exact"), klipper_rounded(fw).machine("rounded"),
                      "the arm angles" if rotary else "the carriage travels", note)
        return text
    text, lost = marlin_text(fw, marlin_version, steps)
    for line in lost:
        note(f"pkmcal: warning: {line}")
    # against what the version holds (one rod, tower C at 90 deg: said above), the rounding alone
    rounding_note(MARLIN_ROUNDING, marlin_held(fw, marlin_version, steps).machine("exact"),
                  marlin_rounded(fw, marlin_version, steps).machine("rounded"), "the carriage travels", note)
    return text


def rounding_note(rule: str, exact, rounded, what: str, note=_ignore) -> None:
    """The export's line on how its numbers are rounded (``rule``, also a comment line of
    the file) and what the rounding changes: the largest change of ``what`` the controller
    commands over the workspace (:func:`pkmcal.io.delta_firmware.rounding_effect`), to ``note``."""
    from pkmcal.conventions import angle_text, length_text
    from pkmcal.io.delta_firmware import rounding_effect

    change = rounding_effect(exact, rounded)
    if all(exact.actuator_is_angle):     # below 1e-3″ (5e-9 rad) or 1 nm: said so, not in digits of round-off
        shown = f"at most {angle_text(change)}" if change >= 5e-9 else "less than 0.001″"
    else:
        shown = f"at most {length_text(change)}" if change >= 1e-6 else "less than 1 nm"
    note(f"pkmcal: note: {rule}; the rounding changes {what} the controller commands by {shown} over the workspace")


__all__ = ["EXPORT_FORMATS", "Exported", "delta_firmware_text", "export_machine", "recorded_measurements",
           "refit_on", "rounding_note", "undetermined_lines", "with_comments"]

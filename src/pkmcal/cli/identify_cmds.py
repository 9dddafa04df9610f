"""``pkmcal identify`` and ``pkmcal identifiability``: the identification engine on files.

* ``identify``: measurement CSV + setup → calibrated machine file (identified parameters
  and their covariance), a table parameter / nominal / identified / ±σ and a fit summary
  (:func:`pkmcal.identification.engine.identify`; paper 1 §V, paper 2 §3, paper 3 §2).
* ``identifiability``: rank, unobservable combinations and the suggested gauge for a
  machine, setup and pose set (:mod:`pkmcal.identification.identifiability`).

Everything is read, validated and computed before the output file is written (atomically);
on a user error nothing is written and the exit code is 2.
"""

from __future__ import annotations

import dataclasses
import json

import click
import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.fit_verdict import diagnose, input_causes, judge
from pkmcal.identification.identifiability import describe_named, format_direction
from pkmcal.identification.residuals import DEFAULT_METHOD_RULE, METHODS
from pkmcal.identification.robust import DEFAULT_F_SCALE, LOSSES, OUTLIER_SIGMA
from pkmcal.cli._limits import unreachable_notes
from pkmcal.cli.calibrated_file import (
    before_registration,
    check_loads_back,
    identified_setup_of,
    identify_heldout_validation,
    setup_json,
    with_calibration_record,
)
from pkmcal.cli.fit_text import fit_summary, free_statement, result_table
from pkmcal.cli.import_options import import_options
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.cli.options import (STDOUT, DeprecatedArgument, check_output, emit, examples, option, output_option,
                                poses_file, quiet_accepted, to_stdout)
from pkmcal.io.atomic import check_output_path
from pkmcal.io.measurements import CLIPPED_POLICIES, apply_clipped_policy, clipped_named_in_errors, load_measurements
from pkmcal.io.tables import read_poses
from pkmcal.reproduce.paper3_baselines import BASELINES, baseline_inputs, baseline_result
from pkmcal.sensors.library import BUILTIN_SETUPS


def _names(values: tuple[str, ...]) -> list[str] | None:
    out = [n for v in values for n in v.replace(",", " ").split() if n]
    return out or None


def merged_free(free: list[str] | None, setup) -> list[str] | None:
    """The free list the fit gets from ``--free`` and the setup (the rule of ``identify
    --help``): None without ``--free`` (the engine's default: every machine parameter and the
    setup's free sensor parameters); else the ``--free`` names and patterns followed by the
    setup's ``free:`` sensor parameters (merged, not replaced; ``--fix`` holds any of them)."""
    if free is None:
        return None
    return list(free) + [n for n in setup.sensor.default_free if n not in free]


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


@click.command("identify", epilog=examples(
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o calibrated.yaml",
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o hexapod-A.yaml --name hexapod-A-2026",
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o - --unweighted > cal-unweighted.yaml",
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o calibrated.yaml --json",
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o cal-robust.yaml --loss soft_l1 --reject 4",
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o cal-prior.yaml --prior 'L0_*=±0.5'"))
@click.argument("machine")
@click.argument("measurements", metavar="MEAS.csv")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml",
              help=f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)}).")
@click.option("--method", type=click.Choice(METHODS + BASELINES), default=None,
              help="ik-residual (full-pose sensor, paper 1), fk-residual (paper 2), projection (paper 3) or "
                   "projection-single (paper 3 eq. 10: one step linearised at the commanded poses, which the "
                   "measurements must give). "
                   f"Default: {DEFAULT_METHOD_RULE}. Baselines for redundant machines (paper 3 §1): ignore-redundancy "
                   "(encoders assumed at their commands), actuator-subset (only the --keep actuators).")
@click.option("--keep", metavar="I,J", help="With --method actuator-subset: the actuators used, 1-based "
                                            "(default: the first n, n = pose coordinates).")
@click.option("--unweighted", is_flag=True, help="Plain least squares (the papers' fits) instead of noise-weighted.")
@click.option("--form", type=click.Choice(["plain", "squared"]), default="plain", show_default=True,
              help="ik-residual: q - IK(x) or paper 1's squared-length residual.")
@click.option("--fix", "fix", multiple=True, metavar="NAMES",
              help="Parameters to hold (names or patterns like 'b1.*', comma separated; repeatable), or 'auto'.")
@click.option("--free", "free", multiple=True, metavar="NAMES",
              help="Parameters to estimate (names or patterns, comma separated; repeatable). Default: all machine "
                   "parameters and the sensor parameters of the setup's 'free:' list. With --free, the setup's "
                   "'free:' sensor parameters are estimated too: --free adds to that list, it does not replace "
                   "it (hold one of them with --fix). The output states which list each free parameter came from.")
@output_option("CALIBRATED.yaml", "Calibrated machine file to write", default=STDOUT)
@click.option("--name", metavar="NAME",
              help="Name of the calibrated machine (default: MACHINE-calibrated-YYYY-MM-DD, the UTC date).")
@click.option("--json", "as_json", is_flag=True, help="Print the fit as JSON instead of a table.")
@click.option("--report", "report_dir", metavar="DIR",
              help="Also write the HTML calibration report (report.html and its figures) into folder DIR.")
@click.option("--loss", type=click.Choice(LOSSES), default="linear", show_default=True,
              help="Robust loss of scipy.optimize.least_squares on the noise-whitened residual rows: soft_l1, huber "
                   "or cauchy bound (cauchy: shrink) the influence of outlying poses; linear is least squares. "
                   "Chi2 and the covariance are then taken over the poses within the outlier threshold (the "
                   "robust estimator's sandwich covariance, stated in the output).")
@click.option("--f-scale", "f_scale", type=FiniteFloat(min=0.0, min_open=True), metavar="SIGMAS",
              help="Where the robust loss turns from quadratic, in noise sigmas of the whitened rows. Default: 95 % "
                   "efficiency at Gaussian noise (" + ", ".join(f"{k} {v:g}" for k, v in DEFAULT_F_SCALE.items())
                   + ").")
@click.option("--reject", type=FiniteFloat(min=0.0, min_open=True), metavar="K",
              help="Drop the poses beyond K sigma (normalised residual sqrt(|W r|^2/k) of the pose) and refit, "
                   "until none is left; each round drops those at least half as far out as the worst. The output "
                   "lists them with their round. Without it, poses beyond "
                   f"{OUTLIER_SIGMA:g} sigma are listed as a warning and kept.")
@click.option("--prior", "prior", multiple=True, metavar="NAME=MEAN±STD",
              help="Gaussian prior on a parameter (maximum a posteriori; repeatable): a name or pattern, the mean "
                   "and std in mm (degrees for angles), e.g. 'L0_*=640±0.5' or 'L0_*=640+-0.5'; 'b1.z=±0.2' "
                   "centres it on the machine's value. Adds to the setup's prior: list, replacing its prior of "
                   "the same parameter. A prior pins a direction the data cannot see: the automatic gauge does "
                   "not fix it. The covariance is then the posterior one.")
@click.option("--clipped", type=click.Choice(CLIPPED_POLICIES), default="drop", show_default=True,
              help="Poses with an actuator reading outside its stroke or at one of its ends (a clipped or stuck "
                   "actuator): listed with a warning and left out (drop), used (keep), or an error.")
@click.option("--session-offsets", "session_offsets", is_flag=True,
              help="With a 'session' column of several sessions: estimate actuator zero offsets dq_i@LABEL for "
                   "every session but the first (the actuators re-homed between sessions; the first session's "
                   "zeros are the machine's). Same as the setup's 'sessions: {actuator_offsets: true}'.")
@option("--held-out", "heldout", metavar="HELDOUT.csv", old=("--heldout",),
              help="Held-out measurements (same columns as MEAS.csv, not used in the fit): print the validation of "
                   "'pkmcal verify CALIBRATED.yaml --held-out HELDOUT.csv' (before / after / "
                   "after_reregistered) and show it in the --report.")
@click.option("--accept-bad-fit", "accept_bad_fit", is_flag=True,
              help="Write the calibrated file even when the fit is refused (it did not converge; its chi2 is "
                   "beyond what the setup's noise allows even with every noise sigma 3 times larger, or beyond the "
                   "noise while the input looks wrong; or a machine parameter moved further than the machine's "
                   "size: the rule of pkmcal.identification.fit_verdict); the file's calibration record says it "
                   "was accepted and why it was refused.")
@click.option("--history", "history_db", metavar="DB",
              help="Also record the calibration in the history database DB (pkmcal history; with --serial), with "
                   "the --held-out figures.")
@click.option("--serial", metavar="SERIAL", help="With --history: the unit's serial number.")
@import_options
@quiet_accepted
def identify_cmd(machine, measurements, setup_spec, method, unweighted, form, fix, free, output, name, as_json,
                 report_dir=None, mapping=None, keep=None, loss="linear", f_scale=None, reject=None,
                 prior=(), clipped="drop", session_offsets=False, heldout=None, accept_bad_fit=False,
                 history_db=None, serial=None) -> None:
    """Identify MACHINE's kinematic parameters from MEAS.csv and write CALIBRATED.yaml.

    Units: mm, degrees in files and tables. Unidentifiable combinations are fixed
    automatically (the gauge, shown in the table) unless --free/--fix say otherwise, in
    which case an unidentifiable request is an error naming the combination.
    CALIBRATED.yaml carries a calibration record: the machine's new name, the UTC date
    (SOURCE_DATE_EPOCH fixes it), the pkmcal version, the command line and the SHA-256 of
    every input file. Without -o, or with -o -, the machine file goes to standard output and
    the table to standard error.

    Every fit lists its poses beyond the outlier threshold (pose numbers: data rows of
    MEAS.csv counted from 1; how many noise sigmas; the worst residual row); --reject
    drops them and refits, --loss bounds their influence. --prior and the setup's prior:
    add Gaussian priors (maximum a posteriori). The fit summary and --json say which
    covariance is reported (JSON: covariance_kind, covariance_in_file; outliers, priors,
    normalised_residuals).

    Sessions: a 'session' column in MEAS.csv (free text labels) gives each session its own
    sensor parameters, named NAME@LABEL (world.x@2); the machine is shared. A name or
    pattern without @ in --free/--fix means that parameter in every session. The fit
    summary and --json ('sessions') give each session's identified sensor, mm and degrees.

    CALIBRATED.yaml also carries the identified sensor under 'setup:' (setup-file form:
    world/tool/plate/zero... in mm and degrees, with their 1σ 'std:' and the covariance
    they come from), so that '--setup CALIBRATED.yaml' reuses it anywhere, and under
    'calibration.before_registration' the sensor's free parameters fitted with the machine
    held at nominal (the fair "before" of 'pkmcal verify'). --held-out validates the result
    on measurements the fit did not see.
    """
    inputs = [machine, measurements, setup_spec] + ([heldout] if heldout is not None else [])
    check_output(output, inputs)
    from pkmcal.history.store import check_history_request, record_identified

    check_history_request(history_db, serial, to_stdout(output))
    if f_scale is not None and loss == "linear":
        raise PkmcalError("--f-scale sets where a robust --loss turns from quadratic, and the loss is linear (least "
                          f"squares): give --loss ({', '.join(lo for lo in LOSSES if lo != 'linear')}) with it, or "
                          "leave out --f-scale")
    if to_stdout(output) and as_json:
        raise PkmcalError("-o - puts the machine file on standard output; --json would go there too: "
                          "write the machine file to a file, or leave out --json")
    if report_dir is not None:
        _check_report_dir(report_dir, inputs)
    from pkmcal.cli.klipper_probe_cmd import machine_and_setup
    from pkmcal.identification.engine import identify
    from pkmcal.io.machine_file import machine_to_text
    from pkmcal.mechanisms.pose_pairs import read_by, single_machine

    nominal, setup = machine_and_setup(machine, setup_spec)   # pose pairs for printed distances
    read = load_measurements(measurements, nominal, setup, mapping)
    meas, clipped_found, clipped_lines = apply_clipped_policy(read, nominal, clipped)
    if keep is not None and method != "actuator-subset":
        raise PkmcalError("--keep selects the actuators of --method actuator-subset; use them together")
    baseline = method if method in BASELINES else None
    fit_machine, fit_setup, fit_meas = nominal, setup, meas
    if baseline is not None:
        parts = _names((keep,)) if keep is not None else None
        if parts is not None and not all(k.isdigit() for k in parts):
            raise PkmcalError(f"--keep '{keep}': give actuator numbers separated by commas, e.g. 1,2")
        keep_idx = None if parts is None else [int(k) - 1 for k in parts]
        fit_machine, fit_setup, fit_meas = baseline_inputs(baseline, nominal, setup, meas, keep_idx)
        method = "projection"
    fix_names = _names(fix)
    if fix_names == ["auto"]:
        fix_names = "auto"
    free_opt = _names(free)
    from pkmcal.identification.priors import parse_prior

    priors = tuple(parse_prior(p) for p in prior)

    def fit(with_priors=True):
        return identify(fit_machine, fit_setup, fit_meas, method=method, free=merged_free(free_opt, fit_setup),
                        fix=fix_names, weighted=not unweighted, form=form, loss=loss, f_scale=f_scale,
                        reject=reject, priors=priors if with_priors else (),
                        session_offsets=True if session_offsets else None)

    with clipped_named_in_errors(clipped_lines):
        result = fit()
        if baseline is not None:
            result = baseline_result(result, nominal, baseline)
        if nominal is not single_machine(nominal):    # pose pairs: the machine file holds the machine
            result = dataclasses.replace(result, mechanism=single_machine(result.mechanism))
        u = result.uncertainty
        if u.dof <= 0:
            raise PkmcalError(
                f"{len(result.used_poses)} poses give {u.dof + len(result.free)} residuals for {len(result.free)} free "
                f"parameters{' (after fixing the gauge)' if result.gauge else ''}: no degree of freedom is left to "
                "check the fit (chi2/dof undefined); measure more poses or fix parameters; nothing written")
        causes = input_causes(nominal, setup, meas)
        verdict = judge(result, causes)
        if not verdict.acceptable:
            verdict = verdict.with_diagnoses(diagnose(
                result, setup, meas, causes, n_read=len(read.actuators),
                refit_without_priors=(lambda: fit(with_priors=False)) if baseline is None and priors else None))
            if not accept_bad_fit:
                raise PkmcalError(f"the fit is refused: {verdict.text()}; nothing written to {output}: mend the cause "
                                  "and run again, or write it anyway with --accept-bad-fit (recorded in the file)")
    undetermined = _undetermined(nominal, setup, meas, result, priors) if baseline is None else []
    hints = [f"warning: {w}" for w in clipped_lines] + [f"warning: {c}" for c in causes] + \
        [e["text"] if e["note"] else f"warning: {e['text']}" for e in undetermined] + \
        [f"warning: {line}: 'pkmcal export --format klipper|marlin' will refuse it unless accepted by name "
         f"(--accept-undetermined {n})" for n, line in _firmware_numbers_undetermined(result)]
    if not verdict.acceptable:
        hints.append(f"warning: written with --accept-bad-fit although the fit is refused: {verdict.text()}")
    if hints:
        result = dataclasses.replace(result, warnings=tuple(result.warnings) + tuple(hints))
    free_line = free_statement(result, free_opt, fit_setup)
    geometry = None
    if result.mechanism.point_sets or "leg-lengths" in result.mechanism.abilities:
        from pkmcal.identification.geometry import readable_geometry

        geometry = readable_geometry(nominal, result.mechanism, "the covariance written to the machine file")
    before = before_registration(nominal, setup, meas, result) if baseline is None else None
    cal_setup = identified_setup_of(setup, result) if baseline is None else None
    text = machine_to_text(with_calibration_record(result, machine, measurements, setup_spec, name,
                                                   setup=cal_setup, before=before,
                                                   accepted=None if verdict.acceptable else verdict,
                                                   undetermined=undetermined))
    check_loads_back(text, "(standard output)" if to_stdout(output) else output)
    validation = None
    if heldout is not None:
        if cal_setup is None:
            raise PkmcalError(f"--held-out: the {baseline} baseline identifies a reduced model; validate the full "
                              "calibration (leave out --method) on held-out data")
        validation = identify_heldout_validation(read_by(result.mechanism, setup.sensor), cal_setup, nominal,
                                                 before, heldout, mapping, clipped)
    report = None if report_dir is None else _report_data(nominal, result, setup, meas, measurements,
                                                           "(standard output)" if to_stdout(output) else output,
                                                           validation)
    if as_json:  # everything printed is made before anything is written
        from pkmcal.io.json_out import finite_or_null

        d = finite_or_null(result.to_dict())
        d["free_rule"] = free_line
        d["verdict"] = verdict.to_dict()
        units = dict(zip(nominal.actuator_names, nominal.actuator_units))
        d["clipped"] = [c.to_dict(units[c.actuator]) for c in clipped_found]
        d["output"] = output
        if geometry is not None:
            d["geometry"] = finite_or_null(geometry.to_dict())
        if cal_setup is not None and cal_setup.sensor.param_names:
            d["setup"] = setup_json(result, cal_setup)
        if before is not None:
            d["before_registration"] = {"values": before[0], "note": before[1],
                                        "units": {"values": "file units: mm, deg for angle parameters"}}
        if validation is not None:
            d["heldout"] = validation.to_dict()
    emit(text, output)
    recorded = None if history_db is None else record_identified(output, history_db, serial, validation)
    if report is not None:
        from pkmcal.report import write_report

        written = write_report(report, report_dir)
    if as_json:
        if report is not None:
            d["report"] = str(written.html)
        if recorded is not None:
            d["history"] = {"db": str(history_db), "id": recorded.id, "serial": recorded.serial}
        click.echo(json.dumps(d, indent=2, allow_nan=False))
    else:
        err = to_stdout(output)
        click.echo(result_table(result), err=err)
        click.echo(fit_summary(result, free_line), err=err)
        if geometry is not None:
            click.echo(geometry.format(), err=err)
        if before is not None:
            click.echo(f"before registration (nominal machine, for 'pkmcal verify'): {before[1]}", err=err)
        if validation is not None:
            click.echo(validation.format_table(), err=err)
        if not err:
            click.echo(f"wrote {output}" + (f" and {written.html}" if report is not None else ""))
        if recorded is not None:
            click.echo(f"recorded #{recorded.id} for serial {recorded.serial} in {history_db}")
        elif report is not None:
            click.echo(f"wrote {written.html}", err=True)


def _check_report_dir(report_dir: str, inputs) -> None:
    """The report folder must be a folder that can be created or written into, and must not
    hold an input file under a report file's name."""
    import os

    from pkmcal.io.atomic import check_output_dir
    from pkmcal.report import REPORT_NAME

    check_output_dir(report_dir, "--report")
    if os.path.isdir(report_dir):
        check_output_path(os.path.join(report_dir, REPORT_NAME), inputs)


def _report_data(nominal, result, setup, meas, meas_path: str, output: str, validation=None):
    """The report of ``pkmcal identify``: the measured poses are the commanded ones of the
    file (cmd_x..), else the nominal machine's FK of the actuator readings."""
    from pkmcal.io.setup_file import setup_to_yaml
    from pkmcal.report.from_results import report_data_from_results

    if meas.commanded is not None:
        poses = meas.commanded
    else:
        with np.errstate(all="ignore"):
            fk = nominal.fk(meas.actuators)
        poses = np.asarray(fk.poses)[fk.ok]
    try:
        setup_text = setup_to_yaml(setup)
    except PkmcalError:
        setup_text = setup.sensor.kind
    return report_data_from_results(
        nominal, result, setup, poses, setup_summary=setup_text, commanded=meas.commanded,
        facts=(("measurement file", str(meas_path)), ("calibrated machine file", str(output))),
        heldout=validation, calibrated_file=None if output.startswith("(") else str(output))


@click.command("identifiability", epilog=examples(
    "pkmcal identifiability stewart-prototype --setup indicators-prototype --poses poses.csv",
    "pkmcal identifiability stewart-prototype --setup full-pose-paper1 --poses poses.csv --json",
    "pkmcal identifiability stewart-prototype --setup indicators-prototype --poses poses.csv --suggest",
    "pkmcal identifiability stewart-prototype --setup full-pose-paper1 --poses poses.csv --accuracy"))
@click.argument("machine")
@click.argument("poses_arg", required=False, cls=DeprecatedArgument)
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml",
              help=f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)}).")
@click.option("--poses", metavar="POSES.csv", help="Poses: columns x,y,z (mm), a,b,c (deg).")
@click.option("--method", type=click.Choice(METHODS), default=None,
              help=f"Method whose Jacobian is analysed (default: {DEFAULT_METHOD_RULE}).")
@click.option("--fix", "fix", multiple=True, metavar="NAMES", help="Parameters held (removed from the analysis).")
@click.option("--free", "free", multiple=True, metavar="NAMES", help="Candidate parameters (default: all + sensor's free).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@click.option("--suggest", is_flag=True, help="Also rank what to measure next: the other built-in setups, printed "
              "distances (deltas) and more planned poses, by the rank and smallest singular value each gives "
              "(JSON key 'suggestions').")
@click.option("--accuracy", is_flag=True, help="Also predict the accuracy a calibration on these poses gives, before "
              "anything is measured: the 95 % bound of the position (and orientation) error over the workspace and at "
              "the ISO 9283 cube's P1..P5, from the setup's noise (JSON key 'predicted_accuracy').")
@click.option("--accuracy-map", "accuracy_map_path", metavar="FILE.png",
              help="With --accuracy: also draw the predicted bound over the workspace (PNG or SVG).")
@import_options
@quiet_accepted
def identifiability_cmd(machine, poses_arg, setup_spec, poses, method, fix, free, as_json, mapping=None,
                        suggest=False, accuracy=False, accuracy_map_path=None) -> None:
    """Which parameters of MACHINE the SETUP can identify from POSES.csv.

    Prints the rank of the column-scaled, noise-weighted identification Jacobian, its
    singular values, the unobservable combinations (named), weakly identifiable
    directions, and a minimal set of parameters to fix (the gauge). JSON keys: n_params,
    rank, singular_values, null_space, fixed, weak, ...
    """
    from pkmcal.cli.klipper_probe_cmd import machine_and_setup
    from pkmcal.identification.identifiability import identifiability

    poses = poses_file(poses, poses_arg, "identifiability")
    nominal, setup = machine_and_setup(machine, setup_spec)   # pose pairs for printed distances
    x = read_poses(poses, nominal, mapping)
    fix_names = _names(fix)
    rep = identifiability(nominal, setup, x, method=method, free=merged_free(_names(free), setup),
                          fix=None if fix_names == ["auto"] else fix_names)
    notes = unreachable_notes(nominal, x, poses)
    if rep.n_unsolved:
        notes.append(f"{rep.n_unsolved} of the {len(x)} poses were left out: their readings or pose cannot be "
                     "computed on this machine (outside the reach of a chain, or the pose does not solve)")
    advice = None
    if suggest:   # identification/advice.py: the candidate additions ranked
        from pkmcal.identification.advice import advise

        advice = advise(nominal, setup, x, method=method, free=merged_free(_names(free), setup),
                        fix=None if fix_names == ["auto"] else fix_names)
    predicted = None
    if accuracy_map_path is not None:
        if not accuracy:
            raise PkmcalError("--accuracy-map draws the predicted accuracy: give --accuracy too")
        if not str(accuracy_map_path).lower().endswith((".png", ".svg")):
            raise PkmcalError(f"--accuracy-map {accuracy_map_path}: use a .png or .svg file name")
        check_output(accuracy_map_path, [machine, setup_spec, poses])
    if accuracy:   # identification/iso9283.py: the covariance of these poses carried over the workspace
        from pkmcal.identification.iso9283 import accuracy_map

        predicted = accuracy_map(nominal, setup, x, method=method, report=rep)
        if accuracy_map_path is not None:
            from pkmcal.io.atomic import atomic_write_bytes
            from pkmcal.report.figures import accuracy_map_figure, render

            drawn = render(accuracy_map_figure(predicted), "accuracy-map", "")
            atomic_write_bytes(accuracy_map_path, drawn.svg if str(accuracy_map_path).lower().endswith(".svg")
                               else drawn.png)
    if as_json:
        d = rep.to_dict()
        d["warnings"] = notes
        if advice is not None:
            d["suggestions"] = advice.to_dict()
        if predicted is not None:
            d["predicted_accuracy"] = predicted.to_dict()
        click.echo(json.dumps(d, indent=2, allow_nan=False))
        return
    click.echo(f"{nominal.name} with {setup.sensor.kind} sensor, {len(x)} poses: rank {rep.rank} of "
               f"{rep.n_params} (relative tolerance {rep.rtol:g}, unit-norm columns), "
               f"condition number {rep.condition_number:.3g}")
    click.echo(f"Jacobian of {rep.basis}")
    s = rep.singular_values
    click.echo("singular values / largest: " + " ".join(f"{v / s[0]:.2e}" for v in s))
    if rep.null_space:
        click.echo(f"{len(rep.null_space)} unobservable combination(s) (no reading changes along them):")
        for d in rep.null_space:
            click.echo(f"  {format_direction(d)}")
        click.echo(f"suggested gauge (fix these): {', '.join(rep.fixed)}")
    for w in rep.weak:
        click.echo(f"weak (ratio {w['ratio']:.2g}): {format_direction(w['direction'])}")
    for entry in rep.named:   # the machine's named directions in its words (identifiability.describe_named)
        click.echo(describe_named(entry))
    if rep.unseen:
        click.echo(f"not seen at all: {', '.join(rep.unseen)}")
    for n in notes:
        click.echo(f"warning: {n}")
    for line in advice.lines() if advice is not None else ():
        click.echo(line)
    for line in predicted.lines() if predicted is not None else ():
        click.echo(line)

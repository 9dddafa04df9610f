"""``pkmcal identify`` and ``pkmcal identifiability``: the identification engine on files.

* ``identify``: measurement CSV + setup → calibrated machine file (identified parameters
  and their covariance), a table parameter / nominal / identified / ±σ and a fit summary
  (:func:`pkmcal.identification.engine.identify`; paper 1 §V, paper 2 §3, paper 3 §2).
* ``identifiability``: rank, unobservable combinations and the suggested gauge for a
  machine, setup and pose set (:mod:`pkmcal.identification.identifiability`).

Everything is read, validated and computed before the output file is written (atomically);
on a user error nothing is written and the exit code is 2. ``identify`` checks its options,
calls :func:`pkmcal.workflow.calibrate` (the fit, its verdict, the calibrated file, the
held-out validation and the report are the :class:`~pkmcal.workflow.Calibration`'s) and prints.
"""

from __future__ import annotations

import json

import click

from pkmcal.errors import PkmcalError
from pkmcal.cli.import_options import import_options
from pkmcal.cli.main import command_line
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.cli.options import (STDOUT, DeprecatedArgument, check_output, emit, examples, option, output_option,
                                poses_file, quiet_accepted, to_stdout)
from pkmcal.workflow.analysis import identifiability_of
from pkmcal.workflow.calibration import calibrate, check_report_dir, write_report
from pkmcal.workflow.text import describe_named, fit_summary, format_direction, result_table
from pkmcal.workflow.vocabulary import (
    BASELINES,
    BUILTIN_SETUPS,
    CLIPPED_POLICIES,
    DEFAULT_F_SCALE,
    DEFAULT_METHOD_RULE,
    LOSSES,
    METHODS,
    OUTLIER_SIGMA,
)


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
    from pkmcal.workflow.history import check_history_request, record_identified

    check_history_request(history_db, serial, to_stdout(output))
    if f_scale is not None and loss == "linear":
        raise PkmcalError("--f-scale sets where a robust --loss turns from quadratic, and the loss is linear (least "
                          f"squares): give --loss ({', '.join(lo for lo in LOSSES if lo != 'linear')}) with it, or "
                          "leave out --f-scale")
    if to_stdout(output) and as_json:
        raise PkmcalError("-o - puts the machine file on standard output; --json would go there too: "
                          "write the machine file to a file, or leave out --json")
    if report_dir is not None:
        check_report_dir(report_dir, inputs)
    where = "(standard output)" if to_stdout(output) else output
    cal = calibrate(machine, setup_spec, measurements, method=method, keep=keep, free=free, fix=fix,
                    merge_setup_free=True, priors=prior, clipped=clipped, mapping=mapping,
                    bad_fit="accept" if accept_bad_fit else "refuse", name=name, command=command_line(), where=where,
                    weighted=not unweighted, form=form, loss=loss, f_scale=f_scale, reject=reject,
                    session_offsets=True if session_offsets else None)
    result, geometry, before = cal.result, cal.geometry, cal.before
    text = cal.text(where)
    validation = None
    if heldout is not None:
        if cal.setup is None:
            raise PkmcalError(f"--held-out: the {cal.baseline} baseline identifies a reduced model; validate the full "
                              "calibration (leave out --method) on held-out data")
        validation = cal.verify(heldout)
    report = None if report_dir is None else cal.report_data(validation, output=where)
    if as_json:  # everything printed is made before anything is written
        d = {}
        for key, value in cal.to_dict().items():     # the keys in the order identify --json has always had
            d[key] = value
            if key == "clipped":
                d["output"] = output
        if validation is not None:
            d["heldout"] = validation.to_dict()
    emit(text, output)
    recorded = None if history_db is None else record_identified(output, history_db, serial, validation)
    if report is not None:
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
        click.echo(fit_summary(result, cal.free_rule), err=err)
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
    poses = poses_file(poses, poses_arg, "identifiability")
    predicted_map = accuracy_map_path is not None
    if predicted_map:
        if not accuracy:
            raise PkmcalError("--accuracy-map draws the predicted accuracy: give --accuracy too")
        if not str(accuracy_map_path).lower().endswith((".png", ".svg")):
            raise PkmcalError(f"--accuracy-map {accuracy_map_path}: use a .png or .svg file name")
        check_output(accuracy_map_path, [machine, setup_spec, poses])
    found = identifiability_of(machine, setup_spec, poses, method=method, free=free, fix=fix, suggest=suggest,
                               accuracy=accuracy, mapping=mapping)
    nominal, setup, x, rep, notes, advice = found.nominal, found.setup, found.poses, found.report, found.notes, \
        found.advice
    predicted = found.predicted
    if predicted_map:
        found.write_accuracy_map(accuracy_map_path)
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

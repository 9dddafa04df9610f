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
from pkmcal.identification.identifiability import describe_named, format_direction
from pkmcal.identification.redundant_campaign import (
    BASELINES,
    baseline_inputs,
    baseline_result,
    sensor_calibration_block,
)
from pkmcal.identification.residuals import METHODS, default_method
from pkmcal.identification.robust import DEFAULT_F_SCALE, LOSSES, OUTLIER_SIGMA
from pkmcal.cli._limits import unreachable_notes
from pkmcal.cli.import_options import import_options
from pkmcal.cli.option_types import FiniteFloat
from pkmcal.cli.options import DeprecatedArgument, check_output, emit, examples, output_option, poses_file, to_stdout
from pkmcal.io.atomic import check_output_path
from pkmcal.io.measurements import CLIPPED_POLICIES, apply_clipped_policy, clipped_named_in_errors, load_measurements
from pkmcal.io.tables import read_poses
from pkmcal.sensors.library import BUILTIN_SETUPS


def _names(values: tuple[str, ...]) -> list[str] | None:
    out = [n for v in values for n in v.replace(",", " ").split() if n]
    return out or None


def _fmt(v: float, angle: bool) -> str:
    return f"{np.rad2deg(v):.6f}°" if angle else f"{v:.6f}"


def _angle_names(result) -> set[str]:
    """Names of the angle parameters (shown in degrees), from the sensor's ``param_is_angle``
    and the machine's (a machine without the flags, the hexapod, has only lengths), and the
    result's own flags where it has them (the sessions' offsets of rotary actuators)."""
    sensor, mech = result.sensor, result.mechanism
    angles = {n for n, a in zip(sensor.param_names, sensor.param_is_angle) if a}
    angles.update(n for n, a in zip(mech.param_names, mech.param_is_angle) if a)
    angles.update(n for n, a in zip(getattr(result, "names", ()), getattr(result, "param_is_angle", ())) if a)
    return angles


def result_table(result) -> str:
    """Parameter, nominal, identified, ±σ (mm; degrees for angles), one line per parameter."""
    angles = _angle_names(result)
    free = set(result.free)
    std = dict(zip(result.free, result.std))
    rows = [("parameter", "nominal", "identified", "±std", "")]
    for i, n in enumerate(result.names):
        if n not in free and n not in result.gauge and i >= len(result.mechanism.param_names):
            continue  # sensor parameters held at their values: not part of the fit
        a = n in angles
        note = "gauge (fixed)" if n in result.gauge else ("fixed" if n not in free else "")
        rows.append((n, _fmt(result.initial[i], a), _fmt(result.estimate[i], a),
                     _fmt(std[n], a) if n in std else "-", note))
    w = [max(len(r[k]) for r in rows) for k in range(5)]
    return "\n".join(f"{r[0]:<{w[0]}}  {r[1]:>{w[1]}}  {r[2]:>{w[2]}}  {r[3]:>{w[3]}}  {r[4]}".rstrip() for r in rows)


def merged_free(free: list[str] | None, setup) -> list[str] | None:
    """The free list the fit gets from ``--free`` and the setup (the rule of ``identify
    --help``): None without ``--free`` (the engine's default: every machine parameter and the
    setup's free sensor parameters); else the ``--free`` names and patterns followed by the
    setup's ``free:`` sensor parameters (merged, not replaced; ``--fix`` holds any of them)."""
    if free is None:
        return None
    return list(free) + [n for n in setup.sensor.default_free if n not in free]


def free_statement(result, free_opt: list[str] | None, setup) -> str:
    """Which parameters were estimated and where each list came from (one line)."""
    p = len(result.mechanism.param_names)
    names = result.names
    mech_free = [n for n in result.free if names.index(n) < p]
    sensor_free = [n for n in result.free if names.index(n) >= p]
    setup_free = set(setup.sensor.default_free)
    several = result.sessions is not None and result.sessions.several
    if several:   # NAME@LABEL of the setup's free: names, and the sessions' actuator offsets
        setup_free = set(result.sensor.default_free)
        offsets = {n for n in names[p + len(result.sensor.param_names):]}
    from pkmcal.identification.residuals import default_fixed_parameters

    held_by_machine = [n for n in default_fixed_parameters(result.mechanism) if n not in result.free]
    if free_opt is not None:
        src = "--free"
    elif held_by_machine:
        src = f"all but {', '.join(held_by_machine)}, which the machine holds unless freed by name; no --free given"
    else:
        src = "all, no --free given"
    text = f"free parameters: {len(mech_free)} of {p} machine parameters ({src})"
    if sensor_free:
        parts = [f"{n} ({'setup free:' if n in setup_free else 'session offsets' if several and n in offsets else '--free'})"
                 for n in sensor_free]
        text += "; sensor: " + ", ".join(parts)
    else:
        text += "; no sensor parameter"
    held = [n for n in (result.sensor.default_free if several else setup.sensor.default_free)
            if n not in result.free]
    if held:
        text += f"; setup-free sensor parameters held: {', '.join(held)} (--fix or gauge)"
    return text + ". Rule: --free adds to the setup's free: list, it does not replace it"


def _residual_line(result) -> str:
    groups: dict[str, list[str]] = {}
    for name, unit in zip(result.residual_names, result.residual_units or ("1",) * len(result.residual_names)):
        groups.setdefault({"rad": "deg"}.get(unit, unit), []).append(name)
    rms = result.rms_by_unit()
    parts = [f"rms {rms[u]:.6g}{'' if u == '1' else ' ' + u} over {', '.join(ns)}" + (" (whitened or mixed units)"
                                                                                   if u == "1" else "")
             for u, ns in groups.items()]
    return "residuals at the solution (measured - predicted, raw): " + "; ".join(parts)


def fit_summary(result, free_line: str | None = None) -> str:
    u = result.uncertainty
    rep = result.identifiability
    dropped = (f", {len(result.dropped)} dropped (rows {', '.join(str(int(k) + 1) for k in result.dropped[:20])}"
               f"{' ...' if len(result.dropped) > 20 else ''} of the file, 1-based)") if len(result.dropped) else ""
    whitened = ("whitened (noise model): chi2 = sum |W r|^2 = "
                f"{u.chi2:.6g} with the weights at the solution, chi2/dof = {u.chi2:.6g}/{u.dof} = "
                f"{u.reduced_chi2:.4g}, rms whitened residual sqrt(chi2/M) = {result.rms_whitened:.4g}")
    extra = "".join([f", {result.loss} loss" if result.loss != "linear" else "",
                     " + 1/2 sum of the squared prior rows" if len(result.priors) else ""])
    cost = (f"solver cost 1/2 sum |W0 r|^2 = {result.cost:.6g} (weights from the start, held fixed while solving"
            f"{extra})"
            if result.weighted else
            f"solver cost 1/2 sum r^2 = {result.cost:.6g} (plain least squares on the raw residuals)")
    lines = [
        f"method {result.method} ({'noise-weighted' if result.weighted else 'unweighted'}), "
        f"{len(result.used_poses)} poses used{dropped}, {len(result.free)} free parameters",
        *([free_line] if free_line else []),
        f"solver: {'converged' if result.success else 'NOT converged'} after {result.nfev} evaluations: {result.message}",
        _residual_line(result),
        whitened if (result.weighted or np.isfinite(u.chi2)) else "no noise model to whiten with: chi2 undefined",
        cost,
        f"identifiability ({rep.basis or 'at the start'}): rank {rep.rank} of {rep.n_params}, "
        f"condition number {rep.condition_number:.3g}",
        f"std: {u.description} — this covariance is written to the machine file",
    ]
    for d in rep.null_space:
        lines.append(f"  unobservable: {format_direction(d)}")
    lines.extend(robust_lines(result))
    lines.extend(session_lines(result))
    for w in result.warnings:
        lines.append(w if w.startswith("warning: ") else f"note: {w}")
    return "\n".join(lines)


def session_lines(result) -> list[str]:
    """The fit summary's lines on the sessions: poses per session and each session's
    identified sensor (setup-file keys, mm and degrees; ``dq`` the re-homing offsets)."""
    values = result.session_values()
    if not values:
        return []
    ses = result.sessions
    counts = dict(zip(ses.labels, ses.counts()))
    out = [f"sessions: {len(values)} ({', '.join(f'{lab}: {int(counts[lab])} poses' for lab in ses.labels)}), "
           "each with its own sensor parameters NAME@LABEL"
           + ("; actuator zero offsets dq_i@LABEL after the first" if ses.offsets else "")]
    for lab, groups in values.items():
        parts = []
        for key, v in groups.items():
            text = (", ".join(f"{k} {x:.6g}" for k, x in v.items()) if isinstance(v, dict)
                    else ", ".join(f"{x:.6g}" for x in v))
            parts.append(f"{key}: {text}")
        out.append(f"  session {lab} (mm, deg): " + "; ".join(parts))
    return out


def robust_lines(result) -> list[str]:
    """The fit summary's lines on the normalised residuals, the loss and the priors."""
    out = []
    sc = result.screening
    if sc is not None and sc.sigma.size:
        j = int(np.argmax(sc.sigma))
        out.append(f"normalised residuals sqrt(|W r|^2/k) per pose (noise sigmas): median {np.median(sc.sigma):.3g}, "
                   f"max {sc.sigma[j]:.3g} (pose {int(sc.pose_numbers[j])}); {len(sc.flagged)} beyond "
                   f"{sc.threshold:g} sigma" + (f"; rejection at {sc.reject:g} sigma: {len(sc.rejected)} pose(s) "
                                                f"dropped in {sc.rounds} fit(s)" if sc.reject is not None else ""))
    if result.loss != "linear":
        out.append(f"loss: {result.loss} on the whitened rows, f_scale {sc.f_scale:g} sigma (scipy least_squares); "
                   "chi2 and the covariance over the poses within the threshold")
    pr = result.priors
    if len(pr):
        std = dict(zip(result.free, result.std))
        out.append(f"priors (maximum a posteriori; the covariance is the posterior one), {len(pr)} parameter(s):")
        for e in pr.to_dict(result.estimate, std):
            post = "-" if e["posterior_std"] is None else f"{e['posterior_std']:.4g}"
            out.append(f"  {e['parameter']}: prior {e['mean']:.6g} ± {e['std']:.4g} {e['unit']} -> {e['estimate']:.6g} "
                       f"± {post} (pull {e['pull']:+.2f}; {e['source']})")
    return out


def radian_hints(nominal, setup, meas) -> list[str]:
    """Warnings when the sensor's angle columns and the poses the fit starts from differ in
    spread by about 180/π (57.3): one of them was written in radians where degrees were
    read. The reference poses are the commanded ones (cmd_a..), else the FK of the actuator
    readings at the nominal machine; per angle column the ratio of standard deviations over
    the poses (offsets of world/tool transforms cancel) is compared with [30, 110]."""
    sensor = setup.sensor
    angle_cols = [k for k, a in enumerate(sensor.reading_is_angle) if a]
    if not angle_cols or tuple(sensor.reading_names) != tuple(nominal.pose_names):
        return []
    if meas.commanded is not None:
        ref, what = np.asarray(meas.commanded, dtype=float), "the commanded poses (cmd_ columns)"
    else:
        with np.errstate(all="ignore"):
            fk = nominal.fk(meas.actuators)
        ref, what = np.asarray(fk.poses)[fk.ok], "the poses of the actuator readings (FK at the nominal machine)"
        if len(ref) < 3:
            return []
    y = np.asarray(meas.readings, dtype=float)[: len(ref)] if meas.commanded is not None else \
        np.asarray(meas.readings, dtype=float)[fk.ok]
    out = []
    for k in angle_cols:
        s_ref, s_y = float(np.std(ref[:, k])), float(np.std(y[:, k]))
        if not (s_ref > np.deg2rad(0.5) or s_y > np.deg2rad(0.5)) or s_ref == 0 or s_y == 0:
            continue
        r = s_ref / s_y
        name = sensor.reading_names[k]
        if 30.0 < r < 110.0:
            out.append(f"warning: column '{name}' varies {r:.3g} times less than the angles of {what}: it looks like "
                       "radians where degrees are read; convert it to degrees (or, when every angle column of the "
                       "file is in radians, give --angle-unit rad)")
        elif 1 / 110.0 < r < 1 / 30.0 and meas.commanded is not None:
            out.append(f"warning: column 'cmd_{name}' varies {1 / r:.3g} times less than the measured '{name}': it "
                       "looks like radians where degrees are read; convert it to degrees")
    return out


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
                   "Default: ik-residual for a full-pose sensor, projection for redundantly actuated machines, "
                   "else fk-residual. Baselines for redundant machines (paper 3 §1): ignore-redundancy "
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
@output_option("CALIBRATED.yaml", "Calibrated machine file to write", stdout=False)
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
              help="Where the robust loss turns from quadratic, in noise sigmas of the whitened rows. Default: 95 %% "
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
@click.option("--heldout", "heldout", metavar="HELDOUT.csv",
              help="Held-out measurements (same columns as MEAS.csv, not used in the fit): print the validation of "
                   "'pkmcal verify CALIBRATED.yaml --measurements HELDOUT.csv' (before / after / "
                   "after_reregistered) and show it in the --report.")
@import_options
def identify_cmd(machine, measurements, setup_spec, method, unweighted, form, fix, free, output, name, as_json,
                 report_dir=None, mapping=None, keep=None, loss="linear", f_scale=None, reject=None,
                 prior=(), clipped="drop", session_offsets=False, heldout=None) -> None:
    """Identify MACHINE's kinematic parameters from MEAS.csv and write CALIBRATED.yaml.

    Units: mm, degrees in files and tables. Unidentifiable combinations are fixed
    automatically (the gauge, shown in the table) unless --free/--fix say otherwise, in
    which case an unidentifiable request is an error naming the combination.
    CALIBRATED.yaml carries a calibration record: the machine's new name, the UTC date
    (SOURCE_DATE_EPOCH fixes it), the pkmcal version, the command line and the SHA-256 of
    every input file. With -o - the machine file goes to standard output and the table to
    standard error.

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
    held at nominal (the fair "before" of 'pkmcal verify'). --heldout validates the result
    on measurements the fit did not see.
    """
    inputs = [machine, measurements, setup_spec] + ([heldout] if heldout is not None else [])
    check_output(output, inputs)
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
    meas, clipped_found, clipped_lines = apply_clipped_policy(load_measurements(measurements, nominal, setup, mapping),
                                                              nominal, clipped)
    if method is None:
        method = default_method(setup, nominal)
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
    with clipped_named_in_errors(clipped_lines):
        result = identify(fit_machine, fit_setup, fit_meas, method=method, free=merged_free(free_opt, fit_setup),
                          fix=fix_names, weighted=not unweighted, form=form, loss=loss, f_scale=f_scale,
                          reject=reject, priors=priors, session_offsets=True if session_offsets else None)
        if baseline is not None:
            result = baseline_result(result, nominal, baseline)
        if nominal is not single_machine(nominal):    # pose pairs: the machine file holds the machine
            result = dataclasses.replace(result, mechanism=single_machine(result.mechanism))
        if not result.success:
            raise PkmcalError(f"the fit did not converge ({result.message}); nothing written")
        u = result.uncertainty
        if u.dof <= 0:
            raise PkmcalError(
                f"{len(result.used_poses)} poses give {u.dof + len(result.free)} residuals for {len(result.free)} free "
                f"parameters{' (after fixing the gauge)' if result.gauge else ''}: no degree of freedom is left to "
                "check the fit (chi2/dof undefined); measure more poses or fix parameters; nothing written")
    hints = [f"warning: {w}" for w in clipped_lines] + radian_hints(nominal, setup, meas)
    if hints:
        result = dataclasses.replace(result, warnings=tuple(result.warnings) + tuple(hints))
    free_line = free_statement(result, free_opt, fit_setup)
    geometry = None
    if result.mechanism.point_sets or "leg-lengths" in result.mechanism.abilities:
        from pkmcal.identification.geometry import readable_geometry

        geometry = readable_geometry(nominal, result.mechanism, "the covariance written to the machine file")
    before = _before_registration(nominal, setup, meas, result) if baseline is None else None
    cal_setup = identified_setup_of(setup, result) if baseline is None else None
    text = machine_to_text(_with_calibration_record(result, machine, measurements, setup_spec, name,
                                                    setup=cal_setup, before=before))
    _check_loads_back(text, "(standard output)" if to_stdout(output) else output)
    validation = None
    if heldout is not None:
        if cal_setup is None:
            raise PkmcalError(f"--heldout: the {baseline} baseline identifies a reduced model; validate the full "
                              "calibration (leave out --method) on held-out data")
        validation = _heldout_validation(read_by(result.mechanism, setup.sensor), cal_setup, nominal, before, heldout,
                                         mapping, clipped)
    report = None if report_dir is None else _report_data(nominal, result, setup, meas, measurements,
                                                           "(standard output)" if to_stdout(output) else output,
                                                           validation)
    if as_json:  # everything printed is made before anything is written
        from pkmcal.io.json_out import finite_or_null

        d = finite_or_null(result.to_dict())
        d["free_rule"] = free_line
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
    if report is not None:
        from pkmcal.report import write_report

        written = write_report(report, report_dir)
    if as_json:
        if report is not None:
            d["report"] = str(written.html)
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
        elif report is not None:
            click.echo(f"wrote {written.html}", err=True)


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


def _before_registration(nominal, setup, meas, result) -> tuple[dict, str, dict] | None:
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


def _heldout_validation(calibrated, cal_setup, nominal, before, path: str, mapping, clipped: str):
    """The held-out validation of ``identify --heldout`` (:mod:`pkmcal.identification.heldout`)."""
    from pkmcal.identification.heldout import heldout_validation, sensor_from_values

    held, found, lines = apply_clipped_policy(load_measurements(path, calibrated, cal_setup, mapping), calibrated,
                                              clipped)
    if before is not None:
        before_sensor, note = sensor_from_values(cal_setup.sensor, before[0], "before_registration"), before[1]
        before_sessions = tuple((lab, sensor_from_values(cal_setup.sensor, v, "before_registration"))
                                for lab, v in before[2].items())
    else:   # no free sensor parameter: nothing to register, the sensor as the setup gives it
        before_sensor, note = cal_setup.sensor, "no free sensor parameter: the sensor as the setup gives it"
        before_sessions = ()
    unit = {n: ("deg" if a else "mm") for n, a in zip(calibrated.actuator_names, calibrated.actuator_is_angle)}
    return heldout_validation(calibrated, cal_setup, nominal, before_sensor, held, source=str(path),
                              before_note=note, before_sessions=before_sessions, notes=[f"warning: {w}" for w in lines],
                              clipped=tuple(c.to_dict(unit[c.actuator]) for c in found))


def _with_calibration_record(result, machine: str, measurements: str, setup_spec: str, name: str | None,
                             setup=None, before=None):
    """The identified machine under its own name with a ``calibration`` record in its
    metadata (kept in the machine file; ``pkmcal export --format json`` shows it): name,
    calibrated-from, UTC date, pkmcal version, command line, the inputs with their SHA-256
    (:mod:`pkmcal.cli.provenance`), and the fit; ``before`` (values, note) is stored as
    ``calibration.before_registration``. With ``setup`` (the setup with the identified
    sensor) the identified setup goes under ``setup:`` (:func:`setup_block`).
    ``SOURCE_DATE_EPOCH`` fixes the date, so that the same inputs give the same bytes."""
    import dataclasses

    from pkmcal import __version__
    from pkmcal.cli.provenance import command_line, input_record, utc_timestamp

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
        "command": command_line(),
        "inputs": {"machine": input_record(machine), "setup": input_record(setup_spec),
                   "measurements": input_record(measurements)},
        "method": result.method, "weighted": bool(result.weighted), "measurements": str(measurements),
        "setup": str(setup_spec), "n_poses": int(len(result.used_poses)), "n_free": int(len(result.free)),
        "gauge": list(result.gauge), "rms_residual": float(result.rms_residual),
        # undefined (null) without degrees of freedom
        "reduced_chi2": float(u.reduced_chi2) if np.isfinite(u.reduced_chi2) else None, "std": u.description,
    }
    if result.loss != "linear":
        record["loss"] = result.loss
    sc = result.screening
    if sc is not None and sc.rejected:
        record["rejected_poses"] = [o.pose for o in sc.rejected]
    if len(result.priors):
        record["priors"] = {e["parameter"]: f"{e['mean']!r} ± {e['std']!r} {e['unit']}"
                            for e in result.priors.to_dict(result.estimate, {})}
    if getattr(result.sensor, "kind", "") == "planar-tool":  # read back by 'pkmcal verify'
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


def _check_loads_back(text: str, output: str) -> None:
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
        heldout=validation)


@click.command("identifiability", epilog=examples(
    "pkmcal identifiability stewart-prototype --setup indicators-prototype --poses poses.csv",
    "pkmcal identifiability stewart-prototype --setup full-pose-paper1 --poses poses.csv --json",
    "pkmcal identifiability stewart-prototype --setup indicators-prototype --poses poses.csv --suggest"))
@click.argument("machine")
@click.argument("poses_arg", required=False, cls=DeprecatedArgument)
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml",
              help=f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)}).")
@click.option("--poses", metavar="POSES.csv", help="Poses: columns x,y,z (mm), a,b,c (deg).")
@click.option("--method", type=click.Choice(METHODS), default=None,
              help="Method whose Jacobian is analysed (default: fk-residual; projection for redundant machines).")
@click.option("--fix", "fix", multiple=True, metavar="NAMES", help="Parameters held (removed from the analysis).")
@click.option("--free", "free", multiple=True, metavar="NAMES", help="Candidate parameters (default: all + sensor's free).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@click.option("--suggest", is_flag=True, help="Also rank what to measure next: the other built-in setups, printed "
              "distances (deltas) and more planned poses, by the rank and smallest singular value each gives "
              "(JSON key 'suggestions').")
@import_options
def identifiability_cmd(machine, poses_arg, setup_spec, poses, method, fix, free, as_json, mapping=None,
                        suggest=False) -> None:
    """Which parameters of MACHINE the SETUP can identify from POSES.csv.

    Prints the rank of the column-scaled, noise-weighted identification Jacobian, its
    singular values, the unobservable combinations (named), weakly identifiable
    directions, and a minimal set of parameters to fix (the gauge). JSON keys: n_params,
    rank, singular_values, null_space, fixed, weak, ...
    """
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.io.machine_file import load_machine
    from pkmcal.io.setup_file import load_setup

    poses = poses_file(poses, poses_arg, "identifiability")
    nominal = load_machine(machine)
    setup = load_setup(setup_spec, nominal)
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
    if as_json:
        d = rep.to_dict()
        d["warnings"] = notes
        if advice is not None:
            d["suggestions"] = advice.to_dict()
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

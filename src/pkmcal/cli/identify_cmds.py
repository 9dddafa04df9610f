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

import json

import click
import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.identifiability import format_direction
from pkmcal.identification.redundant_campaign import (
    BASELINES,
    baseline_inputs,
    baseline_result,
    is_redundant,
    sensor_calibration_block,
)
from pkmcal.identification.residuals import METHODS
from pkmcal.cli.import_options import import_options
from pkmcal.io.atomic import atomic_write_text, check_output_path
from pkmcal.io.measurements import load_measurements
from pkmcal.io.tables import read_poses
from pkmcal.sensors.library import BUILTIN_SETUPS


def _names(values: tuple[str, ...]) -> list[str] | None:
    out = [n for v in values for n in v.replace(",", " ").split() if n]
    return out or None


def _fmt(v: float, angle: bool) -> str:
    return f"{np.rad2deg(v):.6f}°" if angle else f"{v:.6f}"


def _angle_names(result) -> set[str]:
    """Names of the angle parameters (shown in degrees), from the sensor's ``param_is_angle``
    and the machine's (a machine without the flags, the hexapod, has only lengths)."""
    sensor, mech = result.sensor, result.mechanism
    angles = {n for n, a in zip(sensor.param_names, sensor.param_is_angle) if a}
    angles.update(n for n, a in zip(mech.param_names, mech.param_is_angle) if a)
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


def fit_summary(result) -> str:
    u = result.uncertainty
    rep = result.identifiability
    lines = [
        f"method {result.method} ({'noise-weighted' if result.weighted else 'unweighted'}), "
        f"{len(result.used_poses)} poses, {len(result.free)} free parameters",
        f"solver: {'converged' if result.success else 'NOT converged'} after {result.nfev} evaluations: {result.message}",
        f"rms residual {result.rms_residual:.6g} ({', '.join(result.residual_names)}); "
        f"chi2/dof = {u.chi2:.6g}/{u.dof} = {u.reduced_chi2:.4g}",
        f"identifiability: rank {rep.rank} of {rep.n_params}, condition number {rep.condition_number:.3g}",
        "std: a-priori (noise model) x max(1, chi2/dof) — this covariance is written to the machine file",
    ]
    for d in rep.null_space:
        lines.append(f"  unobservable: {format_direction(d)}")
    for w in rep.weak:
        lines.append(f"  weak (sigma ratio {w['ratio']:.2g}): {format_direction(w['direction'])}")
    lines += [f"note: {w}" for w in result.warnings]
    return "\n".join(lines)


@click.command("identify")
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
              help="Parameters to estimate (default: all machine parameters and the sensor's free ones).")
@click.option("-o", "--output", required=True, metavar="CALIBRATED.yaml", help="Calibrated machine file to write.")
@click.option("--json", "as_json", is_flag=True, help="Print the fit as JSON instead of a table.")
@click.option("--report", "report_dir", metavar="DIR",
              help="Also write the HTML calibration report (report.html and its figures) into folder DIR.")
@import_options
def identify_cmd(machine, measurements, setup_spec, method, unweighted, form, fix, free, output, as_json,
                 report_dir=None, mapping=None, keep=None) -> None:
    """Identify MACHINE's kinematic parameters from MEAS.csv and write CALIBRATED.yaml.

    Units: mm, degrees in files and tables. Unidentifiable combinations are fixed
    automatically (the gauge, shown in the table) unless --free/--fix say otherwise, in
    which case an unidentifiable request is an error naming the combination.
    """
    inputs = [machine, measurements, setup_spec]
    check_output_path(output, inputs)
    if report_dir is not None:
        _check_report_dir(report_dir, inputs)
    from pkmcal.identification.engine import identify
    from pkmcal.io.machine_file import load_machine, machine_to_text
    from pkmcal.io.setup_file import load_setup

    nominal = load_machine(machine)
    setup = load_setup(setup_spec, nominal)
    meas = load_measurements(measurements, nominal, setup, mapping)
    if method is None:
        method = ("projection" if is_redundant(nominal) else
                  "ik-residual" if setup.sensor.kind == "full-pose" else "fk-residual")
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
    result = identify(fit_machine, fit_setup, fit_meas, method=method, free=_names(free), fix=fix_names,
                      weighted=not unweighted, form=form)
    if baseline is not None:
        result = baseline_result(result, nominal, baseline)
    if not result.success:
        raise PkmcalError(f"the fit did not converge ({result.message}); nothing written")
    text = machine_to_text(_with_calibration_record(result, measurements, setup_spec))
    _check_loads_back(text, output)
    report = None if report_dir is None else _report_data(nominal, result, setup, meas, measurements, output)
    if as_json:  # everything printed is made before anything is written
        from pkmcal.io.json_out import finite_or_null

        d = finite_or_null(result.to_dict())
        d["output"] = output
    atomic_write_text(output, text)
    if report is not None:
        from pkmcal.report import write_report

        written = write_report(report, report_dir)
    if as_json:
        if report is not None:
            d["report"] = str(written.html)
        click.echo(json.dumps(d, indent=2, allow_nan=False))
    else:
        click.echo(result_table(result))
        click.echo(fit_summary(result))
        click.echo(f"wrote {output}" + (f" and {written.html}" if report is not None else ""))


def _with_calibration_record(result, measurements: str, setup_spec: str):
    """The identified machine with a ``calibration`` record in its metadata (kept in the
    machine file; ``pkmcal export --format json`` shows it). No date: same inputs, same bytes."""
    import dataclasses

    mech = result.mechanism
    if not dataclasses.is_dataclass(mech) or "metadata" not in {f.name for f in dataclasses.fields(mech)}:
        return mech
    u = result.uncertainty
    record = {
        "method": result.method, "weighted": bool(result.weighted), "measurements": str(measurements),
        "setup": str(setup_spec), "n_poses": int(len(result.used_poses)), "n_free": int(len(result.free)),
        "gauge": list(result.gauge), "rms_residual": float(result.rms_residual),
        # undefined (null) without degrees of freedom
        "reduced_chi2": float(u.reduced_chi2) if np.isfinite(u.reduced_chi2) else None,
        "std": "a-priori (noise model) x max(1, chi2/dof)",
    }
    if getattr(result.sensor, "kind", "") == "planar-tool":  # read back by 'pkmcal verify'
        record["sensor"] = sensor_calibration_block(result.sensor)
    return dataclasses.replace(mech, metadata={**dict(mech.metadata), "calibration": record})


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


def _report_data(nominal, result, setup, meas, meas_path: str, output: str):
    """The report of ``pkmcal identify``: the measured poses are the commanded ones of the
    file (cmd_x..), else the nominal machine's FK of the actuator readings."""
    from pkmcal.io.setup_file import setup_to_yaml
    from pkmcal.report.from_results import report_data_from_results

    if meas.commanded is not None:
        poses = meas.commanded
    else:
        with np.errstate(all="ignore"):
            fk = nominal.fk(meas.actuators)
        poses = np.asarray(fk.poses)[np.asarray(fk.converged, dtype=bool)]
    try:
        setup_text = setup_to_yaml(setup)
    except PkmcalError:
        setup_text = setup.sensor.kind
    return report_data_from_results(
        nominal, result, setup, poses, setup_summary=setup_text,
        facts=(("measurement file", str(meas_path)), ("calibrated machine file", str(output))))


@click.command("identifiability")
@click.argument("machine")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml",
              help=f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)}).")
@click.option("--poses", required=True, metavar="POSES.csv", help="Poses: columns x,y,z (mm), a,b,c (deg).")
@click.option("--method", type=click.Choice(METHODS), default=None,
              help="Method whose Jacobian is analysed (default: fk-residual; projection for redundant machines).")
@click.option("--fix", "fix", multiple=True, metavar="NAMES", help="Parameters held (removed from the analysis).")
@click.option("--free", "free", multiple=True, metavar="NAMES", help="Candidate parameters (default: all + sensor's free).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@import_options
def identifiability_cmd(machine, setup_spec, poses, method, fix, free, as_json, mapping=None) -> None:
    """Which parameters of MACHINE the SETUP can identify from POSES.csv.

    Prints the rank of the column-scaled, noise-weighted identification Jacobian, its
    singular values, the unobservable combinations (named), weakly identifiable
    directions, and a minimal set of parameters to fix (the gauge). JSON keys: n_params,
    rank, singular_values, null_space, fixed, weak, ...
    """
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.io.machine_file import load_machine
    from pkmcal.io.setup_file import load_setup

    nominal = load_machine(machine)
    setup = load_setup(setup_spec, nominal)
    x = read_poses(poses, nominal, mapping)
    fix_names = _names(fix)
    rep = identifiability(nominal, setup, x, method=method, free=_names(free),
                          fix=None if fix_names == ["auto"] else fix_names)
    if as_json:
        click.echo(json.dumps(rep.to_dict(), indent=2, allow_nan=False))
        return
    click.echo(f"{nominal.name} with {setup.sensor.kind} sensor, {len(x)} poses: rank {rep.rank} of "
               f"{rep.n_params} (relative tolerance {rep.rtol:g}, unit-norm columns), "
               f"condition number {rep.condition_number:.3g}")
    s = rep.singular_values
    click.echo("singular values / largest: " + " ".join(f"{v / s[0]:.2e}" for v in s))
    if rep.null_space:
        click.echo(f"{len(rep.null_space)} unobservable combination(s) (no reading changes along them):")
        for d in rep.null_space:
            click.echo(f"  {format_direction(d)}")
        click.echo(f"suggested gauge (fix these): {', '.join(rep.fixed)}")
    for w in rep.weak:
        click.echo(f"weak (ratio {w['ratio']:.2g}): {format_direction(w['direction'])}")
    if rep.unseen:
        click.echo(f"not seen at all: {', '.join(rep.unseen)}")

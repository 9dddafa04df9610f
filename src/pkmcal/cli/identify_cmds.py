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
from pkmcal.identification.engine import identify
from pkmcal.identification.identifiability import format_direction, identifiability
from pkmcal.identification.residuals import METHODS
from pkmcal.io.atomic import atomic_write_text, check_output_path
from pkmcal.io.machine_file import load_machine, machine_to_text
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import BUILTIN_SETUPS, load_setup


def _names(values: tuple[str, ...]) -> list[str] | None:
    out = [n for v in values for n in v.replace(",", " ").split() if n]
    return out or None


def _fmt(v: float, angle: bool) -> str:
    return f"{np.rad2deg(v):.6f}°" if angle else f"{v:.6f}"


def _angle_names(result) -> set[str]:
    sensor = result.sensor
    angles = set()
    for n in sensor.param_names:
        if n.split(".")[-1] in ("a", "b", "c") and n.split(".")[0] in ("world", "tool"):
            angles.add(n)
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
@click.option("--method", type=click.Choice(METHODS), default=None,
              help="ik-residual (full-pose sensor, paper 1), fk-residual (paper 2) or projection (paper 3). "
                   "Default: ik-residual for a full-pose sensor, else fk-residual.")
@click.option("--unweighted", is_flag=True, help="Plain least squares (the papers' fits) instead of noise-weighted.")
@click.option("--form", type=click.Choice(["plain", "squared"]), default="plain", show_default=True,
              help="ik-residual: q - IK(x) or paper 1's squared-length residual.")
@click.option("--fix", "fix", multiple=True, metavar="NAMES",
              help="Parameters to hold (names or patterns like 'b1.*', comma separated; repeatable), or 'auto'.")
@click.option("--free", "free", multiple=True, metavar="NAMES",
              help="Parameters to estimate (default: all machine parameters and the sensor's free ones).")
@click.option("-o", "--output", required=True, metavar="CALIBRATED.yaml", help="Calibrated machine file to write.")
@click.option("--json", "as_json", is_flag=True, help="Print the fit as JSON instead of a table.")
def identify_cmd(machine, measurements, setup_spec, method, unweighted, form, fix, free, output, as_json) -> None:
    """Identify MACHINE's kinematic parameters from MEAS.csv and write CALIBRATED.yaml.

    Units: mm, degrees in files and tables. Unidentifiable combinations are fixed
    automatically (the gauge, shown in the table) unless --free/--fix say otherwise, in
    which case an unidentifiable request is an error naming the combination.
    """
    check_output_path(output, [machine, measurements, setup_spec])
    nominal = load_machine(machine)
    setup = load_setup(setup_spec)
    meas = load_measurements(measurements, nominal, setup)
    if method is None:
        method = "ik-residual" if setup.sensor.kind == "full-pose" else "fk-residual"
    fix_names = _names(fix)
    if fix_names == ["auto"]:
        fix_names = "auto"
    result = identify(nominal, setup, meas, method=method, free=_names(free), fix=fix_names,
                      weighted=not unweighted, form=form)
    if not result.success:
        raise PkmcalError(f"the fit did not converge ({result.message}); nothing written")
    text = machine_to_text(result.mechanism)
    atomic_write_text(output, text)
    if as_json:
        d = result.to_dict()
        d["output"] = output
        click.echo(json.dumps(d, indent=2, allow_nan=False))
    else:
        click.echo(result_table(result))
        click.echo(fit_summary(result))
        click.echo(f"wrote {output}")


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
def identifiability_cmd(machine, setup_spec, poses, method, fix, free, as_json) -> None:
    """Which parameters of MACHINE the SETUP can identify from POSES.csv.

    Prints the rank of the column-scaled, noise-weighted identification Jacobian, its
    singular values, the unobservable combinations (named), weakly identifiable
    directions, and a minimal set of parameters to fix (the gauge). JSON keys: n_params,
    rank, singular_values, null_space, fixed, weak, ...
    """
    from pkmcal.cli.campaign_cmds import read_poses

    nominal = load_machine(machine)
    setup = load_setup(setup_spec)
    x = read_poses(poses, nominal)
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


def register(group: click.Group) -> None:
    group.add_command(identify_cmd)
    group.add_command(identifiability_cmd)

"""``pkmcal simulate`` and ``pkmcal verify``: simulated campaigns and held-out verification.

* ``simulate``: commanded poses → nominal IK → real FK → sensor and encoder readings with
  seeded noise (:func:`pkmcal.workflow.simulate.simulate_files`:
  :func:`pkmcal.identification.simulation.simulate_campaign`; paper 1 §IV,
  paper 2 §5), written as a measurement CSV (:mod:`pkmcal.io.measurements`).
* ``verify``: measured held-out validation, or pose errors of the real machine commanded
  through the calibrated (and the nominal) model on held-out poses
  (:mod:`pkmcal.workflow.verify`: :mod:`pkmcal.identification.heldout`,
  :mod:`pkmcal.identification.verification`).

Redundantly actuated machines (more actuators than pose coordinates, paper 3) are simulated
at static equilibrium under the setup's actuator stiffness and tool load, by the same
functions (:func:`~pkmcal.identification.simulation.settles_at_equilibrium`), in
``simulate`` and in ``verify`` (``compare="tool"``).

Everything is read, validated and computed before any output is written (atomically); on
a user error nothing is written and the exit code is 2.
"""

from __future__ import annotations

import json

import click

from pkmcal.errors import PkmcalError
from pkmcal.cli.import_options import import_options
from pkmcal.cli.options import (check_output, emit, examples, option, output_option, quiet_accepted, quiet_option,
                                to_stdout, units_comment_option)
from pkmcal.cli.option_types import SEED, FiniteFloat
from pkmcal.io.atomic import atomic_write_text
from pkmcal.io.limits import MAX_MAGNITUDE
from pkmcal.io.measurements import CLIPPED_POLICIES, measurement_columns
from pkmcal.io.tables import format_table
from pkmcal.io.json_out import finite_or_null
from pkmcal.workflow.simulate import simulate_files
from pkmcal.workflow.verify import verify_against_real, verify_measured
from pkmcal.workflow.vocabulary import BUILTIN_SETUPS


@click.command("simulate", epilog=examples(
    "pkmcal simulate stewart-prototype --real stewart-prototype-real --setup indicators-prototype --poses poses.csv "
    "--seed 2 -o meas.csv",
    "pkmcal simulate stewart-prototype --random-errors 1 --save-real real.yaml --setup full-pose-paper1 "
    "--poses poses.csv --ignore-limit leg_collision -o meas-full.csv",
    "pkmcal simulate planar-3dof-4act --random-errors 0.5 --setup planar-tracker --poses planar-poses.csv "
    "-o planar-meas.csv"))
@click.argument("machine")
@click.option("--real", "real_spec", metavar="REAL", help="The 'real' machine: a machine file or built-in name.")
@click.option("--random-errors", type=FiniteFloat(min=0.0, max=MAX_MAGNITUDE), metavar="MM",
              help="Instead of --real: every parameter of MACHINE plus a random error of this size (mm; "
                   "angle parameters of planar machines MM/1000 rad).")
@click.option("--error-distribution", type=click.Choice(["uniform", "gaussian"]), default="uniform",
              show_default=True, help="With --random-errors: U(-MM, MM) (paper 1) or N(0, MM^2).")
@click.option("--save-real", metavar="REAL.yaml", help="With --random-errors: write the drawn real machine here.")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml",
              help=f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)}).")
@click.option("--poses", required=True, metavar="POSES.csv",
              help="Commanded poses: columns x,y,z (mm), a,b,c (deg); planar machines: their pose names (x,y[,phi]).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same bytes).")
@click.option("--ignore-limit", "ignore_limits", multiple=True, metavar="NAME",
              help="A limit of the real machine not to check (e.g. leg_collision); repeatable.")
@click.option("--sessions", "n_sessions", type=click.IntRange(min=1), metavar="S",
              help="Measure in S sessions: the poses split in order into S parts, labelled 1..S in a 'session' "
                   "column, each read with its own true sensor (e.g. a motion-capture system set up again): "
                   "session 1 the setup's, session L the setup's 'sessions: {L: {...}}' where given, else the "
                   "setup's free sensor parameters moved by --session-errors.")
@click.option("--session-errors", type=FiniteFloat(min=0.0, max=MAX_MAGNITUDE), default=5.0, show_default=True,
              metavar="MM", help="With --sessions: size of the drawn changes of each later session's free sensor "
                                 "parameters, U(-MM, MM) mm, angles MM/1000 rad (the --random-errors rule).")
@click.option("--session-offsets", type=FiniteFloat(min=0.0, max=MAX_MAGNITUDE), metavar="MM",
              help="With --sessions: re-home the actuators before each later session, their zeros moved by "
                   "U(-MM, MM) mm (rotary: MM/1000 rad); the file records the readings of the moved zeros "
                   "(identify --session-offsets estimates them as dq_i@LABEL).")
@click.option("--probe-anywhere", is_flag=True,
              help="Z probes: read the probe at poses off the bed too (a probe on gauge blocks); by default a pose "
                   "whose probe point is not on the bed is refused (a probe reads only where it touches the bed).")
@output_option("MEAS.csv", "Measurement CSV")
@units_comment_option
@quiet_option
@import_options
def simulate_cmd(machine, real_spec, random_errors, error_distribution, save_real, setup_spec, poses, seed,
                 ignore_limits, output, units_comment, quiet, mapping, n_sessions=None, session_errors=5.0,
                 session_offsets=None, probe_anywhere=False) -> None:
    """Simulate measuring POSES.csv on a real machine commanded with the nominal MACHINE.

    The actuators are commanded by MACHINE's inverse kinematics; the real machine goes where
    its forward kinematics take it; the sensor of the setup reads that pose, with the setup's
    noise on the sensor and on the actuator readings. Poses the real machine cannot reach
    (FK not converged, its limits) are dropped and listed. The output has lambda1..lambda6,
    the sensor's columns and the commanded pose cmd_x..cmd_c (mm, deg).

    A redundantly actuated MACHINE (e.g. planar-3dof-4act) cannot follow FK: the real
    machine settles at the static equilibrium of its actuator springs (commanded by
    MACHINE's IK) and the tool load, both from the setup's 'simulation:' block. The output
    has the encoder readings q1..ql at equilibrium (mm, or deg for rotary actuators; the
    following error is q - IK(cmd)), the tracker's px, py and the commanded pose cmd_<pose>.

    With --sessions S the file has a 'session' column (last) and the summary lists each
    session's true sensor parameters (and actuator offsets), mm and degrees.

    A Z probe reads only on the bed: a pose whose probe point the nominal machine puts off
    the bed (more than 0.001 mm) is refused, naming its row, unless --probe-anywhere
    ('pkmcal plan' plans a Z probe's points on the bed).
    """
    if (real_spec is None) == (random_errors is None):
        raise PkmcalError("give the real machine with --real REAL, or draw one with --random-errors MM")
    if save_real is not None and random_errors is None:
        raise PkmcalError("--save-real writes the machine drawn by --random-errors; use it with --random-errors")
    inputs = [machine, real_spec, setup_spec, poses]
    check_output(output, inputs)
    if save_real is not None:
        check_output(save_real, inputs)
    if output is not None and save_real is not None and output == save_real:
        raise PkmcalError("-o and --save-real name the same file; choose two paths")
    from pkmcal.io.machine_file import machine_to_text
    from pkmcal.progress import ProgressBar

    done = simulate_files(machine, setup_spec, poses, real=real_spec, random_errors=random_errors,
                          error_distribution=error_distribution, seed=seed, ignore_limits=tuple(ignore_limits),
                          n_sessions=n_sessions, session_errors=session_errors, session_offsets=session_offsets,
                          probe_anywhere=probe_anywhere, mapping=mapping,
                          progress=lambda: ProgressBar("simulate", quiet=quiet, unit="poses"))
    nominal, real, setup, commanded, result, session_text = done.nominal, done.real, done.setup, done.commanded, \
        done.result, done.session_lines
    if len(result.kept) == 0:
        raise PkmcalError(f"the real machine '{real.name}' reaches none of the {len(commanded)} poses of "
                          f"'{poses}' ({'; '.join(sorted(set(result.dropped.values())))}); nothing written")
    comments = [
        f"pkmcal simulate: nominal {nominal.name}, real {real.name}, setup {setup_spec} "
        f"({setup.sensor.kind}, {setup.noise.distribution} noise), poses {poses}, seed {seed}",
    ]
    if result.dropped:
        comments.append("dropped rows of the pose file: " + ", ".join(
            f"{k + 1} ({why})" for k, why in result.dropped.items()))
    text = format_table(measurement_columns(result.measurements, nominal, setup), comments=comments,
                        units_comment=units_comment)
    real_text = machine_to_text(real) if save_real is not None else None
    if real_text is not None:
        atomic_write_text(save_real, real_text)
    summary = "\n".join([result.summary(), *session_text])
    emit(text, output)
    if to_stdout(output):
        click.echo(summary, err=True)
    else:
        click.echo(summary)
        click.echo(f"wrote {output}" + (f" and {save_real}" if save_real else ""))


@click.command("verify", epilog=examples(
    "pkmcal simulate stewart-prototype --real stewart-prototype-real --setup indicators-prototype --poses heldout.csv "
    "--seed 3 -o heldout-meas.csv",
    "pkmcal verify calibrated.yaml --held-out heldout-meas.csv --setup indicators-prototype",
    "pkmcal verify calibrated.yaml --held-out heldout-meas.csv --setup calibrated.yaml --json -o verify-held.json",
    "pkmcal verify calibrated.yaml --held-out heldout-meas.csv --setup indicators-prototype --nominal "
    "stewart-prototype --calibration-measurements meas.csv",
    "pkmcal verify calibrated.yaml --real stewart-prototype-real --nominal stewart-prototype --poses heldout.csv",
    "pkmcal verify calibrated.yaml --real stewart-prototype-real --poses heldout.csv --json -o verify.json",
    "pkmcal verify calibrated.yaml --real stewart-prototype-real --setup indicators-prototype --nominal "
    "stewart-prototype --poses heldout.csv",
    "pkmcal verify calibrated.yaml --real stewart-prototype-real --poses iso9283.csv --compare commanded"))
@click.argument("calibrated")
@option("--held-out", "meas_path", metavar="HELDOUT.csv", old=("--measurements",),
              help="Measured held-out data (a measurement CSV as identify reads, not used in the fit): predict each "
                   "measurement from its actuator readings and compare with what was measured.")
@click.option("--real", "real_spec", metavar="REAL",
              help="Instead of --held-out: the true machine (file or built-in name) of a simulation, commanded "
                   "at the --poses through each model.")
@click.option("--poses", metavar="HELDOUT.csv",
              help="With --real: held-out poses x,y,z (mm), a,b,c (deg); planar machines: their pose names (x,y[,phi]).")
@click.option("--nominal", metavar="NOMINAL",
              help="The nominal machine, for the 'before' column. Default with --held-out: the machine the "
                   "calibration record names (a built-in, or a file that still exists). With --real and --compare "
                   "sensor or aligned, the --poses are in its frames (default: the record's machine) and are carried "
                   "into the calibrated model's frames, so that both models command the same physical poses.")
@click.option("--setup", "setup_spec", metavar="SETUP.yaml",
              help="With --held-out: the measurement setup (CALIBRATED.yaml itself works; the sensor identified "
                   "in CALIBRATED.yaml's setup: is used when it has one). With --real: the true instrument, whose "
                   "readings are compared (--compare sensor; a printed-distance setup reads the held-out poses with "
                   "its Z probe); redundant machines: the tracker setup with the 'simulation:' stiffness and load "
                   "(required there).")
@click.option("--calibration-measurements", "calib_meas", metavar="MEAS.csv",
              help="With --held-out, for a calibrated file without calibration.before_registration: the "
                   "calibration data on which the nominal machine's sensor frames are registered for 'before'.")
@click.option("--compare", type=click.Choice(["auto", "sensor", "aligned", "commanded"]), default="auto",
              show_default=True,
              help="With --real: what is compared. sensor: the true instrument's readings (--setup) against each "
                   "model's prediction (tool point/frame in the world frame); aligned: platform frames after the "
                   "best rigid alignment of base and platform frames; commanded: platform poses as commanded (depends "
                   "on the gauge when sensor frames were identified). auto: sensor with --setup, else aligned.")
@click.option("--clipped", type=click.Choice(CLIPPED_POLICIES), default=None,
              help="With --held-out: held-out poses with a clipped or stuck actuator reading are listed and left "
                   "out (drop, the default), used (keep), or an error, as identify does.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--ignore-limit", "ignore_limits", multiple=True, metavar="NAME",
              help="With --real: a limit of the real machine not to check (e.g. leg_collision); repeatable.")
@output_option("FILE", "Write the table/JSON here")
@import_options
@quiet_accepted
def verify_cmd(calibrated, meas_path, real_spec, poses, nominal, setup_spec, calib_meas, compare, clipped, as_json,
               ignore_limits, output, mapping) -> None:
    """Validate CALIBRATED on held-out data: measured (--held-out) or a true machine (--real).

    --held-out HELDOUT.csv: each held-out measurement is predicted from its actuator
    readings (FK of CALIBRATED, then the sensor identified with it) and compared with what
    was measured, per pose and in summary (mean, RMS, max): full-pose sensors position
    error (mm) and the rotation angle between measured and predicted rotations (deg);
    position sensors position only; indicators the reading residuals (mm). Beside it:
    'before', the nominal machine with its sensor frames registered on the calibration
    data (calibration.before_registration), and 'after_reregistered', CALIBRATED with only
    the setup's free sensor parameters refitted on the held-out data (what no
    re-registration of the instrument can remove). Poses whose FK fails are listed. JSON
    keys: before, after, after_reregistered: {position_mean_mm, position_rms_mm,
    position_max_mm, orientation_rms_deg (null where the sensor reads no orientation),
    reading_*_mm, n_poses}; per_pose (the file's pose numbers), failed, clipped.

    --real REAL --poses HELDOUT.csv: for each pose the actuators are commanded by the
    model's inverse kinematics and the real machine goes where its FK takes it; --compare
    says what is compared (stated in the output and the JSON key 'compare'). JSON keys:
    before/after: {position_mean_mm, position_max_mm, position_rms_mm,
    orientation_mean_deg, ..., tilt_*_deg, height_*_mm}, compare, compared.

    Held-out poses in the ISO 9283 pattern ('pkmcal plan --pattern iso9283'; with
    --held-out, the cmd_x.. columns): also the standard's AP, RP, AD, RD, each with its
    expanded uncertainty U (k = 2) from the instrument's noise and registration (exact with
    --real). JSON key iso9283. A ballbar's circle test ('plan --algorithm circle') with
    --held-out: ISO 230-4 F_max, F_min, G with U (JSON key iso230_4).
    docs/accuracy-reports.md.

    Redundantly actuated machines (planar-2dof-3act, planar-3dof-4act) with --real: the tool
    point should read the tracker value of each held-out pose; each model commands it (the
    calibrated one with the tracker parameters identified with it), the REAL machine
    settles at static equilibrium under the --setup's stiffness and load, and the tool
    error |reading - target| (mm; plate angle error in deg for 3-dof) is reported. JSON
    keys: before/after: {poses, tool_mean_mm, tool_max_mm, tool_rms_mm[, angle_*_deg]},
    improvement_pct, dropped.
    """
    if (real_spec is None) == (meas_path is None):
        raise PkmcalError("give exactly one of --held-out HELDOUT.csv (measured held-out data) or --real REAL "
                          "(a true machine, with --poses)")
    check_output(output, [calibrated, real_spec, poses, nominal, setup_spec, meas_path, calib_meas])
    if meas_path is not None:
        for name, value in (("--poses", poses), ("--ignore-limit", ignore_limits or None),
                            ("--compare", None if compare == "auto" else compare)):
            if value is not None:
                raise PkmcalError(f"{name} applies to --real; with --held-out the held-out poses are the rows "
                                  "of HELDOUT.csv")
        report = verify_measured(calibrated, meas_path, nominal=nominal, setup=setup_spec,
                                 calibration_measurements=calib_meas, clipped=clipped or "drop", mapping=mapping)
        emit(json.dumps(finite_or_null(report.to_dict()), indent=2, allow_nan=False) + "\n" if as_json
             else report.format_table() + "\n", output)
        return
    if poses is None:
        raise PkmcalError("--real needs the held-out poses: give --poses HELDOUT.csv")
    for name, value in (("--calibration-measurements", calib_meas), ("--clipped", clipped)):
        if value is not None:
            raise PkmcalError(f"{name} applies to --held-out (measured held-out data), not to --real")
    report = verify_against_real(calibrated, real_spec, poses, nominal=nominal,
                                 setup=setup_spec, compare=compare, ignore_limits=tuple(ignore_limits), mapping=mapping)
    emit(json.dumps(finite_or_null(report.to_dict()), indent=2, allow_nan=False) + "\n" if as_json
         else report.format_table() + "\n", output)

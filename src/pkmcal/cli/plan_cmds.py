"""``pkmcal plan`` and ``pkmcal observability``: which poses to measure, and how good a set is.

* ``plan``: candidate poses (random in the workspace box, or a CSV), checked against the
  nominal machine's limits with safety margins a real machine survives
  (:mod:`pkmcal.planning.margins`) and against the sensor's measurability,
  then a selection algorithm (:mod:`pkmcal.planning.selection`) picks N of them; writes
  x, y, z (mm), a, b, c (deg) and the nominal actuator commands lambda1..lambda6 (rotary
  actuators of other machines in degrees).
* ``observability``: the indices O1..O5 (:mod:`pkmcal.planning.indices`) of a pose set,
  on the same identifiable parameters and column scaling as ``plan``.
"""

from __future__ import annotations

import json

import click
import numpy as np

from pkmcal.workflow.analysis import unreachable_notes
from pkmcal.cli.backend_options import backend_options, check_backend
from pkmcal.cli.import_options import import_options
from pkmcal.cli.options import (
    DeprecatedArgument,
    check_output,
    emit,
    examples,
    output_option,
    poses_file,
    quiet_option,
    summary_echo,
    units_comment_option,
)
from pkmcal.errors import PkmcalError
from pkmcal.io.tables import format_table, to_file_units
from pkmcal.planning.candidates import Measurability, read_candidates_csv
from pkmcal.cli.option_types import SEED, FiniteFloat
from pkmcal.planning.indices import INDEX_DESCRIPTIONS, INDEX_NAMES
from pkmcal.planning.margins import ASSUMED_JOINT_ERROR_MM, CLEARANCE_MARGIN_MM
from pkmcal.planning.selection import ALGORITHMS
from pkmcal.sensors.library import BUILTIN_SETUPS

#: What ``plan --format`` writes: the poses, a Klipper macro, Marlin G-code (Z probes).
PLAN_FORMATS = ("csv", "klipper", "gcode")
_SETUP_HELP = f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)})."


def _measurability(travel, plate_radius, sight_cone) -> Measurability:
    return Measurability(travel=None if travel is None else (float(travel[0]), float(travel[1])),
                         plate_radius=plate_radius,
                         sight_cone=None if sight_cone is None else float(np.deg2rad(sight_cone)))


def _format_indices(ind: dict[str, float]) -> str:
    return "  ".join(f"{k} = {ind[k]:.6g}" for k in INDEX_NAMES)


@click.command("plan", epilog=examples(
    "pkmcal plan stewart-prototype --setup indicators-prototype --n 45 --seed 1 -o poses.csv",
    "pkmcal plan stewart-prototype --setup full-pose-paper1 --n 20 --algorithm cuckoo --n-candidates 500 -o cuckoo.csv",
    "pkmcal plan stewart-prototype --setup indicators-prototype --n 50 --algorithm random --seed 9 -o heldout.csv",
    "pkmcal plan stewart-prototype --setup indicators-prototype --n 30 --tilt-margin 5 -o cautious.csv",
    "pkmcal plan planar-3dof-4act --setup planar-tracker --n 12 -o planar-poses.csv",
    "pkmcal plan stewart-prototype --setup full-pose-paper1 --n 30 --n-candidates 20000 --workers 2 -o large.csv",
    "pkmcal plan stewart-prototype --setup examples/setup-ballbar.yaml --algorithm circle --n 36 -o circle.csv",
    "pkmcal plan kossel-mini --setup z-probe-klipper --n 20 --target-accuracy 0.003 -o probe-points.csv",
    "pkmcal plan kossel-mini --setup z-probe-klipper --n 20 --format klipper -o probe-plan.cfg",
    "pkmcal plan kossel-mini --setup z-probe-klipper --n 20 --format gcode -o probe-plan.gcode"))
@click.argument("machine")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml", help=_SETUP_HELP)
@click.option("--n", "n_poses", type=click.IntRange(min=1), default=30, show_default=True, help="Number of poses to choose.")
@click.option("--candidates", "candidates_path", metavar="FILE.csv", type=click.Path(dir_okay=False),
              help="Candidate poses: columns x,y,z (mm), a,b,c (deg). Default: random poses in the workspace box.")
@click.option("--n-candidates", type=click.IntRange(min=1), default=2000, show_default=True,
              help="Number of random candidates (reachable and measurable) when no --candidates file.")
@click.option("--grid", type=click.IntRange(min=2, max=8), metavar="K",
              help="Instead of random candidates: a K^6 grid of the workspace box (checked like the others).")
@click.option("--index", type=click.Choice(INDEX_NAMES, case_sensitive=False), default=None,
              help="Index to maximise: detmax and cuckoo (default O4); the default algorithm maximises O1, "
                   "then polishes the set on this index if given.")
@click.option("--algorithm", type=click.Choice(ALGORITHMS, case_sensitive=False), default="default", show_default=True,
              help="default: D-optimal exchange (O1); detmax / cuckoo: paper 2 add/remove search on --index; "
                   "corners: random corners of the workspace box (paper 1); random; circle: the ballbar circle "
                   "test of a distance setup (N poses on the circle about pivot 1, in order).")
@click.option("--circle-plane", type=click.Choice(("xy", "yz", "zx")), default="xy", show_default=True,
              help="--algorithm circle: the base-frame plane of the circle (through pivot 1).")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same poses).")
@click.option("--stroke-margin", type=FiniteFloat(min=0.0), metavar="MM",
              help=f"Hexapods: keep every leg reading this far inside its stroke, at both ends. Default "
                   f"{ASSUMED_JOINT_ERROR_MM:g} mm (joint errors up to {ASSUMED_JOINT_ERROR_MM:g} mm).")
@click.option("--tilt-margin", type=FiniteFloat(min=0.0), metavar="DEG",
              help=f"Hexapods: keep every U/S-joint tilt this far inside its limit. Default "
                   f"atan(d/r_p) + atan(d/L_min) for joint errors d = {ASSUMED_JOINT_ERROR_MM:g} mm, r_p the smallest "
                   "platform joint radius, L_min the shortest leg (3.02° on stewart-prototype).")
@click.option("--clearance-margin", type=FiniteFloat(min=0.0), metavar="MM",
              help=f"Hexapods: extra leg-to-leg clearance of the collision check. Default {CLEARANCE_MARGIN_MM:g} mm.")
@click.option("--margin", type=FiniteFloat(min=0.0), metavar="X",
              help="Instead of the three above: X on every limit (mm for stroke and clearance, degrees for the "
                   "joint tilts; the former single margin).")
@click.option("--indicator-travel", nargs=2, type=FiniteFloat(), metavar="LO HI",
              help="Indicators: accepted reading range (mm).")
@click.option("--plate-radius", type=FiniteFloat(min=0.0), metavar="MM",
              help="Indicators: the touch points must lie within this radius of the platform origin.")
@click.option("--sight-cone", type=FiniteFloat(min=0.0, max=180.0), metavar="DEG",
              help="Full-pose/position: half-angle of the target's line-of-sight cone.")
@click.option("--probe-anywhere", is_flag=True,
              help="Z probes: plan the probe's points anywhere in the volume (a probe on gauge blocks) instead of on "
                   "the bed (the default: every point lowered to where the probe triggers, its probe point inside "
                   "the build radius).")
@click.option("--format", "fmt", type=click.Choice(PLAN_FORMATS), default="csv", show_default=True,
              help="csv: the poses; klipper: a [gcode_macro PKMCAL_PROBE_PLAN] of G1/PROBE moves for printer.cfg, "
                   "whose console output 'pkmcal import klipper-probe' reads; gcode: Marlin G30 probes, whose "
                   "'Bed X: Y: Z:' output 'pkmcal import marlin-probe' reads (Z probes on the bed).")
@click.option("--target-accuracy", type=FiniteFloat(min=0.0), metavar="MM",
              help="Z probes: also print how many points the plan needs for a predicted first-layer error "
                   "(rms sigma over the bed) of MM, from the identifiability of the setup.")
@backend_options("in this process")
@output_option("POSES.csv", "CSV of the chosen poses (or the --format klipper/gcode file)")
@units_comment_option
@quiet_option
@import_options
def plan_cmd(machine, setup_spec, n_poses, candidates_path, n_candidates, grid, index, algorithm, circle_plane, seed,
             stroke_margin, tilt_margin, clearance_margin, margin, indicator_travel, plate_radius, sight_cone,
             workers, dask_address, output, units_comment=False, quiet=False, mapping=None, probe_anywhere=False,
             fmt="csv", target_accuracy=None) -> None:
    """Choose N poses of MACHINE to measure with SETUP (paper 2 §4, paper 1 §IV).

    Every candidate is checked on the nominal machine (stroke, joint tilts, leg collision,
    singularity) with safety margins that leave room for the real machine's deviations
    (defaults for joint errors up to 3 mm; the plan prints the margins it used), and for
    measurability; rejections are counted by reason. Writes x,y,z,a,b,c and the nominal
    commands lambda1..; prints O1..O5 of the chosen set. Large candidate sets are checked in
    chunks, which --workers / --dask run in parallel (same plan whatever the backend).

    A Z probe (a delta printer's) is planned on the bed: each point where the probe
    triggers (the nozzle z_offset above the bed), the probe point (nozzle + the setup's
    probe_offset) inside the build radius; the plan prints the probe's repeatability (the
    setup's noise.reading) and the predicted first-layer error for other numbers of
    points. --format klipper / gcode write it as a printer runs it.
    """
    from pkmcal.io.lookup import load_machine
    from pkmcal.io.lookup import load_setup
    from pkmcal.planning.executors import chunk_map
    from pkmcal.planning.margins import has_margins, resolve_margin
    from pkmcal.planning.plan import plan_poses
    from pkmcal.progress import ProgressBar

    from pkmcal.study.printed import probes_the_bed

    check_backend(workers, dask_address)
    check_output(output, [candidates_path, setup_spec, machine])
    mech = load_machine(machine)
    setup = load_setup(setup_spec, mech)
    probe = probes_the_bed(setup.sensor)
    for given, name in ((probe_anywhere, "--probe-anywhere"), (target_accuracy is not None, "--target-accuracy"),
                        (fmt != "csv", f"--format {fmt}")):
        if given and not probe:
            raise PkmcalError(f"{name} is for a Z probe's plan; the setup's '{setup.sensor.kind}' sensor is not one")
    if fmt != "csv" and probe_anywhere:
        raise PkmcalError(f"--format {fmt} writes probes a printer runs on its bed; drop --probe-anywhere")
    if fmt != "csv" and units_comment:
        raise PkmcalError(f"--units-comment begins a CSV; --format {fmt} writes G-code")
    given = [n for n, v in (("--stroke-margin", stroke_margin), ("--tilt-margin", tilt_margin),
                            ("--clearance-margin", clearance_margin)) if v is not None]
    if margin is not None and given:
        raise PkmcalError(f"--margin sets every limit's margin; give it or {', '.join(given)}, not both")
    if (given or margin is not None) and not has_margins(mech):
        raise PkmcalError(f"machine '{mech.name}' has no stroke or joint-tilt limits to keep a margin from "
                          "(its limits: workspace box, reach, transmission angle); remove the margin options")
    safety = margin if margin is not None else resolve_margin(mech, stroke_mm=stroke_margin, tilt_deg=tilt_margin,
                                                                clearance_mm=clearance_margin)
    candidates = read_candidates_csv(candidates_path, mech, mapping) if candidates_path else None
    with chunk_map(workers, dask_address) as run_chunks, ProgressBar("plan", quiet=quiet) as bar:
        plan = plan_poses(mech, setup, n_poses, algorithm=algorithm, index=index.upper() if index else None,
                          candidates=candidates, n_candidates=n_candidates, grid=grid, seed=seed, margin=safety,
                          measurability=_measurability(indicator_travel, plate_radius, sight_cone),
                          progress=bar.stage, circle_plane=circle_plane, chunk_map=run_chunks,
                          on_bed=False if probe_anywhere else None)
    command = (f"pkmcal plan {mech.name} --setup {setup_spec} --n {n_poses} --algorithm {plan.selection.algorithm} "
               f"--seed {seed}")
    if fmt != "csv":
        emit(_printer_file(fmt, plan, setup, command, machine, setup_spec), output)
    else:
        _emit_csv(plan, mech, command, output, units_comment)
    say = summary_echo(output)
    say(f"candidates: {plan.candidates.describe()}")
    say(f"safety margin: {plan.describe_margin()}")
    for note in plan.notes:
        say(f"note: {note}")
    sel = plan.selection
    say(f"identifiable parameters: {plan.model.n_params} ({plan.model.method}; gauge fixed: "
        f"{', '.join(plan.model.report.fixed) or 'none'})")
    say(f"{sel.algorithm}: {len(sel.chosen)} poses, maximised {sel.criterion}; {sel.message}")
    say(_format_indices(sel.indices))
    if plan.on_bed:
        _probe_summary(say, plan, setup, target_accuracy)
    if output is not None and output != "-":
        say(f"wrote {output}")


def _emit_csv(plan, mech, command: str, output, units_comment: bool) -> None:
    """The plan's poses and nominal commands as a CSV."""
    sel = plan.selection
    poses = to_file_units(plan.poses, mech.pose_is_angle)
    commands = to_file_units(plan.commands, mech.actuator_is_angle)
    cols = {name: poses[:, i] for i, name in enumerate(mech.pose_names)}
    cols.update({name: commands[:, i] for i, name in enumerate(mech.actuator_names)})
    sel = plan.selection
    emit(format_table(cols, units_comment=units_comment, comments=[
        f"{command}; maximised {sel.criterion}",
        f"safety margin: {plan.describe_margin()}",
        *(f"note: {n}" for n in plan.notes),
        _format_indices(sel.indices)]), output)


def _printer_file(fmt: str, plan, setup, command: str, machine: str, setup_spec: str) -> str:
    """The Klipper macro or Marlin G-code of an on-bed Z-probe plan (:mod:`pkmcal.io.probe_gcode`)."""
    from pkmcal.io.probe_gcode import klipper_probe_macro, marlin_probe_gcode

    offset = np.asarray(setup.sensor.probe_offset, dtype=float)
    nozzle = plan.poses[:, 0:2]
    if fmt == "klipper":
        return klipper_probe_macro(nozzle, offset, [
            f"{command} --format klipper", "Paste into printer.cfg (or [include] this file), RESTART, run "
            "PKMCAL_PROBE_PLAN, save the console (or klippy.log), then:",
            f"  pkmcal import klipper-probe console.log --machine {machine} --setup {setup_spec} -o probe.csv"])
    return marlin_probe_gcode(nozzle + offset[None, 0:2], offset, [
        f"{command} --format gcode", "Run on the printer (print it from SD or send it), save the terminal's "
        "output, then:",
        f"  pkmcal import marlin-probe terminal.log --machine {machine} --setup {setup_spec} -o probe.csv"])


def _probe_summary(say, plan, setup, target: float | None) -> None:
    """What an on-bed Z-probe plan prints: the probe, the predicted first-layer error for
    other numbers of points (:func:`pkmcal.planning.plan.height_sigma`), the points for
    ``target``, and what heights cannot see (:func:`~pkmcal.identification.identifiability.describe_named`)."""
    from pkmcal.identification.identifiability import describe_named, identifiability
    from pkmcal.planning.plan import height_sigma, points_for_height_sigma

    x, y, z = np.asarray(setup.sensor.probe_offset, dtype=float)
    noise = setup.noise.reading_std
    rep = f"{float(noise[0]):g} mm" if noise is not None and np.size(noise) else "not stated"
    say(f"probe: on the bed, each point where the probe triggers (probe offset x {x:g}, y {y:g}, z {z:g} mm: the "
        f"nozzle {z:g} mm above the bed, the probe point {x:g}, {y:g} mm beside it and inside the build radius); "
        f"repeatability sigma {rep} (the setup's noise.reading: give your PROBE_ACCURACY standard deviation)")
    n = len(plan.poses)
    ladder = sorted({k for k in (n // 2, n, 2 * n, 4 * n) if plan.model.n_params <= k <= len(plan.candidates.poses)}
                    | {n})
    curve = [(k, s) for k, s in height_sigma(plan, ladder) if np.isfinite(s)]
    if not curve:
        say(f"predicted first-layer error: none ({n} points give fewer readings than the {plan.model.n_params} "
            "identifiable parameters)")
    else:
        say("predicted first-layer error (rms sigma of the height over the reachable bed, from the identifiability of "
            "the points and the setup's noise): " + ", ".join(f"{k} points {s:.3g} mm" + (" (this plan)" if k == n
                                                                                          else "") for k, s in curve))
    if target is not None:
        need, tried = points_for_height_sigma(plan, target)
        if need is None:
            say(f"target first-layer sigma {target:g} mm: not reached with all {len(plan.candidates.poses)} "
                f"candidates ({tried[-1][1]:.3g} mm); probe each point several times (PROBE SAMPLES=...) or "
                "use a more repeatable probe")
        else:
            sigma = dict(tried)[need]
            say(f"target first-layer sigma {target:g} mm: {need} points ({sigma:.3g} mm); plan them with --n {need}")
    if curve:
        for entry in identifiability(plan.model.mechanism, setup, plan.poses).named:
            if entry["status"] != "identified":
                say(describe_named(entry))


@click.command("observability", epilog=examples(
    "pkmcal observability stewart-prototype --setup indicators-prototype --poses poses.csv",
    "pkmcal observability stewart-prototype --setup indicators-prototype --poses poses.csv --json"))
@click.argument("machine")
@click.argument("poses_arg", required=False, cls=DeprecatedArgument)
@click.option("--poses", metavar="POSES.csv", help="The pose set: columns x,y,z (mm), a,b,c (deg).")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml", help=_SETUP_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (keys O1..O5, n_poses).")
@import_options
def observability_cmd(machine, poses_arg, poses, setup_spec, as_json, mapping=None) -> None:
    """Observability indices O1..O5 of the poses in POSES.csv (columns x,y,z mm, a,b,c deg).

    On the scaled, noise-weighted identification Jacobian restricted to the identifiable
    parameters (as 'pkmcal plan'). O1 is D-optimality, O4 the noise amplification index.
    (The former spelling 'observability MACHINE POSES.csv' still works.)
    """
    from pkmcal.io.lookup import load_machine
    from pkmcal.io.lookup import load_setup
    from pkmcal.planning.plan import pose_set_indices

    poses = poses_file(poses, poses_arg, "observability")
    mech = load_machine(machine)
    setup = load_setup(setup_spec, mech)
    pose_arr = read_candidates_csv(poses, mech, mapping)
    ind = pose_set_indices(mech, setup, pose_arr)
    notes = unreachable_notes(mech, pose_arr, poses)
    if as_json:
        click.echo(json.dumps({**ind, "n_poses": int(len(pose_arr)), "warnings": notes,
                               "units": {**{k: "1" for k in INDEX_NAMES}, "n_poses": "1"}}))
        return
    click.echo(f"{len(pose_arr)} poses")
    for k in INDEX_NAMES:
        click.echo(f"{k} = {ind[k]:.6g}   {INDEX_DESCRIPTIONS[k]}")
    for n in notes:
        click.echo(f"warning: {n}")

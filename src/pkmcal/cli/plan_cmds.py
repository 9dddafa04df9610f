"""``pkmcal plan`` and ``pkmcal observability``: which poses to measure, and how good a set is.

* ``plan``: candidate poses (random in the workspace box, or a CSV), checked against the
  nominal machine's limits with safety margins a real machine survives
  (:mod:`pkmcal.planning.margins`) and against the sensor's measurability,
  then a selection algorithm (:mod:`pkmcal.planning.selection`) picks N of them; writes
  x, y, z (mm), a, b, c (deg) and the nominal actuator commands lambda1..lambda6 (rotary
  actuators of other machines in degrees).
* ``observability``: the indices O1..O5 (:mod:`pkmcal.planning.indices`) of a pose set,
  on the same identifiable parameters and column scaling as ``plan``.

Both are a shell over :mod:`pkmcal.workflow.plan`: they parse options, call it and print.
"""

from __future__ import annotations

import json

import click

from pkmcal.cli.backend_options import backend_options, check_backend
from pkmcal.cli.import_options import import_options
from pkmcal.cli.options import (
    DeprecatedArgument,
    check_output,
    deprecated,
    emit,
    examples,
    option,
    output_option,
    poses_file,
    quiet_accepted,
    quiet_option,
    summary_echo,
    to_stdout,
    units_comment_option,
)
from pkmcal.errors import PkmcalError
from pkmcal.cli.option_types import SEED, FiniteFloat
from pkmcal.workflow.plan import format_indices, measurability
from pkmcal.workflow.vocabulary import (
    ASSUMED_JOINT_ERROR_MM,
    BUILTIN_SETUPS,
    CLEARANCE_MARGIN_MM,
    INDEX_DESCRIPTIONS,
    INDEX_NAMES,
    PLAN_ALGORITHMS,
    PLAN_FORMATS,
)

_SETUP_HELP = f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)})."


@click.command("plan", epilog=examples(
    "pkmcal plan stewart-prototype --setup indicators-prototype --n-poses 45 --seed 1 -o poses.csv",
    "pkmcal plan stewart-prototype --setup full-pose-paper1 --n-poses 20 --algorithm cuckoo --n-candidates 500 -o cuckoo.csv",
    "pkmcal plan stewart-prototype --setup indicators-prototype --n-poses 50 --algorithm random --seed 9 -o heldout.csv",
    "pkmcal plan stewart-prototype --setup indicators-prototype --n-poses 30 --tilt-margin 5 -o cautious.csv",
    "pkmcal plan planar-3dof-4act --setup planar-tracker --n-poses 12 -o planar-poses.csv",
    "pkmcal plan stewart-prototype --setup full-pose-paper1 --n-poses 30 --n-candidates 20000 --workers 2 -o large.csv",
    "pkmcal plan stewart-prototype --setup examples/setup-ballbar.yaml --algorithm circle --n-poses 36 -o circle.csv",
    "pkmcal plan kossel-mini --setup z-probe-klipper --n-poses 20 --target-accuracy 0.003 -o probe-points.csv",
    "pkmcal plan kossel-mini --setup z-probe-klipper --n-poses 20 --format klipper -o probe-plan.cfg",
    "pkmcal plan kossel-mini --setup z-probe-klipper --n-poses 20 --format gcode -o probe-plan.gcode",
    "pkmcal plan stewart-prototype --setup full-pose-paper1 --pattern iso9283 -o iso9283.csv"))
@click.argument("machine")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml", help=_SETUP_HELP)
@option("--n-poses", "n_poses", old=("--n",), type=click.IntRange(min=1), default=30, show_default=True,
        help="Number of poses to choose.")
@click.option("--candidates", "candidates_path", metavar="FILE.csv", type=click.Path(dir_okay=False),
              help="Candidate poses: columns x,y,z (mm), a,b,c (deg). Default: random poses in the workspace box.")
@click.option("--n-candidates", type=click.IntRange(min=1), default=2000, show_default=True,
              help="Number of random candidates (reachable and measurable) when no --candidates file.")
@click.option("--grid", type=click.IntRange(min=2, max=8), metavar="K",
              help="Instead of random candidates: a K^6 grid of the workspace box (checked like the others).")
@click.option("--index", type=click.Choice(INDEX_NAMES, case_sensitive=False), default=None,
              help="Index to maximise: detmax and cuckoo (default O4); the default algorithm maximises O1, "
                   "then polishes the set on this index if given.")
@click.option("--algorithm", type=click.Choice(PLAN_ALGORITHMS, case_sensitive=False), default="default", show_default=True,
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
@click.option("--pattern", type=click.Choice(("iso9283",)), default=None,
              help="Instead of a selection: the ISO 9283 test pattern, P1..P5 on the diagonal plane of the largest "
                   "cube that passes the checks, visited in --cycles cycles; 'pkmcal verify' reports ISO 9283 "
                   "AP/RP/AD/RD on held-out data in this pattern.")
@click.option("--cycles", type=click.IntRange(min=1), default=None, metavar="N",
              help="--pattern iso9283: how many cycles of P1..P5 (ISO 9283 §7.2.1: 30).  [default: 30]")
@backend_options("in this process")
@output_option("POSES.csv", "CSV of the chosen poses (or the --format klipper/gcode file)")
@units_comment_option
@quiet_option
@click.option("--json", "as_json", is_flag=True,
              help="Print the summary as one JSON object on standard output instead of text: candidates (accepted, "
                   "tested, rejected by reason), safety_margin, identifiable parameters and gauge, the selection and "
                   "its indices O1..O5; a Z probe's predicted first-layer error (mm). The poses then need -o FILE.")
@import_options
def plan_cmd(machine, setup_spec, n_poses, candidates_path, n_candidates, grid, index, algorithm, circle_plane, seed,
             stroke_margin, tilt_margin, clearance_margin, margin, indicator_travel, plate_radius, sight_cone,
             workers, dask_address, output, units_comment=False, quiet=False, mapping=None, probe_anywhere=False,
             fmt="csv", target_accuracy=None, pattern=None, as_json=False, cycles=None) -> None:
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
    from pkmcal.progress import ProgressBar
    from pkmcal.workflow.plan import iso9283_plan, plan_inputs, plan_of

    check_backend(workers, dask_address)
    check_output(output, [candidates_path, setup_spec, machine])
    if as_json and to_stdout(output):
        raise PkmcalError("--json prints the summary on standard output, where the poses would go too: write the "
                          "poses with -o FILE, or leave out --json")
    mech, setup, safety = plan_inputs(machine, setup_spec, probe_anywhere=probe_anywhere,
                                      target_accuracy=target_accuracy, fmt=fmt, units_comment=units_comment,
                                      stroke_margin=stroke_margin, tilt_margin=tilt_margin,
                                      clearance_margin=clearance_margin, margin=margin)
    if pattern is None and cycles is not None:
        raise PkmcalError("--cycles counts the cycles of --pattern iso9283; a selection's size is --n-poses")
    if pattern is not None:
        if click.get_current_context().get_parameter_source("n_poses") is not click.core.ParameterSource.DEFAULT:
            if cycles is not None:
                raise PkmcalError(f"--pattern iso9283 visits P1..P5 in --cycles {cycles}; leave out --n-poses (a "
                                  "selection's size)")
            deprecated(f"--n-poses {n_poses} (or --n) with --pattern iso9283", f"--cycles {n_poses}")
            cycles = n_poses
        for name, value in {"--candidates": candidates_path, "--grid": grid, "--index": index,
                            "--algorithm": None if algorithm == "default" else algorithm,
                            "--format": None if fmt == "csv" else fmt, "--target-accuracy": target_accuracy}.items():
            if value is not None:
                raise PkmcalError(f"{name} chooses among candidates; --pattern iso9283 writes the standard's pattern: "
                                  f"remove {name}")
        pat = iso9283_plan(mech, setup, cycles, margin=safety,
                           measurability=measurability(indicator_travel, plate_radius, sight_cone))
        _emit_pattern(pat, output, units_comment,
                      f"pkmcal plan {mech.name} --setup {setup_spec} --pattern {pattern} --cycles {pat.pattern.cycles}",
                      as_json)
        return
    planned = plan_of(mech, setup, n_poses, algorithm=algorithm, index=index, candidates=candidates_path,
                      mapping=mapping, n_candidates=n_candidates, grid=grid, seed=seed, margin=safety,
                      measurability=measurability(indicator_travel, plate_radius, sight_cone),
                      circle_plane=circle_plane, probe_anywhere=probe_anywhere, workers=workers,
                      dask_address=dask_address, progress=lambda: ProgressBar("plan", quiet=quiet))
    command = (f"pkmcal plan {mech.name} --setup {setup_spec} --n-poses {n_poses} "
               f"--algorithm {planned.selection.algorithm} --seed {seed}")
    if fmt != "csv":
        emit(planned.printer_file(fmt, command, machine, setup_spec), output)
    else:
        emit(planned.csv(command, units_comment), output)
    summary = planned.summary(target_accuracy)
    if as_json:
        click.echo(json.dumps({**summary, "output": output}, indent=2, allow_nan=False))
        return
    say = summary_echo(output)
    for line in plan_summary_lines(summary):
        say(line)
    if output is not None and output != "-":
        say(f"wrote {output}")


def plan_summary_lines(summary: dict) -> list[str]:
    """The text of a plan's summary (:meth:`pkmcal.workflow.plan.PosePlan.summary`)."""
    sel = summary["selection"]
    lines = [f"candidates: {summary['candidates']['text']}", f"safety margin: {summary['safety_margin']}",
             *(f"note: {note}" for note in summary["notes"]),
             f"identifiable parameters: {summary['identifiable_parameters']} ({summary['method']}; gauge fixed: "
             f"{', '.join(summary['gauge_fixed']) or 'none'})",
             f"{sel['algorithm']}: {sel['n_poses']} poses, maximised {sel['criterion']}; {sel['message']}",
             format_indices({k: float("nan") if v is None else v for k, v in summary["indices"].items()})]
    if "probe" in summary:
        lines += _probe_lines(summary["probe"], summary["identifiable_parameters"], summary["candidates"]["accepted"])
    return lines


def _emit_pattern(pat, output, units_comment: bool, command: str, as_json: bool = False) -> None:
    """``plan --pattern iso9283``: the pattern's CSV (:meth:`pkmcal.workflow.plan.PatternPlan.csv`)
    and its summary (``--json``: ``pattern``, ``centre_mm``, ``side_mm``, ``cycles``, ``n_poses``,
    ``notes``, ``output``)."""
    emit(pat.csv(command, units_comment), output)
    if as_json:
        click.echo(json.dumps({**pat.summary(), "output": output}, indent=2, allow_nan=False))
        return
    say = summary_echo(output)
    say(f"ISO 9283 pattern: cube centre {pat.centre_text} mm, side {pat.pattern.side:.6g} mm (the largest whose 3x3x3 "
        f"grid and P1..P5 pass the limits with the safety margins and the setup's measurability); P1..P5 x "
        f"{pat.pattern.cycles} cycles = {pat.n_poses} poses")
    for n in pat.pattern.notes:
        say(f"note: {n}")
    if output is not None and output != "-":
        say(f"wrote {output}")


def _probe_lines(facts: dict, n_params: int, n_candidates: int) -> list[str]:
    """What an on-bed Z-probe plan prints (:meth:`pkmcal.workflow.plan.PosePlan.probe_facts`)."""
    x, y, z = facts["offset_mm"]
    rep = "not stated" if facts["repeatability_mm"] is None else f"{facts['repeatability_mm']:g} mm"
    n = facts["points"]
    lines = [f"probe: on the bed, each point where the probe triggers (probe offset x {x:g}, y {y:g}, z {z:g} mm: the "
             f"nozzle {z:g} mm above the bed, the probe point {x:g}, {y:g} mm beside it and inside the build "
             f"radius); repeatability sigma {rep} (the setup's noise.reading: give your PROBE_ACCURACY standard "
             "deviation)"]
    curve = facts["first_layer_sigma_mm"]
    if not curve:
        lines.append(f"predicted first-layer error: none ({n} points give fewer readings than the {n_params} "
                     "identifiable parameters)")
    else:
        lines.append("predicted first-layer error (rms sigma of the height over the reachable bed, from the "
                     "identifiability of the points and the setup's noise): "
                     + ", ".join(f"{k} points {s:.3g} mm" + (" (this plan)" if k == n else "") for k, s in curve))
    if "target" in facts:
        t = facts["target"]
        if t["points"] is None:
            reached = float("nan") if t["reached_sigma_mm"] is None else t["reached_sigma_mm"]
            lines.append(f"target first-layer sigma {t['sigma_mm']:g} mm: not reached with all {n_candidates} "
                         f"candidates ({reached:.3g} mm); probe each point several times (PROBE SAMPLES=...) or "
                         "use a more repeatable probe")
        else:
            lines.append(f"target first-layer sigma {t['sigma_mm']:g} mm: {t['points']} points "
                         f"({t['reached_sigma_mm']:.3g} mm); plan them with --n-poses {t['points']}")
    return lines + facts["undetermined"]


@click.command("observability", epilog=examples(
    "pkmcal observability stewart-prototype --setup indicators-prototype --poses poses.csv",
    "pkmcal observability stewart-prototype --setup indicators-prototype --poses poses.csv --json"))
@click.argument("machine")
@click.argument("poses_arg", required=False, cls=DeprecatedArgument)
@click.option("--poses", metavar="POSES.csv", help="The pose set: columns x,y,z (mm), a,b,c (deg).")
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml", help=_SETUP_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (keys O1..O5, n_poses).")
@import_options
@quiet_accepted
def observability_cmd(machine, poses_arg, poses, setup_spec, as_json, mapping=None) -> None:
    """Observability indices O1..O5 of the poses in POSES.csv (columns x,y,z mm, a,b,c deg).

    On the scaled, noise-weighted identification Jacobian restricted to the identifiable
    parameters (as 'pkmcal plan'). O1 is D-optimality, O4 the noise amplification index.
    (The former spelling 'observability MACHINE POSES.csv' still works.)
    """
    from pkmcal.workflow.plan import observability_of

    poses = poses_file(poses, poses_arg, "observability")
    found = observability_of(machine, setup_spec, poses, mapping=mapping)
    ind, notes = found.indices, found.notes
    if as_json:
        click.echo(json.dumps({**ind, "n_poses": int(len(found.poses)), "warnings": notes,
                               "units": {**{k: "1" for k in INDEX_NAMES}, "n_poses": "1"}}))
        return
    click.echo(f"{len(found.poses)} poses")
    for k in INDEX_NAMES:
        click.echo(f"{k} = {ind[k]:.6g}   {INDEX_DESCRIPTIONS[k]}")
    for n in notes:
        click.echo(f"warning: {n}")

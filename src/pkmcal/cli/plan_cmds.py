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
    from pkmcal.io.lookup import load_machine
    from pkmcal.io.lookup import load_setup
    from pkmcal.planning.executors import chunk_map
    from pkmcal.planning.margins import has_margins, resolve_margin
    from pkmcal.planning.plan import plan_poses
    from pkmcal.progress import ProgressBar

    from pkmcal.study.printed import probes_the_bed

    check_backend(workers, dask_address)
    check_output(output, [candidates_path, setup_spec, machine])
    if as_json and to_stdout(output):
        raise PkmcalError("--json prints the summary on standard output, where the poses would go too: write the "
                          "poses with -o FILE, or leave out --json")
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
    if pattern is None and cycles is not None:
        raise PkmcalError("--cycles counts the cycles of --pattern iso9283; a selection's size is --n-poses")
    if pattern is not None:
        from pkmcal.identification.iso9283 import CYCLES

        if click.get_current_context().get_parameter_source("n_poses") is not click.core.ParameterSource.DEFAULT:
            if cycles is not None:
                raise PkmcalError(f"--pattern iso9283 visits P1..P5 in --cycles {cycles}; leave out --n-poses (a "
                                  "selection's size)")
            deprecated(f"--n-poses {n_poses} (or --n) with --pattern iso9283", f"--cycles {n_poses}")
            cycles = n_poses
        cycles = CYCLES if cycles is None else cycles
        _emit_pattern(mech, setup, cycles, safety, _measurability(indicator_travel, plate_radius, sight_cone), output,
                      units_comment, f"pkmcal plan {mech.name} --setup {setup_spec} --pattern {pattern} --cycles {cycles}",
                      {"--candidates": candidates_path, "--grid": grid, "--index": index,
                       "--algorithm": None if algorithm == "default" else algorithm,
                       "--format": None if fmt == "csv" else fmt, "--target-accuracy": target_accuracy}, as_json)
        return
    candidates = read_candidates_csv(candidates_path, mech, mapping) if candidates_path else None
    with chunk_map(workers, dask_address) as run_chunks, ProgressBar("plan", quiet=quiet) as bar:
        plan = plan_poses(mech, setup, n_poses, algorithm=algorithm, index=index.upper() if index else None,
                          candidates=candidates, n_candidates=n_candidates, grid=grid, seed=seed, margin=safety,
                          measurability=_measurability(indicator_travel, plate_radius, sight_cone),
                          progress=bar.stage, circle_plane=circle_plane, chunk_map=run_chunks,
                          on_bed=False if probe_anywhere else None)
    command = (f"pkmcal plan {mech.name} --setup {setup_spec} --n-poses {n_poses} --algorithm {plan.selection.algorithm} "
               f"--seed {seed}")
    if fmt != "csv":
        emit(_printer_file(fmt, plan, setup, command, machine, setup_spec), output)
    else:
        _emit_csv(plan, mech, command, output, units_comment)
    summary = plan_summary(plan, setup, target_accuracy)
    if as_json:
        click.echo(json.dumps({**summary, "output": output}, indent=2, allow_nan=False))
        return
    say = summary_echo(output)
    for line in plan_summary_lines(summary):
        say(line)
    if output is not None and output != "-":
        say(f"wrote {output}")


def plan_summary(plan, setup, target: float | None) -> dict:
    """What ``pkmcal plan`` prints, as a JSON-ready dict (:func:`plan_summary_lines` is its
    text): the candidates, the safety margin, the identifiable parameters, the selection and
    its indices; for a Z probe on the bed, ``probe`` (:func:`_probe_facts`)."""
    cand, sel, model = plan.candidates, plan.selection, plan.model
    out = {"candidates": {"accepted": int(len(cand.poses)), "tested": int(cand.n_tested), "kind": cand.kind,
                          "rejected": {k: int(v) for k, v in sorted(cand.rejected.items())},
                          "text": cand.describe()},
           "safety_margin": plan.describe_margin(), "notes": list(plan.notes),
           "identifiable_parameters": int(model.n_params), "method": model.method,
           "gauge_fixed": list(model.report.fixed),
           "selection": {"algorithm": sel.algorithm, "n_poses": int(len(sel.chosen)), "criterion": sel.criterion,
                         "message": sel.message},
           "indices": {k: _number(v) for k, v in sel.indices.items()}}
    if plan.on_bed:
        out["probe"] = _probe_facts(plan, setup, target)
    return out


def _number(v) -> float | None:
    """A float for JSON: None where not finite (an index of a degenerate pose set)."""
    return float(v) if np.isfinite(v) else None


def plan_summary_lines(summary: dict) -> list[str]:
    """The text of :func:`plan_summary`."""
    sel = summary["selection"]
    lines = [f"candidates: {summary['candidates']['text']}", f"safety margin: {summary['safety_margin']}",
             *(f"note: {note}" for note in summary["notes"]),
             f"identifiable parameters: {summary['identifiable_parameters']} ({summary['method']}; gauge fixed: "
             f"{', '.join(summary['gauge_fixed']) or 'none'})",
             f"{sel['algorithm']}: {sel['n_poses']} poses, maximised {sel['criterion']}; {sel['message']}",
             _format_indices({k: float("nan") if v is None else v for k, v in summary["indices"].items()})]
    if "probe" in summary:
        lines += _probe_lines(summary["probe"], summary["identifiable_parameters"], summary["candidates"]["accepted"])
    return lines


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


def _emit_pattern(mech, setup, cycles: int, safety, measurability, output, units_comment: bool, command: str,
                  unused: dict, as_json: bool = False) -> None:
    """``plan --pattern iso9283``: the pattern of :func:`~pkmcal.identification.iso9283.iso9283_pattern`
    as a CSV (poses, nominal commands, ``iso_pose`` 1..5, ``cycle``) and its summary (``--json``:
    ``pattern``, ``centre_mm``, ``side_mm``, ``cycles``, ``n_poses``, ``notes``, ``output``)."""
    from pkmcal.identification.iso9283 import iso9283_pattern

    for name, value in unused.items():
        if value is not None:
            raise PkmcalError(f"{name} chooses among candidates; --pattern iso9283 writes the standard's pattern: "
                              f"remove {name}")
    pat = iso9283_pattern(mech, setup, cycles=cycles, margin=safety, measurability=measurability)
    poses, label, cycle = pat.cycle_poses()
    cols = {name: to_file_units(poses, mech.pose_is_angle)[:, i] for i, name in enumerate(mech.pose_names)}
    commands = to_file_units(mech.ik(poses), mech.actuator_is_angle)
    cols.update({name: commands[:, i] for i, name in enumerate(mech.actuator_names)})
    cols.update({"iso_pose": label, "cycle": cycle})
    c = ", ".join(f"{v:.6g}" for v in pat.center)
    emit(format_table(cols, units_comment=units_comment, comments=[
        command, f"ISO 9283 cube: centre {c} mm, side {pat.side:.6g} mm; P1..P5 on its diagonal plane C1-C2-C7-C8, "
        f"{pat.cycles} cycles", *(f"note: {n}" for n in pat.notes)]), output)
    if as_json:
        click.echo(json.dumps({"pattern": "iso9283", "centre_mm": [float(v) for v in pat.center],
                               "side_mm": float(pat.side), "cycles": int(pat.cycles), "n_poses": int(len(poses)),
                               "notes": list(pat.notes), "output": output}, indent=2, allow_nan=False))
        return
    say = summary_echo(output)
    say(f"ISO 9283 pattern: cube centre {c} mm, side {pat.side:.6g} mm (the largest whose 3x3x3 grid and P1..P5 pass "
        f"the limits with the safety margins and the setup's measurability); P1..P5 x {pat.cycles} cycles = "
        f"{len(poses)} poses")
    for n in pat.notes:
        say(f"note: {n}")
    if output is not None and output != "-":
        say(f"wrote {output}")


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


def _probe_facts(plan, setup, target: float | None) -> dict:
    """An on-bed Z-probe plan's facts: the probe offset (mm) and repeatability (the setup's
    noise.reading, mm, or None), the predicted first-layer error for other numbers of points
    (:func:`pkmcal.planning.plan.height_sigma`: ``first_layer_sigma_mm``, ``[points, mm]``), the
    points for ``target`` (``target``: ``{"sigma_mm", "points"`` (None when not reached),
    ``"reached_sigma_mm"}``), and what heights cannot see and what would see it
    (``undetermined``: the sentences of
    :func:`~pkmcal.identification.identifiability.undetermined_directions`, the named directions
    and the rail leans, as ``identify`` says them)."""
    from pkmcal.identification.identifiability import undetermined_directions
    from pkmcal.planning.plan import height_sigma, points_for_height_sigma

    noise = setup.noise.reading_std
    n = len(plan.poses)
    ladder = sorted({k for k in (n // 2, n, 2 * n, 4 * n) if plan.model.n_params <= k <= len(plan.candidates.poses)}
                    | {n})
    curve = [(k, s) for k, s in height_sigma(plan, ladder) if np.isfinite(s)]
    facts: dict = {"offset_mm": [float(v) for v in np.asarray(setup.sensor.probe_offset, dtype=float)],
                   "repeatability_mm": float(noise[0]) if noise is not None and np.size(noise) else None,
                   "points": n, "first_layer_sigma_mm": [[int(k), float(s)] for k, s in curve]}
    if target is not None:
        need, tried = points_for_height_sigma(plan, target)
        facts["target"] = {"sigma_mm": float(target), "points": None if need is None else int(need),
                           "reached_sigma_mm": _number(tried[-1][1] if need is None else dict(tried)[need])}
    facts["undetermined"] = [entry["text"] for entry in
                             undetermined_directions(plan.model.mechanism, setup, plan.poses)] if curve else []
    return facts


def _probe_lines(facts: dict, n_params: int, n_candidates: int) -> list[str]:
    """What an on-bed Z-probe plan prints (:func:`_probe_facts`)."""
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

"""``pkmcal info [MACHINE]``: what a machine is, where it can go, and whether its IK and FK agree.

The values are :func:`pkmcal.workflow.machine_info.machine_info`'s (its module docstring says
how each is found): the machine summary, the single-axis workspace from home, the box
occupancy and the IK→FK round trip. This module prints them as text (:func:`info_lines`) or
as one JSON object (``--json``).
"""

from __future__ import annotations

import json

import click

from pkmcal.cli.options import count_or_poses_file, examples, quiet_accepted
from pkmcal.cli.option_types import SEED
from pkmcal.errors import PkmcalError
from pkmcal.workflow.machine_info import N_ROUND_TRIP, machine_info, round_trip_stats
from pkmcal.workflow.vocabulary import DEFAULT_MACHINE


@click.command("info", epilog=examples(
    "pkmcal info",
    "pkmcal info stewart-prototype-real --n-poses 1000 --seed 2",
    "pkmcal info planar-3dof-4act",
    "pkmcal info stewart-prototype --poses poses.csv",
    "pkmcal info kossel-mini --n-poses 50 --json"))
@click.argument("machine", default=DEFAULT_MACHINE, required=False)
@click.option("--n-poses", type=click.IntRange(1, 100_000), default=None,
              help=f"Random reachable poses for the IK→FK round trip.  [default: {N_ROUND_TRIP}]")
@click.option("--poses", metavar="POSES.csv",
              help="Instead: the round trip on the poses of this file (x,y,z mm, a,b,c deg).")
@click.option("--seed", default=0, show_default=True, type=SEED, help="Seed of the random poses.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object instead of text: summary (its lines), parameters (names by unit), notes, "
                   "workspace (per pose coordinate min/max in mm or deg and the limits that stop them; the box's "
                   "reachable fraction), round_trip (counts; max errors in mm and deg).")
@quiet_accepted
def info_cmd(machine: str, n_poses: int | None, poses: str | None, seed: int, as_json: bool = False) -> None:
    """Describe MACHINE (default: stewart-prototype): summary, workspace, IK→FK round trip."""
    from pkmcal.io.lookup import load_machine

    n_poses, poses_path = count_or_poses_file(poses, n_poses, N_ROUND_TRIP)
    if n_poses > 100_000:
        raise PkmcalError(f"--n-poses {n_poses}: at most 100000")
    mech = load_machine(machine)
    data = machine_info(mech, n_poses, poses_path, seed)
    if as_json:
        click.echo(json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False))
    else:
        for line in info_lines(data):
            click.echo(line)


def info_lines(data: dict) -> list[str]:
    """The text of ``pkmcal info`` from :func:`~pkmcal.workflow.machine_info.machine_info`'s dict."""
    import textwrap

    lines = list(data["summary"])
    by_unit = data["parameters"]
    lines.append(f"parameters ({sum(map(len, by_unit.values()))}; the names --free, --fix, --prior and study error "
                 "groups use):")
    for label, names in by_unit.items():
        lines += textwrap.wrap(", ".join(names), width=100, initial_indent=f"  {label}: ",
                               subsequent_indent="    ", break_on_hyphens=False)
    lines += [f"note: {note}" for note in data["notes"]]
    if "home_violates" in data:
        lines.append(f"home pose violates the limits ({data['home_violates']}): no workspace around it to report")
        return lines
    ws = data["workspace"]
    lines.append(f"workspace, single-axis ranges from home (each coordinate moved alone, the others at home; "
                 f"{ws['grid_points']}-point grid, ends refined by bisection to {ws['bisection_tolerance']:g} mm or "
                 "rad):")
    for name, r in ws["ranges"].items():
        lines.append(f"  {name}  {r['min']:9.3f} .. {r['max']:9.3f} {r['unit']:<3}"
                     f"  (stopped by {r['stopped_by'][0]} / {r['stopped_by'][1]})")
    if "declared_box" in ws:
        text = ", ".join(f"{n} [{f'{lo:9.3f}'.strip()}, {f'{hi:9.3f}'.strip()}]"
                         for n, (lo, hi) in ws["declared_box"].items())
        lines.append(f"  declared workspace box: {text}")
    other = ws["box_other_mode_fraction"]
    lines.append(f"  {100.0 * ws['box_reachable_fraction']:.1f} % of {ws['box_samples']} uniform random poses in the "
                 "box of these ranges are reachable"
                 + (f" ({100.0 * other:.1f} % on another assembly mode than home)" if other else ""))
    rt = data["round_trip"]
    if rt["n"] == 0:
        lines.append("IK→FK round trip: no reachable random pose found")
        return lines
    return lines + round_trip_text(rt)


def round_trip_lines(mech, poses, result, what: str | None = None) -> list[str]:
    """The round-trip report (item 4 of :mod:`pkmcal.workflow.machine_info`) as text
    (:func:`~pkmcal.workflow.machine_info.round_trip_stats`)."""
    return round_trip_text(round_trip_stats(mech, poses, result, what))


def round_trip_text(rt: dict) -> list[str]:
    """The lines of :func:`~pkmcal.workflow.machine_info.round_trip_stats`'s dict."""
    n = rt["n"]
    lines = [f"IK→FK round trip on {rt['poses']} (FK from home):",
             f"  converged {rt['converged']}/{n}; Newton iterations mean {rt['iterations_mean']:.2f}, max "
             f"{rt['iterations_max']}"]
    if rt["returned"]:
        text = (f"  returned the pose they came from: {rt['returned']}/{n}; max position error "
                f"{rt['max_position_error_mm']:.3g} mm")
        if rt["max_orientation_error_deg"] is not None:
            text += f", max orientation error {rt['max_orientation_error_deg']:.3g} deg"
        lines.append(text)
    else:
        lines.append(f"  returned the pose they came from: 0/{n}")
    if rt["other_mode"]:
        lines.append(f"  NOT round trips: {rt['other_mode']} converged on another assembly mode than the pose they "
                     f"came from (max position error {rt['other_mode_max_position_error_mm']:.3g} mm)")
    if rt["other_pose"]:
        lines.append(f"  NOT round trips: {rt['other_pose']} converged to another pose of the same assembly mode "
                     f"(max position error {rt['other_pose_max_position_error_mm']:.3g} mm)")
    if rt["not_converged"]:
        lines.append(f"  NOT round trips: {rt['not_converged']} did not converge")
    if rt["off_home_mode"]:
        lines.append(f"  {rt['off_home_mode']} of the {n} poses satisfy every limit but lie on another assembly "
                     "mode than home (sign det J differs: beyond a singularity): FK from home cannot return them, "
                     "and the machine cannot reach them from home without crossing a singularity")
    return lines


__all__ = ["info_cmd", "info_lines", "round_trip_lines", "round_trip_text"]

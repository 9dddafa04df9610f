"""``pkmcal plan`` and ``pkmcal observability``: which poses to measure, and how good a set is.

* ``plan``: candidate poses (random in the workspace box, or a CSV), checked against the
  nominal machine's limits with a safety margin and against the sensor's measurability,
  then a selection algorithm (:mod:`pkmcal.planning.selection`) picks N of them; writes
  x, y, z (mm), a, b, c (deg) and the nominal actuator commands lambda1..lambda6 (rotary
  actuators of other machines in degrees).
* ``observability``: the indices O1..O5 (:mod:`pkmcal.planning.indices`) of a pose set,
  on the same identifiable parameters and column scaling as ``plan``.
"""

from __future__ import annotations

import json
import sys
import time

import click
import numpy as np

from pkmcal.cli.import_options import import_options
from pkmcal.cli.option_types import SEED, FiniteFloat
from pkmcal.io.atomic import check_output_path
from pkmcal.io.tables import to_file_units, write_table
from pkmcal.planning.candidates import DEFAULT_MARGIN, Measurability, read_candidates_csv
from pkmcal.planning.indices import INDEX_DESCRIPTIONS, INDEX_NAMES
from pkmcal.planning.selection import ALGORITHMS
from pkmcal.sensors.library import BUILTIN_SETUPS

_SETUP_HELP = f"Measurement setup file or built-in ({', '.join(BUILTIN_SETUPS)})."


class _Progress:
    """A one-line progress display on stderr, only on a terminal and after 2 s."""

    def __init__(self, label: str, delay: float = 2.0):
        self.label, self.delay = label, delay
        self.t0 = time.monotonic()
        self.shown = False
        self.tty = sys.stderr.isatty()

    def __call__(self, done: int, total: int) -> None:
        if not self.tty or time.monotonic() - self.t0 < self.delay:
            return
        self.shown = True
        click.echo(f"\r{self.label}: step {done} (at most {total}), {time.monotonic() - self.t0:.1f} s",
                   err=True, nl=False)

    def close(self) -> None:
        if self.shown:
            click.echo("", err=True)


def _measurability(travel, plate_radius, sight_cone) -> Measurability:
    return Measurability(travel=None if travel is None else (float(travel[0]), float(travel[1])),
                         plate_radius=plate_radius,
                         sight_cone=None if sight_cone is None else float(np.deg2rad(sight_cone)))


def _format_indices(ind: dict[str, float]) -> str:
    return "  ".join(f"{k} = {ind[k]:.6g}" for k in INDEX_NAMES)


@click.command("plan")
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
                   "corners: random corners of the workspace box (paper 1); random.")
@click.option("--seed", type=SEED, default=0, show_default=True, help="Random seed (same seed, same poses).")
@click.option("--margin", type=FiniteFloat(min=0.0), default=DEFAULT_MARGIN, show_default=True,
              help="Safety margin on every limit: mm (stroke, collision) and degrees (joint tilts).")
@click.option("--indicator-travel", nargs=2, type=FiniteFloat(), metavar="LO HI",
              help="Indicators: accepted reading range (mm).")
@click.option("--plate-radius", type=FiniteFloat(min=0.0), metavar="MM",
              help="Indicators: the touch points must lie within this radius of the platform origin.")
@click.option("--sight-cone", type=FiniteFloat(min=0.0, max=180.0), metavar="DEG",
              help="Full-pose/position: half-angle of the target's line-of-sight cone.")
@click.option("-o", "--output", required=True, metavar="POSES.csv", help="Output CSV of the chosen poses.")
@import_options
def plan_cmd(machine, setup_spec, n_poses, candidates_path, n_candidates, grid, index, algorithm, seed, margin,
             indicator_travel, plate_radius, sight_cone, output, mapping=None) -> None:
    """Choose N poses of MACHINE to measure with SETUP (paper 2 §4, paper 1 §IV).

    Every candidate is checked on the nominal machine (stroke, joint tilts, leg collision,
    singularity, with --margin) and for measurability; rejections are counted by reason.
    Writes x,y,z,a,b,c and the nominal commands lambda1..; prints O1..O5 of the chosen set.
    """
    from pkmcal.io.machine_file import load_machine
    from pkmcal.io.setup_file import load_setup
    from pkmcal.planning.plan import plan_poses

    mech = load_machine(machine)
    setup = load_setup(setup_spec, mech)
    check_output_path(output, [candidates_path, setup_spec, machine])
    candidates = read_candidates_csv(candidates_path, mech, mapping) if candidates_path else None
    progress = _Progress(f"plan ({algorithm})")
    try:
        plan = plan_poses(mech, setup, n_poses, algorithm=algorithm, index=index.upper() if index else None,
                          candidates=candidates, n_candidates=n_candidates, grid=grid, seed=seed, margin=margin,
                          measurability=_measurability(indicator_travel, plate_radius, sight_cone),
                          progress=progress)
    finally:
        progress.close()
    poses = to_file_units(plan.poses, mech.pose_is_angle)
    commands = to_file_units(plan.commands, mech.actuator_is_angle)
    cols = {name: poses[:, i] for i, name in enumerate(mech.pose_names)}
    cols.update({name: commands[:, i] for i, name in enumerate(mech.actuator_names)})
    sel = plan.selection
    write_table(output, cols, comments=[
        f"pkmcal plan {mech.name} --setup {setup_spec} --n {n_poses} --algorithm {sel.algorithm} "
        f"--seed {seed}; maximised {sel.criterion}",
        _format_indices(sel.indices)])
    click.echo(f"candidates: {plan.candidates.describe()}")
    click.echo(f"identifiable parameters: {plan.model.n_params} ({plan.model.method}; gauge fixed: "
               f"{', '.join(plan.model.report.fixed) or 'none'})")
    click.echo(f"{sel.algorithm}: {len(sel.chosen)} poses, maximised {sel.criterion}; {sel.message}")
    click.echo(_format_indices(sel.indices))
    click.echo(f"wrote {output}")


@click.command("observability")
@click.argument("machine")
@click.argument("poses", metavar="POSES.csv", type=click.Path(dir_okay=False))
@click.option("--setup", "setup_spec", required=True, metavar="SETUP.yaml", help=_SETUP_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (keys O1..O5, n_poses).")
@import_options
def observability_cmd(machine, poses, setup_spec, as_json, mapping=None) -> None:
    """Observability indices O1..O5 of the poses in POSES.csv (columns x,y,z mm, a,b,c deg).

    On the scaled, noise-weighted identification Jacobian restricted to the identifiable
    parameters (as 'pkmcal plan'). O1 is D-optimality, O4 the noise amplification index.
    """
    from pkmcal.io.machine_file import load_machine
    from pkmcal.io.setup_file import load_setup
    from pkmcal.planning.plan import pose_set_indices

    mech = load_machine(machine)
    setup = load_setup(setup_spec, mech)
    pose_arr = read_candidates_csv(poses, mech, mapping)
    ind = pose_set_indices(mech, setup, pose_arr)
    if as_json:
        click.echo(json.dumps({**ind, "n_poses": int(len(pose_arr))}))
        return
    click.echo(f"{len(pose_arr)} poses")
    for k in INDEX_NAMES:
        click.echo(f"{k} = {ind[k]:.6g}   {INDEX_DESCRIPTIONS[k]}")

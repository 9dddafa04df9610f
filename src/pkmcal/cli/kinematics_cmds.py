"""``pkmcal ik`` and ``pkmcal fk``: the kinematics of a machine over a CSV table of poses.

* ``ik``: poses (x, y, z mm; a, b, c deg) → leg lengths L_i = ‖p + R a_i − b_i‖, readings
  λ_i = L_i − L0_i (paper 2 eq. 1–2) and the limits each pose violates.
* ``fk``: readings λ_i (or lengths L_i) → poses by Newton–Raphson (see
  :meth:`pkmcal.mechanisms.hexapod.Hexapod.fk`), with per row a convergence flag, an
  assembly-mode flag (:attr:`pkmcal.mechanisms.base.FKResult.same_branch`) and the limits
  the pose violates (readings beyond the stroke among them).

Every input is validated and every result computed before the output is written
(atomically); on a user error nothing is written and the exit code is 2.
"""

from __future__ import annotations

import contextlib

import click
import numpy as np

from pkmcal.cli.import_options import import_options
from pkmcal.cli.options import (DeprecatedArgument, check_output, emit, examples, output_option, poses_file,
                                quiet_accepted, to_stdout, units_comment_option)
from pkmcal.io.atomic import atomic_writer
from pkmcal.io.tables import LENGTH_COLUMNS, column_kinds, format_table, read_table
from pkmcal.workflow.kinematics import fk_columns, ik_columns, parse_pose_option

_MAX_LISTED = 20
#: Poses computed and written at a time by ``pkmcal ik``.
_IK_BLOCK = 10_000


def _note(message: str) -> None:
    click.echo(f"pkmcal: {message}", err=True)


def _line_list(lines: np.ndarray) -> str:
    shown = ", ".join(str(int(n)) for n in lines[:_MAX_LISTED])
    return shown + (f" and {len(lines) - _MAX_LISTED} more" if len(lines) > _MAX_LISTED else "")


@click.command("ik", epilog=examples(
    "pkmcal ik stewart-prototype --poses poses.csv -o legs.csv",
    "pkmcal ik stewart-prototype --poses poses.csv",
    "pkmcal ik stewart-prototype-real --poses heldout.csv -o heldout-legs.csv"))
@click.argument("machine")
@click.argument("poses_arg", required=False, cls=DeprecatedArgument)
@click.option("--poses", metavar="POSES.csv", help="The poses: columns x,y,z (mm), a,b,c (deg).")
@output_option("LEGS.csv", "Output CSV")
@units_comment_option
@import_options
@quiet_accepted
def ik_cmd(machine: str, poses: str | None, output: str | None, units_comment: bool = False, mapping=None,
           poses_arg: str | None = None) -> None:
    """Inverse kinematics: leg lengths and readings of the poses in POSES.csv.

    MACHINE is a built-in name (see 'pkmcal machines') or a machine YAML file. POSES.csv has
    columns x,y,z (mm) and a,b,c (degrees); other columns are ignored. The output repeats
    x..c and adds l1..l6 (leg lengths, mm), lambda1..lambda6 (actuator readings, mm) and
    'reachable': 'ok' or the violated limits joined by '+'. (Other machines: their pose
    columns, their actuator columns; rotary actuators in degrees.) The former spelling
    'ik MACHINE POSES.csv' still works.
    """
    poses = poses_file(poses, poses_arg, "ik")
    check_output(output, [poses, machine])
    from pkmcal.io.lookup import load_machine

    mech = load_machine(machine)
    from pkmcal.io.orientation import small_angle_limit

    table = read_table(poses, mech.pose_names, kinds=column_kinds(mech.pose_names, mech.pose_is_angle),
                       mapping=mapping, small_angle_deg=small_angle_limit(mech))
    # Every pose is read and checked first; then IK, limits and the CSV text are made
    # _IK_BLOCK poses at a time and written as they come (to a temporary file that becomes
    # the output at the end), so memory stays bounded however many poses there are.
    n_bad = 0
    with (atomic_writer(output) if not to_stdout(output) else contextlib.nullcontext()) as fh:
        for start in range(0, len(table), _IK_BLOCK):
            file_poses = table.values[start:start + _IK_BLOCK]
            columns, violating = ik_columns(mech, file_poses)
            text = format_table(columns, head=start == 0, units_comment=units_comment,
                                comments=(f"pkmcal ik {mech.name} {poses}",))
            if fh is None:
                click.echo(text, nl=False)
            else:
                fh.write(text)
            n_bad += violating
    _note(f"ik: {len(table)} poses, {len(table) - n_bad} reachable"
          + (f"; {n_bad} violate limits (column 'reachable')" if n_bad else ""))


@click.command("fk", epilog=examples(
    "pkmcal fk stewart-prototype legs.csv -o fk-poses.csv",
    "pkmcal fk stewart-prototype-real legs.csv --guess 0,0,315,0,0,0"))
@click.argument("machine")
@click.argument("legs", metavar="LEGS.csv")
@output_option("POSES.csv", "Output CSV")
@click.option("--guess", metavar="X,Y,Z,A,B,C", help="Start pose of the Newton iteration (mm, deg); "
              "default: the machine's home pose.")
@units_comment_option
@import_options
@quiet_accepted
def fk_cmd(machine: str, legs: str, output: str | None, guess: str | None, units_comment: bool = False,
           mapping=None) -> None:
    """Forward kinematics: the poses that give the readings in LEGS.csv.

    LEGS.csv has columns lambda1..lambda6 (actuator readings, mm) or l1..l6 (leg lengths,
    mm); when both are present the readings are used. The output has x,y,z (mm), a,b,c
    (degrees) and per row:

    \b
    converged    1/0: the pose reproduces the readings
    iterations   Newton steps
    same_branch  1/0: converged on the assembly mode of the start pose (sign det J of
                 the pose Jacobian the same); 0 on a converged row means FK found the
                 mirror solution of another assembly mode, not where a machine that
                 started there is
    reachable    'ok', or the limits the pose violates ('stroke' for readings beyond
                 the stroke, ...); 'not-solved' where FK did not converge

    Rows that did not converge get 'nan' poses. Rows that did not converge, changed
    assembly mode or violate limits are listed on standard error by their line in
    LEGS.csv; the exit code is still 0 (check the columns).
    """
    check_output(output, [legs, machine])
    from pkmcal.io.lookup import load_machine

    mech = load_machine(machine)
    start = None if guess is None else parse_pose_option(guess, mech, "--guess")
    groups = [mech.actuator_names]
    if "leg-lengths" in mech.abilities:
        groups.append(LENGTH_COLUMNS[: mech.n_actuators])
    rotary = mech.actuator_is_angle
    kinds = column_kinds(mech.actuator_names, rotary)
    if len(groups) > 1:
        kinds.update({c: "length" for c in groups[1]})
    table = read_table(legs, either=groups, kinds=kinds, mapping=mapping)
    rows = fk_columns(mech, table.values, table.columns == tuple(mech.actuator_names), start)
    columns, conv, same, iters = rows.columns, rows.converged, rows.same_branch, rows.iterations
    text = format_table(columns, units_comment=units_comment, comments=(f"pkmcal fk {mech.name} {legs}",))
    emit(text, output)
    n = len(table)
    good = conv & same
    _note(f"fk: {n} rows, {int(good.sum())} converged on the start pose's assembly mode"
          + (f" (at most {int(iters[conv].max())} iterations)" if conv.any() else ""))
    if not conv.all():
        _note(f"fk: {int((~conv).sum())} rows did not converge (their poses are nan): lines "
              f"{_line_list(table.lines[~conv])} of {legs}; try --guess near the expected pose")
    changed = conv & ~same
    if changed.any():
        _note(f"fk: {int(changed.sum())} rows converged on another assembly mode than the start pose "
              f"(same_branch 0: a mirror solution, not where the machine is): lines "
              f"{_line_list(table.lines[changed])} of {legs}; give --guess on the machine's assembly mode")
    beyond = rows.violating
    if beyond.any():
        _note(f"fk: {int(beyond.sum())} rows violate the machine's limits (column 'reachable'): lines "
              f"{_line_list(table.lines[beyond])} of {legs}")


__all__ = ["fk_cmd", "ik_cmd"]

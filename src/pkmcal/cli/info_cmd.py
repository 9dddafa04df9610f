"""``pkmcal info [MACHINE]``: what a machine is, where it can go, and whether its IK and FK agree.

1. The machine summary (:meth:`Hexapod.summary`).
2. Single-axis workspace: from the home pose, each pose coordinate is moved alone (the others
   stay at home) over a grid of 1001 values; the reachable interval around home (every limit of
   ``check_limits`` satisfied) is then refined at both ends by bisection to 1e-6 mm/deg. This is
   the "travel range" of hexapod data sheets. The limit that stops each end is named.
3. Box occupancy: the fraction of uniform random poses in the box of those ranges that are
   reachable (the 6-D workspace is much smaller than the box).
4. IK→FK round trip on random reachable poses of that box: readings q = IK(x), then
   x̂ = FK(q) from the home pose; reported: converged fraction, Newton iterations, and
   max ‖p̂ − p‖ (mm) and max rotation angle of R̂ Rᵀ (rad) over converged poses.

Everything is vectorised over poses (one ``check_limits`` call per bisection step).
"""

from __future__ import annotations

import click
import numpy as np

from pkmcal.cli.option_types import SEED
from pkmcal.conventions import euler_to_matrix, rotation_error
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.library import DEFAULT_MACHINE

GRID_POINTS = 1001
BISECTION_TOL = 1e-6
BOX_SAMPLES = 10_000


def _half_widths(mech: Mechanism) -> np.ndarray:
    """Search half-width per pose coordinate: the largest reach of a leg for translations
    (mm), 180° for angles (90° for the pitch b of a 6-DoF Euler pose)."""
    reach = 1000.0
    if hasattr(mech, "offset") and hasattr(mech, "stroke"):
        reach = float(np.max(np.asarray(mech.offset) + np.asarray(mech.stroke)[:, 1]))
        if hasattr(mech, "base"):
            reach += float(np.max(np.linalg.norm(np.asarray(mech.base), axis=1)))
    out = np.where(np.array(mech.pose_is_angle), np.pi, reach)
    if mech.pose_names == ("x", "y", "z", "a", "b", "c"):
        out[4] = np.pi / 2
    return out


def _reachable(mech: Mechanism, poses: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return mech.check_limits(poses).ok


def single_axis_ranges(mech: Mechanism, home: np.ndarray) -> tuple[np.ndarray, list[list[str]]]:
    """``(ranges, stops)``: (n, 2) reachable interval of each coordinate moved alone from
    ``home`` (internal units), and for each end the limits violated just beyond it
    (``["search bound"]`` when the grid edge is still reachable)."""
    n = mech.n_dof
    half = _half_widths(mech)
    steps = np.linspace(-1.0, 1.0, GRID_POINTS)
    centre = GRID_POINTS // 2
    grid = np.repeat(home[None, None, :], n * GRID_POINTS, axis=0).reshape(n, GRID_POINTS, n)
    for k in range(n):
        grid[k, :, k] = home[k] + steps * half[k]
    ok = _reachable(mech, grid.reshape(-1, n)).reshape(n, GRID_POINTS)
    inner = np.empty((n, 2))  # last reachable value on each side
    outer = np.full((n, 2), np.nan)  # first unreachable value beyond it
    for k in range(n):  # loop over the n coordinates, not over poses
        bad_hi = np.flatnonzero(~ok[k, centre:])
        bad_lo = np.flatnonzero(~ok[k, : centre + 1][::-1])
        hi = centre + (bad_hi[0] - 1 if len(bad_hi) else GRID_POINTS - 1 - centre)
        lo = centre - (bad_lo[0] - 1 if len(bad_lo) else centre)
        inner[k] = grid[k, lo, k], grid[k, hi, k]
        if len(bad_lo):
            outer[k, 0] = grid[k, lo - 1, k]
        if len(bad_hi):
            outer[k, 1] = grid[k, hi + 1, k]
    # Bisection on every end at once: inner stays reachable, outer stays unreachable.
    active = ~np.isnan(outer)
    a, b = inner.copy(), outer.copy()
    while np.any(active & (np.abs(b - a) > BISECTION_TOL)):
        mid = np.where(active, 0.5 * (a + b), a)
        poses = np.repeat(home[None, None, :], 2 * n, axis=0).reshape(n, 2, n)
        for k in range(n):
            poses[k, :, k] = mid[k]
        good = _reachable(mech, poses.reshape(-1, n)).reshape(n, 2)
        a = np.where(active & good, mid, a)
        b = np.where(active & ~good, mid, b)
    stops: list[list[str]] = []
    beyond = np.repeat(home[None, None, :], 2 * n, axis=0).reshape(n, 2, n)
    for k in range(n):
        beyond[k, :, k] = np.where(active[k], b[k], a[k])
    with np.errstate(all="ignore"):
        report = mech.check_limits(beyond.reshape(-1, n))
    for k in range(n):
        row = []
        for side in range(2):
            row.append("+".join(report.reasons(2 * k + side)) if active[k, side] else "search bound")
        stops.append(row)
    return a, stops


def _fmt(value: float, is_angle: bool) -> str:
    return f"{np.rad2deg(value):9.3f}" if is_angle else f"{value:9.3f}"


@click.command("info")
@click.argument("machine", default=DEFAULT_MACHINE, required=False)
@click.option("--poses", "n_poses", default=300, show_default=True, type=click.IntRange(1, 100_000),
              help="Random reachable poses for the IK→FK round trip.")
@click.option("--seed", default=0, show_default=True, type=SEED, help="Seed of the random poses.")
def info_cmd(machine: str, n_poses: int, seed: int) -> None:
    """Describe MACHINE (default: stewart-prototype): summary, workspace, IK→FK round trip."""
    from pkmcal.io.machine_file import load_machine

    mech = load_machine(machine)
    summary = mech.summary() if hasattr(mech, "summary") else mech.name
    click.echo(summary)
    home = np.asarray(mech.home_pose, dtype=float)
    angle = np.array(mech.pose_is_angle)
    unit = lambda k: "deg" if angle[k] else "mm"  # noqa: E731
    if not _reachable(mech, home[None])[0]:
        with np.errstate(all="ignore"):
            why = mech.check_limits(home[None]).verdicts()[0]
        click.echo(f"home pose violates the limits ({why}): no workspace around it to report")
        return
    ranges, stops = single_axis_ranges(mech, home)
    click.echo("workspace, single-axis ranges from home (each coordinate moved alone, the others at home; "
               f"{GRID_POINTS}-point grid, ends refined by bisection to {BISECTION_TOL:g} mm or rad):")
    for k, name in enumerate(mech.pose_names):
        click.echo(f"  {name}  {_fmt(ranges[k, 0], angle[k])} .. {_fmt(ranges[k, 1], angle[k])} {unit(k):<3}"
                   f"  (stopped by {stops[k][0]} / {stops[k][1]})")
    if getattr(mech, "workspace", None) is not None:
        ws = np.asarray(mech.workspace)
        text = ", ".join(f"{n} [{_fmt(ws[k, 0], angle[k]).strip()}, {_fmt(ws[k, 1], angle[k]).strip()}]"
                         for k, n in enumerate(mech.pose_names))
        click.echo(f"  declared workspace box: {text}")

    rng = np.random.default_rng(seed)
    box = rng.uniform(ranges[:, 0], ranges[:, 1], size=(BOX_SAMPLES, mech.n_dof))
    ok = _reachable(mech, box)
    click.echo(f"  {100.0 * ok.mean():.1f} % of {BOX_SAMPLES} uniform random poses in the box of these ranges "
               "are reachable")
    pool = box[ok]
    for _ in range(20):  # top up in batches (not per pose) when the box is sparsely reachable
        if len(pool) >= n_poses:
            break
        more = rng.uniform(ranges[:, 0], ranges[:, 1], size=(BOX_SAMPLES, mech.n_dof))
        pool = np.concatenate([pool, more[_reachable(mech, more)]])
    poses = pool[:n_poses]
    if len(poses) == 0:
        click.echo("IK→FK round trip: no reachable random pose found")
        return
    readings = mech.ik(poses)
    result = mech.fk(readings)
    conv = np.asarray(result.converged, dtype=bool)
    iters = np.asarray(result.iterations)
    click.echo(f"IK→FK round trip on {len(poses)} random reachable poses (FK from home):")
    click.echo(f"  converged {int(conv.sum())}/{len(poses)}; Newton iterations mean {iters.mean():.2f}, "
               f"max {int(iters.max())}")
    if conv.any():
        p, q = poses[conv], np.asarray(result.poses)[conv]
        lin = ~angle
        pos_err = float(np.max(np.linalg.norm(p[:, lin] - q[:, lin], axis=1)))
        if mech.pose_names == ("x", "y", "z", "a", "b", "c"):
            rot_err = float(np.max(rotation_error(euler_to_matrix(p[:, 3:]), euler_to_matrix(q[:, 3:]))))
        elif angle.any():
            d = np.angle(np.exp(1j * (p[:, angle] - q[:, angle])))
            rot_err = float(np.max(np.abs(d)))
        else:
            rot_err = None
        click.echo(f"  max position error {pos_err:.3g} mm"
                   + ("" if rot_err is None else f", max orientation error {rot_err:.3g} rad"))


__all__ = ["info_cmd", "single_axis_ranges"]

"""What a machine is, where it can go, and whether its IK and FK agree: the values ``pkmcal info``
prints (its text and ``--json`` are one dict, :func:`machine_info`).

1. The machine summary (:meth:`Hexapod.summary`).
2. Single-axis workspace of the machine within what its geometry reaches
   (:meth:`Mechanism.within_geometry`, as ``pkmcal plan``: limits looser than that are
   noted and clipped): from the home pose, each pose coordinate is moved alone (the others
   stay at home) over a grid of 1001 values; the reachable interval around home (every limit of
   ``check_limits`` satisfied) is then refined at both ends by bisection to 1e-6 mm/deg. This is
   the "travel range" of hexapod data sheets. The limit that stops each end is named.
3. Box occupancy: the fraction of uniform random poses in the box of those ranges that are
   reachable (the 6-D workspace is much smaller than the box), and of those on another
   assembly mode than home.
4. IK→FK round trip on random reachable poses of that box (``--n-poses``), or on the poses
   of a file (``--poses FILE``): readings q = IK(x), then x̂ = FK(q) from the home pose. A
   pose is a round trip only when x̂ is x: converged, on the assembly mode of x
   (:meth:`Mechanism.same_branch`, sign det J the same) and within 1e-6 mm and 1e-6 rad;
   max ‖p̂ − p‖ (mm) and max rotation angle of R̂ Rᵀ (deg) are reported over those. Poses
   that converged on another assembly mode (the mirror solution) or to another pose, and
   those that did not converge, are counted apart, never as round trips; poses that lie on
   another assembly mode than home are counted too (the limits admit them, but FK from home
   cannot return them).

Everything is vectorised over poses (one ``check_limits`` call per bisection step).
"""

from __future__ import annotations

import numpy as np

from pkmcal.conventions import euler_to_matrix, rotation_error

GRID_POINTS = 1001
#: A round trip returned the pose when within these (mm, rad). The FK stops at leg errors of
#: 1e-9 mm; a pose with inverse condition number ≥ 0.01 (the default singularity margin)
#: turns that into a pose error ≤ 1e-9·√6/0.01 ≈ 2.5e-7 mm (rad × the joint radius), so a
#: pose farther off is another solution, not rounding.
ROUND_TRIP_TOL_MM = 1e-6
ROUND_TRIP_TOL_RAD = 1e-6
BISECTION_TOL = 1e-6
BOX_SAMPLES = 10_000


def _half_widths(mech) -> np.ndarray:
    """Search half-width per pose coordinate: the machine's :meth:`~pkmcal.mechanisms.base.Mechanism.reach` (1000 mm
    when it states none) for translations, 180° for angles (90° for the pitch b of a 6-DoF
    Euler pose)."""
    reach = mech.reach()
    reach = 1000.0 if reach is None else reach
    out = np.where(np.array(mech.pose_is_angle), np.pi, reach)
    if mech.pose_names == ("x", "y", "z", "a", "b", "c"):
        out[4] = np.pi / 2
    return out


def _reachable(mech, poses: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return mech.check_limits(poses).ok


def single_axis_ranges(mech, home: np.ndarray) -> tuple[np.ndarray, list[list[str]]]:
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


N_ROUND_TRIP = 300


def machine_info(mech, n_poses: int, poses_path: str | None, seed: int) -> dict:
    """Items 1-4 of the module docstring as one JSON-ready dict (mm and degrees); the text of
    ``pkmcal info`` is :func:`pkmcal.cli.info_cmd.info_lines` of it."""
    data: dict = {"machine": mech.name, "summary": mech.summary().splitlines(),
                  "parameters": _parameters_by_unit(mech)}
    mech, notes = mech.within_geometry()     # the workspace of what the geometry reaches, as plan's
    data["notes"] = list(notes)
    home = np.asarray(mech.home_pose, dtype=float)
    angle = np.array(mech.pose_is_angle)
    if not _reachable(mech, home[None])[0]:
        with np.errstate(all="ignore"):
            data["home_violates"] = mech.check_limits(home[None]).verdicts()[0]
        return data
    ranges, stops = single_axis_ranges(mech, home)
    file_units = lambda row: [float(np.rad2deg(v)) if a else float(v) for v, a in zip(row, angle)]  # noqa: E731
    workspace: dict = {"grid_points": GRID_POINTS, "bisection_tolerance": BISECTION_TOL, "ranges": {
        name: {"min": file_units(ranges[:, 0])[k], "max": file_units(ranges[:, 1])[k],
               "unit": "deg" if angle[k] else "mm", "stopped_by": list(stops[k])}
        for k, name in enumerate(mech.pose_names)}}
    if mech.workspace is not None:   # the box the machine file declares (workspace_box() is it then)
        ws = mech.workspace_box()
        workspace["declared_box"] = {name: [file_units(ws[:, 0])[k], file_units(ws[:, 1])[k]]
                                     for k, name in enumerate(mech.pose_names)}
    rng = np.random.default_rng(seed)
    box = rng.uniform(ranges[:, 0], ranges[:, 1], size=(BOX_SAMPLES, mech.n_dof))
    ok = _reachable(mech, box)
    other = int(np.count_nonzero(~mech.same_branch(box[ok], home))) if ok.any() else 0
    workspace.update(box_samples=BOX_SAMPLES, box_reachable_fraction=float(ok.mean()),
                     box_other_mode_fraction=other / BOX_SAMPLES)
    data["workspace"] = workspace
    if poses_path is not None:
        from pkmcal.io.tables import read_poses

        poses = read_poses(poses_path, mech)
        what = f"the {len(poses)} poses of {poses_path}"
    else:
        pool = box[ok]
        for _ in range(20):  # top up in batches (not per pose) when the box is sparsely reachable
            if len(pool) >= n_poses:
                break
            more = rng.uniform(ranges[:, 0], ranges[:, 1], size=(BOX_SAMPLES, mech.n_dof))
            pool = np.concatenate([pool, more[_reachable(mech, more)]])
        poses = pool[:n_poses]
        what = f"{len(poses)} random reachable poses"
        if len(poses) == 0:
            data["round_trip"] = {"poses": "no reachable random pose found", "n": 0}
            return data
    data["round_trip"] = round_trip_stats(mech, poses, mech.fk(mech.ik(poses)), what)
    return data


def _parameters_by_unit(mech) -> dict[str, list[str]]:
    """The machine's parameter names by unit ('deg' for angles, 'no unit' for a hexapod's leg
    gains): what ``--free``, ``--fix``, ``--prior`` and a study's error groups name."""
    by_unit: dict[str, list[str]] = {}
    for name, unit, angle in zip(mech.param_names, mech.param_units, mech.param_is_angle):
        by_unit.setdefault("deg" if angle else ("no unit" if unit == "1" else unit), []).append(name)
    return by_unit


def round_trip_stats(mech, poses: np.ndarray, result, what: str | None = None) -> dict:
    """The round-trip report of module docstring item 4: poses (N, n) the readings came
    from, ``result`` their FK from home. A pose counts as a round trip only when FK
    returned it (converged, on the assembly mode of the pose itself, position within
    :data:`ROUND_TRIP_TOL_MM` and angles within :data:`ROUND_TRIP_TOL_RAD`); errors are
    reported over those poses only (mm, deg; None where none returned), and every other
    pose is counted with its reason."""
    angle = np.array(mech.pose_is_angle)
    conv = np.asarray(result.converged, dtype=bool)
    iters = np.asarray(result.iterations)
    q = np.asarray(result.poses)
    n = len(poses)
    with np.errstate(invalid="ignore"):
        pos_err = np.linalg.norm(poses[:, ~angle] - q[:, ~angle], axis=1)
        if mech.pose_names == ("x", "y", "z", "a", "b", "c"):
            rot_err = rotation_error(euler_to_matrix(poses[:, 3:]), euler_to_matrix(q[:, 3:]))
        elif angle.any():
            rot_err = np.max(np.abs(np.angle(np.exp(1j * (poses[:, angle] - q[:, angle])))), axis=1)
        else:
            rot_err = np.zeros(n)
    mode = mech.same_branch(np.where(conv[:, None], q, poses), poses)
    home_mode = mech.same_branch(poses, mech.home_pose)
    back = conv & mode & (pos_err <= ROUND_TRIP_TOL_MM) & (rot_err <= ROUND_TRIP_TOL_RAD)
    other_mode = conv & ~mode
    other_pose = conv & mode & ~back
    largest = lambda err, rows: float(err[rows].max()) if rows.any() else None  # noqa: E731
    return {"poses": what or f"{n} poses", "n": n, "converged": int(conv.sum()),
            "iterations_mean": float(iters.mean()), "iterations_max": int(iters.max()),
            "returned": int(back.sum()), "max_position_error_mm": largest(pos_err, back),
            "max_orientation_error_deg": (float(np.rad2deg(rot_err[back].max())) if back.any() and angle.any()
                                          else None),
            "other_mode": int(other_mode.sum()), "other_mode_max_position_error_mm": largest(pos_err, other_mode),
            "other_pose": int(other_pose.sum()), "other_pose_max_position_error_mm": largest(pos_err, other_pose),
            "not_converged": int((~conv).sum()), "off_home_mode": int((~home_mode).sum())}


__all__ = ["BISECTION_TOL", "BOX_SAMPLES", "GRID_POINTS", "N_ROUND_TRIP", "ROUND_TRIP_TOL_MM", "ROUND_TRIP_TOL_RAD",
           "machine_info", "round_trip_stats", "single_axis_ranges"]

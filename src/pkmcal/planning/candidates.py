"""Candidate poses for measurement planning, and their reachability and measurability.

Candidates (paper 1 §IV; paper 2 §4):

* ``corners`` — the 2^6 = 64 corners of the workspace box (paper 1: every pose coordinate
  at its minimum or maximum; 2^n for a machine with n pose coordinates);
* ``random`` — uniform in the box; ``grid`` — k points per coordinate (k^6 poses);
* ``file`` — a user CSV with the machine's pose columns (x, y, z, a, b, c: mm, degrees).

Every machine's limits take the safety margin (:meth:`Mechanism.check_limits`); those
whose limits take none ignore it.

**Workspace box.** The machine's :meth:`~pkmcal.mechanisms.base.Mechanism.workspace_box`
when it declares one (a given ``workspace``, a delta's print volume, the planar boxes, the
6-RSS/6-PUS boxes about home); otherwise (the 6-UPS hexapod without a ``workspace``:
:meth:`~pkmcal.mechanisms.base.Mechanism.reach_search_shape`) the per-axis reach around
home: coordinate i spans ``home_i ± t_i·h_i`` with t_i ∈ (0, 1] the largest scale
(bisection, 24 halvings, all axes in one check per halving) at which both poses
home ± t_i h_i e_i are reachable (with the safety margin) and measurable, for the default
shape h = (s, s, s/2, s/r, s/r, s/r), s = the mean actuator stroke (reading units) and
r = the platform joint radius (mm) (the angles rotate a platform joint by s). Either box
stays within the range in which the Euler angles represent each orientation once
(:func:`angle_bounds`: a, c within ±180°, b within ±90°, from
:data:`~pkmcal.conventions.EULER_RANGES`): the search goes no further, a declared box
beyond it is clipped with a note (the rotations beyond are those inside, by whole turns
or by the convention's other branch). A declared box of which fewer than 1 %
(:data:`MIN_REACHED_FRACTION`) of 2000 uniform poses (seed 0) pass the checks is shrunk, on
each side of home along each coordinate, to the reach from home (the same bisection), with
a note: the candidates are drawn where the machine reaches, not in a box 99 % beyond it.
Random and grid candidates are drawn in this box and filtered. Corner selection (paper 1) needs all 64 corners
reachable: :func:`corner_box` shrinks the box about its centre by the largest common scale
t ∈ (0, 1] whose corners all pass (same bisection).

**Checks** (every candidate, on the nominal machine): the machine's limits with a safety
margin (:meth:`Mechanism.check_limits`: stroke, U/S-joint tilt, leg collision,
singularity) and measurability:

* indicators (paper 2 eq. 4–6): the platform plane must face the indicators
  (n_z ≥ ``MIN_NORMAL_Z``), every reading z_k must lie in the indicator travel [lo, hi]
  when given, and every touch point must lie on the plate (distance from the platform
  origin in the plane ≤ plate radius) when a plate radius is given;
* full-pose / position: optional line-of-sight cone — the angle between the target's z
  axis (R·R_t·e_z) and the direction from the target to the sensor origin must not exceed
  the cone's half-angle.

Rejected candidates are counted by reason.

**On the bed** (``Measurability(on_bed=True)``, the default of ``pkmcal plan`` with a Z probe:
:func:`pkmcal.planning.plan.plan_poses`): a printer probes its bed only, so every candidate
is first lowered to where its probe triggers (:func:`pkmcal.identification.advice.where_read`,
the study's ``on_bed``), then checked there: the machine's bed limits
(:data:`pkmcal.study.printed.BED_LIMITS`, ``min_z``) are not checked (the nozzle is at the
bed, or z_offset above it), and the probe point (the nozzle plus the probe's x, y offset,
:meth:`~pkmcal.sensors.z_probe.ZProbeSensor.probe_points`) must lie inside the machine's
build radius (:data:`BED_EDGE_LIMITS`, with the same margin; Klipper's delta
``print_radius``, klippy/kinematics/delta.py ``DeltaKinematics.__init__``): rejected as
``probe_point_radius``. The accepted candidates are the lowered poses.

**Large sets** (:func:`generate_candidates`): candidates are drawn and checked in chunks
of :data:`CHUNK_SIZE` poses, so memory stays bounded by the chunk and the accepted poses;
a chunk is a picklable unit of work (:func:`check_chunk`) that an executor's ``map`` can
run (in order by default, in this process). Chunks cut one random draw into pieces, so the
candidates, their rejection counts and the random generator's final state are those of
the unchunked draw, whatever the chunk size.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np

from pkmcal.conventions import EULER_RANGES, POSE_COLUMNS, euler_to_matrix
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.frame import Frame
from pkmcal.parallel import IN_PROCESS
from pkmcal.planning.indices import blas_single_threaded
from pkmcal.sensors.base import MeasurementSetup
from pkmcal.sensors.indicators import MIN_NORMAL_Z

CANDIDATE_KINDS = ("random", "grid", "corners", "file")
#: Poses checked per chunk: bounds the memory of the checks (a few MB per chunk) and is
#: the unit of work of an executor (:func:`generate_candidates`).
CHUNK_SIZE = 50_000
#: A progress callback: called with (done, total).
Progress = Callable[[int, int], None]
#: Default safety margin: mm for stroke and collision, degrees for the joint tilts.
DEFAULT_MARGIN = 0.1
#: A declared workspace box of which fewer than this fraction of uniform poses pass the
#: checks is shrunk to the reach from home (:func:`workspace_box`); and the probe's size.
MIN_REACHED_FRACTION = 0.01
N_PROBE = 2000
#: Limits of a machine that bound where its bed is: the probe point of an on-bed candidate
#: is checked against them (module docstring, "On the bed").
BED_EDGE_LIMITS = ("print_radius",)


@dataclass(frozen=True)
class Measurability:
    """Measurability options (module docstring); ``None`` disables a check.

    ``travel`` (lo, hi) indicator reading range, mm; ``plate_radius`` platform plate
    radius for the indicator touch points, mm; ``sight_cone`` line-of-sight half-angle,
    radians (full-pose and position sensors); ``on_bed`` a Z probe's candidates lowered
    onto the bed before they are checked (module docstring, "On the bed").
    """

    travel: tuple[float, float] | None = None
    plate_radius: float | None = None
    sight_cone: float | None = None
    on_bed: bool = False


@dataclass(frozen=True)
class CandidateCheck:
    """Per-pose verdicts: ``violations`` reason → (N,) bool; ``ok`` (N,) all passed;
    ``poses`` the poses checked when they are not those given (lowered onto the bed)."""

    violations: dict[str, np.ndarray]
    poses: np.ndarray | None = None

    @property
    def ok(self) -> np.ndarray:
        n = len(next(iter(self.violations.values())))
        bad = np.zeros(n, dtype=bool)
        for v in self.violations.values():
            bad |= v
        return ~bad

    def counts(self) -> dict[str, int]:
        """Number of poses violating each reason (a pose may count under several)."""
        return {k: int(v.sum()) for k, v in self.violations.items() if v.any()}


@dataclass(frozen=True)
class CandidateSet:
    """Accepted candidate poses (N, 6) (mm, rad), the number tested and rejections by reason."""

    poses: np.ndarray
    n_tested: int
    rejected: dict[str, int] = field(default_factory=dict)
    kind: str = ""

    def describe(self) -> str:
        rej = ", ".join(f"{k} {v}" for k, v in sorted(self.rejected.items())) or "none"
        return (f"{len(self.poses)} of {self.n_tested} {self.kind} candidates accepted; "
                f"rejected by reason: {rej}")


# -- measurability ----------------------------------------------------------------------


def measurability_violations(setup: MeasurementSetup, poses: np.ndarray,
                             spec: Measurability = Measurability()) -> dict[str, np.ndarray]:
    """Reason → (N,) True where the sensor of ``setup`` cannot measure the pose."""
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    sensor = setup.sensor
    out: dict[str, np.ndarray] = {}
    if sensor.kind == "indicators":
        facing = np.cos(poses[:, 4]) * np.cos(poses[:, 3]) >= MIN_NORMAL_Z    # n_z = R_22 = cos b cos a
        out["indicator_plane_tilt"] = ~facing
        if spec.travel is None and spec.plate_radius is None:
            return out
        R = euler_to_matrix(poses[:, 3:6])
        safe = np.where(facing[:, None], poses, np.zeros(6))
        if spec.travel is not None:
            z = sensor.predict(Frame.from_poses(safe))
            lo, hi = spec.travel
            out["indicator_travel"] = facing & ~np.all((z >= lo) & (z <= hi), axis=1)
        if spec.plate_radius is not None:
            # touch point under indicator k (IndicatorSensor.touch_points, {F}); in {P} minus p, Rᵀ.
            pts = sensor.touch_points(Frame.from_poses(safe))
            local = np.einsum("nji,nkj->nki", R, pts - poses[:, None, 0:3])
            out["indicator_off_plate"] = facing & np.any(np.linalg.norm(local[..., :2], axis=-1)
                                                         > spec.plate_radius, axis=1)
    elif spec.sight_cone is not None and sensor.kind in ("full-pose", "position"):
        R = euler_to_matrix(poses[:, 3:6])
        world = np.asarray(sensor.world, dtype=float)
        Rw = euler_to_matrix(world[3:6])
        origin = -Rw.T @ world[0:3]                      # sensor origin in {F}
        if sensor.kind == "full-pose":
            tool = np.asarray(sensor.tool, dtype=float)
            offset, Rt = tool[0:3], euler_to_matrix(tool[3:6])
        else:
            offset, Rt = np.asarray(sensor.target, dtype=float), np.eye(3)
        target = poses[:, 0:3] + R @ offset
        normal = (R @ Rt)[:, :, 2]
        sight = origin - target
        cosang = np.einsum("nk,nk->n", normal, sight) / np.maximum(np.linalg.norm(sight, axis=1), 1e-12)
        out["line_of_sight"] = cosang < np.cos(spec.sight_cone)
    return out


def check_candidates(mechanism: Mechanism, setup: MeasurementSetup | None, poses: np.ndarray, *,
                     margin: float = DEFAULT_MARGIN, measurability: Measurability = Measurability()) -> CandidateCheck:
    """Limits (with ``margin``) and measurability of every pose; see module docstring."""
    poses = mechanism.as_pose_array(poses)
    lowered = None
    if measurability.on_bed and setup is not None:
        from pkmcal.identification.advice import where_read

        with np.errstate(invalid="ignore"):
            lowered = poses = where_read(mechanism, setup.sensor, poses)
    finite = np.all(np.isfinite(poses), axis=1)
    safe = np.where(finite[:, None], poses, mechanism.home_pose)
    lim = mechanism.check_limits(safe, margin=margin, margins=False)   # verdicts only: the faster path
    viol = {k: v | ~finite for k, v in lim.violations.items()}
    if lowered is not None:
        viol.update(_bed_violations(mechanism, setup, safe, margin, finite))
    if setup is not None:
        viol.update(measurability_violations(setup, safe, measurability))
    return CandidateCheck(viol, lowered)


def _bed_violations(mechanism: Mechanism, setup: MeasurementSetup, safe: np.ndarray, margin: float,
                    finite: np.ndarray) -> dict[str, np.ndarray]:
    """The checks of an on-bed candidate (module docstring, "On the bed"): its bed limits
    dropped, its probe point inside the build radius."""
    from pkmcal.study.printed import BED_LIMITS

    out = {name: np.zeros(len(safe), dtype=bool) for name in BED_LIMITS}   # the nozzle at the bed
    points = getattr(setup.sensor, "probe_points", None)
    if points is None:
        return out
    at_probe = safe.copy()
    at_probe[:, 0:3] = points(mechanism.frame(safe))
    edge = mechanism.check_limits(at_probe, margin=margin, margins=False).violations
    bad = np.zeros(len(safe), dtype=bool)
    for name in BED_EDGE_LIMITS:
        if name in edge:
            bad |= edge[name]
    out["probe_point_radius"] = bad | ~finite
    return out


# -- the workspace box ------------------------------------------------------------------


def corner_poses(box: np.ndarray) -> np.ndarray:
    """The 2^n corners (2^n, n) of a box (n, 2) [min, max]; 64 for a hexapod (paper 1 §IV)."""
    box = np.asarray(box, dtype=float).reshape(-1, 2)
    n = box.shape[0]
    bits = np.array(list(itertools.product((0, 1), repeat=n)))
    return box[np.arange(n), bits]


def _scaled_box(center, half, t):
    return np.stack([center - t * half, center + t * half], axis=1)


def _bisect_scale(ok, t_max: float = 1.0, n_iter: int = 24) -> float:
    if ok(t_max):
        return t_max
    lo, hi = 0.0, t_max
    for _ in range(n_iter):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def _bisect_scales(ok, n: int, t_max: float = 1.0, n_iter: int = 24) -> np.ndarray:
    """:func:`_bisect_scale` of ``n`` independent scales at once: ``ok(t)`` takes the (n,)
    scales and returns which pass (n,); the same halvings, one call per halving."""
    lo, hi = np.zeros(n), np.full(n, t_max)
    done = ok(hi.copy())
    for _ in range(n_iter):
        if done.all():
            break
        mid = 0.5 * (lo + hi)
        passed = ok(np.where(done, hi, mid))
        lo = np.where(~done & passed, mid, lo)
        hi = np.where(~done & ~passed, mid, hi)
    return np.where(done, t_max, lo)


@blas_single_threaded
def corner_box(mechanism: Mechanism, box: np.ndarray, setup: MeasurementSetup | None = None, *,
               margin: float = DEFAULT_MARGIN, measurability: Measurability = Measurability()) -> np.ndarray:
    """The box (n, 2) scaled about its centre by the largest t ∈ (0, 1] whose 2^n corners all
    pass :func:`check_candidates`; error if even tiny boxes fail (home pose unreachable)."""
    box = np.asarray(box, dtype=float).reshape(-1, 2)
    center, half = box.mean(axis=1), (box[:, 1] - box[:, 0]) / 2

    def ok(t):
        return bool(check_candidates(mechanism, setup, corner_poses(_scaled_box(center, half, t)),
                                     margin=margin, measurability=measurability).ok.all())

    t = _bisect_scale(ok)
    if t <= 1e-6:
        raise PkmcalError(f"machine '{mechanism.name}': no box around {np.round(center, 3).tolist()} has all its "
                          "corners reachable and measurable; check the home pose, the workspace, the safety "
                          "margin and the sensor set-up")
    return _scaled_box(center, half, t)


def angle_bounds(mechanism: Mechanism) -> np.ndarray:
    """Bounds (n, 2) of each pose coordinate in a planning box: the Euler angles' ranges
    (:data:`~pkmcal.conventions.EULER_RANGES`: a and c ±π, b ±π/2) on a machine with the
    pose convention, ±π on any other angle, unbounded lengths."""
    n = mechanism.n_dof
    bounds = np.tile([-np.inf, np.inf], (n, 1))
    angle = np.flatnonzero(np.asarray(mechanism.pose_is_angle, dtype=bool))
    bounds[angle] = [-np.pi, np.pi]
    if "pose-convention" in mechanism.abilities and n == len(POSE_COLUMNS):
        bounds[3:6] = EULER_RANGES
    return bounds


def _clip_box(mechanism: Mechanism, box: np.ndarray, notes: list[str] | None, what: str) -> np.ndarray:
    """``box`` clipped to :func:`angle_bounds`, with a note naming the coordinates clipped."""
    bounds = angle_bounds(mechanism)
    clipped = np.stack([np.maximum(box[:, 0], bounds[:, 0]), np.minimum(box[:, 1], bounds[:, 1])], axis=1)
    changed = np.flatnonzero(np.any(clipped != box, axis=1))
    if notes is not None and len(changed):
        notes.append(f"{what}: " + ", ".join(
            f"{mechanism.pose_names[i]} [{np.rad2deg(box[i, 0]):.6g}, {np.rad2deg(box[i, 1]):.6g}] deg -> "
            f"[{np.rad2deg(clipped[i, 0]):.6g}, {np.rad2deg(clipped[i, 1]):.6g}]" for i in changed)
            + " (beyond the range in which the Euler angles represent each orientation once: a, c ±180, b ±90)")
    return clipped


def _reached_part(mechanism: Mechanism, box: np.ndarray, setup, margin, measurability,
                  notes: list[str] | None) -> np.ndarray:
    """A declared ``box`` of which fewer than :data:`MIN_REACHED_FRACTION` of
    :data:`N_PROBE` uniform poses (seed 0) pass the checks, shrunk on each side of home along
    each coordinate to the reach from home (bisection, as the search); with a note. The box
    unchanged otherwise, or when home is outside it."""
    home = np.asarray(mechanism.home_pose, dtype=float)
    if not np.all((box[:, 0] <= home) & (home <= box[:, 1])):
        return box
    probe = random_poses(box, N_PROBE, np.random.default_rng(0))
    reached = float(check_candidates(mechanism, setup, probe, margin=margin, measurability=measurability).ok.mean())
    if reached >= MIN_REACHED_FRACTION:
        return box
    n = len(home)
    edge = np.concatenate([box[:, 1] - home, box[:, 0] - home])      # the upper sides, then the lower

    def ok(t):
        poses = np.tile(home, (2 * n, 1))
        poses[np.arange(2 * n), np.tile(np.arange(n), 2)] += t * edge
        return check_candidates(mechanism, setup, poses, margin=margin, measurability=measurability).ok

    t = _bisect_scales(ok, 2 * n)
    if not np.any(t > 0):
        return box                                   # home fails the checks: the candidates' error says so
    shrunk = np.stack([home + t[n:] * edge[n:], home + t[:n] * edge[:n]], axis=1)
    if notes is not None:
        changed = np.flatnonzero(np.any(shrunk != box, axis=1))
        unit = ["deg" if a else "mm" for a in mechanism.pose_is_angle]
        shown = [np.where(np.asarray(mechanism.pose_is_angle)[:, None], np.rad2deg(b), b) for b in (box, shrunk)]
        source = mechanism.limit_source("workspace", "'workspace:' in the machine file")
        notes.append(f"the machine's workspace box ({source}) is mostly beyond what the machine reaches "
                     f"({100 * reached:.2g} % of "
                     f"{N_PROBE} uniform poses in it pass the limits): planning draws in the reach from home along "
                     "each coordinate: " + ", ".join(
                         f"{mechanism.pose_names[i]} [{shown[0][i, 0]:.6g}, {shown[0][i, 1]:.6g}] -> "
                         f"[{shown[1][i, 0]:.4g}, {shown[1][i, 1]:.4g}] {unit[i]}" for i in changed)
                     + "; set it to the poses the machine reaches")
    return shrunk


@blas_single_threaded
def workspace_box(mechanism: Mechanism, setup: MeasurementSetup | None = None, *,
                  margin: float = DEFAULT_MARGIN, measurability: Measurability = Measurability(),
                  notes: list[str] | None = None) -> np.ndarray:
    """The machine's declared box, or the largest reachable box around home along its
    :meth:`~pkmcal.mechanisms.base.Mechanism.reach_search_shape` (module docstring); either
    within :func:`angle_bounds` (a declared box beyond them is clipped, with a note appended
    to ``notes``; the search never goes beyond them). A declared box that is mostly beyond
    the machine's reach is shrunk to it (:func:`_reached_part`, with a note)."""
    shape = mechanism.reach_search_shape()
    home = np.asarray(mechanism.home_pose, dtype=float)
    if shape is None:
        source = mechanism.limit_source("workspace", "'workspace:' in the machine file")
        box = _clip_box(mechanism, np.array(mechanism.workspace_box(), dtype=float).reshape(mechanism.n_dof, 2),
                        notes, f"the machine's workspace box ({source}) is clipped")
        return _reached_part(mechanism, box, setup, margin, measurability, notes)
    bounds = angle_bounds(mechanism)
    # the search is symmetric about home: no further than the farther bound on either side
    half = np.minimum(np.asarray(shape, dtype=float), np.maximum(bounds[:, 1] - home, home - bounds[:, 0]))
    n = len(half)

    def ok(t):               # the poses home ± t_i h_i e_i of every axis i in one check
        steps = np.diag(t * half)
        passed = check_candidates(mechanism, setup, np.concatenate([home + steps, home - steps]), margin=margin,
                                  measurability=measurability).ok
        return passed[:n] & passed[n:]

    reach = _bisect_scales(ok, n) * half
    if np.any(reach <= 1e-6 * half):
        raise PkmcalError(f"machine '{mechanism.name}': the home pose cannot move along "
                          f"{', '.join(mechanism.pose_names[i] for i in np.flatnonzero(reach <= 1e-6 * half))} "
                          "within the limits and the safety margin; check the home pose, the margin and the sensor "
                          "set-up")
    return _clip_box(mechanism, np.stack([home - reach, home + reach], axis=1), None, "")


# -- generators -------------------------------------------------------------------------


def random_poses(box: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` poses uniform in the box (d, 2)."""
    box = np.asarray(box, dtype=float).reshape(-1, 2)
    return box[:, 0] + rng.random((n, box.shape[0])) * (box[:, 1] - box[:, 0])


def grid_poses(box: np.ndarray, per_axis: int) -> np.ndarray:
    """``per_axis``^d poses on a regular grid of the box (d, 2), faces included (per_axis ≥ 2)."""
    if per_axis < 2:
        raise PkmcalError("a candidate grid needs at least 2 points per pose coordinate")
    box = np.asarray(box, dtype=float).reshape(-1, 2)
    axes = [np.linspace(lo, hi, per_axis) for lo, hi in box]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, box.shape[0])


def read_candidates_csv(path: str | os.PathLike, mechanism: Mechanism | None = None, mapping=None) -> np.ndarray:
    """Poses (N, n) (mm, rad) from a CSV file with the machine's pose columns (default
    x, y, z, a, b, c; lengths mm, angles degrees); ``mapping`` an optional
    :class:`~pkmcal.io.import_mapping.ImportMapping` for files from other tools."""
    from pkmcal.io.tables import POSE_KINDS, check_magnitudes, column_kinds, from_file_units, read_table

    if mechanism is not None:
        names, is_angle = tuple(mechanism.pose_names), tuple(mechanism.pose_is_angle)
    else:
        names, is_angle = POSE_COLUMNS, tuple(POSE_KINDS[c] == "angle" for c in POSE_COLUMNS)
    from pkmcal.io.orientation import small_angle_limit

    table = read_table(path, names, kinds=column_kinds(names, is_angle), mapping=mapping,
                       small_angle_deg=None if mechanism is None else small_angle_limit(mechanism))
    check_magnitudes(table, column_kinds(names, is_angle))
    if len(table) == 0:
        raise InputFileError(path, "no candidate poses (the file has a header but no rows)")
    return from_file_units(table[list(names)], is_angle)   # any pose dimension (planar: 2 or 3)


# -- checking in chunks ------------------------------------------------------------------


@dataclass(frozen=True)
class CheckedChunk:
    """One chunk of candidate ``poses`` (N, n) and its :class:`CandidateCheck`."""

    poses: np.ndarray
    check: CandidateCheck


def check_chunk(poses: np.ndarray, *, mechanism: Mechanism, setup: MeasurementSetup | None,
                margin: float = DEFAULT_MARGIN, measurability: Measurability = Measurability()) -> CheckedChunk:
    """:func:`check_candidates` of one chunk: the unit of work that
    :func:`generate_candidates` maps over the chunks; a module-level function of picklable
    arguments, so that a process pool or Dask can run it."""
    check = check_candidates(mechanism, setup, poses, margin=margin, measurability=measurability)
    return CheckedChunk(poses if check.poses is None else check.poses, check)


class _Accepted:
    """Accepted poses and per-reason rejection counts of the chunks, in order, up to
    ``limit`` accepted poses (None: all): a chunk that crosses the limit counts only up to
    its last pose used."""

    def __init__(self, limit: int | None = None):
        self.limit = limit
        self.tested = 0
        self.total = 0
        self.rejected: dict[str, int] = {}
        self.poses: list[np.ndarray] = []

    @property
    def full(self) -> bool:
        return self.limit is not None and self.total >= self.limit

    def add(self, chunk: CheckedChunk) -> None:
        ok = chunk.check.ok
        used, take = len(ok), int(ok.sum())
        if self.limit is not None and self.total + take >= self.limit:
            take = self.limit - self.total
            used = int(np.flatnonzero(ok)[take - 1]) + 1 if take > 0 else 0
        for k, v in chunk.check.violations.items():
            self.rejected[k] = self.rejected.get(k, 0) + int(np.count_nonzero(v[:used]))
        self.poses.append(chunk.poses[:used][ok[:used]])
        self.tested += used
        self.total += take

    def result(self, kind: str, n_dof: int) -> CandidateSet:
        poses = np.concatenate(self.poses) if self.poses else np.empty((0, n_dof))
        return CandidateSet(poses, self.tested, {k: v for k, v in self.rejected.items() if v}, kind)


def _chunks(poses: np.ndarray, size: int):
    for i in range(0, len(poses), size):
        yield poses[i:i + size]


class _RandomDraws:
    """``total`` poses uniform in ``box``, drawn from ``rng`` in chunks of ``size`` as they
    are consumed. :meth:`skip_rest` advances ``rng`` past the poses not drawn, so that the
    generator ends in the state one draw of all ``total`` poses leaves (numpy fills
    ``rng.random`` arrays in order, so consecutive chunks are that one draw, split)."""

    def __init__(self, box: np.ndarray, total: int, rng: np.random.Generator, size: int):
        self.box, self.left, self.rng, self.size = box, total, rng, size

    def __iter__(self):
        while self.left > 0:
            k = min(self.size, self.left)
            self.left -= k
            yield random_poses(self.box, k, self.rng)

    def skip_rest(self) -> None:
        while self.left > 0:
            k = min(self.size, self.left)
            self.left -= k
            self.rng.random((k, self.box.shape[0]))


@blas_single_threaded
def generate_candidates(mechanism: Mechanism, setup: MeasurementSetup | None, *, kind: str = "random",
                        n: int = 2000, rng: np.random.Generator | None = None, box: np.ndarray | None = None,
                        path: str | os.PathLike | None = None, poses: np.ndarray | None = None,
                        grid_per_axis: int = 4, margin: float = DEFAULT_MARGIN,
                        measurability: Measurability = Measurability(), max_rounds: int = 50,
                        chunk_size: int = CHUNK_SIZE, chunk_map: Callable = IN_PROCESS,
                        progress: Progress | None = None) -> CandidateSet:
    """Checked candidate poses of one ``kind`` of :data:`CANDIDATE_KINDS`, processed in
    chunks of ``chunk_size`` poses (bounded memory); error if none passes.

    ``random`` draws rounds of max(4·(n − accepted), 256) poses until ``n`` pass the checks
    (at most ``max_rounds`` rounds); each round is drawn and checked chunk by chunk, the
    poses after the n-th accepted one are drawn (so that ``rng`` ends in the same state)
    but neither checked nor counted. The others check a fixed set: ``file`` the ``poses``
    given or those of the CSV ``path``, ``grid`` the grid of ``box``, ``corners`` the
    corners of :func:`corner_box` of it (so that all 64 pass). ``box`` defaults to
    :func:`workspace_box`. The result does not depend on ``chunk_size``.

    ``chunk_map(fn, chunks)`` runs :func:`check_chunk` on the chunks and must yield the
    results in order; the default, :data:`~pkmcal.parallel.IN_PROCESS` (the built-in lazy
    ``map``), runs them in this process
    one after the other and stops at the n-th accepted pose. An executor's ``map``
    (``concurrent.futures``; Dask's ``client.map`` then ``gather``) may run a round's chunks
    at once; results after the n-th accepted pose are then discarded. ``progress`` is
    called after every chunk with (accepted so far, n) for ``random``, (checked so far,
    number of poses) otherwise. Limits are checked without their margins
    (:meth:`~pkmcal.mechanisms.hexapod.Hexapod.check_limits` with ``margins=False``).
    """
    if chunk_size < 1:
        raise PkmcalError(f"chunk_size must be a positive number of poses, not {chunk_size}")
    rng = np.random.default_rng() if rng is None else rng
    kw = dict(margin=margin, measurability=measurability)
    task = partial(check_chunk, mechanism=mechanism, setup=setup, **kw)
    if kind == "random":
        if box is None:
            box = workspace_box(mechanism, setup, **kw)
        box = np.asarray(box, dtype=float).reshape(-1, 2)
        acc = _Accepted(limit=n)
        for _ in range(max_rounds):
            draws = _RandomDraws(box, max(4 * (n - acc.total), 256), rng, chunk_size)
            for chunk in chunk_map(task, iter(draws)):
                acc.add(chunk)
                if progress is not None:
                    progress(acc.total, n)
                if acc.full:
                    break
            draws.skip_rest()
            if acc.full:
                break
        if not acc.full:
            raise PkmcalError(f"only {acc.total} of {acc.tested} random poses in the workspace box are reachable and "
                              f"measurable; ask for fewer candidates or relax the margin/sensor checks")
        return acc.result("random", box.shape[0])
    if kind == "file":
        if poses is None:
            if path is None:
                raise PkmcalError("candidate kind 'file' needs a CSV path")
            poses = read_candidates_csv(path)
        poses = mechanism.as_pose_array(poses)
    else:
        if box is None:
            box = workspace_box(mechanism, setup, **kw)
        if kind == "corners":
            poses = corner_poses(corner_box(mechanism, box, setup, **kw))
        elif kind == "grid":
            poses = grid_poses(box, grid_per_axis)
        else:
            raise PkmcalError(f"unknown candidate kind '{kind}'; use one of {', '.join(CANDIDATE_KINDS)}")
    acc = _Accepted()
    for chunk in chunk_map(task, _chunks(poses, chunk_size)):
        acc.add(chunk)
        if progress is not None:
            progress(acc.tested, len(poses))
    cand = acc.result(kind, poses.shape[1])
    if len(cand.poses) == 0:
        raise PkmcalError(f"none of the {cand.n_tested} {kind} candidate poses is reachable and measurable "
                          f"(rejected by reason: {cand.rejected}); check the candidates, the margin and the sensor "
                          "set-up")
    return cand

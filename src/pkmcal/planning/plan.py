"""Measurement planning end to end: candidates → per-pose blocks → selection → poses.

:func:`plan_poses` ties :mod:`.candidates` (reachable, measurable candidate poses, checked
in chunks), :mod:`.blocks` (each accepted candidate's whitened, scaled identification
Jacobian rows on the identifiable parameters, in batches: :func:`candidate_blocks`) and
:mod:`.selection` (the algorithms) together;
:func:`pose_set_indices` gives O1..O5 (:mod:`.indices`) of any pose set with the same
parameters and scaling, so ``pkmcal plan`` and ``pkmcal observability`` agree.

Candidates are checked inside the nominal machine's limits, clipped first to what its joint
geometry reaches (:meth:`~pkmcal.mechanisms.base.Mechanism.within_geometry`: a controller's
configuration may allow struts of metres on a machine of decimetres, with a note in
:attr:`Plan.notes`), by the safety margins of :mod:`.margins` (by default those a real
machine with joint errors of 3 mm survives), and the stages report progress through an
optional ``progress(stage)`` announcer (:data:`pkmcal.progress.Stages`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pkmcal.conventions import wrap_angle
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.parallel import IN_PROCESS
from pkmcal.planning.blocks import PlanningModel, planning_model
from pkmcal.planning.candidates import (
    CHUNK_SIZE,
    CandidateSet,
    Measurability,
    corner_box,
    generate_candidates,
    read_candidates_csv,
    workspace_box,
)
from pkmcal.planning.indices import observability_indices
from pkmcal.planning.margins import DeltaSafetyMargin, SafetyMargin, planning_checks, resolve_margin
from pkmcal.planning.selection import ALGORITHMS, Selection, select
from pkmcal.progress import Stages
from pkmcal.sensors.base import MeasurementSetup


@dataclass(frozen=True)
class Plan:
    """Chosen ``poses`` (n, 6) (mm, rad) with their nominal actuator ``commands`` (n, l), the
    ``selection`` (indices into the candidates, O1..O5), the ``candidates``, the model and the
    safety ``margin`` the candidates were checked with (a :class:`SafetyMargin` or
    :class:`DeltaSafetyMargin`, a single number on every limit, or None for a machine whose
    limits take none); ``notes``: what the plan changed of what it was given (limits looser
    than the geometry reaches, :meth:`~pkmcal.mechanisms.base.Mechanism.within_geometry`; a workspace
    box or candidate angles beyond the Euler angles' range), one line each; ``on_bed``: a Z
    probe's points lowered onto the bed (:func:`plan_poses`)."""

    poses: np.ndarray
    commands: np.ndarray
    selection: Selection
    candidates: CandidateSet
    model: PlanningModel
    box: np.ndarray | None = None
    margin: SafetyMargin | DeltaSafetyMargin | float | None = None
    notes: tuple[str, ...] = ()
    on_bed: bool = False

    def describe_margin(self) -> str:
        """The safety margin in words (what ``pkmcal plan`` prints)."""
        if self.margin is None:
            return "none (this machine's limits take no safety margin)"
        if isinstance(self.margin, (SafetyMargin, DeltaSafetyMargin)):
            return self.margin.describe()
        return f"{self.margin:g} on every limit (mm for stroke and clearance, degrees for joint tilts)"

    @property
    def indices(self) -> dict[str, float]:
        return self.selection.indices


#: Accepted candidates per call of :meth:`PlanningModel.blocks`. It bounds the temporaries of
#: a call (about 3 kB per candidate at 6 rows × 60 parameters), small enough that the
#: allocator reuses them instead of faulting in fresh pages: for the 100,000-candidate
#: full-pose plan, 50,000 → 10,000 took peak RSS 853 → 511 MB; 10,000 → 2,000 took it
#: 610–670 → 480 MB and system time 0.55–0.67 → 0.35–0.44 s (wall −0.1 s).
BLOCK_BATCH = 2_000


def candidate_blocks(model: PlanningModel, poses: np.ndarray, *, batch: int = BLOCK_BATCH,
                     chunk_map: Callable | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``model.blocks`` of the accepted candidate ``poses``, in ⌈N / batch⌉ near-equal
    batches: G (N, k, n) and the solved flags. ``chunk_map`` None (default): the batches
    run in this process on local threads (:func:`~pkmcal.parallel.thread_map`),
    each written straight into G; else ``chunk_map(model.blocks, batches)`` yields them in
    order (a process pool, Dask) and they are copied in.

    The batches depend only on N and ``batch`` — not on how the candidates were chunked —
    and are never shorter than batch/2 (or N), so that code paths chosen by batch size
    (e.g. NumPy below a few dozen poses, compiled above) take the same path as one call
    on all N: the blocks are bit-identical to ``model.blocks(poses)``.
    """
    from pkmcal.parallel import thread_map

    parts = np.array_split(poses, max(1, -(-len(poses) // batch)))
    bounds = np.cumsum([0] + [len(p) for p in parts])
    if chunk_map is None:
        G = np.empty((len(poses), model.rows_per_pose, model.n_params))
        ok = np.empty(len(poses), dtype=bool)

        def fill(i: int) -> None:
            ok[bounds[i]:bounds[i + 1]] = model.blocks(parts[i], out=G[bounds[i]:bounds[i + 1]])[1]

        for _ in thread_map(fill, range(len(parts))):
            pass
        return G, ok
    G = ok = None
    for i, (g, solved) in enumerate(chunk_map(model.blocks, parts)):
        if G is None:
            G, ok = np.empty((len(poses),) + g.shape[1:]), np.empty(len(poses), dtype=bool)
        G[bounds[i]:bounds[i + 1]], ok[bounds[i]:bounds[i + 1]] = g, solved
    return G, ok


def plan_poses(mechanism: Mechanism, setup: MeasurementSetup, n: int, *, algorithm: str = "default",
               index: str | None = None, candidates: np.ndarray | str | os.PathLike | None = None,
               n_candidates: int = 2000, grid: int | None = None, seed: int | None = None,
               margin: SafetyMargin | DeltaSafetyMargin | float | None = None,
               measurability: Measurability = Measurability(), method: str | None = None,
               model: PlanningModel | None = None, progress: Stages | None = None, circle_plane: str = "xy",
               chunk_size: int = CHUNK_SIZE, chunk_map: Callable = IN_PROCESS, on_bed: bool | None = None) -> Plan:
    """Choose ``n`` poses to measure (paper 2 §4, paper 1 §IV).

    ``candidates``: an array (N, 6) (mm, rad) or a CSV path (x, y, z, a, b, c in mm, deg);
    default ``n_candidates`` random poses of the workspace box, or with ``grid=k`` the k^6
    grid of the box. ``algorithm="circle"`` measures the ballbar circle test of a distance
    setup (``n`` poses in the ``circle_plane``, all of them, in order). ``algorithm="corners"``
    ignores them and draws among the 64 corners of the largest all-reachable box. Every
    candidate is checked (limits with the safety margin, measurability) before selection.

    ``margin``: a :class:`~pkmcal.planning.margins.SafetyMargin` (or ``DeltaSafetyMargin``); None (default) the
    machine's default margins (:func:`~pkmcal.planning.margins.default_margin`); a number,
    that margin on every limit (mm and degrees, as ``check_limits(margin=...)``).
    ``progress(stage)`` is called as each stage starts and returns that stage's
    ``(done, total)`` callback or None.

    The candidates are generated and checked in chunks of ``chunk_size`` poses
    (:func:`~pkmcal.planning.candidates.generate_candidates`, the "candidates" stage's
    callback called with (done, total) after every chunk), then only the accepted ones get
    their planning blocks (:func:`candidate_blocks`); both steps are mapped by ``chunk_map``
    (default :data:`~pkmcal.parallel.IN_PROCESS`: in this process, in order). The plan does not
    depend on ``chunk_size``.

    ``on_bed``: plan a Z probe's points on the bed (every candidate lowered to where its
    probe triggers, its probe point inside the build radius:
    :class:`~pkmcal.planning.candidates.Measurability`, "On the bed" in
    :mod:`pkmcal.planning.candidates`), as a printer probes; None (default) does so for a
    sensor that probes the bed (:func:`pkmcal.study.printed.probes_the_bed`); False plans
    the probe's points anywhere in the volume (a probe on gauge blocks).
    """
    from dataclasses import replace

    from pkmcal.study.printed import probes_the_bed

    bed = probes_the_bed(setup.sensor) if on_bed is None else bool(on_bed)
    if bed and not probes_the_bed(setup.sensor):
        raise PkmcalError(f"on-bed planning lowers a Z probe onto the bed; the setup's '{setup.sensor.kind}' sensor "
                          "is not a probe (plan it without on_bed)")
    measurability = replace(measurability, on_bed=bed)
    algorithm = str(algorithm).lower()
    if algorithm not in ALGORITHMS:
        raise PkmcalError(f"unknown selection algorithm '{algorithm}'; use one of {', '.join(ALGORITHMS)}")
    announce = progress or (lambda stage: None)
    rng = np.random.default_rng(seed)
    nominal = mechanism
    reachable, geometry_notes = mechanism.within_geometry()
    notes = list(geometry_notes)
    if margin is None:
        margin = resolve_margin(reachable)
    mechanism, check_margin = planning_checks(reachable, margin)
    kw = dict(margin=check_margin, measurability=measurability)
    chunked = dict(chunk_size=chunk_size, chunk_map=chunk_map, **kw)
    try:
        box, cand = _candidate_set(algorithm, candidates, grid, n, n_candidates, rng, nominal, mechanism, setup, notes,
                                   kw, chunked, announce, circle_plane)
    except PkmcalError as exc:
        if not bed:
            raise
        z = float(getattr(setup.sensor, "bed", np.zeros(3))[0])
        raise PkmcalError(f"{exc} (a Z probe's points are planned on the bed, z = {z:g} mm of the setup, where the "
                          f"probe triggers: machine '{nominal.name}' must reach it; give the bed's height in the "
                          "setup, or plan the points anywhere in the volume: --probe-anywhere, on_bed=False)") from None
    if n > len(cand.poses):
        raise PkmcalError(f"asked for {n} poses but only {len(cand.poses)} candidates are reachable and "
                          f"measurable ({cand.describe()}); ask for fewer poses or give more candidates")
    announce("planning model")
    model = model or planning_model(nominal, setup, method=method)   # the nominal's scaling (= observability)
    # in this process the block batches run on local threads, in place (candidate_blocks)
    G, ok = candidate_blocks(model, cand.poses, chunk_map=None if chunk_map is IN_PROCESS else chunk_map)
    if not ok.all():
        rejected = dict(cand.rejected)
        rejected["pose_not_solved"] = rejected.get("pose_not_solved", 0) + int((~ok).sum())
        cand = CandidateSet(cand.poses[ok], cand.n_tested, rejected, cand.kind)
        G = G[ok]
    sel = select(G, n, algorithm=algorithm, index=index, rng=rng, positions=cand.poses,
                 progress=announce(f"selection ({algorithm})"))
    poses = cand.poses[sel.chosen]
    return Plan(poses, nominal.ik(poses), sel, cand, model, box, margin, tuple(notes), bed)


def _candidate_set(algorithm, candidates, grid, n, n_candidates, rng, nominal, mechanism, setup, notes, kw, chunked,
                   announce, circle_plane):
    """(workspace box or None, the checked candidates) of :func:`plan_poses`."""
    box = None
    if algorithm == "corners":
        if candidates is not None:
            raise PkmcalError("--algorithm corners draws among the workspace-box corners; do not give --candidates")
        announce("workspace box")
        box = workspace_box(mechanism, setup, notes=notes, **kw)
        cand = generate_candidates(mechanism, setup, kind="corners", box=box,
                                   progress=announce("candidates"), **chunked)
        box = corner_box(mechanism, box, setup, **kw)
    elif algorithm == "circle":
        if candidates is not None or grid is not None:
            raise PkmcalError("--algorithm circle measures the ballbar's circle; do not give --candidates or --grid")
        if "circle-test" not in setup.sensor.abilities:
            raise PkmcalError(f"--algorithm circle is the ballbar circle test; the setup's '{setup.sensor.kind}' "
                              "sensor has none (use a 'sensor: distance' setup)")
        home = nominal.frame(np.asarray(nominal.home_pose, dtype=float)[None, :])
        circle = nominal.poses_from_frame(setup.sensor.circle_frames(n, home, circle_plane))
        cand = generate_candidates(mechanism, setup, kind="file", poses=circle, progress=announce("candidates"),
                                   **chunked)
        if len(cand.poses) < n:
            raise PkmcalError(f"{n - len(cand.poses)} of the {n} circle-test poses ({circle_plane} plane about pivot 1) "
                              f"cannot be measured ({cand.describe()}); move the pivot or shorten the bar")
    elif candidates is None:
        announce("workspace box")
        box = workspace_box(mechanism, setup, notes=notes, **kw)
        step = announce("candidates")
        if grid is not None:
            cand = generate_candidates(mechanism, setup, kind="grid", grid_per_axis=grid, box=box, progress=step,
                                       **chunked)
        else:
            cand = generate_candidates(mechanism, setup, kind="random", n=n_candidates, rng=rng, box=box,
                                       progress=step, **chunked)
    else:
        step = announce("candidates")
        poses = candidates if isinstance(candidates, np.ndarray) else read_candidates_csv(candidates, mechanism)
        poses = _wrapped(nominal, poses, notes)
        cand = generate_candidates(mechanism, setup, kind="file", poses=poses, progress=step, **chunked)
    return box, cand


def _wrapped(mechanism: Mechanism, poses: np.ndarray, notes: list[str]) -> np.ndarray:
    """Candidate ``poses`` with their angles brought into (−180°, 180°] by whole turns (the
    same orientations; :func:`~pkmcal.conventions.wrap_angle`), a note counting them."""
    poses = mechanism.as_pose_array(poses)
    angle = np.flatnonzero(np.asarray(mechanism.pose_is_angle, dtype=bool))
    wrapped = poses.copy()
    wrapped[:, angle] = wrap_angle(poses[:, angle])
    moved = np.any(wrapped != poses, axis=1) & np.all(np.isfinite(poses), axis=1)
    if moved.any():
        notes.append(f"{int(moved.sum())} of the {len(poses)} candidate poses have angles beyond ±180 deg; they are "
                     "planned and written with the same angles brought into (-180, 180] by whole turns")
    return wrapped


def pose_set_indices(mechanism: Mechanism, setup: MeasurementSetup, poses: np.ndarray, *,
                     method: str | None = None, model: PlanningModel | None = None) -> dict[str, float]:
    """O1..O5 of a pose set (same identifiable parameters and scaling as :func:`plan_poses`)."""
    model = model or planning_model(mechanism, setup, method=method)
    G, ok = model.blocks(mechanism.as_pose_array(poses))
    if not ok.all():
        bad = np.flatnonzero(~ok)
        raise PkmcalError(f"the pose of row(s) {', '.join(str(i + 1) for i in bad[:10])} cannot be solved at the "
                          "nominal machine (forward kinematics did not converge); remove them")
    return observability_indices(G)


def height_sigma(plan: Plan, n_values, *, check: np.ndarray | None = None) -> list[tuple[int, float]]:
    """The predicted first-layer error of a Z-probe plan as a function of its number of
    points: for each n of ``n_values``, the rms over ``check`` poses (default: the plan's
    accepted candidates, uniform over the reachable bed) of the standard deviation of the
    reading there, predicted from the identifiability of the n points the plan's selection
    (D-optimal, ``default``) chooses among the same candidates:

        σ²(c) = j_c D M⁻¹ D j_cᵀ,    M = Σ_{j chosen} G_jᵀ G_j,

    G_j the whitened, scaled blocks of the plan's model (the setup's noise: the probe's
    repeatability ``noise.reading`` and the carriages' ``noise.actuator``;
    :mod:`pkmcal.planning.blocks`), j_c the unweighted residual Jacobian at c on the same
    identifiable parameters and D their column scales. For a Z probe j_c δθ is the change
    of the height the model predicts for the nozzle commanded to c: the error of the first
    layer there. ``[(n, rms σ mm)]``; σ = inf where the n points do not determine the
    identifiable parameters (M singular)."""
    model = plan.model
    pool = plan.candidates.poses
    G, ok = candidate_blocks(model, pool)
    G = G[ok]
    check = pool if check is None else check
    from pkmcal.planning.blocks import raw_blocks

    J, solved, _ = raw_blocks(model.mechanism, model.setup, check, model.method, weighted=False,
                              columns=model.free_index)
    J = (J * model.scale)[solved]
    out = []
    for n in n_values:
        if int(n) * model.rows_per_pose < model.n_params or int(n) > len(G):
            out.append((int(n), float("inf")))      # fewer readings than parameters, or than candidates
            continue
        sel = select(G, int(n), algorithm="default")
        rows = G[sel.chosen].reshape(-1, G.shape[-1])
        try:
            L = np.linalg.cholesky(rows.T @ rows)
        except np.linalg.LinAlgError:
            out.append((int(n), float("inf")))
            continue
        # σ²(c) = |L⁻¹ j_cᵀ|² summed over c's rows
        V = np.linalg.solve(L, J.reshape(-1, J.shape[-1]).T)
        out.append((int(n), float(np.sqrt(np.sum(V ** 2) / len(J)))))
    return out


def points_for_height_sigma(plan: Plan, target: float, *, check: np.ndarray | None = None
                            ) -> tuple[int | None, list[tuple[int, float]]]:
    """The smallest number of points n whose predicted rms first-layer σ
    (:func:`height_sigma`) is at most ``target`` mm, found by doubling from the plan's own
    n then bisecting (σ falls about as 1/√n), among the plan's candidates; None when even
    all of them do not reach it. Also every (n, σ) evaluated, by n."""
    n_max = len(plan.candidates.poses)
    seen: dict[int, float] = {}

    def sigma(n: int) -> float:
        if n not in seen:
            seen[n] = height_sigma(plan, [n], check=check)[0][1]
        return seen[n]

    n_min = max(1, -(-plan.model.n_params // plan.model.rows_per_pose))
    lo, hi = n_min - 1, max(len(plan.poses), n_min)
    while sigma(hi) > target:
        if hi >= n_max:
            return None, sorted(seen.items())
        lo, hi = hi, min(2 * hi, n_max)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if mid < n_min or sigma(mid) > target:
            lo = mid
        else:
            hi = mid
    return hi, sorted(seen.items())

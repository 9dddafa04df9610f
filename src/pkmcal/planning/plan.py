"""Measurement planning end to end: candidates → per-pose blocks → selection → poses.

:func:`plan_poses` ties :mod:`.candidates` (reachable, measurable candidate poses),
:mod:`.blocks` (each candidate's whitened, scaled identification Jacobian rows on the
identifiable parameters) and :mod:`.selection` (the algorithms) together;
:func:`pose_set_indices` gives O1..O5 (:mod:`.indices`) of any pose set with the same
parameters and scaling, so ``pkmcal plan`` and ``pkmcal observability`` agree.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.planning.blocks import PlanningModel, planning_model
from pkmcal.planning.candidates import (
    CHUNK_SIZE,
    DEFAULT_MARGIN,
    CandidateSet,
    Measurability,
    checked_candidates,
    corner_box,
    read_candidates_csv,
    workspace_box,
)
from pkmcal.planning.indices import observability_indices
from pkmcal.planning.selection import ALGORITHMS, Progress, Selection, select
from pkmcal.sensors.base import MeasurementSetup


@dataclass(frozen=True)
class Plan:
    """Chosen ``poses`` (n, 6) (mm, rad) with their nominal actuator ``commands`` (n, l), the
    ``selection`` (indices into the candidates, O1..O5), the ``candidates`` and the model."""

    poses: np.ndarray
    commands: np.ndarray
    selection: Selection
    candidates: CandidateSet
    model: PlanningModel
    box: np.ndarray | None = None

    @property
    def indices(self) -> dict[str, float]:
        return self.selection.indices


def plan_poses(mechanism: Mechanism, setup: MeasurementSetup, n: int, *, algorithm: str = "default",
               index: str | None = None, candidates: np.ndarray | str | os.PathLike | None = None,
               n_candidates: int = 2000, grid: int | None = None, seed: int | None = None,
               margin: float = DEFAULT_MARGIN,
               measurability: Measurability = Measurability(), method: str | None = None,
               model: PlanningModel | None = None, progress: Progress | None = None,
               chunk_size: int = CHUNK_SIZE, chunk_map: Callable = map,
               candidate_progress: Progress | None = None) -> Plan:
    """Choose ``n`` poses to measure (paper 2 §4, paper 1 §IV).

    ``candidates``: an array (N, 6) (mm, rad) or a CSV path (x, y, z, a, b, c in mm, deg);
    default ``n_candidates`` random poses of the workspace box, or with ``grid=k`` the k^6
    grid of the box. ``algorithm="corners"``
    ignores them and draws among the 64 corners of the largest all-reachable box. Every
    candidate is checked (limits with ``margin``, measurability) before selection.

    The candidates are generated, checked and reduced to their planning blocks chunk by
    chunk (:func:`~pkmcal.planning.candidates.checked_candidates`: ``chunk_size`` poses at a
    time, mapped by ``chunk_map``, ``candidate_progress`` called with (done, total)); only
    accepted candidates get blocks. ``progress`` is the selection's.
    """
    algorithm = str(algorithm).lower()
    if algorithm not in ALGORITHMS:
        raise PkmcalError(f"unknown selection algorithm '{algorithm}'; use one of {', '.join(ALGORITHMS)}")
    rng = np.random.default_rng(seed)
    kw = dict(margin=margin, measurability=measurability)
    model = model or planning_model(mechanism, setup, method=method)
    chunked = dict(chunk_size=chunk_size, chunk_map=chunk_map, progress=candidate_progress, reduce=model.blocks, **kw)
    box = None
    if algorithm == "corners":
        if candidates is not None:
            raise PkmcalError("--algorithm corners draws among the workspace-box corners; do not give --candidates")
        box = workspace_box(mechanism, setup, **kw)
        cand, (G, solved) = checked_candidates(mechanism, setup, kind="corners", box=box, **chunked)
        box = corner_box(mechanism, box, setup, **kw)
    elif candidates is None:
        box = workspace_box(mechanism, setup, **kw)
        if grid is not None:
            cand, (G, solved) = checked_candidates(mechanism, setup, kind="grid", grid_per_axis=grid, box=box,
                                                   **chunked)
        else:
            cand, (G, solved) = checked_candidates(mechanism, setup, kind="random", n=n_candidates, rng=rng, box=box,
                                                   **chunked)
    else:
        poses = candidates if isinstance(candidates, np.ndarray) else read_candidates_csv(candidates, mechanism)
        cand, (G, solved) = checked_candidates(mechanism, setup, kind="file", poses=poses, **chunked)
    if len(cand.poses) == 0:
        raise PkmcalError(f"none of the {cand.n_tested} candidate poses is reachable and measurable "
                          f"(rejected by reason: {cand.rejected}); check the file, the margin and the sensor")
    if n > len(cand.poses):
        raise PkmcalError(f"asked for {n} poses but only {len(cand.poses)} candidates are reachable and "
                          f"measurable ({cand.describe()}); ask for fewer poses or give more candidates")
    if not solved.all():
        rejected = dict(cand.rejected)
        rejected["pose_not_solved"] = rejected.get("pose_not_solved", 0) + int((~solved).sum())
        cand = CandidateSet(cand.poses[solved], cand.n_tested, rejected, cand.kind)
        G = G[solved]
    sel = select(G, n, algorithm=algorithm, index=index, rng=rng, positions=cand.poses, progress=progress)
    poses = cand.poses[sel.chosen]
    return Plan(poses, mechanism.ik(poses), sel, cand, model, box)


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

"""Measurement planning end to end: candidates → per-pose blocks → selection → poses.

:func:`plan_poses` ties :mod:`.candidates` (reachable, measurable candidate poses),
:mod:`.blocks` (each candidate's whitened, scaled identification Jacobian rows on the
identifiable parameters) and :mod:`.selection` (the algorithms) together;
:func:`pose_set_indices` gives O1..O5 (:mod:`.indices`) of any pose set with the same
parameters and scaling, so ``pkmcal plan`` and ``pkmcal observability`` agree.

Candidates are checked inside the nominal machine's limits by the safety margins of
:mod:`.margins` (by default those a real machine with joint errors of 3 mm survives), and
the stages report progress through an optional ``progress(stage)`` announcer
(:data:`pkmcal.progress.Stages`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.planning.blocks import PlanningModel, planning_model
from pkmcal.planning.candidates import (
    CandidateSet,
    Measurability,
    check_candidates,
    corner_box,
    generate_candidates,
    read_candidates_csv,
    workspace_box,
)
from pkmcal.planning.indices import observability_indices
from pkmcal.planning.margins import SafetyMargin, planning_machine, resolve_margin
from pkmcal.planning.selection import ALGORITHMS, Selection, select
from pkmcal.progress import Stages
from pkmcal.sensors.base import MeasurementSetup


@dataclass(frozen=True)
class Plan:
    """Chosen ``poses`` (n, 6) (mm, rad) with their nominal actuator ``commands`` (n, l), the
    ``selection`` (indices into the candidates, O1..O5), the ``candidates``, the model and the
    safety ``margin`` the candidates were checked with (a :class:`SafetyMargin`, a single
    number on every limit, or None for a machine whose limits take none)."""

    poses: np.ndarray
    commands: np.ndarray
    selection: Selection
    candidates: CandidateSet
    model: PlanningModel
    box: np.ndarray | None = None
    margin: SafetyMargin | float | None = None

    def describe_margin(self) -> str:
        """The safety margin in words (what ``pkmcal plan`` prints)."""
        if self.margin is None:
            return "none (this machine's limits take no safety margin)"
        if isinstance(self.margin, SafetyMargin):
            return self.margin.describe()
        return f"{self.margin:g} on every limit (mm for stroke and clearance, degrees for joint tilts)"

    @property
    def indices(self) -> dict[str, float]:
        return self.selection.indices


def plan_poses(mechanism: Mechanism, setup: MeasurementSetup, n: int, *, algorithm: str = "default",
               index: str | None = None, candidates: np.ndarray | str | os.PathLike | None = None,
               n_candidates: int = 2000, grid: int | None = None, seed: int | None = None,
               margin: SafetyMargin | float | None = None,
               measurability: Measurability = Measurability(), method: str | None = None,
               model: PlanningModel | None = None, progress: Stages | None = None) -> Plan:
    """Choose ``n`` poses to measure (paper 2 §4, paper 1 §IV).

    ``candidates``: an array (N, 6) (mm, rad) or a CSV path (x, y, z, a, b, c in mm, deg);
    default ``n_candidates`` random poses of the workspace box, or with ``grid=k`` the k^6
    grid of the box. ``algorithm="corners"``
    ignores them and draws among the 64 corners of the largest all-reachable box. Every
    candidate is checked (limits with the safety margin, measurability) before selection.

    ``margin``: a :class:`~pkmcal.planning.margins.SafetyMargin`; None (default) the
    machine's default margins (:func:`~pkmcal.planning.margins.default_margin`); a number,
    that margin on every limit (mm and degrees, as ``check_limits(margin=...)``).
    ``progress(stage)`` is called as each stage starts and returns that stage's
    ``(done, total)`` callback or None.
    """
    algorithm = str(algorithm).lower()
    if algorithm not in ALGORITHMS:
        raise PkmcalError(f"unknown selection algorithm '{algorithm}'; use one of {', '.join(ALGORITHMS)}")
    announce = progress or (lambda stage: None)
    rng = np.random.default_rng(seed)
    if margin is None:
        margin = resolve_margin(mechanism)
    nominal = mechanism
    if isinstance(margin, SafetyMargin) or margin is None:
        mechanism = planning_machine(mechanism, margin)
        kw = dict(margin=0.0, measurability=measurability)
    else:
        kw = dict(margin=float(margin), measurability=measurability)
    box = None
    if algorithm == "corners":
        if candidates is not None:
            raise PkmcalError("--algorithm corners draws among the workspace-box corners; do not give --candidates")
        announce("workspace box")
        box = workspace_box(mechanism, setup, **kw)
        announce("candidates")
        cand = generate_candidates(mechanism, setup, kind="corners", box=box, **kw)
        box = corner_box(mechanism, box, setup, **kw)
    elif candidates is None:
        announce("workspace box")
        box = workspace_box(mechanism, setup, **kw)
        announce("candidates")
        if grid is not None:
            cand = generate_candidates(mechanism, setup, kind="grid", grid_per_axis=grid, box=box, **kw)
        else:
            cand = generate_candidates(mechanism, setup, kind="random", n=n_candidates, rng=rng, box=box, **kw)
    else:
        announce("candidates")
        poses = candidates if isinstance(candidates, np.ndarray) else read_candidates_csv(candidates, mechanism)
        chk = check_candidates(mechanism, setup, poses, **kw)
        if not chk.ok.any():
            raise PkmcalError(f"none of the {len(poses)} candidate poses is reachable and measurable "
                              f"(rejected by reason: {chk.counts()}); check the file, the margin and the sensor")
        cand = CandidateSet(mechanism.as_pose_array(poses)[chk.ok], len(poses), chk.counts(), "file")
    if n > len(cand.poses):
        raise PkmcalError(f"asked for {n} poses but only {len(cand.poses)} candidates are reachable and "
                          f"measurable ({cand.describe()}); ask for fewer poses or give more candidates")
    announce("planning model")
    model = model or planning_model(nominal, setup, method=method)   # the nominal's scaling (= observability)
    G, ok = model.blocks(cand.poses)
    if not ok.all():
        rejected = dict(cand.rejected)
        rejected["pose_not_solved"] = rejected.get("pose_not_solved", 0) + int((~ok).sum())
        cand = CandidateSet(cand.poses[ok], cand.n_tested, rejected, cand.kind)
        G = G[ok]
    sel = select(G, n, algorithm=algorithm, index=index, rng=rng, positions=cand.poses,
                 progress=announce(f"selection ({algorithm})"))
    poses = cand.poses[sel.chosen]
    return Plan(poses, nominal.ik(poses), sel, cand, model, box, margin)


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

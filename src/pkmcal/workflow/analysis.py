"""Analyses of a pose set before measuring it (``pkmcal identifiability``, ``observability``):
which parameters a setup can identify from the poses
(:func:`pkmcal.identification.identifiability.identifiability`: the rank of the column-scaled,
noise-weighted identification Jacobian, its null space named, the gauge; with ``suggest`` what
to measure next, :func:`pkmcal.identification.advice.advise`), and which rows of a pose file
the machine cannot reach (an analysis of poses the machine cannot take describes a plan it
cannot carry out).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pkmcal.errors import PkmcalError


def unreachable_notes(machine, poses: np.ndarray, path: str) -> list[str]:
    """One warning per kind of limit that poses (N, n) of the file ``path`` violate on
    ``machine``, naming their rows (data rows of the file, 1-based): an analysis of poses
    the machine cannot take describes a plan it cannot carry out."""
    with np.errstate(all="ignore"):
        report = machine.check_limits(poses)
    bad = ~report.ok
    if not bad.any():
        return []
    rows = np.flatnonzero(bad) + 1
    shown = ", ".join(str(int(k)) for k in rows[:20]) + (" ..." if len(rows) > 20 else "")
    kinds = ", ".join(f"{name} ({int(np.count_nonzero(v))})" for name, v in report.violations.items() if v.any())
    return [f"{int(bad.sum())} of the {len(poses)} poses of {path} violate the machine's limits ({kinds}): rows "
            f"{shown} (data rows, 1-based); the numbers above assume the machine reaches them"]


@dataclass
class IdentifiabilityAnalysis:
    """What :func:`identifiability_of` found: the machine as the sensor reads it, the setup,
    the poses (internal units), the :class:`~pkmcal.identification.identifiability.IdentifiabilityReport`,
    warnings (``notes``) and, when asked, the ranked suggestions (``advice``) and the
    accuracy predicted over the workspace (``predicted``:
    :func:`pkmcal.identification.iso9283.accuracy_map`)."""

    nominal: Any
    setup: Any
    poses: np.ndarray
    report: Any
    notes: list[str] = field(default_factory=list)
    advice: Any = None
    predicted: Any = None

    def write_accuracy_map(self, path) -> None:
        """Draw the predicted accuracy over the workspace into ``path`` (``.png`` or ``.svg``)."""
        from pkmcal.io.atomic import atomic_write_bytes
        from pkmcal.report.figures import accuracy_map_figure, render

        if self.predicted is None:
            raise PkmcalError("the accuracy map draws the predicted accuracy: analyse with accuracy=True "
                              "(--accuracy)")
        drawn = render(accuracy_map_figure(self.predicted), "accuracy-map", "")
        atomic_write_bytes(path, drawn.svg if str(path).lower().endswith(".svg") else drawn.png)


def identifiability_of(machine, setup, poses, *, method: str | None = None, free=None, fix=None,
                       suggest: bool = False, accuracy: bool = False, mapping=None) -> IdentifiabilityAnalysis:
    """``pkmcal identifiability MACHINE --setup SETUP --poses POSES.csv``: ``machine`` and
    ``setup`` files, built-in names or objects; ``poses`` a pose file (read with ``mapping``)
    or an (N, n) array; ``free`` and ``fix`` names or patterns (``free`` adds to the setup's
    free sensor parameters, ``fix="auto"``: the suggested gauge); ``suggest``: rank what to
    measure next; ``accuracy``: predict the accuracy a calibration on these poses gives over
    the workspace, from the setup's noise (the covariance of these poses carried to the tool
    point)."""
    import os

    from pkmcal.identification.identifiability import identifiability
    from pkmcal.io.tables import read_poses
    from pkmcal.workflow.calibration import merged_free, names_of
    from pkmcal.workflow.inputs import machine_and_setup

    nominal, setup = machine_and_setup(machine, setup)   # pose pairs for printed distances
    from_file = isinstance(poses, (str, os.PathLike))
    x = read_poses(poses, nominal, mapping) if from_file else np.asarray(poses, dtype=float)
    fix_names = names_of(fix)
    fix_names = None if fix_names == ["auto"] else fix_names
    free_names = merged_free(names_of(free), setup)
    rep = identifiability(nominal, setup, x, method=method, free=free_names, fix=fix_names)
    notes = unreachable_notes(nominal, x, os.fspath(poses) if from_file else "the poses")
    if rep.n_unsolved:
        notes.append(f"{rep.n_unsolved} of the {len(x)} poses were left out: their readings or pose cannot be "
                     "computed on this machine (outside the reach of a chain, or the pose does not solve)")
    advice = None
    if suggest:   # identification/advice.py: the candidate additions ranked
        from pkmcal.identification.advice import advise

        advice = advise(nominal, setup, x, method=method, free=free_names, fix=fix_names)
    predicted = None
    if accuracy:   # identification/iso9283.py: the covariance of these poses carried over the workspace
        from pkmcal.identification.iso9283 import accuracy_map

        predicted = accuracy_map(nominal, setup, x, method=method, report=rep)
    return IdentifiabilityAnalysis(nominal, setup, x, rep, notes, advice, predicted)


__all__ = ["IdentifiabilityAnalysis", "identifiability_of", "unreachable_notes"]

"""A warning for commands that analyse poses a machine may not reach (``identifiability``,
``observability``): which rows of the pose file violate which limits."""

from __future__ import annotations

import numpy as np


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

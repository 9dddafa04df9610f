"""Three-sphere intersection (trilateration), batched: the forward kinematics of every
delta, whose effector joint centre is at known distances (the arms) from three known
points (the carriage joints of a linear delta, the elbows of a rotary one).

With p1, p2, p3 the centres and L1..L3 the radii: e_x along p2 − p1 (d = |p2 − p1|),
i = e_x·(p3 − p1), e_y the unit rest of p3 − p1 (j its length), e_z = e_x × e_y turned
upwards; then x = (L1² − L2² + d²)/2d, y = (L1² − L3² + i² + j²)/2j − i x/j,
z = ±sqrt(L1² − x² − y²), and the delta's effector is the solution below the centres.
"""

from __future__ import annotations

import numpy as np


def trilaterate(C: np.ndarray, L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points q (N, 3) at distances L (3,) from the three centres C (N, 3, 3), the solution
    below the centres' plane (the plane's normal taken upwards); ``ok`` (N,) False where the
    spheres do not meet or the centres are collinear."""
    p1, p2, p3 = C[:, 0], C[:, 1], C[:, 2]
    ex = p2 - p1
    d = np.linalg.norm(ex, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ex = ex / d[:, None]
        t = p3 - p1
        i = np.einsum("nk,nk->n", ex, t)
        ey = t - i[:, None] * ex
        j = np.linalg.norm(ey, axis=1)
        ey = ey / j[:, None]
        ez = np.cross(ex, ey)
        ez = np.where(ez[:, 2:3] < 0, -ez, ez)      # upwards
        x = (L[0] ** 2 - L[1] ** 2 + d**2) / (2 * d)
        y = (L[0] ** 2 - L[2] ** 2 + i**2 + j**2) / (2 * j) - i / j * x
        z2 = L[0] ** 2 - x**2 - y**2
        ok = np.isfinite(z2) & (z2 >= 0) & (j > 1e-9 * d)
        z = np.sqrt(np.where(ok, z2, 0.0))
    q = p1 + x[:, None] * ex + y[:, None] * ey - z[:, None] * ez
    return q, ok



__all__ = ["trilaterate"]

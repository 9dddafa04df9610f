"""Error maps (paper 1 §IV, Figs 4–9): where in the workspace parameter errors show most.

A "real" machine is the nominal one with every kinematic parameter off by a random error
in [−e, +e] (paper 1: e = 0.1 mm). Commanded to pose x through the nominal inverse
kinematics, λ = IK(x, ρ₀), it goes to x' = FK(λ, ρ₀ + δρ); the pose error at x is

    e_pos(x) = ‖p' − p‖ (mm),      e_ori(x) = ∠(R' Rᵀ) (rad).

A *slice* varies one pose coordinate across the workspace box with the other five fixed at
a random point of the box; several slices ("curves", paper 1 draws 20 of 100) per
coordinate show whether the error peaks at the box boundary (paper 1's conclusion:
observability is largest at the workspace boundary, and at the highest z). Poses outside
the nominal machine's limits are left blank (NaN).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from pkmcal.conventions import POSE_COLUMNS
from pkmcal.errors import PkmcalError
from pkmcal.identification import verification
from pkmcal.mechanisms.base import Mechanism


@dataclass(frozen=True)
class ErrorSlices:
    """Slices of the pose-error map: for coordinate k, ``values[k]`` (n_points,) of that
    coordinate and ``position[k]``, ``orientation[k]`` (n_curves, n_points) errors
    (mm, rad; NaN where unreachable); ``bases[k]`` (n_curves, 6) the fixed poses."""

    values: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    bases: np.ndarray
    magnitude: float


def pose_errors(nominal: Mechanism, real: Mechanism, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(e_pos (N,) mm, e_ori (N,) rad) of ``real`` commanded to ``poses`` by ``nominal``
    (module docstring): :func:`pkmcal.identification.verification.pose_errors` with none of
    the real machine's limits checked (the maps blank poses by the nominal limits); NaN where
    the real machine's FK does not converge."""
    poses = nominal.as_pose_array(poses)
    every_limit = tuple(real.check_limits(poses[:1]).violations)
    e = verification.pose_errors(nominal, real, poses, ignore_limits=every_limit)
    return e.position, e.orientation


def error_slices(nominal: Mechanism, box: np.ndarray, *, magnitude: float = 0.1, n_curves: int = 20,
                 n_points: int = 41, rng: np.random.Generator | None = None, real: Mechanism | None = None,
                 margin: float = 0.0) -> ErrorSlices:
    """Pose-error slices along each of the six coordinates of ``box`` (6, 2) (module doc).

    ``real`` defaults to ``nominal`` with U(−magnitude, magnitude) errors on every parameter.
    """
    if nominal.n_dof != 6:
        raise PkmcalError(f"error maps are drawn for 6-coordinate machines (hexapods); '{nominal.name}' has "
                          f"{nominal.n_dof} pose coordinates")
    rng = np.random.default_rng() if rng is None else rng
    box = np.asarray(box, dtype=float).reshape(6, 2)
    if real is None:
        from pkmcal.identification.simulation import perturb_machine

        real = perturb_machine(nominal, magnitude, rng)
    values = np.linspace(box[:, 0], box[:, 1], n_points).T                      # (6, n_points)
    pos = np.full((6, n_curves, n_points), np.nan)
    ori = np.full((6, n_curves, n_points), np.nan)
    bases = box[:, 0] + rng.random((6, n_curves, 6)) * (box[:, 1] - box[:, 0])
    for k in range(6):                                                           # 6 coordinates, vectorised inside
        poses = np.repeat(bases[k][:, None, :], n_points, axis=1)
        poses[:, :, k] = values[k]
        flat = poses.reshape(-1, 6)
        ok = nominal.check_limits(flat, margin=margin).ok
        e_p, e_o = pose_errors(nominal, real, flat)
        pos[k] = np.where(ok, e_p, np.nan).reshape(n_curves, n_points)
        ori[k] = np.where(ok, e_o, np.nan).reshape(n_curves, n_points)
    return ErrorSlices(values, pos, ori, bases, float(magnitude))


def plot_error_maps(slices: ErrorSlices, path: str | os.PathLike, title: str = "") -> None:
    """Write the slices as a figure (PNG or SVG, by the file extension): one column per
    coordinate, position error (mm) on top, orientation error (mrad) below."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in (".png", ".svg"):
        raise PkmcalError(f"error map '{path}': use a .png or .svg file name")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pkmcal.io.atomic import atomic_write_bytes

    fig, axes = plt.subplots(2, 6, figsize=(18, 6), sharey="row", constrained_layout=True)
    for k, name in enumerate(POSE_COLUMNS):
        x = slices.values[k] if k < 3 else np.rad2deg(slices.values[k])
        for c in range(slices.position.shape[1]):
            axes[0, k].plot(x, slices.position[k, c], lw=0.8)
            axes[1, k].plot(x, 1e3 * slices.orientation[k, c], lw=0.8)
        axes[1, k].set_xlabel(f"{name} ({'mm' if k < 3 else 'deg'})")
    axes[0, 0].set_ylabel("position error (mm)")
    axes[1, 0].set_ylabel("orientation error (mrad)")
    fig.suptitle(title or f"pose error from ±{slices.magnitude:g} mm parameter errors (paper 1 Figs 4–9)")
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format=ext[1:], dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())

"""A machine's kinematics over a table of poses or readings, with the limits each row
violates: the values ``pkmcal ik`` and ``pkmcal fk`` write (file units: mm and degrees).

* :func:`ik_columns`: poses → leg lengths L_i = ‖p + R a_i − b_i‖, readings
  λ_i = L_i − L0_i (paper 2 eq. 1–2) and the reach verdict of each pose
  (:meth:`pkmcal.mechanisms.base.LimitReport.verdicts`).
* :func:`fk_columns`: readings λ_i (or lengths L_i) → poses by Newton–Raphson (see
  :meth:`pkmcal.mechanisms.hexapod.Hexapod.fk`), with per row a convergence flag, an
  assembly-mode flag (:attr:`pkmcal.mechanisms.base.FKResult.same_branch`) and the limits
  the pose violates ('not-solved' where FK did not converge).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.io.tables import from_file_units, to_file_units


def parse_pose_option(text: str, mech, option: str) -> np.ndarray:
    """A pose given on the command line as ``x,y,z,a,b,c`` (mm, deg) → internal units."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != mech.n_dof:
        raise PkmcalError(f"{option} '{text}': needs {mech.n_dof} comma-separated numbers "
                          f"{','.join(mech.pose_names)} (mm, deg), got {len(parts)}")
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise PkmcalError(f"{option} '{text}': not all of {','.join(mech.pose_names)} are numbers") from None
    if not np.all(np.isfinite(values)):
        raise PkmcalError(f"{option} '{text}': the pose must be finite")
    return from_file_units(values, mech.pose_is_angle)


def ik_columns(mech, file_poses: np.ndarray) -> tuple[dict[str, np.ndarray], int]:
    """``(columns, n_violating)`` of poses ``file_poses`` (N, n_dof; mm, deg): the pose
    columns, ``l1..`` (leg lengths, mm, for a machine with the leg-lengths ability), the
    actuator readings (mm, or deg for rotary actuators) and ``reachable`` ('ok' or the
    violated limits joined by '+'); and how many poses violate a limit."""
    internal = from_file_units(file_poses, mech.pose_is_angle)
    with np.errstate(all="ignore"):
        readings = mech.ik(internal)
        limits = mech.check_limits(internal)
        lengths = mech.leg_lengths(internal) if "leg-lengths" in mech.abilities else None
    columns: dict[str, np.ndarray] = {n: file_poses[:, k] for k, n in enumerate(mech.pose_names)}
    if lengths is not None:
        columns.update({f"l{i + 1}": lengths[:, i] for i in range(lengths.shape[1])})
    readings = to_file_units(readings, mech.actuator_is_angle)
    columns.update({n: readings[:, i] for i, n in enumerate(mech.actuator_names)})
    columns["reachable"] = limits.verdicts()
    return columns, int(np.count_nonzero(~limits.ok))


@dataclass(frozen=True)
class FKRows:
    """:func:`fk_columns`' result: the columns ``pkmcal fk`` writes and, per row, whether FK
    converged, stayed on the start pose's assembly mode, and violates a limit."""

    columns: dict
    converged: np.ndarray
    same_branch: np.ndarray
    iterations: np.ndarray
    violating: np.ndarray


def fk_columns(mech, values: np.ndarray, by_readings: bool, guess: np.ndarray | None = None) -> FKRows:
    """FK of the rows ``values``: actuator readings (``by_readings``; mm, or deg for rotary
    actuators) or leg lengths (mm), from ``guess`` (internal units; None: the home pose).
    Columns: the pose (nan where FK did not converge; mm, deg), ``converged``,
    ``iterations``, ``same_branch`` (0 where not converged) and ``reachable``."""
    with np.errstate(all="ignore"):
        if by_readings:
            result = mech.fk(from_file_units(values, mech.actuator_is_angle), guess=guess)
        else:
            result = mech.fk_lengths(values, guess=guess)
        conv = np.asarray(result.converged, dtype=bool)
        same = np.asarray(result.same_branch, dtype=bool)
        verdicts = np.array(mech.check_limits(np.where(conv[:, None], result.poses, mech.home_pose)).verdicts(),
                            dtype=object)
    verdicts[~conv] = "not-solved"
    poses = to_file_units(result.poses, mech.pose_is_angle)
    poses[~conv] = np.nan
    iterations = np.asarray(result.iterations, dtype=int)
    columns: dict[str, np.ndarray] = {n: poses[:, k] for k, n in enumerate(mech.pose_names)}
    columns["converged"] = conv.astype(int)
    columns["iterations"] = iterations
    columns["same_branch"] = (same & conv).astype(int)
    columns["reachable"] = verdicts.tolist()
    return FKRows(columns, conv, same, iterations, conv & (verdicts != "ok"))


__all__ = ["FKRows", "fk_columns", "ik_columns", "parse_pose_option"]

"""Held-out tool errors of a machine that settles at static equilibrium (paper 3 §3, Fig. 5/8).

The tracker reading each held-out commanded pose x_c should give is y* = h(x_c, θ_setup).
A model (mechanism M, sensor S_M) commands it as c = IK(S_M⁻¹(y*), ρ_M)
(:func:`commands_for_targets`; for n = 3 at the commanded plate angle); the real machine
settles under the setup's stiffness and load (:func:`pkmcal.identification.simulation.settle`,
paper 3 eq. 1–3), and the tool error is

    e = ‖h(x_eq, θ_setup) − y*‖ (mm),      plate-angle error φ_eq − φ_c (n = 3).

"Before" is the nominal machine with the setup's sensor, "after" the calibrated machine with
the sensor parameters identified with it (its file's ``calibration.sensor`` block,
:func:`calibrated_sensor`). :func:`pkmcal.identification.verification.verify` reports them
(``compare="tool"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pkmcal.identification.simulation import settle
from pkmcal.io.tables import to_file_units
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.statics import StaticsModel
from pkmcal.sensors.base import MeasurementSetup


def commands_for_targets(mechanism: Mechanism, sensor, targets: np.ndarray, angles=None,
                         statics: StaticsModel | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Poses (N, n) and commanded readings (N, l) that put the tool on ``targets`` (N, 2,
    tracker frame) according to the model: x = S⁻¹(y*) (``sensor.poses_for_readings``, for
    n = 3 at the plate ``angles``), c = IK(x, ρ). With ``statics`` (a model that knows the
    stiffness K and load F, paper 3 ref. [7]) the commands are pre-deflected so that the
    model's equilibrium is x: c = IK(x) − Γ (ΓᵀKΓ)⁻¹ J_fᵀ F at x, which satisfies
    Γᵀ K (IK(x) − c) = J_fᵀ F exactly (:mod:`pkmcal.mechanisms.statics`)."""
    targets = np.atleast_2d(np.asarray(targets, dtype=float))
    ang = np.array(mechanism.pose_is_angle, dtype=bool)
    ref = np.tile(mechanism.home_pose, (targets.shape[0], 1))    # the plate rotation at the angles
    if angles is not None:
        ref[:, ang] = np.reshape(angles, (targets.shape[0], -1))
    poses = mechanism.poses_from_frame(sensor.frame_for_readings(targets, mechanism.frame(ref).R))
    poses[:, ang] = ref[:, ang]                                     # the given angles, exactly
    c = mechanism.ik(poses)
    if statics is not None and statics.load is not None:
        K = statics.stiffness_for(mechanism)
        G = mechanism.actuator_pose_jacobian(poses)
        Jf = mechanism.pose_jacobian_from_twist(sensor.tool_frame_jacobian(mechanism.frame(poses)), poses)
        b = np.einsum("nki,k->ni", Jf, statics.load)
        dx = np.linalg.solve(np.einsum("nli,l,nlj->nij", G, K, G), b[..., None])
        c = c - (G @ dx)[..., 0]
    return poses, c


def calibrated_sensor(machine: Mechanism, sensor):
    """``sensor`` with the parameters identified together with ``machine`` (its file's
    ``calibration.sensor`` block: names → values in file units, mm and degrees for the
    parameters the sensor declares angles, ``sensor.param_is_angle``), or ``sensor`` itself
    when the machine has none."""
    record = (machine.metadata or {}).get("calibration") or {}
    values = record.get("sensor") if isinstance(record, dict) else None
    if not values:
        return sensor
    from pkmcal.identification.heldout import sensor_from_values

    return sensor_from_values(sensor, {k: float(v) for k, v in values.items()},
                              f"machine '{machine.name}': calibration.sensor")


def sensor_calibration_block(sensor) -> dict:
    """The ``calibration.sensor`` block (file units: mm, degrees for the parameters of
    ``sensor.param_is_angle``) of an identified sensor; :func:`calibrated_sensor` reads it."""
    values = to_file_units(sensor.params, sensor.param_is_angle)
    return {k: float(v) for k, v in zip(sensor.param_names, values)}


@dataclass(frozen=True)
class ToolErrors:
    """Per held-out pose: tool-point error (mm), plate-angle error (rad; NaN for n = 2),
    ``valid`` where the real machine settled within its limits (``dropped`` the others)."""

    model: str
    tool: np.ndarray
    angle: np.ndarray
    valid: np.ndarray
    dropped: dict[int, str] = field(default_factory=dict)

    def summary(self, mask: np.ndarray) -> dict:
        """``{poses, tool_mean_mm, tool_max_mm, tool_rms_mm[, angle_*_deg]}`` over ``mask``."""
        from pkmcal.identification.verification import error_stats

        out: dict = {"poses": int(np.count_nonzero(mask))}
        out.update(error_stats(self.tool[mask], "tool", "mm"))
        if not np.all(np.isnan(self.angle)):
            out.update(error_stats(np.rad2deg(self.angle[mask]), "angle", "deg"))
        return out


def tool_errors(model: Mechanism, model_sensor, real: Mechanism, setup: MeasurementSetup, poses: np.ndarray,
                name: str = "model", ignore_limits: tuple[str, ...] = (), target_sensor=None,
                model_statics: StaticsModel | None = None) -> ToolErrors:
    """Tool errors of ``real`` commanded through (``model``, ``model_sensor``) at the
    held-out ``poses`` (module docstring). The targets are y* = h(x_c) of ``target_sensor``
    (default the setup's): a simulated experiment whose true tool point (the setup's sensor)
    differs from the nominal one passes the nominal sensor, so that "before" includes the
    tool-point error, as on a real machine whose tool point is only known nominally.
    ``model_statics``: the model also knows stiffness and load and pre-deflects its
    commands (:func:`commands_for_targets`)."""
    x_c = model.as_pose_array(poses)
    targets = (setup.sensor if target_sensor is None else target_sensor).predict(model.frame(x_c))
    angle_columns = np.flatnonzero(np.asarray(model.pose_is_angle, dtype=bool))
    plate = int(angle_columns[0]) if len(angle_columns) == 1 else None   # a planar machine's plate angle
    angles = None if plate is None else x_c[:, plate]
    with np.errstate(invalid="ignore"):
        x_m, commands = commands_for_targets(model, model_sensor, targets, angles, model_statics)
    x_eq, _, ok, dropped = settle(real, setup, commands, x_m, ignore_limits)
    y = setup.sensor.predict(real.frame(x_eq))
    tool = np.where(ok, np.linalg.norm(y - targets, axis=1), np.nan)
    angle = np.full(len(x_c), np.nan) if plate is None else np.where(ok, x_eq[:, plate] - x_c[:, plate], np.nan)
    return ToolErrors(model=name, tool=tool, angle=angle, valid=ok, dropped=dropped)

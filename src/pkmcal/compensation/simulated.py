"""Errors no kinematic parameter explains, added to simulated campaigns: a warped bed under a
printer's probe and a compliant hexapod's sag under its load. They stand in for a real
machine when showing what a correction gains (docs/compensation.md, the tests).

* :class:`BedBump`: the bed surface w(x, y) = A exp(−|(x, y) − c|² / (2 s²)) above the flat
  bed; a probe reading (its height above the bed, :mod:`pkmcal.sensors.z_probe`) is lower by
  w at the probe point: y = P_z − w(P_xy).
* :class:`Sag`: the legs of stiffness k (N/mm, all alike) give way under the weight F (N)
  of a load whose centre of mass sits at c (mm) in the platform frame: the wrench
  (F, (R c) × F) about the platform origin, W = Tᵀ (F, (R c) × F) on the pose coordinates
  (T = ∂twist/∂x, :meth:`Mechanism.frame_jacobians`; its torque turns with the platform,
  which makes the sag depend on the orientation), and the actuator forces f solve Aᵀ f = W
  (A = ∂q/∂x, the pose Jacobian of the readings), the legs shorten by f/k, and the
  platform moves by δx = A⁻¹ f / k = (Aᵀ A)⁻¹ W / k (mm, rad; first order, the stiffness
  matrix Aᵀ k A of a parallel machine), a smooth function of the pose that no geometric
  parameter reproduces. The encoders read the commands: only the pose and what the sensor
  reads change.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pkmcal.identification.simulation import SimulationResult
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import Sensor


@dataclass(frozen=True)
class BedBump:
    """A Gaussian bump of ``amplitude`` mm at ``centre`` (x, y) mm, of width ``width`` mm."""

    amplitude: float
    centre: tuple[float, float]
    width: float

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        d = np.asarray(xy, dtype=float)[:, :2] - np.asarray(self.centre, dtype=float)
        return self.amplitude * np.exp(-np.sum(d * d, axis=1) / (2.0 * self.width**2))


@dataclass(frozen=True)
class Sag:
    """Leg compliance under a load (module docstring): ``weight`` F (3,) N in the base frame,
    ``centre`` c (3,) mm its centre of mass in the platform frame, ``stiffness`` k (N/mm)
    of every actuator."""

    weight: tuple[float, float, float]
    centre: tuple[float, float, float]
    stiffness: float

    def displacement(self, machine: Mechanism, poses: np.ndarray) -> np.ndarray:
        """δx (N, n) = (Aᵀ A)⁻¹ W / k at ``poses``."""
        poses = machine.as_pose_array(poses)
        A = machine.actuator_pose_jacobian(poses)
        F = np.broadcast_to(np.asarray(self.weight, dtype=float), (len(A), 3))
        arm = machine.frame(poses).R @ np.asarray(self.centre, dtype=float)
        T, _ = machine.frame_jacobians(poses)
        W = np.einsum("nki,nk->ni", T, np.concatenate([F, np.cross(arm, F)], axis=1))
        return np.linalg.solve(np.swapaxes(A, 1, 2) @ A, W[..., None])[..., 0] / self.stiffness


def with_bed(sim: SimulationResult, real: Mechanism, sensor: Sensor, bed: BedBump) -> SimulationResult:
    """``sim`` measured over the warped bed ``bed``: each probe reading lower by w at the
    real probe point (module docstring)."""
    w = bed(sensor.probe_points(real.frame(sim.real_poses)))[:, None]
    return dataclasses.replace(sim, sensor_true=sim.sensor_true - w, sensor_readings=sim.sensor_readings - w)


def with_sag(sim: SimulationResult, real: Mechanism, sensor: Sensor, sag: Sag) -> SimulationResult:
    """``sim`` on a machine that sags (module docstring): the real poses moved by δx, the
    sensor reading the moved platform (with the same noise)."""
    moved = sim.real_poses + sag.displacement(real, sim.real_poses)
    y = sensor.predict(real.frame(moved))
    return dataclasses.replace(sim, real_poses=moved, sensor_true=y,
                               sensor_readings=sim.sensor_readings - sim.sensor_true + y)


__all__ = ["BedBump", "Sag", "with_bed", "with_sag"]

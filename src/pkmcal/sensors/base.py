"""The sensor interface: what an external measuring device reads at a pose.

A sensor model is ``y = h(x, θ)``: the readings y (m,) it gives when the platform frame is
at pose x (internal units: mm, radians, pose convention of :mod:`pkmcal.conventions`),
with θ the sensor's own parameters (e.g. an unknown world→base transform, a target offset
on the platform, indicator zero offsets). Every sensor supplies analytic derivatives
∂h/∂x (with respect to the pose coordinates x, y, z, a, b, c, like
:meth:`pkmcal.mechanisms.base.Mechanism.actuator_pose_jacobian`) and ∂h/∂θ.

The actuators are the machine's own sensor: their readings are ``q = IK(x, ρ)``, with the
noise given by :class:`NoiseModel`. A :class:`MeasurementSetup` bundles a sensor with the
noise of its readings and of the actuators; it is what a setup YAML file describes.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pkmcal.mechanisms.statics import StaticsModel


class Sensor(ABC):
    """Abstract external sensor (see module docstring)."""

    #: Sensor kind as written in setup files: "full-pose", "position", "indicators", ...
    kind: str

    @property
    @abstractmethod
    def reading_names(self) -> tuple[str, ...]:
        """CSV column names of the readings, e.g. ("x", ..., "c") or ("d1", "d2", "d3")."""

    @property
    def reading_is_angle(self) -> tuple[bool, ...]:
        """True for readings that are angles (degrees in files, radians inside)."""
        return (False,) * len(self.reading_names)

    @property
    def n_readings(self) -> int:
        return len(self.reading_names)

    @property
    @abstractmethod
    def param_names(self) -> tuple[str, ...]:
        """Names of the sensor's own parameters θ (may be empty)."""

    @property
    @abstractmethod
    def params(self) -> np.ndarray:
        """Current values of θ (s,), internal units."""

    @property
    def default_free(self) -> tuple[str, ...]:
        """Sensor parameters estimated by default (the rest are held at their values)."""
        return ()

    @abstractmethod
    def with_params(self, params: np.ndarray) -> "Sensor":
        """A copy of this sensor with θ replaced."""

    @abstractmethod
    def predict(self, poses: np.ndarray) -> np.ndarray:
        """Readings y (N, m) at poses (N, n); n = 6 for the hexapod, n = the mechanism's
        pose dimension for planar machines (2 or 3)."""

    @abstractmethod
    def pose_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂pose (N, m, n): (x, y, z, a, b, c) for the hexapod (n = 6), the mechanism's
        pose coordinates otherwise."""

    @abstractmethod
    def param_jacobian(self, poses: np.ndarray) -> np.ndarray:
        """∂y/∂θ (N, m, s)."""

    def reading_residual(self, measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """``measured − predicted`` (N, m); sensors with angle readings wrap them to (−π, π]."""
        r = np.asarray(measured, dtype=float) - predicted
        ang = np.array(self.reading_is_angle, dtype=bool)
        if ang.any():
            r[..., ang] = (r[..., ang] + np.pi) % (2 * np.pi) - np.pi
        return r


@dataclass(frozen=True)
class NoiseModel:
    """Measurement noise. ``reading_std`` (m,) for the sensor readings and ``actuator_std``
    (l,) for the actuator readings, as standard deviations in internal units (mm, rad).

    ``distribution`` is "gaussian" or "uniform"; a uniform noise of half-width h has the
    standard deviation h/√3, which is what is stored here (the setup file may give
    half-widths; the loader converts).
    """

    reading_std: np.ndarray
    actuator_std: np.ndarray
    distribution: str = "gaussian"

    def sample(self, rng: np.random.Generator, shape_readings, shape_actuators):
        """Seeded noise draws ``(e_y, e_q)`` of the given shapes (N, m) and (N, l)."""
        def draw(std, shape):
            std = np.broadcast_to(np.asarray(std, dtype=float), shape[-1:])
            if self.distribution == "uniform":
                h = std * np.sqrt(3.0)
                return rng.uniform(-1.0, 1.0, size=shape) * h
            return rng.standard_normal(size=shape) * std
        return draw(self.reading_std, shape_readings), draw(self.actuator_std, shape_actuators)


@dataclass(frozen=True)
class MeasurementSetup:
    """A sensor and the noise of its readings and of the actuators; optionally the physics
    that only a simulation uses (``simulation``: a
    :class:`~pkmcal.mechanisms.statics.StaticsModel`, actuator stiffness and tool load of a
    redundantly actuated machine; the identifier never reads it)."""

    sensor: Sensor
    noise: NoiseModel
    simulation: "StaticsModel | None" = None

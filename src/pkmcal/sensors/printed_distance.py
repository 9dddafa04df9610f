"""Printed-object distances with Z-probe heights: Klipper's ``DELTA_ANALYZE`` on a delta
printer (issue 13, item 3).

A printed point is where the nozzle was when it laid it down: the platform frame's origin p
at a commanded pose. The distance between two printed points, measured with calipers, is a
reading of *two* poses,

    d = ‖p(x_1) − p(x_2)‖,                                        (reading ``distance``, mm)

which the engine reads as one row of a :class:`~pkmcal.mechanisms.pose_pairs.PosePairs`
machine (the row's pose is the pair (x_1, x_2), its actuator readings the carriage positions
of both points; that module says why this is the least invasive correct design). Klipper
fits such distances together with its probe heights, so one sensor reads both kinds of row:

* a **distance row** is a pair of two different points: ``distance`` = d and ``probe_z`` = 0
  (no height was measured; its prediction is 0 at every θ, with zero derivative, so the row
  adds nothing but its noise);
* a **height row** is a pair of one point with itself (pose 2 = pose 1: the measurement
  file repeats the carriage positions): ``probe_z`` is the Z probe's reading of that pose
  (:mod:`pkmcal.sensors.z_probe`, its parameters ``probe.x…``, ``bed.z…`` are this
  sensor's) and ``distance`` = 0 (predicted 0 with zero derivative).

A row is a height row where its two points are within :data:`SAME_POINT_MM` of each other
(the same carriage positions give the same point to rounding, at every θ; two printed points
are never a micrometre apart).

Jacobians (analytic; tested against finite differences). With u = (p_1 − p_2)/d, on a
distance row, over the pair's twist (δp_1, δω_1, δp_2, δω_2):

    ∂d/∂δp_1 = uᵀ,   ∂d/∂δp_2 = −uᵀ,   ∂d/∂δω_1 = ∂d/∂δω_2 = 0    (the point is the frame origin);

on a height row the Z probe's (:mod:`.z_probe`) in the columns of pose 1 and 0 in those of
pose 2; ∂/∂θ the Z probe's on height rows, 0 on distance rows.

What the distances add (the reason to print the object): Z heights alone barely see the
common scale of arms and radius (the machine's ``named_directions``); a distance is a
length, and sees it. Klipper's ``SCALE`` of the printed object and its pillar widths are
applied before the distances reach this sensor (:mod:`pkmcal.io.klipper_analyze`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from pkmcal.sensors.base import MeasurementSetup, NoiseModel, Sensor
from pkmcal.sensors.z_probe import ZProbeSensor

#: Two points of a pair closer than this (mm) are one point: the row is a height row.
SAME_POINT_MM = 1e-6


@dataclass(frozen=True, eq=False)
class PrintedDistanceSensor(Sensor):
    """Distances between printed points, and Z-probe heights, on pose pairs (module
    docstring). ``probe_offset``, ``bed``, ``free`` as :class:`~pkmcal.sensors.z_probe.ZProbeSensor`."""

    probe_offset: np.ndarray = None  # type: ignore[assignment]
    bed: np.ndarray = None  # type: ignore[assignment]
    free: tuple[str, ...] | None = None

    kind = "printed-distance"
    reads_pose_pairs = True
    #: the object's points and the probe's are on the bed: a lean shows only across heights
    reads_one_plane = True

    def __post_init__(self) -> None:
        self._init_params()

    @cached_property
    def probe(self) -> ZProbeSensor:
        """The Z probe of the height rows (same θ and free set): what this setup reads of a
        single pose."""
        return ZProbeSensor(probe_offset=self.probe_offset, bed=self.bed, free=self.free)

    @property
    def param_groups(self):
        return self.probe.param_groups

    @property
    def reading_names(self) -> tuple[str, ...]:
        return ("probe_z", "distance")

    @staticmethod
    def _rows(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(height-row mask (N,), v = p_1 − p_2 (N, 3), d = ‖v‖ (N,))."""
        v = frame.p - frame.second.p
        d = np.linalg.norm(v, axis=1)
        return d <= SAME_POINT_MM, v, d

    def predict(self, frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings (N, 2): probe_z on height rows, distance on distance rows, else 0."""
        height, _, d = self._rows(frame)
        y = np.zeros((len(frame), 2))
        y[:, 0] = np.where(height, self.probe.predict(frame.first, params)[:, 0], 0.0)
        y[:, 1] = np.where(height, 0.0, d)
        return y

    def frame_jacobian(self, frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(twist 1, twist 2) (N, 2, 12) (module docstring)."""
        height, v, d = self._rows(frame)
        J = np.zeros((len(frame), 2, 12))
        J[:, 0, 0:6] = np.where(height[:, None], self.probe.frame_jacobian(frame.first, params)[:, 0], 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(height[:, None], 0.0, v / d[:, None])
        J[:, 1, 0:3] = u
        J[:, 1, 6:9] = -u
        return J

    def param_jacobian(self, frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂θ (N, 2, 6): the Z probe's on height rows."""
        height, _, _ = self._rows(frame)
        J = np.zeros((len(frame), 2, len(self.param_names)))
        J[:, 0] = np.where(height[:, None], self.probe.param_jacobian(frame.first, params)[:, 0], 0.0)
        return J

    def measured_readings(self, frame) -> np.ndarray:
        """(N, 2): a height row measures probe_z, a distance row the distance; the other
        reading is recorded as 0 and predicted 0 (no degree of freedom)."""
        height, _, _ = self._rows(frame)
        return np.c_[height, ~height]

    def readable(self, frame) -> tuple[np.ndarray, str]:
        """Height rows where the Z probe can read pose 1; every distance row."""
        height, _, _ = self._rows(frame)
        ok, why = self.probe.readable(frame.first)
        return ok | ~height, why

    def works_with(self, mechanism) -> str | None:
        """Machines read as pose pairs (:class:`~pkmcal.mechanisms.pose_pairs.PosePairs`) of
        a machine the Z probe can measure."""
        if "pose-pairs" not in mechanism.abilities:
            return (f"a '{self.kind}' sensor reads pairs of poses (the distances of Klipper's printed object with "
                    f"probe heights), which 'pkmcal identify', 'identifiability', 'verify' and 'study' read on machine "
                    f"'{mechanism.name}' as pose pairs (files of x, y, z, x_2, y_2, z_2; 'pkmcal import klipper-analyze'); "
                    "the object is Klipper's, not planned or simulated pose by pose: plan or simulate the probe points "
                    "with the Z probe (--setup z-probe-klipper)")
        return self.probe.works_with(mechanism.single)


def probe_setup(setup: MeasurementSetup) -> MeasurementSetup:
    """The Z-probe setup of a printed-distance ``setup``: its probe (:attr:`PrintedDistanceSensor.probe`),
    the probe's reading noise and the same actuator noise; what it reads of single poses
    (a study plans its probe points and verifies its heights with it)."""
    n = setup.noise
    reading = np.broadcast_to(np.asarray(n.reading_std, dtype=float), (2,))[:1].copy()
    return replace(setup, sensor=setup.sensor.probe, noise=NoiseModel(reading, n.actuator_std, n.distribution))


def single_pose_setup(setup: MeasurementSetup) -> MeasurementSetup:
    """What ``setup`` reads of single poses: the setup itself, or the Z probe of a
    printed-distance setup (:func:`probe_setup`; the sensor that reads pose pairs)."""
    return probe_setup(setup) if setup.sensor.reads_pose_pairs else setup


def height_rows(actuators: np.ndarray, probe_z: np.ndarray, poses: np.ndarray):
    """Height rows (module docstring) of single-pose probe measurements: ``(actuators (N, 2l),
    readings (N, 2), poses (N, 2n))`` with each pose's carriage positions and pose twice,
    ``probe_z`` the reading and ``distance`` 0."""
    z = np.asarray(probe_z, dtype=float).reshape(-1)
    return np.c_[actuators, actuators], np.c_[z, np.zeros(len(z))], np.c_[poses, poses]


def distance_rows(actuators_1: np.ndarray, actuators_2: np.ndarray, distance: np.ndarray, poses_1: np.ndarray,
                  poses_2: np.ndarray):
    """Distance rows (module docstring): ``(actuators (N, 2l), readings (N, 2), poses (N, 2n))``
    with both points' carriage positions and poses, ``probe_z`` 0 and ``distance``."""
    d = np.asarray(distance, dtype=float).reshape(-1)
    return np.c_[actuators_1, actuators_2], np.c_[np.zeros(len(d)), d], np.c_[poses_1, poses_2]


__all__ = ["PrintedDistanceSensor", "SAME_POINT_MM", "distance_rows", "height_rows", "probe_setup",
           "single_pose_setup"]

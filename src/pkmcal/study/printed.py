"""A delta printer calibrated with a printed object in a study: the campaign of a
``printed-distance`` setup (Klipper's ``DELTA_CALIBRATE`` probe heights and ``DELTA_ANALYZE``
distances, :mod:`pkmcal.sensors.printed_distance`), and what its trials verify on single poses.

The campaign is what ``pkmcal import klipper-analyze`` writes for the same printer: first the
plan's n probe points as height rows (each pose twice, the reading ``probe_z``), then the 12
distances of Klipper's calibration object (:func:`pkmcal.io.klipper_analyze.object_point_pairs`,
at the setup's ``object_scale``) as distance rows, read on the machine as pose pairs
(:mod:`pkmcal.mechanisms.pose_pairs`). A row holds only what was measured: the other reading
is 0, as in the imported file (:func:`~pkmcal.sensors.printed_distance.height_rows`,
:func:`~pkmcal.sensors.printed_distance.distance_rows`).

* **Planning.** The object is Klipper's, not planned: the probe points are planned as for
  the setup's Z probe alone (:func:`~pkmcal.sensors.printed_distance.single_pose_setup`: the
  same pool and selection), so a study compares the probe alone and the probe with the
  object on the same planners.
* **Simulation** (:func:`simulate`): the probe points are commanded through the nominal
  model and probed on the real machine with the probe's noise
  (:func:`~pkmcal.identification.simulation.simulate_campaign` of the Z probe); the object is
  printed through the nominal model at z = 0 (as ``DELTA_ANALYZE`` places it) and its
  distances read on the real machine with the calipers' noise (the same function on the
  pose pairs). A printed point is where the nozzle was, on the bed or pressed into the first
  layer: the real machine's bed limit (``min_z``) is not checked for the object
  (:data:`BED_LIMITS`), whose z the endstop errors move by tenths of a mm.
* **On the bed** (a study setup's ``on_bed: true``, any Z probe): a printer probes its bed
  only, so the plan's probe points are lowered to where the probe triggers
  (:func:`pkmcal.identification.advice.where_read`) before they are chosen, and, like the object, not checked
  against the bed limit on the real machine. Without it the probe reads its height
  anywhere in the volume (a probe on gauge blocks), as the studies of ``z-probe-klipper``
  always have.
* **Verification** on single poses of the machine (:func:`single_pose_fit`): its heights
  are what the Z probe reads (``compare: sensor``), the printed geometry the nozzle
  positions after the best rigid alignment (``compare: aligned``, the default for this
  setup: :func:`pkmcal.study.trial.heldout_compare`).
* **The scale** (:func:`scale_columns`): what ``pkmcal identifiability`` says of the
  machine's named direction (a linear delta's common scale of arms and radius,
  :meth:`~pkmcal.mechanisms.base.Mechanism.named_directions`) on the trial's measured poses,
  with what the method holds besides the scale held (a method that holds the rods: would
  the measurements determine them): the columns ``scale_status`` and ``scale_sigma`` of
  every configuration of a study with a printed-distance setup.

Lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import SimulationResult, simulate_campaign
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.pose_pairs import PosePairs, single_machine
from pkmcal.sensors.base import MeasurementSetup, Sensor
from pkmcal.sensors.printed_distance import distance_rows, height_rows, probe_setup

#: Machine kinds a printed-distance setup is studied on: Klipper's object is printed by a
#: linear delta printer.
PRINTER_KINDS = ("linear-delta",)
#: Limits of the real machine not checked for what is printed or probed on the bed (module
#: docstring), where the machine has them.
BED_LIMITS = ("min_z",)


def bed_limits(machine: Mechanism) -> tuple[str, ...]:
    """The :data:`BED_LIMITS` ``machine`` has."""
    known = machine.check_limits(np.asarray(machine.home_pose, dtype=float)[None, :], margins=False).violations
    return tuple(n for n in BED_LIMITS if n in known)


def probes_the_bed(sensor: Sensor) -> bool:
    """Whether ``sensor`` reads where it is lowered to (it declares ``"touch-probe"``: a Z
    probe, :meth:`~pkmcal.sensors.base.Sensor.measured_frames`)."""
    return "touch-probe" in sensor.abilities


def object_poses(machine: Mechanism, scale: float) -> np.ndarray:
    """Klipper's calibration object at ``scale`` as commanded pose pairs (12, 6): the points
    of its 12 distances; a :class:`PkmcalError` when ``machine`` cannot print it (outside its
    reach or limits)."""
    from pkmcal.io.klipper_analyze import object_point_pairs

    p1, p2 = object_point_pairs(scale)
    points = np.r_[p1, p2]
    with np.errstate(invalid="ignore"):
        reached = np.all(np.isfinite(machine.ik(points)), axis=1)
    limits = [name for name, v in machine.check_limits(points, margins=False).violations.items() if np.any(v)]
    if limits or not reached.all():
        raise PkmcalError(f"Klipper's calibration object at scale {scale:g} (points up to "
                          f"{np.max(np.linalg.norm(points[:, :2], axis=1)):.4g} mm from the centre) is outside what "
                          f"machine '{machine.name}' can print ({', '.join(limits) or 'reach'}); print it smaller "
                          "(object_scale)")
    return np.c_[p1, p2]


@dataclass(frozen=True)
class SinglePoseModel:
    """What the held-out verification reads of a fit (:func:`pkmcal.study.trial.heldout_errors`):
    the calibrated machine and the sensor of single poses."""

    mechanism: Mechanism
    sensor: Sensor


def single_pose_fit(fit, setup: MeasurementSetup):
    """``fit`` (of a campaign measured with ``setup``) as verified on single poses: itself,
    or for a fit of pose pairs the machine (:func:`~pkmcal.mechanisms.pose_pairs.single_machine`)
    with its identified Z probe."""
    if not setup.sensor.reads_pose_pairs:
        return fit
    return SinglePoseModel(single_machine(fit.mechanism), fit.sensor.probe)


def simulate(nominal: Mechanism, real: Mechanism, setup: MeasurementSetup, probe_poses: np.ndarray, scale: float,
             rng: np.random.Generator, ignore_limits: tuple[str, ...] = ()) -> SimulationResult:
    """The campaign of a printed-distance ``setup`` (module docstring) on ``real`` commanded
    through ``nominal`` (single machines): the probe points ``probe_poses`` (N, 3), then the
    object at ``scale``, as one simulated campaign of the pose-pair machine (its rows
    numbered in that order). ``rng`` draws the probe's noise, then the calipers';
    ``ignore_limits`` are the real machine's limits not checked at the probe points (the
    object's: those and :func:`bed_limits`)."""
    heights = simulate_campaign(nominal, real, probe_setup(setup), probe_poses, rng, ignore_limits=ignore_limits)
    objects = simulate_campaign(PosePairs(nominal), PosePairs(real), setup, object_poses(nominal, scale), rng,
                                ignore_limits=tuple(dict.fromkeys(tuple(ignore_limits) + bed_limits(nominal))))
    l, n = nominal.n_actuators, len(heights.commanded)

    def rows(h_q, h_z, h_x, d_q, d_d, d_x):
        return tuple(np.r_[a, b] for a, b in zip(height_rows(h_q, h_z, h_x),
                                                  distance_rows(d_q[:, :l], d_q[:, l:], d_d, d_x[:, :3], d_x[:, 3:])))

    true_q, true_y, real_poses = rows(heights.actuator_true, heights.sensor_true, heights.real_poses,
                                      objects.actuator_true, objects.sensor_true[:, 1], objects.real_poses)
    read_q, read_y, _ = rows(heights.actuator_readings, heights.sensor_readings, heights.real_poses,
                             objects.actuator_readings, objects.sensor_readings[:, 1], objects.real_poses)
    commanded = np.r_[np.c_[heights.commanded, heights.commanded], objects.commanded]
    dropped = dict(heights.dropped) | {n + k: why for k, why in objects.dropped.items()}
    return SimulationResult(commanded=commanded, kept=np.r_[heights.kept, n + objects.kept], dropped=dropped,
                            real_poses=real_poses, actuator_true=true_q, sensor_true=true_y,
                            actuator_readings=read_q, sensor_readings=read_y, setup=setup)


def scale_columns(machine: Mechanism, setup: MeasurementSetup, poses: np.ndarray, free=None, fix=None) -> dict:
    """``scale_status`` and ``scale_sigma`` (module docstring): whether the measured ``poses``
    (commanded, of ``machine`` as the setup reads it) determine the machine's first named
    direction, as ``pkmcal identifiability`` judges it
    (:func:`~pkmcal.identification.identifiability.identifiability`: the nominal machine,
    noise-free readings, the setup's default method), on a method's candidates ``free`` and
    ``fix`` (names or patterns; None or "auto": all) with the direction's own parameters
    freed: a method that holds the rods is asked whether the measurements would determine
    the scale without them, a gauge it holds explicitly is judged as a gauge. Identified,
    weak, not determined or unidentifiable, and the standard deviation of its amount
    (relative: 1e-3 is 0.1 %); empty for a machine without one."""
    directions = machine.named_directions()
    if not directions:
        return {}
    from pkmcal.identification.identifiability import identifiability
    from pkmcal.identification.residuals import _matching     # the engine's shell-pattern match

    own = set(directions[0].direction)
    names = tuple(machine.param_names) + tuple(setup.sensor.param_names)
    held = None if fix is None or isinstance(fix, str) else [n for n in _matching(names, tuple(fix)) if n not in own]
    chosen = None if free is None else [n for n in names if n in own or n in _matching(names, tuple(free))]
    rep = identifiability(machine, setup, poses, free=chosen, fix=held)
    if not rep.named:
        return {}
    return {"scale_status": rep.named[0]["status"], "scale_sigma": rep.named[0]["sigma"]}


__all__ = ["BED_LIMITS", "PRINTER_KINDS", "SinglePoseModel", "bed_limits", "object_poses",
           "probes_the_bed", "scale_columns", "simulate", "single_pose_fit"]

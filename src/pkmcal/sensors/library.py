"""Built-in measurement setups, usable by name wherever a setup file is (``pkmcal plan
--setup indicators-prototype``), and :func:`bind_setup`, which fits a setup to a machine.

A setup is a sensor, the noise of its readings and of the actuators, and optionally the
physics only a simulation uses (:class:`~pkmcal.mechanisms.statics.StaticsModel`). This
module imports only NumPy and the sensor models, so that the command line can list the
built-in names without loading the setup-file parser (pydantic).
"""

from __future__ import annotations

import math

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.statics import StaticsModel
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor
from pkmcal.sensors.indicators import IndicatorSensor
from pkmcal.sensors.planar_tool import PlanarToolSensor
from pkmcal.sensors.position import PositionSensor
from pkmcal.sensors.printed_distance import PrintedDistanceSensor
from pkmcal.sensors.z_probe import ZProbeSensor

SQRT3 = math.sqrt(3.0)


#: Indicator positions of ``indicators-prototype``: radius 40 mm at 0°, 120°, 240° in the
#: base frame, inside the 70 mm platform-joint radius of paper 2's prototype.
PROTOTYPE_INDICATORS = np.array([[40.0, 0.0], [-20.0, 20.0 * math.sqrt(3.0)], [-20.0, -20.0 * math.sqrt(3.0)]])


def _indicators_prototype() -> MeasurementSetup:
    return MeasurementSetup(
        IndicatorSensor(positions=PROTOTYPE_INDICATORS, plane_offset=10.0),
        NoiseModel(reading_std=np.full(3, 0.01), actuator_std=np.array(0.005)),
    )


def _full_pose_paper1() -> MeasurementSetup:
    h_pos, h_ori, h_leg = 0.025, 0.001, 0.01
    return MeasurementSetup(
        FullPoseSensor(),
        NoiseModel(reading_std=np.array([h_pos] * 3 + [h_ori] * 3) / SQRT3,
                   actuator_std=np.array(h_leg / SQRT3), distribution="uniform"),
    )


def _laser_tracker() -> MeasurementSetup:
    return MeasurementSetup(
        PositionSensor(),
        NoiseModel(reading_std=np.full(3, 0.01), actuator_std=np.array(0.005)),
    )


#: Built-in planar tracker setups (benchmarks/redundant.py, paper 3 §3): tracker σ 0.010 mm
#: per axis (Leica AT901), load [0, −30] N on the tool point, and per actuator type
#: (encoder σ, stiffness K): rotary 1e-5 rad, 5e7 N·mm/rad; linear 0.001 mm, 2e4 N/mm.
PLANAR_TRACKER_STD = 0.010
PLANAR_LOAD = (0.0, -30.0)
PLANAR_ACTUATORS = {"rotary": (1e-5, 5e7), "linear": (1e-3, 2e4)}


def _planar_tracker(kind: str, machine=None) -> MeasurementSetup:
    if kind == "auto":
        if machine is None:
            raise PkmcalError("the built-in setup 'planar-tracker' depends on the machine's actuators; use "
                              "planar-tracker-rotary or planar-tracker-linear here")
        kind = "rotary" if any(machine.actuator_is_angle) else "linear"
    enc, k = PLANAR_ACTUATORS[kind]
    return MeasurementSetup(
        PlanarToolSensor(n_pose=2 if machine is None else machine.n_dof),
        NoiseModel(reading_std=np.full(2, PLANAR_TRACKER_STD), actuator_std=np.array(enc)),
        simulation=StaticsModel(stiffness=np.array(k), load=np.array(PLANAR_LOAD)),
    )


#: ``z-probe-klipper``: a delta printer's Z probe as Klipper uses it (bed z = 0, level; probe
#: offset 0: give yours in a setup file). Probe σ 0.005 mm: the BLTouch maker's stated
#: repeatability (Antclabs, standard deviation about 0.005 mm), also typical of a good
#: inductive probe's PROBE_ACCURACY; a nominal assumption, replace it by your PROBE_ACCURACY
#: standard deviation. Carriages σ 0.0036 mm: one step of an 80 steps/mm tower (a 20-tooth
#: GT2 pulley at 16 microsteps) as a uniform quantisation, 0.0125 mm / √12.
Z_PROBE_KLIPPER_STD = 0.005
Z_PROBE_KLIPPER_CARRIAGE_STD = 0.0125 / math.sqrt(12.0)


def _z_probe_klipper() -> MeasurementSetup:
    return MeasurementSetup(
        ZProbeSensor(),
        NoiseModel(reading_std=np.array([Z_PROBE_KLIPPER_STD]), actuator_std=np.array(Z_PROBE_KLIPPER_CARRIAGE_STD)),
    )


#: ``printed-distance-klipper``: the Z probe above, and calipers on Klipper's printed
#: calibration object (DELTA_ANALYZE): σ 0.02 mm, a nominal assumption for a hand-held
#: caliper reading of a printed edge; replace it by your own repeatability.
PRINTED_DISTANCE_STD = 0.02


def _printed_distance_klipper() -> MeasurementSetup:
    return MeasurementSetup(
        PrintedDistanceSensor(),
        NoiseModel(reading_std=np.array([Z_PROBE_KLIPPER_STD, PRINTED_DISTANCE_STD]),
                   actuator_std=np.array(Z_PROBE_KLIPPER_CARRIAGE_STD)),
    )


#: Built-in setups by name → (factory, one-line description).
BUILTIN_SETUPS = {
    "indicators-prototype": (
        _indicators_prototype,
        "paper 2 style: 3 dial indicators at radius 40 mm, 0/120/240 deg, plane_offset 10 mm; "
        "noise std 0.01 mm (indicators), 0.005 mm (legs)",
    ),
    "full-pose-paper1": (
        _full_pose_paper1,
        "paper 1 full-pose measurement: uniform noise +-0.025 mm position, +-0.001 rad "
        "orientation, +-0.01 mm legs",
    ),
    "laser-tracker": (
        _laser_tracker,
        "3D laser tracker on one target point (offset free, initial 0): noise std 0.01 mm, 0.005 mm (legs)",
    ),
    "z-probe-klipper": (
        _z_probe_klipper,
        "delta printer Z probe as Klipper uses it (bed z = 0 and level, probe offset 0): std 0.005 mm "
        "(nominal, BLTouch spec), carriages 0.0036 mm (one 0.0125 mm step, uniform)",
    ),
    "printed-distance-klipper": (
        _printed_distance_klipper,
        "delta printer: Klipper's Z probe (as z-probe-klipper) and DELTA_ANALYZE printed-object distances "
        "(calipers std 0.02 mm, nominal); the machine read as pose pairs",
    ),
    "planar-tracker": (
        lambda machine=None: _planar_tracker("auto", machine),
        "planar machines (paper 3): planar-tracker-rotary or -linear by the machine's actuators",
    ),
    "planar-tracker-rotary": (
        lambda machine=None: _planar_tracker("rotary", machine),
        "planar tool-point tracker (target free, initial 0): std 0.010 mm, encoders 1e-5 rad; "
        "simulation: K 5e7 N*mm/rad, load [0, -30] N",
    ),
    "planar-tracker-linear": (
        lambda machine=None: _planar_tracker("linear", machine),
        "planar tool-point tracker (target free, initial 0): std 0.010 mm, encoders 0.001 mm; "
        "simulation: K 2e4 N/mm, load [0, -30] N",
    ),
}

_PLANAR_BUILTINS = ("planar-tracker", "planar-tracker-rotary", "planar-tracker-linear")


def builtin_setup(name: str, machine=None) -> MeasurementSetup:
    """The built-in setup ``name``; bound to ``machine`` (:func:`bind_setup`) when given."""
    try:
        factory, _ = BUILTIN_SETUPS[name]
    except KeyError:
        raise PkmcalError(
            f"unknown setup '{name}': not a file and not a built-in setup ({', '.join(BUILTIN_SETUPS)})"
        ) from None
    setup = factory(machine) if name in _PLANAR_BUILTINS else factory()
    return setup if machine is None else bind_setup(setup, machine, name)


def bind_setup(setup: MeasurementSetup, machine, source: object = "setup") -> MeasurementSetup:
    """``setup`` for ``machine``: a planar-tool sensor takes the machine's pose dimension
    (2 or 3); a sensor that cannot measure the machine, or a ``simulation:`` stiffness list
    of the wrong length, is a :class:`PkmcalError` naming ``source``."""
    import dataclasses

    sensor = setup.sensor
    if isinstance(sensor, PlanarToolSensor) and sensor.n_pose != machine.n_dof and "planar" in machine.abilities:
        sensor = dataclasses.replace(sensor, n_pose=machine.n_dof)
        setup = dataclasses.replace(setup, sensor=sensor)
    why = sensor.works_with(machine)      # declared by the sensor, not probed here
    if why is not None:
        raise PkmcalError(f"{source}: {why}")
    a = np.asarray(setup.noise.actuator_std, dtype=float)
    if a.ndim and a.size not in (1, machine.n_actuators):
        raise PkmcalError(f"{source}: {a.size} actuator noise values but machine '{machine.name}' has "
                          f"{machine.n_actuators} actuators; give one value or one per actuator")
    if setup.simulation is not None:
        try:
            setup.simulation.stiffness_for(machine)
        except PkmcalError as exc:
            raise PkmcalError(f"{source}: simulation.stiffness: {exc}") from None
    return setup

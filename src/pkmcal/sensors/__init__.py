"""Sensors: what is measured. Every sensor implements :class:`~pkmcal.sensors.base.Sensor`."""

from pkmcal.sensors.base import MeasurementSetup, NoiseModel, Sensor

__all__ = ["MeasurementSetup", "NoiseModel", "Sensor"]

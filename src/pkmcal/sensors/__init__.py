"""Sensors: what is measured. Every sensor implements :class:`~pkmcal.sensors.base.Sensor`.

* :class:`FullPoseSensor` (``full-pose``): x, y, z, a, b, c of a target frame (paper 1)
* :class:`PositionSensor` (``position``): one target point, 3D laser tracker
* :class:`IndicatorSensor` (``indicators``): K ≥ 3 dial indicators under the platform (paper 2)
* :class:`PlanarToolSensor` (``planar-tool``): tracker on the tool point of a planar machine (paper 3)
* :class:`DistanceSensor` (``distance``): distances from base pivots to a ball on the platform
  (double ballbar, string potentiometer, interferometer to a fixed point)
* :class:`ZProbeSensor` (``z-probe``): a delta printer's Z probe, the height of a probe point above the bed
* :class:`PrintedDistanceSensor` (``printed-distance``): distances between printed points (two poses) and
  Z-probe heights, on a machine read as pose pairs

``base`` holds the interface (θ declared as :class:`ParamGroup` fields, from which names,
angle flags, ``with_params`` and value equality follow), ``_common`` the shared argument
checks and 3-D helpers, ``_frames`` the world ← base ← platform ← point chain of the
full-pose and position sensors, ``sessions`` several measurement sessions in one fit (a
copy of a sensor's parameters per session, ``NAME@LABEL``); each other module is one sensor.
"""

from pkmcal.sensors.base import MeasurementSetup, NoiseModel, ParamGroup, Sensor
from pkmcal.sensors.distance import DistanceSensor
from pkmcal.sensors.full_pose import FullPoseSensor
from pkmcal.sensors.indicators import IndicatorSensor
from pkmcal.sensors.planar_tool import PlanarToolSensor
from pkmcal.sensors.position import PositionSensor
from pkmcal.sensors.printed_distance import PrintedDistanceSensor
from pkmcal.sensors.z_probe import ZProbeSensor

#: Sensor classes by the ``kind`` written in setup files.
SENSOR_KINDS = {cls.kind: cls for cls in (FullPoseSensor, PositionSensor, IndicatorSensor, PlanarToolSensor,
                                          DistanceSensor, ZProbeSensor, PrintedDistanceSensor)}

__all__ = [
    "DistanceSensor",
    "FullPoseSensor",
    "IndicatorSensor",
    "MeasurementSetup",
    "NoiseModel",
    "ParamGroup",
    "PlanarToolSensor",
    "PositionSensor",
    "PrintedDistanceSensor",
    "SENSOR_KINDS",
    "Sensor",
    "ZProbeSensor",
]

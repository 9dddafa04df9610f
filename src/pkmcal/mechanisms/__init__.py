"""Mechanisms: what moves. Every machine implements :class:`~pkmcal.mechanisms.base.Mechanism`."""

from pkmcal.mechanisms.base import FKResult, LimitReport, Mechanism
from pkmcal.mechanisms.hexapod import Hexapod, HexapodLimits
from pkmcal.mechanisms.library import BUILTIN_MACHINES, DEFAULT_MACHINE, builtin_machine, symmetric_hexapod

__all__ = [
    "BUILTIN_MACHINES",
    "DEFAULT_MACHINE",
    "FKResult",
    "Hexapod",
    "HexapodLimits",
    "LimitReport",
    "Mechanism",
    "builtin_machine",
    "symmetric_hexapod",
]

"""Mechanisms: what moves. Every machine implements :class:`~pkmcal.mechanisms.base.Mechanism`.

The names below are imported on first use (PEP 562), so that importing a light submodule
(:mod:`pkmcal.mechanisms.catalogue`, which ``pkmcal machines`` prints) loads no NumPy.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "FKResult": "pkmcal.mechanisms.base",
    "LimitReport": "pkmcal.mechanisms.base",
    "Mechanism": "pkmcal.mechanisms.base",
    "Hexapod": "pkmcal.mechanisms.hexapod",
    "HexapodLimits": "pkmcal.mechanisms.hexapod",
    "BUILTIN_MACHINES": "pkmcal.mechanisms.library",
    "DEFAULT_MACHINE": "pkmcal.mechanisms.library",
    "builtin_machine": "pkmcal.mechanisms.library",
    "symmetric_hexapod": "pkmcal.mechanisms.library",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'pkmcal.mechanisms' has no attribute {name!r}")


__all__ = sorted(_EXPORTS)

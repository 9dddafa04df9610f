"""The closed vocabularies of the campaign's options, named once for the command line and
the Python API: methods (paper 1 ik-residual, paper 2 fk-residual, paper 3 projection and
its baselines), robust losses, clipped-reading policies, built-in setups, export formats,
the built-in machines (names, kinds, descriptions) and the default machine.
Each is defined where its meaning is implemented; this module only gathers them.

The machines' catalogue is plain text (``pkmcal machines`` lists it without importing
NumPy); every other name is imported from its home on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pkmcal.mechanisms.catalogue import BUILTIN_CATALOGUE, SYMMETRIC_DESCRIPTION, SYMMETRIC_KIND, SYMMETRIC_PREFIX

if TYPE_CHECKING:                       # the names of _HOMES, for readers and checkers
    from pkmcal.identification.baselines import BASELINES
    from pkmcal.identification.residuals import DEFAULT_METHOD_RULE, METHODS
    from pkmcal.identification.robust import DEFAULT_F_SCALE, LOSSES, OUTLIER_SIGMA
    from pkmcal.io.measurements import CLIPPED_POLICIES
    from pkmcal.mechanisms.library import DEFAULT_MACHINE
    from pkmcal.sensors.library import BUILTIN_SETUPS
    from pkmcal.workflow.export import EXPORT_FORMATS

#: name → the module that defines it (imported on first use: they need NumPy).
_HOMES = {
    "BASELINES": "pkmcal.identification.baselines",
    "DEFAULT_METHOD_RULE": "pkmcal.identification.residuals",
    "METHODS": "pkmcal.identification.residuals",
    "DEFAULT_F_SCALE": "pkmcal.identification.robust",
    "LOSSES": "pkmcal.identification.robust",
    "OUTLIER_SIGMA": "pkmcal.identification.robust",
    "CLIPPED_POLICIES": "pkmcal.io.measurements",
    "BUILTIN_SETUPS": "pkmcal.sensors.library",
    "EXPORT_FORMATS": "pkmcal.workflow.export",
    "DEFAULT_MACHINE": "pkmcal.mechanisms.library",
}


def __getattr__(name: str):
    if name in _HOMES:
        import importlib

        value = getattr(importlib.import_module(_HOMES[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def builtin_machines() -> list[tuple[str, str, str]]:
    """``(name, kind, description)`` of every built-in machine in the order ``pkmcal machines``
    lists them, the symmetric hexapod generator (``symmetric:KEY=VALUE,...``) last."""
    rows = [(name, kind, text) for name, (kind, text) in BUILTIN_CATALOGUE.items()]
    rows.append((f"{SYMMETRIC_PREFIX}KEY=VALUE,...", SYMMETRIC_KIND, SYMMETRIC_DESCRIPTION))
    return rows


__all__ = ["BASELINES", "BUILTIN_CATALOGUE", "BUILTIN_SETUPS", "CLIPPED_POLICIES", "DEFAULT_F_SCALE", "DEFAULT_MACHINE",
           "DEFAULT_METHOD_RULE", "EXPORT_FORMATS", "LOSSES", "METHODS", "OUTLIER_SIGMA", "builtin_machines"]

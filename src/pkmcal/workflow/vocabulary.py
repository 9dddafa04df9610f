"""The closed vocabularies of the campaign's options, named once for the command line and
the Python API: methods (paper 1 ik-residual, paper 2 fk-residual, paper 3 projection and
its baselines), robust losses, clipped-reading policies, built-in setups, export formats,
the built-in machines (names, kinds, descriptions) and the default machine; the planning's
algorithms, observability indices, default safety margins and plan formats.
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
    from pkmcal.planning.indices import INDEX_DESCRIPTIONS, INDEX_NAMES
    from pkmcal.planning.margins import ASSUMED_JOINT_ERROR_MM, CLEARANCE_MARGIN_MM
    from pkmcal.planning.selection import ALGORITHMS as PLAN_ALGORITHMS
    from pkmcal.sensors.library import BUILTIN_SETUPS
    from pkmcal.workflow.export import EXPORT_FORMATS
    from pkmcal.workflow.plan import PLAN_FORMATS

#: name → the module that defines it, or (module, its name there) (imported on first use: they
#: need NumPy).
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
    "INDEX_DESCRIPTIONS": "pkmcal.planning.indices",
    "INDEX_NAMES": "pkmcal.planning.indices",
    "ASSUMED_JOINT_ERROR_MM": "pkmcal.planning.margins",
    "CLEARANCE_MARGIN_MM": "pkmcal.planning.margins",
    "PLAN_ALGORITHMS": ("pkmcal.planning.selection", "ALGORITHMS"),
    "PLAN_FORMATS": "pkmcal.workflow.plan",
}


def __getattr__(name: str):
    if name in _HOMES:
        import importlib

        module, there = _HOMES[name] if isinstance(_HOMES[name], tuple) else (_HOMES[name], name)
        value = getattr(importlib.import_module(module), there)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def builtin_machines() -> list[tuple[str, str, str]]:
    """``(name, kind, description)`` of every built-in machine in the order ``pkmcal machines``
    lists them, the symmetric hexapod generator (``symmetric:KEY=VALUE,...``) last."""
    rows = [(name, kind, text) for name, (kind, text) in BUILTIN_CATALOGUE.items()]
    rows.append((f"{SYMMETRIC_PREFIX}KEY=VALUE,...", SYMMETRIC_KIND, SYMMETRIC_DESCRIPTION))
    return rows


__all__ = ["ASSUMED_JOINT_ERROR_MM", "BASELINES", "BUILTIN_CATALOGUE", "BUILTIN_SETUPS", "CLEARANCE_MARGIN_MM",
           "CLIPPED_POLICIES", "DEFAULT_F_SCALE", "DEFAULT_MACHINE", "DEFAULT_METHOD_RULE", "EXPORT_FORMATS",
           "INDEX_DESCRIPTIONS", "INDEX_NAMES", "LOSSES", "METHODS", "OUTLIER_SIGMA", "PLAN_ALGORITHMS", "PLAN_FORMATS",
           "builtin_machines"]

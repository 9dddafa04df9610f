"""Where the machine and sensor kinds register themselves (issue 12 item 2; docs/architecture.md).

Plain text, no imports: the one line a new machine family adds, in one of two tables. A
family whose file is the generic layout (every parameter by name) names its class in
:data:`PARAMETER_FILE_KINDS`. A family with a file schema of its own names the module of
that schema in :data:`MACHINE_FILE_MODULES`; each such module registers its kinds on import with
:func:`pkmcal.io.machine_file.register_machine_kind` (its file schema, reader and writer);
:mod:`pkmcal.io.machine_file` imports them all once, so that its generic loader and saver
know every kind. The Gough–Stewart hexapod's file kind is registered by
:mod:`pkmcal.io.machine_file` itself. Sensor kinds of setup files register in
:mod:`pkmcal.io.setup_file` (:func:`~pkmcal.io.setup_file.register_sensor_kind`); built-in
machines are listed in :mod:`pkmcal.mechanisms.catalogue`.
"""

from __future__ import annotations

#: Modules that register machine-file kinds, in the order an unknown kind's error lists them.
MACHINE_FILE_MODULES: tuple[str, ...] = (
    "pkmcal.io.delta_machine_file",    # linear-delta, rotary-delta
    "pkmcal.io.planar_machine_file",   # planar-2dof-3act, planar-3dof-4act
    "pkmcal.io.pus_machine_file",      # 6-PUS
    "pkmcal.io.rss_machine_file",      # 6-RSS
)

#: Mechanism kinds whose machine files are the generic layout, every parameter by name with
#: units from the mechanism's declarations (:mod:`pkmcal.io.parameter_machine_file`):
#: kind → "module:Class", the class imported when a file of that kind is first read. The one
#: line a new family without a file schema of its own adds, e.g.
#: ``"6-XYZ": "pkmcal.mechanisms.xyz_hexapod:XYZHexapod"``.
PARAMETER_FILE_KINDS: dict[str, str] = {}

__all__ = ["MACHINE_FILE_MODULES", "PARAMETER_FILE_KINDS"]

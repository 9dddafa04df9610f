"""A machine or a measurement setup by built-in name or by file path: the commands' front door.

A built-in name is resolved here from :mod:`pkmcal.mechanisms.library` and
:mod:`pkmcal.sensors.library`; only a file imports its reader (:mod:`.machine_file`,
:mod:`.setup_file`: YAML and pydantic, about 0.1 s of imports), so a command on the
built-in machines does not pay for file validation it does not use. An existing file wins
over a built-in of the same name.
"""

from __future__ import annotations

import os
from pathlib import Path

from pkmcal.errors import InputFileError, PkmcalError, record_source
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.library import builtin_machine, is_builtin_name
from pkmcal.sensors.base import MeasurementSetup
from pkmcal.sensors.library import BUILTIN_SETUPS, builtin_setup


def load_machine(spec: str | os.PathLike) -> Mechanism:
    """A machine by built-in name (``stewart-prototype``, ``symmetric:...``; see
    ``pkmcal machines``) or by the path of a YAML machine file."""
    text = os.fspath(spec)
    if os.path.exists(text):
        from pkmcal.io.machine_file import read_machine_file

        return read_machine_file(text)
    if is_builtin_name(text):
        machine = builtin_machine(text)
        record_source("machine", machine.name, "built-in")
        return machine
    from pkmcal.io.machine_file import MACHINE_FILE_SUFFIXES

    if text.lower().endswith(MACHINE_FILE_SUFFIXES) or os.sep in text or "/" in text:
        raise InputFileError(text, "no such machine file; check the path (or run 'pkmcal machines' for "
                                   "the built-in machines)")
    return builtin_machine(text)  # raises: unknown machine, listing the built-in names


def load_setup(path: str | os.PathLike, machine=None) -> MeasurementSetup:
    """The measurement setup of a YAML file, or of a built-in setup name; bound to
    ``machine`` (:func:`~pkmcal.sensors.library.bind_setup`) when one is given.

    Raises :class:`~pkmcal.errors.InputFileError` naming the file, line and key.
    """
    try:
        exists = Path(path).exists()
    except (OSError, ValueError):  # a name too long for the file system, a NUL byte
        exists = False
    if exists:
        from pkmcal.io.setup_file import read_setup_file

        return read_setup_file(path, machine)
    if str(path) in BUILTIN_SETUPS:
        return builtin_setup(str(path), machine)
    raise PkmcalError(f"setup file '{path}' does not exist and is not a built-in setup ({', '.join(BUILTIN_SETUPS)})")

"""Files: machine YAML (:mod:`~pkmcal.io.machine_file`), numeric CSV tables
(:mod:`~pkmcal.io.tables`) and atomic writes (:mod:`~pkmcal.io.atomic`).

The names below are imported on first use (PEP 562): the file schemas are pydantic models,
whose definition costs ~0.2 s, and ``pkmcal --help`` imports this package.
"""

from importlib import import_module

_EXPORTS = {
    "atomic_write_bytes": "pkmcal.io.atomic",
    "atomic_write_text": "pkmcal.io.atomic",
    "atomic_writer": "pkmcal.io.atomic",
    "check_output_dir": "pkmcal.io.atomic",
    "check_output_path": "pkmcal.io.atomic",
    "load_machine": "pkmcal.io.machine_file",
    "machine_from_text": "pkmcal.io.machine_file",
    "machine_to_text": "pkmcal.io.machine_file",
    "read_machine_file": "pkmcal.io.machine_file",
    "register_machine_kind": "pkmcal.io.machine_file",
    "save_machine": "pkmcal.io.machine_file",
    "Table": "pkmcal.io.tables",
    "format_table": "pkmcal.io.tables",
    "read_table": "pkmcal.io.tables",
    "write_table": "pkmcal.io.tables",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'pkmcal.io' has no attribute '{name}'")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
